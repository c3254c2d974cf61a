"""Property-based fuzzing of every loader: valid files made in code, mutated by hypothesis.

Each loader gets a few seed files (valid, small) and reads byte-level mutations of them
(truncations, flipped bytes, inserted and deleted runs, repeated runs, numbers swapped for
``nan``/``1e309``/huge integers in text formats) and, for ``.npz`` files, array-level ones
(a key dropped, an array replaced by one of another shape or dtype, NaN). The property: the
loader either returns a well-formed result (finite numbers, indices in range) or raises one
of meshmocap's own errors (:class:`~meshmocap.errors.MeshmocapError`) — anything else (a
``KeyError``, ``zipfile.BadZipFile``, a NumPy warning turned error, a ``MemoryError``) is a
defect. Used by ``tests/io/test_fuzz_loaders.py`` (a few hundred examples) and by
``benchmarks/bench_fuzz.py`` (≥ 10,000).
"""

from __future__ import annotations

import io
import json
import shutil
import tarfile
import tempfile
import warnings
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from hypothesis import strategies as st

from meshmocap.errors import MeshmocapError, MeshmocapWarning

_NUMBERS = [
    b"nan",
    b"inf",
    b"-inf",
    b"1e309",
    b"-1e309",
    b"99999999999999999999",
    b"-1",
    b"0",
    b"1e-320",
    b"abc",
    b"",
    b"3.5.6",
    b"0x10",
    b"7",
    b"0.25",
    b"-2.5",
    b"1e3",
    b"12",
    b"1",
]


@st.composite
def mutated(draw, seeds: list[bytes], text: bool = False) -> bytes:
    """One mutation of one of ``seeds`` (1 to 4 edits)."""
    data = bytearray(draw(st.sampled_from(seeds)))
    for _ in range(draw(st.integers(1, 4))):
        n = len(data)
        kind = draw(
            st.sampled_from(
                ["truncate", "flip", "insert", "delete", "repeat", "number", "random"]
                if text
                else ["truncate", "flip", "insert", "delete", "repeat", "random"]
            )
        )
        at = draw(st.integers(0, max(n - 1, 0)))
        if kind == "truncate":
            del data[at:]
        elif kind == "flip" and n:
            for k in draw(st.lists(st.integers(0, n - 1), min_size=1, max_size=8)):
                data[k] = draw(st.integers(0, 255))
        elif kind == "insert":
            data[at:at] = draw(st.binary(min_size=1, max_size=32))
        elif kind == "delete":
            del data[at : at + draw(st.integers(1, 64))]
        elif kind == "repeat":
            span = data[at : at + draw(st.integers(1, 64))]
            data[at:at] = span * draw(st.integers(1, 4))
        elif kind == "number" and n:
            tokens = [m for m in range(n) if chr(data[m]).isdigit()]
            if tokens:
                k = draw(st.sampled_from(tokens))
                end = k
                while end < n and (chr(data[end]).isdigit() or data[end] in b".eE-+"):
                    end += 1
                data[k:end] = draw(st.sampled_from(_NUMBERS))
        elif kind == "random":
            data = bytearray(draw(st.binary(max_size=256)))
    return bytes(data)


@st.composite
def npz_mutated(draw, seeds: list[dict[str, np.ndarray]]) -> bytes:
    """An ``.npz`` of one of ``seeds`` with array-level edits, or its bytes mutated."""
    if draw(st.booleans()):
        arrays = dict(draw(st.sampled_from(seeds)))
        for _ in range(draw(st.integers(1, 3))):
            key = draw(st.sampled_from(sorted(arrays)))
            kind = draw(st.sampled_from(["drop", "shape", "dtype", "nan", "scalar", "string"]))
            a = arrays[key]
            if kind == "drop":
                del arrays[key]
            elif kind == "shape":
                shape = tuple(draw(st.lists(st.integers(0, 5), max_size=3)))
                arrays[key] = np.zeros(shape, dtype=a.dtype if a.dtype.kind != "U" else float)
            elif kind == "dtype":
                dt = draw(st.sampled_from(["f4", "i1", "u8", "c16", "?", "U3"]))
                arrays[key] = np.zeros(a.shape, dtype=dt)
            elif kind == "nan" and a.dtype.kind == "f" and a.size:
                b = a.copy()
                b.flat[draw(st.integers(0, a.size - 1))] = np.nan
                arrays[key] = b
            elif kind == "scalar":
                arrays[key] = np.array(draw(st.sampled_from([-1, 0, 2**40, 1e300, -0.5])))
            elif kind == "string":
                arrays[key] = np.array(draw(st.text(max_size=8)))
            if not arrays:
                break
        buf = io.BytesIO()
        np.savez_compressed(buf, **arrays)
        return buf.getvalue()
    buf = io.BytesIO()
    np.savez_compressed(buf, **draw(st.sampled_from(seeds)))
    return draw(mutated([buf.getvalue()]))


def _finite(*arrays) -> None:
    for a in arrays:
        if a is not None:
            a = np.asarray(a)
            assert a.dtype.kind in "fiub", f"non-numeric output ({a.dtype})"
            assert np.all(np.isfinite(a)), "non-finite output"


def _points_ok(out) -> None:
    P, N = out
    assert P.ndim == 2 and P.shape[1] == 3 and len(P), "bad P"
    assert N is None or N.shape == P.shape, "normals do not match the points"
    _finite(P, N)


def _mesh_ok(out) -> None:
    V, F = out
    assert V.ndim == 2 and V.shape[1] == 3 and len(V), "bad V"
    _finite(V)
    if F is not None:
        assert F.ndim == 2 and F.shape[1] == 3, "bad F"
        assert len(F) == 0 or (F.min() >= 0 and F.max() < len(V)), "face index out of range"


@dataclass
class Loader:
    """A loader under test: seed files, how to mutate them, how to read and check one."""

    name: str
    suffix: str
    strategy: st.SearchStrategy
    read: Callable[[Path], object]
    check: Callable[[object], None] = lambda out: None


class Defect(AssertionError):
    """A loader raised something other than a meshmocap error, or returned garbage."""


def run_one(loader: Loader, data: bytes, workdir: Path) -> str:
    """Write ``data`` to a file of ``loader``'s kind in ``workdir`` and read it.

    Returns ``"ok"`` or ``"error"`` (a meshmocap error); raises :class:`Defect` otherwise.
    """
    target = workdir / f"{loader.name}{loader.suffix}"
    if target.is_dir():
        shutil.rmtree(target)
    target.write_bytes(data)
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("error")  # a stray NumPy/Pillow warning is a defect too
            warnings.simplefilter("ignore", MeshmocapWarning)
            out = loader.read(target)
            loader.check(out)
    except MeshmocapError as exc:
        text = str(exc)
        if "\n" in text or not text:
            raise Defect(f"{loader.name}: error message is not one line: {text!r}") from exc
        return "error"
    except AssertionError as exc:
        raise Defect(f"{loader.name}: returned garbage ({exc})") from exc
    except Exception as exc:
        raise Defect(f"{loader.name}: {type(exc).__name__}: {str(exc)[:200]}") from exc
    return "ok"


# --------------------------------------------------------------------------- seeds


def _seed_meshes() -> dict[str, list[bytes]]:
    import trimesh

    from meshmocap.io.meshes import write_mesh

    V = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1.0]])
    F = np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]])
    out: dict[str, list[bytes]] = {}
    with tempfile.TemporaryDirectory() as d:
        for ext in (".ply", ".obj", ".off", ".stl", ".glb"):
            out[ext] = [write_mesh(Path(d) / f"m{ext}", V, F).read_bytes()]
    mesh = trimesh.Trimesh(V, F, process=False)
    out[".ply"].append(trimesh.exchange.ply.export_ply(mesh, encoding="ascii"))
    out[".stl"].append(trimesh.exchange.stl.export_stl_ascii(mesh).encode())
    out[".obj"].append(
        b"v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nvt 0 0\nf 1/1 3/1 2/1\nf 1 2 4\nf 1 4 3\nf 2 3 4\n"
    )
    gltf = trimesh.exchange.gltf.export_gltf(mesh, embed_buffers=True)
    out[".gltf"] = [next(v for k, v in gltf.items() if k.endswith(".gltf"))]
    return out


def _seed_points() -> dict[str, list[bytes]]:
    rng = np.random.default_rng(0)
    P = rng.normal(size=(12, 3))
    N = P / np.linalg.norm(P, axis=1, keepdims=True)
    buf = io.BytesIO()
    np.save(buf, np.hstack([P, N]))
    ply = (
        "ply\nformat ascii 1.0\nelement vertex 12\nproperty float x\nproperty float y\n"
        "property float z\nproperty float nx\nproperty float ny\nproperty float nz\n"
        "end_header\n" + "".join(" ".join(f"{x:.4f}" for x in r) + "\n" for r in np.hstack([P, N]))
    ).encode()
    xyz = "".join(" ".join(f"{x:.5f}" for x in r) + "\n" for r in P).encode()
    pcd = (
        b"VERSION .7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\nWIDTH 12\nHEIGHT 1\n"
        b"POINTS 12\nDATA ascii\n"
    ) + xyz
    return {".npy": [buf.getvalue()], ".ply": [ply], ".xyz": [xyz], ".pcd": [pcd]}


def _tar(members: dict[str, bytes], gz: bool) -> bytes:
    buf = io.BytesIO()
    with tarfile.open(fileobj=buf, mode="w:gz" if gz else "w") as tf:
        for name, data in members.items():
            info = tarfile.TarInfo(name)
            info.size = len(data)
            tf.addfile(info, io.BytesIO(data))
    return buf.getvalue()


def _tiny_bvh() -> bytes:
    from toys import TINY_BVH as TINY

    return TINY.encode()


def _tiny_asf_amc() -> tuple[bytes, bytes]:
    from toys import TINY_AMC as AMC
    from toys import TINY_ASF as ASF

    return ASF.encode(), AMC.encode()


def _cameras() -> tuple[bytes, bytes]:
    from meshmocap.io.cameras import write_cameras
    from meshmocap.studio.rigs import camera_rig

    cams = camera_rig("humaneva4")[:2]
    with tempfile.TemporaryDirectory() as d:
        write_cameras(Path(d) / "c.json", cams)
        write_cameras(Path(d) / "c.yml", cams)
        return (Path(d) / "c.json").read_bytes(), (Path(d) / "c.yml").read_bytes()


def _masks() -> list[bytes]:
    from PIL import Image

    m = np.zeros((12, 16), dtype=np.uint8)
    m[3:9, 4:12] = 255
    out = []
    for mode in ("1", "L", "RGBA"):
        buf = io.BytesIO()
        img = Image.fromarray(m, "L").convert(mode)
        img.save(buf, format="PNG")
        out.append(buf.getvalue())
    return out


def _template_arrays() -> dict[str, np.ndarray]:
    from meshmocap.body.template import load_template, save_template

    with tempfile.TemporaryDirectory() as d:
        path = save_template(Path(d) / "t.npz", load_template("neutral_5k"))
        with np.load(path, allow_pickle=False) as z:
            return {k: z[k] for k in z.files}


# --------------------------------------------------------------------------- loaders


def loaders(workdir: Path) -> list[Loader]:
    """Every loader under test (seeds made in code; ``workdir`` holds helper files)."""
    from meshmocap.body.template import load_template
    from meshmocap.io.asf_amc import read_amc, read_asf
    from meshmocap.io.bvh import read_bvh
    from meshmocap.io.cameras import read_cameras
    from meshmocap.io.meshes import MeshSequence, read_mesh, read_points
    from meshmocap.io.silhouettes import read_mask

    meshes, points = _seed_meshes(), _seed_points()
    asf_text, amc_text = _tiny_asf_amc()
    (workdir / "ref.asf").write_bytes(asf_text)
    json_cams, yaml_cams = _cameras()
    out = [
        Loader(
            f"mesh_{ext[1:]}",
            ext,
            mutated(seeds, text=ext in (".obj", ".off", ".gltf")),
            read_mesh,
            _mesh_ok,
        )
        for ext, seeds in meshes.items()
    ]
    out += [
        Loader(
            f"points_{ext[1:]}", ext, mutated(seeds, text=ext != ".npy"), read_points, _points_ok
        )
        for ext, seeds in points.items()
    ]
    frames = {f"f/{k:03d}.ply": meshes[".ply"][k % 2] for k in range(3)}
    out.append(
        Loader(
            "archive_tar_gz",
            ".tar.gz",
            mutated([_tar(frames, True), _tar(frames, False)]),
            lambda p: [(f.V, f.F) for f in MeshSequence(p)],
            lambda out: [_mesh_ok(m) for m in out],
        )
    )
    out.append(
        Loader(
            "bvh",
            ".bvh",
            mutated([_tiny_bvh()], text=True),
            read_bvh,
            lambda m: _finite(m.rotations, m.root_positions),
        )
    )
    out.append(
        Loader(
            "asf",
            ".asf",
            mutated([asf_text], text=True),
            read_asf,
            lambda a: _finite(a.skeleton.offsets, a.axes),
        )
    )
    out.append(
        Loader(
            "amc",
            ".amc",
            mutated([amc_text], text=True),
            lambda p: read_amc(p, read_asf(workdir / "ref.asf")),
            lambda m: _finite(m.rotations, m.root_positions),
        )
    )
    cams_ok = lambda cams: [_finite(c.K, c.R, c.t, c.dist) for c in cams]  # noqa: E731
    out.append(
        Loader("cameras_json", ".json", mutated([json_cams], text=True), read_cameras, cams_ok)
    )
    out.append(
        Loader("cameras_yaml", ".yml", mutated([yaml_cams], text=True), read_cameras, cams_ok)
    )
    out.append(
        Loader(
            "silhouette_png",
            ".png",
            mutated(_masks()),
            read_mask,
            lambda m: None if m.dtype == bool and m.ndim == 2 else _bad("mask"),
        )
    )
    out.append(
        Loader(
            "template_npz",
            ".npz",
            npz_mutated([_template_arrays()]),
            load_template,
            lambda t: _finite(t.V, t.skeleton.offsets),
        )
    )
    out += _result_loaders(workdir)
    return out


def _arrays(path: Path) -> dict[str, np.ndarray]:
    with np.load(path, allow_pickle=False) as z:
        return {k: z[k] for k in z.files}


def _bad(what: str) -> None:
    raise AssertionError(f"bad {what}")


def _result_loaders(workdir: Path) -> list[Loader]:
    """Track folders, capture frames and pose manifolds: one file of a valid folder mutated."""
    from meshmocap.geometry.carving import VoxelHull
    from meshmocap.io.capture import Capture, Truth, write_hull, write_truth
    from meshmocap.io.results import FrameResult, read_track, start_track, write_frame

    F = np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]])
    V = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1.0]])
    track = workdir / "track_seed"
    start_track(track, {"method": "x", "eval_names": ["a", "b"], "eval_parents": [-1, 0]}, F)
    for i in range(2):
        write_frame(
            track,
            FrameResult(i, V[:2] + i, V + i, {"data": 1.0}, 3, 0.1, state={"pose": np.eye(3)}),
        )
    frame_seed = (track / "frames" / "00001.npz").read_bytes()
    with np.load(track / "frames" / "00001.npz") as z:
        frame_arrays = {k: z[k] for k in z.files}
    json_seed = (track / "track.json").read_bytes()

    def read_track_with(part: str) -> Callable[[Path], object]:
        def read(p: Path):
            folder = workdir / "track_fuzz"
            if folder.exists():
                shutil.rmtree(folder)
            shutil.copytree(track, folder)
            (folder / part).write_bytes(p.read_bytes())
            return read_track(folder)

        return read

    def track_ok(t) -> None:
        _finite(t.joints, t.vertices)
        assert t.faces.min() >= 0 and t.faces.max() < t.vertices.shape[1], "faces out of range"

    occ = np.zeros((6, 6, 6), dtype=bool)
    occ[1:5, 1:5, 1:5] = True
    hull = VoxelHull(occ, np.zeros(3), 0.01)
    cap = workdir / "capture_seed"
    (cap / "hulls").mkdir(parents=True)
    (cap / "truth").mkdir()
    write_hull(cap / "hulls" / "00000.npz", hull)
    write_truth(
        cap / "truth" / "00000.npz", Truth(V, V[:2], np.tile(np.eye(3), (2, 1, 1)), np.zeros(3))
    )
    (cap / "capture.json").write_text(
        json.dumps({"format": "meshmocap-capture-1", "fps": 30, "frames": [0]})
    )
    hull_arrays = _arrays(cap / "hulls" / "00000.npz")

    def read_capture_with(part: str) -> Callable[[Path], object]:
        def read(p: Path):
            folder = workdir / "capture_fuzz"
            if folder.exists():
                shutil.rmtree(folder)
            shutil.copytree(cap, folder)
            (folder / part).write_bytes(p.read_bytes())
            c = Capture(folder)
            fr = c[0]
            return c.fps, fr.missing, fr.hull_mesh, fr.hull, fr.truth

        return read

    def capture_ok(out) -> None:
        fps, _missing, mesh, hull, truth = out
        assert fps > 0 and np.isfinite(fps)
        _mesh_ok(mesh)
        _finite(hull.origin, truth.vertices)

    return [
        Loader(
            "track_frame_npz",
            ".npz",
            npz_mutated([frame_arrays]),
            read_track_with("frames/00001.npz"),
            track_ok,
        ),
        Loader(
            "track_frame_bytes",
            ".npz",
            mutated([frame_seed]),
            read_track_with("frames/00001.npz"),
            track_ok,
        ),
        Loader(
            "track_json",
            ".json",
            mutated([json_seed], text=True),
            read_track_with("track.json"),
            track_ok,
        ),
        Loader(
            "capture_hull_npz",
            ".npz",
            npz_mutated([hull_arrays]),
            read_capture_with("hulls/00000.npz"),
            capture_ok,
        ),
        Loader(
            "capture_truth_npz",
            ".npz",
            npz_mutated([_arrays(cap / "truth" / "00000.npz")]),
            read_capture_with("truth/00000.npz"),
            capture_ok,
        ),
        Loader(
            "capture_json",
            ".json",
            mutated([(cap / "capture.json").read_bytes()], text=True),
            read_capture_with("capture.json"),
            capture_ok,
        ),
    ]


def manifold_loader(path: Path) -> Loader:
    """The pose-manifold loader, seeded with the manifold file at ``path`` (slow to make)."""
    from meshmocap.trackers.cage.manifold import PoseManifold

    with np.load(path, allow_pickle=False) as z:
        arrays = {k: z[k] for k in z.files}
    return Loader(
        "manifold_npz",
        ".npz",
        npz_mutated([arrays]),
        PoseManifold.load,
        lambda pm: _finite(pm.gp.X_, pm.gp.Y_),
    )
