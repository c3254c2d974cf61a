"""Visual hulls by voxel carving, hull meshes and signed-distance grids.

Silhouettes are exact: sphere and capsule masks test each pixel centre's viewing ray
analytically; the box's is rasterised from its 12 triangles (exact for a polyhedron).
"""

import numpy as np
import pytest
from scipy import ndimage

from meshmocap.errors import InputError
from meshmocap.geometry.camera import Camera, intrinsics, look_at
from meshmocap.geometry.carving import (
    DistanceGrid,
    VoxelHull,
    carve,
    distance_grid,
    distance_grid_from_mesh,
    hull_bounds,
    hull_mesh,
)
from meshmocap.geometry.mesh import edges_unique, signed_volume
from meshmocap.geometry.raster import coverage

W, H = 320, 240
SPHERE_C, SPHERE_R = np.array([0.1, -0.05, 1.0]), 0.3
CAPSULE = np.array([[-0.15, 0.0, 0.35], [0.2, 0.1, 1.35]]), 0.15
BOX = np.array([[-0.25, -0.15, 0.2], [0.2, 0.25, 0.9]])


def rig(n: int, *, radius: float = 3.5, dist=None) -> list[Camera]:
    """``n`` cameras on a ring around (0, 0, 0.9), alternately high and low."""
    cams = []
    for i in range(n):
        a = 2 * np.pi * (i + 0.3) / n
        eye = [radius * np.cos(a), radius * np.sin(a), 2.6 if i % 2 == 0 else 1.4]
        R, t = look_at(eye, [0.0, 0.0, 0.9])
        cams.append(Camera(intrinsics(W, H, 55.0), R, t, W, H, dist=dist, name=f"cam{i}"))
    return cams


def pixel_rays(cam: Camera) -> tuple[np.ndarray, np.ndarray]:
    """Camera centre (3,) and unit world directions (H, W, 3) through the pixel centres."""
    v, u = np.mgrid[0 : cam.height, 0 : cam.width].astype(float)
    d = np.stack([u, v, np.ones_like(u)], axis=-1) @ np.linalg.inv(cam.K).T @ cam.R
    return cam.centre, d / np.linalg.norm(d, axis=-1, keepdims=True)


def sphere_mask(cam: Camera, c=SPHERE_C, r=SPHERE_R) -> np.ndarray:
    o, d = pixel_rays(cam)
    s = d @ (c - o)
    return (s > 0) & (np.sum((c - o) ** 2) - s**2 <= r * r)


def capsule_mask(cam: Camera) -> np.ndarray:
    """Pixels whose ray passes within r of the capsule's segment (closest points)."""
    (a, b), r = CAPSULE
    o, d = pixel_rays(cam)
    e, w = b - a, o - a
    dd, de, ee = 1.0, d @ e, e @ e
    dw, ew = d @ w, e @ w
    den = dd * ee - de**2
    t = np.clip((dd * ew - de * dw) / den, 0.0, 1.0)  # on the segment
    s = np.maximum((t * de - dw) / dd, 0.0)  # on the ray, then back onto the segment
    t = np.clip((s * de + ew) / ee, 0.0, 1.0)
    gap = o + s[..., None] * d - (a + t[..., None] * e)
    return np.sum(gap**2, axis=-1) <= r * r


def box_mesh(lo, hi) -> tuple[np.ndarray, np.ndarray]:
    V = np.array(
        [[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])]
    )
    F = np.array(
        [
            [0, 1, 3],
            [0, 3, 2],
            [4, 6, 7],
            [4, 7, 5],
            [0, 4, 5],
            [0, 5, 1],
            [2, 3, 7],
            [2, 7, 6],
            [0, 2, 6],
            [0, 6, 4],
            [1, 5, 7],
            [1, 7, 3],
        ]
    )
    return V, F


def box_mask(cam: Camera) -> np.ndarray:
    V, F = box_mesh(*BOX)
    return coverage(cam.project(V)[0], F, cam.shape)


def icosphere(level: int, r: float) -> tuple[np.ndarray, np.ndarray]:
    t = (1 + 5**0.5) / 2
    V = np.array(
        [
            [-1, t, 0],
            [1, t, 0],
            [-1, -t, 0],
            [1, -t, 0],
            [0, -1, t],
            [0, 1, t],
            [0, -1, -t],
            [0, 1, -t],
            [t, 0, -1],
            [t, 0, 1],
            [-t, 0, -1],
            [-t, 0, 1],
        ]
    )
    F = np.array(
        [
            [0, 11, 5],
            [0, 5, 1],
            [0, 1, 7],
            [0, 7, 10],
            [0, 10, 11],
            [1, 5, 9],
            [5, 11, 4],
            [11, 10, 2],
            [10, 7, 6],
            [7, 1, 8],
            [3, 9, 4],
            [3, 4, 2],
            [3, 2, 6],
            [3, 6, 8],
            [3, 8, 9],
            [4, 9, 5],
            [2, 4, 11],
            [6, 2, 10],
            [8, 6, 7],
            [9, 8, 1],
        ]
    )
    V = V / np.linalg.norm(V, axis=1, keepdims=True)
    for _ in range(level):
        E, inv = np.unique(
            np.sort(np.concatenate([F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]]), axis=1),
            axis=0,
            return_inverse=True,
        )
        mid = V[E].mean(axis=1)
        m = len(V) + inv.reshape(3, -1).T
        V = np.vstack([V, mid / np.linalg.norm(mid, axis=1, keepdims=True)])
        (a, b, c), (ab, bc, ca) = F.T, m.T
        F = np.vstack([np.c_[a, ab, ca], np.c_[b, bc, ab], np.c_[c, ca, bc], np.c_[ab, bc, ca]])
    return V * r, F


def fibonacci_sphere(n: int) -> np.ndarray:
    k = np.arange(n) + 0.5
    z = 1 - 2 * k / n
    phi = np.pi * (1 + 5**0.5) * k
    rho = np.sqrt(1 - z * z)
    return np.stack([rho * np.cos(phi), rho * np.sin(phi), z], axis=1)


def sphere_surface(n=4000) -> np.ndarray:
    return SPHERE_C + SPHERE_R * fibonacci_sphere(n)


def capsule_surface(n=4000, seed=0) -> np.ndarray:
    (a, b), r = CAPSULE
    rng = np.random.default_rng(seed)
    e = (b - a) / np.linalg.norm(b - a)
    p = np.cross(e, [1.0, 0, 0])
    p /= np.linalg.norm(p)
    q = np.cross(e, p)
    t, ang = rng.uniform(0, 1, n), rng.uniform(0, 2 * np.pi, n)
    side = a + t[:, None] * (b - a) + r * (np.cos(ang)[:, None] * p + np.sin(ang)[:, None] * q)
    cap = r * fibonacci_sphere(2 * n)
    ends = np.vstack([a + cap[cap @ e < 0], b + cap[cap @ e > 0]])
    return np.vstack([side, ends])


def box_surface(n=4000, seed=0) -> np.ndarray:
    lo, hi = BOX
    rng = np.random.default_rng(seed)
    P = rng.uniform(lo, hi, (n, 3))
    axis, side = rng.integers(0, 3, n), rng.integers(0, 2, n)
    P[np.arange(n), axis] = np.where(side == 1, hi[axis], lo[axis])
    return P


def within_one_voxel(hull: VoxelHull, P: np.ndarray) -> np.ndarray:
    """(n,) bool: ``P`` lies in an occupied voxel's cell or within one voxel of one."""
    grown = ndimage.binary_dilation(np.pad(hull.occupancy, 2), np.ones((3, 3, 3), bool))
    idx = np.rint((P - hull.origin) / hull.voxel_size).astype(int) + 2
    ok = np.all((idx >= 0) & (idx < grown.shape), axis=1)
    out = np.zeros(len(P), dtype=bool)
    out[ok] = grown[tuple(idx[ok].T)]
    return out


def brute_force(masks, cameras, hull: VoxelHull) -> tuple[np.ndarray, np.ndarray]:
    """Occupancy by projecting every voxel centre with Camera.project, and the voxels
    that project within 1e-6 px of a pixel border in some view (rounding decides)."""
    X = hull.origin + np.indices(hull.occupancy.shape).reshape(3, -1).T * hull.voxel_size
    ok = np.ones(len(X), dtype=bool)
    tie = np.zeros(len(X), dtype=bool)
    for m, cam in zip(masks, cameras, strict=True):
        uv, z = cam.project(X)
        c, r = np.floor(uv[:, 0] + 0.5), np.floor(uv[:, 1] + 0.5)
        v = (z > 0) & (c >= 0) & (c < cam.width) & (r >= 0) & (r < cam.height)
        v[v] = m[r[v].astype(int), c[v].astype(int)]
        ok &= v
        tie |= np.any(np.abs(uv + 0.5 - np.rint(uv + 0.5)) < 1e-6, axis=1)
    return ok.reshape(hull.occupancy.shape), tie.reshape(hull.occupancy.shape)


def assert_same_as_brute_force(masks, cameras, hull: VoxelHull) -> None:
    expect, tie = brute_force(masks, cameras, hull)
    assert tie.mean() < 0.01
    assert np.array_equal(hull.occupancy[~tie], expect[~tie])


SHAPES = {
    "sphere": (sphere_mask, sphere_surface, 4 / 3 * np.pi * SPHERE_R**3),
    "capsule": (
        capsule_mask,
        capsule_surface,
        np.pi * CAPSULE[1] ** 2 * np.linalg.norm(np.subtract(*CAPSULE[0]))
        + 4 / 3 * np.pi * CAPSULE[1] ** 3,
    ),
    "box": (box_mask, box_surface, float(np.prod(BOX[1] - BOX[0]))),
}


@pytest.mark.parametrize("n_cams", [4, 8])
@pytest.mark.parametrize("shape", ["sphere", "capsule", "box"])
def test_hull_contains_the_object(shape, n_cams):
    make_mask, surface, true_volume = SHAPES[shape]
    cams = rig(n_cams)
    masks = [make_mask(c) for c in cams]
    hull = carve(masks, cams, voxel_size=0.01)
    # Acceptance criterion: ≥ 99 % of true surface points inside or within one voxel.
    assert within_one_voxel(hull, surface()).mean() >= 0.99
    ratio = hull.volume / true_volume
    # Sampling the silhouettes at pixel centres (~1 cm here) shaves < 3 % off the object.
    assert ratio >= 0.97
    # The default bounds leave an empty border except on the floor (not reached here).
    occ = hull.occupancy
    assert not (occ[[0, -1]].any() or occ[:, [0, -1]].any() or occ[:, :, [0, -1]].any())


def test_more_cameras_carve_less_phantom_volume():
    for shape in ("sphere", "capsule", "box"):
        make_mask = SHAPES[shape][0]
        vols = []
        for n in (4, 8):
            cams = rig(n)
            vols.append(carve([make_mask(c) for c in cams], cams, voxel_size=0.02).volume)
        assert vols[1] < vols[0]


@pytest.mark.parametrize("dist", [None, [-0.25, 0.08, 0.001, -0.002, 0.0]])
def test_coarse_to_fine_equals_projecting_every_voxel(dist):
    cams = rig(4, dist=dist)
    masks = [capsule_mask(c) | sphere_mask(c) for c in cams]  # any masks will do
    hull = carve(masks, cams, voxel_size=0.015, bounds=[[-0.6, -0.6, 0.2], [0.6, 0.6, 1.6]])
    assert hull.occupancy.any()
    assert_same_as_brute_force(masks, cams, hull)
    P = hull.centres()
    b = hull_bounds(masks, cams, margin=0.0)
    assert np.all((b[0] - 1e-9 <= P) & (b[1] + 1e-9 >= P))


def test_points_behind_a_camera_and_outside_images_are_outside():
    cams = rig(2, radius=1.2)
    masks = [np.ones(c.shape, bool) for c in cams]  # everything in view is foreground
    bounds = [[-2.0, -2.0, 0.0], [2.0, 2.0, 3.0]]  # contains both cameras
    hull = carve(masks, cams, voxel_size=0.1, bounds=bounds)
    assert_same_as_brute_force(masks, cams, hull)
    assert 0 < hull.occupancy.mean() < 0.5


def test_bounds_are_conservative_tight_and_above_the_floor():
    cams = rig(4)
    masks = [capsule_mask(c) for c in cams]
    b = hull_bounds(masks, cams, margin=0.0, resolution=0.02)
    wide = carve(masks, cams, voxel_size=0.02, bounds=[[-1, -1, 0], [1, 1, 2]])
    P = wide.centres()
    assert np.all((b[0] - 1e-9 <= P) & (b[1] + 1e-9 >= P))
    assert np.all(b[0] >= P.min(axis=0) - 0.05) and np.all(b[1] <= P.max(axis=0) + 0.05)
    low = hull_bounds(masks, cams, floor=0.6, margin=0.1)
    assert low[0, 2] == 0.6
    assert hull_bounds(masks, cams, margin=0.1)[0, 2] == pytest.approx(b[0, 2] - 0.1)


def test_one_camera_with_explicit_bounds():
    cam = rig(1)[0]
    mask = sphere_mask(cam)
    hull = carve([mask], [cam], voxel_size=0.02, bounds=[[-0.5, -0.5, 0.5], [0.5, 0.5, 1.5]])
    assert_same_as_brute_force([mask], [cam], hull)
    b = hull_bounds([mask], [cam], max_depth=6.0)
    assert np.all(np.isfinite(b)) and b[0, 2] == 0.0


def test_hull_mesh_is_watertight_outward_and_in_world_units():
    cams = rig(4)
    masks = [capsule_mask(c) for c in cams]
    hull = carve(masks, cams, voxel_size=0.01)
    V, F = hull_mesh(hull)
    _, counts = edges_unique(F)
    assert np.all(counts == 2)
    vol = signed_volume(V, F)
    assert vol > 0 and vol == pytest.approx(hull.volume, rel=0.01)
    lo, hi = hull.bounds
    assert np.all((lo - hull.voxel_size <= V) & (hi + hull.voxel_size >= V))
    # The mesh is the zero level of the distance grid (to within a voxel).
    assert np.abs(distance_grid(hull)(V)).max() <= hull.voxel_size


def test_hull_cut_by_the_floor_is_closed():
    cams = rig(4)
    masks = [capsule_mask(c) for c in cams]
    hull = carve(masks, cams, voxel_size=0.02, floor=0.5)
    assert hull.bounds[0, 2] == 0.5 and hull.occupancy[:, :, 0].any()
    V, F = hull_mesh(hull)
    assert np.all(edges_unique(F)[1] == 2) and signed_volume(V, F) > 0


def test_empty_hull():
    hull = VoxelHull(np.zeros((4, 5, 6), bool), np.zeros(3), 0.1)
    V, F = hull_mesh(hull)
    assert V.shape == (0, 3) and F.shape == (0, 3)
    with pytest.raises(InputError, match="empty"):
        distance_grid(hull)


def analytic_sphere_hull(h=0.02, r=0.3):
    n = int(np.ceil(2 * (r + 0.1) / h)) + 1
    origin = np.full(3, -(r + 0.1))
    X = origin + np.indices((n, n, n)).reshape(3, -1).T * h
    occ = (np.linalg.norm(X, axis=1) < r).reshape(n, n, n)
    return VoxelHull(occ, origin, h)


def test_distance_grid_matches_the_sphere_distance():
    hull = analytic_sphere_hull()
    g = distance_grid(hull, pad=0.05)
    assert distance_grid(hull, pad=0.05) is g  # kept on the hull, not recomputed
    assert g.shape == tuple(np.array(hull.occupancy.shape) + 2 * 4)  # 1 + ceil(0.05 / 0.02)
    rng = np.random.default_rng(1)
    P = rng.uniform(-0.45, 0.45, (5000, 3))
    true = np.linalg.norm(P, axis=1) - 0.3
    assert np.abs(g(P) - true).max() <= hull.voxel_size
    _, grad = g.value_and_gradient(P[np.abs(true) > 0.06])
    radial = P[np.abs(true) > 0.06] / np.linalg.norm(P[np.abs(true) > 0.06], axis=1)[:, None]
    assert np.median(np.sum(grad * radial, axis=1)) > 0.9  # the field grows outwards


def test_distance_grid_from_mesh_matches_the_sphere_distance():
    V, F = icosphere(3, 0.3)
    g = distance_grid_from_mesh(V + 1.0, F, spacing=0.01, margin=0.05)
    X = g.origin + np.indices(g.shape).reshape(3, -1).T * g.spacing
    true = np.linalg.norm(X - 1.0, axis=1) - 0.3
    assert np.abs(g.values.ravel() - true).max() <= 0.01  # one voxel
    flipped = distance_grid_from_mesh(V + 1.0, F[:, ::-1], spacing=0.01, margin=0.05)
    assert np.array_equal(flipped.values, g.values)  # the winding rule ignores orientation


def test_mesh_voxelisation_is_exact_off_the_surface_and_unites_overlaps():
    lo, hi = BOX
    V, F = box_mesh(lo, hi)  # faces fall on grid points: lines through edges and vertices
    V2, F2 = box_mesh(lo + [0.2, 0.0, 0.1], hi + [0.2, 0.0, 0.1])
    g = distance_grid_from_mesh(np.vstack([V, V2]), np.vstack([F, F2 + 8]), spacing=0.01)
    X = g.origin + np.indices(g.shape).reshape(3, -1).T * g.spacing
    inside = (g.values < 0).ravel()

    def depth(lo, hi):  # > 0 strictly inside, < 0 strictly outside, ~0 on the surface
        return np.min(np.minimum(X - lo, hi - X), axis=1)

    d = np.maximum(depth(lo, hi), depth(lo + [0.2, 0, 0.1], hi + [0.2, 0, 0.1]))
    assert np.all(inside[d > 1e-6]) and not np.any(inside[d < -1e-6])


def test_trilinear_gradient_matches_central_differences():
    rng = np.random.default_rng(2)
    g = DistanceGrid(rng.normal(size=(5, 6, 7)), origin=[0.1, -0.2, 0.3], spacing=[0.1, 0.2, 0.15])
    # Points at cell fractions in [0.1, 0.9]: away from the kinks between cells.
    cell = rng.integers(0, [4, 5, 6], (200, 3))
    P = g.origin + (cell + rng.uniform(0.1, 0.9, (200, 3))) * g.spacing
    val, grad = g.value_and_gradient(P)
    assert np.allclose(val, g(P))
    # The interpolant is linear in each coordinate inside a cell, so central differences
    # are exact up to rounding: error ~ eps·|f| / h ≈ 1e-16 / 1e-6 = 1e-10; tolerance 1e-8.
    h = 1e-6
    fd = np.stack([(g(P + h * e) - g(P - h * e)) / (2 * h) for e in np.eye(3)], axis=1)
    assert np.abs(fd - grad).max() < 1e-8
    # At grid points the value is the stored one.
    idx = np.array([[0, 0, 0], [4, 5, 6], [2, 3, 1]])
    assert np.allclose(g(g.origin + idx * g.spacing), g.values[tuple(idx.T)])


def test_outside_the_grid_values_are_finite_continuous_and_grow_away():
    rng = np.random.default_rng(3)
    g = DistanceGrid(rng.normal(size=(4, 4, 4)), origin=np.zeros(3), spacing=0.1)
    far = rng.normal(size=(500, 3)) * 10
    val, grad = g.value_and_gradient(far)
    assert np.all(np.isfinite(val)) and np.all(np.isfinite(grad))
    q = np.clip(far, g.origin, g.upper)
    assert np.allclose(val, g(q) + np.linalg.norm(far - q, axis=1))
    assert np.all(np.sum(grad * (far - q), axis=1) > 0)  # −gradient points back to the box
    # Continuous across the box's faces; gradient checked by differences off the faces.
    face = np.array([[0.35, 0.1, 0.17], [0.1, -0.05, 0.17], [0.15, 0.12, 0.42]])
    assert np.allclose(g(face - [1e-9, 0, 0]), g(face + [1e-9, 0, 0]), atol=1e-7)
    P = np.array([[0.5, 0.13, 0.17], [0.13, -0.2, 0.5], [-0.3, 0.4, 0.05]])
    _, grad = g.value_and_gradient(P)
    h = 1e-6
    fd = np.stack([(g(P + h * e) - g(P - h * e)) / (2 * h) for e in np.eye(3)], axis=1)
    assert np.abs(fd - grad).max() < 1e-6
    assert g(np.zeros((2, 5, 3))).shape == (2, 5)
    with pytest.raises(InputError, match="finite"):
        g(np.array([[np.nan, 0, 0]]))


def test_input_errors_are_one_line_and_name_the_culprit():
    cams = rig(4)
    masks = [sphere_mask(c) for c in cams]
    cases = [
        ((masks[:3], cams), "one per camera"),
        (([*masks[:2], np.zeros((H, W), bool), masks[3]], cams), "camera 'cam2'.*empty"),
        (([*masks[:3], np.ones((W, H), bool)], cams), r"masks\[3\].*\(240, 320\)"),
        (([], []), "at least one"),
    ]
    for args, pattern in cases:
        for fn in (carve, hull_bounds):
            with pytest.raises(InputError, match=pattern) as err:
                fn(*args)
            assert "\n" not in str(err.value)
    with pytest.raises(InputError, match="voxel_size"):
        carve(masks, cams, voxel_size=0.0)
    with pytest.raises(InputError, match="bounds"):
        carve(masks, cams, bounds=[[0, 0, 0], [1, 1]])
    corner = np.zeros((H, W), bool)
    corner[:5, :5] = True  # cam0 sees something far from what the others see
    for fn in (carve, hull_bounds):
        with pytest.raises(InputError, match="do not meet"):
            fn([corner, *masks[1:]], cams)
