"""Patch tracker acceptance benchmark (accuracy and speed on the CMU clips): a thin wrapper over
:func:`meshmocap.apps.bench.run.run_bench` (``meshmocap bench``) on the CMU clips.

Protocol: synthetic captures from the studio at 60 fps, subject = tracking template unless
stated, first frame initialised from ground truth, visual hulls carved at 1 cm from the
rig's silhouettes; every tracker is scored with ``meshmocap.analysis.evaluate`` against
the capture's ground truth (15 evaluation joints; bone-length std over the tracked
skeleton). Clips (../shared/data/mocap/cmu, ``meshmocap.apps.bench.captures.CMU_CLIPS``):
05_01.amc (walk, whole), 09_01.bvh (run, whole from frame 4), 01_01.amc (jumps and a turn,
first 600 frames at 60 fps).

Speed (``--speed``): a 60-frame procedural walk (``humaneva4``) tracked by ``patch`` with
the ~5k-vertex ``neutral_5k`` and the ~12k-vertex ``neutral`` templates, ``--repeats``
runs each: seconds per frame of the tracker's ``step`` (the driver's timer; frame 0, the
initialisation, left out; hull files are read inside ``step``) and the tracker's stage
breakdown (:data:`meshmocap.trackers.patch.tracker.STAGES`) of the fastest run. Wall clock on a
shared machine: the load average is printed with it.

Run: ``python benchmarks/bench_patch.py [--clips 05_01 09_01 01_01] [--methods patch ...]
[--rig humaneva4] [--subject heavy_male] [--degrade] [--max-frames N] [--out DIR]
[--speed [--repeats 3]]``. Captures and tracks are kept in ``--out``/work (default
/tmp/meshmocap-bench) so runs resume; the table, plots and CSV files are written to
``--out``.
"""

from __future__ import annotations

import argparse
import os
from pathlib import Path

import numpy as np

from meshmocap.analysis.evaluate import evaluate
from meshmocap.apps.bench.captures import CMU_CLIPS, make_capture, parse_capture
from meshmocap.apps.bench.report import markdown_table
from meshmocap.apps.bench.run import run_bench
from meshmocap.body.template import load_template
from meshmocap.trackers.driver import track_sequence
from meshmocap.trackers.options import TrackOptions
from meshmocap.trackers.patch.tracker import STAGES, PatchOptions, PatchTracker

DATA = Path(__file__).resolve().parents[1].parent / "shared" / "data"


def speed(out: Path, repeats: int) -> None:
    """Print the speed table (module docstring)."""
    print(
        f"speed: 60-frame procedural walk, humaneva4, patch (defaults); fastest of {repeats} "
        f"runs; load average {os.getloadavg()[0]:.2f} on {os.cpu_count()} cores"
    )
    head = "| template | vertices | s/frame min | s/frame max | " + " | ".join(STAGES)
    head += " | mean mm |"
    print(head)
    print("|" + "---|" * (head.count("|") - 1))
    spec = parse_capture("walk", frames=60)
    for name in ("neutral_5k", "neutral"):
        template = load_template(name)
        capture = make_capture(spec, out / "work", template=name, show_progress=False)
        runs = []
        for r in range(repeats):
            tracker = PatchTracker(PatchOptions())
            track = track_sequence(
                tracker,
                template,
                capture,
                out / "speed" / f"{name}-{r}",
                TrackOptions(resume=False, show_progress=False),
            )
            stages = {k: v / max(tracker.n_steps, 1) for k, v in tracker.stage_seconds.items()}
            runs.append((float(np.mean(track.seconds[1:])), stages, track))
        s_min, stages, track = min(runs, key=lambda r: r[0])
        ev = evaluate(track, capture, surface_frames=0, silhouettes=False)
        st = " | ".join(f"{stages[k]:.3f}" for k in STAGES)
        print(
            f"| {name} | {template.n_vertices} | {s_min:.3f} | {max(r[0] for r in runs):.3f} "
            f"| {st} | {ev.joints.overall.mean:.1f} |",
            flush=True,
        )
    print(
        f"(stages: seconds per frame of the fastest run; load average {os.getloadavg()[0]:.2f} "
        "after)"
    )


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--clips", nargs="+", default=list(CMU_CLIPS))
    ap.add_argument("--methods", nargs="+", default=["patch", "patch_noclf", "articulated_icp"])
    ap.add_argument("--rig", default="humaneva4")
    ap.add_argument("--template", default="neutral_5k")
    ap.add_argument("--subject", default=None)
    ap.add_argument("--degrade", action="store_true", help="jitter, holes, blobs in silhouettes")
    ap.add_argument("--max-frames", type=int, default=None)
    ap.add_argument("--out", default="/tmp/meshmocap-bench")
    ap.add_argument("--speed", action="store_true", help="only the speed table")
    ap.add_argument("--repeats", type=int, default=3)
    args = ap.parse_args()
    if args.speed:
        speed(Path(args.out), args.repeats)
        return
    variants = [
        args.rig,
        *([args.subject] if args.subject else []),
        *(["degraded"] if args.degrade else []),
    ]
    captures = ["+".join([clip, *variants]) for clip in args.clips]
    res = run_bench(
        args.out,
        captures=captures,
        methods=args.methods,
        data=DATA,
        max_frames=args.max_frames,
        keep_fractions=(),
        template=args.template,
        show_progress=True,
        log=print,
    )
    print(
        f"\nsetting: {' '.join(variants)}, template {args.template}, 60 fps, "
        "first frame from ground truth"
    )
    print(markdown_table(res.rows))


if __name__ == "__main__":
    main()
