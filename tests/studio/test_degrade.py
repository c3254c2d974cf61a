"""Seeded silhouette degradations."""

import numpy as np
import pytest
from scipy import ndimage
from scipy.stats import norm

from meshmocap.errors import InputError
from meshmocap.studio.degrade import (
    Degradation,
    add_blobs,
    degrade,
    jitter_boundary,
    punch_holes,
    remove_limb,
)

H, W = 240, 320
RADIUS = 60


def _disc() -> np.ndarray:
    yy, xx = np.mgrid[:H, :W]
    return (xx - 160) ** 2 + (yy - 120) ** 2 <= RADIUS**2


def _figure() -> np.ndarray:
    """A crude standing person: a body block and one arm reaching out to the right."""
    m = np.zeros((H, W), dtype=bool)
    m[40:200, 130:170] = True  # body
    m[80:90, 170:260] = True  # arm, its hand at column 259
    return m


DEGRADATIONS = [
    lambda m, s: jitter_boundary(m, amplitude=1.5, seed=s),
    lambda m, s: punch_holes(m, count=4, radius=4, seed=s),
    lambda m, s: add_blobs(m, count=3, radius=5, seed=s),
    lambda m, s: remove_limb(m, seed=s),
    lambda m, s: degrade(m, Degradation(jitter=1.0, holes=2, blobs=2, missed_limb=True), seed=s),
]


@pytest.mark.parametrize("func", DEGRADATIONS)
def test_deterministic_for_a_seed_and_pure(func):
    m = _figure()
    before = m.copy()
    a, b = func(m, 7), func(m, 7)
    assert np.array_equal(a, b) and a.dtype == bool and a.shape == m.shape
    assert np.array_equal(m, before)  # the input is untouched
    assert not np.array_equal(a, m)
    assert any(not np.array_equal(a, func(m, s)) for s in (8, 9))  # seeds matter
    assert np.array_equal(func(m, np.random.default_rng(3)), func(m, np.random.default_rng(3)))


def test_jitter_changes_perimeter_times_mean_offset():
    # Pixels at signed distance ±(k + ½) from the outline flip when the offset field
    # (std a) crosses them: per unit of perimeter, Σ_k 2·Q((k + ½)/a) ≈ 1.58 px for a = 2.
    # Averaged over 4 seeds the offset field has ~4·2πR/(3·correlation) ≈ 125 independent
    # stretches of outline: ±5 % of noise, plus a few % of discretisation: tolerance 15 %.
    m, a = _disc(), 2.0
    expect = 2 * np.pi * RADIUS * sum(2 * norm.sf((k + 0.5) / a) for k in range(40))
    changed = [(jitter_boundary(m, amplitude=a, seed=s) != m).sum() for s in range(4)]
    assert np.mean(changed) == pytest.approx(expect, rel=0.15)
    # No pixel farther than 5 σ from the outline changes.
    j = jitter_boundary(m, amplitude=a, seed=0)
    far = ndimage.distance_transform_edt(m) + ndimage.distance_transform_edt(~m) > 5 * a + 1
    assert np.array_equal(j[far], m[far])
    assert np.array_equal(jitter_boundary(m, amplitude=0.0, seed=0), m)


def test_holes_are_inside_and_of_the_expected_size():
    m = _disc()
    out = punch_holes(m, count=5, radius=4, seed=1)
    removed = m & ~out
    assert not (out & ~m).any()  # only removes
    # The outline and the pixel ring inside it are untouched (centres ≥ radius + 2 deep).
    assert np.array_equal(
        out[ndimage.distance_transform_edt(m) <= 2], m[ndimage.distance_transform_edt(m) <= 2]
    )
    # Each hole is an ellipse with semi-axes in [2, 4] px: 4π ≤ area ≤ 16π each, up to
    # pixel rounding (±perimeter/2) and overlaps (fewer pixels).
    assert removed.sum() <= 5 * np.pi * 4.5**2
    assert removed.sum() >= np.pi * 1.5**2
    _, n_background = ndimage.label(~out)
    assert 2 <= n_background <= 6  # the outside plus one component per separate hole


def test_blobs_are_added_near_the_body():
    m = _disc()
    out = add_blobs(m, count=3, radius=5, seed=2, distance=30)
    added = out & ~m
    assert not (m & ~out).any() and added.any()
    # Blob centres are 7.5–30 px from the body; blobs reach ≤ 5 px (+½ rounding) further.
    dist = ndimage.distance_transform_edt(~m)[added]
    assert dist.min() >= 7.5 - 5.5 and dist.max() <= 30 + 5.5
    assert added.sum() <= 3 * np.pi * 5.5**2
    _, n = ndimage.label(out)
    assert 2 <= n <= 4  # the body plus separate blobs


def test_missed_limb_at_a_point_and_at_an_extremity():
    m = _figure()
    out = remove_limb(m, seed=0, point=(262.0, 84.0), radius=40)  # near the hand
    removed = m & ~out
    # The removed chunk: exactly the arm pixels within 40 px of the silhouette pixel
    # nearest the point, (row 84, column 259); the body (columns < 170) is out of reach.
    yy, xx = np.mgrid[:H, :W]
    expect = m & ((yy - 84) ** 2 + (xx - 259) ** 2 <= 40**2)
    assert np.array_equal(removed, expect) and 390 < expect.sum() <= 410
    # Without a point it removes an extremity: the silhouette pixel farthest along a
    # random direction, and a connected chunk around it.
    for seed in range(4):
        out = remove_limb(m, seed=seed)
        removed = m & ~out
        assert 0 < removed.sum() < 0.25 * m.sum()
        assert ndimage.label(removed, structure=np.ones((3, 3)))[1] == 1
        assert not (out & ~m).any()


def test_degrade_streams_are_independent():
    # Switching blobs on does not change the holes: each step has its own random stream.
    m = _disc()
    holes = degrade(m, Degradation(holes=3), seed=5)
    both = degrade(m, Degradation(holes=3, blobs=2), seed=5)
    assert np.array_equal(holes & m, both & m) and (both & ~m).any()
    assert np.array_equal(degrade(m, Degradation(), seed=5), m)


def test_bad_arguments():
    m = _disc()
    with pytest.raises(InputError, match="jitter must be from 0 to 20 pixels"):
        Degradation(jitter=-1.0)
    with pytest.raises(InputError, match="holes must be a whole number"):
        Degradation(holes=1.5)
    with pytest.raises(InputError, match="seed must be"):
        jitter_boundary(m, amplitude=1.0, seed=None)
    with pytest.raises(InputError, match="bool array"):
        punch_holes(m.astype(np.uint8), count=1, radius=3, seed=0)
    with pytest.raises(InputError, match="spec must be a Degradation"):
        degrade(m, {"holes": 1}, seed=0)
