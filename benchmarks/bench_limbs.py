"""The default path against the papers' protocol: every limb found and kept.

Protocol. Motions never seen by the pose prior: the CMU clips of ../shared/data (05_01 walk,
01_01 forward jumps, 49_18 balance with the arms out; none is in the pose library) and
trials of its pose-library folder (``mocap/cmu/library``) across its categories — modern
dance (05_03, held out of the library; 05_09), jump (13_39), run (09_06), salsa (60_01,
held out; 61_03), everyday (14_08) and arm-heavy motions (13_10, 14_07: the hands above
the chest in most frames): 12 trials of 8 categories. **The library split**: a library
trial is tracked with the pose library less that trial and, for salsa, less its partner's
take of the same dance (60_k and 61_k are the two partners of one take), so a motion that
trains the prior never scores it; the evaluation clips are not in the library at all. The
trials are performed by ``--performers`` in turn (heavy_male, small_female, heavy_male,
...; ``--every-performer``: each trial by each), turned by a heading and shifted by an
offset of up to 1 m drawn per trial from a fixed seed (kept in the volume as
``bench_init.offset_for`` does), synthesised at 60 fps in the ``humaneva4`` rig (4
cameras, visual hulls at 1 cm), ``--frames`` frames (150; fewer where the clip is shorter)
from its start (past a BVH's T-pose).

Each capture is tracked by each ``--methods`` (patch, cage, articulated ICP):

* **papers' protocol** — the performer's own body as the template, the first pose from
  the truth (``init="truth"``), the forward pass alone;
* **default path** — the body estimated from the capture
  (:func:`~meshmocap.estimate.performer.tracking_template.tracking_template` with
  ``"auto"``), the first pose searched (``init="auto"``), loss checks on, with each of
  ``--passes``: ``forward`` (the forward pass alone) and ``two-way`` (the default for a
  capture on disk: the forward pass, then the two-way pass over its lost runs,
  :mod:`meshmocap.trackers.two_way`). The two-way track starts from the forward one (a copy
  of its folder, resumed: only the pass runs), so the pass's seconds are its own.

Per track: mean and worst joint error over the 15 evaluation joints (mm), the longest run
of frames with some joint more than 150 mm off, the frames flagged ``lost``, wall and CPU
seconds. Per tracker and pass: the mean over every frame of the set, the papers'
protocol's and their ratio, the trials with a run of more than 10 frames with a joint
more than 150 mm off and the longest such run, the ``lost`` flags' recall on bad frames (a
joint more than 150 mm off) and rate on good ones — as tracked (the shipped rule, fitted on
every category) and on the categories left out of the rule's fit (``bench_lost.py``'s
leave-one-category-out fit and scores on the evidence replayed over these tracks; rule
fitted on the other categories' default-path tracks of both passes, its budget held in
each of them, the two-way pass's disagreement flagged at the rule's fixed thresholds) — and
the two-way pass's
seconds against the forward pass's. Trials where patch is less accurate than articulated
ICP are listed.

Cost. Per capture the CPU seconds of each stage are printed (synthesis, each track, the
evidence replay) and, at the end, the projected wall time of the whole default set on two
quiet cores (``--jobs 2``: captures tracked in two processes, one BLAS thread each, none
forking workers of its own: ``MESHMOCAP_JOBS=1`` unless set). The
defaults (12 captures, each trial by one performer in turn, the three trackers, both
passes, 150 frames) are meant to fit 45 minutes there; the projection says whether they
do (the performer's body estimate is the largest single stage per capture). ``--quick``:
3 trials × 60 frames × articulated ICP. ``--set METHOD.FIELD=VALUE`` (repeatable): a
field of that method's options dataclass set for every track of it (e.g.
``articulated_icp.extrapolate=3``; a track cached in ``--work`` with other settings is
refused, so such a run takes a ``--work`` of its own). Captures and tracks are cached in
``--work``; the tables are printed and written to ``--work``/results.md.

Run: ``python benchmarks/bench_limbs.py [--quick] [--trials ...] [--methods ...]
[--passes forward two-way] [--frames 150] [--jobs 2] [--set METHOD.FIELD=VALUE ...]
[--work /tmp/meshmocap-limbs]``.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from dataclasses import fields
from datetime import datetime
from pathlib import Path

import numpy as np

from meshmocap.body.light import tracking_body
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
PASSES = ("forward", "two-way")
SEED = 28
#: A joint this far off (mm) makes a frame bad; a run of more than RUN_FRAMES such frames
#: fails a trial (the acceptance).
BAD_MM, RUN_FRAMES = 150.0, 10
#: Minutes the whole default set may take on two quiet cores.
BUDGET_MIN = 45.0


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


def has_passes() -> bool:
    """Whether this tree's tracking record has ``passes`` (the two-way pass)."""
    return "passes" in {f.name for f in fields(TrackOptions)}


def options(**kw) -> TrackOptions:
    """A tracking record; ``passes`` left out where this tree has no two-way pass (its
    tracks are then the forward pass's)."""
    if not has_passes():
        kw.pop("passes", None)
    return TrackOptions(show_progress=False, **kw)


class _Clock:
    """Wall and CPU seconds of a stage (this process's CPU time: one BLAS thread)."""

    def __enter__(self):
        self.wall, self.cpu = time.perf_counter(), time.process_time()
        return self

    def __exit__(self, *exc):
        self.wall = time.perf_counter() - self.wall
        self.cpu = time.process_time() - self.cpu


def start_from(forward: Path, out: Path) -> None:
    """Make ``out`` a copy of the finished forward track ``forward`` that a two-way run
    resumes (its ``track.json`` saying ``passes: two-way``): only the pass runs there."""
    if (out / "track.json").is_file():
        return  # already started (or done): resumed as it is
    tmp = out.with_name(out.name + ".partial")
    shutil.rmtree(tmp, ignore_errors=True)
    shutil.copytree(forward, tmp, ignore=shutil.ignore_patterns("*.lock", ".lock*"))
    meta_path = tmp / "track.json"
    meta = json.loads(meta_path.read_text())
    if "passes" in meta:
        meta["passes"] = "two-way"
    meta_path.write_text(json.dumps(meta, indent=2) + "\n")
    tmp.rename(out)


def made_forward(out: Path) -> None:
    """Say in the ``track.json`` of a track cached by a tree without the two-way pass (no
    ``passes`` key) what it was, the forward pass's, so that this tree resumes it."""
    meta_path = out / "track.json"
    if not has_passes() or not meta_path.is_file():
        return
    meta = json.loads(meta_path.read_text())
    if "passes" not in meta:
        meta["passes"] = "forward"
        meta_path.write_text(json.dumps(meta, indent=2) + "\n")


def evidence_of(track_dir: Path, cap, template) -> dict:
    """The ``lost`` evidence replayed over a track as the driver computes it
    (``bench_lost.track_evidence``), cached beside the track folder, the tracks'
    disagreement the two-way pass recorded (``bench_lost.track_disagreement``: the rule's
    second part, fitted and scored with the evidence) and, for a two-way track made before
    that record, ``also`` (T,): the frames it flagged because its tracks disagree there
    (``ambiguous`` in ``track.json``, added to the rule's flags when scored)."""
    from bench_lost import track_disagreement, track_evidence  # it imports TRIALS from here

    cache = track_dir.with_name(f"{track_dir.name}.evidence.npz")
    if not cache.is_file():
        np.savez(cache, **track_evidence(track_dir, cap, template))
    z = np.load(cache)
    meta = json.loads((track_dir / "track.json").read_text())
    two = meta.get("two_way") or {}
    amb = {int(a["frame"]) for a in two.get("ambiguous", ())} if "disagreement" not in two else {}
    frames = sorted(int(p.stem) for p in (track_dir / "frames").glob("*.npz"))
    also = np.array([i in amb for i in frames[1 : 1 + len(z["lost"])]], dtype=bool)
    return {
        **{k: z[k] for k in ("evidence", "error", "lost")},
        "also": also,
        "disagreement": track_disagreement(track_dir, len(z["lost"])),
    }


def tracker_settings(items: list[str]) -> dict[str, dict]:
    """``--set`` items ``METHOD.FIELD=VALUE`` as method → {field: value}; a value is read
    as JSON (numbers, true/false, lists) or else kept as a string."""
    out: dict[str, dict] = {}
    for item in items:
        key, eq, value = item.partition("=")
        method, dot, field = key.partition(".")
        if not (eq and dot and method and field):
            raise SystemExit(f"bench_limbs: --set expects METHOD.FIELD=VALUE, found {item!r}")
        try:
            parsed = json.loads(value)
        except ValueError:
            parsed = value
        out.setdefault(method, {})[field] = parsed
    return out


def settings_note(settings: dict[str, dict]) -> str:
    """The ``--set`` options as the results' heading states them ('' where none)."""
    items = [f"{m}.{k}={v}" for m, kv in settings.items() for k, v in kv.items()]
    return f"; options {', '.join(items)}" if items else ""


def run_case(trial: str, performer: str, index: int, args) -> tuple[list[dict], dict]:
    """Synthesise one capture and track it by every method, the papers' protocol and the
    default path with each pass; the rows and the CPU seconds per stage."""
    from meshmocap._threads import blas_threads

    work = Path(args.work)
    spec, info = spec_of(trial, performer, index, args.frames)
    name = f"{trial}-{performer}-n{info['n']}"
    cost: dict[str, float] = {}
    with _Clock() as c:
        cap = synthesize(work / "captures" / name, spec, show_progress=False)
    cost["synthesis"] = c.cpu
    own = load_template(performer)
    with _Clock() as c:
        choice = tracking_template(cap, "auto", work / "subjects" / name)
    cost["body"] = c.cpu
    base = dict(trial=trial, category=TRIALS[trial][1], performer=performer, **info)
    rows = []
    runs = [("protocol", "forward"), *(("default", p) for p in args.passes)]
    for method in args.methods:
        for path, passes in runs:
            out = work / "tracks" / name / f"{method}-{path}"
            made_forward(out)
            if path == "default" and passes == "two-way":
                out = out.with_name(f"{method}-two-way")
                start_from(out.with_name(f"{method}-default"), out)
            if path == "protocol":
                template, opts = own, options(init="truth", passes="forward")
            else:
                template = choice.template
                opts = options(
                    init="auto",
                    passes=passes,
                    template_info=choice.info,
                    init_options={"exclude_trials": excluded(trial)},
                    start=choice.start,  # as api.track: the body fit's pose is a candidate
                )
            light = tracking_body(template).light  # as tracked
            tracker = make_tracker(method, template=light, **args.set.get(method, {}))
            with _Clock() as c:
                track = track_sequence(tracker, template, cap, out, opts)
            cost[f"{method} {path} {passes}"] = c.cpu
            e = joint_errors(track, cap)
            row = dict(
                base,
                method=method,
                path=path,
                passes=passes,
                mean=float(e.mean()),
                worst=float(e.max()),
                first=float(e[0].mean()),
                run150=longest_run((e > BAD_MM).any(axis=1)),
                lost=int(sum("lost" in f for f in track.flags)),
                frames=len(e),
                seconds=c.wall,
                cpu=c.cpu,
                pass_seconds=float((track.meta.get("two_way") or {}).get("seconds", 0.0)),
            )
            if path == "default" and args.left_out:
                with _Clock() as c, blas_threads():
                    row["evidence"] = evidence_of(out, cap, template)
                cost[f"{method} evidence {passes}"] = c.cpu
            rows.append(row)
            print(
                f"  {name} {method} {path} {passes}: mean {row['mean']:.1f} worst "
                f"{row['worst']:.0f} first {row['first']:.1f} run>150 {row['run150']} lost "
                f"{row['lost']}/{row['frames']} ({row['seconds']:.0f} s, {row['cpu']:.0f} s CPU)",
                flush=True,
            )
    print(
        f"  {name} CPU s: " + ", ".join(f"{k} {v:.0f}" for k, v in cost.items()),
        flush=True,
    )
    return rows, cost


def table(rows: list[dict]) -> str:
    """The default path against the protocol, per capture, method and pass (markdown)."""
    head = ["trial", "category", "performer", "heading °", "method", "pass"]
    head += ["protocol mean / worst mm", "default mean / worst mm", "ratio"]
    head += ["first frame mm", ">150 mm run", "lost frames", "s (pass s)"]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    by = {(r["trial"], r["performer"], r["method"], r["path"], r["passes"]): r for r in rows}
    for (trial, performer, method, path, passes), d in by.items():
        p = by.get((trial, performer, method, "protocol", "forward"))
        if path != "default" or p is None:
            continue
        cells = [
            trial,
            d["category"],
            performer,
            f"{d['heading']:g}",
            method,
            passes,
            f"{p['mean']:.1f} / {p['worst']:.0f}",
            f"{d['mean']:.1f} / {d['worst']:.0f}",
            f"{d['mean'] / p['mean']:.2f}",
            f"{d['first']:.1f}",
            str(d["run150"]),
            f"{d['lost']}/{d['frames']} (protocol {p['lost']})",
            f"{d['seconds']:.0f}" + (f" ({d['pass_seconds']:.0f})" if passes == "two-way" else ""),
        ]
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines)


def _pct(a: int, b: int) -> str:
    return f"{100 * a / b:.1f} %" if b else "–"


def left_out_flags(rows: list[dict], method: str, passes: str) -> dict:
    """The flags' counts on each category's ``method``/``passes`` tracks by the rule fitted
    without that category (``bench_lost``: on the other categories' tracks of both passes,
    the budget held in each category)."""
    from bench_lost import GOOD_RATE, rule_of, score

    def ev(r: dict) -> dict:
        return dict(r["evidence"], category=r["category"])

    have = [r for r in rows if r["path"] == "default" and "evidence" in r]
    total = dict.fromkeys(("bad", "bad_flagged", "good", "good_flagged"), 0)
    for c in sorted({r["category"] for r in have}):
        train = [ev(r) for r in have if r["category"] != c]
        test = [
            ev(r)
            for r in have
            if r["category"] == c and r["method"] == method and r["passes"] == passes
        ]
        if not train or not test:
            continue
        for k, v in score(rule_of(train, GOOD_RATE), test).items():
            total[k] += v
    return total


def summary(rows: list[dict]) -> str:
    """Per tracker and pass: the acceptance's numbers (module docstring)."""
    from bench_lost import as_tracked

    lines = [
        "| tracker | pass | mean mm | protocol mean mm | ratio | trials with a >10-frame run "
        "> 150 mm | longest run | flags as tracked: bad / good flagged | flags, category "
        "left out: bad / good flagged | seconds: forward / pass |",
        "|---|---|--:|--:|--:|--:|--:|---|---|---|",
    ]
    prot = {(r["trial"], r["performer"], r["method"]): r for r in rows if r["path"] == "protocol"}
    fwd_s = {
        (r["trial"], r["performer"], r["method"]): r["seconds"]
        for r in rows
        if r["path"] == "default" and r["passes"] == "forward"
    }
    for method in dict.fromkeys(r["method"] for r in rows):
        for passes in dict.fromkeys(r["passes"] for r in rows if r["path"] == "default"):
            ds = [
                r
                for r in rows
                if r["method"] == method and r["path"] == "default" and r["passes"] == passes
            ]
            if not ds:
                continue
            n = sum(r["frames"] for r in ds)
            mean = sum(r["mean"] * r["frames"] for r in ds) / n
            ps = [prot[r["trial"], r["performer"], method] for r in ds]
            pmean = sum(r["mean"] * r["frames"] for r in ps) / sum(r["frames"] for r in ps)
            failing = sum(r["run150"] > RUN_FRAMES for r in ds)
            tracked = [
                {"error": r["evidence"]["error"], "lost": r["evidence"]["lost"]}
                for r in ds
                if "evidence" in r
            ]
            t = as_tracked(tracked) if tracked else None
            lo = left_out_flags(rows, method, passes) if tracked else None
            flags = (
                f"{_pct(t['bad_flagged'], t['bad'])} of {t['bad']} / "
                f"{_pct(t['good_flagged'], t['good'])} of {t['good']}"
                if t
                else "–"
            )
            left = (
                f"{_pct(lo['bad_flagged'], lo['bad'])} / {_pct(lo['good_flagged'], lo['good'])}"
                if lo and lo["bad"] + lo["good"]
                else "–"
            )
            if passes == "two-way":
                f_s = sum(fwd_s.get((r["trial"], r["performer"], method), 0.0) for r in ds)
                p_s = sum(r["pass_seconds"] or r["seconds"] for r in ds)
                secs = f"{f_s:.0f} / {p_s:.0f} (×{p_s / f_s:.2f})" if f_s else f"– / {p_s:.0f}"
            else:
                secs = f"{sum(r['seconds'] for r in ds):.0f} / –"
            lines.append(
                f"| {method} | {passes} | {mean:.1f} | {pmean:.1f} | {mean / pmean:.2f} | "
                f"{failing} of {len(ds)} | {max(r['run150'] for r in ds)} | {flags} | {left} "
                f"| {secs} |"
            )
    worse = _patch_worse(rows)
    lines += ["", "patch less accurate than articulated ICP (default path, per pass): "]
    lines[-1] += "; ".join(worse) if worse else "none"
    return "\n".join(lines)


def _patch_worse(rows: list[dict]) -> list[str]:
    """The trials (and pass) where patch's mean is above articulated ICP's."""
    by = {
        (r["trial"], r["performer"], r["passes"], r["method"]): r["mean"]
        for r in rows
        if r["path"] == "default"
    }
    out = []
    for (trial, performer, passes, method), m in by.items():
        icp = by.get((trial, performer, passes, "articulated_icp"))
        if method == "patch" and icp is not None and m > icp:
            out.append(f"{trial} {performer} {passes}: {m:.1f} vs {icp:.1f} mm")
    return out


def cost_lines(costs: list[dict], cases: int, jobs: int, default_cases: int) -> str:
    """CPU seconds per capture and stage, and the default set's projected wall time on
    ``jobs`` quiet cores (the stages' CPU seconds per capture, scaled to the default set)."""
    keys = list(dict.fromkeys(k for c in costs for k in c))
    per = {k: float(np.mean([c.get(k, 0.0) for c in costs])) for k in keys}
    total = sum(per.values())
    lines = [
        f"CPU seconds per capture (mean of {len(costs)}): "
        + ", ".join(f"{k} {v:.0f}" for k, v in per.items())
        + f"; {total:.0f} in all",
        f"projected from these stages: {default_cases} captures on {jobs} quiet cores ≈ "
        f"{total * default_cases / jobs / 60:.0f} min (budget {BUDGET_MIN:.0f}; the default "
        f"set's methods, passes and frames; this run: {cases} captures)",
    ]
    return "\n".join(lines)


def main() -> None:
    # the captures are the processes (--jobs): no worker pools inside them, so each stage's
    # CPU seconds are its process's, as in the earlier runs (meshmocap._parallel)
    os.environ.setdefault("MESHMOCAP_JOBS", "1")
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--quick", action="store_true", help="3 trials × 60 frames × ICP")
    ap.add_argument("--trials", nargs="+", choices=list(TRIALS), default=None)
    ap.add_argument("--methods", nargs="+", default=None)
    ap.add_argument("--performers", nargs="+", default=list(PERFORMERS))
    ap.add_argument("--every-performer", action="store_true", help="each trial by every performer")
    ap.add_argument("--passes", nargs="+", choices=PASSES, default=list(PASSES))
    ap.add_argument("--frames", type=int, default=None)
    ap.add_argument("--jobs", type=int, default=2, help="captures tracked at once (processes)")
    ap.add_argument(
        "--no-left-out",
        dest="left_out",
        action="store_false",
        help="skip the evidence replay and the flags scored on left-out categories",
    )
    ap.add_argument(
        "--set",
        action="append",
        default=[],
        metavar="METHOD.FIELD=VALUE",
        help="an option of a method's tracker, e.g. articulated_icp.extrapolate=3",
    )
    ap.add_argument("--work", default="/tmp/meshmocap-limbs")
    args = ap.parse_args()
    args.set = tracker_settings(args.set)
    if not (DATA / "mocap" / "cmu" / "library").is_dir():
        print(f"skipped: {DATA / 'mocap' / 'cmu' / 'library'} is absent")
        return
    if "two-way" in args.passes and not has_passes():
        print("this tree has no two-way pass (TrackOptions.passes): the forward pass only")
        args.passes = ["forward"]
    if "two-way" in args.passes and "forward" not in args.passes:
        args.passes = ["forward", "two-way"]  # the two-way track starts from the forward one
    args.trials = args.trials or list(QUICK if args.quick else TRIALS)
    args.methods = args.methods or (["articulated_icp"] if args.quick else list(METHODS))
    args.frames = args.frames or (60 if args.quick else 150)
    cases = []
    for i, trial in enumerate(args.trials):
        index = list(TRIALS).index(trial)
        if args.every_performer:
            cases += [(trial, p, index) for p in args.performers]
        else:
            cases.append((trial, args.performers[i % len(args.performers)], index))
    load0 = os.getloadavg()[0]
    stamp = datetime.now().strftime("%Y-%m-%d %H:%M")
    print(
        f"{len(cases)} captures × {', '.join(args.methods)} × passes {', '.join(args.passes)}, "
        f"{args.jobs} at once; load average {load0:.1f} on {os.cpu_count()} cores",
        flush=True,
    )
    t0 = time.perf_counter()
    rows, costs = [], []
    if args.jobs > 1 and len(cases) > 1:
        with ProcessPoolExecutor(max_workers=args.jobs) as pool:
            futures = [pool.submit(run_case, *c, args) for c in cases]
            for f in futures:
                r, c = f.result()
                rows += r
                costs.append(c)
    else:
        for c in cases:
            r, cost = run_case(*c, args)
            rows += r
            costs.append(cost)
    text = (
        f"Default path and papers' protocol "
        f"({'quick: ' if args.quick else ''}{len(cases)} captures × "
        f"{', '.join(args.methods)}, passes {', '.join(args.passes)}, ≤ {args.frames} frames "
        f"at 60 fps, humaneva4{settings_note(args.set)}), measured {stamp}, "
        f"load average {load0:.1f}→"
        f"{os.getloadavg()[0]:.1f} on {os.cpu_count()} cores, {args.jobs} at once, "
        f"{time.perf_counter() - t0:.0f} s\n\n{table(rows)}\n\n{summary(rows)}\n\n"
        f"{cost_lines(costs, len(cases), 2, len(TRIALS))}"
    )
    print("\n" + text)
    work = Path(args.work)
    work.mkdir(parents=True, exist_ok=True)
    (work / "results.md").write_text(text + "\n")


if __name__ == "__main__":
    main()
