"""Cage tracker acceptance benchmark: accuracy with a CMU-learned manifold, the
ablations of the paper, and speed with a per-stage breakdown.

Protocol: synthetic ``humaneva4`` captures from the studio at 60 fps
(:func:`meshmocap.apps.bench.captures.make_capture`, the captures of ``meshmocap bench``) of
CMU 05_01.amc (walk, whole clip) and 09_01.bvh (run, from frame 4: the BVH blends out of
a T-pose first); subject = tracking template ``neutral_5k``; first frame from ground truth;
visual hulls carved at 1 cm. The pose manifold (q = 2, 120 poses) is learned from the
subject-35 walks and jogs of ``cmu35WalkJog.mat`` (``meshmocap learn ... --template
neutral_5k``), and, for comparison, from the procedural walk and jog. Scores: 3D error of
the 15 evaluation joints (:func:`meshmocap.analysis.evaluate.evaluate`), in mm: mean and
median over all (frame, joint) pairs, worst frame (mean over its joints), worst joint.
Methods (:data:`meshmocap.trackers.registry.METHODS`): ``cage`` (with local adjustment),
``cage_quads`` (quads, no manifold: Fig. 5a), ``cage_noreg`` (no variance term: Fig. 5b),
``cage_nolocal`` (no local adjustment: Table 1), and ``cage`` with ``joints="quads"``.

Frames the cameras do not all see whole (the subject walks or runs out of their common
view at the end of both clips) are skipped by ``evaluate``; the counts are printed.

Speed: seconds per frame of the tracker's ``step`` (the driver's timer; frame 0, the
initialisation, left out) and the tracker's own stage breakdown
(:attr:`~meshmocap.trackers.cage.tracker.CageTracker.stage_seconds`): distance field (hull read,
lazy distance grid), pose steps, latent shape steps (with the restarts), local adjustment,
output deformation (every vertex and the joints). The speed table tracks a 60-frame
procedural walk with the 12k-vertex ``neutral`` and the 5k ``neutral_5k`` templates.
Timings are wall clock on a shared machine: the load average is printed with them.

Run: ``python benchmarks/bench_cage.py [--work /tmp/meshmocap-bench-cage] [--clips 05_01
09_01] [--max-frames N] [--skip-speed | --speed-only]``; captures and manifolds are cached
in ``--work``, tracks are redone (for the timings).
"""

from __future__ import annotations

import argparse
import os
import time
from pathlib import Path

import numpy as np

from meshmocap.analysis.evaluate import evaluate
from meshmocap.apps.bench.captures import make_capture, parse_capture
from meshmocap.body.template import load_template
from meshmocap.trackers.cage.manifold import PoseManifold, learn_pose_manifold
from meshmocap.trackers.cage.tracker import STAGES
from meshmocap.trackers.driver import track_sequence
from meshmocap.trackers.options import TrackOptions
from meshmocap.trackers.registry import make_tracker

DATA = Path(__file__).resolve().parents[1].parent / "shared" / "data"
CMU35 = DATA / "mocap" / "cmu" / "cmu35WalkJog.mat"
#: (label, registry method, extra options)
RUNS = (
    ("cage", "cage", {}),
    ("cage_quads", "cage_quads", {}),
    ("cage_noreg", "cage_noreg", {}),
    ("cage_nolocal", "cage_nolocal", {}),
    ("cage joints=quads", "cage", {"joints": "quads"}),
)


def manifold(kind: str, template, work: Path) -> PoseManifold:
    """The pose manifold ``kind`` ("cmu35" or "procedural") of ``template``, cached."""
    path = work / f"manifold-{kind}-{template.name}.npz"
    if path.is_file():
        return PoseManifold.load(path)
    sources = [CMU35] if kind == "cmu35" else ["walk", "jog"]
    pm = learn_pose_manifold(template, sources)
    pm.save(path)
    return pm


def run(label, method, opts, kind, template, capture, work: Path) -> dict:
    """Track ``capture`` afresh with manifold ``kind`` and score it; the row's numbers."""
    pm = manifold(kind, template, work)
    tracker = make_tracker(method, manifold=pm, template=template, **opts)
    out = work / "tracks" / capture.path.name / f"{label.replace(' ', '_')}-{kind}"
    track = track_sequence(
        tracker, template, capture, out, TrackOptions(resume=False, show_progress=False)
    )
    ev = evaluate(track, capture, surface_frames=0, silhouettes=False)
    steps = max(tracker.n_steps, 1)
    return {
        "scored": len(ev.joints.frames),
        "mean": ev.joints.overall.mean,
        "median": ev.joints.overall.median,
        "worst_frame": float(ev.joints.per_frame.max()),
        "worst_joint": ev.joints.overall.max,
        "s_frame": float(np.mean(track.seconds[1:])),
        "stages": {k: tracker.stage_seconds[k] / steps for k in STAGES},
    }


def load() -> str:
    return "load average {:.2f} {:.2f} {:.2f}".format(*os.getloadavg())


def accuracy(args, work: Path, template) -> None:
    head = (
        "| capture | manifold | method | mean | median | worst frame | worst joint | s/frame "
        "| " + " | ".join(STAGES) + " |"
    )
    print(head)
    print("|" + "---|" * (head.count("|") - 1))
    notes = []
    for clip in args.clips:
        spec = parse_capture(clip, data=DATA, frames=args.max_frames)
        capture = make_capture(spec, work, template=template.name, show_progress=False)
        for kind in ("cmu35", "procedural"):
            for label, method, opts in RUNS:
                t0 = time.perf_counter()
                r = run(label, method, opts, kind, template, capture, work)
                st = " | ".join(f"{r['stages'][k]:.4f}" for k in STAGES)
                print(
                    f"| {clip} | {kind} | {label} | {r['mean']:.1f} | {r['median']:.1f} | "
                    f"{r['worst_frame']:.1f} | {r['worst_joint']:.1f} | {r['s_frame']:.3f} | "
                    f"{st} |",
                    flush=True,
                )
                args.log(f"  ({label}, {kind}, {clip}: {time.perf_counter() - t0:.0f} s, {load()})")
        notes.append(
            f"{clip}: {len(capture)} frames, {r['scored']} scored (the others are not "
            "fully seen by the cameras)"
        )
    print()
    for n in notes:
        print(n)


def speed(args, work: Path) -> None:
    print(
        f"speed: 60-frame procedural walk, cage (local adjustment), procedural manifold; "
        f"3 runs each (min and max of their mean s/frame); {load()} on {os.cpu_count()} "
        "cores"
    )
    head = (
        "| template | vertices | s/frame min | s/frame max | " + " | ".join(STAGES) + " | mean mm |"
    )
    print(head)
    print("|" + "---|" * (head.count("|") - 1))
    spec = parse_capture("walk", frames=60)
    for name in ("neutral", "neutral_5k"):
        template = load_template(name)
        capture = make_capture(spec, work, template=name, show_progress=False)
        manifold("procedural", template, work)  # learned before the clock starts
        runs = [run("speed", "cage", {}, "procedural", template, capture, work) for _ in range(3)]
        best = min(runs, key=lambda r: r["s_frame"])
        st = " | ".join(f"{best['stages'][k]:.4f}" for k in STAGES)
        worst = max(r["s_frame"] for r in runs)
        print(
            f"| {name} | {template.n_vertices} | {best['s_frame']:.3f} | {worst:.3f} | {st} "
            f"| {best['mean']:.1f} |",
            flush=True,
        )
    print(f"(stages: of the fastest run; {load()} after)")


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--work", default="/tmp/meshmocap-bench-cage")
    ap.add_argument("--clips", nargs="+", default=["05_01", "09_01"])
    ap.add_argument("--max-frames", type=int, default=None)
    ap.add_argument("--skip-speed", action="store_true")
    ap.add_argument("--speed-only", action="store_true", help="only the speed table")
    ap.add_argument("--quiet", action="store_true", help="no per-run progress lines")
    args = ap.parse_args()
    args.log = (lambda _: None) if args.quiet else (lambda s: print(s, flush=True))
    work = Path(args.work)
    work.mkdir(parents=True, exist_ok=True)
    template = load_template("neutral_5k")
    print(
        f"cage tracker benchmark: humaneva4 rig, 60 fps, template {template.name}, subject = "
        f"template, first frame from ground truth; joint errors in mm; {load()}\n"
    )
    if not args.skip_speed:
        speed(args, work)
        print()
    if not args.speed_only:
        accuracy(args, work, template)


if __name__ == "__main__":
    main()
