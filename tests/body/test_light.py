"""The light body: the full template read out of a decimated copy exactly at rest, rigidly
under a rigid motion, and within a millimetre on average (a few at the worst vertices) of
the full template's own skinning in a walk."""

import numpy as np
import pytest

from meshmocap.body.light import (
    LIGHT_VERTICES,
    bound_vertices,
    light_template,
    surface_binding,
    tracking_body,
)
from meshmocap.body.procedural import procedural_motion
from meshmocap.body.template import load_template, template_problems
from meshmocap.geometry.rotations import so3_exp


@pytest.fixture(scope="module")
def body():
    """neutral (12k vertices) and its light body."""
    return tracking_body(load_template("neutral"))


def test_a_heavy_template_is_tracked_on_a_valid_light_copy(body):
    light = body.light
    assert body.template.n_vertices > 12_000
    assert abs(light.n_vertices - LIGHT_VERTICES) <= 0.02 * LIGHT_VERTICES
    assert template_problems(light) == []
    assert light.skeleton is body.template.skeleton  # the same rig: poses carry over
    assert light.eval_skeleton.names == body.template.eval_skeleton.names
    assert tracking_body(body.template) is body  # made once per template and process


def test_a_light_template_is_tracked_as_it_is():
    t = load_template("neutral_5k")
    b = tracking_body(t)
    assert b.light is t and b.binding is None
    assert tracking_body(load_template("neutral"), n_vertices=None).binding is None
    V = np.zeros((t.n_vertices, 3))
    assert b.full_vertices(V) is V


def test_read_out_is_exact_at_rest_and_rigid_under_a_rigid_motion(body):
    V = body.full_vertices(body.light.V)
    assert np.abs(V - body.template.V).max() < 1e-9
    R, t = so3_exp(np.array([0.3, -0.5, 1.1])), np.array([0.4, -1.0, 0.2])
    moved = body.full_vertices(body.light.V @ R.T + t)
    assert np.abs(moved - (body.template.V @ R.T + t)).max() < 1e-9


def test_read_out_follows_the_full_templates_skinning_in_a_walk(body):
    t, light = body.template, body.light
    m = procedural_motion("walk", t, duration=1.0, fps=10.0)
    err = []
    for f in range(m.n_frames):
        full = t.pose(m.rotations[f], m.root_positions[f]).V
        read = body.full_vertices(light.pose(m.rotations[f], m.root_positions[f]).V)
        err.append(np.linalg.norm(read - full, axis=1))
    e = 1000 * np.concatenate(err)  # mm; measured: mean 0.14, 99th percentile 2.3
    assert e.mean() < 0.5 and np.percentile(e, 99) < 5.0


def test_binding_of_a_surface_to_itself_is_nearly_the_identity():
    """Each vertex binds to itself (zero offset), but for a few where the nearest triangle
    with agreeing normals lies elsewhere; posed, the read-out stays within a millimetre."""
    t = load_template("neutral_5k")
    b = surface_binding(t.V, t.F, t.V, t.F)
    assert np.mean(np.abs(b.offset).max(axis=1) < 1e-9) > 0.999
    posed = t.pose(procedural_motion("jog", t, duration=0.2, fps=10).rotations[1], np.zeros(3))
    assert np.abs(bound_vertices(b, posed.V) - posed.V).max() < 1e-3


def test_light_template_keeps_the_parts_where_they_were(body):
    light = light_template(load_template("neutral_5k"), n_vertices=2000)
    assert template_problems(light) == []
    t = body.template
    # every light vertex has the body part of the nearest full vertex, nearly everywhere
    from pykdtree.kdtree import KDTree

    _, k = KDTree(t.V).query(body.light.V, k=1)
    agree = np.mean(t.part_labels[k.astype(np.int64)] == body.light.part_labels)
    assert agree > 0.97
