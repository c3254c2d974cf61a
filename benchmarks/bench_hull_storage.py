"""Disk per frame of a capture's hulls: the old layout (binary PLY mesh + bit-packed
occupancy ``.npz``) against the new one (occupancy and compact mesh in one ``.npz``), and
the time to read a frame's hull mesh back from each.

Protocol: the procedural walk on ``neutral`` (12k vertices) at 30 fps, frames 0:``--frames``,
in the 4-camera studio, carved at 1 cm (the defaults of ``meshmocap synth``). The old layout
is rewritten beside it with :func:`write_mesh` (PLY) and an occupancy-only ``.npz``; both
are read with :meth:`CaptureFrame.hull_mesh`, which must give identical arrays.

Usage: ``python benchmarks/bench_hull_storage.py [--frames 10] [--work DIR]``
"""

from __future__ import annotations

import argparse
import os
import shutil
import time
from pathlib import Path

import numpy as np

from meshmocap.geometry.carving import hull_mesh
from meshmocap.io.capture import Capture
from meshmocap.io.meshes import write_mesh
from meshmocap.studio.synth import SynthSpec, synthesize


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--frames", type=int, default=10)
    ap.add_argument("--work", default="hull-storage-work")
    args = ap.parse_args()
    work = Path(args.work)
    new = synthesize(
        work / "new", SynthSpec(motion="walk", fps=30.0, stop=args.frames), show_progress=False
    )
    old = work / "old"
    shutil.rmtree(old, ignore_errors=True)
    shutil.copytree(new.path, old)
    for p in sorted((old / "hulls").glob("*.npz")):  # the layout written before
        hull = new[new.indices.index(int(p.stem))].hull
        np.savez_compressed(
            p,
            bits=np.packbits(hull.occupancy.ravel()),
            shape=np.array(hull.occupancy.shape),
            origin=hull.origin,
            voxel_size=np.float64(hull.voxel_size),
        )
        write_mesh(p.with_suffix(".ply"), *hull_mesh(hull))
    sizes = {}
    for name, root in (("old", old), ("new", new.path)):
        files = list((root / "hulls").iterdir())
        sizes[name] = sum(f.stat().st_size for f in files) / len(new)
    reads = {}
    for name, root in (("old", old), ("new", new.path)):
        cap = Capture(root)
        t0 = time.perf_counter()
        meshes = [cap[k].hull_mesh for k in range(len(cap))]
        reads[name] = ((time.perf_counter() - t0) / len(cap), meshes)
    same = all(
        np.array_equal(a[0], b[0]) and np.array_equal(a[1], b[1])
        for a, b in zip(reads["old"][1], reads["new"][1], strict=True)
    )
    nv = np.mean([len(m[0]) for m in reads["new"][1]])
    print(f"{len(new)} frames, hull meshes of {nv:.0f} vertices on average; identical: {same}")
    print("| layout | hull disk per frame | read one hull mesh |")
    print("|---|---:|---:|")
    for name, label in (
        ("old", "PLY + occupancy .npz"),
        ("new", "one .npz (occupancy + compact mesh)"),
    ):
        print(f"| {label} | {sizes[name] / 1e6:.3f} MB | {reads[name][0] * 1e3:.1f} ms |")
    print(f"reduction: {sizes['old'] / sizes['new']:.1f}x; load average {os.getloadavg()[0]:.1f}")
    return 0 if same else 1


if __name__ == "__main__":
    raise SystemExit(main())
