"""The malformed-input corpus of every loader, called directly: each file (made on the fly)
raises the exact meshmocap error, in one line naming the file."""

from __future__ import annotations

import io
from pathlib import Path

import numpy as np
import pytest

from meshmocap.errors import FormatError, InputError, MeshError, MeshmocapFileNotFoundError


def _read_mesh(p):
    from meshmocap.io.meshes import read_mesh

    return read_mesh(p)


def _read_points(p):
    from meshmocap.io.meshes import read_points

    return read_points(p)


def _sequence(p):
    from meshmocap.io.meshes import MeshSequence

    return [f.V for f in MeshSequence(p)]


def _bvh(p):
    from meshmocap.io.bvh import read_bvh

    return read_bvh(p)


def _asf(p):
    from meshmocap.io.asf_amc import read_asf

    return read_asf(p)


def _cameras(p):
    from meshmocap.io.cameras import read_cameras

    return read_cameras(p)


def _mask(p):
    from meshmocap.io.silhouettes import read_mask

    return read_mask(p)


def _npy(a) -> bytes:
    buf = io.BytesIO()
    np.save(buf, a)
    return buf.getvalue()


def _tar_gz(members: dict[str, bytes], cut: int | None = None) -> bytes:
    import tarfile

    buf = io.BytesIO()
    with tarfile.open(fileobj=buf, mode="w:gz") as tf:
        for name, data in members.items():
            info = tarfile.TarInfo(name)
            info.size = len(data)
            tf.addfile(info, io.BytesIO(data))
    data = buf.getvalue()
    return data[:cut] if cut else data


_PLY_HEAD = b"ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n"
_PLY_HEAD += (
    b"property float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n"
)
_PNG = b"\x89PNG\r\n\x1a\n"

#: (id, reader, file name, bytes, error class, message after the file name)
CASES = [
    ("ply_empty", _read_mesh, "m.ply", b"", MeshError, "cannot read PLY file"),
    ("ply_garbage", _read_mesh, "m.ply", b"\x00\x01\x02garbage", MeshError, "cannot read PLY file"),
    (
        "ply_nan",
        _read_mesh,
        "m.ply",
        _PLY_HEAD + b"nan 0 0\n1 0 0\n0 1 0\n3 0 1 2\n",
        MeshError,
        "1 vertex is NaN or infinite (first: vertex 1 of the file)",
    ),
    (
        "ply_face_range",
        _read_mesh,
        "m.ply",
        _PLY_HEAD + b"0 0 0\n1 0 0\n0 1 0\n3 0 1 7\n",
        MeshError,
        "",
    ),
    (
        "ply_bomb",
        _read_mesh,
        "m.ply",
        _PLY_HEAD.replace(b"vertex 3", b"vertex 4000000000"),
        MeshError,
        "header declares 4000000000 elements in a file of",
    ),
    (
        "ply_points_as_mesh",
        _read_mesh,
        "m.ply",
        b"ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\n"
        b"property float y\nproperty float z\nend_header\n0 0 0\n",
        MeshError,
        "no triangles",
    ),
    ("obj_empty", _read_mesh, "m.obj", b"", MeshError, ""),
    ("obj_no_faces", _read_mesh, "m.obj", b"v 0 0 0\nv 1 0 0\n", MeshError, "no triangles"),
    ("obj_bad_number", _read_mesh, "m.obj", b"v 0 0 x\nv 1 0 0\nv 0 1 0\nf 1 2 3\n", MeshError, ""),
    (
        "obj_inf",
        _read_mesh,
        "m.obj",
        b"# made by hand\nv 0 0 0\nv 1 0 1e999\nv 0 1 0\nf 1 2 3\n",
        MeshError,
        "1 vertex is NaN or infinite (first: vertex 2 of the file, line 3)",
    ),
    ("off_header", _read_mesh, "m.off", b"OFF\n3 1 0\n0 0 0\n", MeshError, ""),
    (
        "off_bomb",
        _read_mesh,
        "m.off",
        b"OFF\n999999999999 1 0\n0 0 0\n",
        MeshError,
        "header declares 999999999999",
    ),
    ("stl_garbage", _read_mesh, "m.stl", b"solid x\nfacet normal 0 0\n", MeshError, ""),
    (
        "glb_garbage",
        _read_mesh,
        "m.glb",
        b"glTF\x02\x00\x00\x00junk",
        MeshError,
        "cannot read GLB file",
    ),
    (
        "gltf_json",
        _read_mesh,
        "m.gltf",
        b'{"asset": {"version": "2.0"}, "meshes": [{}]}',
        MeshError,
        "",
    ),
    ("mesh_extension", _read_mesh, "m.fbx", b"x", InputError, "mesh files must end in"),
    ("mesh_missing", _read_mesh, None, b"", MeshmocapFileNotFoundError, "no such file"),
    (
        "npy_shape",
        _read_points,
        "p.npy",
        _npy(np.zeros((4, 2))),
        FormatError,
        "expected (n, 3) or (n, 6) numbers, found (4, 2)",
    ),
    (
        "npy_object",
        _read_points,
        "p.npy",
        _npy(np.array([None, 1], dtype=object)),
        FormatError,
        "not a readable .npy array",
    ),
    (
        "npy_nan",
        _read_points,
        "p.npy",
        _npy(np.array([[0, 0, np.nan]])),
        MeshError,
        "1 point is NaN or infinite (first: point 1 of the file)",
    ),
    (
        "npy_header",
        _read_points,
        "p.npy",
        b"\x93NUMPY\x01\x00v\x00{'descr': '<f8', 'fortran_order': False, 'shape': (",
        FormatError,
        "not a readable .npy array",
    ),
    (
        "npy_empty",
        _read_points,
        "p.npy",
        _npy(np.zeros((0, 3))),
        MeshError,
        "empty point cloud (0 points)",
    ),
    ("xyz_text", _read_points, "p.xyz", b"0 0 0\n1 one 2\n", FormatError, "not a table of numbers"),
    (
        "xyz_columns",
        _read_points,
        "p.xyz",
        b"0 0\n1 2\n",
        FormatError,
        "expected (n, 3) or (n, 6) numbers, found (2, 2)",
    ),
    (
        "pcd_binary",
        _read_points,
        "p.pcd",
        b"FIELDS x y z\nDATA binary\n\x00\x01",
        FormatError,
        "only ASCII PCD is supported, found DATA 'binary'",
    ),
    (
        "pcd_fields",
        _read_points,
        "p.pcd",
        b"FIELDS a b c\nDATA ascii\n1 2 3\n",
        FormatError,
        "PCD FIELDS must start with x y z",
    ),
    (
        "archive_truncated",
        _sequence,
        "a.tar.gz",
        _tar_gz({"f/0.xyz": b"0 0 0\n" * 200}, cut=60),
        FormatError,
        "",
    ),
    (
        "archive_not_gzip",
        _sequence,
        "a.tar.gz",
        b"plain text",
        FormatError,
        "not a readable tar archive",
    ),
    (
        "archive_empty",
        _sequence,
        "a.tar.gz",
        _tar_gz({"readme.txt": b"x"}),
        MeshmocapFileNotFoundError,
        "archive holds no frame files",
    ),
    ("bvh_empty", _bvh, "c.bvh", b"", FormatError, ""),
    (
        "bvh_no_motion",
        _bvh,
        "c.bvh",
        b"HIERARCHY\nROOT a\n{\n OFFSET 0 0 0\n CHANNELS 3 Xposition Yposition Zposition\n}\n",
        FormatError,
        "",
    ),
    (
        "bvh_values",
        _bvh,
        "c.bvh",
        b"HIERARCHY\nROOT a\n{\n OFFSET 0 0 0\n CHANNELS 3 Xposition Yposition Zposition\n"
        b" End Site\n {\n OFFSET 0 1 0\n }\n}\nMOTION\nFrames: 1\nFrame Time: 0.1\n0 0 nan\n",
        FormatError,
        "non-finite value 'nan'",
    ),
    ("asf_empty", _asf, "s.asf", b"", FormatError, ""),
    (
        "asf_units",
        _asf,
        "s.asf",
        b":units\n  length -1\n:root\n:bonedata\n:hierarchy\n",
        FormatError,
        "length unit must be positive",
    ),
    ("cameras_json", _cameras, "c.json", b'{"cameras": [{"K": 1}]}', FormatError, ""),
    ("cameras_json_syntax", _cameras, "c.json", b"{", FormatError, ""),
    ("cameras_yaml", _cameras, "c.yml", b"%YAML:1.0\nK_C1: [1, 2\n", FormatError, ""),
    ("cameras_empty", _cameras, "c.json", b"[]", FormatError, ""),
    (
        "mask_text",
        _mask,
        "m.png",
        b"not an image",
        FormatError,
        "not a readable image, expected a PNG mask",
    ),
    ("mask_truncated", _mask, "m.png", _PNG + b"\x00\x00\x00\rIHDR\x00\x00", FormatError, ""),
    ("mask_folder", _mask, "", b"", MeshmocapFileNotFoundError, "is a folder, not a file"),
]


@pytest.mark.parametrize(
    ("name", "read", "file", "data", "error", "message"), CASES, ids=[c[0] for c in CASES]
)
def test_malformed_files_raise_one_line_errors(tmp_path, name, read, file, data, error, message):
    if file is None:
        path = tmp_path / "absent.ply"
    elif file == "":
        path = tmp_path
    else:
        path = tmp_path / file
        path.write_bytes(data)
    with pytest.raises(error) as info:
        read(path)
    text = str(info.value)
    assert "\n" not in text and str(path) in text, text
    assert message in text, text


def test_the_corpus_covers_every_loader():
    readers = {c[1] for c in CASES}
    assert readers == {_read_mesh, _read_points, _sequence, _bvh, _asf, _cameras, _mask}
    exts = {Path(c[2]).suffix for c in CASES if c[2]}
    assert {
        ".ply",
        ".obj",
        ".off",
        ".stl",
        ".glb",
        ".gltf",
        ".npy",
        ".xyz",
        ".pcd",
        ".gz",
        ".bvh",
        ".asf",
        ".json",
        ".yml",
        ".png",
    } <= exts
