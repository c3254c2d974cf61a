"""The cage tracker's compiled loops against the array code they replace
(trackers/cage/kernels.py)."""

import numpy as np
import pytest

from meshmocap.body.template import load_template
from meshmocap.geometry.camera import Camera
from meshmocap.geometry.rotations import so3_exp
from meshmocap.trackers.cage.kernels import contour_pixels
from meshmocap.trackers.cage.oqr import build_oqr, quads_from_pose
from meshmocap.trackers.cage.oqr_skinning import QuadSkinning
from meshmocap.trackers.cage.quad_frames import gram_schmidt, gram_schmidt_reference
from meshmocap.trackers.cage.residuals import SilhouetteCoverage


def _views(rng, n_cameras):
    """Cameras 3 m around the origin looking at it, each mask a disc and a far blob."""
    cams, masks = [], []
    K = np.array([[400.0, 0, 160], [0, 400.0, 120], [0, 0, 1]])
    rr, cc = np.mgrid[:240, :320]
    for k in range(n_cameras):
        a = 2 * np.pi * k / n_cameras
        R = np.array([[np.sin(a), -np.cos(a), 0], [0, 0, -1], [np.cos(a), np.sin(a), 0]])
        R = -R if np.linalg.det(R) < 0 else R
        t = np.array([0.0, 0.0, 3.0])  # the origin 3 m in front
        cams.append(Camera(K, R, t, 320, 240))
        r0, c0 = 120 + rng.integers(-10, 10), 160 + rng.integers(-10, 10)
        disc = (rr - r0) ** 2 + (cc - c0) ** 2 < rng.integers(30, 60) ** 2
        masks.append(disc | ((rr - 20) ** 2 + (cc - 290) ** 2 < 36))
    return cams, masks


@pytest.mark.parametrize("cap", [6.0, 15.0, 40.0])
def test_silhouette_kernel_equals_the_array_code(cap):
    rng = np.random.default_rng(int(cap))
    cams, masks = _views(rng, 3)
    sil = SilhouetteCoverage(cams, masks, 80, 1.0, seed=1, cap=cap)
    on = 0
    for scale in (0.05, 0.1, 0.2, 0.5):
        P = rng.normal(scale=scale, size=(300, 3))
        P[:3] = 5.0 * np.array([[0, 0, 1], [0, 1, 0], [1, 0, 0]])  # behind some cameras
        r, g = sil.residuals(P)
        r0, g0 = sil.residuals_reference(P)
        assert (r > 0).sum() == (r0 > 0).sum()
        on += (r > 0).sum()
        # rounding only: the same nearest points, sums in another order
        np.testing.assert_allclose(r, r0, rtol=0, atol=1e-12)
        np.testing.assert_allclose(g, g0, rtol=0, atol=1e-9)
    assert on > 20  # samples farther than the margin from every point, within the cap


def test_silhouette_kernel_gradient_matches_finite_differences():
    rng = np.random.default_rng(3)
    cams, masks = _views(rng, 2)
    sil = SilhouetteCoverage(cams, masks, 60, 1.0, seed=0, cap=25.0)
    P = rng.normal(scale=0.15, size=(200, 3))

    def energy(P):
        r = sil.residuals(P)[0]
        return 0.5 * r @ r

    r, a = sil.residuals(P)
    grad, h = r[:, None] * a, 1e-7
    for _ in range(3):
        d = rng.normal(size=P.shape)
        fd = (energy(P + h * d) - energy(P - h * d)) / (2 * h)
        # central differences: O(h²); no sample changes its nearest point over ±h
        assert abs(np.sum(grad * d) - fd) <= 1e-6 * max(1e-3, abs(fd)), (np.sum(grad * d), fd)


def test_quad_skinning_kernel_equals_the_array_code():
    t = load_template("neutral_5k")
    sk = QuadSkinning(oqr := build_oqr(t), t)
    rng = np.random.default_rng(0)
    for _ in range(5):
        R = so3_exp(rng.normal(scale=0.4, size=(t.skeleton.n_joints, 3)))
        c, Q = quads_from_pose(oqr, t, R, rng.normal(size=3))
        np.testing.assert_allclose(
            sk.transforms(c, Q), sk.transforms_reference(c, Q), rtol=0, atol=1e-12
        )


def test_skinned_points_kernel_equals_apply_skinning_to_the_bit():
    """The compiled skinning of the sampled points sums in scipy's order: the same bits."""
    from meshmocap.body.procedural import walk
    from meshmocap.body.skinning import apply_skinning
    from meshmocap.body.template import load_template
    from meshmocap.trackers.cage.oqr import build_oqr, configuration_vector, quads_from_pose
    from meshmocap.trackers.cage.surface import SkinnedSurface

    t = load_template("neutral_5k")
    oqr = build_oqr(t)
    m = walk(t, duration=0.5, fps=10.0)
    c, Q = quads_from_pose(oqr, t, m.rotations, m.root_positions)
    s = SkinnedSurface(oqr, t, np.random.default_rng(0).choice(len(t.V), 300, replace=False))
    for k in range(len(c)):
        y = configuration_vector(c[k], Q[k])
        A = s.transforms(y, Q[k, 0], c[k, 0])[0]
        np.testing.assert_array_equal(s.points(y, Q[k, 0], c[k, 0]), apply_skinning(s._S, A))


def test_gram_schmidt_kernel_equals_the_array_code_to_the_bit():
    """The quads' frames, compiled, are the array code's numbers: the tracker's results do
    not move (axes of every scale, nearly parallel pairs, strided views as the tracker
    passes them)."""
    rng = np.random.default_rng(5)
    Y = rng.normal(size=(200, 3, 3)) * 10.0 ** rng.uniform(-3, 3, size=(200, 1, 1))
    Y[:20, 2] = Y[:20, 1] + 1e-7 * rng.normal(size=(20, 3))  # nearly parallel axes
    R = gram_schmidt(Y[:, 1], Y[:, 2])
    assert np.array_equal(R, gram_schmidt_reference(Y[:, 1], Y[:, 2]))
    assert np.abs(np.swapaxes(R[20:], 1, 2) @ R[20:] - np.eye(3)).max() < 1e-12


def test_contour_kernel_equals_label_then_erosion_in_their_order():
    """A mask's pieces and contour, compiled, are those of ``ndimage.label`` (pieces below
    ``min_component`` of the largest dropped) and ``np.nonzero(m & ~binary_erosion(m))``:
    the same pixels in the same order (the silhouette samples drawn from them do not move);
    masks touching the image's edges, empty, full, a single pixel, thin lines, many pieces."""
    from scipy import ndimage

    rng = np.random.default_rng(11)
    masks = [ndimage.binary_opening(rng.random((40, 60)) < p) for p in (0.3, 0.6, 0.9)]
    masks += [rng.random((30, 30)) < p for p in (0.2, 0.5)]  # many small pieces
    masks += [np.zeros((5, 7), bool), np.ones((5, 7), bool), np.eye(6, dtype=bool)]
    masks += [np.zeros((1, 1), bool) | True, rng.random((1, 9)) < 0.5, rng.random((9, 1)) < 0.5]
    for m in masks:
        for frac in (0.0, 0.02, 0.3, 1.0):
            kept = m
            lab, n = ndimage.label(m)
            if frac > 0 and n > 1:
                size = np.bincount(lab.ravel())[1:]
                kept = np.isin(lab, 1 + np.flatnonzero(size >= frac * size.max()))
            rows, cols = np.nonzero(kept & ~ndimage.binary_erosion(kept))
            found = contour_pixels(np.ascontiguousarray(m), frac, 3, 5)  # m at row 3, col 5
            assert np.array_equal(found[0], rows + 3) and np.array_equal(found[1], cols + 5)
