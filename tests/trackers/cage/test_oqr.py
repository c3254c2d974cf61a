"""Oriented Quads Rigging: quad placement, the procedural cage, configurations, mapping.

Tolerances. Cage vertices, configuration vectors and quad mappings are a few float64
products and sums of O(1) numbers (metres, rotation entries): exact to ~1e-15, checked at
1e-12. Winding numbers sum 166 solid angles: ~1e-14, checked at 1e-9. Green coordinates
reproduce the rest template to ~1e-14 (test_green.py), checked at 1e-9. Green vs
linear-blend skinning on a walk is a modelling difference, not a rounding one: measured
on neutral_5k (31 frames, 1 s of walk) mean 4.3 mm, 99th percentile 26.5 mm, max 65 mm
(at the back of the bent knee); asserted with margin at 1 cm, 4 cm and 8 cm. A template
turned about Z gets its rig turned: measured to 5e-16 m and 5e-16 on the rotations (the
placement is the same float64 arithmetic on coordinates that differ by rounding), checked
at 1e-9.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from meshmocap.body.procedural import procedural_motion
from meshmocap.body.skeleton import Skeleton, forward_kinematics
from meshmocap.body.template import EvalSkeleton, Template, bundled_templates, load_template
from meshmocap.errors import InputError, MeshError, SkeletonError
from meshmocap.geometry.green import GreenDeformer
from meshmocap.geometry.mesh import edges_unique, mesh_problems, signed_volume
from meshmocap.geometry.rotations import so3_exp
from meshmocap.trackers.cage.cage_mesh import (
    OQR_APEX,
    cage_problems,
    self_intersections,
    surface_distances,
    winding_numbers,
)
from meshmocap.trackers.cage.oqr import (
    N_QUADS,
    QUAD_NAMES,
    build_oqr,
    cage_vertices,
    configuration_from_vector,
    configuration_vector,
    heading,
    quads_from_pose,
)

TEMPLATES = ("neutral", "neutral_5k", "heavy_male", "small_female")


@pytest.fixture(scope="module")
def built():
    """Template and OQR for every bundled template (built once: ~1 s each)."""
    out = {}
    for name in TEMPLATES:
        t = load_template(name)
        out[name] = (t, build_oqr(t))
    return out


def _random_configuration(rng: np.random.Generator, batch: tuple[int, ...] = ()):
    c = rng.normal(scale=0.5, size=(*batch, N_QUADS, 3))
    R = so3_exp(rng.normal(scale=2.0, size=(*batch, N_QUADS, 3)))
    return c, R


def test_bundled_templates_are_the_ones_tested():
    assert set(bundled_templates()) == set(TEMPLATES)


@pytest.mark.slow
@pytest.mark.parametrize("name", TEMPLATES)
def test_cage_is_a_closed_outward_manifold_enclosing_the_template(built, name):
    t, o = built[name]
    V, F = o.rest_vertices, o.faces
    assert V.shape == (85, 3) and F.shape == (166, 3)
    assert mesh_problems(V, F) == []  # closed: every edge in exactly two faces
    E, _ = edges_unique(F)
    assert len(V) - len(E) + len(F) == 2  # genus 0
    directed = np.concatenate([F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]])
    assert len(np.unique(directed, axis=0)) == len(directed)  # consistently oriented
    assert signed_volume(V, F) > 0  # outward
    assert len(self_intersections(V, F)) == 0
    w = winding_numbers(t.V, V, F)
    assert np.abs(w - 1.0).max() < 1e-9  # every template vertex inside
    d, _ = surface_distances(t.V, V, F)
    assert d.min() >= 0.004 - 1e-12  # and at least the default clearance deep
    assert cage_problems(V, F, t.V, clearance=0.004) == []


@pytest.mark.parametrize("name", TEMPLATES)
def test_quads_are_cross_sections_of_constant_size_at_their_joints(built, name):
    t, o = built[name]
    q = o.quads
    assert q.names == QUAD_NAMES and len(q.joints) == N_QUADS
    R = q.rotations
    assert np.abs(R @ np.swapaxes(R, 1, 2) - np.eye(3)).max() < 1e-12
    assert np.abs(np.linalg.det(R) - 1.0).max() < 1e-12
    assert np.all(q.half_sizes > 0.02) and np.all(q.half_sizes < 0.35)  # metres
    signs = np.sign(q.corners[..., :2])
    assert np.all(np.abs(q.corners[..., :2]) == q.half_sizes[:, None])
    assert np.all(signs[:, :, 0] * signs[:, :, 1] == [1, -1, 1, -1])  # CCW about n
    assert np.all(q.corners[..., 2] == 0)
    n = dict(zip(q.names, R[:, :, 2], strict=True))
    c = dict(zip(q.names, q.centres, strict=True))
    assert n["pelvis"][2] > 0.95 and n["chest"][2] > 0.95  # trunk normals point up
    assert n["left_knee"][2] < -0.95 and n["left_toe"][1] < -0.9  # shins down, toes forward
    assert c["pelvis"][2] < c["abdomen"][2] < c["chest"][2] < c["neck"][2] < c["head"][2]
    assert c["left_shoulder"][0] > 0 > c["right_shoulder"][0]  # the subject's left is +X
    # each quad sits on its rig joint's limb: within a quad size of the bone segment
    P, sk = t.skeleton.rest_positions, t.skeleton
    for k, j in enumerate(q.joint_indices):
        tail = P[j] + sk.end_offsets[j] if not sk.children[j] else P[list(sk.children[j])].mean(0)
        a, b = P[j], tail
        s = np.clip((c[q.names[k]] - a) @ (b - a) / ((b - a) @ (b - a)), 0, 1)
        assert np.linalg.norm(c[q.names[k]] - (a + s * (b - a))) < 0.25, q.names[k]


def test_every_cage_vertex_is_bound_rigidly_to_one_quad(built):
    _, o = built["neutral"]
    assert o.vertex_quad.shape == (85,) and o.vertex_local.shape == (85, 3)
    assert np.array_equal(o.vertex_quad[:84], np.repeat(np.arange(N_QUADS), 4))
    assert o.vertex_quad[OQR_APEX] == QUAD_NAMES.index("head")
    assert np.array_equal(o.vertex_local[:84], o.quads.corners.reshape(-1, 3))
    assert o.vertex_local[OQR_APEX, 2] > 0  # the apex is above the head-top quad
    assert np.abs(o.quads.world_corners().reshape(-1, 3) - o.rest_vertices[:84]).max() < 1e-12


def test_cage_vertices_reproduce_the_rest_cage_and_move_rigidly(built):
    _, o = built["neutral"]
    q = o.quads
    assert np.abs(cage_vertices(o, q.centres, q.rotations) - o.rest_vertices).max() < 1e-12
    # a rigid motion of every quad moves the whole cage rigidly; batches broadcast
    rng = np.random.default_rng(0)
    G = so3_exp(rng.normal(size=(4, 3)))
    t = rng.normal(size=(4, 3))
    c = np.einsum("bij,qj->bqi", G, q.centres) + t[:, None]
    R = G[:, None] @ q.rotations
    V = cage_vertices(o, c, R)
    assert V.shape == (4, 85, 3)
    expected = np.einsum("bij,vj->bvi", G, o.rest_vertices) + t[:, None]
    assert np.abs(V - expected).max() < 1e-12


def test_configuration_vector_round_trip():
    rng = np.random.default_rng(1)
    c, R = _random_configuration(rng, (5,))
    y = configuration_vector(c, R)
    assert y.shape == (5, 180)
    c2, R2 = configuration_from_vector(y, c[:, 0], R[:, 0])
    assert np.abs(c2 - c).max() < 1e-12 and np.abs(R2 - R).max() < 1e-12
    assert np.abs(configuration_vector(c2, R2) - y).max() < 1e-12
    ya = configuration_vector(c, R, relative_to_pelvis=False)
    assert ya.shape == (5, 189)
    c3, R3 = configuration_from_vector(ya)
    assert np.abs(c3 - c).max() < 1e-12 and np.abs(R3 - R).max() < 1e-12
    # layout: quad k+1 relative to the pelvis occupies y[9k : 9k + 9] = (c, u, v)
    k = 4
    rel_c = R[0, 0].T @ (c[0, k + 1] - c[0, 0])
    rel_R = R[0, 0].T @ R[0, k + 1]
    assert np.abs(y[0, 9 * k : 9 * k + 9] - np.r_[rel_c, rel_R[:, 0], rel_R[:, 1]]).max() < 1e-12


def test_configuration_vector_is_invariant_to_the_pelvis_pose_and_orthonormalised():
    rng = np.random.default_rng(2)
    c, R = _random_configuration(rng)
    G, t = so3_exp(rng.normal(size=3)), rng.normal(size=3)
    y = configuration_vector(c, R)
    y_moved = configuration_vector(c @ G.T + t, G @ R)
    assert np.abs(y_moved - y).max() < 1e-12  # §4: aligned on the pelvis quad
    # a blend of two configurations (what a GPLVM mean produces) decodes to rotations
    y2 = configuration_vector(*_random_configuration(rng))
    _, Rb = configuration_from_vector(0.5 * (y + y2))
    assert np.abs(Rb @ np.swapaxes(Rb, -1, -2) - np.eye(3)).max() < 1e-12
    assert np.abs(np.linalg.det(Rb) - 1.0).max() < 1e-12


def test_quads_from_pose_at_rest_gives_the_rest_quads(built):
    t, o = built["neutral"]
    J = t.skeleton.n_joints
    R = np.broadcast_to(np.eye(3), (3, J, 3, 3))
    root = np.broadcast_to(t.skeleton.rest_positions[0], (3, 3))
    c, Rq = quads_from_pose(o, t, R, root)
    assert c.shape == (3, N_QUADS, 3) and Rq.shape == (3, N_QUADS, 3, 3)
    assert np.abs(c - o.quads.centres).max() < 1e-12
    assert np.abs(Rq - o.quads.rotations).max() < 1e-12


def test_quads_from_pose_keep_their_rest_pose_relative_to_their_joints(built):
    t, o = built["neutral"]
    m = procedural_motion("walk", t, duration=0.5, fps=20.0)
    c, R = quads_from_pose(o, t, m.rotations, m.root_positions)
    G, P = forward_kinematics(t.skeleton, m.rotations, m.root_positions)
    j = o.quads.joint_indices
    Gj = G[:, j]
    local_c = np.einsum("tqji,tqj->tqi", Gj, c - P[:, j])
    assert np.abs(local_c - (o.quads.centres - t.skeleton.rest_positions[j])).max() < 1e-12
    assert np.abs(np.swapaxes(Gj, -1, -2) @ R - o.quads.rotations).max() < 1e-12
    # single frame, no leading axis
    c1, R1 = quads_from_pose(o, t, m.rotations[3], m.root_positions[3])
    assert np.abs(c1 - c[3]).max() < 1e-12 and np.abs(R1 - R[3]).max() < 1e-12


def test_green_coordinates_in_the_cage_reproduce_rest_and_follow_skinning(built):
    t, o = built["neutral_5k"]
    gd = GreenDeformer(o.rest_vertices, o.faces, t.V)
    assert not gd.outside_.any()
    assert np.abs(gd.deform(o.rest_vertices) - t.V).max() < 1e-9
    m = procedural_motion("walk", t, duration=1.0, fps=30.0)
    c, R = quads_from_pose(o, t, m.rotations, m.root_positions)
    cages = cage_vertices(o, c, R)
    lbs = t.pose(m.rotations, m.root_positions).V
    err = np.stack(
        [np.linalg.norm(gd.deform(v) - x, axis=1) for v, x in zip(cages, lbs, strict=True)]
    )
    assert err.mean() < 0.01  # measured 4.3 mm
    assert np.percentile(err, 99) < 0.04  # measured 26.5 mm
    assert err.max() < 0.08  # measured 65 mm (back of the bent knee)


def test_self_intersection_and_enclosure_checks_catch_broken_cages(built):
    t, o = built["neutral_5k"]
    V, F = o.rest_vertices.copy(), o.faces
    elbow = QUAD_NAMES.index("left_elbow")
    V[4 * elbow : 4 * elbow + 4, 0] -= 0.3  # pull the left elbow through the trunk
    assert len(self_intersections(V, F)) > 0
    problems = cage_problems(V, F, t.V)
    assert any(p.startswith("self-intersection") for p in problems)
    assert any(p.startswith("enclosure") for p in problems)  # the forearm now sticks out
    assert cage_problems(o.rest_vertices, F[:, ::-1])[0].startswith("outward")
    assert cage_problems(o.rest_vertices, F[1:])[0].startswith("manifold")


def turned(t: Template, angle: float, shift=(0.0, 0.0, 0.0)) -> tuple[Template, np.ndarray]:
    """``t`` turned by ``angle`` (radians) about +Z through the origin, then shifted; and
    the rotation (3, 3)."""
    C = so3_exp(np.array([0.0, 0.0, angle]))
    sk, ev = t.skeleton, t.eval_skeleton
    offsets = sk.offsets @ C.T
    offsets[0] += shift
    skel = Skeleton(sk.names, sk.parents, offsets, sk.end_offsets @ C.T)
    evs = EvalSkeleton(ev.names, ev.parents, ev.rest_positions @ C.T + shift, ev.weights)
    V = t.V @ C.T + shift
    return Template(f"{t.name}_turned", V, t.F, skel, t.weights, t.part_labels, evs), C


@pytest.mark.parametrize("degrees", [90.0, 180.0, 37.0])
def test_a_turned_template_gets_its_rig_turned(built, degrees):
    t, o = built["neutral_5k"]
    shift = np.array([0.4, -1.1, 0.0])
    t2, C = turned(t, np.radians(degrees), shift)
    assert np.abs(heading(t2) - C).max() < 1e-12 and np.array_equal(heading(t), np.eye(3))
    o2 = build_oqr(t2)
    assert np.array_equal(o2.faces, o.faces) and np.array_equal(o2.vertex_quad, o.vertex_quad)
    assert np.abs(o2.rest_vertices - (o.rest_vertices @ C.T + shift)).max() < 1e-9
    assert np.abs(o2.quads.centres - (o.quads.centres @ C.T + shift)).max() < 1e-9
    assert np.abs(o2.quads.rotations - C @ o.quads.rotations).max() < 1e-9
    assert np.abs(o2.quads.half_sizes - o.quads.half_sizes).max() < 1e-9
    assert np.abs(o2.vertex_local - o.vertex_local).max() < 1e-9
    E, _ = edges_unique(o2.faces)
    assert len(o2.rest_vertices) - len(E) + len(o2.faces) == 2  # closed genus 0
    assert cage_problems(o2.rest_vertices, o2.faces, t2.V, clearance=0.004) == []


def test_a_template_lying_down_is_refused_in_one_line(built):
    t, _ = built["neutral_5k"]
    sk = t.skeleton
    R = so3_exp(np.array([0.0, np.pi / 2, 0.0]))  # its left (+X) now points down
    lying = replace(
        t, skeleton=Skeleton(sk.names, sk.parents, sk.offsets @ R.T, sk.end_offsets @ R.T)
    )
    with pytest.raises(SkeletonError, match="upright") as info:
        build_oqr(lying)
    assert "\n" not in str(info.value)


def test_trunk_quads_fitted_into_the_arms_are_untangled_and_regrown(built):
    # margin 1.6 makes the chest and abdomen quads cut into the upper arms' tubes: the cage
    # starts self-intersecting (6 rounds of shrinking) and needs quads to slide to enclose
    t, _ = built["neutral_5k"]
    o = build_oqr(t, margin=1.6)
    assert cage_problems(o.rest_vertices, o.faces, t.V, clearance=0.004) == []


@pytest.mark.slow
def test_arms_held_against_the_trunk_get_a_cage(built):
    # neutral_5k re-rested with its arms lowered 0.3 rad towards the trunk and its elbows
    # bent forward (the MIT crane's frame 0 stands so): the first placement leaves the
    # upper arms' inner sides outside the cage, the second (upper arms boxed) encloses all
    from meshmocap.body.autorig import rest_in_pose

    t, _ = built["neutral_5k"]
    sk = t.skeleton
    R = np.tile(np.eye(3), (sk.n_joints, 1, 1))
    for side, sign in (("Left", 1.0), ("Right", -1.0)):
        R[sk.index(f"{side}Arm")] = so3_exp(np.array([0.0, sign * 0.3, 0.0]))
        R[sk.index(f"{side}ForeArm")] = so3_exp(np.array([-0.8, 0.0, 0.0]))
    arms = rest_in_pose(t, R, sk.rest_positions[0], name="arms_down")
    o = build_oqr(arms)
    assert cage_problems(o.rest_vertices, o.faces, arms.V, clearance=0.004) == []


def test_build_oqr_names_the_failed_check_and_validates_its_inputs():
    t = load_template("neutral_5k")
    with pytest.raises(MeshError, match=r"'neutral_5k': the [a-z ]+: enclosure: ") as e:
        build_oqr(t, clearance=0.05, max_grow=0)
    assert e.value.part in str(e.value) and e.value.reason.startswith("enclosure")
    with pytest.raises(MeshError, match="cross-section holds no vertex") as e:
        build_oqr(t, slab=1e-5)
    assert e.value.part == "left shoulder"  # the first quad placed
    for kw, what in [
        (dict(margin=0.5), r"margin must be a number in \[1, 3\], found 0.5"),
        (dict(pad=0), r"pad must be a number in \(0, 0.1\] metres, found 0"),
        (dict(pad=float("nan")), "pad must be a number"),
        (dict(slab=True), "slab must be a number"),
        (dict(clearance="4 mm"), "clearance must be a number"),
        (dict(grow_step=np.inf), "grow_step must be a number"),
        (dict(max_grow=-1), "max_grow must be a non-negative integer, found -1"),
        (dict(max_grow=True), "max_grow must be a non-negative integer, found True"),
    ]:
        with pytest.raises(InputError, match=what) as info:
            build_oqr(t, **kw)
        assert "\n" not in str(info.value) and str(info.value).startswith("build_oqr: ")
    sk = t.skeleton
    names = tuple("Elbow" if n == "LeftForeArm" else n for n in sk.names)
    renamed = replace(t, skeleton=Skeleton(names, sk.parents, sk.offsets, sk.end_offsets))
    with pytest.raises(SkeletonError, match="LeftForeArm"):
        build_oqr(renamed)


def test_configuration_functions_validate_their_inputs(built):
    t, o = built["neutral"]
    c, R = o.quads.centres, o.quads.rotations
    with pytest.raises(InputError, match="centres"):
        configuration_vector(c[:20], R[:20])
    with pytest.raises(InputError, match="rotations"):
        cage_vertices(o, c, R[:, :2])
    with pytest.raises(InputError, match="y must"):
        configuration_from_vector(np.zeros(181))
    with pytest.raises(InputError, match="absolute"):
        configuration_from_vector(np.zeros(189), c[0])
    with pytest.raises(InputError, match="R_local"):
        quads_from_pose(o, t, np.eye(3), np.zeros(3))
    with pytest.raises(InputError, match="root"):
        quads_from_pose(o, t, np.tile(np.eye(3), (31, 1, 1)), np.zeros(2))


CUBE_V = np.array([[x, y, z] for x in (0, 1) for y in (0, 1) for z in (0, 1)], dtype=float)
CUBE_F = np.array(
    [
        [0, 3, 2],
        [0, 1, 3],
        [4, 7, 5],
        [4, 6, 7],
        [0, 5, 1],
        [0, 4, 5],
        [2, 7, 6],
        [2, 3, 7],
        [0, 6, 4],
        [0, 2, 6],
        [1, 7, 3],
        [1, 5, 7],
    ]
)


def test_winding_numbers_and_distances_on_a_cube():
    P = np.array([[0.5, 0.5, 0.5], [0.1, 0.2, 0.9], [1.5, 0.5, 0.5], [2.0, 2.0, 2.0]])
    w = winding_numbers(P, CUBE_V, CUBE_F)
    assert np.abs(w - [1, 1, 0, 0]).max() < 1e-12
    d, f = surface_distances(P, CUBE_V, CUBE_F)
    assert np.abs(d - [0.5, 0.1, 0.5, np.sqrt(3.0)]).max() < 1e-12
    assert set(CUBE_F[f[2]]) <= {4, 5, 6, 7}  # the x = 1 side
    # nearest to an edge or a corner: the faces tie and the lowest index wins, whatever
    # the rounding of the coordinates (here the cube turned by 90° about Z and back)
    P = np.array([[1.5, 0.5, 1.5], [1.5, 1.5, 1.5], [0.5, -0.5, -0.5]])
    C = so3_exp(np.array([0.0, 0.0, np.pi / 2]))
    for X in (P, (P @ C.T) @ C):
        d, f = surface_distances(X, CUBE_V, CUBE_F)
        for x, dx, fx in zip(X, d, f, strict=True):
            all_d = np.array(
                [surface_distances(x[None], CUBE_V, CUBE_F[[k]])[0][0] for k in range(len(CUBE_F))]
            )
            assert fx == np.flatnonzero(all_d <= all_d.min() + 1e-12)[0]
            assert abs(dx - all_d.min()) < 1e-12


def test_self_intersections_on_small_examples():
    assert len(self_intersections(CUBE_V, CUBE_F)) == 0
    # two triangles crossing without sharing a vertex
    V = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0.2, 0.2, -1], [0.2, 0.2, 1], [1, 1, 1.0]])
    assert self_intersections(V, np.array([[0, 1, 2], [3, 4, 5]])).tolist() == [[0, 1]]
    # sharing one vertex: the edge opposite it crosses the other triangle, or not
    V = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0.4, 0.4, -1], [0.4, 0.4, 1]])
    assert len(self_intersections(V, np.array([[0, 1, 2], [0, 3, 4]]))) == 1
    V[3:, :2] = -0.6  # now it only touches the shared vertex
    assert len(self_intersections(V, np.array([[0, 1, 2], [0, 3, 4]]))) == 0
    # sharing an edge: only a fold-over counts
    V = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0.3, 0.5, 1e-9], [0.5, -1, 0]])
    assert len(self_intersections(V, np.array([[0, 1, 2], [1, 0, 3]]))) == 1
    assert len(self_intersections(V, np.array([[0, 1, 2], [1, 0, 4]]))) == 0


def test_a_long_dress_gets_a_relaxed_cage():
    # ~10 s: four placements. A dress flaring 25 cm beyond the legs down to the ankles: the
    # first two placements leave a vertex 2.5 mm from the cage (clearance 4 mm); the relaxed
    # ones (wider cross-sections, more growth, less clearance) enclose it
    t = load_template("neutral_5k")
    E, names = t.eval_skeleton.rest_positions, t.eval_skeleton.names
    top, hem = E[names.index("pelvis"), 2] + 0.05, E[names.index("left_ankle"), 2] + 0.05
    V = t.V.copy()
    flare = 0.25 * np.clip((top - V[:, 2]) / (top - hem), 0, 1) * (V[:, 2] > hem)
    d = V[:, :2] - E[names.index("pelvis"), :2]
    V[:, :2] += d / np.maximum(np.linalg.norm(d, axis=1, keepdims=True), 1e-9) * flare[:, None]
    dress = replace(t, V=V, name="dress")
    o = build_oqr(dress)
    assert cage_problems(o.rest_vertices, o.faces, dress.V, clearance=0.001) == []
