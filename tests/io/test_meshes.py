"""Mesh, point-cloud and frame-sequence reading and writing (meshmocap.io.meshes)."""

import gzip
import io
import os
import pickle
import re
import tarfile
import zlib

import numpy as np
import pytest
import trimesh

from meshmocap.errors import (
    FormatError,
    InputError,
    MeshError,
    MeshmocapFileNotFoundError,
    MeshmocapWarning,
)
from meshmocap.io.archives import GzipIndex, GzipReader
from meshmocap.io.meshes import (
    Frame,
    MeshSequence,
    natural_key,
    plain_obj_arrays,
    read_mesh,
    read_points,
    write_mesh,
)

RNG = np.random.default_rng(5)


def _sphere(subdivisions: int = 1, radius: float = 1.0) -> tuple[np.ndarray, np.ndarray]:
    m = trimesh.creation.icosphere(subdivisions=subdivisions, radius=radius)
    V = np.asarray(m.vertices) + RNG.normal(scale=0.01, size=m.vertices.shape)
    return V, np.asarray(m.faces, dtype=np.int64)


# ---------------------------------------------------------------- single meshes


# Tolerances: OBJ is written with 10 decimals (≤ 5e-11 m); PLY and GLB store float32
# (relative 6e-8, coordinates ≤ 1.1 m → < 1e-7 m); OFF is written by trimesh in full.
@pytest.mark.parametrize(
    ("suffix", "atol"), [(".obj", 1e-10), (".ply", 1e-7), (".off", 1e-7), (".glb", 1e-7)]
)
def test_write_then_read_keeps_vertex_and_face_order(tmp_path, suffix, atol):
    V, F = _sphere()
    path = write_mesh(tmp_path / f"m{suffix}", V, F)
    V2, F2 = read_mesh(path)
    assert V2.dtype == np.float64 and F2.dtype == np.int64
    assert np.abs(V2 - V).max() <= atol
    assert np.array_equal(F2, F)
    assert [p.name for p in tmp_path.iterdir()] == [f"m{suffix}"]  # no temporary left over


def _obj(V, F, vertex="v {:.6f} {:.6f} {:.6f}", face="f {} {} {}") -> bytes:
    lines = [vertex.format(*v) for v in V] + [face.format(*(f + 1)) for f in F]
    return ("\n".join(lines) + "\n").encode()


def test_plain_obj_is_read_by_numpy_as_trimesh_reads_it(tmp_path):
    """A plain OBJ (v lines, then f lines) is parsed without trimesh, to the same arrays;
    any other OBJ is left to trimesh (plain_obj_arrays returns None) and reads the same."""
    V, F = _sphere()
    data = _obj(V, F)
    fast = plain_obj_arrays(data)
    assert fast is not None
    (tmp_path / "a.obj").write_bytes(data)
    scene = trimesh.load(tmp_path / "a.obj", process=False, maintain_order=True)
    assert np.array_equal(fast[0], scene.vertices) and np.array_equal(fast[1], scene.faces)
    assert np.array_equal(read_mesh(tmp_path / "a.obj")[1], F)
    assert plain_obj_arrays(data.replace(b"\n", b"\r\n")) is not None  # Windows lines
    not_plain = {
        "comment": b"# made by hand\n" + data,
        "normals": data + b"vn 0 0 1\n",
        "slashes": _obj(V, F, face="f {0}//{0} {1}//{1} {2}//{2}"),
        "negative": _obj(V, F - len(V) - 1),
        "blank line": data.replace(b"\nf", b"\n\nf", 1),
        "a quad": data + b"f 1 2 3 4\n",
        "four numbers": _obj(V, F, vertex="v {:.6f} {:.6f} {:.6f} 1.0"),
        "no faces": _obj(V, F[:0]),
        "words": data.replace(b"v ", b"v x", 1),
    }
    for why, text in not_plain.items():
        assert plain_obj_arrays(text) is None, why
    (tmp_path / "c.obj").write_bytes(not_plain["comment"])
    V2, F2 = read_mesh(tmp_path / "c.obj")  # through trimesh
    assert np.array_equal(V2, fast[0]) and np.array_equal(F2, F)
    bad = _obj(np.where(np.arange(len(V))[:, None] == 3, np.nan, V), F)
    (tmp_path / "n.obj").write_bytes(bad)
    with pytest.raises(MeshError, match=r"n\.obj: 1 vertex is NaN.*vertex 4 of the file, line 4"):
        read_mesh(tmp_path / "n.obj")


def test_stl_triangle_soup_is_merged_into_the_same_surface(tmp_path):
    V, F = _sphere()
    V2, F2 = read_mesh(write_mesh(tmp_path / "m.stl", V, F))
    assert len(V2) == len(V) and len(F2) == len(F)  # corners merged back into shared vertices
    c, c2 = V[F].mean(axis=1), V2[F2].mean(axis=1)
    gap = np.linalg.norm(c[:, None] - c2[None], axis=2)
    assert gap.min(axis=1).max() < 1e-6  # every triangle is there (float32 file: < 1e-7 m)
    assert len(np.unique(gap.argmin(axis=1))) == len(F)  # one to one


def test_y_up_files_are_rotated_to_z_up(tmp_path):
    V = np.array([[1.0, 2.0, 3.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]])
    F = np.array([[0, 1, 2]])
    path = write_mesh(tmp_path / "y.obj", V, F)  # stored as is: pretend the file is Y up
    Vz, _ = read_mesh(path, up="y")
    assert np.allclose(Vz, [[1.0, -3.0, 2.0], [0.0, 0.0, 1.0], [0.0, -1.0, 0.0]], atol=1e-12)
    # writing Y up applies the inverse rotation: a round trip is the identity
    V3, _ = read_mesh(write_mesh(tmp_path / "z.obj", V, F, up="y"), up="y")
    assert np.allclose(V3, V, atol=1e-12)


def test_a_scene_of_several_parts_is_concatenated(tmp_path):
    a = trimesh.creation.box()
    b = trimesh.creation.icosphere(subdivisions=1)
    b.apply_translation([3.0, 0.0, 0.0])
    trimesh.Scene([a, b]).export(tmp_path / "s.glb")
    V, F = read_mesh(tmp_path / "s.glb")
    assert len(V) == len(a.vertices) + len(b.vertices)
    assert len(F) == len(a.faces) + len(b.faces)
    assert V[:, 0].max() > 3.5  # the second part keeps its place


def test_obj_whose_vertices_do_not_survive_warns(tmp_path):
    path = tmp_path / "loose.obj"
    path.write_text(
        "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 5 5 5\nvt 0 0\nvt 1 0\nvt 0 1\nf 1/1 2/2 3/3\n"
    )  # trimesh drops vertex 4 when texture coordinates exist
    with pytest.warns(MeshmocapWarning, match="4 'v' lines but 3 vertices"):
        V, _ = read_mesh(path)
    assert len(V) == 3


@pytest.mark.parametrize(
    ("name", "content", "error", "match"),
    [
        ("empty.obj", "", MeshError, "empty mesh|no triangles"),
        ("garbage.ply", "hello", MeshError, "cannot read PLY"),
        (
            "nan.obj",
            "v nan 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n",
            MeshError,
            "1 vertex is NaN or infinite \\(first: vertex 1 of the file, line 1\\)",
        ),
        ("points.obj", "v 0 0 0\nv 1 0 0\n", MeshError, "no triangles|empty"),
        ("mesh.xyz", "0 0 0\n", InputError, "must end in"),
    ],
)
def test_bad_mesh_files_raise_one_line_errors_naming_the_file(
    tmp_path, name, content, error, match
):
    path = tmp_path / name
    path.write_text(content)
    with pytest.raises(error, match=match) as info:
        read_mesh(path)
    message = str(info.value)
    assert str(path) in message and "\n" not in message and "Traceback" not in message


def test_missing_file_and_bad_options(tmp_path):
    with pytest.raises(MeshmocapFileNotFoundError, match="no such file"):
        read_mesh(tmp_path / "nope.obj")
    with pytest.raises(InputError, match=r"up must be one of \['z', 'y'\], found 'x'"):
        read_mesh(tmp_path / "nope.obj", up="x")
    V, F = _sphere(0)
    with pytest.raises(MeshmocapFileNotFoundError, match="folder does not exist"):
        write_mesh(tmp_path / "no" / "m.obj", V, F)
    with pytest.raises(InputError, match="face indices"):
        write_mesh(tmp_path / "m.obj", V, F + len(V))
    with pytest.raises(InputError, match="must end in"):
        write_mesh(tmp_path / "m.dae", V, F)
    with pytest.raises(MeshError, match="NaN"):
        write_mesh(tmp_path / "m.obj", np.where(np.arange(len(V))[:, None] == 3, np.nan, V), F)


# ---------------------------------------------------------------- point clouds


def _cloud(n: int = 50) -> tuple[np.ndarray, np.ndarray]:
    P = RNG.normal(size=(n, 3))
    N = RNG.normal(size=(n, 3))
    return P, N / np.linalg.norm(N, axis=1, keepdims=True)


def test_point_formats_with_normals(tmp_path):
    P, N = _cloud()
    rows = "".join(" ".join(f"{v:.9f}" for v in r) + "\n" for r in np.hstack([P, N]))
    (tmp_path / "c.xyz").write_text("# x y z nx ny nz\n" + rows)
    np.save(tmp_path / "c.npy", np.hstack([P, N]))
    head = "ply\nformat ascii 1.0\nelement vertex 50\n" + "".join(
        f"property float {k}\n" for k in ("x", "y", "z", "nx", "ny", "nz")
    )
    (tmp_path / "c.ply").write_text(head + "end_header\n" + rows)
    pcd = "VERSION .7\nFIELDS x y z normal_x normal_y normal_z\nWIDTH 50\nDATA ascii\n"
    (tmp_path / "c.pcd").write_text(pcd + rows)
    for name, atol in (("c.xyz", 1e-9), ("c.npy", 0.0), ("c.ply", 1e-6), ("c.pcd", 1e-9)):
        P2, N2 = read_points(tmp_path / name)  # ascii PLY is parsed as float32: 1e-6
        assert np.abs(P2 - P).max() <= atol and np.abs(N2 - N).max() <= atol, name
    P3, N3 = read_points(tmp_path / "c.npy", up="y")  # normals rotate with the points
    assert np.allclose(P3, P[:, [0, 2, 1]] * [1, -1, 1]) and np.allclose(
        N3, N[:, [0, 2, 1]] * [1, -1, 1]
    )


def test_points_without_normals_and_from_a_mesh(tmp_path):
    P, _ = _cloud()
    np.save(tmp_path / "p.npy", P)
    P2, N2 = read_points(tmp_path / "p.npy")
    assert N2 is None and np.array_equal(P2, P)
    V, F = _sphere(0)
    P3, N3 = read_points(write_mesh(tmp_path / "m.obj", V, F))
    assert N3 is None and np.allclose(P3, V, atol=1e-10)


def test_bad_point_files(tmp_path):
    (tmp_path / "empty.xyz").write_text("# nothing\n")
    with pytest.raises(MeshError, match="empty point cloud"):
        read_points(tmp_path / "empty.xyz")
    (tmp_path / "b.pcd").write_text("FIELDS x y z\nDATA binary\n\x00\x01")
    with pytest.raises(FormatError, match="only ASCII PCD"):
        read_points(tmp_path / "b.pcd")
    (tmp_path / "t.xyz").write_text("1 2 three\n")
    with pytest.raises(FormatError, match="not a table of numbers"):
        read_points(tmp_path / "t.xyz")
    (tmp_path / "n.xyz").write_text("1 2 3\nnan 0 0\n")
    with pytest.raises(
        MeshError, match=r"1 point is NaN or infinite \(first: point 2 of the file\)"
    ):
        read_points(tmp_path / "n.xyz")


# ---------------------------------------------------------------- sequences


def _frames(folder, n: int = 4, suffix: str = ".obj") -> list[np.ndarray]:
    folder.mkdir(exist_ok=True)
    V0, F = _sphere(0)
    Vs = []
    for k in range(n):
        V = V0 + [0.1 * k, 0.0, 0.0]
        write_mesh(folder / f"mesh_{k * 5}{suffix}", V, F)  # mesh_0, mesh_5, mesh_10, mesh_15
        Vs.append(V)
    return Vs


def test_natural_order_indexing_slicing_and_iteration(tmp_path):
    Vs = _frames(tmp_path / "cap")
    seq = MeshSequence(tmp_path / "cap")
    assert len(seq) == 4
    assert [os.path.basename(p) for p in seq.paths] == [f"mesh_{k}.obj" for k in (0, 5, 10, 15)]
    assert sorted(["m10", "m2", "M1"], key=natural_key) == ["M1", "m2", "m10"]
    f = seq[-1]
    assert isinstance(f, Frame) and f.index == 3 and f.normals is None
    assert np.allclose(f.V, Vs[3], atol=1e-10)
    sub = seq[1::2]
    assert isinstance(sub, MeshSequence) and list(sub.indices) == [1, 3]
    assert [fr.index for fr in sub] == [1, 3]
    picked = MeshSequence(tmp_path / "cap", frames=range(0, 4, 3))
    assert [fr.index for fr in picked] == [0, 3]
    glob = MeshSequence(str(tmp_path / "cap" / "mesh_1*.obj"))
    assert [os.path.basename(p) for p in glob.paths] == ["mesh_10.obj", "mesh_15.obj"]
    listed = MeshSequence([tmp_path / "cap" / "mesh_5.obj", tmp_path / "cap" / "mesh_0.obj"])
    assert np.allclose(listed[0].V, Vs[1], atol=1e-10)  # an explicit list keeps its order
    again = pickle.loads(pickle.dumps(seq))
    assert np.array_equal(again[2].V, seq[2].V)
    with pytest.raises(IndexError):
        seq[4]


def test_point_cloud_frames(tmp_path):
    (tmp_path / "pc").mkdir()
    for k in range(3):
        np.save(tmp_path / "pc" / f"cloud_{k}.npy", RNG.normal(size=(20, 6)))
    seq = MeshSequence(tmp_path / "pc")
    f = seq[1]
    assert f.F is None and f.V.shape == (20, 3) and f.normals.shape == (20, 3)


def test_sequence_errors(tmp_path):
    with pytest.raises(MeshmocapFileNotFoundError, match="no such folder"):
        MeshSequence(tmp_path / "missing")
    with pytest.raises(MeshmocapFileNotFoundError, match="glob matches no files"):
        MeshSequence(str(tmp_path / "*.obj"))
    (tmp_path / "empty").mkdir()
    with pytest.raises(MeshmocapFileNotFoundError, match="holds no frame files"):
        MeshSequence(tmp_path / "empty")
    _frames(tmp_path / "mixed", 2)
    _frames(tmp_path / "mixed", 2, ".ply")
    with pytest.raises(InputError, match="mixes"):
        MeshSequence(tmp_path / "mixed")
    _frames(tmp_path / "ok", 2)
    with pytest.raises(InputError, match="frames must"):
        MeshSequence(tmp_path / "ok", frames=[0, 2])
    with pytest.raises(InputError, match="kind must be one of"):
        MeshSequence(tmp_path / "ok", kind="cloud")
    (tmp_path / "bad").mkdir()
    (tmp_path / "bad" / "f_1.obj").write_text("v 0 0 nan\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")
    seq = MeshSequence(tmp_path / "bad")  # listing is lazy: the error comes with the frame
    with pytest.raises(MeshError, match=r"f_1\.obj: 1 vertex is NaN"):
        seq[0]


def _tar_gz(path, folder, order) -> None:
    with tarfile.open(path, "w:gz") as tf:
        for name in order:  # members in a scrambled order, under a folder, like the crane
            tf.add(folder / name, arcname=f"capture/{name}")


def test_tar_gz_archive_matches_the_folder(tmp_path):
    _frames(tmp_path / "cap", 5)
    archive = tmp_path / "cap.tar.gz"
    _tar_gz(archive, tmp_path / "cap", [f"mesh_{k}.obj" for k in (10, 0, 20, 5, 15)])
    folder, packed = MeshSequence(tmp_path / "cap"), MeshSequence(archive)
    assert len(packed) == 5 and packed.paths[1] == f"{archive}::capture/mesh_5.obj"
    for a, b in zip(folder, packed, strict=True):
        assert a.index == b.index and np.array_equal(a.V, b.V) and np.array_equal(a.F, b.F)
    assert np.array_equal(packed[-1].V, folder[-1].V)  # random access after iteration


def test_gzip_reader_random_access_with_checkpoints(tmp_path):
    """Seeks anywhere in a two-member gzip stream, restored from decompressor snapshots."""
    data = RNG.integers(0, 20, size=3_000_000, dtype=np.uint8).tobytes()  # compressible
    path = tmp_path / "x.gz"
    path.write_bytes(gzip.compress(data[:1_000_000]) + gzip.compress(data[1_000_000:]))
    index = GzipIndex(spacing=100_000, max_points=8)  # small: forces snapshots and thinning
    with open(path, "rb") as f:
        r = GzipReader(f, index)
        assert r.seek(0, 2) == len(data)  # decompresses to the end, taking snapshots
        assert 2 <= len(index.points) <= 8
        for start in RNG.integers(0, len(data), size=20):
            r.seek(int(start))
            assert r.read(5000) == data[start : start + 5000]
        r.seek(len(data) - 10)
        assert r.read() == data[-10:] and r.read(10) == b""


def test_gzip_reads_in_order_resume_where_the_last_stopped(tmp_path, monkeypatch):
    """Each read opens a new reader (as TarArchive.read does); reads in order continue from
    the index's cursor (each byte decompressed once), out of order from the snapshots."""
    data = RNG.integers(0, 20, size=2_000_000, dtype=np.uint8).tobytes()
    path = tmp_path / "x.gz"
    path.write_bytes(gzip.compress(data))
    index = GzipIndex(spacing=10 << 20)  # no snapshot but the start
    steps = []
    step = GzipReader._step
    monkeypatch.setattr(GzipReader, "_step", lambda self: steps.append(1) or step(self))

    def read(at: int, n: int) -> bytes:
        with open(path, "rb") as f:
            r = GzipReader(f, index)
            r.seek(at)
            return r.read(n)

    for at in range(0, len(data), 100_000):  # in order
        assert read(at, 100_000) == data[at : at + 100_000]
    in_order = len(steps)
    assert in_order <= len(path.read_bytes()) // GzipReader._CHUNK + 2  # one pass
    for at in RNG.integers(0, len(data), size=5):  # out of order, from the start
        assert read(int(at), 1000) == data[at : at + 1000]


def test_corrupt_archive(tmp_path):
    _frames(tmp_path / "cap", 2)
    good = tmp_path / "good.tar.gz"
    _tar_gz(good, tmp_path / "cap", ["mesh_0.obj", "mesh_5.obj"])
    bad = tmp_path / "bad.tar.gz"
    bad.write_bytes(good.read_bytes()[:300])
    with pytest.raises(FormatError, match=r"bad\.tar\.gz"):
        MeshSequence(bad)
    with pytest.raises(zlib.error):  # the archive layer turns it into a FormatError
        GzipReader(io.BytesIO(b"\x1f\x8bnot really"), GzipIndex()).read(10)


# ---------------------------------------------------------------- the real crane sequence


def test_crane_frames_from_folder_and_archive_are_identical(shared_data):
    crane = shared_data / "meshes" / "crane"
    archive = crane / "crane_mesh_0000-0174.tar.gz"
    if not archive.is_file() or not (crane / "first10").is_dir():
        pytest.skip(f"crane sequence not available under {crane}")
    folder = MeshSequence(crane / "first10", frames=range(3))
    packed = MeshSequence(archive)
    assert len(packed) == 175
    for k in range(3):
        a, b = folder[k], packed[k]
        assert a.V.shape == (10002, 3) and a.F.shape == (20000, 3)
        assert np.array_equal(a.V, b.V) and np.array_equal(a.F, b.F)  # exact, same order
        assert b.path.endswith(f"mesh_{k:04d}.obj")
        raw = np.loadtxt(a.path, comments=None, usecols=(1, 2, 3), max_rows=10002)
        assert np.array_equal(a.V, raw)  # vertex k of the array is the k-th 'v' line


def test_frame_numbers_come_from_the_file_names():
    from meshmocap.io.meshes import frame_numbers

    assert frame_numbers(["a/00000.ply", "a/00005.ply", "a/00012.ply"]) == [0, 5, 12]
    assert frame_numbers(["c.tar.gz::mesh_0000.obj", "c.tar.gz::mesh_0174.obj"]) == [0, 174]
    assert frame_numbers(["scan.obj"]) == [0]  # one file without a number: frame 0
    assert frame_numbers(["take2_007.ply"]) == [7]
    for names, bad in (
        (["00000.ply", "00005 (1).ply"], "00005 (1).ply: not a frame number"),
        (["00000.ply", "00001.ply", "x_00002.ply"], "x_00002.ply: not a frame number"),
        (["a.ply", "b.ply"], "a.ply: not a frame number"),
        (["m_1.ply", "m_001.ply"], "m_001.ply: frame 1 again (also m_1.ply)"),
    ):
        with pytest.raises(InputError, match=re.escape(bad)):
            frame_numbers(names)
