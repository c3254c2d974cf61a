"""The fit-quality check names the limb standing outside the observations and the
observations it leaves unexplained."""

import numpy as np
import pytest

from meshmocap.estimate.recovery.quality import fit_quality, limb_labels, uncovered_points
from toys import observed_frame


def test_fit_quality_names_the_limb_outside_and_unexplained(walker):
    t, R, root, posed = walker
    labels = limb_labels(t)
    obs = observed_frame(posed.V, t.F)  # the true surface, closed
    P, field = obs.points[0], obs.field
    good = fit_quality(posed.V, labels, P, field)
    assert good.lost == () and max(good.outside.values()) < 0.02
    down = R.copy()
    down[t.skeleton.index("LeftArm")] = np.eye(3)
    q = fit_quality(t.pose(down, root).V, labels, P, field)
    assert q.lost == ("left_arm",)
    assert q.outside["left_arm"] > 0.25 and q.unexplained["left_arm"] > 0.02
    assert "left_arm (" in q.describe() and "outside the observations" in q.describe()


def test_unexplained_points_by_the_trunk_count_for_the_nearest_other_limb(walker, monkeypatch):
    """An arm held away from the body while the observations have it hanging by the trunk:
    its points nearest the tracked trunk are counted for the nearest vertex of another
    limb; the points unexplained in all are the same."""
    from meshmocap.estimate.recovery import quality

    t, R, root, posed = walker
    labels = limb_labels(t)
    hang = R.copy()
    hang[[t.skeleton.index(n) for n in ("LeftArm", "LeftForeArm")]] = np.eye(3)
    obs = observed_frame(t.pose(hang, root).V, t.F)
    P, field = obs.points[0], obs.field
    q = fit_quality(posed.V, labels, P, field)  # the tracked arm in the T-pose
    assert q.unexplained["torso"] == 0.0 and q.total_unexplained > 0.05
    monkeypatch.setattr(quality, "UNEXPLAINED_ELSEWHERE", ())
    q0 = fit_quality(posed.V, labels, P, field)
    assert q0.unexplained["torso"] > 0.0
    assert q.total_unexplained == pytest.approx(q0.total_unexplained, abs=1e-12)


def _uncovered_by_images(V, F, P, cameras, masks):
    """The definition: whole eroded masks and whole rendered silhouettes, every point."""
    from scipy import ndimage

    from meshmocap.geometry.camera import project
    from meshmocap.geometry.silhouette import silhouette

    hit = np.zeros(len(P), dtype=bool)
    for cam, mask in zip(cameras, masks, strict=True):
        miss = ndimage.binary_erosion(mask) & ~silhouette(V, F, cam, assume_closed=True)
        uv, depth = project(P, cam.K, cam.R, cam.t)
        px = np.round(uv).astype(np.int64)
        ok = (depth > 0) & (px[:, 0] >= 0) & (px[:, 0] < mask.shape[1])
        ok &= (px[:, 1] >= 0) & (px[:, 1] < mask.shape[0])
        hit[ok] |= miss[px[ok, 1], px[ok, 0]]
    return hit


def test_uncovered_points_looked_up_per_point_is_the_image_definition(walker):
    from meshmocap.geometry.camera import Camera, intrinsics, look_at
    from meshmocap.geometry.silhouette import silhouette

    t, R, root, posed = walker
    eyes = [root + [3 * np.cos(a), 3 * np.sin(a), 0.2] for a in (0.3, 2.0, 4.0)]
    K = intrinsics(160, 120, 60.0)
    cams = [Camera(K, *look_at(e, root), 160, 120, None, f"C{i}") for i, e in enumerate(eyes)]
    truth = posed.V
    masks = [silhouette(truth, t.F, c, assume_closed=True) for c in cams]
    down = R.copy()
    down[t.skeleton.index("LeftArm")] = np.eye(3)  # the model's arm elsewhere
    V = t.pose(down, root).V
    rng = np.random.default_rng(3)
    P = np.concatenate([truth[rng.choice(len(truth), 1500, replace=False)], [root + 9.0]])
    got = uncovered_points(V, t.F, P, cams, masks)
    assert np.array_equal(got, _uncovered_by_images(V, t.F, P, cams, masks))
    assert 0 < got.sum() < len(P) // 2  # the real arm's points, not the rest
