"""Exports against their tracks: how closely the exported BVH reproduces each tracker's
surface and joints, what each format costs in time and bytes.

Usage::

    python benchmarks/bench_export.py [--frames 40] [--data ../shared/data] [--work DIR]

Protocol: a synthetic walk (procedural, ``neutral_5k``, 4-camera hulls, 60 fps) and, with
``--data``, CMU 05_01 (the first ``--frames`` frames, same set-up) are tracked by the patch
tracker, the cage tracker (manifold learned from the procedural walk and jog) and
articulated ICP; every track is exported to every format. The BVH is read back
(:func:`meshmocap.io.bvh.read_bvh`) and the template re-skinned with it; the table gives
the mean distance to the tracked vertices (and the worst frame's mean) and to the tracked
joints (mean and max), then each format's export time and size. Captures and tracks are
kept in ``--work`` and reused. Timings depend on the machine's load: the load average is
printed.
"""

from __future__ import annotations

import argparse
import os
from pathlib import Path

import numpy as np

from meshmocap.apps.files.export import export_track
from meshmocap.body.template import load_template
from meshmocap.io.bvh import read_bvh
from meshmocap.io.results import read_track
from meshmocap.studio.synth import SynthSpec, synthesize
from meshmocap.trackers.driver import track_sequence
from meshmocap.trackers.options import TrackOptions
from meshmocap.trackers.registry import make_tracker

METHODS = ("patch", "cage", "articulated_icp")
FORMATS = ("bvh", "glb", "c3d", "trc", "csv")


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--frames", type=int, default=40)
    p.add_argument("--data", help="../shared/data: add CMU 05_01")
    p.add_argument("--work", default="bench-export-work")
    args = p.parse_args()
    work = Path(args.work)
    template = load_template("neutral_5k")
    motions = {"walk": "walk"}
    if args.data:
        motions["cmu 05_01"] = str(Path(args.data) / "mocap" / "cmu" / "05_01.amc")
    print(
        "| capture | tracker | frames | vertices mean (mm) | worst frame (mm) | joints mean "
        "(mm) | joints max (mm) | " + " | ".join(f"{f} s / kB" for f in FORMATS) + " |"
    )
    print("|" + "---|" * (7 + len(FORMATS)))
    for label, motion in motions.items():
        name = label.replace(" ", "_")
        spec = SynthSpec(motion=motion, template="neutral_5k", stop=args.frames)
        cap_dir = work / f"{name}-cap"
        cap = synthesize(cap_dir, spec, show_progress=False)
        for method in METHODS:
            out = work / f"{name}-{method}"
            if not (out / "track.json").is_file():
                tracker = (
                    make_tracker(method, template=template)
                    if method == "cage"
                    else (make_tracker(method))
                )
                track_sequence(tracker, template, cap, out, TrackOptions(show_progress=False))
            tr = read_track(out)
            files = work / "exports" / f"{name}-{method}"
            files.mkdir(parents=True, exist_ok=True)
            res = {f: export_track(out, files / f"x.{f}") for f in FORMATS}
            m = read_bvh(files / "x.bvh")
            posed = template.pose(m.rotations, m.root_positions)
            ve = np.linalg.norm(posed.V - tr.vertices, axis=2)
            je = np.linalg.norm(posed.eval_joints - tr.joints, axis=2)
            cells = [f"{res[f].seconds:.1f} / {res[f].size_bytes / 1e3:.0f}" for f in FORMATS]
            print(
                f"| {label} | {method} | {len(tr.frames)} | {ve.mean() * 1e3:.2f} | "
                f"{ve.mean(axis=1).max() * 1e3:.2f} | {je.mean() * 1e3:.2f} | "
                f"{je.max() * 1e3:.1f} | " + " | ".join(cells) + " |",
                flush=True,
            )
    print(
        f"\nload average {' '.join(f'{x:.1f}' for x in os.getloadavg())} on {os.cpu_count()} cores"
    )


if __name__ == "__main__":
    main()
