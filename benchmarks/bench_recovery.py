"""Loss detection acceptance: is a frame far off flagged, with its limb? (The limb-only
re-seat it once measured was removed: the forward pass now flags and never moves the track.)

Protocol: synthetic captures of CMU clips from ../shared/data on ``neutral_5k`` (the
template is the performer), ``humaneva4`` rig, 60 fps, visual hulls at 1 cm, the first 300
frames:

* **gaps** — 05_01 (walk) with the left forearm and hand (``left_elbow`` and below) seen by
  no camera for frames 100–109, and 09_01 (run, 71 frames) with the right lower leg and
  foot (``right_knee``) unseen for frames 30–39 (``meshmocap synth --missed-limb-joint
  --missed-limb-frames``: the limb's pixels off the rest of the body are lost in every
  view, so the hull misses it for 10 frames);
* **motions beyond walking** — 01_01 (forward jumps), and from the pose library
  (``mocap/cmu/library``, not used to train anything these trackers use) 05_03 (modern
  dance) and 60_01 (salsa).

Each capture is tracked from its ground-truth first pose (the papers' protocol: recovery is
measured apart from initialisation) by each ``--methods`` with the checks (``recover=True``:
lost limbs flagged) and without (``recover=False``: the same track, unscored; what the checks
cost per frame). Per track: the mean joint error; the frames where a joint is
more than 150 mm off and how many of them are flagged ``lost`` with that joint's limb
(:data:`~meshmocap.estimate.recovery.quality.LIMB_PARTS`; "body" counts for every limb) named in the
frame's message; the longest run of consecutive frames with some joint more than 100 mm
off; for gap captures, the frames after the gap until every joint is within 40 mm again.
Acceptance (from when the re-seat acted on the flags): every >150 mm frame flagged
with its limb, no >100 mm run longer than 10 frames, back under 40 mm within 10 frames of
the hull being whole.

Run: ``python benchmarks/bench_recovery.py [--captures gap_05_01 gap_09_01 01_01 05_03
60_01] [--methods patch] [--frames 300] [--work /tmp/meshmocap-recovery]``. Captures and
tracks are cached in ``--work``; the table is printed and written to ``--work``/results.md.
"""

from __future__ import annotations

import argparse
import os
import time
from datetime import datetime
from pathlib import Path

import numpy as np

from bench_init import DATA
from meshmocap.body.template import load_template
from meshmocap.estimate.recovery.quality import LIMB_PARTS
from meshmocap.studio.degrade import Degradation
from meshmocap.studio.synth import SynthSpec, synthesize
from meshmocap.trackers.driver import track_sequence
from meshmocap.trackers.options import TrackOptions
from meshmocap.trackers.registry import make_tracker

TEMPLATE = "neutral_5k"
#: capture → (motion file under DATA/mocap/cmu, first frame, missed limb joint, gap frames)
CAPTURES: dict[str, tuple[str, int, str | None, tuple[int, int] | None]] = {
    "gap_05_01": ("05_01.amc", 0, "left_elbow", (100, 110)),
    "gap_09_01": ("09_01.bvh", 4, "right_knee", (30, 40)),
    "01_01": ("01_01.amc", 0, None, None),
    "05_03": ("library/05_03.amc", 0, None, None),
    "60_01": ("library/60_01.amc", 0, None, None),
}


def limb_of(names: tuple[str, ...]) -> list[str]:
    """The limb (:data:`LIMB_PARTS`) of each evaluation joint."""
    return [next(limb for limb, parts in LIMB_PARTS.items() if n in parts) for n in names]


def longest_run(bad: np.ndarray) -> int:
    """Longest run of consecutive True values of ``bad`` (T,)."""
    best = run = 0
    for b in bad:
        run = run + 1 if b else 0
        best = max(best, run)
    return best


def score(track, cap, gap: tuple[int, int] | None, names) -> dict:
    """The recovery numbers of one track (module docstring)."""
    truth = np.stack([cap[cap.indices.index(int(i))].truth.joints for i in track.frames])
    e = np.linalg.norm(track.joints - truth, axis=2) * 1000  # (T, K) mm
    limbs = limb_of(names)
    over = [(k, j) for k, j in zip(*np.nonzero(e > 150), strict=True)]
    named = sum(
        "lost" in track.flags[k] and (limbs[j] in track.messages[k] or "body" in track.messages[k])
        for k, j in over
    )
    frames_over = sorted({k for k, _ in over})
    after = None
    if gap is not None:
        whole = [k for k, i in enumerate(track.frames) if i >= gap[1]]
        ok = [k for k in whole if e[k].max() < 40]
        after = (int(track.frames[ok[0]]) - gap[1]) if ok else None
    return dict(
        mean=float(e.mean()),
        worst=float(e.max()),
        n150=len(frames_over),
        joints150=len(over),
        named=int(named),
        run100=longest_run(e.max(axis=1) > 100),
        after=after,
        lost=sum("lost" in f for f in track.flags),
        reinit=sum("reinit" in f for f in track.flags),
        seconds=float(np.median(track.seconds[1:])),
    )


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--captures", nargs="+", default=list(CAPTURES), choices=list(CAPTURES))
    ap.add_argument("--methods", nargs="+", default=["patch"])
    ap.add_argument("--frames", type=int, default=300)
    ap.add_argument("--no-baseline", action="store_true", help="skip the recover=False tracks")
    ap.add_argument("--work", default="/tmp/meshmocap-recovery")
    args = ap.parse_args()
    if not (DATA / "mocap" / "cmu").is_dir():
        print(f"skipped: {DATA / 'mocap' / 'cmu'} is absent")
        return
    work = Path(args.work)
    template = load_template(TEMPLATE)
    names = template.eval_skeleton.names
    stamp = datetime.now().strftime("%Y-%m-%d %H:%M")
    load0, t0 = os.getloadavg()[0], time.perf_counter()
    rows = []
    for name in args.captures:
        file, s0, joint, gap = CAPTURES[name]
        deg = Degradation()
        if joint is not None:
            deg = Degradation(
                missed_limb=True,
                missed_limb_joint=joint,
                missed_limb_frames=(s0 + gap[0], s0 + gap[1]),
            )
        spec = SynthSpec(
            motion=str(DATA / "mocap" / "cmu" / file),
            template=TEMPLATE,
            fps=60.0,
            start=s0,
            stop=s0 + args.frames,
            degradation=deg,
        )
        print(f"{name}: capture", flush=True)
        cap = synthesize(work / "captures" / f"{name}-{args.frames}", spec, show_progress=True)
        gap_abs = None if gap is None else (s0 + gap[0], s0 + gap[1])
        for m in args.methods:
            for recover in (True,) if args.no_baseline else (True, False):
                out = (
                    work
                    / "tracks"
                    / f"{name}-{args.frames}"
                    / f"{m}-{'rec' if recover else 'norec'}"
                )
                print(f"  {m}, recover={recover}", flush=True)
                tracker = (
                    make_tracker(m, template=template) if m.startswith("cage") else make_tracker(m)
                )
                track = track_sequence(
                    tracker,
                    template,
                    cap,
                    out,
                    TrackOptions(init="truth", recover=recover, show_progress=True),
                )
                r = score(track, cap, gap_abs, names)
                rows.append((name, m, recover, len(track.frames), r))
                print(
                    f"    mean {r['mean']:.1f} mm, >150: {r['named']}/{r['joints150']} named, "
                    f"longest >100 run {r['run100']}, after gap {r['after']}",
                    flush=True,
                )
    head = (
        "| capture | method | recovery | frames | mean mm | worst mm | frames >150 | "
        ">150 joint-frames flagged with the limb | longest >100 run | back <40 mm after "
        "gap | lost | reinit | s/frame |"
    )
    lines = [
        f"Recovery acceptance (neutral_5k = performer, humaneva4, 60 fps, first pose from "
        f"truth), measured {stamp}, load average {load0:.1f}→{os.getloadavg()[0]:.1f} on "
        f"{os.cpu_count()} cores, {time.perf_counter() - t0:.0f} s",
        "",
        head,
        "|---|---|---|--:|--:|--:|--:|--:|--:|--:|--:|--:|--:|",
    ]
    for name, m, rec, n, r in rows:
        after = (
            ""
            if CAPTURES[name][3] is None
            else ("never" if r["after"] is None else f"{r['after']} frames")
        )
        lines.append(
            f"| {name} | {m} | {'on' if rec else 'off'} | {n} | {r['mean']:.1f} | "
            f"{r['worst']:.0f} | {r['n150']} | {r['named']}/{r['joints150']} | "
            f"{r['run100']} | {after} | {r['lost']} | {r['reinit']} | "
            f"{r['seconds']:.2f} |"
        )
    text = "\n".join(lines)
    print("\n" + text)
    work.mkdir(parents=True, exist_ok=True)
    (work / "results.md").write_text(text + "\n")


if __name__ == "__main__":
    main()
