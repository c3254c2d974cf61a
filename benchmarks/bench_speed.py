"""Speed end to end per frame, stage by stage, and against trimesh's non-rigid ICP.

**Part 1, the whole frame** (``--templates``, ``--methods``): what a user waits for per
frame, measured on the tracking driver's own path (:func:`~meshmocap.trackers.driver.
track_sequence`, as ``meshmocap track`` runs it: the light body, the default checks on),
old tree and new in the same run (``--old``, ``--new``: ``src/`` folders; by default the
main this checkout started from, ``../base/src``, and this checkout). A ``--frames``-frame
procedural walk (``humaneva4`` hulls at 1 cm) of each template (default ``neutral``, 12k
vertices), the first pose from the truth (``init="truth"``), each method, each tree in a
child process of its own, trees alternating, ``--repeats`` times. Per frame, the driver's
stages (:mod:`meshmocap._timing`): ``read`` (the frame's files as the driver reads them),
``observe`` (points, normals, the distance's set-up), ``step`` with the tracker's own
stages, ``checks`` (the lost-limb assessment and any re-seat) and ``write`` (the frame's
result file). The new tree's driver records them itself (``timer=``); a tree whose driver
cannot is timed by wrapping the functions its driver calls (``observed``, the tracker's
``step``, ``recovered``, ``write_frame``: the same stages, ``--wrap`` forces it on both
trees to check they agree). On a loaded machine ``--cpu-clock`` makes every stage clock
read the child's CPU time (``time.perf_counter`` replaced by ``time.process_time`` in the
child), so the tracker's own stages are CPU too instead of their share of the step's.
Medians over frames 2… (frame 1 learns what a frame reads,
:class:`~meshmocap._timing.StageTimer`), then the median run; wall ms and CPU ms of the
child (CPU says what a frame costs when the machine is shared; the trackers clock their
own stages in wall time only, shown in CPU as ``≈`` their share of the step's CPU); the
mean joint error (mm, 15 joints against the truth) says the speed is not bought with
accuracy. The tables are
markdown, to paste into a change's note.

**Part 2, against trimesh** (``--crane``): the MIT crane (``../shared/data``), ``ring8``
hulls at 1 cm as ``meshmocap bench`` makes them, the tracking template frame 0's true mesh
rigged (10,002 vertices, :func:`~meshmocap.apps.bench.captures.mesh_template`). Frames 2,
4, …, 40 are tracked by each method after frame 0 (the template's own pose), and
``trimesh.registration.nricp_amberg`` (Amberg et al. 2007, default schedule) registers the
same template to the hull mesh of each of those frames, from the template as it is
(``--nricp-every`` k: every k-th of those frames, to save time). Error: per vertex against
the crane's true vertices (mm), over frames 2–40, and over the frames nricp registered. The
ratio is nricp's median seconds per frame over the method's (driver's time: read + step).
trimesh's closest-point queries need ``rtree`` (``pip install rtree``; skipped without).

**Part 3, light body** (``--light``): the driver's path (``track_sequence``) on a
``--frames``-frame walk of a 12k-vertex body (``--light-template``, default ``neutral``:
the bundled topology, as an estimated body has), first pose from the truth, each method
tracking the template itself (``light=None``) and its 5,000-vertex light copy
(:mod:`meshmocap.body.light`, the default), alternating, ``--repeats`` times: median
seconds per frame of the driver (frames 1…), mean joint and vertex error (mm, the full
template's vertices against the truth's), and the ratios.

Wall times on a shared machine are noisy: the load average is printed with every table.
Run: ``python benchmarks/bench_speed.py [--frames 30] [--repeats 3] [--templates ...]
[--methods ...] [--old SRC] [--new SRC] [--trees old new] [--wrap] [--cpu-clock] [--no-crane]
[--nricp-every 1] [--light] [--work /tmp/meshmocap-speed]``.
"""

from __future__ import annotations

import argparse
import importlib.util
import inspect
import json
import time
from pathlib import Path

import numpy as np

from _trees import add_tree_args, load, python_in, run_child, tree_env
from meshmocap.analysis.metrics import correspondence_error
from meshmocap.apps.bench.captures import make_capture, mesh_template, parse_capture
from meshmocap.body.template import load_template
from meshmocap.io.capture import Capture
from meshmocap.trackers.driver import track_sequence
from meshmocap.trackers.registry import make_tracker

try:  # a tree from before the driver's options record (an older main) takes keywords
    from meshmocap.trackers.options import TrackOptions
except ImportError:
    TrackOptions = None

DATA = Path(__file__).resolve().parents[1].parent / "shared" / "data"
METHODS = ("cage", "patch", "articulated_icp")


def _load() -> str:
    return load()


class WrapTimer:
    """The driver's stages for a tree whose driver records none: the functions it calls
    wrapped in the child process (``track_frame`` starts a frame; ``observed`` ends the
    read, reads and derives what the frame before used, as the new driver does, and ends
    the observation; the tracker's ``step`` and its ``stage_seconds``; ``recovered``: the
    checks; ``write_frame``: the write). Per-frame dicts like
    :class:`~meshmocap._timing.StageTimer`'s."""

    def __init__(self, driver, tracker) -> None:
        self.frames: list[dict] = []
        self.cpu: list[dict] = []
        self.reads: tuple = ()
        self.derived: tuple = ()
        self.frame = None
        on = {k: getattr(driver, k) for k in ("track_frame", "observed", "recovered")}
        write, step = driver.write_frame, tracker.step

        def track_frame(*a, **k):
            self.frames.append({})
            self.cpu.append({})
            self.t, self.c, self.frame = time.perf_counter(), time.process_time(), ()
            return on["track_frame"](*a, **k)

        def observed(raw):
            if self.frame is None:  # the first pose's search, not a tracked frame
                return on["observed"](raw)
            for name in self.reads:
                getattr(raw, name)
            self.lap("read")
            obs = on["observed"](raw)
            for name in self.derived:
                getattr(obs, name)
            self.lap("observe")
            self.frame = (raw, obs)
            return obs

        def timed_step(frame):
            before = dict(getattr(tracker, "stage_seconds", {}))
            r = step(frame)
            if self.frame is not None:
                self.lap("step")
                for k, v in getattr(tracker, "stage_seconds", {}).items():
                    self.frames[-1][f"step.{k}"] = v - before.get(k, 0.0)
            return r

        def recovered(*a, **k):
            r = on["recovered"](*a, **k)
            self.lap("checks")
            return r

        def write_frame(out, r):
            write(out, r)
            if self.frame is not None:
                self.lap("write")
                if self.frame:
                    raw, obs = self.frame
                    self.reads = tuple(n for n in ("hull_mesh", "hull") if n in vars(raw))
                    self.derived = tuple(n for n in ("points", "field") if n in vars(obs))
                self.frame = None

        for name, fn in (
            ("track_frame", track_frame),
            ("observed", observed),
            ("recovered", recovered),
            ("write_frame", write_frame),
        ):
            setattr(driver, name, fn)
        tracker.step = timed_step

    def lap(self, stage: str) -> None:
        t, c = time.perf_counter(), time.process_time()
        self.frames[-1][stage] = self.frames[-1].get(stage, 0.0) + t - self.t
        self.cpu[-1][stage] = self.cpu[-1].get(stage, 0.0) + c - self.c
        self.t, self.c = t, c


def child_stages(args) -> dict:
    """One run in this process (the tree on ``PYTHONPATH``): per-frame stage seconds (wall,
    CPU) of the driver tracking the walk, and the mean joint error (mm)."""
    import meshmocap.trackers.driver as driver
    from meshmocap.body.light import tracking_body

    if args.cpu_clock:  # every stage clock of the library (time.perf_counter) reads CPU
        time.perf_counter = time.process_time

    template = load_template(args.templates[0])
    capture = Capture(args.capture)
    tracker = make_tracker(args.methods[0], template=tracking_body(template).light)
    kw: dict = {}
    if not args.wrap and "timer" in inspect.signature(driver.track_sequence).parameters:
        from meshmocap._timing import StageTimer

        timer = kw["timer"] = StageTimer()
    else:
        timer = WrapTimer(driver, tracker)
    settings = dict(resume=False, show_progress=False, init="truth")
    if TrackOptions is not None:
        settings = {"options": TrackOptions(**settings)}
    c0 = time.process_time()
    track = driver.track_sequence(
        tracker,
        template,
        capture,
        Path(args.work) / "tracks" / f"stages-{args.methods[0]}",
        **settings,
        **kw,
    )
    truth = np.stack([f.truth.joints for f in capture])
    err = 1000 * np.linalg.norm(track.joints - truth, axis=2).mean()
    return {
        "frames": timer.frames,
        "cpu": timer.cpu,
        "error_mm": float(err),
        "cpu_s": time.process_time() - c0,
        "timer": type(timer).__name__,
    }


def _medians(frames: list[dict]) -> dict[str, float]:
    """Median ms per frame of each stage over frames 2… (a frame without it: 0), and of
    the driver's stages' sum (``total``)."""
    rows = frames[1:] or frames
    keys = {k for f in rows for k in f}
    out = {k: 1000 * float(np.median([f.get(k, 0.0) for f in rows])) for k in keys}
    out["total"] = 1000 * float(
        np.median([sum(v for k, v in f.items() if "." not in k) for f in rows])
    )
    return out


STAGE_ORDER = ("read", "observe", "step", "checks", "write")


def stages_table(args, work: Path) -> None:
    for name in args.templates:
        template = load_template(name)
        # made by the first tree (the old one): a newer tree reads older captures
        code = (
            "from meshmocap.apps.bench.captures import make_capture, parse_capture; "
            f"print(make_capture(parse_capture('walk', frames={args.frames}), "
            f"{str(work / args.trees[0])!r}, template={name!r}, show_progress=False).path)"
        )
        first = args.trees[0]
        capture = Capture(python_in(tree_env(getattr(args, first), work, first), code))
        print(
            f"\n### whole frame: {name} ({template.n_vertices} vertices, tracked on its light "
            f"body), {args.frames}-frame walk, humaneva4 hulls, init truth, default checks; "
            f"{args.repeats} runs per tree, alternating; {_load()}",
            flush=True,
        )
        for method in args.methods:
            runs: dict[str, list[dict]] = {t: [] for t in args.trees}
            for _ in range(args.repeats):
                for tree in args.trees:
                    child = [
                        *("--templates", name, "--methods", method, "--frames", str(args.frames)),
                        *("--capture", str(capture.path), "--work", str(work / tree)),
                        *(["--wrap"] if args.wrap else []),
                        *(["--cpu-clock"] if args.cpu_clock else []),
                    ]
                    env = tree_env(getattr(args, tree), work, tree)
                    res = run_child(__file__, child, env, work / f"stages-{tree}.json")
                    res["wall_ms"], res["cpu_ms"] = _medians(res["frames"]), _medians(res["cpu"])
                    runs[tree].append(res)
            clock = "; --cpu-clock: the wall columns are CPU too" if args.cpu_clock else ""
            print(
                f"\n**{method}** (ms per frame, median of frames 2…{args.frames - 1}; "
                f"{_load()}{clock})"
            )
            print(_stage_markdown(runs))
    print(f"(after: {_load()})")


def _stage_markdown(runs: dict[str, list[dict]]) -> str:
    """The markdown table of one method: a row per stage, wall and CPU ms per tree (the
    median run by total wall time)."""
    pick = {}
    for tree, rs in runs.items():
        order = np.argsort([r["wall_ms"]["total"] for r in rs])
        pick[tree] = rs[int(order[len(rs) // 2])]
    keys = list(dict.fromkeys(k for r in pick.values() for f in r["frames"] for k in f))
    rows = []
    for s in STAGE_ORDER:  # the driver's stages, each with its parts in the tracker's order
        rows += [s] * (s in keys) + [k for k in keys if k.startswith(f"{s}.")]
    rows.append("total")
    head = " | ".join(f"{t} wall | {t} CPU" for t in pick)
    out = [f"| stage | {head} |", "|---" + "|---:" * (2 * len(pick)) + "|"]
    for k in rows:
        cells = []
        for r in pick.values():
            w, c = r["wall_ms"].get(k), r["cpu_ms"].get(k)
            if c is None and w is not None and "." in k:  # a tracker's stage: wall only
                share = r["cpu_ms"].get("step", 0.0) / max(r["wall_ms"].get("step", 0.0), 1e-9)
                cells += [f"{w:.1f}", f"≈{w * share:.1f}"]
                continue
            cells += [f"{w:.1f}" if w is not None else "", f"{c:.1f}" if c is not None else ""]
        label = f"&nbsp;&nbsp;{k.split('.', 1)[1]}" if "." in k else k
        out.append(f"| {label} | {' | '.join(cells)} |")
    errs = " | ".join(f"{r['error_mm']:.1f} mm | " for r in pick.values())
    out.append(f"| joint error | {errs.rstrip()} |".replace("|  |", "| |"))
    spread = "; ".join(
        f"{t}: runs {min(r['wall_ms']['total'] for r in rs):.0f}–"
        f"{max(r['wall_ms']['total'] for r in rs):.0f} ms wall ({pick[t]['timer']})"
        for t, rs in runs.items()
    )
    return "\n".join(out) + f"\n\n({spread})"


def nricp(template, capture, positions: list[int]) -> tuple[np.ndarray, list[float]]:
    """trimesh's Amberg non-rigid ICP of the template onto each frame's hull mesh:
    vertices (T, n, 3) and seconds per frame."""
    import trimesh
    from trimesh.registration import nricp_amberg  # its closest points need rtree

    source = trimesh.Trimesh(template.V, template.F, process=False)
    out, sec = [], []
    for k in positions:
        V, F = capture[k].hull_mesh
        target = trimesh.Trimesh(V, F, process=False)
        t0 = time.perf_counter()
        out.append(np.asarray(nricp_amberg(source, target), dtype=np.float64))
        sec.append(time.perf_counter() - t0)
        print(f"  nricp frame {capture.indices[k]}: {sec[-1]:.1f} s", flush=True)
    return np.stack(out), sec


def crane_table(args, work: Path) -> None:
    spec = parse_capture("crane", data=DATA)
    capture = make_capture(spec, work, show_progress=True)
    template = mesh_template(capture, cache=work / "templates" / f"{capture.path.name}.npz")
    positions = [0, *range(2, 41, 2)]
    truth = np.stack([capture[k].truth.vertices for k in positions[1:]]).astype(np.float64)
    rows = []
    for method in [m for m in args.methods if m != "cage"]:  # cage needs a crane manifold
        out = work / "tracks" / f"crane-{method}"
        track = track_sequence(
            make_tracker(method),
            template,
            capture,
            out,
            TrackOptions(positions=positions, resume=False, show_progress=False),
        )
        e = correspondence_error(track.vertices[1:], truth).errors  # (20, n) mm
        rows.append((method, e, float(np.median(track.seconds[1:]))))
        print(f"  {method}: {e.mean():.1f} mm, {rows[-1][2]:.3f} s/frame", flush=True)
    picked = positions[1 :: args.nricp_every]
    V, sec = nricp(template, capture, picked)
    e_n = correspondence_error(V, truth[:: args.nricp_every]).errors
    s_n = float(np.median(sec))
    print(
        f"\n### crane, ring8 hulls, template frame 0 rigged ({template.n_vertices} v), "
        f"frames 2–40 every 2nd; nricp on {len(picked)} of them; {_load()}"
    )
    print(
        "| method | mean mm | median mm | p95 mm | mean mm, nricp's frames | s/frame "
        "| nricp s / method s |\n|---|---:|---:|---:|---:|---:|---:|"
    )
    print(f"| trimesh nricp_amberg | | | | {e_n.mean():.1f} | {s_n:.2f} | 1 |")
    for method, e, s in rows:
        sub = e[:: args.nricp_every].mean()
        print(
            f"| {method} | {e.mean():.1f} | {np.median(e):.1f} | {np.percentile(e, 95):.1f} "
            f"| {sub:.1f} | {s:.3f} | {s_n / s:.0f}× |"
        )


def light_table(args, work: Path) -> None:
    from meshmocap.body.light import LIGHT_VERTICES, tracking_body

    name = args.light_template
    template = load_template(name)
    capture = make_capture(
        parse_capture("walk", frames=args.frames), work, template=name, show_progress=False
    )
    truth_J = np.stack([f.truth.joints for f in capture])
    truth_V = np.stack([f.truth.vertices for f in capture])
    print(
        f"\n### light body: {name} ({template.n_vertices} v) tracked as it is and on "
        f"{tracking_body(template).light.n_vertices} v; {args.frames}-frame walk, humaneva4, "
        f"init truth; {args.repeats} runs each, alternating; {_load()}"
    )
    print(
        "| method | s/frame full | s/frame light | ratio | joints mm full → light "
        "| vertices mm full → light |\n|---|---:|---:|---:|---:|---:|"
    )
    for method in args.methods:
        res: dict = {None: [], LIGHT_VERTICES: []}
        for _ in range(args.repeats):
            for light in (None, LIGHT_VERTICES):
                body = tracking_body(template, n_vertices=light)
                out = work / "tracks" / f"light-{method}-{light}"
                track = track_sequence(
                    make_tracker(method, template=body.light),
                    template,
                    capture,
                    out,
                    TrackOptions(
                        resume=False, show_progress=False, init="truth", recover=False, light=light
                    ),
                )
                ej = 1000 * np.linalg.norm(track.joints - truth_J, axis=2).mean()
                ev = 1000 * np.linalg.norm(track.vertices - truth_V, axis=2).mean()
                res[light].append((float(np.median(track.seconds[1:])), ej, ev))
        (sf, jf, vf), (sl, jl, vl) = (np.median(np.array(res[k]), axis=0) for k in res)
        print(
            f"| {method} | {sf:.3f} | {sl:.3f} | {sl / sf:.2f} | {jf:.1f} → {jl:.1f} "
            f"| {vf:.1f} → {vl:.1f} |",
            flush=True,
        )
    print(f"(after: {_load()})")


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--frames", type=int, default=30)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--templates", nargs="+", default=["neutral"])
    ap.add_argument("--methods", nargs="+", default=list(METHODS), choices=METHODS)
    ap.add_argument("--no-stages", action="store_true", help="only the crane table")
    ap.add_argument("--no-crane", action="store_true", help="only the stage tables")
    ap.add_argument("--light", action="store_true", help="only the light-body table")
    ap.add_argument("--light-template", default="neutral", help="the light table's body")
    ap.add_argument("--nricp-every", type=int, default=1, help="nricp on every k-th frame")
    ap.add_argument("--work", default="/tmp/meshmocap-speed")
    ap.add_argument("--wrap", action="store_true", help="time by wrapping on every tree")
    ap.add_argument(
        "--cpu-clock",
        action="store_true",
        help="every stage clock reads CPU time (a loaded machine: the tracker's stages too)",
    )
    ap.add_argument("--child", help=argparse.SUPPRESS)  # a run in this process: JSON here
    ap.add_argument("--capture", help=argparse.SUPPRESS)
    add_tree_args(ap)
    args = ap.parse_args()
    work = Path(args.work)
    if args.child:
        Path(args.child).write_text(json.dumps(child_stages(args)))
        return
    if args.light:
        light_table(args, work)
        return
    if not args.no_stages:
        stages_table(args, work)
    if args.no_crane:
        return
    if not (DATA / "meshes" / "crane").is_dir():
        print(f"crane table skipped: {DATA / 'meshes' / 'crane'} is absent")
        return
    if importlib.util.find_spec("rtree") is None:
        print("crane table skipped: trimesh's nricp_amberg needs rtree (pip install rtree)")
        return
    crane_table(args, work)


if __name__ == "__main__":
    main()
