"""The two-way pass against the forward pass alone, on captures of ``bench_limbs.py`` that
the forward pass fails.

Each capture (a trial of ``bench_limbs``'s table by a performer, its heading and offset
drawn there) is tracked on the default path (the body estimated from the capture, the
first pose searched, the pose library less the trial) by each ``--methods``: first the
forward pass alone (``passes="forward"``), then, on a copy of that track folder, the
two-way pass (``passes="two-way"``: the forward frames are read back, only the pass runs).
Per track: mean and worst joint error (mm) against the truth, the longest run of frames
with a joint more than 150 mm off, frames flagged lost, and the seconds of the forward pass
and of the two-way pass (wall time, same machine and run). Captures, bodies and tracks are
cached in ``--work``. Run:
``python benchmarks/bench_two_way.py --cases 01_01:heavy_male:patch 60_01:small_female:patch
[--frames 150] [--work /tmp/meshmocap-two-way]``.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import sys
import time
from pathlib import Path

import numpy as np

from meshmocap.estimate.performer.tracking_template import tracking_template
from meshmocap.studio.synth import synthesize
from meshmocap.trackers.driver import track_sequence
from meshmocap.trackers.options import TrackOptions
from meshmocap.trackers.registry import make_tracker

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_init import DATA
from bench_limbs import TRIALS, excluded, joint_errors, spec_of
from bench_recovery import longest_run

#: trial:performer:method tracked by default (they fail on the forward pass)
CASES = ("01_01:heavy_male:patch", "60_01:small_female:patch")


def _track(method, choice, cap, out, passes, trial):
    how = TrackOptions(
        init="auto",
        show_progress=False,
        template_info=choice.info,
        init_options={"exclude_trials": excluded(trial)},
        passes=passes,
    )
    return track_sequence(make_tracker(method), choice.template, cap, out, how)


def run_case(case: str, args) -> list[dict]:
    """Both passes on one capture: a row each."""
    trial, performer, method = case.split(":")
    work = Path(args.work)
    spec, info = spec_of(trial, performer, list(TRIALS).index(trial), args.frames)
    name = f"{trial}-{performer}-n{info['n']}"
    cap = synthesize(work / "captures" / name, spec, show_progress=False)
    choice = tracking_template(cap, "auto", work / "subjects" / name)
    fwd = work / "tracks" / name / f"{method}-forward"
    t0 = time.perf_counter()
    track = _track(method, choice, cap, fwd, "forward", trial)
    seconds = {"forward": time.perf_counter() - t0}
    timing = fwd / "bench_seconds.json"  # a cached forward track keeps its first timing
    if timing.is_file():
        seconds["forward"] = json.loads(timing.read_text())["forward"]
    else:
        timing.write_text(json.dumps(seconds))
    both = work / "tracks" / name / f"{method}-two-way"
    if both.exists():
        shutil.rmtree(both)
    shutil.copytree(fwd, both)
    t0 = time.perf_counter()
    two = _track(method, choice, cap, both, "two-way", trial)
    seconds["two-way"] = time.perf_counter() - t0
    record = two.meta.get("two_way", {})
    rows = []
    for passes, tr in (("forward", track), ("two-way", two)):
        e = joint_errors(tr, cap)
        rows.append(
            dict(
                case=name,
                method=method,
                passes=passes,
                mean=float(e.mean()),
                worst=float(e.max()),
                run150=longest_run((e > 150).any(axis=1)),
                bad=int((e > 150).any(axis=1).sum()),
                lost=int(sum("lost" in f for f in tr.flags)),
                frames=len(e),
                seconds=seconds[passes],
                keys=sum(bool(k["kept"]) for k in record.get("keyframes", ())),
                searched=len(record.get("keyframes", ())),
                changed=sum(c["frames"][1] - c["frames"][0] + 1 for c in record.get("changed", ())),
            )
        )
        r = rows[-1]
        print(
            f"  {name} {method} {passes}: mean {r['mean']:.1f} worst {r['worst']:.0f} "
            f"run>150 {r['run150']} bad {r['bad']} lost {r['lost']}/{r['frames']} "
            f"({r['seconds']:.0f} s)",
            flush=True,
        )
    return rows


def table(rows: list[dict]) -> str:
    """Forward against two-way per capture (markdown)."""
    head = ["capture", "method", "forward mean / worst mm", "two-way mean / worst mm"]
    head += [">150 mm run fwd → 2way", "frames >150 mm", "lost frames", "keyframes kept/searched"]
    head += ["frames changed", "forward s", "two-way pass s"]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    by = {(r["case"], r["method"], r["passes"]): r for r in rows}
    for (case, method, passes), f in by.items():
        if passes != "forward":
            continue
        t = by[case, method, "two-way"]
        cells = [
            case,
            method,
            f"{f['mean']:.1f} / {f['worst']:.0f}",
            f"{t['mean']:.1f} / {t['worst']:.0f}",
            f"{f['run150']} → {t['run150']}",
            f"{f['bad']} → {t['bad']}",
            f"{f['lost']} → {t['lost']} of {f['frames']}",
            f"{t['keys']}/{t['searched']}",
            str(t["changed"]),
            f"{f['seconds']:.0f}",
            f"{t['seconds']:.0f}",
        ]
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--cases", nargs="+", default=list(CASES), help="trial:performer:method")
    ap.add_argument("--frames", type=int, default=150)
    ap.add_argument("--work", default="/tmp/meshmocap-two-way")
    args = ap.parse_args()
    if not (DATA / "mocap" / "cmu" / "library").is_dir():
        print(f"skipped: {DATA / 'mocap' / 'cmu' / 'library'} is absent")
        return
    print(f"{len(args.cases)} captures, load average {os.getloadavg()[0]:.1f}", flush=True)
    rows = []
    for case in args.cases:
        rows += run_case(case, args)
    text = table(rows)
    print(text)
    print(f"load average at the end {os.getloadavg()[0]:.1f}")
    Path(args.work, "results.md").write_text(text + "\n")
    means = {
        p: np.mean([r["mean"] for r in rows if r["passes"] == p]) for p in ("forward", "two-way")
    }
    print(
        f"mean over captures: forward {means['forward']:.1f} mm, two-way {means['two-way']:.1f} mm"
    )


if __name__ == "__main__":
    main()
