"""Speed end to end per frame, stage by stage, and against trimesh's non-rigid ICP (issue 21).

**Part 1, stages** (``--templates``, ``--methods``): a ``--frames``-frame procedural walk
(``humaneva4`` hulls at 1 cm) of each template (``neutral_5k``, 5,000 vertices, and
``neutral``, 12k), tracked by each method from the true pose of frame 0, ``--repeats``
times. Per frame: ``read`` (inflating the tracker's input: the hull's surface mesh, or the
cage tracker's occupancy), then ``step`` with the tracker's own stage breakdown
(``STAGES`` of each tracker module, median per frame); the total is read + step, wall
clock and CPU time of this process (the CPU time says what the frame costs when the
machine is shared). Medians
over frames 1…, then the median run (min–max of the runs' medians beside it); the mean
joint error (mm, 15 joints against the truth) shows the speed is not bought with accuracy.

**Part 2, against trimesh** (``--crane``): the MIT crane (``../shared/data``), ``ring8``
hulls at 1 cm as ``meshmocap bench`` makes them, the tracking template frame 0's true mesh
rigged (10,002 vertices, :func:`~meshmocap.apps.bench_captures.mesh_template`). Frames 2,
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
[--methods ...] [--no-crane] [--nricp-every 1] [--light] [--work /tmp/meshmocap-speed]``.
"""

from __future__ import annotations

import argparse
import importlib
import importlib.util
import os
import time
from pathlib import Path

import numpy as np

from meshmocap.analysis.metrics import correspondence_error
from meshmocap.apps.bench_captures import make_capture, mesh_template, parse_capture
from meshmocap.body.template import load_template
from meshmocap.trackers.driver import track_sequence
from meshmocap.trackers.registry import make_tracker

DATA = Path(__file__).resolve().parents[1].parent / "shared" / "data"
METHODS = ("cage", "patch", "articulated_icp")
MODULES = {"cage": "cage.tracker", "patch": "patch.tracker", "articulated_icp": "articulated_icp"}


def _load() -> str:
    return f"load average {os.getloadavg()[0]:.2f} on {os.cpu_count()} cores"


def stage_run(method: str, template, capture, n: int):
    """One run: per-frame (wall, cpu, read) seconds (frames 1…n−1), the median seconds
    per frame of each stage, mean joint error (mm)."""
    tracker = make_tracker(method, template=template)
    f0 = capture[0]
    truth = f0.truth
    tracker.init(template, f0, truth.rotations, truth.root)
    wall, cpu, read, err, stages = [], [], [], [], []
    for k in range(1, n):
        frame = capture[k]  # a fresh frame: nothing read yet
        before = dict(tracker.stage_seconds)
        w0, c0 = time.perf_counter(), time.process_time()
        _ = frame.hull if method.startswith("cage") else frame.hull_mesh  # cached for step
        w1 = time.perf_counter()
        r = tracker.step(frame)
        wall.append(time.perf_counter() - w0)
        cpu.append(time.process_time() - c0)
        read.append(w1 - w0)
        stages.append({k: v - before[k] for k, v in tracker.stage_seconds.items()})
        err.append(1000 * np.linalg.norm(r.joints - frame.truth.joints, axis=1).mean())
    st = {k: float(np.median([s[k] for s in stages])) for k in stages[0]}
    return np.array(wall), np.array(cpu), np.array(read), st, float(np.mean(err))


def stages_table(args, work: Path) -> None:
    spec = parse_capture("walk", frames=args.frames)
    for name in args.templates:
        template = load_template(name)
        capture = make_capture(spec, work, template=name, show_progress=False)
        print(
            f"\n### {name} ({template.n_vertices} vertices), {args.frames}-frame walk, "
            f"humaneva4 hulls; {args.repeats} runs; {_load()}"
        )
        for method in args.methods:
            runs = [stage_run(method, template, capture, args.frames) for _ in range(args.repeats)]
            meds = [float(np.median(r[0])) for r in runs]
            i = int(np.argsort(meds)[len(meds) // 2])  # the median run
            wall, cpu, read, st, err = runs[i]
            names = importlib.import_module(f"meshmocap.trackers.{MODULES[method]}").STAGES
            parts = " ".join(f"{k} {1000 * st[k]:.1f}" for k in names)
            print(
                f"- **{method}**: {1000 * np.median(wall):.0f} ms/frame wall "
                f"(runs {1000 * min(meds):.0f}–{1000 * max(meds):.0f}), "
                f"{1000 * np.median(cpu):.0f} ms CPU; read {1000 * np.median(read):.1f} ms, "
                f"step stages (ms): {parts}; joint error {err:.1f} mm",
                flush=True,
            )
    print(f"(after: {_load()})")


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
            frames=positions,
            resume=False,
            show_progress=False,
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
                    resume=False,
                    show_progress=False,
                    init="truth",
                    recover=False,
                    light=light,
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
    ap.add_argument("--templates", nargs="+", default=["neutral_5k", "neutral"])
    ap.add_argument("--methods", nargs="+", default=list(METHODS), choices=METHODS)
    ap.add_argument("--no-stages", action="store_true", help="only the crane table")
    ap.add_argument("--no-crane", action="store_true", help="only the stage tables")
    ap.add_argument("--light", action="store_true", help="only the light-body table")
    ap.add_argument("--light-template", default="neutral", help="the light table's body")
    ap.add_argument("--nricp-every", type=int, default=1, help="nricp on every k-th frame")
    ap.add_argument("--work", default="/tmp/meshmocap-speed")
    args = ap.parse_args()
    work = Path(args.work)
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
