"""The fast binary PLY path (io/ply.py): identical arrays to trimesh's reader where it
applies, None (general reader) everywhere else."""

from __future__ import annotations

import io

import numpy as np
import pytest
import trimesh

from meshmocap.io.meshes import read_mesh
from meshmocap.io.ply import binary_ply_arrays


def _box() -> trimesh.Trimesh:
    return trimesh.creation.box(extents=(0.3, 0.2, 0.5))


def _trimesh_arrays(data: bytes) -> tuple[np.ndarray, np.ndarray]:
    m = trimesh.load(io.BytesIO(data), file_type="ply", process=False)
    return np.asarray(m.vertices, dtype=np.float64), np.asarray(m.faces, dtype=np.int64)


def _ply(
    vprops: str,
    vrows: bytes,
    faces: bytes,
    nv: int,
    nf: int,
    fmt="binary_little_endian",
    flist="list uchar int vertex_indices",
    extra="",
) -> bytes:
    head = (
        f"ply\nformat {fmt} 1.0\ncomment test\nelement vertex {nv}\n{vprops}"
        f"element face {nf}\nproperty {flist}\n{extra}end_header\n"
    )
    return head.encode() + vrows + faces


def test_same_arrays_as_trimesh_for_exported_meshes():
    mesh = _box()
    plain = mesh.export(file_type="ply")
    V, F = binary_ply_arrays(plain)
    V0, F0 = _trimesh_arrays(plain)
    # exact: both read the same float32 values and widen them to float64
    np.testing.assert_array_equal(V, V0)
    np.testing.assert_array_equal(F, F0)
    assert V.dtype == np.float64 and F.dtype == np.int64


def test_extra_vertex_properties_and_doubles():
    rng = np.random.default_rng(0)
    P = rng.normal(size=(4, 3))
    rows = np.zeros(
        4, dtype=[("x", "<f8"), ("nx", "<f4"), ("y", "<f8"), ("z", "<f8"), ("red", "u1")]
    )
    rows["x"], rows["y"], rows["z"] = P.T
    F = np.array([[0, 1, 2], [0, 2, 3]])
    faces = np.zeros(2, dtype=[("n", "u1"), ("i", "<u4", 3)])
    faces["n"], faces["i"] = 3, F
    props = (
        "property double x\nproperty float nx\nproperty double y\nproperty double z\n"
        "property uchar red\n"
    )
    data = _ply(
        props, rows.tobytes(), faces.tobytes(), 4, 2, flist="list uchar uint vertex_indices"
    )
    V, F2 = binary_ply_arrays(data)
    np.testing.assert_array_equal(V, P)  # doubles kept to the bit
    np.testing.assert_array_equal(F2, F)


@pytest.mark.parametrize(
    "case", ["ascii", "big_endian", "quad", "other_element", "truncated", "out_of_range", "not_ply"]
)
def test_other_layouts_fall_back(case):
    V = np.zeros(4, dtype=[("x", "<f4"), ("y", "<f4"), ("z", "<f4")])
    props = "property float x\nproperty float y\nproperty float z\n"
    tri = np.zeros(2, dtype=[("n", "u1"), ("i", "<i4", 3)])
    tri["n"], tri["i"] = 3, [[0, 1, 2], [0, 2, 3]]
    kw = {}
    faces = tri.tobytes()
    if case == "ascii":
        kw["fmt"] = "ascii"
    elif case == "big_endian":
        kw["fmt"] = "binary_big_endian"
    elif case == "quad":
        quad = np.zeros(2, dtype=[("n", "u1"), ("i", "<i4", 4)])
        quad["n"], quad["i"] = 4, [[0, 1, 2, 3]] * 2
        faces = quad.tobytes()
    elif case == "other_element":
        kw["extra"] = "element edge 0\nproperty int vertex1\n"
    elif case == "truncated":
        faces = faces[:-1]
    elif case == "out_of_range":
        tri["i"][1, 2] = 4
        faces = tri.tobytes()
    data = _ply(props, V.tobytes(), faces, 4, 2, **kw)
    if case == "not_ply":
        data = b"solid x\n" + data
    assert binary_ply_arrays(data) is None


def test_read_mesh_takes_either_path(tmp_path):
    mesh = _box()
    path = tmp_path / "box.ply"
    path.write_bytes(mesh.export(file_type="ply"))
    V, F = read_mesh(path)  # fast path
    np.testing.assert_allclose(V, mesh.vertices, atol=1e-7)  # float32 file
    np.testing.assert_array_equal(F, mesh.faces)
    # a quad file: binary_ply_arrays declines, trimesh fan-triangulates it
    quad = np.zeros(1, dtype=[("n", "u1"), ("i", "<i4", 4)])
    quad["n"], quad["i"] = 4, [0, 1, 2, 3]
    pts = np.zeros(4, dtype=[("x", "<f4"), ("y", "<f4"), ("z", "<f4")])
    pts["x"], pts["y"] = [0, 1, 1, 0], [0, 0, 1, 1]
    props = "property float x\nproperty float y\nproperty float z\n"
    path.write_bytes(_ply(props, pts.tobytes(), quad.tobytes(), 4, 1))
    V, F = read_mesh(path)
    assert F.shape == (2, 3) and len(V) == 4
