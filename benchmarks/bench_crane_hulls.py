"""Visual hulls of a real captured mesh sequence (MIT crane, ../shared/data/meshes/crane).

Each crane frame is rendered into the silhouettes of a rig and carved at 1 cm; we report
how well the hull contains the true surface (fraction of true vertices inside the hull or
within one voxel of it: the studio's acceptance criterion is ≥ 99 % for ring8) and the
hull/true volume ratio (phantom volume: sparse rigs such as humaneva4 carve less).

Run: ``python benchmarks/bench_crane_hulls.py [--step 5]``
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import numpy as np

from meshmocap.geometry.carving import distance_grid
from meshmocap.geometry.mesh import signed_volume
from meshmocap.io.meshes import MeshSequence
from meshmocap.studio.synth import synthesize_from_meshes

CRANE = (
    Path(__file__).resolve().parents[1].parent
    / "shared/data/meshes/crane/crane_mesh_0000-0174.tar.gz"
)


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--step", type=int, default=5, help="use every STEP-th frame")
    args = ap.parse_args()
    if not CRANE.is_file():
        print(f"skipped: {CRANE} is absent")
        return
    frames = range(0, 175, args.step)
    F = MeshSequence(CRANE, frames=range(1), up="y")[0].F
    print(f"crane: {len(frames)} frames (every {args.step}th), voxel 1 cm, 640×480 views")
    head = ("rig", "inside or ≤1 voxel", "worst frame", "hull/true volume", "s/frame")
    print(f"{head[0]:<10} {head[1]:>19} {head[2]:>12} {head[3]:>17} {head[4]:>8}")
    for rig in ("ring8", "humaneva4"):
        with tempfile.TemporaryDirectory() as tmp:
            t0 = time.perf_counter()
            cap = synthesize_from_meshes(CRANE, tmp, rig=rig, frames=frames)
            dt = (time.perf_counter() - t0) / len(cap)
            inside, ratio = [], []
            for f in cap:
                V = f.truth.vertices
                inside.append(np.mean(distance_grid(f.hull)(V) <= f.hull.voxel_size))
                ratio.append(f.hull.volume / signed_volume(V, F))
        inside, ratio = np.array(inside), np.array(ratio)
        print(
            f"{rig:<10} {100 * inside.mean():>18.2f}% {100 * inside.min():>11.2f}% "
            f"{ratio.mean():>9.3f} ± {ratio.std():.3f} {dt:>8.2f}"
        )


if __name__ == "__main__":
    main()
