"""Exports opened in Blender (the ``bpy`` module, ``pip install -e ".[blender]"``) by
the script of the documentation's Blender page, run as a user runs it.

``bpy`` pins NumPy below 2, so CI runs these tests in a virtual environment of their own
(``.ci/run``); elsewhere they skip without it, unless ``MESHMOCAP_REQUIRE`` names
``blender`` (CI sets it), where a missing ``bpy`` fails."""

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from external import SCRIPTS, included_script, require_module, walk_track
from meshmocap.apps.files.export import export_track
from meshmocap.body.template import load_template
from meshmocap.io.capture import Capture
from meshmocap.io.results import read_track

SCRIPT = SCRIPTS / "blender_import.py"
T, FPS = 40, 30.0


def test_the_docs_page_is_the_script():
    """The page shows the file these tests run, whole, and nothing else as Python."""
    assert included_script("guide/blender.rst") == SCRIPT


@pytest.fixture(scope="module")
def template():
    return load_template("neutral_5k")


@pytest.fixture(scope="module")
def track_dir(tmp_path_factory):
    """A procedural walk on neutral_5k as a track: 40 frames at 30 fps from frame 5 on,
    the posed template's vertices and evaluation joints."""
    out = tmp_path_factory.mktemp("blender") / "walk"
    walk_track(out, T, FPS, first=5)
    return out


def run_script(path: Path, tmp_path: Path, *extra: str) -> tuple[dict, str]:
    """Run the docs' script on ``path`` with ``--report``; return the report and stdout."""
    report = tmp_path / "report.json"
    cmd = [sys.executable, str(SCRIPT), str(path), "--report", str(report), *extra]
    res = subprocess.run(cmd, capture_output=True, text=True, timeout=300, cwd=tmp_path)
    assert res.returncode == 0, res.stdout[-3000:] + res.stderr[-3000:]
    return json.loads(report.read_text()), res.stdout


def eval_joints(report: dict, template) -> np.ndarray:
    """(F, 15, 3) evaluation joints skinned by Blender's armature: each joint's rig weights
    blend the bones' world transforms from rest (the template's rule, Z up, metres). The
    armature rests where Blender put it (a BVH's at the origin): the joints' rest positions
    move with it."""
    ev = template.eval_skeleton
    order = [report["bones"].index(n) for n in template.skeleton.names]
    A = np.array(report["transforms"])[:, order]  # (F, J, 4, 4)
    rest = np.array(report["rest_heads"])[order]
    shift = rest[0] - template.skeleton.rest_positions[0]
    np.testing.assert_allclose(rest, template.skeleton.rest_positions + shift, atol=1e-5)
    E0 = ev.rest_positions + shift
    Ae = np.einsum("kj,fjab->fkab", ev.weights, A)
    return np.einsum("fkab,kb->fka", Ae[..., :3, :3], E0) + Ae[..., :3, 3]


@pytest.mark.parametrize("ext", ["bvh", "glb"])
def test_blender_opens_the_export(ext, track_dir, template, tmp_path):
    require_module("bpy", "blender")
    res = export_track(track_dir, tmp_path / f"walk.{ext}")
    track = read_track(track_dir)
    png = tmp_path / "frame.png"
    report, out = run_script(res.path, tmp_path, "--render", str(png))
    # the bones, at the track's rate, one Blender frame per tracked frame
    assert report["bones"][0] == "Hips" and sorted(report["bones"]) == sorted(
        template.skeleton.names
    )
    assert report["fps"] == pytest.approx(FPS)
    assert report["frame_end"] - report["frame_start"] + 1 == T
    # the armature moves the evaluation joints where the track has them
    err = np.linalg.norm(eval_joints(report, template) - track.joints, axis=2)
    assert err.mean() < 0.001, err.mean()
    assert err.mean() * 1e3 == pytest.approx(res.joint_error_mm, abs=0.1)  # Blender adds nothing
    if ext == "glb":  # the skinned mesh, as tall as the tracked one, frame by frame
        tracked = np.ptp(track.vertices[..., 2], axis=1)
        np.testing.assert_allclose(report["mesh_heights"], tracked, atol=0.01)
        assert 1.6 < tracked[0] < 1.9
    else:
        assert report["mesh_heights"] == []
    assert f"{len(template.skeleton.names)} bones, {T} frames at 30 fps" in out
    if ext == "bvh":  # bones only: no mesh to render
        assert "nothing to render" in out and not png.exists()
        return
    # one frame rendered: a body on the background, not an empty picture
    from PIL import Image

    img = np.asarray(Image.open(png).convert("L"), dtype=np.float64)
    assert img.shape == (240, 320)
    assert 0.01 < np.mean(np.abs(img - np.median(img)) > 10) < 0.5


def test_a_gltf_at_24_fps_scene_loses_frames(track_dir, tmp_path):
    """Why the script sets the rate first: the glTF importer places keys (seconds) at the
    scene's rate, 24 fps unless set, so 40 frames at 30 fps span 32 Blender frames."""
    require_module("bpy", "blender")
    res = export_track(track_dir, tmp_path / "walk.glb")
    report, _ = run_script(res.path, tmp_path, "--fps", "24")
    assert report["frame_end"] - report["frame_start"] + 1 == 32


def test_own_mesh_folder_to_blender(tmp_path):
    """The newcomer's path (docs/guide/own_4d.rst): a folder of meshes in centimetres with
    Y up, tracked by ``meshmocap track`` with nothing else given, exported as GLB, opened
    in Blender by the docs' script: every frame at the rate, the body where the truth is."""
    require_module("bpy", "blender")
    from meshmocap.api import example_capture
    from meshmocap.cli import main

    n = 12
    example_capture(tmp_path / "studio", n_frames=n)
    track = tmp_path / "my-track"
    assert main(["track", str(tmp_path / "studio" / "meshes"), "--out", str(track)]) == 0
    glb = tmp_path / "my-track.glb"
    assert main(["export", str(track), "--out", str(glb)]) == 0
    report, out = run_script(glb, tmp_path, "--render", str(tmp_path / "frame.png"))
    assert f"{n} frames at 30 fps" in out
    assert report["frame_end"] - report["frame_start"] + 1 == n and report["fps"] == 30.0
    body = load_template(str(track / "subject.npz"))  # the body track estimated
    truth = Capture(tmp_path / "studio" / "reference")
    J = np.stack([f.truth.joints for f in truth])
    err = np.linalg.norm(eval_joints(report, body) - J, axis=2)
    assert err.mean() < 0.04, err.mean()  # tracking error, through export and Blender
    heights = np.ptp(np.stack([f.truth.vertices for f in truth])[..., 2], axis=1)
    np.testing.assert_allclose(report["mesh_heights"], heights, atol=0.03)
    assert (tmp_path / "frame.png").stat().st_size > 1000
