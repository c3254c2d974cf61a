"""Reading ``.npz`` archives safely: one-line errors and a size cap, never unpacked to disk.

``numpy.load`` lets through ``zipfile.BadZipFile``, ``zlib.error``, ``EOFError``, a pickle
complaint for a file that is not a zip at all, and happily inflates a small archive into
gigabytes. :func:`read_npz` reads every array of an archive in memory, refuses archives
whose arrays would unpack past :data:`MAX_NPZ_BYTES` (read from the zip directory before
anything is inflated), and turns every failure into one line naming the file, what it was
expected to be and what went wrong. :func:`open_npz` does the same for readers that need
only some of the arrays (a hull's mesh without its occupancy), inflating only those.

Vertices are written byte-shuffled (:func:`shuffled_float32`, the array named ``NAME`` +
:data:`SHUFFLED` in the archive): deflate then packs a float32 surface about 15–20 %
smaller, losslessly; both readers hand it back as ``NAME``, float32, as it was.
"""

from __future__ import annotations

import io
import math
import os
import re
import struct
import sys
import zipfile
import zlib
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from tokenize import TokenError
from typing import IO

import numpy as np

from meshmocap.errors import FormatError, MeshmocapError, MeshmocapFileNotFoundError

#: What ``numpy.load`` raises on a damaged ``.npy`` (its header is parsed as Python syntax).
NPY_ERRORS = (
    ValueError,
    OSError,
    EOFError,
    SyntaxError,
    TokenError,
    UnicodeDecodeError,
    TypeError,
    MemoryError,
    OverflowError,
)

#: Largest total of uncompressed array bytes one ``.npz`` may hold (4 GiB; a 2.6-million-
#: vertex hull's occupancy and mesh take about 100 MB). ``MESHMOCAP_MAX_NPZ_MB`` changes it.
MAX_NPZ_BYTES = 4 << 30


def max_npz_bytes() -> int:
    """The cap in force: ``MESHMOCAP_MAX_NPZ_MB`` megabytes if set, else :data:`MAX_NPZ_BYTES`."""
    env = os.environ.get("MESHMOCAP_MAX_NPZ_MB", "")
    return int(float(env) * 1e6) if env.replace(".", "", 1).isdigit() else MAX_NPZ_BYTES


def read_npz(
    path: str | os.PathLike,
    what: str,
    *,
    keys: tuple[str, ...] = (),
    error: type[MeshmocapError] = FormatError,
) -> dict[str, np.ndarray]:
    """Every array of the ``.npz`` file ``path`` (no pickles), as a dict.

    Parameters
    ----------
    path : path, the file
    what : str, what the file should be, for messages (``"template"``, ``"pose manifold"``)
    keys : tuple of str, arrays the file must hold (a missing one raises ``error``)
    error : the error class raised for an unreadable file (a :class:`MeshmocapError`)

    Raises
    ------
    MeshmocapFileNotFoundError
        No such file.
    error
        Not a zip archive, a corrupt or truncated one, an array that is not a readable
        ``.npy`` (or holds Python objects), arrays above the size cap, or a missing key.
    """
    with open_npz(path, what, error=error) as z:
        total = sum(i.file_size for i in z.members.values())
        if total > z.cap:
            raise z.too_big(total)
        d = {k: z[k] for k in z.members}
    missing = [k for k in keys if k not in d]
    if missing:
        raise error(f"{path}: not a {what}: missing {', '.join(map(repr, missing))}")
    return d


#: Suffix of an array stored by :func:`shuffled_float32` (``vertices.f4s``).
SHUFFLED = ".f4s"


def shuffled_float32(a: np.ndarray) -> np.ndarray:
    """``a`` (n, k) as float32, its bytes grouped by significance, coordinate by coordinate:
    (4, k, n) uint8 (the sign and exponent bytes, nearly constant, side by side), which
    deflate compresses better than the interleaved floats; :func:`unshuffled_float32`
    inverts it exactly."""
    f = np.asarray(a, dtype=np.float32)
    n, k = f.shape
    cols = np.ascontiguousarray(f.T)  # (k, n)
    return np.ascontiguousarray(cols.view(np.uint8).reshape(k, n, 4).transpose(2, 0, 1))


def unshuffled_float32(b: np.ndarray) -> np.ndarray:
    """The (n, k) float32 array :func:`shuffled_float32` made ``b`` (4, k, n) uint8 from.

    Raises
    ------
    ValueError
        ``b`` is not (4, k, n) bytes.
    """
    if b.dtype != np.uint8 or b.ndim != 3 or b.shape[0] != 4:
        raise ValueError(f"shuffled float32 must be (4, k, n) uint8, found {b.shape} {b.dtype}")
    _, k, n = b.shape
    return np.ascontiguousarray(b.transpose(2, 1, 0)).view(np.float32).reshape(n, k)


#: Arrays of at most this many bytes are stored in a written archive as they are
#: (:func:`write_npz`): deflating them saves a few bytes at the cost of a compressor each.
STORED_BYTES = 4096


def write_npz(f: IO[bytes], **arrays) -> None:
    """Write ``arrays`` (name → array-like, no Python objects) to the binary file ``f`` as
    an ``.npz`` archive that ``numpy.load`` and :func:`read_npz` read as they read
    ``numpy.savez_compressed``'s: the arrays above :data:`STORED_BYTES` deflated at
    deflate's fastest level (a frame's vertices: 1.5× faster, the file about 5 % larger),
    the others stored, the archive assembled in memory and written at once (one write
    instead of a few small ones per array). The archive's bytes are those ``zipfile``
    writes (its local headers, central directory and end record, packed here at once:
    a frame's ~25 small members cost ``zipfile`` more than their data), each ``.npy``
    member's those ``numpy.lib.format.write_array`` writes (its header kept per dtype,
    order and shape)."""
    members = []
    for name, value in arrays.items():
        a = np.asanyarray(value)
        members.append((f"{name}.npy", _npy_bytes(a), a.nbytes > STORED_BYTES))
    small = sum(len(data) for _, data, _ in members) < 1 << 30 and len(members) < 1 << 15
    if small and all(name.isascii() for name, _, _ in members):
        f.write(_zip_bytes(members))
        return
    buf = io.BytesIO()  # a name or a size zipfile writes differently (UTF-8, ZIP64)
    with zipfile.ZipFile(buf, "w") as zf:
        for name, data, deflate in members:
            info = zipfile.ZipInfo(name, date_time=(1980, 1, 1, 0, 0, 0))
            if deflate:
                zf.writestr(info, data, zipfile.ZIP_DEFLATED, compresslevel=1)
            else:
                zf.writestr(info, data, zipfile.ZIP_STORED)
    f.write(buf.getbuffer())


#: ``.npy`` headers written so far, by dtype, order and shape (a track's frames repeat them).
_HEADERS: dict[tuple, bytes] = {}


def _npy_bytes(a: np.ndarray) -> bytes:
    """The bytes ``numpy.lib.format.write_array`` (no pickles) writes for ``a``."""
    plain = type(a) is np.ndarray and not a.dtype.hasobject and a.dtype.names is None
    fortran = a.flags.f_contiguous and not a.flags.c_contiguous
    key = (a.dtype.str, fortran, a.shape)
    if not plain or key not in _HEADERS:
        member = io.BytesIO()
        np.lib.format.write_array(member, a, allow_pickle=False)
        raw = member.getvalue()
        if plain and len(_HEADERS) < 4096:
            _HEADERS[key] = raw[: len(raw) - a.nbytes]
        return raw
    return _HEADERS[key] + a.tobytes(order="F" if fortran else "C")


def _zip_bytes(members: list[tuple[str, bytes, bool]]) -> bytes:
    """The zip archive ``zipfile.ZipFile(..., "w")`` writes of ``members`` (name, data,
    deflated at level 1 or stored), each dated 1980-01-01 00:00, in a seekable file: each
    member's local header (version 2.0, no flags, its checksum and sizes), its data, then
    the central directory (made by Unix, read-write by the owner) and the end record."""
    dosdate, dostime, made = 1 << 5 | 1, 0, 0 if sys.platform == "win32" else 3
    local, central = [], []
    offset = 0
    for name, data, deflate in members:
        if deflate:
            packer = zlib.compressobj(1, zlib.DEFLATED, -15)
            stored, kind = packer.compress(data) + packer.flush(), 8
        else:
            stored, kind = data, 0
        crc, fname = zlib.crc32(data), name.encode("ascii")
        sizes = (dostime, dosdate, crc, len(stored), len(data), len(fname))
        local += [struct.pack("<4s2B4HL2L2H", b"PK\003\004", 20, 0, 0, kind, *sizes, 0), fname]
        local.append(stored)
        central.append(
            struct.pack(
                "<4s4B4HL2L5H2L",
                b"PK\001\002",
                20,
                made,
                20,
                0,
                0,
                kind,
                *sizes,
                0,
                0,
                0,
                0,
                0o600 << 16,
                offset,
            )
            + fname
        )
        offset += 30 + len(fname) + len(stored)
    directory = b"".join(central)
    n = len(members)
    end = struct.pack("<4s4H2LH", b"PK\005\006", 0, 0, n, n, len(directory), offset, 0)
    return b"".join(local) + directory + end


#: The header ``numpy.save`` writes for a plain array (format 1.0: a numeric, boolean or
#: string dtype, C or Fortran order), which :func:`_plain_array` reads without evaluating it.
_PLAIN_HEADER = re.compile(
    rb"\{'descr': '([<>|=][biufcU]\d+)', 'fortran_order': (False|True), "
    rb"'shape': \(((?:\d+, )*\d*,?)\), \} *\n"
)


def _plain_array(raw: bytes) -> np.ndarray | None:
    """The array of the ``.npy`` bytes ``raw`` when its header is the plain one
    :data:`_PLAIN_HEADER` matches and its data are all there (a fresh, writable array, as
    ``numpy.lib.format.read_array`` gives from a buffer); None otherwise. Parsing the
    header with a pattern instead of evaluating it as Python: a frame file holds ~25 small
    arrays, and the evaluation was most of reading them."""
    if raw[6:8] != b"\x01\x00" or len(raw) < 10:
        return None
    end = 10 + int.from_bytes(raw[8:10], "little")
    m = _PLAIN_HEADER.fullmatch(raw, 10, end)
    if m is None:
        return None
    dtype = np.dtype(m.group(1).decode("ascii"))
    shape = tuple(int(n) for n in m.group(3).split(b",") if n.strip())
    count = math.prod(shape)
    if dtype.itemsize == 0 or len(raw) < end + count * dtype.itemsize:
        return None
    a = np.frombuffer(raw, dtype=dtype, count=count, offset=end).copy()
    if m.group(2) == b"True":
        return a.reshape(shape[::-1]).transpose()
    return a.reshape(shape)


class NpzArchive:
    """An ``.npz`` file read into memory, whose arrays are inflated one at a time on request
    (``z[name]``), so that a reader pays only for the arrays it uses; see :func:`open_npz`.

    Attributes
    ----------
    path : Path; ``members``: array name → its zip entry (a shuffled array under its own
    name, :data:`SHUFFLED`); ``cap``: the size cap in bytes
    """

    def __init__(self, path: Path, what: str, error: type[MeshmocapError]):
        self.path, self.what, self.error = path, what, error
        self.cap = max_npz_bytes()
        self._inflated = 0
        with self._errors():
            # one read of the whole file: a zip read in place makes many small reads
            self._zip = zipfile.ZipFile(io.BytesIO(path.read_bytes()))
            self.members = {
                i.filename[:-4] if i.filename.endswith(".npy") else i.filename: i
                for i in self._zip.infolist()
            }
        self._shuffled = {k[: -len(SHUFFLED)] for k in self.members if k.endswith(SHUFFLED)}
        self._shuffled -= set(self.members)  # a plain array of the same name wins
        for name in self._shuffled:
            self.members[name] = self.members.pop(name + SHUFFLED)

    def __contains__(self, name: str) -> bool:
        return name in self.members

    def __getitem__(self, name: str) -> np.ndarray:
        """The array ``name`` (as ``numpy.load`` gives it: the raw bytes of a member that is
        not a ``.npy``); a name the archive lacks raises ``error``."""
        if name not in self.members:
            raise self.error(f"{self.path}: not a {self.what}: missing {name!r}")
        info = self.members[name]
        self._inflated += info.file_size
        if self._inflated > self.cap:
            raise self.too_big(self._inflated)
        with self._errors():
            raw = self._zip.read(info)
            if not raw.startswith(np.lib.format.MAGIC_PREFIX):
                return raw
            a = _plain_array(raw)
            if a is None:  # any other header: numpy's own reader and its checks
                a = np.lib.format.read_array(io.BytesIO(raw), allow_pickle=False)
            return unshuffled_float32(a) if name in self._shuffled else a

    def too_big(self, total: int) -> MeshmocapError:
        """The error for arrays unpacking to ``total`` bytes, above the cap."""
        return self.error(
            f"{self.path}: {self.what} arrays unpack to {total / 1e6:.0f} MB, above the "
            f"{self.cap / 1e6:.0f} MB limit (MESHMOCAP_MAX_NPZ_MB)"
        )

    @contextmanager
    def _errors(self) -> Iterator[None]:
        try:
            yield
        except MeshmocapError:
            raise
        except (
            zipfile.BadZipFile,
            zlib.error,
            KeyError,
            NotImplementedError,
            RuntimeError,
            *NPY_ERRORS,
        ) as exc:
            text = str(exc).strip().splitlines()
            why = f"{type(exc).__name__}: {text[0] if text else ''}".rstrip(": ")
            why = f"not a readable .npz {self.what} ({why[:160]})"
            raise self.error(f"{self.path}: {why}") from None

    def close(self) -> None:
        """Release the archive."""
        self._zip.close()

    def __enter__(self) -> NpzArchive:
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def open_npz(
    path: str | os.PathLike, what: str, *, error: type[MeshmocapError] = FormatError
) -> NpzArchive:
    """Open the ``.npz`` file ``path`` for reading arrays one at a time (a context manager;
    errors as :func:`read_npz`'s, each array counted against the size cap as it is read).

    Raises
    ------
    MeshmocapFileNotFoundError
        No such file.
    error
        Not a zip archive (the arrays' own damage is raised when they are read).
    """
    path = Path(path)
    if not path.is_file():
        what_is = "is a folder, not a file" if path.is_dir() else "no such file"
        raise MeshmocapFileNotFoundError(f"{path}: {what_is}")
    return NpzArchive(path, what, error)
