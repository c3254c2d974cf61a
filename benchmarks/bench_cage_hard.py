"""Cage tracker on hard captures: varied CMU motions, degraded silhouettes, and
the clips the bundled pose library holds out.

Protocol (the papers'): synthetic ``humaneva4`` captures (4 cameras, 60 fps) of the
``meshmocap bench`` clips (:data:`meshmocap.apps.bench.captures.CMU_CLIPS`: 05_01 walk,
09_01 run from frame 4, 01_01 forward jumps, 49_18 balance on one leg, 16_01 a jump at its
true 120 fps) and their ``degraded`` variants (boundary jitter, holes, spurious blobs, a
missed limb); subject = tracking template ``neutral_5k``; first frame from ground truth;
the cage tracker with its default pose manifold (the bundled CMU pose library, learned at
first use and cached; none of these clips is in it). ``--held-out`` adds the library's
held-out trials 05_03 (modern dance) and 60_01, 61_01 (salsa), the first 200 frames at
60 fps. Scores (:func:`meshmocap.analysis.evaluate.evaluate`, frames the cameras do not
all see whole left out): mean 3D error of the 15 evaluation joints, worst frame (mean over
its joints), worst single joint, frames over 60 mm, in mm; frames the tracker found off
its manifold; seconds per frame of ``step`` (wall clock, shared machine: the load average
is printed).

Run: ``python benchmarks/bench_cage_hard.py [--work /tmp/meshmocap-bench-cage-hard]
[--captures 05_01 09_01+degraded ...] [--methods cage cage_nosil ...] [--max-frames N]
[--held-out]``; captures and the manifold cache live in ``--work``, tracks are redone.
"""

from __future__ import annotations

import argparse
import os
import time
from pathlib import Path

import numpy as np

from meshmocap.analysis.evaluate import evaluate
from meshmocap.apps.bench.captures import BenchCapture, make_capture, parse_capture
from meshmocap.body.template import load_template
from meshmocap.trackers.driver import track_sequence
from meshmocap.trackers.options import TrackOptions
from meshmocap.trackers.registry import make_tracker

DATA = Path(__file__).resolve().parents[1].parent / "shared" / "data"
CAPTURES = (
    "05_01",
    "09_01",
    "01_01",
    "49_18",
    "16_01",
    "05_01+degraded",
    "09_01+degraded",
    "01_01+degraded",
)
HELD_OUT = ("05_03", "60_01", "61_01")


def capture_of(name: str, work: Path, frames: int | None):
    """A bench capture, or a held-out library trial (first 200 frames), made once."""
    if name in HELD_OUT:
        path = DATA / "mocap" / "cmu" / "library" / f"{name}.amc"
        spec = BenchCapture(name, "synthetic", str(path), stop=min(200, frames or 200))
    else:
        spec = parse_capture(name, data=DATA, frames=frames)
    return make_capture(spec, work, template="neutral_5k", show_progress=False)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--work", default="/tmp/meshmocap-bench-cage-hard")
    ap.add_argument("--captures", nargs="+", default=list(CAPTURES))
    ap.add_argument("--methods", nargs="+", default=["cage"])
    ap.add_argument("--max-frames", type=int, default=300)
    ap.add_argument("--held-out", action="store_true")
    args = ap.parse_args()
    work = Path(args.work)
    os.environ.setdefault("MESHMOCAP_CACHE", str(work / "cache"))
    template = load_template("neutral_5k")
    names = list(args.captures) + (list(HELD_OUT) if args.held_out else [])
    print(
        "| capture | method | frames | mean | worst frame | worst joint | frames > 60 | "
        "off manifold | s/frame | load |"
    )
    print("|---|---|--:|--:|--:|--:|--:|--:|--:|--:|")
    for name in names:
        cap = capture_of(name, work, args.max_frames)
        for method in args.methods:
            tracker = make_tracker(method, template=template)
            out = work / "tracks" / name / method
            t0 = time.perf_counter()
            track = track_sequence(
                tracker, template, cap, out, TrackOptions(resume=False, show_progress=False)
            )
            wall = time.perf_counter() - t0
            ev = evaluate(track, cap, surface_frames=0, silhouettes=False)
            pf = ev.joints.per_frame
            off = int(np.sum(np.asarray(track.energies.get("off_manifold", [0.0])) > 0))
            sec = np.mean(track.seconds[1:]) if len(track.seconds) > 1 else wall
            print(
                f"| {name} | {method} | {len(pf)} | {ev.joints.overall.mean:.1f} | "
                f"{np.nanmax(pf):.1f} | {ev.joints.overall.max:.1f} | "
                f"{int(np.sum(pf > 60))} | {off} | {sec:.2f} | "
                f"{os.getloadavg()[0]:.1f} |",
                flush=True,
            )


if __name__ == "__main__":
    main()
