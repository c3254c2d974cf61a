"""Foreground segmentation: background models, shadows, clean-up, multi-view consistency."""

import numpy as np
import pytest

from meshmocap.errors import InputError
from meshmocap.geometry.camera import Camera, intrinsics, look_at
from meshmocap.geometry.foreground import (
    clean_mask,
    colour_model,
    consistent_masks,
    foreground_mask,
    grow_mask,
    learn_background,
    others_reach,
    others_silhouettes,
    reach,
    restore_background,
)


def _scene(n=12, H=40, W=50, seed=0):
    """A textured background and a bright square moving across it (its masks too)."""
    rng = np.random.default_rng(seed)
    bg = rng.integers(40, 200, (H, W, 3)).astype(np.uint8)
    frames = np.repeat(bg[None], n, axis=0)
    masks = np.zeros((n, H, W), bool)
    for k in range(n):
        c = 2 + 3 * k
        masks[k, 10:22, c : c + 10] = True
    frames[masks] = (250, 30, 30)
    noise = rng.normal(0, 1.5, frames.shape)
    return np.clip(frames + noise, 0, 255).astype(np.uint8), bg, masks


def test_learned_background_is_the_scene_without_the_subject():
    frames, bg, masks = _scene()
    B, noise = learn_background(frames)
    assert np.abs(B - bg).max() <= 6  # the subject covers each pixel in < half the frames
    assert noise.shape == bg.shape[:2] and noise.min() >= 3.0
    # masked median: a subject standing still for most frames is left out where masks say
    still = frames.copy()
    still[:8, 10:22, 20:30] = (250, 30, 30)
    m = masks.copy()
    m[:8, 10:22, 20:30] = True
    plain, _ = learn_background(still)
    masked, _ = learn_background(still, masks=m, min_frames=3)  # 4 frames see the floor
    assert np.abs(plain[15, 25] - (250, 30, 30)).max() < 10  # the plain median is the ghost
    assert np.abs(masked[15, 25] - bg[15, 25]).max() <= 6
    with pytest.raises(InputError, match="frames must be"):
        learn_background(frames[..., 0])


def test_foreground_mask_finds_the_subject_and_not_its_shadow():
    frames, bg, masks = _scene()
    B, noise = learn_background(frames)
    image = frames[5].astype(float)
    shadow = np.zeros(bg.shape[:2], bool)
    shadow[28:36, 5:45] = True
    image[shadow] *= 0.6  # a floor shadow: darker, same chromaticity
    m = foreground_mask(image, B, noise, blur=0.0)  # a 12×10 px subject: no smoothing
    iou = (m & masks[5]).sum() / (m | masks[5]).sum()
    assert iou > 0.95
    assert m[shadow].mean() < 0.05
    very_dark = image.copy()
    very_dark[shadow] = 5.0  # a black object is not a shadow
    assert foreground_mask(very_dark, B, noise)[shadow].mean() > 0.9


def test_clean_mask_fills_small_holes_keeps_gaps_and_drops_specks():
    m = np.zeros((100, 100), bool)
    m[10:90, 10:70] = True  # 4800 px
    m[20:23, 15:18] = False  # a small hole (9 px, 0.19 %): a part of the background's colour
    m[50:60, 30:40] = False  # a gap (100 px, 2 %): the room seen between arm and trunk
    m[95, 95] = True  # a speck
    m[92:95, 80:83] = True  # a small blob (9 px)
    out = clean_mask(m, min_area=20 / m.size)
    assert out[21, 16] and not out[95, 95] and not out[93, 81]
    assert not out[51:59, 31:39].any()
    assert out[11:89, 11:29].all() and abs(int(out.sum()) - int(m.sum())) <= 30  # corners
    assert clean_mask(m, max_hole=np.inf)[51:59, 31:39].all()


def _rig(n=4, size=(64, 48)):
    cams = []
    for k in range(n):
        a = 2 * np.pi * k / n
        R, t = look_at([3 * np.cos(a), 3 * np.sin(a), 1.5], [0.0, 0.0, 1.0])
        cams.append(Camera(intrinsics(*size, 50.0), R, t, *size, None, f"c{k}"))
    return cams


def _sphere_mask(cam, centre, radius):
    v, u = np.mgrid[: cam.height, : cam.width]
    Kinv = np.linalg.inv(cam.K)
    rays = np.stack([u, v, np.ones_like(u)], -1).reshape(-1, 3) @ Kinv.T @ cam.R  # world dirs
    rays /= np.linalg.norm(rays, axis=1, keepdims=True)
    oc = np.asarray(centre) - cam.centre
    along = rays @ oc
    d2 = oc @ oc - along**2
    return (d2 < radius**2).reshape(cam.shape)


def test_consistency_drops_what_the_other_cameras_do_not_see():
    cams = _rig()
    truth = [_sphere_mask(c, [0.0, 0.0, 1.0], 0.3) for c in cams]
    masks = [m.copy() for m in truth]
    masks[0][2:8, 2:8] = True  # clutter seen by camera 0 only
    out = consistent_masks(masks, cams, voxel_size=0.03)
    assert not out[0][2:8, 2:8].any()
    for m, t in zip(out, truth, strict=True):
        assert (m & t).sum() / t.sum() > 0.97  # the sphere stays
    reaches = others_reach([truth[0], truth[1], np.zeros_like(truth[2]), truth[3]], cams)
    assert reaches[2] is not None and reaches[2][truth[2]].mean() > 0.97
    with pytest.raises(InputError, match="3 masks for 4 cameras"):
        consistent_masks(masks[:3], cams)


def test_others_silhouettes_show_the_part_one_camera_lost():
    cams = _rig()
    truth = [_sphere_mask(c, [0.0, 0.0, 1.0], 0.3) for c in cams]
    masks = [m.copy() for m in truth]
    masks[0][: masks[0].shape[0] // 2] = False  # camera 0 lost the sphere's upper half
    views = others_silhouettes(masks, cams, voxel_size=0.02)
    lost = truth[0] & ~masks[0]
    assert views[0][lost].mean() > 0.97  # every other camera still sees it there
    assert views[0][truth[0]].mean() > 0.97
    assert views[0].sum() < 1.5 * truth[0].sum()  # a hull of three, a little larger
    few = others_silhouettes([truth[0], truth[1], *[np.zeros_like(t) for t in truth[2:]]], cams)
    assert few[0] is None and few[1] is None  # one other camera only: a cone
    assert few[2] is not None
    with pytest.raises(InputError, match="3 masks for 4 cameras"):
        others_silhouettes(masks[:3], cams)


def test_reach_covers_the_projected_cubes():
    (cam,) = _rig(1)
    X = np.array([[0.0, 0.0, 1.0]])
    r = reach(X, cam, 0.1)
    uv, _ = cam.project(X)
    c, row = np.round(uv[0]).astype(int)
    assert r[row, c] and r.sum() < 0.2 * r.size


def _stays(n=20, H=60, W=60, seed=3):
    """A smooth background and a subject that stays: at one place in 16 of 20 frames,
    leaning 12 pixels right in the other 4; its masks too."""
    rng = np.random.default_rng(seed)
    y, x = np.mgrid[:H, :W]
    bg = np.stack([60 + 2 * x, 80 + y, 150 - x], -1).astype(np.float64)
    frames = np.repeat(bg[None], n, axis=0)
    masks = np.zeros((n, H, W), bool)
    for k in range(n):
        c = 16 if k < 16 else 28
        masks[k, 14:46, c : c + 18] = True
    frames[masks] = (230, 190, 160)  # skin-like, far from the background around it
    frames = np.clip(frames + rng.normal(0, 1.5, frames.shape), 0, 255).astype(np.uint8)
    return frames, bg, masks


def test_restored_background_takes_out_a_subject_who_stays():
    frames, bg, masks = _stays()
    B, noise = learn_background(frames)
    covered = masks.mean(axis=0) > 0.5
    assert np.abs(B - bg).max(axis=2)[covered].min() > 60  # the median is the subject
    R, noise2, envelope = restore_background(frames, B, noise)
    assert envelope[covered].all() and not envelope[:, :8].any()
    err = np.abs(R - bg).max(axis=2)
    leaves = covered & ~masks[16:].all(axis=0)  # the subject leaves these in 4 frames
    assert np.median(err[leaves]) < 8  # the second colour is the background's
    assert np.median(err[covered]) < 25  # never left: brought in from around
    assert noise2[envelope].min() == 6.0 and np.array_equal(noise2[~envelope], noise[~envelope])
    found = foreground_mask(frames[0], R, noise2)
    iou = (found & masks[0]).sum() / (found | masks[0]).sum()
    assert iou > 0.9
    plain = foreground_mask(frames[0], B, noise)
    assert (plain & masks[0]).sum() / (plain | masks[0]).sum() < 0.3
    with pytest.raises(InputError, match="must agree"):
        restore_background(frames[:, :10], B, noise)


def test_grow_mask_recovers_the_subjects_colours_that_touch_it():
    rng = np.random.default_rng(4)
    H, W = 60, 60
    image = np.full((H, W, 3), (40, 120, 200), np.float64)  # a blue room
    image[:, 45:] = (200, 200, 60)  # and a yellow wall on the right
    truth = np.zeros((H, W), bool)
    truth[10:50, 20:35] = True
    image[truth] = (220, 170, 140)
    image[30:50, 20:35] = (30, 30, 30)  # dark shorts
    image[5:10, 50:55] = (220, 170, 140)  # something of the subject's colour, apart
    image = np.clip(image + rng.normal(0, 2, image.shape), 0, 255).astype(np.uint8)
    seen = truth.copy()
    seen[15:28, 20:35] = False  # differencing lost the trunk in this frame
    model = colour_model(image[None].repeat(2, 0), np.stack([truth, truth]))
    grown = grow_mask(image, seen, model)
    assert (grown & truth).sum() / (grown | truth).sum() > 0.95
    assert not (grown & ~truth).any()  # no rim of the room's pixels beside the subject
    assert not grown[5:10, 50:55].any()  # not connected: left out
    assert not grow_mask(image, np.zeros_like(seen), model).any()
    within = np.zeros((H, W), bool)
    within[10:22] = True  # the others' view holds only the upper part of what was lost
    part = grow_mask(image, seen, model, within=within)
    assert part[15:22, 20:35].all() and not part[22:28, 20:35].any()
    with pytest.raises(InputError, match="within must be"):
        grow_mask(image, seen, model, within=within[:5])
    with pytest.raises(InputError, match="bins must be"):
        colour_model(image[None], truth[None], bins=10)
