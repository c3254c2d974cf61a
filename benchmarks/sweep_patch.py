"""Option sweep of the patch tracker over many captures (issue 20: an extension is turned on
by default only where it helps across clips, never tuned on one).

Protocol: synthetic captures from the studio (``neutral_5k`` performs and tracks, 60 fps
unless the capture says otherwise, 4 cameras ``humaneva4``, hulls carved at 1 cm), first
frame from the truth; joint error over the 15 evaluation joints of frames 1… of each
capture. Each cell: mean / worst frame (mean over the joints) / worst joint, mm.

Captures: ``CLIP[:START:STOP[:STEP]][+deg][+ring8]`` with CLIP a file stem of
../shared/data/mocap/cmu or its ``library/`` (a Daz BVH of the library starts in a T-pose
at frame 0: an abrupt start), e.g. ``13_32:0:80`` or ``05_01:0:160:2+deg``. Variants:
``NAME`` or ``NAME:opt=value,opt=value`` (PatchOptions fields). Held-out clips 05_03,
60_01 and 61_01 are for checking, never for choosing.

Run: ``python benchmarks/sweep_patch.py --captures 13_32:0:60 ... --variants base
gate:accel_gate=0.03 ...``. Captures are made once in ``--work``; one CSV row per capture
and variant is appended to ``--out``.
"""

from __future__ import annotations

import argparse
import ast
import csv
import os
import time
from pathlib import Path

import numpy as np

from meshmocap.apps.bench_captures import DEGRADED
from meshmocap.body.template import load_template
from meshmocap.studio.degrade import Degradation
from meshmocap.studio.synth import SynthSpec, synthesize
from meshmocap.trackers.driver import track_sequence
from meshmocap.trackers.patch import PatchOptions, PatchTracker
from meshmocap.trackers.registry import make_tracker

DATA = Path(__file__).resolve().parents[1].parent / "shared" / "data"
#: True rate of files whose header misstates it (16_01 says 30 for 120 fps).
SOURCE_FPS = {"16_01": 120.0}


def capture_of(name: str, work: Path, template: str):
    """Make (or reuse) the capture ``name`` (module docstring)."""
    base, *flags = name.split("+")
    clip, *rng = base.split(":")
    rng = [int(x) if x else None for x in rng] + [None] * (3 - len(rng))
    hits = sorted((DATA / "mocap" / "cmu").glob(f"{clip}.*"))
    hits += sorted((DATA / "mocap" / "cmu" / "library").glob(f"{clip}.*"))
    motion = str(next(h for h in hits if h.suffix in (".amc", ".bvh")))
    fps = 60.0 * (30.0 / SOURCE_FPS[clip] if clip in SOURCE_FPS else 1.0)
    spec = SynthSpec(motion=motion, template=template,
                     rig="ring8" if "ring8" in flags else "humaneva4", fps=fps,
                     start=rng[0], stop=rng[1], step=rng[2],
                     degradation=DEGRADED if "deg" in flags else Degradation())  # fmt: skip
    folder = name.replace(":", "-").replace("+", "_")
    return synthesize(work / folder, spec, show_progress=False)


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--captures", nargs="+", required=True)
    ap.add_argument("--variants", nargs="+", default=["base"])
    ap.add_argument("--frames", type=int, default=None, help="track only the first N")
    ap.add_argument("--template", default="neutral_5k")
    ap.add_argument("--work", default="/tmp/meshmocap-sweep")
    ap.add_argument("--out", default="/tmp/meshmocap-sweep/sweep.csv")
    args = ap.parse_args()
    work, out = Path(args.work), Path(args.out)
    t = load_template(args.template)
    out.parent.mkdir(parents=True, exist_ok=True)
    new = not out.exists()
    with out.open("a", newline="") as fh:
        wr = csv.writer(fh)
        if new:
            wr.writerow(["capture", "variant", "frames", "mean_mm", "worst_frame_mm",
                         "worst_joint_mm", "frames_over_60", "s_per_frame", "load"])  # fmt: skip
        for name in args.captures:
            cap = capture_of(name, work, args.template)
            n = len(cap) if args.frames is None else min(args.frames, len(cap))
            true = np.stack([cap[i].truth.joints for i in range(n)])
            for v in args.variants:
                vname, _, rest = v.partition(":")
                opts = {k: ast.literal_eval(x) for k, x in
                        (s.split("=", 1) for s in rest.split(",") if s)}  # fmt: skip
                if vname == "icp":
                    tracker = make_tracker("articulated_icp")
                else:
                    tracker = PatchTracker(PatchOptions(**opts))
                t0 = time.perf_counter()
                track = track_sequence(tracker, t, cap, work / "tracks" / f"{name}-{v}",
                                       frames=range(n), resume=False, show_progress=False,
                                       vertices=False)  # fmt: skip
                sec = (time.perf_counter() - t0) / max(n - 1, 1)
                e = np.linalg.norm(track.joints - true, axis=2)[1:] * 1000
                ef = np.nan_to_num(e, nan=1e4).mean(axis=1)
                row = [name, v, len(e), f"{np.nanmean(e):.1f}", f"{ef.max():.1f}",
                       f"{np.nanmax(e):.0f}", int((ef > 60).sum()), f"{sec:.2f}",
                       f"{os.getloadavg()[0]:.1f}"]  # fmt: skip
                wr.writerow(row)
                fh.flush()
                print(" ".join(map(str, row)), flush=True)


if __name__ == "__main__":
    main()
