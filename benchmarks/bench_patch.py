"""Patch tracker acceptance benchmark (issue: patch tracker, in full): a thin wrapper over
:func:`meshmocap.evaluation.bench.run_bench` (``meshmocap bench``) on the CMU clips.

Protocol: synthetic captures from the studio at 60 fps, subject = tracking template unless
stated, first frame initialised from ground truth, visual hulls carved at 1 cm from the
rig's silhouettes; every tracker is scored with ``meshmocap.evaluation.evaluate`` against
the capture's ground truth (15 evaluation joints; bone-length std over the tracked
skeleton). Clips (../shared/data/mocap/cmu, ``meshmocap.evaluation.bench.CMU_CLIPS``):
05_01.amc (walk, whole), 09_01.bvh (run, whole from frame 4), 01_01.amc (jumps and a turn,
first 600 frames at 60 fps).

Run: ``python benchmarks/bench_patch.py [--clips 05_01 09_01 01_01] [--methods patch ...]
[--rig humaneva4] [--subject heavy_male] [--degrade] [--max-frames N] [--out DIR]``.
Captures and tracks are kept in ``--out``/work (default /tmp/meshmocap-bench) so runs
resume; the table, plots and CSV files are written to ``--out``.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from meshmocap.evaluation.bench import CMU_CLIPS, run_bench
from meshmocap.evaluation.bench_report import markdown_table

DATA = Path(__file__).resolve().parents[1].parent / "shared" / "data"


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
    args = ap.parse_args()
    variants = [args.rig, *([args.subject] if args.subject else []),
                *(["degraded"] if args.degrade else [])]  # fmt: skip
    captures = ["+".join([clip, *variants]) for clip in args.clips]
    res = run_bench(
        args.out, captures=captures, methods=args.methods, data=DATA, max_frames=args.max_frames,
        keep_fractions=(), template=args.template, show_progress=True, log=print,
    )  # fmt: skip
    print(f"\nsetting: {' '.join(variants)}, template {args.template}, 60 fps, "
          "first frame from ground truth")  # fmt: skip
    print(markdown_table(res.rows))


if __name__ == "__main__":
    main()
