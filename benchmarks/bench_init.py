"""Automatic initialisation acceptance: a performer anywhere in the
volume, facing any way, started at any frame.

Protocol: CMU clips from ../shared/data (05_01 walk, 09_01 run, 01_01 jumps), retargeted on
``neutral_5k`` (the template is the performer), synthetic captures at 60 fps in the
``humaneva4`` rig (4 cameras, visual hulls carved at 1 cm), the first 300 frames of each
clip (09_01 has 71 after its T-pose blend-in). Each clip is turned by every ``--headings``
angle (``meshmocap synth --heading``, about the vertical axis through the volume's centre)
and shifted (``--offset``): 1 m for even heading indices, 0.5 m for odd ones, along the
one of 8 compass directions that keeps the tracked frames closest to the volume's centre
(a walk already spans 4.5 m; the other directions take the performer out of the cameras'
view). Each case starts at frame ``start`` of the clip (``--starts``; a start past the
clip's end is replaced by the clip's middle frame, once) and is tracked to frame 300 by
``--method`` (patch) twice: ``init="auto"`` (the first pose found from the capture alone,
:func:`~meshmocap.estimate.pose.first_pose.initial_pose`) and ``init="truth"`` (the papers'
protocol), both with loss recovery on (the default). Scores: the mean joint error over the
15 evaluation joints of the first frame (auto) and of the whole tracked segment (auto and
truth, mm; :func:`~meshmocap.analysis.evaluate.evaluate`, frames whose subject leaves a
camera's view not scored). Acceptance: first frame ≤ 30 mm in every case, clip mean within
2 mm of ``--init truth``.

``--first-only`` synthesises and initialises the first frame of each case only (no
tracking), in a fraction of the time (the first pose's acceptance): clips 05_01 (walk),
01_01 (forward jumps) and 49_18 (balance, arms outstretched) by default, performed by
``--subjects`` (heavy_male and small_female, alternating with the heading), the first pose
searched with the performer's body as the template; per start the mean and worst joint
error, the search's winner, ranking key and margin to a distinct runner-up, and whether the
start is flagged uncertain (:func:`~meshmocap.estimate.pose.start.start_message`). None of
these clips is in the pose library the search uses (``tools/make_pose_library.py``). Acceptance:
≤ 30 mm in ≥ 95 % of starts, every start above that flagged. ``--jobs N`` runs cases
in N processes (each case is independent). Run:
``python benchmarks/bench_init.py [--clips 05_01 09_01 01_01] [--headings 0 45 ...]
[--starts 0 100 200] [--frames 300] [--first-only] [--jobs 1] [--work /tmp/meshmocap-init]``.
Captures and tracks are cached in ``--work`` (runs resume); the table is printed and written
to ``--work``/results.md (``results-first.md`` with ``--first-only``).
"""

from __future__ import annotations

import argparse
import os
import time
from concurrent.futures import ProcessPoolExecutor
from datetime import datetime
from pathlib import Path

import numpy as np

from meshmocap.analysis.evaluate import evaluate
from meshmocap.body.template import load_template
from meshmocap.estimate.pose.first_pose import initial_pose_of_frame
from meshmocap.estimate.pose.start import search_start
from meshmocap.estimate.recovery.observe import observed
from meshmocap.io.clips import clip_on
from meshmocap.studio.synth import SynthSpec, placed_motion, synthesize
from meshmocap.trackers.driver import track_sequence
from meshmocap.trackers.options import TrackOptions
from meshmocap.trackers.registry import make_tracker

#: ../shared/data beside the project (a worktree one level deeper finds it one more up)
DATA = next(
    (
        p / "shared" / "data"
        for p in Path(__file__).resolve().parents[2:4]
        if (p / "shared" / "data").is_dir()
    ),
    Path(__file__).resolve().parents[1].parent / "shared" / "data",
)
#: clip → (file in DATA/mocap/cmu, first frame at 60 fps)
CLIPS = {
    "05_01": ("05_01.amc", 0),
    "09_01": ("09_01.bvh", 4),
    "01_01": ("01_01.amc", 0),
    "49_18": ("49_18.amc", 0),
}
TEMPLATE = "neutral_5k"
#: Performers of the first-pose cases, alternating with the heading.
SUBJECTS = ("heavy_male", "small_female")


def offset_for(roots: np.ndarray, heading: float, size: float) -> tuple[float, float]:
    """The ``size``-metre shift, along one of 8 compass directions, that keeps the root
    positions ``roots`` (T, 3), turned by ``heading`` degrees, closest to the centre."""
    _, root = placed_motion(np.tile(np.eye(3), (len(roots), 1, 1, 1)), roots, heading=heading)
    best = None
    for k in range(8):
        d = size * np.array([np.cos(k * np.pi / 4), np.sin(k * np.pi / 4)])
        reach = np.linalg.norm(root[:, :2] + d, axis=1).max()
        if best is None or reach < best[0]:
            best = (reach, (round(float(d[0]), 3), round(float(d[1]), 3)))
    return best[1]


def cases(args) -> list[dict]:
    """Every (clip, heading, start) case with its capture spec."""
    template = load_template(TEMPLATE)
    out = []
    subjects = args.subjects or [TEMPLATE]
    for clip in args.clips:
        file, s0 = CLIPS[clip]
        motion = clip_on(template, DATA / "mocap" / "cmu" / file, fps=60.0)
        n = min(args.frames, motion.n_frames - s0)
        starts = [s for s in args.starts if s < n - 10]
        if len(starts) < len(args.starts):
            starts.append(n // 2)
        for i, h in enumerate(args.headings):
            for start in dict.fromkeys(starts):
                stop = start + 1 if args.first_only else n
                roots = motion.root_positions[s0 + start : s0 + stop]
                off = offset_for(roots, h, 1.0 if i % 2 == 0 else 0.5)
                subject = subjects[i % len(subjects)]
                spec = SynthSpec(
                    motion=str(DATA / "mocap" / "cmu" / file),
                    template=subject if args.first_only else TEMPLATE,
                    fps=60.0,
                    start=s0 + start,
                    stop=s0 + stop,
                    heading=float(h),
                    offset=off,
                )
                name = f"{clip}-h{h:g}-s{start}-n{stop - start}"
                if subject != TEMPLATE:
                    name += f"-{subject}"
                out.append(
                    dict(
                        clip=clip,
                        subject=subject,
                        heading=h,
                        start=start,
                        offset=off,
                        spec=spec,
                        name=name,
                        n=stop - start,
                    )
                )
    return out


def first_case(case: dict, work: str, options: dict) -> dict:
    """Synthesise (or reuse) one case's first frame and search its first pose with the
    performer's body; returns its numbers."""
    cap = synthesize(Path(work) / "captures" / case["name"], case["spec"], show_progress=False)
    template = load_template(case["subject"])
    frame = observed(cap[0])
    t0 = time.perf_counter()
    res = initial_pose_of_frame(template, frame, **options)
    err = np.linalg.norm(template.pose(res.R, res.root).eval_joints - frame.truth.joints, axis=1)
    return dict(
        case,
        spec=None,
        auto_first=1000 * float(err.mean()),
        auto_worst=1000 * float(err.max()),
        auto_label=res.label,
        score=1000 * res.score,
        key=1000 * res.key,
        margin=1000 * res.margin,
        mismatch=100 * res.mismatch,
        runner_up=res.runner_up.label if res.runner_up is not None else "",
        flagged=not search_start(int(cap.indices[0]), res).confident,
        seconds=time.perf_counter() - t0,
    )


def run_case(case: dict, work: str, method: str, first_only: bool) -> dict:
    """Synthesise (or resume) one case and track it; returns its numbers."""
    work = Path(work)
    t0 = time.perf_counter()
    cap = synthesize(work / "captures" / case["name"], case["spec"], show_progress=False)
    template = load_template(TEMPLATE)
    res = dict(case, spec=None)
    for init in ("auto",) if first_only else ("auto", "truth"):
        out = work / "tracks" / case["name"] / f"{method}-{init}"
        track = track_sequence(
            make_tracker(method), template, cap, out, TrackOptions(init=init, show_progress=False)
        )
        ev = evaluate(track, cap, silhouettes=False, surface_frames=0)
        res[f"{init}_first"] = float(ev.joints.per_frame[0]) if ev.joints.per_frame.size else np.nan
        res[f"{init}_mean"] = ev.joints.overall.mean
        res[f"{init}_label"] = ev.init
        res[f"{init}_lost"] = ev.lost
    res["seconds"] = time.perf_counter() - t0
    return res


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--clips", nargs="+", default=None, choices=list(CLIPS))
    ap.add_argument("--headings", nargs="+", type=float, default=list(range(0, 360, 45)))
    ap.add_argument("--starts", nargs="+", type=int, default=[0, 100, 200])
    ap.add_argument("--frames", type=int, default=300, help="first N frames of each clip")
    ap.add_argument("--method", default="patch")
    ap.add_argument("--first-only", action="store_true", help="initialise the first frames only")
    ap.add_argument(
        "--subjects",
        nargs="+",
        default=None,
        help=f"performers of the first-only cases, alternating (default {' '.join(SUBJECTS)})",
    )
    ap.add_argument("--jobs", type=int, default=1)
    ap.add_argument("--work", default="/tmp/meshmocap-init")
    args = ap.parse_args()
    if args.clips is None:
        args.clips = ["05_01", "01_01", "49_18"] if args.first_only else ["05_01", "09_01", "01_01"]
    if args.first_only and args.subjects is None:
        args.subjects = list(SUBJECTS)
    if not (DATA / "mocap" / "cmu").is_dir():
        print(f"skipped: {DATA / 'mocap' / 'cmu'} is absent")
        return
    todo = cases(args)
    stamp = datetime.now().strftime("%Y-%m-%d %H:%M")
    load0 = os.getloadavg()[0]
    print(
        f"{len(todo)} cases, {args.jobs} jobs, load average {load0:.1f} on {os.cpu_count()} cores",
        flush=True,
    )
    t0 = time.perf_counter()
    rows = []
    with ProcessPoolExecutor(args.jobs) as pool:
        if args.first_only:
            futures = [pool.submit(first_case, c, args.work, {}) for c in todo]
        else:
            futures = [pool.submit(run_case, c, args.work, args.method, False) for c in todo]
        for f in futures:
            r = f.result()
            rows.append(r)
            if args.first_only:
                print(
                    f"  {r['name']}: first {r['auto_first']:.1f} mm (worst joint "
                    f"{r['auto_worst']:.0f}), {r['auto_label']}, key {r['key']:.1f}, "
                    f"margin {r['margin']:.1f}, silhouettes {r['mismatch']:.1f} % off"
                    f"{', flagged' if r['flagged'] else ''}, "
                    f"{r['seconds']:.0f} s",
                    flush=True,
                )
            else:
                print(
                    f"  {r['name']}: first {r['auto_first']:.1f} mm ({r['auto_label']}), mean "
                    f"{r['auto_mean']:.1f} vs truth {r['truth_mean']:.1f}, {r['seconds']:.0f} s",
                    flush=True,
                )
    text = first_table(rows) if args.first_only else track_table(rows)
    if args.first_only:
        what = "first frames only, performer = template (heavy_male, small_female alternating)"
    else:
        what = f"{args.method}, neutral_5k = performer, tracked to frame {args.frames}"
    head = (
        f"Start acceptance ({what}; humaneva4, 60 fps), measured {stamp}, load average "
        f"{load0:.1f}→{os.getloadavg()[0]:.1f} on {os.cpu_count()} cores, "
        f"{time.perf_counter() - t0:.0f} s"
    )
    text = head + "\n\n" + text
    print("\n" + text)
    work = Path(args.work)
    work.mkdir(parents=True, exist_ok=True)
    (work / ("results-first.md" if args.first_only else "results.md")).write_text(text + "\n")


def first_table(rows: list[dict]) -> str:
    """The first-pose cases' table and summary (markdown)."""
    head = ["clip", "performer", "heading °", "start", "offset m", "first pose found"]
    head += ["key mm", "margin mm", "silhouette off %", "flagged", "mean mm", "worst joint mm"]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for r in rows:
        cells = [
            r["clip"],
            r["subject"],
            f"{r['heading']:g}",
            str(r["start"]),
            f"{r['offset'][0]:+.2f},{r['offset'][1]:+.2f}",
            r["auto_label"],
            f"{r['key']:.1f}",
            f"{r['margin']:.1f}",
            f"{r['mismatch']:.1f}",
            "yes" if r["flagged"] else "",
            f"{r['auto_first']:.1f}",
            f"{r['auto_worst']:.0f}",
        ]
        lines.append("| " + " | ".join(cells) + " |")
    first = np.array([r["auto_first"] for r in rows])
    flagged = np.array([r["flagged"] for r in rows])
    bad = first > 30
    lines += [
        "",
        f"first frame: {np.sum(~bad)}/{len(first)} starts ≤ 30 mm "
        f"({100 * np.mean(~bad):.0f} %); worst {first.max():.1f} mm, median "
        f"{np.median(first):.1f}; starts above 30 mm flagged: {np.sum(bad & flagged)}/"
        f"{np.sum(bad)}; starts ≤ 30 mm flagged: {np.sum(~bad & flagged)}/{np.sum(~bad)}",
    ]
    return "\n".join(lines)


def track_table(rows: list[dict]) -> str:
    """The tracked cases' table and summary (markdown)."""
    head = ["clip", "heading °", "start", "offset m", "first pose found", "first frame mm"]
    head += ["mean auto mm", "mean truth mm", "Δ mm", "lost auto/truth"]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for r in rows:
        cells = [
            r["clip"],
            f"{r['heading']:g}",
            str(r["start"]),
            f"{r['offset'][0]:+.2f},{r['offset'][1]:+.2f}",
            r["auto_label"].replace("auto: ", ""),
            f"{r['auto_first']:.1f}",
            f"{r['auto_mean']:.1f}",
            f"{r['truth_mean']:.1f}",
            f"{r['auto_mean'] - r['truth_mean']:+.1f}",
            f"{r['auto_lost']}/{r['truth_lost']}",
        ]
        lines.append("| " + " | ".join(cells) + " |")
    first = np.array([r["auto_first"] for r in rows])
    d = np.array([r["auto_mean"] - r["truth_mean"] for r in rows])
    lines += [
        "",
        f"first frame: {np.sum(first <= 30)}/{len(first)} cases ≤ 30 mm; worst "
        f"{first.max():.1f} mm, median {np.median(first):.1f}",
        f"clip mean, auto − truth: {np.sum(np.abs(d) <= 2)}/{len(d)} cases within "
        f"2 mm; largest {d[np.argmax(np.abs(d))]:+.1f} mm",
    ]
    return "\n".join(lines)


if __name__ == "__main__":
    main()
