"""A malformed-input corpus against every command, run in-process: each case ends in one line
``meshmocap: error: ...`` naming the flag or file and what was expected (status 2), never a
traceback, a hang or a silent success. Inputs are made on the fly in ``tmp_path``."""

from __future__ import annotations

import io
import json
import shutil
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest

from meshmocap.cli import main


@pytest.fixture(autouse=True)
def _quiet_progress(monkeypatch):
    """No progress or phase lines on stderr, however slow a loaded machine runs: the
    messages checked here are exact."""
    monkeypatch.setenv("MESHMOCAP_PROGRESS_SECONDS", "3600")
    monkeypatch.setattr("meshmocap._progress.PHASE_SECONDS", 3600.0)


# ----------------------------------------------------------------------------- fixtures


@pytest.fixture(scope="module")
def cap(synth_capture) -> Path:
    """A 3-frame synthetic walk (neutral_5k, 30 fps, 2 cm voxels), the session's."""
    return synth_capture("walk", stop=3, fps=30.0, voxel_size=0.02).path


def _bytes(path: Path, data: bytes) -> str:
    path.write_bytes(data)
    return str(path)


def _npz(path: Path, **arrays) -> str:
    buf = io.BytesIO()
    np.savez(buf, **arrays)
    return _bytes(path, buf.getvalue())


def _template_file(tmp: Path, how: str) -> str:
    from importlib import resources

    src = (resources.files("meshmocap.body") / "data" / "neutral_5k.npz").read_bytes()
    if how == "random":
        return _bytes(
            tmp / "t.npz", bytes(np.random.default_rng(0).integers(0, 256, 300, np.uint8))
        )
    if how == "truncated":
        return _bytes(tmp / "t.npz", src[: len(src) // 2])
    if how == "flipped":
        b = bytearray(src)
        b[len(b) // 3] ^= 0xFF
        return _bytes(tmp / "t.npz", bytes(b))
    if how == "no_key":
        with np.load(io.BytesIO(src)) as z:
            d = {k: z[k] for k in z.files if k != "weights_data"}
        return _npz(tmp / "t.npz", **d)
    if how == "other_format":
        return _npz(tmp / "t.npz", format=np.str_("something-else"))
    return _bytes(tmp / "t.npz", b"")  # empty


def _manifold_file(tmp: Path, how: str) -> str:
    if how == "random":
        return _bytes(tmp / "m.npz", b"PK\x03\x04" + bytes(200))
    if how == "npz_not_gplvm":
        return _npz(tmp / "m.npz", kind=np.str_("other"))
    return _bytes(tmp / "m.npz", b"")


def _silhouette_only(tmp: Path, cap: Path) -> str:
    out = tmp / "sil"
    shutil.copytree(cap, out, ignore=shutil.ignore_patterns("hulls", "truth", "capture.json"))
    return str(out)


def _hull_layout(tmp: Path, cap: Path, how: str) -> str:
    out = tmp / "real"
    shutil.copytree(cap, out, ignore=shutil.ignore_patterns("hulls", "truth", "capture.json"))
    cams = json.loads((out / "cameras.json").read_text())
    if how == "two_cameras":
        cams["cameras"] = cams["cameras"][:2]
        (out / "cameras.json").write_text(json.dumps(cams))
    elif how == "no_cameras":
        (out / "cameras.json").unlink()
    elif how == "bad_json":
        (out / "cameras.json").write_text('{"cameras": [')
    elif how == "lost_folder":
        shutil.rmtree(out / "silhouettes" / "C2")
    elif how == "corrupt_png":
        (out / "silhouettes" / "C1" / "00001.png").write_bytes(b"\x89PNG\r\n\x1a\nxx")
    elif how == "small_png":
        from meshmocap.io.silhouettes import write_mask

        write_mask(out / "silhouettes" / "C1" / "00001.png", np.ones((10, 10), bool))
    elif how == "no_masks":
        for p in (out / "silhouettes").rglob("*.png"):
            p.unlink()
    return str(out)


def _mesh_folder(tmp: Path, cap: Path, how: str) -> list[str]:
    from meshmocap.io.capture import Capture
    from meshmocap.io.meshes import write_mesh

    out = tmp / "meshes"
    out.mkdir()
    for f in Capture(cap):
        write_mesh(out / f"m_{f.index}.ply", *f.hull_mesh)
    if how == "mixed":
        (out / "m_9.obj").write_text("v 0 0 0\n")
        return [str(out / "m_0.ply"), str(out / "m_9.obj")]
    if how == "empty":
        shutil.rmtree(out)
        out.mkdir()
        (out / "notes.txt").write_text("hello")
    return [str(out)]


def _locked(tmp: Path, cap: Path) -> str:
    import fcntl
    import os

    out = tmp / "busy"
    out.mkdir()
    fd = os.open(out / ".meshmocap.lock", os.O_RDWR | os.O_CREAT)
    os.write(fd, b"4242\n")
    fcntl.flock(fd, fcntl.LOCK_EX)  # held by this test's open file (another description)
    _LOCKS.append(fd)
    return str(out)


_LOCKS: list[int] = []


def _other_settings(tmp: Path, cap: Path) -> str:
    out = tmp / "t"
    assert (
        main(
            [
                "track",
                str(cap),
                "--method",
                "articulated_icp",
                "--max-iter",
                "1",
                "--frames",
                "0:2",
                "--init",
                "truth",  # the start is not what is refused: no search for it
                "--out",
                str(out),
            ]
        )
        == 0
    )
    return str(out)


def _synth_other(tmp: Path, cap: Path) -> str:
    out = tmp / "s"
    shutil.copytree(cap, out)
    return str(out)


def _bad_bvh(tmp: Path) -> str:
    return _bytes(tmp / "bad.bvh", b"HIERARCHY\nROOT a\n{\n OFFSET 0 0 0\n")


def _amc_without_asf(tmp: Path) -> str:
    (tmp / "lone").mkdir()
    return _bytes(tmp / "lone" / "01_01.amc", b":FULLY-SPECIFIED\n:DEGREES\n1\nroot 0 0 0 0 0 0\n")


def _track_with(tmp: Path, cap: Path, how: str) -> str:
    out = tmp / "t"
    argv = ["track", str(cap), "--method", "articulated_icp", "--max-iter", "1"]
    # the start is not what is refused: no search for it
    assert main([*argv, "--init", "truth", "--out", str(out)]) == 0
    if how == "corrupt_frame":
        (out / "frames" / "00001.npz").write_bytes(b"PK\x03\x04garbage")
    elif how == "nan_frame":
        with np.load(out / "frames" / "00001.npz") as z:
            d = {k: z[k] for k in z.files}
        d["joints"][0, 0] = np.nan
        _npz(out / "frames" / "00001.npz", **d)
    elif how == "no_faces":
        (out / "faces.npy").unlink()
    elif how == "bad_json":
        (out / "track.json").write_text("{")
    elif how == "foreign_frame":
        shutil.copy(out / "frames" / "00001.npz", out / "frames" / "00099.npz")
    return str(out)


# ----------------------------------------------------------------------------- the corpus

Case = tuple[str, Callable[[Path, Path], list[str]], str]
C = "CAP"  # replaced by the capture folder


def _args(*argv: str) -> Callable[[Path, Path], list[str]]:
    return lambda tmp, cap: [str(cap) if a == C else a.replace("TMP", str(tmp)) for a in argv]


#: Flags with a valid range: (command and arguments, flag value, expected message)
RANGES: list[tuple[list[str], str]] = [
    (
        ["synth", "TMP/s", "--jitter", "1e9"],
        "argument --jitter: expected a number from 0 to 20 (pixels), found '1e9'",
    ),
    (["synth", "TMP/s", "--jitter", "-1"], "argument --jitter: expected a number from 0 to 20"),
    (["synth", "TMP/s", "--jitter", "nan"], "argument --jitter: expected a number from 0 to 20"),
    (["synth", "TMP/s", "--fps", "0"], "argument --fps: expected a number above 0 up to 1000"),
    (["synth", "TMP/s", "--fps", "1e9"], "argument --fps: expected a number above 0 up to 1000"),
    (
        ["synth", "TMP/s", "--voxel-size", "0"],
        "argument --voxel-size: expected a number from 0.002 to 0.1 (metres)",
    ),
    (
        ["synth", "TMP/s", "--voxel-size", "5"],
        "argument --voxel-size: expected a number from 0.002 to 0.1",
    ),
    (["synth", "TMP/s", "--holes", "-1"], "argument --holes: expected an integer from 0 to 100"),
    (["synth", "TMP/s", "--holes", "1.5"], "argument --holes: expected an integer from 0 to 100"),
    (["synth", "TMP/s", "--blobs", "1000"], "argument --blobs: expected an integer from 0 to 100"),
    (
        ["synth", "TMP/s", "--seed", "-1"],
        "argument --seed: expected an integer from 0 to 4.29497e+09",
    ),
    (["synth", "TMP/s", "--frames", "-3"], "argument --frames: expected frame numbers ≥ 0"),
    (
        ["synth", "TMP/s", "--frames", "5:2"],
        "argument --frames: expected START < STOP, found '5:2'",
    ),
    (["synth", "TMP/s", "--frames", "1:9:0"], "argument --frames: expected STEP ≥ 1"),
    (
        ["synth", "TMP/s", "--frames", "a:b"],
        "argument --frames: expected START:STOP[:STEP] with integers",
    ),
    (["synth", "TMP/s", "--frames", "1:2:3:4"], "argument --frames: expected START:STOP[:STEP]"),
    (
        ["hull", "TMP", "--voxel-size", "0"],
        "argument --voxel-size: expected a number from 0.002 to 0.1",
    ),
    (["hull", "TMP", "--voxel-size", "inf"], "argument --voxel-size: expected a number from 0.002"),
    (
        ["track", C, "--out", "TMP/t", "--max-iter", "0"],
        "argument --max-iter: expected an integer from 1 to 10000",
    ),
    (
        ["track", C, "--out", "TMP/t", "--max-iter", "2.5"],
        "argument --max-iter: expected an integer",
    ),
    (
        ["track", C, "--out", "TMP/t", "--n-patches", "0"],
        "argument --n-patches: expected an integer from 16",
    ),
    (
        ["track", C, "--out", "TMP/t", "--n-patches", "1"],
        "argument --n-patches: expected an integer from 16 to 10000, found '1'",
    ),
    (
        ["track", C, "--out", "TMP/t", "--keep-fraction", "0"],
        "argument --keep-fraction: expected a number above 0 up to 1",
    ),
    (
        ["track", C, "--out", "TMP/t", "--keep-fraction", "1.5"],
        "argument --keep-fraction: expected a number above 0 up to 1",
    ),
    (
        ["track", C, "--out", "TMP/t", "--outlier-sigmas", "-1"],
        "argument --outlier-sigmas: expected a number above 0",
    ),
    (
        ["track", C, "--out", "TMP/t", "--fast-iter-scale", "0.5"],
        "argument --fast-iter-scale: expected a number from 1 to 100",
    ),
    (
        ["track", C, "--out", "TMP/t", "--frames", "-3"],
        "argument --frames: expected frame numbers ≥ 0 (START:STOP[:STEP] or N), found '-3'",
    ),
    (["track", C, "--out", "TMP/t", "--frames", "3:1"], "argument --frames: expected START < STOP"),
    (
        ["eval", C, "TMP/t", "--surface-frames", "-1"],
        "argument --surface-frames: expected an integer from 0 to 10000",
    ),
    (
        ["report", C, "TMP/t", "--out", "TMP/r.html", "--max-frames", "0"],
        "argument --max-frames: expected an integer from 1",
    ),
    (
        ["report", C, "TMP/t", "--out", "TMP/r.html", "--surface-frames", "-2"],
        "argument --surface-frames: expected an integer",
    ),
    (
        ["bench", "--out", "TMP/b", "--max-frames", "0"],
        "argument --max-frames: expected an integer from 1",
    ),
    (
        ["learn", "walk", "--out", "TMP/m.npz", "--latent-dim", "0"],
        "argument --latent-dim: expected an integer from 1 to 20",
    ),
    (
        ["learn", "walk", "--out", "TMP/m.npz", "--samples", "0"],
        "argument --samples: expected an integer from 3 to 100000",
    ),
    (
        ["learn", "walk", "--out", "TMP/m.npz", "--seed", "-1"],
        "argument --seed: expected an integer from 0",
    ),
    (
        ["render", "walk", "--out", "TMP/r", "--width", "0"],
        "argument --width: expected an integer from 16 to 8192 (pixels)",
    ),
    (
        ["render", "walk", "--out", "TMP/r", "--height", "100000"],
        "argument --height: expected an integer from 16 to 8192",
    ),
    (
        ["render", "walk", "--out", "TMP/r", "--fps", "0"],
        "argument --fps: expected a number above 0 up to 1000",
    ),
    (
        ["render", "walk", "--out", "TMP/r", "--step", "0"],
        "argument --step: expected an integer from 1",
    ),
    (
        ["render", "walk", "--out", "TMP/r", "--azimuth", "1e9"],
        "argument --azimuth: expected a number from -360 to 360 (degrees)",
    ),
    (
        ["render", "walk", "--out", "TMP/r", "--frames", "-1"],
        "argument --frames: expected frame numbers ≥ 0",
    ),
    (
        ["retarget", "walk", "--out", "TMP/w.bvh", "--fps", "-1"],
        "argument --fps: expected a number above 0 up to 1000",
    ),
    (
        ["transfer", "TMP/t", "heavy_male", "--out", "TMP/x", "--tolerance", "-1"],
        "argument --tolerance: expected a number from 0 to 1 (metres)",
    ),
    (
        ["demo", "--out", "TMP/d", "--seconds", "0"],
        "argument --seconds: expected a number from 0.1 to 600",
    ),
    (
        ["demo", "--out", "TMP/d", "--track-frames", "-1"],
        "argument --track-frames: expected an integer from 0",
    ),
    (
        ["export", "TMP/t", "--format", "bvh", "--out", "TMP/e.bvh", "--fps", "0"],
        "argument --fps: expected a number above 0 up to 1000",
    ),
    (
        ["export", "TMP/t", "--format", "bvh", "--out", "TMP/e.bvh", "--joint-weight", "-1"],
        "argument --joint-weight: expected a number from 0 to 1000",
    ),
    (["track", C], "the following arguments are required: --out"),
    (["nope"], "argument COMMAND: invalid choice: 'nope'"),
]

#: Inputs that are wrong: (id, arguments built in tmp, expected message)
INPUTS: list[Case] = [
    (
        "track_method",
        _args("track", C, "--method", "nope", "--out", "TMP/t"),
        "track: method must be one of",
    ),
    (
        "track_max_iter_cage",
        _args("track", C, "--method", "cage", "--max-iter", "5", "--out", "TMP/t"),
        # (the rest of the list: the patch tracker's bench variants, then articulated_icp)
        "track: --max-iter is not an option of --method cage (it is of patch, patch_svc, ",
    ),
    (
        "track_patches_icp",
        _args("track", C, "--method", "articulated_icp", "--n-patches", "50", "--out", "TMP/t"),
        "track: --n-patches is not an option of --method articulated_icp (it is of patch, "
        "patch_svc, patch_noclf, ",
    ),
    (
        "track_classifier_cage",
        _args("track", C, "--method", "cage_quads", "--classifier", "svc", "--out", "TMP/t"),
        "track: --classifier is not an option of --method cage_quads",
    ),
    (
        "track_readout",
        _args("track", C, "--joint-readout", "elbows", "--out", "TMP/t"),
        "joint_readout must be one of",
    ),
    (
        "track_classifier_name",
        _args("track", C, "--classifier", "forest", "--out", "TMP/t"),
        "classifier must be one of",
    ),
    *[
        (
            f"track_template_{how}",
            (
                lambda how: (
                    lambda tmp, cap: [
                        "track",
                        str(cap),
                        "--out",
                        str(tmp / "t"),
                        "--template",
                        _template_file(tmp, how),  # noqa: B023 (bound by the outer lambda)
                    ]
                )
            )(how),
            msg,
        )
        for how, msg in [
            ("random", "t.npz: not a readable .npz template (BadZipFile: File is not a zip file)"),
            ("truncated", "t.npz: not a readable .npz template (BadZipFile"),
            ("flipped", "t.npz: not a readable .npz template ("),
            ("empty", "t.npz: not a readable .npz template (BadZipFile"),
            ("no_key", "t.npz: template is missing key 'weights_data'"),
            (
                "other_format",
                "t.npz: expected format 'meshmocap-template-1', found 'something-else'",
            ),
        ]
    ],
    (
        "track_template_name",
        _args("track", C, "--template", "nobody", "--out", "TMP/t"),
        "'nobody' is neither a bundled template",
    ),
    *[
        (
            f"track_manifold_{how}",
            (
                lambda how: (
                    lambda tmp, cap: [
                        "track",
                        str(cap),
                        "--method",
                        "cage",
                        "--out",
                        str(tmp / "t"),
                        "--manifold",
                        _manifold_file(tmp, how),  # noqa: B023 (bound by the outer lambda)
                    ]
                )
            )(how),
            msg,
        )
        for how, msg in [
            ("random", "m.npz: not a readable .npz GPLVM file (BadZipFile"),
            ("npz_not_gplvm", "m.npz: not a meshmocap GPLVM file"),
            ("empty", "m.npz: not a readable .npz GPLVM file (BadZipFile"),
        ]
    ],
    (
        "track_manifold_patch",
        _args("track", C, "--manifold", "TMP/m.npz", "--out", "TMP/t"),
        "a manifold is only used by",
    ),
    (
        "track_missing",
        _args("track", "TMP/nothing", "--out", "TMP/t"),
        "TMP/nothing: no such folder, file or archive",
    ),
    ("track_glob_nothing", _args("track", "TMP/*.ply", "--out", "TMP/t"), "glob matches no files"),
    (
        "track_silhouettes_only",
        lambda tmp, cap: ["track", _silhouette_only(tmp, cap), "--out", str(tmp / "t")],
        "has silhouettes but no hulls; run 'meshmocap hull",
    ),
    (
        "track_two_captures",
        lambda tmp, cap: ["track", str(cap), str(cap), "--out", str(tmp / "t")],
        "track: give one capture folder, or several mesh files and folders",
    ),
    (
        "track_mixed_formats",
        lambda tmp, cap: ["track", *_mesh_folder(tmp, cap, "mixed"), "--out", str(tmp / "t")],
        "frame files of several formats ['.obj', '.ply']; give one format",
    ),
    (
        "track_empty_folder",
        lambda tmp, cap: ["track", *_mesh_folder(tmp, cap, "empty"), "--out", str(tmp / "t")],
        "folder holds no frame files",
    ),
    (
        "track_not_a_frame",
        lambda tmp, cap: [
            "track",
            _bytes(tmp / "a.txt", b"x"),
            _bytes(tmp / "b.txt", b"y"),
            "--out",
            str(tmp / "t"),
        ],
        "a.txt: not a frame file",
    ),
    (
        "track_frames_outside",
        _args("track", C, "--frames", "100:200", "--out", "TMP/t"),
        "track: --frames 100:200 selects none of the 3 frames",
    ),
    (
        "track_other_settings",
        lambda tmp, cap: [
            "track",
            str(cap),
            "--out",
            _other_settings(tmp, cap),
            "--method",
            "articulated_icp",
            "--frames",
            "0:3",
        ],
        "track.json: holds a track made with other settings (frames: [0, 1] there, "
        "[0, 1, 2] now); use another folder",
    ),
    (
        "track_locked",
        lambda tmp, cap: [
            "track",
            str(cap),
            "--out",
            _locked(tmp, cap),
            "--method",
            "articulated_icp",
        ],
        "track: TMP/busy is being written by another meshmocap process (pid 4242); wait for it "
        "to finish or write to another folder",
    ),
    (
        "synth_motion",
        _args("synth", "TMP/s", "--motion", "moonwalk"),
        "clip: expected a .bvh or .amc file or one of",
    ),
    (
        "synth_motion_bvh",
        lambda tmp, cap: ["synth", str(tmp / "s"), "--motion", _bad_bvh(tmp)],
        "bad.bvh",
    ),
    ("synth_rig", _args("synth", "TMP/s", "--rig", "dome99"), "dome99"),
    (
        "synth_rig_file",
        lambda tmp, cap: ["synth", str(tmp / "s"), "--rig", _bytes(tmp / "r.json", b"[{]")],
        "r.json",
    ),
    (
        "synth_template",
        lambda tmp, cap: ["synth", str(tmp / "s"), "--template", _template_file(tmp, "random")],
        "t.npz: not a readable .npz template",
    ),
    (
        "synth_frames_none",
        _args("synth", "TMP/s", "--template", "neutral_5k", "--frames", "5000:6000"),
        "synth: frame range 5000:6000:None selects none of the 241 frames of walk",
    ),
    (
        "synth_other_params",
        lambda tmp, cap: [
            "synth",
            _synth_other(tmp, cap),
            "--motion",
            "squat",
            "--template",
            "neutral_5k",
        ],
        "holds a capture made with other parameters; use a new folder",
    ),
    (
        "hull_two_cameras",
        lambda tmp, cap: ["hull", _hull_layout(tmp, cap, "two_cameras")],
        "hull: TMP/real/silhouettes holds 4 camera folders but the camera file lists 2 "
        "(['C1', 'C2']); not in it: ['C3', 'C4']",
    ),
    (
        "hull_no_cameras",
        lambda tmp, cap: ["hull", _hull_layout(tmp, cap, "no_cameras")],
        "has no cameras.json or cameras.yml",
    ),
    (
        "hull_bad_json",
        lambda tmp, cap: ["hull", _hull_layout(tmp, cap, "bad_json")],
        "cameras.json",
    ),
    (
        "hull_lost_folder",
        lambda tmp, cap: ["hull", _hull_layout(tmp, cap, "lost_folder")],
        "hull: camera 'C2' has no silhouette folder",
    ),
    (
        "hull_corrupt_png",
        lambda tmp, cap: ["hull", _hull_layout(tmp, cap, "corrupt_png")],
        "C1/00001.png: not a readable image, expected a PNG mask",
    ),
    (
        "hull_small_png",
        lambda tmp, cap: ["hull", _hull_layout(tmp, cap, "small_png")],
        "C1/00001.png: mask of 10×10 pixels, expected 640×480",
    ),
    (
        "hull_no_masks",
        lambda tmp, cap: ["hull", _hull_layout(tmp, cap, "no_masks")],
        "holds no <camera>/NNNNN.png masks",
    ),
    ("hull_missing", _args("hull", "TMP/none"), "hull: TMP/none is not a folder"),
    (
        "eval_no_track",
        _args("eval", C, "TMP/none"),
        "eval: TMP/none is not a track folder (it does not exist); expected a folder written "
        "by 'meshmocap track'",
    ),
    (
        "eval_no_capture",
        lambda tmp, cap: ["eval", str(tmp / "none"), _track_with(tmp, cap, "")],
        "TMP/none: no such folder, file or archive",
    ),
    (
        "eval_corrupt_frame",
        lambda tmp, cap: ["eval", str(cap), _track_with(tmp, cap, "corrupt_frame")],
        "frames/00001.npz: not a readable .npz frame result (BadZipFile",
    ),
    (
        "eval_nan_frame",
        lambda tmp, cap: ["eval", str(cap), _track_with(tmp, cap, "nan_frame")],
        "frames/00001.npz: joints hold NaN or infinite values",
    ),
    (
        "eval_no_faces",
        lambda tmp, cap: ["eval", str(cap), _track_with(tmp, cap, "no_faces")],
        "has no faces.npy",
    ),
    (
        "eval_bad_json",
        lambda tmp, cap: ["eval", str(cap), _track_with(tmp, cap, "bad_json")],
        "track.json: not valid JSON",
    ),
    (
        "eval_foreign_frame",
        lambda tmp, cap: ["eval", str(cap), _track_with(tmp, cap, "foreign_frame")],
        "evaluate: track frames [99] are not in the capture",
    ),
    (
        "report_no_track",
        _args("report", C, "TMP/none", "--out", "TMP/r.html"),
        "report: TMP/none is not a track folder (it does not exist)",
    ),
    (
        "report_on_a_capture",
        _args("report", C, C, "--out", "TMP/r.html"),
        "is not a track folder (it has no track.json); expected a folder written by",
    ),
    (
        "export_no_track",
        _args("export", "TMP", "--out", "TMP/x.bvh"),
        "export: TMP is not a track folder (it has no track.json)",
    ),
    (
        "export_no_format",
        lambda tmp, cap: ["export", _track_with(tmp, cap, ""), "--out", str(tmp / "x.anim")],
        "export: cannot tell the format of 'x.anim' from its extension; use one of ['.bvh', "
        "'.c3d', '.trc', '.gltf', '.glb', '.csv'] or give --format",
    ),
    (
        "retarget_bvh",
        lambda tmp, cap: ["retarget", _bad_bvh(tmp), "--out", str(tmp / "o.bvh")],
        "bad.bvh",
    ),
    (
        "retarget_amc_alone",
        lambda tmp, cap: ["retarget", _amc_without_asf(tmp), "--out", str(tmp / "o.bvh")],
        "no ASF skeleton found beside it",
    ),
    ("retarget_missing", _args("retarget", "TMP/none.amc", "--out", "TMP/o.bvh"), "none.amc"),
    (
        "render_template",
        lambda tmp, cap: [
            "render",
            "--template",
            _template_file(tmp, "truncated"),
            "--out",
            str(tmp / "r"),
        ],
        "t.npz: not a readable .npz template",
    ),
    (
        "learn_source",
        lambda tmp, cap: ["learn", _bytes(tmp / "p.npz", b"junk"), "--out", str(tmp / "m.npz")],
        "p.npz: not a readable .npz pose file",
    ),
    (
        "learn_out",
        _args("learn", "walk", "--out", "TMP/m.txt"),
        "learn: --out must be a .npz file in an existing folder",
    ),
    (
        "batch_frames",
        _args("batch", C, "--out", "TMP/b", "--serial", "--frames", "-3"),
        "expected frame numbers ≥ 0 (START:STOP[:STEP] or N), found '-3'",
    ),
    ("batch_missing", _args("batch", "TMP/none", "--out", "TMP/b", "--serial"), "no such capture"),
    (
        "batch_workers",
        _args("batch", C, "--out", "TMP/b", "--workers", "0"),
        "batch: --workers must be an integer ≥ 1, found 0",
    ),
    (
        "batch_manifest_extra_cells",
        lambda tmp, cap: [
            "batch",
            _bytes(tmp / "m.csv", f"capture,method\n{cap},patch,oops\n".encode()),
            "--out",
            str(tmp / "b"),
            "--serial",
        ],
        "batch: TMP/m.csv:2: expected 2 cells (capture, method), found 3",
    ),
    (
        "transfer_no_track",
        _args("transfer", "TMP/none", "heavy_male", "--out", "TMP/x"),
        "transfer: TMP/none is not a track folder (it does not exist)",
    ),
]


@pytest.mark.parametrize(
    ("argv", "message"), RANGES, ids=[" ".join(a[:1] + a[-2:]) for a, _ in RANGES]
)
def test_values_out_of_range_are_refused_in_one_line(tmp_path, cap, capsys, argv, message):
    args = [str(cap) if a == C else a.replace("TMP", str(tmp_path)) for a in argv]
    assert main(args) == 2
    _one_error_line(capsys, message, tmp_path)


@pytest.mark.parametrize(("name", "build", "message"), INPUTS, ids=[c[0] for c in INPUTS])
def test_wrong_inputs_give_one_line(tmp_path, cap, capsys, name, build, message):
    args = build(tmp_path, cap)
    capsys.readouterr()
    try:
        assert main(args) == 2
    finally:
        while _LOCKS:
            import os

            os.close(_LOCKS.pop())
    _one_error_line(capsys, message, tmp_path)


def _one_error_line(capsys, message: str, tmp: Path) -> None:
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("meshmocap: error: "), err
    assert "Traceback" not in err
    assert message.replace("TMP", str(tmp)) in err, err


# ------------------------------------------------- output places, track folders, captures


@pytest.fixture(scope="module")
def trk(cap, tmp_path_factory) -> Path:
    """A 2-frame track of ``cap`` (articulated ICP, one iteration)."""
    out = tmp_path_factory.mktemp("badcli_track") / "t"
    argv = ["track", str(cap), "--method", "articulated_icp", "--max-iter", "1", "--init", "truth"]
    assert main([*argv, "--frames", "0:2", "--template", "neutral_5k", "--out", str(out)]) == 0
    return out


@pytest.fixture(scope="module")
def jog(synth_capture) -> Path:
    """Another take: a 3-frame jog on the same rig."""
    return synth_capture("jog", stop=3, fps=30.0, voxel_size=0.02).path


T = "TRK"  # replaced by the track folder

#: Every writing command with an ``--out`` it cannot write: a read-only place (/proc takes
#: no new file, even for root), a file standing where a folder of the path should be, a
#: folder where a file is expected or a file where a folder is.
_WRITERS: list[tuple[str, list[str], str]] = [
    ("track", ["track", C, "--method", "articulated_icp", "--out", "OUT"], "folder"),
    ("synth", ["synth", "OUT", "--template", "neutral_5k"], "folder"),
    ("eval", ["eval", C, T, "--no-silhouettes", "--out", "OUT"], "folder"),
    ("report", ["report", C, T, "--out", "OUT"], "file"),
    *[
        (f"export_{f}", ["export", T, "--format", f, "--out", "OUT"], "file")
        for f in ("bvh", "c3d", "trc", "gltf", "glb", "csv")
    ],
]

_PLACES = {
    "read_only": ("/proc/meshmocap-out", "cannot write in /proc ("),
    "file_as_parent": ("TMP/plain.txt/out", "TMP/plain.txt is a file, not a folder"),
    "wrong_kind": (None, None),  # a folder for a file, a file for a folder
}


def _fill(argv: list[str], tmp: Path, cap: Path, trk: Path, out: str = "") -> list[str]:
    """``argv`` with CAP, TRK (also inside a path), TMP and OUT filled in."""
    return [
        str(cap)
        if a == C
        else out
        if a == "OUT"
        else a.replace("TMP", str(tmp)).replace(T, str(trk))
        for a in argv
    ]


@pytest.mark.parametrize("place", list(_PLACES))
@pytest.mark.parametrize(("name", "argv", "kind"), _WRITERS, ids=[w[0] for w in _WRITERS])
@pytest.mark.skipif(
    not Path("/proc/self").is_dir(), reason="needs Linux /proc as a read-only place"
)
def test_an_out_that_cannot_be_written_is_refused_before_any_work(
    tmp_path, cap, trk, capsys, name, argv, kind, place
):
    (tmp_path / "plain.txt").write_text("a file")
    out, message = _PLACES[place]
    flag = "OUT" if argv[0] == "synth" else "--out"
    if place == "wrong_kind":
        out = str(tmp_path) if kind == "file" else str(tmp_path / "plain.txt")
        message = (
            f"{flag} {out}: is a folder; expected a file name to write"
            if kind == "file"
            else f"{flag} {out}: is a file; expected a folder"
        )
    else:
        out = out.replace("TMP", str(tmp_path))
    capsys.readouterr()
    assert main(_fill(argv, tmp_path, cap, trk, out)) == 2
    _one_error_line(capsys, f"{argv[0]}: {flag} {out}: " + message.split(f"{out}: ")[-1], tmp_path)
    assert (tmp_path / "plain.txt").read_text() == "a file"


#: Writes in a track folder, refused: (id, argv, expected message). Only ``track`` writes
#: there: over its own files, and beside them too. One case per command that writes.
INSIDE = (
    "lies in the track folder TRK, which only 'meshmocap track' writes; expected a path outside it"
)
PROTECTED: list[tuple[str, list[str], str]] = [
    (
        "export_over_track_json",
        ["export", T, "--out", "TRK/track.json", "--format", "csv"],
        f"export: --out TRK/track.json: {INSIDE}",
    ),
    (
        "export_into_frames",
        ["export", T, "--out", "TRK/frames/00000.npz", "--format", "csv"],
        f"export: --out TRK/frames/00000.npz: {INSIDE}",
    ),
    ("export_beside", ["export", T, "--out", "TRK/x.bvh"], f"export: --out TRK/x.bvh: {INSIDE}"),
    ("synth_into_track", ["synth", "TRK", "--template", "neutral_5k"], "OUT TRK: is the track"),
    ("synth_beside", ["synth", "TRK/cap"], f"synth: OUT TRK/cap: {INSIDE}"),
    (
        "silhouettes_beside",
        ["silhouettes", "TMP", "--calibration", "TMP/c.toml", "--out", "TRK/s"],
        f"silhouettes: --out TRK/s: {INSIDE}",
    ),
    ("eval_into_track", ["eval", C, T, "--out", "TRK"], "eval: --out TRK: is the track folder TRK"),
    ("eval_beside", ["eval", C, T, "--out", "TRK/e"], f"eval: --out TRK/e: {INSIDE}"),
    ("report_over_track", ["report", C, T, "--out", "TRK/track.json"], INSIDE),
    (
        "report_beside",
        ["report", C, T, "--out", "TRK/r.html"],
        f"report: --out TRK/r.html: {INSIDE}",
    ),
    ("subject_over_subject", ["subject", C, "--out", "TRK/subject.npz"], INSIDE),
    ("subject_beside", ["subject", C, "--out", "TRK/s.npz"], f"subject: --out TRK/s.npz: {INSIDE}"),
    ("learn_beside", ["learn", "walk", "--out", "TRK/m.npz"], f"learn: --out TRK/m.npz: {INSIDE}"),
    (
        "learn_plot_beside",
        ["learn", "walk", "--out", "TMP/m.npz", "--plot", "TRK/l.png"],
        f"learn: --plot TRK/l.png: {INSIDE}",
    ),
    ("gait_beside", ["gait", T, "--out", "TRK/g"], f"gait: --out TRK/g: {INSIDE}"),
    ("retarget_beside", ["retarget", "walk", "--out", "TRK/w.bvh"], f"--out TRK/w.bvh: {INSIDE}"),
    ("render_beside", ["render", "walk", "--out", "TRK/r"], f"render: --out TRK/r: {INSIDE}"),
    ("batch_beside", ["batch", C, "--out", "TRK/b"], f"batch: --out TRK/b: {INSIDE}"),
    ("bench_beside", ["bench", "--out", "TRK/b"], f"bench: --out TRK/b: {INSIDE}"),
    (
        "bench_work_beside",
        ["bench", "--out", "TMP/b", "--work", "TRK/w"],
        f"bench: --work TRK/w: {INSIDE}",
    ),
    ("demo_beside", ["demo", "--out", "TRK/d"], f"demo: --out TRK/d: {INSIDE}"),
    (
        "track_into_another_track",
        ["track", C, "--out", "TRK/frames", "--method", "articulated_icp"],
        f"track: --out TRK/frames: {INSIDE}",
    ),
    (
        "track_recording_in_another_track",
        ["track", C, "--follow", "--recording", "TRK/x.rrd", "--out", "TMP/t"],
        f"track: --recording TRK/x.rrd: {INSIDE}",
    ),
    (
        "transfer_into_track",
        ["transfer", T, "heavy_male", "--out", "TRK"],
        "transfer: --out TRK: is the track folder TRK",
    ),
    (
        "transfer_beside",
        ["transfer", T, "heavy_male", "--out", "TRK/x"],
        f"transfer: --out TRK/x: {INSIDE}",
    ),
]


@pytest.mark.parametrize(("name", "argv", "message"), PROTECTED, ids=[p[0] for p in PROTECTED])
def test_no_command_but_track_writes_in_a_track_folder(
    tmp_path, cap, trk, capsys, name, argv, message
):
    before = {p: p.read_bytes() for p in sorted(trk.rglob("*")) if p.is_file()}
    capsys.readouterr()
    assert main(_fill(argv, tmp_path, cap, trk)) == 2
    _one_error_line(capsys, message.replace("TRK", str(trk)), tmp_path)
    assert {p: p.read_bytes() for p in sorted(trk.rglob("*")) if p.is_file()} == before
    assert not list(tmp_path.iterdir())  # nothing written elsewhere either


def test_every_writing_command_has_a_case_above():
    from meshmocap.cli import OTHER_OUTPUTS, OUTPUTS

    cases = {a[0] for _, a, _ in PROTECTED}
    assert set(OUTPUTS) <= cases and set(OTHER_OUTPUTS) <= cases
    flags = {f for _, a, _ in PROTECTED for f in a if f.startswith("--")}
    assert {f for outs in OTHER_OUTPUTS.values() for _, f, _ in outs} <= flags


def test_the_live_recording_goes_in_the_track_folder_written(tmp_path, cap, capsys):
    """``track --recording OUT/x.rrd`` writes in the track folder it makes: allowed."""
    from meshmocap.cli import build_parser, check_outputs

    out = tmp_path / "t"
    argv = ["track", str(cap), "--follow", "--recording", str(out / "x.rrd"), "--out", str(out)]
    check_outputs(build_parser().parse_args(argv))  # no error


@pytest.mark.parametrize("command", ["eval", "report"])
def test_a_capture_that_is_not_the_tracks_is_refused_unless_forced(
    tmp_path, cap, trk, jog, capsys, command
):
    argv = [command, str(jog), str(trk), "--no-silhouettes", "--surface-frames", "0"]
    if command == "report":
        argv += ["--out", str(tmp_path / "r.html")]
    capsys.readouterr()
    assert main(argv) == 2
    _one_error_line(
        capsys,
        f"{command}: track {trk} was made from capture {cap}, expected it or a copy, found "
        f"{jog} (its frames differ from those of {cap}); pass --force to score it anyway",
        tmp_path,
    )
    assert main([*argv, "--force"]) == 0
    err = capsys.readouterr().err
    assert err.startswith(f"meshmocap: warning: {command}: track {trk} was made from capture")
    assert "scored anyway (--force)" in err and "Traceback" not in err


def test_a_copy_of_the_tracks_capture_is_accepted_and_a_moved_one_needs_force(
    tmp_path, cap, trk, capsys
):
    import json

    copy = tmp_path / "copy"
    shutil.copytree(cap, copy)
    assert main(["eval", str(copy), str(trk), "--no-silhouettes", "--surface-frames", "0"]) == 0
    assert "warning" not in capsys.readouterr().err
    moved = tmp_path / "t"
    shutil.copytree(trk, moved)
    meta = json.loads((moved / "track.json").read_text())
    meta["capture"] = str(tmp_path / "gone")  # the capture folder was moved since
    (moved / "track.json").write_text(json.dumps(meta))
    assert main(["eval", str(copy), str(moved), "--no-silhouettes"]) == 2
    _one_error_line(capsys, "TMP/gone no longer exists, so the two cannot be compared", tmp_path)


def test_os_and_memory_errors_while_working_end_in_one_line(tmp_path, trk, capsys, monkeypatch):
    import errno

    import meshmocap.apps.files.export as export

    def full(path, *args, **kwargs):
        raise OSError(errno.ENOSPC, "No space left on device", str(path))

    monkeypatch.setattr(export, "write_trc", full)
    assert main(["export", str(trk), "--out", str(tmp_path / "x.trc")]) == 1
    _one_error_line(capsys, "export: TMP/x.trc: No space left on device", tmp_path)

    def big(*args, **kwargs):
        raise MemoryError("Unable to allocate 4.9 GiB for an array with shape (2600000, 250)")

    monkeypatch.setattr(export, "write_joints_csv", big)
    assert main(["export", str(trk), "--out", str(tmp_path / "x.csv")]) == 1
    _one_error_line(
        capsys,
        f"export: out of memory on {trk} (Unable to allocate 4.9 GiB for an array with shape "
        "(2600000, 250)); try a smaller input or a machine with more memory",
        tmp_path,
    )
