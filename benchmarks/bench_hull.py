"""Speed of the visual hull: carve + marching cubes + distance grid at 1 cm.

Target: carving ≤ 150 ms per frame for 4 views of a person at
1 cm voxels (bounds ~1 × 1 × 2 m, ~2 M voxels) on a 2-core machine.

Subject: the bundled ``neutral`` template (A-posed human mesh) when it loads, else a
union of capsules of a person's size. Four 640×480 cameras high in the corners of the
room, ~4.5 m from the subject. Silhouettes are made before timing.

Run: ``python benchmarks/bench_hull.py`` (best of 5 runs per stage).
"""

from __future__ import annotations

import numpy as np

from _timing import best_of
from meshmocap.geometry.camera import Camera, intrinsics, look_at
from meshmocap.geometry.carving import VoxelHull, carve, distance_grid, hull_bounds, hull_mesh
from meshmocap.geometry.mesh import signed_volume
from meshmocap.geometry.raster import coverage

VOXEL = 0.01
REPEAT = 5

# A person of capsules (a, b, radius), metres, Z up, facing −Y: for when no template loads.
CAPSULES = [
    ((0.0, 0.0, 1.05), (0.0, 0.0, 1.45), 0.16),  # torso
    ((0.0, 0.0, 1.55), (0.0, 0.0, 1.65), 0.10),  # head
    ((-0.1, 0.0, 0.1), (-0.1, 0.0, 0.95), 0.075),  # legs
    ((0.1, 0.0, 0.1), (0.1, 0.0, 0.95), 0.075),
    ((-0.2, 0.0, 1.42), (-0.75, 0.0, 1.25), 0.05),  # arms
    ((0.2, 0.0, 1.42), (0.75, 0.0, 1.25), 0.05),
    ((-0.1, -0.05, 0.04), (-0.1, -0.2, 0.04), 0.045),  # feet
    ((0.1, -0.05, 0.04), (0.1, -0.2, 0.04), 0.045),
]


def studio(width: int = 640, height: int = 480) -> list[Camera]:
    """Four cameras high in the corners of a 6 × 6 m room, looking at the centre."""
    cams = []
    for i, (x, y) in enumerate([(3.0, 3.0), (-3.0, 3.0), (-3.0, -3.0), (3.0, -3.0)]):
        R, t = look_at([x, y, 2.6], [0.0, 0.0, 0.95])
        cams.append(Camera(intrinsics(width, height, 60.0), R, t, width, height, name=f"c{i}"))
    return cams


def capsule_masks(cams: list[Camera]) -> list[np.ndarray]:
    masks = []
    for cam in cams:
        v, u = np.mgrid[0 : cam.height, 0 : cam.width].astype(float)
        d = np.stack([u, v, np.ones_like(u)], axis=-1) @ np.linalg.inv(cam.K).T @ cam.R
        d /= np.linalg.norm(d, axis=-1, keepdims=True)
        o, mask = cam.centre, np.zeros(cam.shape, bool)
        for a, b, r in CAPSULES:
            a, b = np.array(a), np.array(b)
            e, w = b - a, o - a
            de, ee, dw, ew = d @ e, e @ e, d @ w, e @ w
            t = np.clip((ew - de * dw) / (ee - de**2), 0, 1)
            s = np.maximum(t * de - dw, 0)
            t = np.clip((s * de + ew) / ee, 0, 1)
            gap = o + s[..., None] * d - (a + t[..., None] * e)
            mask |= np.sum(gap**2, axis=-1) <= r * r
        masks.append(mask)
    return masks


def subject(cams: list[Camera]) -> tuple[str, list[np.ndarray], float | None]:
    """Silhouettes of the template (or the capsules), a label and the true volume."""
    try:
        from meshmocap.body.template import load_template

        t = load_template("neutral")
    except Exception as err:
        print(f"(template unavailable: {err}; using capsules)")
        return "capsule person", capsule_masks(cams), None
    try:
        from meshmocap.geometry.silhouette import silhouette

        masks = [silhouette(t.V, t.F, c) for c in cams]
    except ImportError:
        masks = [coverage(c.project(t.V)[0], t.F, c.shape) for c in cams]
    label = f"template 'neutral' ({len(t.V)} vertices)"
    return label, masks, signed_volume(t.V, t.F)


def main() -> None:
    cams = studio()
    label, masks, true_volume = subject(cams)
    dist = np.linalg.norm(cams[0].centre - [0, 0, 0.95])
    print(f"subject: {label}; 4 cameras 640×480, {dist:.2f} m away; voxel {VOXEL * 100:.0f} cm")
    t_bounds, bounds = best_of(lambda: hull_bounds(masks, cams, margin=2 * VOXEL))
    t_carve, hull = best_of(lambda: carve(masks, cams, voxel_size=VOXEL, bounds=bounds))
    t_all, _ = best_of(lambda: carve(masks, cams, voxel_size=VOXEL))
    t_mesh, (V, F) = best_of(lambda: hull_mesh(hull))
    # distance_grid keeps its result on the hull: time it on fresh copies of the hull.
    t_dist, grid = best_of(lambda: distance_grid(VoxelHull(hull.occupancy, hull.origin, VOXEL)))
    n = hull.occupancy.shape
    ext = np.diff(bounds, axis=0)[0]
    rows = [
        ("hull_bounds", t_bounds, f"{ext[0]:.2f} × {ext[1]:.2f} × {ext[2]:.2f} m"),
        ("carve (given bounds)", t_carve, f"{n[0]}×{n[1]}×{n[2]} = {np.prod(n) / 1e6:.2f} M"),
        ("carve (bounds + carve)", t_all, f"{hull.occupancy.sum()} voxels occupied"),
        ("hull_mesh (marching cubes)", t_mesh, f"{len(V)} vertices, {len(F)} faces"),
        ("distance_grid (EDT)", t_dist, f"{grid.shape}"),
    ]
    total = t_all + t_mesh + t_dist
    print(f"{'stage':<28}{'best of 5':>11}   notes")
    for name, t, note in rows:
        print(f"{name:<28}{t * 1e3:>8.1f} ms   {note}")
    print(f"{'total per frame':<28}{total * 1e3:>8.1f} ms   (bounds + carve + mesh + distance)")
    print(f"target carve ≤ 150 ms: {'met' if t_all <= 0.150 else 'MISSED'}")
    if true_volume:
        print(f"hull / true volume: {hull.volume / true_volume:.2f} (phantom volume, 4 views)")
    print(f"|distance| at mesh vertices: max {np.abs(grid(V)).max() * 1e3:.1f} mm")


if __name__ == "__main__":
    main()
