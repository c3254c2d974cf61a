"""The default path against the papers' protocol (issue 28): every limb found and kept.

Protocol. Motions never seen by the pose prior: the CMU clips of ../shared/data (05_01 walk,
01_01 forward jumps, 49_18 balance with the arms out; none is in the pose library) and
trials of its pose-library folder (``mocap/cmu/library``) across its categories — modern
dance (05_03, held out of the library; 05_09), jump (13_39), run (09_06), salsa (60_01,
held out; 61_03), everyday (14_08) and arm-heavy motions (13_10, 14_07: the hands above
the chest in most frames). **The library split**: a library trial is tracked with the
pose library less that trial and, for salsa, less its partner's take of the same dance
(60_k and 61_k are the two partners of one take), so a motion that trains the prior never
scores it; the evaluation clips are not in the library at all. Each trial is performed by
``--performers`` (heavy_male and small_female, every trial by each; ``--quick``:
alternating), turned by a heading and shifted by an offset of up to 1 m drawn per trial
from a fixed seed (kept in the volume as ``bench_init.offset_for`` does), synthesised at
60 fps in the ``humaneva4`` rig (4 cameras, visual hulls at 1 cm), ``--frames`` frames
(150; fewer where the clip is shorter) from its start (past a BVH's T-pose).

Each capture is tracked by each ``--methods`` two ways:

* **papers' protocol** — the performer's own body as the template, the first pose from
  the truth (``init="truth"``);
* **default path** — the body estimated from the capture
  (:func:`~meshmocap.estimate.performer.tracking_template.tracking_template` with ``"auto"``), the
  first pose searched (``init="auto"``), loss checks on (the driver's defaults).

Per track: mean and worst joint error over the 15 evaluation joints (mm), the longest run
of frames with some joint more than 150 mm off, and the frames flagged ``lost``; the table
gives the default path's mean over the protocol's. ``--quick`` runs 3 trials × 60 frames ×
articulated ICP. Captures and tracks are cached in ``--work``; the table is printed and
written to ``--work``/results.md. Run:
``python benchmarks/bench_limbs.py [--quick] [--trials ...] [--methods ...] [--frames 150]``.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from datetime import datetime
from pathlib import Path

import numpy as np

from meshmocap.body.template import load_template
from meshmocap.estimate.performer.tracking_template import tracking_template
from meshmocap.io.clips import clip_on
from meshmocap.studio.synth import SynthSpec, synthesize
from meshmocap.trackers.driver import track_sequence
from meshmocap.trackers.options import TrackOptions
from meshmocap.trackers.registry import make_tracker

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_init import DATA, offset_for
from bench_recovery import longest_run

#: trial, file under DATA/mocap/cmu, first frame at 60 fps, category
_TABLE = """
05_01 05_01.amc 0 walk
01_01 01_01.amc 0 jump
49_18 49_18.amc 0 balance, arms out
05_03 library/05_03.amc 0 dance
05_09 library/05_09.amc 0 dance
13_39 library/13_39.bvh 10 jump
09_06 library/09_06.bvh 4 run
60_01 library/60_01.amc 0 salsa
61_03 library/61_03.amc 0 salsa
14_08 library/14_08.bvh 10 everyday
13_10 library/13_10.bvh 10 arm-heavy
14_07 library/14_07.bvh 10 arm-heavy
"""
#: trial → (file under DATA/mocap/cmu, category, first frame at 60 fps)
TRIALS: dict[str, tuple[str, str, int]] = {
    t: (f, c, int(s0)) for t, f, s0, c in (r.split(" ", 3) for r in _TABLE.strip().splitlines())
}
QUICK = ("13_10", "60_01", "01_01")
METHODS = ("patch", "cage", "articulated_icp")
PERFORMERS = ("heavy_male", "small_female")
SEED = 28


def excluded(trial: str) -> tuple[str, ...]:
    """Library trials kept out of the prior that scores ``trial`` (module docstring)."""
    if not TRIALS[trial][0].startswith("library/"):
        return ()
    subject, take = trial.split("_")
    partner = {"60": "61", "61": "60"}.get(subject)
    return (trial, f"{partner}_{take}") if partner else (trial,)


def spec_of(trial: str, performer: str, index: int, frames: int) -> tuple[SynthSpec, dict]:
    """The capture of ``trial`` by ``performer``: heading and offset drawn for the trial."""
    file, _, s0 = TRIALS[trial]
    path = DATA / "mocap" / "cmu" / file
    rng = np.random.default_rng([SEED, index])
    heading = float(np.round(rng.uniform(0, 360)))
    size = float(np.round(rng.uniform(0.0, 1.0), 2))
    motion = clip_on(load_template(performer), path, fps=60.0)
    stop = min(s0 + frames, motion.n_frames)
    off = offset_for(motion.root_positions[s0:stop], heading, size)
    spec = SynthSpec(
        motion=str(path),
        template=performer,
        fps=60.0,
        start=s0,
        stop=stop,
        heading=heading,
        offset=off,
    )
    return spec, dict(heading=heading, offset=off, n=stop - s0)


def joint_errors(track, cap) -> np.ndarray:
    """(T, K) joint errors of ``track`` against the capture's truth, mm."""
    truth = np.stack([cap[cap.indices.index(int(i))].truth.joints for i in track.frames])
    return np.linalg.norm(track.joints - truth, axis=2) * 1000


def run_case(trial: str, performer: str, index: int, args) -> list[dict]:
    """Synthesise one capture and track it by every method both ways."""
    work = Path(args.work)
    spec, info = spec_of(trial, performer, index, args.frames)
    name = f"{trial}-{performer}-n{info['n']}"
    cap = synthesize(work / "captures" / name, spec, show_progress=False)
    own = load_template(performer)
    rows = []
    for method in args.methods:
        for path in ("protocol", "default"):
            out = work / "tracks" / name / f"{method}-{path}"
            t0 = time.perf_counter()
            if path == "protocol":
                track = track_sequence(
                    make_tracker(method),
                    own,
                    cap,
                    out,
                    TrackOptions(init="truth", show_progress=False),
                )
            else:
                choice = tracking_template(cap, "auto", work / "subjects" / name)
                track = track_sequence(
                    make_tracker(method),
                    choice.template,
                    cap,
                    out,
                    TrackOptions(
                        init="auto",
                        show_progress=False,
                        template_info=choice.info,
                        init_options={"exclude_trials": excluded(trial)},
                    ),
                )
            e = joint_errors(track, cap)
            rows.append(
                dict(
                    trial=trial,
                    category=TRIALS[trial][1],
                    performer=performer,
                    method=method,
                    path=path,
                    mean=float(e.mean()),
                    worst=float(e.max()),
                    first=float(e[0].mean()),
                    run150=longest_run((e > 150).any(axis=1)),
                    lost=int(sum("lost" in f for f in track.flags)),
                    frames=len(e),
                    seconds=time.perf_counter() - t0,
                    **info,
                )
            )
            r = rows[-1]
            print(
                f"  {name} {method} {path}: mean {r['mean']:.1f} worst {r['worst']:.0f} "
                f"first {r['first']:.1f} run>150 {r['run150']} lost {r['lost']}/{r['frames']}"
                f" ({r['seconds']:.0f} s)",
                flush=True,
            )
    return rows


def table(rows: list[dict]) -> str:
    """The default path against the protocol, per capture and method (markdown)."""
    head = ["trial", "category", "performer", "heading °", "method"]
    head += ["protocol mean / worst mm", "default mean / worst mm", "ratio"]
    head += ["first frame mm", ">150 mm run", "lost frames"]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    by = {(r["trial"], r["performer"], r["method"], r["path"]): r for r in rows}
    summary: dict[str, list] = {}
    for (trial, performer, method, path), d in by.items():
        if path != "default" or (trial, performer, method, "protocol") not in by:
            continue
        p = by[trial, performer, method, "protocol"]
        summary.setdefault(method, []).append((p["mean"], d["mean"], d["worst"], d["run150"]))
        cells = [
            trial,
            d["category"],
            performer,
            f"{d['heading']:g}",
            method,
            f"{p['mean']:.1f} / {p['worst']:.0f}",
            f"{d['mean']:.1f} / {d['worst']:.0f}",
            f"{d['mean'] / p['mean']:.2f}",
            f"{d['first']:.1f}",
            str(d["run150"]),
            f"{d['lost']}/{d['frames']} (protocol {p['lost']})",
        ]
        lines.append("| " + " | ".join(cells) + " |")
    lines.append("")
    for method, v in summary.items():
        a = np.array(v)
        lines.append(
            f"{method}: protocol mean {a[:, 0].mean():.1f} mm, default mean {a[:, 1].mean():.1f}"
            f" mm (×{a[:, 1].mean() / a[:, 0].mean():.2f}), worst joint {a[:, 2].max():.0f} mm,"
            f" longest >150 mm run {int(a[:, 3].max())} frames, over {len(a)} captures"
        )
    return "\n".join(lines)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--quick", action="store_true", help="3 trials × 60 frames × ICP")
    ap.add_argument("--trials", nargs="+", choices=list(TRIALS), default=None)
    ap.add_argument("--methods", nargs="+", default=None)
    ap.add_argument("--performers", nargs="+", default=list(PERFORMERS))
    ap.add_argument("--frames", type=int, default=None)
    ap.add_argument("--work", default="/tmp/meshmocap-limbs")
    args = ap.parse_args()
    if not (DATA / "mocap" / "cmu" / "library").is_dir():
        print(f"skipped: {DATA / 'mocap' / 'cmu' / 'library'} is absent")
        return
    args.trials = args.trials or list(QUICK if args.quick else TRIALS)
    args.methods = args.methods or (["articulated_icp"] if args.quick else list(METHODS))
    args.frames = args.frames or (60 if args.quick else 150)
    cases = []
    for i, trial in enumerate(args.trials):
        index = list(TRIALS).index(trial)
        if args.quick:
            cases.append((trial, args.performers[i % len(args.performers)], index))
        else:
            cases += [(trial, p, index) for p in args.performers]
    load0 = os.getloadavg()[0]
    stamp = datetime.now().strftime("%Y-%m-%d %H:%M")
    print(f"{len(cases)} captures, load average {load0:.1f} on {os.cpu_count()} cores", flush=True)
    t0 = time.perf_counter()
    rows = []
    for trial, performer, index in cases:
        rows += run_case(trial, performer, index, args)
    text = (
        f"Issue 28 benchmark ({'quick: ' if args.quick else ''}{len(cases)} captures × "
        f"{', '.join(args.methods)}, ≤ {args.frames} frames at 60 fps, humaneva4), measured "
        f"{stamp}, load average {load0:.1f}→{os.getloadavg()[0]:.1f} on {os.cpu_count()} "
        f"cores, {time.perf_counter() - t0:.0f} s\n\n{table(rows)}"
    )
    print("\n" + text)
    work = Path(args.work)
    work.mkdir(parents=True, exist_ok=True)
    (work / "results.md").write_text(text + "\n")


if __name__ == "__main__":
    main()
