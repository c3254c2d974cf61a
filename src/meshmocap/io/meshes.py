"""Reading and writing capture geometry: meshes, point clouds and frame sequences.

Every array leaving this module is in the library's world frame: metres, right-handed,
**Z up**. Files stored Y up (most scanners, Maya, the MIT crane sequence) are converted on
reading with ``up="y"``: the rotation of +90° about X, ``(x, y, z) → (x, −z, y)``.

Meshes are read through trimesh with ``process=False`` (and ``maintain_order=True`` for
OBJ) so that vertex ``i`` of the array is vertex ``i`` of the file: fixed-connectivity
sequences such as the crane keep their correspondences. In OBJ files with texture
coordinates trimesh drops the vertices no face uses; :func:`read_mesh` then warns
(:class:`MeshmocapWarning`). STL triangle soup has its coincident corners merged.

A :class:`MeshSequence` streams frames from a folder, a glob, a list of files or a ``.tar``
/ ``.tar.gz`` archive, reading one frame at a time. Archives are read in place: a gzip
stream is indexed once (decompressor checkpoints every few MiB), so a member anywhere in
the archive costs a few MiB of decompression, not a pass over the archive.
"""

from __future__ import annotations

import copy
import glob as globlib
import io
import logging
import os
import re
import warnings
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Literal, get_args

import numpy as np
import trimesh

from meshmocap._atomic import write_bytes_atomic
from meshmocap._npz import NPY_ERRORS
from meshmocap._validate import counted
from meshmocap.errors import FormatError, InputError, MeshError, MeshmocapWarning
from meshmocap.errors import MeshmocapFileNotFoundError as NotFound
from meshmocap.io.archives import TarArchive
from meshmocap.io.ply import binary_ply_arrays

Up = Literal["z", "y"]
Kind = Literal["auto", "mesh", "points"]

#: Extensions read as meshes (PLY without faces is read as a point cloud by ``kind="auto"``).
MESH_EXTENSIONS = (".obj", ".ply", ".off", ".stl", ".glb", ".gltf")
#: Extensions read as point clouds.
POINT_EXTENSIONS = (".ply", ".xyz", ".npy", ".pcd")
#: Extensions :func:`write_mesh` can write.
WRITE_EXTENSIONS = (".obj", ".ply", ".off", ".stl", ".glb")
_FRAME_EXTENSIONS = tuple(dict.fromkeys(MESH_EXTENSIONS + POINT_EXTENSIONS))
_ARCHIVE_SUFFIXES = (".tar.gz", ".tgz", ".tar")

# (x, y, z) → (x, −z, y): rows are the new axes in old coordinates (det = +1).
_Y_TO_Z = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])


def _check_choice(name: str, value: object, literal: object) -> None:
    choices = get_args(literal)
    if value not in choices:
        raise InputError(f"{name} must be one of {list(choices)}, found {value!r}")


def _ext(name: str) -> str:
    return os.path.splitext(name)[1].lower()


def _to_world(X: np.ndarray | None, up: str) -> np.ndarray | None:
    return X if X is None or up == "z" else X @ _Y_TO_Z.T


def _one_line(exc: BaseException) -> str:
    text = str(exc).strip().splitlines()
    return f"{type(exc).__name__}: {text[0] if text else ''}".rstrip(": ")


def _finite(
    X: np.ndarray, label: str, what: str, data: bytes | None = None, *, array: bool = False
) -> None:
    """Refuse NaN or infinite rows of ``X``, naming the first as a reader of the file counts:
    vertex ``k + 1`` (1-based), and for an OBJ file (``data``) its line; row ``k`` of an
    ``array`` given in Python."""
    bad = np.flatnonzero(~np.isfinite(X).all(axis=1))
    if bad.size:
        k, one = int(bad[0]), _SINGULAR[what]
        first = f"row {k}" if array else f"{one} {k + 1} of the file"
        line = _obj_line(data, b"v", k) if data is not None else None
        first += f", line {line}" if line is not None else ""
        are = "is" if bad.size == 1 else "are"
        raise MeshError(
            f"{label}: {counted(bad.size, one, what)} {are} NaN or infinite (first: {first})"
        )


_SINGULAR = {"vertices": "vertex", "points": "point", "normals": "normal"}


def _obj_line(data: bytes, keyword: bytes, k: int) -> int | None:
    """The 1-based line number of the ``k``-th (0-based) ``keyword`` line of an OBJ file."""
    for n, m in enumerate(re.finditer(rb"(?m)^" + keyword + rb"[ \t]", data)):
        if n == k:
            return data.count(b"\n", 0, m.start()) + 1
    return None


def _load_scene(data: bytes, ext: str, label: str):
    _check_header(data, ext, label)
    kwargs = {"maintain_order": True, "skip_materials": True} if ext == ".obj" else {}
    log = logging.getLogger("trimesh")
    level, log.level = log.level, logging.CRITICAL  # trimesh logs tracebacks of bad files
    try:
        with warnings.catch_warnings(), np.errstate(all="ignore"):
            warnings.simplefilter("ignore")  # its parsers warn on what they then reject
            return trimesh.load_scene(io.BytesIO(data), file_type=ext[1:], process=False, **kwargs)
    except Exception as exc:  # trimesh raises anything from KeyError to IndexError
        raise MeshError(f"{label}: cannot read {ext[1:].upper()} file ({_one_line(exc)})") from None
    finally:
        log.level = level


#: Largest mesh or point-cloud file read, bytes (1 GiB: a binary PLY of about 25 million
#: vertices; a 2.6-million-vertex visual hull takes about 100 MB). ``MESHMOCAP_MAX_MESH_MB``
#: changes it. Archive members are held to the same limit.
MAX_MESH_BYTES = 1 << 30
#: Largest vertex or face count a file header may declare.
MAX_MESH_ELEMENTS = 50_000_000


def max_mesh_bytes() -> int:
    """The file-size limit in force (``MESHMOCAP_MAX_MESH_MB`` megabytes, else 1 GiB)."""
    env = os.environ.get("MESHMOCAP_MAX_MESH_MB", "")
    return int(float(env) * 1e6) if env.replace(".", "", 1).isdigit() else MAX_MESH_BYTES


def _check_size(size: int, label: str) -> None:
    cap = max_mesh_bytes()
    if size > cap:
        raise MeshError(
            f"{label}: {size / 1e6:.0f} MB, above the {cap / 1e6:.0f} MB limit of one mesh "
            "file (about 25 million vertices; MESHMOCAP_MAX_MESH_MB raises it)"
        )


def _check_header(data: bytes, ext: str, label: str) -> None:
    """Refuse headers declaring more elements than :data:`MAX_MESH_ELEMENTS` or than the
    file could hold (a reader would allocate for them before finding out)."""
    if ext == ".ply":
        counts = [int(n) for n in re.findall(rb"element \w+ (\d{1,30})", data[:4096])]
    elif ext == ".off":
        m = re.match(
            rb"\s*(?:#[^\n]*\n\s*)*[A-Z]*OFF\s+(?:#[^\n]*\n\s*)*(\d{1,30})\s+(\d{1,30})",
            data[:4096],
        )
        counts = [int(n) for n in m.groups()] if m else []
    else:
        return
    big = max(counts, default=0)
    if big > MAX_MESH_ELEMENTS or big > len(data):
        raise MeshError(
            f"{label}: header declares {big} elements in a file of {len(data)} "
            f"bytes (at most {MAX_MESH_ELEMENTS} are read)"
        )


def _read_bytes(path: Path) -> bytes:
    if not path.is_file():
        raise NotFound(f"{path}: no such file")
    try:
        _check_size(path.stat().st_size, str(path))
        return path.read_bytes()
    except OSError as exc:
        raise MeshError(f"{path}: cannot read ({_one_line(exc)})") from None


def _parse_mesh(data: bytes, ext: str, label: str, up: str) -> tuple[np.ndarray, np.ndarray]:
    if ext not in MESH_EXTENSIONS:
        raise InputError(f"{label}: mesh files must end in {list(MESH_EXTENSIONS)}, found {ext!r}")
    fast = binary_ply_arrays(data) if ext == ".ply" else None  # ~30x faster than trimesh
    if ext == ".obj":  # a plain OBJ (a 4D capture's frame): ~10x faster than trimesh
        fast = plain_obj_arrays(data)
    if fast is not None and len(fast[0]) and len(fast[1]):
        _finite(fast[0], label, "vertices", data if ext == ".obj" else None)
        return _to_world(fast[0], up), fast[1]
    scene = _load_scene(data, ext, label)
    meshes = [g for g in scene.geometry.values() if isinstance(g, trimesh.Trimesh)]
    if not meshes:
        raise MeshError(
            f"{label}: no triangles (a file cut off before its faces, or a point cloud, which "
            "is read from .ply, .xyz, .npy or .pcd files)"
        )
    try:
        with warnings.catch_warnings(), np.errstate(all="ignore"):
            warnings.simplefilter("ignore")
            mesh = scene.to_mesh()  # parts concatenated in order, scene transforms applied
            if ext == ".stl":
                mesh.merge_vertices()
            V = np.asarray(mesh.vertices, dtype=np.float64)
            F = np.asarray(mesh.faces, dtype=np.int64)
    except Exception as exc:  # trimesh's post-processing of a damaged file
        raise MeshError(f"{label}: cannot read {ext[1:].upper()} file ({_one_line(exc)})") from None
    if V.ndim != 2 or V.shape[1] != 3 or F.ndim != 2 or F.shape[1] != 3:
        raise MeshError(f"{label}: malformed mesh: vertices {V.shape}, faces {F.shape}")
    if len(V) == 0 or len(F) == 0:
        raise MeshError(f"{label}: empty mesh ({len(V)} vertices, {len(F)} faces)")
    if F.min() < 0 or F.max() >= len(V):
        raise MeshError(
            f"{label}: face indices must lie in [0, {len(V) - 1}], found [{F.min()}, {F.max()}]"
        )
    _finite(V, label, "vertices", data if ext == ".obj" else None)
    if ext == ".obj":
        _check_obj_faces(data, label)
        n_file = len(re.findall(rb"(?m)^v[ \t]", data))
        if n_file != len(V):
            msg = f"{n_file} 'v' lines but {len(V)} vertices read (unreferenced vertices"
            msg += " dropped or split at texture seams): indices differ from the file's"
            warnings.warn(f"{label}: {msg}", MeshmocapWarning, stacklevel=3)
    return _to_world(V, up), F


def plain_obj_arrays(data: bytes) -> tuple[np.ndarray, np.ndarray] | None:
    """The vertices ``V`` (n, 3) float64 and triangles ``F`` (m, 3) int64 (0-based) of a
    plain OBJ file, in file order, or None where the file is not plain (anything else is
    read by trimesh).

    Plain: every line ``v x y z`` (all the vertices first) then ``f i j k`` (1-based
    indices of those vertices, no texture or normal indices), nothing else (no comment, no
    blank line but a last one): what 4D capture exporters write. The lines' tokens are
    counted on the bytes at once, and each block is parsed by one ``numpy.fromstring``."""
    b = np.frombuffer(data, dtype=np.uint8)
    if len(b) < 8 or b[0] != ord("v"):
        return None
    nl = b == 10
    ws = nl | (b == 32) | (b == 9) | (b == 13)
    first = np.concatenate(([True], ws[:-1])) & ~ws  # each token's first byte
    line = np.cumsum(nl) - nl  # each byte's line
    n_lines = int(line[-1]) + 1
    if not (np.bincount(line[first], minlength=n_lines) == 4).all():
        return None  # a line of other than 4 tokens, a blank line
    starts = np.concatenate(([0], np.flatnonzero(nl[:-1]) + 1))  # each line's first byte
    head = b[starts]
    n = int(np.count_nonzero(head == ord("v")))
    if n == n_lines or not (head[:n] == ord("v")).all() or not (head[n:] == ord("f")).all():
        return None
    if not ws[starts + 1].all():  # "vn", "vt", "fo..." lines
        return None
    cut = int(starts[n])
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # numpy warns where a block has unmatched data
        try:
            V = np.fromstring(data[:cut].replace(b"v", b" "), dtype=np.float64, sep=" ")
            F = np.fromstring(data[cut:].replace(b"f", b" "), dtype=np.int64, sep=" ")
        except (ValueError, DeprecationWarning):  # "1/2/3" faces, words: trimesh's
            return None
    if len(V) != 3 * n or len(F) != 3 * (n_lines - n):
        return None
    F = F.reshape(-1, 3) - 1
    if F.min() < 0 or F.max() >= n:  # relative (negative) indices, or out of range
        return None
    return V.reshape(-1, 3), F


#: An OBJ face line of fewer than 3 vertices (what a file cut off in its faces ends with).
_SHORT_FACE = re.compile(rb"(?m)^f(?:[ \t]+[^\s]+){0,2}[ \t]*\r?$")


def _check_obj_faces(data: bytes, label: str) -> None:
    """Refuse an OBJ face line of fewer than 3 vertices (a reader drops it silently): one
    line naming the file's line (1-based) and what it holds."""
    m = _SHORT_FACE.search(data)
    if m is None:
        return
    text = m.group().decode(errors="replace").strip()
    line = data.count(b"\n", 0, m.start()) + 1
    last = not data[m.end() :].strip()
    why = "the file is cut off there" if last else "the file is damaged"
    n = len(text.split()) - 1
    raise MeshError(
        f"{label}: line {line} {text!r} is a face of {counted(n, 'vertex', 'vertices')}, "
        f"expected 3 or more ({why})"
    )


def read_mesh(path: str | os.PathLike, *, up: Up = "z") -> tuple[np.ndarray, np.ndarray]:
    """Read a triangle mesh (OBJ, PLY, OFF, STL, GLB/glTF) as arrays.

    Parameters
    ----------
    path : str or path, the file; its extension selects the format
    up : {"z", "y"}, the file's up axis; ``"y"`` converts to Z up by ``(x, y, z) → (x, −z, y)``

    Returns
    -------
    V : (n, 3) float64
        Vertices, metres, world frame, in file order (see the module notes for OBJ limits).
    F : (m, 3) int64
        Triangles (polygons are fan-triangulated by trimesh). A file with several parts
        (a glTF scene, OBJ objects) is flattened into one mesh, scene transforms applied.

    Raises
    ------
    MeshmocapFileNotFoundError : ``path`` does not exist.
    MeshError : unreadable, empty, face-less, NaN/infinite vertices (one line naming the file).
    InputError : unsupported extension or ``up``.
    """
    _check_choice("up", up, Up)
    path = Path(path)
    ext = _ext(path.name)
    if ext not in MESH_EXTENSIONS:
        raise InputError(f"{path}: mesh files must end in {list(MESH_EXTENSIONS)}, found {ext!r}")
    return _parse_mesh(_read_bytes(path), ext, str(path), up)


def _parse_points(
    data: bytes, ext: str, label: str, up: str
) -> tuple[np.ndarray, np.ndarray | None]:
    N = None
    if ext == ".npy":
        try:
            A = np.load(io.BytesIO(data), allow_pickle=False)
        except NPY_ERRORS as exc:
            raise FormatError(f"{label}: not a readable .npy array ({_one_line(exc)})") from None
        A = np.asarray(A, dtype=np.float64) if A.dtype.kind in "fiu" else A
    elif ext in (".xyz", ".pcd"):
        A = _parse_text_points(data, ext, label)
    elif ext in MESH_EXTENSIONS:
        scene = _load_scene(data, ext, label)
        geoms = list(scene.geometry.values())
        if not geoms:
            raise MeshError(f"{label}: empty point cloud (0 points)")
        try:
            with warnings.catch_warnings(), np.errstate(all="ignore"):
                warnings.simplefilter("ignore")
                g = geoms[0] if len(geoms) == 1 else scene.to_mesh()  # mesh parts: all vertices
                A = np.asarray(g.vertices, dtype=np.float64)
                raw = g.metadata.get("_ply_raw", {}).get("vertex", {}).get("data", {})
                if isinstance(raw, dict) and all(k in raw for k in ("nx", "ny", "nz")):
                    N = np.column_stack([np.ravel(raw[k]) for k in ("nx", "ny", "nz")])
                    N = N.astype(np.float64) if N.shape == A.shape else None
        except Exception as exc:  # trimesh's post-processing of a damaged file
            raise MeshError(
                f"{label}: cannot read {ext[1:].upper()} points ({_one_line(exc)})"
            ) from None
    else:
        ok = list(dict.fromkeys(POINT_EXTENSIONS + MESH_EXTENSIONS))
        raise InputError(f"{label}: point files must end in {ok}, found {ext!r}")
    if A.dtype.kind != "f" or A.ndim != 2 or A.shape[1] not in (3, 6):
        raise FormatError(f"{label}: expected (n, 3) or (n, 6) numbers, found {A.shape} {A.dtype}")
    if len(A) == 0:
        raise MeshError(f"{label}: empty point cloud (0 points)")
    P = np.ascontiguousarray(A[:, :3])
    N = np.ascontiguousarray(A[:, 3:]) if A.shape[1] == 6 else N
    for X, what in ((P, "points"), (N, "normals")):
        if X is not None:
            _finite(X, label, what)
    return _to_world(P, up), _to_world(N, up)


def _parse_text_points(data: bytes, ext: str, label: str) -> np.ndarray:
    cols = None
    if ext == ".pcd":
        head, sep, body = data.partition(b"\nDATA ")
        fmt = body.split(b"\n", 1)[0].strip() if sep else b""
        if fmt != b"ascii":
            raise FormatError(
                f"{label}: only ASCII PCD is supported, found DATA {fmt.decode(errors='replace')!r}"
            )
        fields = next((ln.split()[1:] for ln in head.splitlines() if ln[:6] == b"FIELDS"), [])
        if not fields or fields[:3] != [b"x", b"y", b"z"]:
            raise FormatError(f"{label}: PCD FIELDS must start with x y z, found {fields}")
        names = [b"x", b"y", b"z", b"normal_x", b"normal_y", b"normal_z"]
        has_n = all(n in fields for n in names[3:])
        cols = [fields.index(n) for n in (names if has_n else names[:3])]
        data = body.split(b"\n", 1)[1] if b"\n" in body else b""
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", UserWarning)  # numpy: "input contained no data"
            A = np.loadtxt(io.BytesIO(data), comments="#", ndmin=2, dtype=np.float64)
    except ValueError as exc:
        raise FormatError(f"{label}: not a table of numbers ({_one_line(exc)})") from None
    if A.size == 0 or cols is not None:
        if A.size and A.shape[1] <= max(cols):
            raise FormatError(
                f"{label}: PCD FIELDS name {len(fields)} columns, the data has {A.shape[1]}"
            )
        return A[:, cols] if A.size else np.zeros((0, 3))
    return A[:, :6] if A.shape[1] >= 6 else A[:, :3] if A.shape[1] >= 3 else A


def read_points(path: str | os.PathLike, *, up: Up = "z") -> tuple[np.ndarray, np.ndarray | None]:
    """Read a point cloud (PLY, XYZ text, NPY, ASCII PCD, or a mesh file's vertices).

    Parameters
    ----------
    path : str or path
        ``.ply`` (``x y z`` and optional ``nx ny nz`` vertex properties), ``.xyz`` (text
        columns ``x y z [nx ny nz]``, ``#`` comments), ``.npy`` ((n, 3) or (n, 6) array),
        ``.pcd`` (``DATA ascii`` with fields ``x y z`` and optional ``normal_x/y/z``), or
        any mesh format of :func:`read_mesh` (its vertices, no normals).
    up : {"z", "y"}, the file's up axis (see :func:`read_mesh`); normals are rotated too

    Returns
    -------
    P : (n, 3) float64, points, metres, world frame
    N : (n, 3) float64, normals as stored (not renormalised), or None where the file has none
    """
    _check_choice("up", up, Up)
    path = Path(path)
    return _parse_points(_read_bytes(path), _ext(path.name), str(path), up)


def write_mesh(path: str | os.PathLike, V: np.ndarray, F: np.ndarray, *, up: Up = "z") -> Path:
    """Write a triangle mesh atomically (temporary file, then ``os.replace``).

    Parameters
    ----------
    path : str or path, ending in ``.obj``, ``.ply``, ``.off``, ``.stl`` or ``.glb``
    V : (n, 3) float, vertices, metres, world frame (Z up). OBJ keeps 10 decimals; PLY and
        GLB store float32 (relative precision 6e-8).
    F : (m, 3) int, triangles; vertex and face order are kept (STL has no shared vertices).
    up : {"z", "y"}, the file's up axis; ``"y"`` applies ``(x, y, z) → (x, z, −y)``, the
        inverse of :func:`read_mesh`'s conversion.

    Returns
    -------
    Path : ``path``.
    """
    _check_choice("up", up, Up)
    path = Path(path)
    ext = _ext(path.name)
    if ext not in WRITE_EXTENSIONS:
        raise InputError(f"write_mesh: path must end in {list(WRITE_EXTENSIONS)}, found {ext!r}")
    V = np.asarray(V, dtype=np.float64)
    F = np.asarray(F)
    if V.ndim != 2 or V.shape[1] != 3 or len(V) == 0:
        raise InputError(f"write_mesh: V must have shape (n, 3) with n > 0, found {V.shape}")
    if F.ndim != 2 or F.shape[1] != 3 or F.dtype.kind not in "iu":
        raise InputError(f"write_mesh: F must be (m, 3) integers, found {F.shape} {F.dtype}")
    if len(F) and (F.min() < 0 or F.max() >= len(V)):
        raise InputError(f"write_mesh: face indices must lie in [0, {len(V) - 1}]")
    _finite(V, "write_mesh: V", "vertices", array=True)
    if not path.parent.is_dir():
        raise NotFound(f"{path.parent}: folder does not exist")
    if up == "y":
        V = V @ _Y_TO_Z  # inverse rotation: (x, y, z) → (x, z, −y)
    mesh = trimesh.Trimesh(V, F.astype(np.int64), process=False)
    extra = {"digits": 10, "include_normals": False} if ext == ".obj" else {}
    data = mesh.export(file_type=ext[1:], **extra)
    write_bytes_atomic(path, data.encode() if isinstance(data, str) else data)
    return path


# --------------------------------------------------------------------------- sequences


@dataclass(frozen=True, eq=False)
class Frame:
    """One frame of a capture.

    Attributes
    ----------
    index : int, position of the file in the source's sorted listing (its frame number)
    path : str, the file, or ``"archive.tar.gz::member/name.obj"`` for an archive member
    V : (n, 3) float64, vertices or points, metres, world frame (Z up)
    F : (m, 3) int64, triangles, or None for a point cloud
    normals : (n, 3) float64, normals stored in a point-cloud file, or None
    """

    index: int
    path: str
    V: np.ndarray
    F: np.ndarray | None
    normals: np.ndarray | None = None


def natural_key(name: str) -> tuple:
    """Sort key putting ``mesh_2`` before ``mesh_10`` (digit runs compare as integers)."""
    parts = re.split(r"(\d+)", name)
    return tuple((0, int(p), "") if p.isdigit() else (1, 0, p.lower()) for p in parts)


class MeshSequence:
    """A lazy, indexable sequence of capture frames, read one at a time.

    Parameters
    ----------
    source : str, path or sequence of paths
        A folder (its frame files, non-recursive), a glob pattern (``"cap/*.ply"``), one
        file, an explicit list of files (kept in the given order), or a ``.tar``,
        ``.tar.gz`` or ``.tgz`` archive of frame files (read in place, never unpacked).
        Folder, glob and archive listings are sorted naturally (``mesh_2`` before
        ``mesh_10``); hidden files (``.name``) are skipped.
    frames : range, slice or sequence of int, optional
        Which frames of the sorted listing to keep, e.g. ``range(0, 175, 5)``;
        :attr:`Frame.index` keeps the position in the full listing.
    kind : {"auto", "mesh", "points"}
        ``"auto"`` reads OBJ/OFF/STL/GLB as meshes, XYZ/NPY/PCD as points, and PLY as a
        mesh when it has faces; ``"mesh"`` requires triangles; ``"points"`` keeps only
        vertices (with normals where the file has them).
    up : {"z", "y"}, the files' up axis (see :func:`read_mesh`)

    Raises
    ------
    MeshmocapFileNotFoundError : missing folder/file, glob matching nothing, no frame files.
    InputError : bad ``frames``, ``kind`` or ``up``; a folder mixing frame formats.
    FormatError : a corrupt archive.

    Notes
    -----
    ``len()``, indexing (``seq[i]`` → :class:`Frame`, ``seq[a:b:c]`` → a sub-sequence) and
    iteration read files on demand; nothing is cached. Archive members are located once at
    construction (for a gzip archive this decompresses it once: 0.6 s for the 39 MB crane
    archive). Not thread-safe; give each worker its own sequence (sequences pickle).
    """

    def __init__(
        self,
        source: str | os.PathLike | Sequence[str | os.PathLike],
        *,
        frames: range | slice | Sequence[int] | None = None,
        kind: Kind = "auto",
        up: Up = "z",
    ) -> None:
        _check_choice("kind", kind, Kind)
        _check_choice("up", up, Up)
        self._kind, self._up = kind, up
        self._archive: TarArchive | None = None
        if isinstance(source, str | os.PathLike):
            self._source = os.fspath(source)
            self._names = self._list(self._source)
        else:
            paths = [os.fspath(p) for p in source]
            missing = [p for p in paths if not os.path.isfile(p)]
            if missing or not paths:
                what = f"{missing[0]}: no such file" if missing else "no files given"
                raise NotFound(f"MeshSequence: {what}")
            self._source, self._names = f"[{len(paths)} files]", paths
        self._select = _selection(frames, len(self._names))

    def _list(self, source: str) -> list[str]:
        path, what = Path(source), "folder"
        if source.lower().endswith(_ARCHIVE_SUFFIXES) and path.is_file():
            self._archive, what = TarArchive(path, _check_size), "archive"
            names = [n for n in self._archive.names if is_frame_file(n)]
        elif path.is_dir():
            names = [str(p) for p in path.iterdir() if p.is_file() and is_frame_file(p.name)]
            exts = sorted({_ext(n) for n in names})
            if len(exts) > 1:  # the glob of the format most files have
                count = {e: sum(_ext(n) == e for n in names) for e in exts}
                most = max(exts, key=lambda e: count[e])
                held = ", ".join(f"{count[e]} {e}" for e in exts)
                raise InputError(
                    f"{source}: folder mixes {exts} ({held}); pass a glob like "
                    f"'{path / ('*' + most)}'"
                )
        elif path.is_file():
            if not is_frame_file(path.name):
                raise InputError(f"{source}: not a frame file {list(_FRAME_EXTENSIONS)}")
            return [source]
        elif globlib.has_magic(source):
            names = [p for p in globlib.glob(source) if os.path.isfile(p)]
            if not names:
                raise NotFound(f"{source}: glob matches no files")
            bad = sorted({_ext(n) for n in names if not is_frame_file(n)})
            if bad:
                raise InputError(f"{source}: glob matches non-frame files {bad}; narrow it")
        else:
            raise NotFound(f"{source}: no such folder, file or archive")
        if not names:
            raise NotFound(f"{source}: {what} holds no frame files {list(_FRAME_EXTENSIONS)}")
        return sorted(names, key=natural_key)

    def __len__(self) -> int:
        return len(self._select)

    def __repr__(self) -> str:
        return f"MeshSequence({self._source!r}, {len(self)} frames, kind={self._kind!r})"

    @property
    def paths(self) -> list[str]:
        """The selected frames' sources (files, or ``archive::member``), in order."""
        return [self._label(i) for i in self._select]

    @property
    def indices(self) -> np.ndarray:
        """(len,) int64: the selected frames' positions in the full sorted listing."""
        return np.array(self._select, dtype=np.int64)

    @property
    def numbers(self) -> np.ndarray:
        """(len,) int64: the selected frames' numbers, read from their file names
        (:func:`frame_numbers`: ``00005.ply`` is frame 5, whatever files are missing).

        Raises
        ------
        InputError : a name that is not a frame number, or two files of one number.
        """
        numbers = frame_numbers([self._label(i) for i in range(len(self._names))])
        return np.array([numbers[i] for i in self._select], dtype=np.int64)

    def _label(self, i: int) -> str:
        return f"{self._archive.path}::{self._names[i]}" if self._archive else self._names[i]

    def __getitem__(self, key: int | slice) -> Frame | MeshSequence:
        if isinstance(key, slice):
            sub = copy.copy(self)  # shares the listing and the archive index
            sub._select = self._select[key]
            return sub
        if not isinstance(key, int | np.integer):
            raise InputError(f"MeshSequence index must be an int or slice, found {type(key)}")
        n = len(self)
        if not -n <= key < n:
            raise IndexError(f"frame {key} out of range for {n} frames")
        return self._read(self._select[int(key)])

    def __iter__(self) -> Iterator[Frame]:
        for i in self._select:
            yield self._read(i)

    def _read(self, i: int) -> Frame:
        name, label = self._names[i], self._label(i)
        data = self._archive.read(name) if self._archive else _read_bytes(Path(name))
        ext, kind = _ext(name), self._kind
        if kind == "auto":
            no_faces = ext == ".ply" and not re.search(rb"element face [1-9]", data[:4096])
            kind = "points" if ext in (".xyz", ".npy", ".pcd") or no_faces else "mesh"
        if kind == "mesh":
            V, F = _parse_mesh(data, ext, label, self._up)
            return Frame(int(i), label, V, F)
        P, N = _parse_points(data, ext, label, self._up)
        return Frame(int(i), label, P, None, N)


def frame_files(sources: Sequence[str | os.PathLike]) -> list[str]:
    """The frame files of several sources (files, folders, globs), one list, sorted
    naturally (``mesh_2`` before ``mesh_10``), as a quoted glob would list them: what a
    shell passes for an unquoted ``my-meshes/*.ply``.

    Raises
    ------
    MeshmocapFileNotFoundError : a source that does not exist, or no frame files at all.
    InputError : a file that is not a frame file, or frame files of several formats.
    """
    names: list[str] = []
    for source in map(os.fspath, sources):
        path = Path(source)
        if path.is_file():
            if not is_frame_file(path.name):
                raise InputError(f"{source}: not a frame file {list(_FRAME_EXTENSIONS)}")
            names.append(source)
        elif path.is_dir() or globlib.has_magic(source):
            names += MeshSequence(source).paths
        else:
            raise NotFound(f"{source}: no such file or folder")
    exts = sorted({_ext(n) for n in names})
    if len(exts) > 1:
        raise InputError(f"frame files of several formats {exts}; give one format")
    return sorted(dict.fromkeys(names), key=natural_key)


_NUMBERED = re.compile(r"^(.*?)(\d+)$")


def frame_numbers(names: Sequence[str]) -> list[int]:
    """The frame number of each file name: the run of digits that ends its stem
    (``mesh_0042.obj`` → 42, ``00005.ply`` → 5), after a prefix the names share. A single
    file without digits is frame 0.

    Raises
    ------
    InputError
        One line naming the file: a name that does not end in digits (``00005 (1).ply``, a
        copy), whose prefix differs from the others' (``00005_1.ply`` among ``NNNNN.ply``), or
        two files of the same number.
    """
    stems = [os.path.splitext(os.path.basename(n.split("::")[-1]))[0] for n in names]
    matches = [_NUMBERED.match(s) for s in stems]
    if len(names) == 1 and matches[0] is None:
        return [0]
    prefixes = [m.group(1) for m in matches if m is not None]
    common = max(set(prefixes), key=prefixes.count) if prefixes else ""
    seen: dict[int, str] = {}
    out = []
    for name, m in zip(names, matches, strict=True):
        if m is None or m.group(1) != common:
            like = f"{common}NNNN{_ext(name)}"
            raise InputError(
                f"{name}: not a frame number (frame files are named like {like}, the frame "
                "number last); rename or remove it"
            )
        k = int(m.group(2))
        if k in seen:
            raise InputError(f"{name}: frame {k} again (also {seen[k]}); remove one of them")
        seen[k] = name
        out.append(k)
    return out


def is_frame_file(name: str) -> bool:
    """Whether the file ``name`` is a frame of a mesh or point folder (a known extension,
    not hidden)."""
    base = os.path.basename(name)
    return not base.startswith(".") and _ext(base) in _FRAME_EXTENSIONS


def _selection(frames: range | slice | Sequence[int] | None, n: int) -> list[int]:
    if frames is None or isinstance(frames, slice):
        return list(range(n)[frames or slice(None)])
    idx = np.asarray(list(frames))
    bad = idx.ndim != 1 or not idx.size or idx.dtype.kind not in "iu"
    if bad or not 0 <= idx.min() <= idx.max() < n:
        raise InputError(
            f"frames must be a non-empty range, slice or list of ints in [0, {n - 1}] "
            f"({n} frame files), found {frames!r}"
        )
    return idx.tolist()
