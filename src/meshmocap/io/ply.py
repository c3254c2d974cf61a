"""Fast reading of binary PLY triangle meshes (the visual hulls meshmocap writes).

A tracker reads one hull per frame; trimesh's general PLY reader takes ~30 ms for a
41k-vertex hull, :func:`binary_ply_arrays` ~1 ms (one ``numpy.frombuffer`` per element).
It handles the common layout only — ``binary_little_endian``, a ``vertex`` element of
scalar properties including ``x``, ``y``, ``z``, then a ``face`` element whose single list
property holds triangles — and returns None for anything else, so that the caller falls
back to the general reader (which also reports malformed files).
"""

from __future__ import annotations

import numpy as np

#: PLY scalar type names → little-endian numpy type codes.
_SCALARS = {
    "char": "i1",
    "int8": "i1",
    "uchar": "u1",
    "uint8": "u1",
    "short": "<i2",
    "int16": "<i2",
    "ushort": "<u2",
    "uint16": "<u2",
    "int": "<i4",
    "int32": "<i4",
    "uint": "<u4",
    "uint32": "<u4",
    "float": "<f4",
    "float32": "<f4",
    "double": "<f8",
    "float64": "<f8",
}
_END = b"end_header\n"


def _header(data: bytes) -> tuple[list[tuple[str, int, list[list[str]]]], int] | None:
    """Elements ``(name, count, property lines)`` and the body's offset, or None."""
    end = data.find(_END, 0, 4096)
    if not data.startswith(b"ply\n") or end < 0:
        return None
    try:
        lines = data[4:end].decode("ascii").splitlines()
    except UnicodeDecodeError:
        return None
    elements: list[tuple[str, int, list[list[str]]]] = []
    fmt = None
    for line in lines:
        words = line.split()
        if not words or words[0] in ("comment", "obj_info"):
            continue
        if words[0] == "format":
            fmt = words[1:]
        elif words[0] == "element" and len(words) == 3 and words[2].isdigit():
            elements.append((words[1], int(words[2]), []))
        elif words[0] == "property" and elements:
            elements[-1][2].append(words[1:])
        else:
            return None
    if fmt != ["binary_little_endian", "1.0"]:
        return None
    return elements, end + len(_END)


def binary_ply_arrays(data: bytes) -> tuple[np.ndarray, np.ndarray] | None:
    """``(V, F)`` of a binary PLY triangle mesh in the common layout, else None.

    Parameters
    ----------
    data : bytes
        The whole file.

    Returns
    -------
    V : (n, 3) float64
        Vertices (the file's ``x``, ``y``, ``z``; other vertex properties are skipped).
    F : (m, 3) int64
        Triangles, indices in ``[0, n)``.
    None
        If the file is not in the layout described in the module docstring (ASCII or
        big-endian, other elements, polygons that are not all triangles, a size that does
        not match the header, indices out of range): read it with a general reader.
    """
    head = _header(data)
    if head is None:
        return None
    elements, offset = head
    if [e[0] for e in elements] != ["vertex", "face"]:
        return None
    (_, nv, vprops), (_, nf, fprops) = elements
    if any(len(p) != 2 or p[0] not in _SCALARS for p in vprops):
        return None
    vtype = np.dtype([(p[1], _SCALARS[p[0]]) for p in vprops])
    if not {"x", "y", "z"} <= set(vtype.names or ()):
        return None
    if len(fprops) != 1 or len(fprops[0]) != 4 or fprops[0][0] != "list":
        return None
    count_t, index_t = (_SCALARS.get(t) for t in fprops[0][1:3])
    if count_t is None or index_t is None or np.dtype(index_t).kind not in "iu":
        return None
    ftype = np.dtype([("n", count_t), ("i", index_t, 3)])
    if len(data) != offset + nv * vtype.itemsize + nf * ftype.itemsize:
        return None  # polygons other than triangles, or a truncated file
    vert = np.frombuffer(data, dtype=vtype, count=nv, offset=offset)
    face = np.frombuffer(data, dtype=ftype, count=nf, offset=offset + nv * vtype.itemsize)
    if nf and np.any(face["n"] != 3):
        return None
    V = np.stack([vert["x"], vert["y"], vert["z"]], axis=1).astype(np.float64)
    F = face["i"].astype(np.int64)
    if nf and (F.min() < 0 or F.max() >= nv):
        return None
    return V, F
