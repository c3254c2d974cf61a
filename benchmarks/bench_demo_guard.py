"""Guard the demo: fail when a tracker got worse on ``meshmocap demo``'s capture.

**Run it before every merge that touches a tracker** (``trackers/``, ``estimate/``, the
driver, the light body, the studio)::

    python benchmarks/bench_demo_guard.py            # check against demo_guard.json
    python benchmarks/bench_demo_guard.py --record   # after a deliberate, explained change

It builds the demo's capture (:func:`meshmocap.apps.demo.demo_spec`: the procedural walk,
120 frames at 60 fps, performed by ``heavy_male``, a body the trackers are not told about,
4 cameras), then tracks it with patch, cage and articulated ICP exactly as ``meshmocap
demo`` does (:func:`meshmocap.apps.demo.demo_tracks`: the performer's body estimated from
the hulls, the first pose searched, the light body, default options) and scores the joints
against the truth. It exits 1 when any method's mean joint error is worse than the figure
recorded in ``benchmarks/demo_guard.json`` by more than ``--tolerance`` (1 mm), 2 when there
is no record for a method. The record holds the commit and date it was made at and, per
method, the mean joint error, the worst frame and the seconds per frame; ``--record``
rewrites it from this run. The same 1 mm rule guards all three methods: the tracks are
deterministic (two runs of one tree give the same figures), so 1 mm is a change of code or
of its inputs, not noise.

The capture, its estimated body and first pose are kept in ``--work`` (default: the system's
temporary folder): the capture in a folder named after a digest of the code that makes it
(studio, geometry, body and io sources), the estimates in its cache, keyed by their own
code (:mod:`meshmocap.estimate.capture_cache`). A re-run reuses them while that code is
unchanged (the body estimate is most of a first run: about 4 minutes on 2 cores) and
remakes them when it changed; the tracks are made afresh every run. It runs on the BLAS
threads the demo command runs on (one, unless ``MESHMOCAP_THREADS`` says otherwise). It prints
the wall and CPU time it took and the load.
"""

from __future__ import annotations

import argparse
import datetime
import hashlib
import json
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import meshmocap
from meshmocap._threads import blas_threads
from meshmocap.apps.demo import DEMO_METHODS, demo_spec, demo_tracks
from meshmocap.studio.synth import synthesize

RECORD = Path(__file__).with_name("demo_guard.json")
#: Packages whose source makes the capture (a change remakes it; the estimates cached with
#: it are keyed by their own code, :mod:`meshmocap.estimate.capture_cache`).
CAPTURE_CODE = ("studio", "geometry", "body", "io")


def code_digest() -> str:
    """12 hex digits over the source files of :data:`CAPTURE_CODE` and the version."""
    root = Path(meshmocap.__file__).parent
    h = hashlib.sha256(meshmocap.__version__.encode())
    for package in CAPTURE_CODE:
        for p in sorted((root / package).rglob("*.py")):
            h.update(p.relative_to(root).as_posix().encode())
            h.update(p.read_bytes())
    return h.hexdigest()[:12]


def commit() -> str:
    """The checkout's commit, with ``+dirty`` when tracked files differ from it."""
    here = Path(__file__).parent
    try:
        sha = subprocess.run(
            ["git", "rev-parse", "--short", "HEAD"], cwd=here, capture_output=True, text=True
        ).stdout.strip()
        dirty = subprocess.run(
            ["git", "status", "--porcelain", "--untracked-files=no"],
            cwd=here,
            capture_output=True,
            text=True,
        ).stdout.strip()
    except OSError:
        return "unknown"
    return (sha or "unknown") + ("+dirty" if dirty else "")


def demo_figures(work: Path, methods: tuple[str, ...]) -> dict[str, dict[str, float]]:
    """Track the demo capture (made in ``work`` once per :func:`code_digest`) with each
    method as the demo does; per method the mean joint error, the worst frame's mean (mm),
    the seconds per frame, and the wall and CPU seconds of its track."""
    cap_dir = work / f"capture-{code_digest()}"
    for old in work.glob("capture-*"):  # captures of older code
        if old != cap_dir:
            shutil.rmtree(old, ignore_errors=True)
    t0, c0 = time.perf_counter(), time.process_time()
    cap = synthesize(cap_dir, demo_spec(), show_progress=False)
    print(
        f"capture: {len(cap)} frames in {cap_dir} "
        f"({time.perf_counter() - t0:.0f} s wall, {time.process_time() - c0:.0f} s CPU)",
        flush=True,
    )
    tracks = work / "tracks"  # afresh: a track left from a run before would be resumed
    shutil.rmtree(tracks, ignore_errors=True)
    figures = {}
    for method in methods:
        t0, c0 = time.perf_counter(), time.process_time()
        # one method at a time to time each; the body and first pose come from the
        # capture's cache after the first
        _, [(_, _, _, ev)], _ = demo_tracks(cap, tracks, methods=(method,), show_progress=False)
        figures[method] = {
            "mean_mm": round(float(ev.joints.overall.mean), 2),
            "worst_frame_mm": round(float(ev.joints.per_frame.max()), 2),
            "seconds_per_frame": round(float(ev.seconds.mean), 3),
            "wall_s": round(time.perf_counter() - t0, 1),
            "cpu_s": round(time.process_time() - c0, 1),
        }
        print(
            f"{method}: {figures[method]['mean_mm']:.2f} mm mean, worst frame "
            f"{figures[method]['worst_frame_mm']:.2f} mm ({figures[method]['wall_s']:.0f} s "
            f"wall, {figures[method]['cpu_s']:.0f} s CPU, with the estimates it made)",
            flush=True,
        )
    return figures


def verdict(
    figures: dict[str, dict[str, float]], record: dict, tolerance: float
) -> tuple[int, list[str]]:
    """Exit status (0 pass, 1 a method worse than its record by more than ``tolerance``
    mm, 2 a method without a record) and one line per method."""
    status, lines = 0, []
    recorded = record.get("methods", {})
    for method, f in figures.items():
        if method not in recorded:
            status = max(status, 2)
            lines.append(f"{method:<16} {f['mean_mm']:8.2f} mm: no record (run with --record)")
            continue
        was = recorded[method]["mean_mm"]
        worse = f["mean_mm"] - was
        ok = worse <= tolerance
        if not ok:
            status = 1
        lines.append(
            f"{method:<16} {f['mean_mm']:8.2f} mm (recorded {was:.2f}, {worse:+.2f}; worst frame "
            f"{f['worst_frame_mm']:.1f}, recorded {recorded[method]['worst_frame_mm']:.1f}) "
            f"{'ok' if ok else f'WORSE by more than {tolerance:g} mm'}"
        )
    return status, lines


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--record", action="store_true", help=f"rewrite {RECORD.name} from this run")
    ap.add_argument("--tolerance", type=float, default=1.0, help="mm worse that fails (1)")
    ap.add_argument("--methods", nargs="+", default=list(DEMO_METHODS), choices=DEMO_METHODS)
    ap.add_argument(
        "--work",
        type=Path,
        default=Path(tempfile.gettempdir()) / "meshmocap-demo-guard",
        help="where the capture and its estimates are kept between runs",
    )
    args = ap.parse_args(argv)
    t0, c0 = time.perf_counter(), time.process_time()
    print(f"demo guard: meshmocap {meshmocap.__version__} at {commit()}; load {os.getloadavg()}")
    args.work.mkdir(parents=True, exist_ok=True)
    with blas_threads():  # as the demo command runs (meshmocap.cli)
        figures = demo_figures(args.work, tuple(args.methods))
    record = json.loads(RECORD.read_text()) if RECORD.exists() else {}
    status, lines = verdict(figures, record, args.tolerance)
    if record:
        print(f"against the record of {record.get('commit')} ({record.get('date')}):")
    print("\n".join(lines))
    if args.record:
        methods = {**record.get("methods", {}), **figures}
        new = {
            "commit": commit(),
            "date": datetime.date.today().isoformat(),
            "capture": "meshmocap demo's: procedural walk, frames 0:120 at 60 fps, heavy_male, "
            "humaneva4; default path (estimated body, automatic first pose, light body)",
            "tolerance_mm": args.tolerance,
            "methods": methods,
        }
        RECORD.write_text(json.dumps(new, indent=2) + "\n")
        print(f"recorded in {RECORD}")
        status = 0
    print(
        f"took {time.perf_counter() - t0:.0f} s wall, {time.process_time() - c0:.0f} s CPU; "
        f"load {os.getloadavg()}"
    )
    return status


if __name__ == "__main__":
    sys.exit(main())
