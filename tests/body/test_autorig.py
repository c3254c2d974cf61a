"""Automatic rigging: a posed, scaled, turned bundled template is rigged back within stated
tolerances; the rigged template is valid and starts on its mesh; bad meshes are refused in
one line; the real crane frame 0 gets its joints inside the body."""

from __future__ import annotations

import numpy as np
import pytest

from meshmocap.body.autorig import (
    MIN_VERTICES,
    fit_skeleton,
    mesh_samples,
    rest_in_pose,
    rig_mesh,
)
from meshmocap.body.procedural import procedural_motion
from meshmocap.body.template import load_template, template_problems
from meshmocap.errors import InputError, MeshError
from meshmocap.geometry.rotations import so3_exp

SCALE, YAW, SHIFT = 1.1, 1.2, np.array([0.3, -0.2, 0.0])


def winding_numbers(P, V, F):
    """Winding numbers (p,) of a few points (p, 3) in a closed outward mesh: 1 inside."""
    A, B, C = (V[F[:, c]][None] - P[:, None] for c in range(3))  # (p, m, 3)
    a, b, c = (np.linalg.norm(X, axis=2) for X in (A, B, C))
    dot = lambda X, Y: np.einsum("pmi,pmi->pm", X, Y)  # noqa: E731
    num = dot(A, np.cross(B, C))
    den = a * b * c + dot(A, B) * c + dot(B, C) * a + dot(C, A) * b
    return np.arctan2(num, den).sum(axis=1) / (2 * np.pi)


@pytest.fixture(scope="module")
def subject():
    """neutral_5k in frame 10 of the procedural walk (30 fps), scaled ×1.1 about its root,
    turned 1.2 rad about Z and moved: its mesh, rig joints and evaluation joints."""
    t = load_template("neutral_5k")
    m = procedural_motion("walk", t, duration=1.0, fps=30.0)
    R, root = m.rotations[10], m.root_positions[10]
    p = t.pose(R, root)
    C = so3_exp(np.array([0.0, 0.0, YAW]))

    def move(X):
        return (SCALE * (X - root)) @ C.T + root + SHIFT

    return t, move(p.V), move(p.joints), move(p.eval_joints)


@pytest.fixture(scope="module")
def rigged(subject):
    t, V, _, _ = subject
    return rig_mesh(V, t.F, reference="neutral", name="walker", n_yaws=6, iterations=30)


def test_rig_recovers_joints_and_parts(subject, rigged):
    t, V, P, E = subject
    eval_err = np.linalg.norm(rigged.eval_skeleton.rest_positions - E, axis=1)
    assert eval_err.mean() < 0.03  # measured 13 mm (shoulders 23-25 mm)
    rig_err = np.linalg.norm(rigged.skeleton.rest_positions - P, axis=1)
    assert np.median(rig_err) < 0.03
    assert np.mean(rigged.part_labels == t.part_labels) >= 0.9  # measured 98 %
    assert rigged.name == "walker"
    np.testing.assert_array_equal(rigged.V, V)  # the mesh itself is the rest pose


def test_rigged_template_is_valid_and_starts_on_its_mesh(rigged):
    assert template_problems(rigged) == []
    W = rigged.weights.tocsr()
    assert np.diff(W.indptr).max() <= 4
    np.testing.assert_allclose(np.asarray(W.sum(axis=1)).ravel(), 1.0, atol=1e-12)
    J = rigged.skeleton.n_joints
    p = rigged.pose(np.tile(np.eye(3), (J, 1, 1)), rigged.skeleton.rest_positions[0])
    np.testing.assert_allclose(p.V, rigged.V, atol=1e-12)
    np.testing.assert_allclose(p.eval_joints, rigged.eval_skeleton.rest_positions, atol=1e-12)


def test_rest_in_pose_keeps_the_posed_mesh():
    t = load_template("neutral_5k")
    m = procedural_motion("squat", t, duration=1.0, fps=10.0)
    R, root = m.rotations[5], m.root_positions[5]
    r = rest_in_pose(t, R, root, scale=0.9, name="squat")
    posed = t.pose(R, root)
    np.testing.assert_allclose(r.V, root + 0.9 * (posed.V - root), atol=1e-12)
    # posing the re-rested template by a further rotation of the left knee moves only the leg
    R2 = np.tile(np.eye(3), (t.skeleton.n_joints, 1, 1))
    R2[t.skeleton.index("LeftLeg")] = so3_exp(np.array([0.5, 0.0, 0.0]))
    moved = np.linalg.norm(r.pose(R2, r.skeleton.rest_positions[0]).V - r.V, axis=1) > 1e-9
    assert moved.any() and np.all(r.V[moved, 2] < r.skeleton.rest_positions[0, 2])


def test_fit_skeleton_recovers_a_pose_of_the_same_template(subject):
    t, _, _, _ = subject
    m = procedural_motion("walk", t, duration=1.0, fps=30.0)
    R, root = m.rotations[20], m.root_positions[20]
    p = t.pose(R, root)
    fit = fit_skeleton(t, p.V, t.F, root=root + [0.05, -0.04, 0.02], iterations=30)
    err = np.linalg.norm(fit.joints(t) - p.joints, axis=1)
    assert np.median(err) < 0.015  # measured 7 mm
    assert fit.rms < 0.02  # sample spacing: about 14 mm at a perfect fit
    assert fit.scale == 1.0


def test_bad_meshes_are_refused_in_one_line():
    t = load_template("neutral_5k")
    V = t.V.copy()
    V[7] = np.nan
    cases = [
        (V, t.F, "NaN"),
        (t.V[:4], np.array([[0, 1, 2], [0, 3, 1], [0, 2, 3], [1, 3, 2]]), f"n ≥ {MIN_VERTICES}"),
        (t.V, t.F[1:], "holes"),
        (t.V, t.F.astype(float), "integer"),
    ]
    for Vb, Fb, what in cases:
        with pytest.raises(MeshError, match=what) as info:
            rig_mesh(Vb, Fb)
        assert "\n" not in str(info.value) and str(info.value).startswith("rig_mesh:")
    with pytest.raises(InputError, match="n_yaws"):
        rig_mesh(t.V, t.F, n_yaws=0)


def test_rig_mesh_decimates_after_the_fit(subject, rigged):
    t, V, _, _ = subject
    small = rig_mesh(
        V, t.F, reference="neutral", name="walker", n_yaws=6, iterations=30, decimate=2000
    )
    assert small.n_vertices == 2000 and template_problems(small) == []
    # the skeleton is fitted to the full mesh: the same as without decimation
    np.testing.assert_array_equal(small.skeleton.rest_positions, rigged.skeleton.rest_positions)
    for bad in (50, 2000.0):
        with pytest.raises(InputError, match="rig_mesh: decimate: decimate_mesh: n_vertices") as e:
            rig_mesh(V, t.F, decimate=bad)
        assert "\n" not in str(e.value)
    with pytest.raises(InputError, match="rig_mesh: smooth must be an integer ≥ 0, found -1"):
        rig_mesh(V, t.F, smooth=-1)


@pytest.fixture(scope="module")
def crane0(shared_data):
    """The real crane's frame 0 (10,002 vertices, facing −X) rigged from ``neutral``."""
    from meshmocap.io.meshes import read_mesh

    path = shared_data / "meshes" / "crane" / "first10" / "mesh_0000.obj"
    if not path.is_file():
        pytest.skip(f"crane meshes not available: {path} is absent")
    V, F = read_mesh(path, up="y")
    return rig_mesh(V, F, name="crane_frame0")


@pytest.mark.slow
def test_crane_frame0_gets_an_oqr_enclosing_every_vertex(crane0):
    from meshmocap.trackers.cage.cage_mesh import cage_problems
    from meshmocap.trackers.cage.oqr import build_oqr, heading

    # it faces −X: its rig is built turned to the canonical heading; its arms hang against
    # its jacket, so trunk and arm quads first intersect and the armpits and crotch need
    # quads to slide (body.cage_growth.untangle, enclose)
    C = heading(crane0)
    assert abs(abs(np.degrees(np.arctan2(C[1, 0], C[0, 0]))) - 90) < 10
    o = build_oqr(crane0)
    assert cage_problems(o.rest_vertices, o.faces, crane0.V, clearance=0.004) == []


def test_crane_frame0_joints_are_inside_the_body(crane0):
    t = crane0
    assert template_problems(t) == [] and t.n_vertices == 10002
    inside = winding_numbers(t.eval_skeleton.rest_positions, t.V, t.F) > 0.5
    assert inside.all(), [n for n, i in zip(t.eval_skeleton.names, inside, strict=True) if not i]
    sk = t.skeleton
    body = [j for j, n in enumerate(sk.names) if "Index" not in n and "Thumb" not in n]
    assert (winding_numbers(sk.rest_positions[body], t.V, t.F) > 0.5).all()
    # a plausible adult: 1.5-2 m from the ankles' level to the head joint
    E = dict(zip(t.eval_skeleton.names, t.eval_skeleton.rest_positions, strict=True))
    assert 1.4 < E["head"][2] - E["left_ankle"][2] < 1.9


@pytest.mark.slow
def test_bench_crane_hook_rigs_frame0_for_every_method(shared_data, tmp_path):
    import math

    from meshmocap.apps.bench.run import run_bench

    archive = shared_data / "meshes" / "crane" / "crane_mesh_0000-0174.tar.gz"
    if not archive.is_file():
        pytest.skip(f"crane archive not available: {archive} is absent")
    res = run_bench(
        tmp_path / "out",
        captures=["crane+humaneva4"],
        data=shared_data,
        methods=["articulated_icp", "cage"],
        max_frames=2,
        keep_fractions=(),
        show_progress=False,
    )
    icp, cage = res.rows
    # two frames cannot make a pose manifold (a GPLVM needs q + 2 poses): said, not raised
    assert cage.status == "n/a" and "at least 3 frames" in cage.note
    assert icp.status == "ok" and icp.metric == "vertices" and icp.frames == 2
    assert icp.per_frame_mm[0] < 1.0  # frame 0 is the template itself
    assert icp.mean_mm < 30.0 and not math.isnan(icp.bone_std_max_mm)  # a real skeleton now
    assert (tmp_path / "out" / "work" / "templates" / "crane+humaneva4-2f.npz").is_file()


def test_a_fit_on_shared_mesh_samples_is_the_fit_on_the_mesh(subject):
    """mesh_samples made once (for fits from several starts) give the very fit that
    fit_skeleton samples for itself; a bad mesh is refused there in one line."""
    t, V, _, _ = subject
    kw = dict(iterations=3, fit_scale=True, n_model_points=400, seed=1)
    own = fit_skeleton(t, V, t.F, n_data_points=900, **kw)
    shared = fit_skeleton(t, V, t.F, samples=mesh_samples(V, t.F, 900, seed=1), **kw)
    assert np.array_equal(own.R, shared.R) and np.array_equal(own.root, shared.root)
    assert own.scale == shared.scale and own.rms == shared.rms
    with pytest.raises(MeshError, match="mesh_samples: "):
        mesh_samples(V, t.F[:-1], 900)
