"""The Python API (meshmocap.api): light to import, the CLI's own errors. That its five
lines reproduce the command line's numbers is checked by the documentation's page
(docs/guide/python.rst, a doctest)."""

import subprocess
import sys

import numpy as np
import pytest

import meshmocap
from meshmocap.errors import InputError, MeshmocapFileNotFoundError


def test_import_meshmocap_stays_light():
    code = (
        "import sys, meshmocap; heavy = [m for m in ('scipy', 'sklearn', 'numba', "
        "'matplotlib', 'meshmocap.api') if m in sys.modules]; print(heavy)"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "[]"
    assert meshmocap.track is meshmocap.api.track  # loaded on first use
    assert {"open_capture", "track", "evaluate", "summary"} <= set(dir(meshmocap))
    with pytest.raises(AttributeError, match="no attribute 'trak'"):
        meshmocap.trak  # noqa: B018


def test_mistakes_are_one_line(tmp_path):
    with pytest.raises(InputError, match="found none"):
        meshmocap.open_capture([])
    with pytest.raises(MeshmocapFileNotFoundError, match="no such folder"):
        meshmocap.open_capture(tmp_path / "nope")
    (tmp_path / "cap").mkdir()
    (tmp_path / "cap" / "capture.json").write_text("{}")
    with pytest.raises(InputError, match="is a capture folder"):
        meshmocap.open_capture([tmp_path / "a.obj", tmp_path / "cap"])
    with pytest.raises(InputError, match="method must be one of"):
        meshmocap.track(tmp_path / "cap", method="pach")


@pytest.mark.slow
def test_a_mesh_folder_tracks_and_exports(tmp_path):
    """Three posed frames of neutral_5k as OBJ files, in centimetres with Y up (as many
    tools write them): opened, tracked with articulated ICP, exported, evaluated."""
    from meshmocap.body.procedural import procedural_motion
    from meshmocap.body.template import load_template
    from meshmocap.io.meshes import write_mesh

    template = load_template("neutral_5k")
    m = procedural_motion("walk", template, duration=0.1, fps=30.0)
    posed = template.pose(m.rotations[:3], m.root_positions[:3])
    folder = tmp_path / "meshes"
    folder.mkdir()
    y_up_cm = np.array([[1.0, 0, 0], [0, 0, 1], [0, -1, 0]]) * 100.0
    for k in range(3):
        write_mesh(folder / f"frame_{k:03d}.obj", posed.V[k] @ y_up_cm.T, template.F)
    cap = meshmocap.open_capture(folder)
    assert len(cap) == 3
    axes = meshmocap.api.capture_and_axes(folder)[1]
    assert (axes.up, axes.units) == ("y", "cm")
    track = meshmocap.track(
        cap, method="articulated_icp", template="neutral_5k", out=tmp_path / "t"
    )
    assert track.joints.shape == (3, 15, 3) and track.frames.tolist() == [0, 1, 2]
    assert np.linalg.norm(track.joints - posed.eval_joints, axis=2).mean() < 0.03
    res = track.to_bvh(tmp_path / "walk.bvh")
    assert res.n_frames == 3 and (tmp_path / "walk.bvh").is_file()
    again = meshmocap.open_track(tmp_path / "t")
    np.testing.assert_array_equal(again.joints, track.joints)
    ev = meshmocap.evaluate(cap, track, silhouettes=False, surface_frames=0)
    assert ev.joints is None and ev.n_frames == 3  # a mesh folder has no truth
    assert "3 frames" in meshmocap.summary(ev)


# ------------------------------------------------------------- arguments of the wrong type

from pathlib import Path  # noqa: E402

from meshmocap.errors import ArgumentTypeError  # noqa: E402


def _no_track():
    """A TrackResult of nothing: its methods check their arguments before using it."""
    return meshmocap.TrackResult(Path("nowhere"), None, None)


#: (call, the argument named, the type found): each refused in one line, before any work
WRONG_TYPES = [
    (lambda: meshmocap.track(12345), "track: capture must be a path", "int 12345"),
    (lambda: meshmocap.track(["a.obj", 3]), "track: capture[1] must be a path", "int 3"),
    (lambda: meshmocap.track("c", method=3), "track: method must be a method name", "int 3"),
    (lambda: meshmocap.track("c", out=3.5), "track: out must be a path or name", "float 3.5"),
    (lambda: meshmocap.track("c", template=1), "track: template must be a path or", "int 1"),
    (lambda: meshmocap.track("c", manifold=[1]), "track: manifold must be a path", "list [1]"),
    (lambda: meshmocap.track("c", resume="no"), "track: resume must be True or False", "str 'no'"),
    (lambda: meshmocap.track("c", vertices=1), "track: vertices must be True or False", "int 1"),
    (lambda: meshmocap.track("c", show_progress=0), "track: show_progress must be", "int 0"),
    (lambda: meshmocap.track("c", log="print"), "track: log must be a callable", "str 'print'"),
    (lambda: meshmocap.track("c", on_frame=1), "track: on_frame must be a callable", "int 1"),
    (lambda: meshmocap.open_capture(12345), "open_capture: source must be a path", "int 12345"),
    (lambda: meshmocap.open_capture(b"c"), "open_capture: source must be a path", "bytes b'c'"),
    (
        lambda: meshmocap.open_capture("c", fps="30"),
        "open_capture: fps must be a number",
        "str '30'",
    ),
    (lambda: meshmocap.open_capture("c", follow=1), "open_capture: follow must be True", "int 1"),
    (lambda: meshmocap.open_capture("c", stop=1), "open_capture: stop must be a callable", "int 1"),
    (lambda: meshmocap.api.capture_and_axes(2.5), "open_capture: source must be a", "float 2.5"),
    (lambda: meshmocap.evaluate(7, "t"), "evaluate: capture must be a path", "int 7"),
    (lambda: meshmocap.evaluate("c", 7), "evaluate: track must be a TrackResult", "int 7"),
    (lambda: meshmocap.evaluate("c", "t", silhouettes=0), "evaluate: silhouettes must", "int 0"),
    (
        lambda: meshmocap.evaluate("c", "t", surface_frames=1.5),
        "surface_frames must be",
        "float 1.5",
    ),
    (lambda: meshmocap.evaluate("c", "t", force="yes"), "evaluate: force must be", "str 'yes'"),
    (lambda: meshmocap.open_track(5), "open_track: path must be a track folder", "int 5"),
    (lambda: meshmocap.open_track("t", template=5), "open_track: template must be a", "int 5"),
    (lambda: meshmocap.summary("text"), "summary: evaluation must be an Evaluation", "str 'text'"),
    (lambda: _no_track().export(5), "TrackResult.export: out must be a file path", "int 5"),
    (
        lambda: _no_track().to_bvh(None),
        "TrackResult.to_bvh: out must be a file path",
        "NoneType None",
    ),
    (lambda: _no_track().to_glb(1.0), "TrackResult.to_glb: out must be a file path", "float 1.0"),
    (lambda: _no_track().gait(fps="30"), "TrackResult.gait: fps must be a number", "str '30'"),
    (lambda: meshmocap.api.example_capture(5), "example_capture: out must be a folder", "int 5"),
    (
        lambda: meshmocap.api.example_capture("x", n_frames="3"),
        "n_frames must be an int",
        "str '3'",
    ),
    (lambda: meshmocap.api.example_capture("x", fps="30"), "fps must be a number", "str '30'"),
    (lambda: meshmocap.api.example_capture("x", motion=3), "motion must be a motion", "int 3"),
    (
        lambda: meshmocap.api.example_capture("x", performer=None),
        "performer must be",
        "NoneType None",
    ),
]


@pytest.mark.parametrize(("call", "named", "found"), WRONG_TYPES)
def test_a_wrong_type_is_refused_in_one_line_naming_the_argument(call, named, found, tmp_path):
    with pytest.raises(ArgumentTypeError) as info:
        call()
    text = str(info.value)
    assert isinstance(info.value, TypeError) and "\n" not in text
    assert named in text and text.endswith(f", found {found}"), text
    assert not (tmp_path / "x").exists()  # refused before any work


def test_wrong_values_are_refused_in_one_line_too(tmp_path):
    with pytest.raises(InputError, match=r"track: init must be one of \['auto', 'truth'\]"):
        meshmocap.track("c", init="gt")
    with pytest.raises(InputError, match=r"open_capture: up must be one of"):
        meshmocap.open_capture("c", up="x")
    with pytest.raises(InputError, match="open_capture: idle must be a positive number"):
        meshmocap.open_capture("c", follow=True, idle=-1)
    with pytest.raises(InputError, match="idle and stop go with follow=True"):
        meshmocap.open_capture("c", idle=2)
    with pytest.raises(InputError, match="evaluate: surface_frames must be ≥ 0, found -1"):
        meshmocap.evaluate("c", "t", surface_frames=-1)
    with pytest.raises(InputError, match=r"TrackResult.export: format must be one of"):
        _no_track().export(tmp_path / "x.obj", format="obj")
    with pytest.raises(InputError, match=r"example_capture: units must be one of \['m'"):
        meshmocap.api.example_capture(tmp_path / "x", units="km")
