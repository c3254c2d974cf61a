"""Byte-shuffled vertices: written smaller, read back bit for bit, older plain files read
as before, a damaged one refused in one line."""

import io
import zipfile
import zlib

import numpy as np
import pytest

from meshmocap._npz import (
    SHUFFLED,
    STORED_BYTES,
    open_npz,
    read_npz,
    shuffled_float32,
    unshuffled_float32,
    write_npz,
)
from meshmocap.body.template import load_template
from meshmocap.errors import FormatError
from meshmocap.io.results import FrameResult, read_frame_arrays, start_track, write_frame

RNG = np.random.default_rng(7)


def test_shuffled_vertices_come_back_bit_for_bit_and_pack_smaller():
    V = load_template("neutral_5k").V + RNG.normal(scale=1e-3, size=(5000, 3))
    b = shuffled_float32(V)
    assert b.shape == (4, 3, 5000) and b.dtype == np.uint8
    back = unshuffled_float32(b)
    assert back.dtype == np.float32 and back.shape == V.shape
    np.testing.assert_array_equal(back, V.astype(np.float32))
    plain = len(zlib.compress(V.astype(np.float32).tobytes()))
    packed = len(zlib.compress(b.tobytes()))
    # measured on the 12k demo truth: 136 → 111 kB; here at least 8 % smaller
    assert packed < 0.92 * plain
    with pytest.raises(ValueError, match=r"\(4, k, n\) uint8"):
        unshuffled_float32(b[:3])


def test_readers_give_the_shuffled_array_under_its_name(tmp_path):
    V = RNG.normal(size=(10, 3))
    p = tmp_path / "a.npz"
    np.savez_compressed(p, **{f"vertices{SHUFFLED}": shuffled_float32(V)}, joints=V[:2])
    d = read_npz(p, "test", keys=("vertices", "joints"))
    assert sorted(d) == ["joints", "vertices"]
    np.testing.assert_array_equal(d["vertices"], V.astype(np.float32))
    with open_npz(p, "test") as z:
        assert "vertices" in z and f"vertices{SHUFFLED}" not in z
        np.testing.assert_array_equal(z["vertices"], V.astype(np.float32))
    np.savez_compressed(p, **{f"vertices{SHUFFLED}": np.zeros((3, 3, 10), np.uint8)})
    with pytest.raises(FormatError, match=r"a\.npz: not a readable \.npz test"):
        read_npz(p, "test")


def test_a_frame_is_written_shuffled_and_an_older_plain_one_still_reads(tmp_path):
    t = load_template("neutral_5k")
    start_track(tmp_path, {"method": "x", "eval_names": ["a"], "eval_parents": [-1]}, t.F)
    V = t.V + RNG.normal(scale=1e-3, size=t.V.shape)
    write_frame(tmp_path, FrameResult(0, V[:1], V))
    f = tmp_path / "frames" / "00000.npz"
    with np.load(f) as z:
        assert f"vertices{SHUFFLED}" in z.files and "vertices" not in z.files
        arrays = {k: z[k] for k in z.files if k != f"vertices{SHUFFLED}"}
    np.testing.assert_array_equal(read_frame_arrays(tmp_path, 0)["vertices"], V.astype(np.float32))
    plain = io.BytesIO()  # an older file: the vertices plain
    np.savez_compressed(plain, vertices=V.astype(np.float32), **arrays)
    assert len(plain.getvalue()) > f.stat().st_size
    f.write_bytes(plain.getvalue())
    np.testing.assert_array_equal(read_frame_arrays(tmp_path, 0)["vertices"], V.astype(np.float32))


def test_written_archives_read_as_numpys_own(tmp_path):
    arrays = {
        "big": RNG.normal(size=(STORED_BYTES // 8 + 1,)),
        "small": RNG.normal(size=(31, 3, 3)),
        "n": 7,
        "flag": True,
        "text": np.str_("lost left_arm"),
        "empty": np.zeros((0, 3)),
    }
    ours, theirs = tmp_path / "ours.npz", tmp_path / "theirs.npz"
    with open(ours, "wb") as f:
        write_npz(f, **arrays)
    np.savez_compressed(theirs, **arrays)
    a, b = read_npz(ours, "test"), read_npz(theirs, "test")
    assert list(a) == list(b) == list(arrays)
    for k in arrays:
        assert a[k].dtype == b[k].dtype and a[k].shape == b[k].shape, k
        np.testing.assert_array_equal(a[k], b[k])
    with np.load(ours) as z:
        np.testing.assert_array_equal(z["big"], arrays["big"])
    with zipfile.ZipFile(ours) as z:  # the big array deflated, the others stored
        kinds = {i.filename: i.compress_type for i in z.infolist()}
    assert kinds.pop("big.npy") == zipfile.ZIP_DEFLATED
    assert set(kinds.values()) == {zipfile.ZIP_STORED}


def test_arrays_read_as_numpy_reads_them_whatever_their_header(tmp_path):
    # plain headers are parsed by a pattern, any other by numpy: the same arrays either way
    arrays = {
        "f8": RNG.normal(size=(31, 3, 3)),
        "fortran": np.asfortranarray(RNG.normal(size=(4, 3))),
        "big_endian": RNG.normal(size=7).astype(">f4"),
        "text": np.str_("lost left_arm"),
        "texts": np.array(["ab", "c"]),
        "flag": np.asarray(True),
        "scalar": np.float64(2.5),
        "empty": np.zeros((0, 3)),
        "ints": np.arange(5, dtype=np.int32),
        "complex": np.complex128(1 + 2j),
        "record": np.zeros(3, dtype=[("a", "<f4"), ("b", "<i2")]),  # numpy's reader
    }
    p = tmp_path / "a.npz"
    np.savez(p, **arrays)
    d = read_npz(p, "test")
    with np.load(p) as z:
        for k in arrays:
            ref = z[k]
            assert d[k].dtype == ref.dtype and d[k].shape == ref.shape, k
            assert d[k].flags.writeable and d[k].flags.f_contiguous == ref.flags.f_contiguous, k
            np.testing.assert_array_equal(d[k], ref)
    raw = io.BytesIO()  # a member cut short: refused in one line, as before
    with zipfile.ZipFile(raw, "w") as zf:
        member = io.BytesIO()
        np.lib.format.write_array(member, RNG.normal(size=(31, 3, 3)))
        zf.writestr("cut.npy", member.getvalue()[:-8])
    (tmp_path / "cut.npz").write_bytes(raw.getvalue())
    with pytest.raises(FormatError, match=r"cut\.npz: not a readable \.npz test"):
        read_npz(tmp_path / "cut.npz", "test")


def test_written_archives_are_the_bytes_zipfile_and_numpy_write():
    # the archive packed at once: byte for byte what zipfile writes of write_array's
    # members (deflated above STORED_BYTES), the second time (headers kept) as the first
    arrays = {
        "big": RNG.normal(size=(STORED_BYTES // 8 + 1,)),
        "small": RNG.normal(size=(31, 3, 3)),
        "fortran": np.asfortranarray(RNG.normal(size=(40, 30))),
        "strided": RNG.normal(size=(20, 6))[::2, ::3],
        "big_endian": RNG.normal(size=7).astype(">f4"),
        "n": 7,
        "flag": True,
        "text": np.str_("lost left_arm"),
        "texts": np.array(["ab", "c"]),
        "empty": np.zeros((0, 3)),
        "bytes": RNG.integers(0, 255, (3, 5000), dtype=np.uint8),
    }
    want = io.BytesIO()
    with zipfile.ZipFile(want, "w") as zf:
        for name, value in arrays.items():
            a = np.asanyarray(value)
            member = io.BytesIO()
            np.lib.format.write_array(member, a, allow_pickle=False)
            info = zipfile.ZipInfo(f"{name}.npy", date_time=(1980, 1, 1, 0, 0, 0))
            deflate = a.nbytes > STORED_BYTES
            kind = zipfile.ZIP_DEFLATED if deflate else zipfile.ZIP_STORED
            zf.writestr(info, member.getbuffer(), kind, compresslevel=1 if deflate else None)
    for _ in range(2):
        ours = io.BytesIO()
        write_npz(ours, **arrays)
        assert ours.getvalue() == want.getvalue()
    with pytest.raises(ValueError, match="pickle"):
        write_npz(io.BytesIO(), objects=np.array([{}], dtype=object))
