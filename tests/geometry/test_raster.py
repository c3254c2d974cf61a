"""Rasterisation and the software renderer."""

import numpy as np
import pytest
import trimesh

from meshmocap.apps.figures.render import contact_sheet, framing_view, render_mesh, render_motion
from meshmocap.body.motion import Motion
from meshmocap.errors import InputError
from meshmocap.geometry.camera import intrinsics, look_at, project
from meshmocap.geometry.raster import coverage, rasterize
from toys import toy_template


def test_square_covers_exactly_its_pixel_centres():
    uv = np.array([[1.5, 1.5], [5.5, 1.5], [5.5, 4.5], [1.5, 4.5]])
    F = np.array([[0, 1, 2], [0, 2, 3]])
    mask = coverage(uv, F, (8, 8))
    expect = np.zeros((8, 8), bool)
    expect[2:5, 2:6] = True  # centres 2..4 (rows) and 2..5 (columns) lie inside
    assert np.array_equal(mask, expect)


def test_nearest_triangle_wins():
    uv = np.array([[0, 0], [9, 0], [0, 9], [0, 0], [9, 0], [0, 9.0]])
    depth = np.array([2.0, 2, 2, 1, 1, 1])
    F = np.array([[0, 1, 2], [3, 4, 5]])
    face, z = rasterize(uv, depth, F, (10, 10))
    assert (face[face >= 0] == 1).all() and np.allclose(z[face >= 0], 1.0)
    face_rev, _ = rasterize(uv, depth, F[::-1], (10, 10))
    assert (face_rev[face_rev >= 0] == 0).all()  # order-independent: still the nearer one


def test_sphere_silhouette_area_matches_the_projected_disc():
    m = trimesh.creation.icosphere(subdivisions=4, radius=0.5)
    K = intrinsics(640, 480, 60.0)
    R, t = look_at([0, -3.0, 1.0], [0, 0, 1.0])
    uv, d = project(np.asarray(m.vertices) + [0, 0, 1.0], K, R, t)
    face, _ = rasterize(uv, d, np.asarray(m.faces), (480, 640))
    # The silhouette of a sphere at distance 3 is a disc of angular radius asin(r/d);
    # the polyhedron is inscribed, so its area is slightly smaller (< 1 % at 5k faces).
    r_px = K[0, 0] * np.tan(np.arcsin(0.5 / 3.0))
    assert (face >= 0).sum() == pytest.approx(np.pi * r_px**2, rel=0.01)


def test_render_draws_the_body_and_sheet_tiles():
    t = toy_template()
    R = np.tile(np.eye(3), (t.skeleton.n_joints, 1, 1))
    posed = t.pose(R, t.skeleton.rest_positions[0])
    view = framing_view(posed.V, size=(120, 160), azimuth=0.0)
    img = render_mesh(posed.V, t.F, view, joints=posed.eval_joints, parents=t.eval_skeleton.parents)
    assert img.shape == (160, 120, 3) and img.dtype == np.uint8
    # red joint markers and grey body pixels exist; the frame is not blank
    assert ((img[..., 0] > 200) & (img[..., 1] < 60)).sum() > 10
    sheet = contact_sheet([img] * 5, columns=3)
    assert sheet.shape == (320, 360, 3)


def test_contact_sheet_captions_are_legible():
    """Captions sit in a band under each tile, dark on white, their letters at least a
    twenty-third of the tile's width tall (14 px on 320-px tiles; the old bitmap font: 8)."""
    tile = np.full((400, 320, 3), 200, np.uint8)
    sheet = contact_sheet([tile] * 4, columns=2, labels=["0.00 s · frame 0"] * 4)
    band = sheet.shape[0] // 2 - 400
    assert sheet.shape == (2 * (400 + band), 640, 3) and band >= 30
    under = sheet[400 : 400 + band, :320].min(axis=2)
    rows = np.flatnonzero((under < 100).any(axis=1))
    cols = np.flatnonzero((under < 100).any(axis=0))
    assert np.ptp(rows) + 1 >= 14 and np.ptp(cols) + 1 >= 120
    with pytest.raises(InputError, match="labels"):
        contact_sheet([tile] * 2, labels=["one"])


def test_render_motion_writes_frames_and_sheet(tmp_path):
    t = toy_template()
    T = 5
    R = np.tile(np.eye(3), (T, t.skeleton.n_joints, 1, 1))
    root = t.skeleton.rest_positions[0] + np.linspace(0, 0.5, T)[:, None] * [1, 0, 0]
    res = render_motion(
        t, Motion(t.skeleton, R, root, 30), tmp_path, size=(64, 80), show_progress=False
    )
    assert len(res.frames) == T and res.sheet.exists()
    assert sorted(p.name for p in tmp_path.iterdir())[-1] == "frame_00004.png"
    with pytest.raises(InputError, match="step"):
        render_motion(t, Motion(t.skeleton, R, root, 30), tmp_path, step=0)
