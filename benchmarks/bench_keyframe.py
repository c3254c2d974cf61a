"""The keyframe search against the first pose's search, on frames inside failure runs
(target: one keyframe search ≤ 3 s on 2 cores, as accurate as the full search).

Protocol. Frames of bench_limbs captures where the default path lost a limb:
01_01 forward jumps by heavy_male (a wrist lost over frames 1–100), 60_01 salsa by
small_female (an arm lost) and 05_03 modern dance by heavy_male (a leg lost from frame 61),
each turned and shifted as :mod:`bench_limbs` draws it, synthesised one frame at a time at
60 fps in the ``humaneva4`` rig (4 cameras, 1 cm hulls). The performer's body is the
template; the library trials of the motion (and a salsa's partner take) are left out of the
search (``bench_limbs.excluded``). Per frame, three searches:

* ``full`` — :func:`~meshmocap.estimate.pose.first_pose.initial_pose_of_frame` (16 headings
  × the whole library, 12 coarse fits, 3 refined limb by limb);
* ``near`` — :func:`~meshmocap.estimate.pose.keyframe.keyframe_pose` with ``near`` the true
  pose made wrong as a track that lost a limb is: every joint turned by up to 5° at random,
  the heading off by 10°, the root 3 cm off, and the case's limb turned 70° at its upper
  joint and 60° at its middle one (its end joint more than 150 mm off), ``lost`` that limb;
* ``blind`` — :func:`keyframe_pose` without ``near``.

Per search: mean and worst joint error over the 15 evaluation joints against the truth (mm)
and the CPU seconds of the search process (``time.process_time``: on a shared machine the
wall clock measures the others' load; the ratio between searches is what carries over).
Results are cached per frame and search in ``--work``; the table is printed and written to
``--work``/results.md. Run: ``python benchmarks/bench_keyframe.py [--searches full near
blind] [--cases 01_01:heavy_male:left_arm:20,50 ...] [--work /tmp/meshmocap-keyframe]``.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import sys
import time
from datetime import datetime
from pathlib import Path

import numpy as np

from meshmocap.body.template import load_template
from meshmocap.estimate.pose.first_pose import initial_pose_of_frame
from meshmocap.estimate.pose.keyframe import keyframe_pose
from meshmocap.estimate.pose.pose_search import turned_about_z
from meshmocap.estimate.recovery.limbs import LIMBS
from meshmocap.estimate.recovery.observe import observed
from meshmocap.geometry.rotations import so3_exp
from meshmocap.studio.synth import synthesize

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_limbs import TRIALS, excluded, spec_of

#: trial:performer:limb made wrong in ``near``:frames (of the 150 bench_limbs frames)
CASES = (
    "01_01:heavy_male:right_arm:20,50,80,100",
    "60_01:small_female:left_arm:30,70,110,140",
    "05_03:heavy_male:left_leg:70,100,130",
)
SEARCHES = ("full", "near", "blind")


def wrong_near(template, R: np.ndarray, root: np.ndarray, limb: str, seed: int):
    """The true pose ``(R, root)`` as a track with ``limb`` lost might hold it (module
    docstring)."""
    rng = np.random.default_rng(seed)
    sk = template.skeleton
    w = rng.normal(size=(len(R), 3))
    w *= np.deg2rad(5.0) * rng.uniform(size=(len(R), 1)) / np.linalg.norm(w, axis=1, keepdims=True)
    Rn = so3_exp(w) @ R
    Rn = turned_about_z(Rn, np.deg2rad(10.0))
    upper, middle = (sk.index(n) for n in LIMBS[limb][0][:2])
    Rn[upper] = so3_exp(np.deg2rad(70.0) * np.array([1.0, 0.0, 0.0])) @ Rn[upper]
    Rn[middle] = so3_exp(np.deg2rad(60.0) * np.array([0.0, 1.0, 0.0])) @ Rn[middle]
    return Rn, root + np.array([0.03, 0.0, 0.0])


def frame_of(trial: str, performer: str, f: int, work: Path):
    """Frame ``f`` of the bench_limbs capture of ``trial`` by ``performer``, alone."""
    spec, _ = spec_of(trial, performer, list(TRIALS).index(trial), 150)
    spec = dataclasses.replace(spec, start=spec.start + f, stop=spec.start + f + 1)
    cap = synthesize(work / "captures" / f"{trial}-{performer}-f{f}", spec, show_progress=False)
    return observed(cap[0])


def run(search: str, trial: str, performer: str, limb: str, f: int, work: Path) -> dict:
    """One search on one frame: its errors and CPU seconds (cached in ``work``)."""
    out = work / "results" / f"{trial}-{performer}-f{f}-{search}.json"
    if out.exists():
        return json.loads(out.read_text())
    t = load_template(performer)
    fr = frame_of(trial, performer, f, work)
    _ = fr.points, fr.hull  # the frame read and carved before the clock
    truth = fr.truth
    near = wrong_near(t, truth.rotations, truth.root, limb, f)
    c0, w0 = time.process_time(), time.perf_counter()
    if search == "full":
        res = initial_pose_of_frame(t, fr, exclude_trials=excluded(trial))
    elif search == "near":
        res = keyframe_pose(t, fr, near=near, lost=(limb,), exclude_trials=excluded(trial))
    else:
        res = keyframe_pose(t, fr, exclude_trials=excluded(trial))
    cpu, wall = time.process_time() - c0, time.perf_counter() - w0
    e = np.linalg.norm(t.pose(res.R, res.root).eval_joints - truth.joints, axis=1) * 1000
    e_near = np.linalg.norm(t.pose(*near).eval_joints - truth.joints, axis=1) * 1000
    row = dict(
        search=search,
        trial=trial,
        performer=performer,
        limb=limb,
        frame=f,
        mean=float(e.mean()),
        worst=float(e.max()),
        near_mean=float(e_near.mean()),
        near_worst=float(e_near.max()),
        cpu=cpu,
        wall=wall,
        label=res.label,
        lost=list(res.lost),
    )
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(row))
    return row


def table(rows: list[dict], searches: list[str]) -> str:
    """Per frame, each search's mean / worst error and CPU seconds (markdown)."""
    head = ["trial", "performer", "frame", "near given (limb wrong)"]
    head += [f"{s} mean / worst mm, CPU s" for s in searches]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    by = {(r["trial"], r["performer"], r["frame"], r["search"]): r for r in rows}
    keys = sorted({k[:3] for k in by}, key=lambda k: (list(TRIALS).index(k[0]), k[2]))
    for trial, performer, f in keys:
        any_row = next(
            by[trial, performer, f, s] for s in searches if (trial, performer, f, s) in by
        )
        cells = [trial, performer, str(f)]
        cells.append(
            f"{any_row['near_mean']:.0f} / {any_row['near_worst']:.0f} ({any_row['limb']})"
        )
        for s in searches:
            r = by.get((trial, performer, f, s))
            cells.append(
                "–" if r is None else f"{r['mean']:.1f} / {r['worst']:.0f}, {r['cpu']:.1f}"
            )
        lines.append("| " + " | ".join(cells) + " |")
    lines.append("")
    for s in searches:
        rs = [r for r in rows if r["search"] == s]
        if rs:
            cpu = [r["cpu"] for r in rs]
            lines.append(
                f"{s}: mean {np.mean([r['mean'] for r in rs]):.1f} mm, worst joint "
                f"{max(r['worst'] for r in rs):.0f} mm, CPU {np.mean(cpu):.1f} s "
                f"per search (max {max(cpu):.1f}) over {len(rs)} frames"
            )
    return "\n".join(lines)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--cases", nargs="+", default=list(CASES))
    ap.add_argument("--searches", nargs="+", default=list(SEARCHES), choices=SEARCHES)
    ap.add_argument("--work", default="/tmp/meshmocap-keyframe")
    args = ap.parse_args()
    work = Path(args.work)
    load0 = os.getloadavg()[0]
    stamp = datetime.now().strftime("%Y-%m-%d %H:%M")
    rows = []
    for case in args.cases:
        trial, performer, limb, frames = case.split(":")
        for f in (int(x) for x in frames.split(",")):
            for s in args.searches:
                r = run(s, trial, performer, limb, f, work)
                print(
                    f"  {trial} {performer} f{f} {s}: mean {r['mean']:.1f} worst {r['worst']:.0f}"
                    f" cpu {r['cpu']:.1f} s (wall {r['wall']:.1f}) {r['label']} lost {r['lost']}",
                    flush=True,
                )
                rows.append(r)
    text = (
        f"Keyframe search against the first pose's search, measured {stamp}, load average "
        f"{load0:.1f}→{os.getloadavg()[0]:.1f} on {os.cpu_count()} cores\n\n"
        f"{table(rows, args.searches)}"
    )
    print("\n" + text)
    (work / "results.md").write_text(text + "\n")


if __name__ == "__main__":
    main()
