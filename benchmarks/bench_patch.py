"""Patch tracker acceptance benchmark (issue: patch tracker, in full).

Protocol: synthetic captures from the studio at 60 fps, subject = tracking template unless
stated, first frame initialised from ground truth, visual hulls carved at 1 cm from the
rig's silhouettes; every tracker is scored with ``meshmocap.evaluation.evaluate`` against
the capture's ground truth (15 evaluation joints; bone-length std over the tracked
skeleton). Clips (../shared/data/mocap/cmu): 05_01.amc (walk, whole), 09_01.bvh (run,
whole), 01_01.amc (jumps and a turn, first 600 frames at 60 fps).

Run: ``python benchmarks/bench_patch.py [--clips 05_01 09_01 01_01] [--methods patch ...]
[--rig humaneva4] [--subject heavy_male] [--degrade] [--max-frames N] [--out DIR]``.
Captures and tracks are kept in ``--out`` (default /tmp/meshmocap-bench) so runs resume.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

from meshmocap.body.template import load_template
from meshmocap.evaluation.evaluate import evaluate
from meshmocap.io.results import read_track
from meshmocap.studio.degrade import Degradation
from meshmocap.studio.synth import SynthSpec, synthesize
from meshmocap.trackers.driver import track_sequence
from meshmocap.trackers.registry import make_tracker

CMU = Path(__file__).resolve().parents[1].parent / "shared" / "data" / "mocap" / "cmu"
#: clip → (file, first frame, last frame) at 60 fps; the Daz BVH starts with a T-pose and
#: blends out of it over its first 8 frames at 120 fps (hands at 20 m/s): skipped.
CLIPS = {
    "05_01": ("05_01.amc", None, None),
    "09_01": ("09_01.bvh", 4, None),
    "01_01": ("01_01.amc", None, 600),
}


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--clips", nargs="+", default=list(CLIPS))
    ap.add_argument("--methods", nargs="+", default=["patch", "patch_noclf", "articulated_icp"])
    ap.add_argument("--rig", default="humaneva4")
    ap.add_argument("--template", default="neutral_5k")
    ap.add_argument("--subject", default=None)
    ap.add_argument("--degrade", action="store_true", help="jitter, holes, blobs in silhouettes")
    ap.add_argument("--max-frames", type=int, default=None)
    ap.add_argument("--out", default="/tmp/meshmocap-bench")
    args = ap.parse_args()
    template = load_template(args.template)
    deg = Degradation(jitter=1.5, holes=2, blobs=2) if args.degrade else Degradation()
    tag = f"{args.rig}-{args.subject or args.template}{'-degraded' if args.degrade else ''}"
    rows = []
    for clip in args.clips:
        name, start, stop = CLIPS[clip]
        if not (CMU / name).is_file():
            print(f"skipped {clip}: {CMU / name} is absent")
            continue
        limits = [x for x in (stop, args.max_frames) if x]
        stop = min(limits) if limits else None
        spec = SynthSpec(
            motion=str(CMU / name),
            template=args.template,
            subject=args.subject,
            rig=args.rig,
            fps=60.0,
            start=start,
            stop=stop,
            degradation=deg,
        )
        t0 = time.perf_counter()
        cap = synthesize(Path(args.out) / f"{clip}-{tag}", spec, show_progress=True)
        print(f"{clip}: capture of {len(cap)} frames ready ({time.perf_counter() - t0:.0f} s)")
        for method in args.methods:
            out = Path(args.out) / f"{clip}-{tag}-{method}"
            try:
                tracker = make_tracker(method)
            except Exception as exc:  # a method not built yet
                print(f"  {method}: unavailable ({exc})")
                continue
            track_sequence(tracker, template, cap, out, show_progress=True)
            ev = evaluate(read_track(out), cap, silhouettes=False, surface_frames=0)
            j = ev.joints.overall
            per_frame = ev.joints.per_frame
            rows.append(
                (
                    clip,
                    method,
                    len(cap),
                    j.mean,
                    j.median,
                    j.std,
                    float(per_frame.max()),
                    float(np.nanmax(ev.bones.std)),
                    ev.seconds.mean,
                    ev.unhealthy,
                )
            )
            print(
                f"  {method}: mean {j.mean:.1f} mm, worst frame {per_frame.max():.1f} mm, "
                f"{ev.seconds.mean:.2f} s/frame"
            )
    print(f"\nsetting: {tag}, template {args.template}, 60 fps, first frame from ground truth")
    head = (
        "clip",
        "method",
        "frames",
        "mean mm",
        "median",
        "std",
        "worst frame",
        "bone std max",
        "s/frame",
        "flagged",
    )
    print("| " + " | ".join(head) + " |")
    print("|" + "---|" * len(head))
    for r in rows:
        print(
            f"| {r[0]} | {r[1]} | {r[2]} | {r[3]:.1f} | {r[4]:.1f} | {r[5]:.1f} | {r[6]:.1f} | "
            f"{r[7]:.1f} | {r[8]:.2f} | {r[9]} |"
        )


if __name__ == "__main__":
    main()
