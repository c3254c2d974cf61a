"""Motion transfer: another mesh in the rest cage of a cage track replays the motion."""

from __future__ import annotations

import json
import warnings

import numpy as np
import pytest

from meshmocap.body.template import load_template
from meshmocap.errors import FormatError, InputError, MeshmocapWarning
from meshmocap.io.meshes import read_mesh
from meshmocap.io.results import frame_path, read_track
from meshmocap.trackers.cage import transfer as transfer_module
from meshmocap.trackers.cage.manifold import fit_pose_manifold
from meshmocap.trackers.cage.oqr import build_oqr
from meshmocap.trackers.cage.training_poses import load_pose_sources
from meshmocap.trackers.cage.transfer import (
    Placement,
    place_in_cage,
    read_cage_track,
    transfer_motion,
    write_transfer,
)
from meshmocap.trackers.driver import track_sequence
from meshmocap.trackers.options import TrackOptions
from meshmocap.trackers.registry import make_tracker


@pytest.fixture(scope="module")
def rig():
    t = load_template("neutral_5k")
    return t, build_oqr(t)


@pytest.fixture(scope="module")
def tracked(rig, synth_capture, tmp_path_factory):
    """A 4-frame cage track of a synthetic walk on neutral_5k (cheap tracker settings), its
    surface and joints through Green coordinates in the cage (the paper's model, which a
    transfer replays; the default skinned surface differs from it by centimetres)."""
    t, oqr = rig
    poses = load_pose_sources(["walk"], t, oqr=oqr, duration=1.2, fps=15.0)
    pm = fit_pose_manifold(poses, t, oqr=oqr, n_samples=18, max_iter=200)
    cap = synth_capture("walk", stop=8, step=2, voxel_size=0.02)
    tr = make_tracker("cage_green", manifold=pm.gp, alternations=1, local_iters=1, n_sample=300)
    out = tmp_path_factory.mktemp("track")
    track = track_sequence(
        tr, t, cap, out, TrackOptions(show_progress=False, init="truth", recover=False)
    )
    return t, out, track, read_cage_track(out, template=t, oqr=oqr)


def test_cage_track_holds_every_frames_cage(tracked):
    t, out, track, ct = tracked
    assert ct.cages.shape == (4, 85, 3) and ct.faces.shape == (166, 3)
    np.testing.assert_array_equal(ct.frames, track.frames)
    assert np.abs(ct.cages[1:] - ct.cages[:1]).max() > 0.01  # the walk moves the cage
    assert read_cage_track(out).template.name == t.name  # bundled: found by name


def test_transferring_the_template_reproduces_the_track(tracked):
    t, _, track, ct = tracked
    V = transfer_motion(ct, t.V)
    # same Green coordinates, same cages: equal up to the track's float32 storage
    # (6e-8 relative, < 2e-7 m on a 1.8 m body)
    assert V.shape == track.vertices.shape
    assert np.abs(V - track.vertices).max() < 1e-6


def test_another_body_moves_coherently(tracked):
    t, _, track, ct = tracked
    heavy = load_template("heavy_male")
    body = heavy.V[::3]  # every third vertex is enough (and 3x faster)
    with pytest.warns(MeshmocapWarning, match="outside the rest cage by more than 5 mm"):
        transfer_motion(ct, body)  # as it is: 38 % outside, up to 10 cm
    place = place_in_cage(heavy.V, t.V, fit="scale")
    assert np.allclose(place.scale, 1.754 / 1.858, atol=2e-3)  # heights, metres
    V = transfer_motion(ct, body, fit=place, tolerance=0.03)  # within 3 cm: no warning
    J = transfer_motion(ct, heavy.eval_skeleton.rest_positions, fit=place, outside="ignore")
    # its joints stay within 3 cm of the tracked ones and follow their motion to 5 mm,
    # its centroid the template's to 3 mm (measured: 1.5 cm, 1.5 mm, 1.2 mm)
    assert np.linalg.norm(J - track.joints, axis=2).mean() < 0.03
    dj = (J - J[0]) - (track.joints - track.joints[0])
    assert np.linalg.norm(dj, axis=2).max() < 0.005
    c, ct_ = V.mean(axis=1), track.vertices.mean(axis=1)
    assert np.linalg.norm((c - c[0]) - (ct_ - ct_[0]), axis=1).max() < 0.003
    assert np.abs(c[-1] - c[0]).max() > 0.05  # and it did move


def test_place_in_cage_undoes_a_similarity_and_checks_options(tracked):
    t = tracked[0]
    moved = t.V * 1.1 + [0.3, -0.2, 0.05]
    for fit in ("scale", "stretch"):
        p = place_in_cage(moved, t.V, fit=fit)
        np.testing.assert_allclose(p.apply(moved), t.V, atol=1e-12)
    p = place_in_cage(moved, t.V, fit="none")
    np.testing.assert_array_equal(p.apply(moved), moved)
    with pytest.raises(InputError, match="fit must be one of"):
        place_in_cage(moved, t.V, fit="affine")
    with pytest.raises(InputError, match="V must have shape"):
        place_in_cage(moved[:, :2], t.V)


def test_outside_policy(tracked):
    t, _, _, ct = tracked
    far = t.V[::10] * 1.3
    with pytest.raises(InputError, match=r"\d+ of 500 vertices lie outside"):
        transfer_motion(ct, far, outside="raise")
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        transfer_motion(ct, far, outside="ignore")
    with pytest.raises(InputError, match="outside must be one of"):
        transfer_motion(ct, t.V, outside="silent")
    with pytest.raises(InputError, match="tolerance must be"):
        transfer_motion(ct, t.V, tolerance=-1.0)


def test_transfer_binds_a_bounded_number_of_vertices(tracked, monkeypatch):
    t, _, _, ct = tracked
    ref = transfer_motion(ct, t.V[:400])
    # above FLOAT32_VERTICES the coordinates are stored in float32: micrometres apart
    monkeypatch.setattr(transfer_module, "FLOAT32_VERTICES", 100)
    np.testing.assert_allclose(transfer_motion(ct, t.V[:400]), ref, rtol=0, atol=1e-5)
    # above the cap: refused in one line that names the size, the cap and the remedy
    monkeypatch.setattr(transfer_module, "MAX_TRANSFER_VERTICES", 300)
    with pytest.raises(InputError, match=r"400 vertices, more than the 300 .* decimate it"):
        transfer_motion(ct, t.V[:400])


def test_write_transfer_is_atomic_per_frame_and_resumes(tracked, tmp_path):
    t, _, _, ct = tracked
    body = t.V * [1.04, 1.0, 0.97]  # a wider, shorter body on the template's mesh
    out = tmp_path / "body"
    place = Placement(np.full(3, 1.01), np.zeros(3))
    kw = dict(fit=place, outside="ignore", name="body")
    res = write_transfer(ct, body, t.F, out, **kw)
    assert (res.written, res.skipped, len(res.files)) == (4, 0, 4)
    assert [p.name for p in res.files] == [f"frame_{i:05d}.obj" for i in ct.frames]
    V, F = read_mesh(res.files[2])
    want = transfer_motion(ct, body, fit=place, outside="ignore")
    np.testing.assert_allclose(V, want[2], atol=1e-9)  # OBJ keeps 10 decimals
    np.testing.assert_array_equal(F, t.F)
    assert res.n_outside > 0 and res.max_outside > 0
    res.files[3].unlink()  # an interrupted run: the last frame is missing
    again = write_transfer(ct, body, t.F, out, **kw)
    assert (again.written, again.skipped) == (1, 3)
    np.testing.assert_allclose(read_mesh(res.files[3])[0], want[3], atol=1e-9)
    assert json.loads((out / "transfer.json").read_text())["mesh"] == "body"
    with pytest.raises(FormatError, match="other settings"):
        write_transfer(ct, body * 1.01, t.F, out, **kw)
    fresh = write_transfer(ct, body * 1.01, t.F, out, resume=False, **kw)
    assert fresh.written == 4
    with pytest.raises(InputError, match="ext must be one of"):
        write_transfer(ct, body, t.F, out, ext=".xyz", **kw)


def test_write_transfer_as_one_animated_y_up_gltf(tracked, tmp_path):
    """glb: one file, every frame a morph target (pygltflib reads it back), Y up."""
    import pygltflib

    t, _, _, ct = tracked
    body = t.V * [1.04, 1.0, 0.97]
    kw = dict(fit=Placement(np.full(3, 1.01), np.zeros(3)), outside="ignore", name="body.obj")
    res = write_transfer(ct, body, t.F, tmp_path, ext=".glb", fps=30.0, **kw)
    assert [p.name for p in res.files] == ["transfer.glb"] and (res.written, res.skipped) == (4, 0)
    want = transfer_motion(ct, body, fit=kw["fit"], outside="ignore")
    g = pygltflib.GLTF2.load(str(res.files[0]))
    blob = g.binary_blob()

    def data(i):
        a = g.accessors[i]
        start = g.bufferViews[a.bufferView].byteOffset
        dt = {5126: "<f4", 5121: "u1"}[a.componentType]
        n = a.count * {"SCALAR": 1, "VEC3": 3}[a.type]
        return np.frombuffer(blob, dt, n, start).astype(np.float64)

    prim = g.meshes[0].primitives[0]
    base = data(prim.attributes.POSITION).reshape(-1, 3)
    to_y_up = np.array([[1, 0, 0], [0, 0, 1], [0, -1, 0]])
    np.testing.assert_allclose(base, want[0] @ to_y_up.T, atol=1e-6)
    frame2 = base + data(prim.targets[1]["POSITION"]).reshape(-1, 3)
    np.testing.assert_allclose(frame2, want[2] @ to_y_up.T, atol=1e-6)
    sampler = g.animations[0].samplers[0]
    np.testing.assert_allclose(data(sampler.input), (ct.frames - ct.frames[0]) / 30.0, atol=1e-6)
    weights = data(sampler.output).reshape(4, 3)  # frame k shows target k − 1
    np.testing.assert_array_equal(weights, 255 * np.eye(4, 3, -1))
    again = write_transfer(ct, body, t.F, tmp_path, ext=".glb", fps=30.0, **kw)
    assert (again.written, again.skipped) == (0, 4)


def test_read_cage_track_checks_its_input(rig, tracked, tmp_path):
    t, oqr = rig
    _, out, _, ct = tracked
    with pytest.raises(InputError, match="tracked with template 'neutral_5k', found 'heavy_male'"):
        read_cage_track(out, template=load_template("heavy_male"))
    # a track from before the cage was stored: rebuilt from the quads, identically
    old = tmp_path / "old"
    (old / "frames").mkdir(parents=True)
    (old / "track.json").write_text((out / "track.json").read_text())
    for i in ct.frames:
        with np.load(frame_path(out, i)) as z:
            d = {k: z[k] for k in z.files if k != "state_cage"}
        np.savez(frame_path(old, i), **d)
    np.testing.assert_allclose(
        read_cage_track(old, template=t, oqr=oqr).cages, ct.cages, atol=1e-12
    )
    # a stored cage its rigging does not rebuild
    d["state_cage"] = ct.cages[-1] + 0.01
    np.savez(frame_path(old, ct.frames[-1]), **d)
    with pytest.raises(InputError, match="does not follow the quad rigging"):
        read_cage_track(old, template=t, oqr=oqr)
    meta = json.loads((out / "track.json").read_text())
    (old / "track.json").write_text(json.dumps({**meta, "method": "patch"}))
    with pytest.raises(InputError, match="needs a cage track, found method 'patch'"):
        read_cage_track(old)
    assert read_track(out).vertices.shape[0] == 4
