"""Speed of silhouette rasterisation for the four humaneva4 cameras at 640×480.

Target: ≤ 50 ms per 640×480 view of a 28k-face mesh.

Subjects: a 28k-face "capsule person" built here (always available: nine capsules and an
icosphere head, each closed) and, when it loads, the bundled template ``neutral``
(25k faces). Rows: :func:`silhouette` exact for any triangle soup, with
``assume_closed=True`` (front-facing triangles only), and the general z-buffer
:func:`~meshmocap.geometry.raster.coverage` for reference. Best of 5 per camera.

Run: ``python benchmarks/bench_silhouette.py``
"""

from __future__ import annotations

import numpy as np
import trimesh

from _timing import best_of
from meshmocap.geometry.raster import coverage
from meshmocap.geometry.silhouette import silhouette
from meshmocap.studio.rigs import camera_rig

REPEAT = 5


def capsule_person() -> tuple[np.ndarray, np.ndarray]:
    """A 28,448-face person of capsules, 1.74 m tall, feet on z = 0, facing −Y (metres)."""
    parts = [  # (start, end, radius)
        ((0, 0, 0.95), (0, 0, 1.40), 0.15),  # torso
        *[
            seg
            for s in (1, -1)
            for seg in (
                ((0.20 * s, 0, 1.42), (0.33 * s, 0, 1.15), 0.05),  # upper arm
                ((0.33 * s, 0, 1.15), (0.42 * s, -0.05, 0.90), 0.04),  # forearm
                ((0.10 * s, 0, 0.92), (0.12 * s, 0, 0.50), 0.07),  # thigh
                ((0.12 * s, 0, 0.50), (0.12 * s, 0.02, 0.10), 0.05),  # shin
            )
        ],
    ]
    meshes = []
    for a, b, r in parts:
        a, b = np.asarray(a, float), np.asarray(b, float)
        m = trimesh.creation.capsule(height=np.linalg.norm(b - a), radius=r, count=[36, 36])
        T = trimesh.geometry.align_vectors([0, 0, 1], b - a)
        T[:3, 3] = (a + b) / 2
        meshes.append(m.apply_transform(T))
    head = trimesh.creation.icosphere(subdivisions=4, radius=0.11)
    meshes.append(head.apply_translation([0, 0, 1.63]))
    m = trimesh.util.concatenate(meshes)
    return np.asarray(m.vertices), np.asarray(m.faces)


def subjects() -> list[tuple[str, np.ndarray, np.ndarray]]:
    out = [("capsule person", *capsule_person())]
    try:
        from meshmocap.body.template import load_template

        t = load_template("neutral")
        out.append(("template neutral", t.V, t.F))
    except Exception as err:  # the bundled template is optional here
        print(f"(template unavailable: {err})")
    return out


def main() -> None:
    cams = camera_rig("humaneva4")
    print(f"humaneva4, {cams[0].width}×{cams[0].height}, best of {REPEAT} (ms per view)")
    print(
        f"{'subject':18s} {'faces':>6s} {'camera':>6s} {'pixels':>7s} "
        f"{'exact':>7s} {'closed':>7s} {'coverage':>9s}  same"
    )
    worst = 0.0
    for name, V, F in subjects():
        for cam in cams:
            t_exact, mask = best_of(lambda cam=cam, V=V, F=F: silhouette(V, F, cam))
            t_closed, closed = best_of(
                lambda cam=cam, V=V, F=F: silhouette(V, F, cam, assume_closed=True)
            )
            t_ref, ref = best_of(
                lambda cam=cam, V=V, F=F: coverage(cam.project(V)[0], F, cam.shape)
            )
            same = np.array_equal(mask, ref) and np.array_equal(closed, ref)
            worst = max(worst, t_exact)
            print(
                f"{name:18s} {len(F):6d} {cam.name:>6s} {int(mask.sum()):7d} "
                f"{t_exact * 1e3:7.1f} {t_closed * 1e3:7.1f} {t_ref * 1e3:9.1f}  {same}"
            )
    print(f"worst exact silhouette: {worst * 1e3:.1f} ms per view (target ≤ 50 ms)")


if __name__ == "__main__":
    main()
