"""The patch tracker's speed and accuracy, this tree against an earlier revision, in one run.

Protocol: synthetic captures from the studio at 60 fps (``humaneva4`` hulls at
1 cm) of the ~12k-vertex ``neutral`` template playing a procedural walk, a dance (CMU
05_03, ``../shared/data/mocap/cmu/library``) and a jump (CMU 16_01); the first pose from
ground truth; frames 1… tracked by ``--method`` of each source tree (``src/`` of
``--base`` extracted by ``git archive``, and this checkout's ``src/``), one process per
run, the trees alternating. Per run: median wall seconds per frame (reading the hull and
the step; frame 1, which compiles, left out), CPU seconds per frame of the process (less
sensitive to a shared machine's load), the tracker's stages (wall), the mean joint error
(mm, 15 joints against the truth); per capture, the largest difference between the two
trees' joints (mm: 0 when a change keeps the tracks).

Run: ``python benchmarks/bench_patch_versions.py [--base REV] [--captures walk 05_03 16_01]
[--frames 61] [--repeats 1] [--method patch] [--work /tmp/meshmocap-versions]``.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tarfile
import time
from io import BytesIO
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
DATA = ROOT.parent / "shared" / "data"
THREADS = {"OMP_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1", "NUMBA_NUM_THREADS": "1"}


def _capture(name: str, frames: int, work: Path):
    from meshmocap.apps.bench.captures import BenchCapture, make_capture, parse_capture

    if name == "05_03":  # a dance by subject 5, not among the bench's clips
        path = DATA / "mocap" / "cmu" / "library" / "05_03.amc"
        spec = BenchCapture("05_03", "synthetic", str(path), stop=frames)
    else:
        spec = parse_capture(name, data=DATA, frames=frames)
    return make_capture(spec, work, template="neutral", show_progress=False)


def track_one(name: str, frames: int, method: str, work: Path, out: Path) -> dict:
    """Track capture ``name`` in this process (the tree on ``sys.path``); joints to ``out``."""
    from meshmocap.body.template import load_template
    from meshmocap.trackers.registry import make_tracker

    template = load_template("neutral")
    cap = _capture(name, frames, work)
    tracker = make_tracker(method, template=template)
    f0 = cap[0]
    tracker.init(template, f0, f0.truth.rotations, f0.truth.root)
    wall, joints, truth = [], [], []
    for k in range(1, len(cap)):
        frame = cap[k]
        if k == 2:  # frame 1 compiles the kernels
            cpu0, stages0 = time.process_time(), dict(tracker.stage_seconds)
        t0 = time.perf_counter()
        _ = frame.hull_mesh
        joints.append(tracker.step(frame).joints)
        wall.append(time.perf_counter() - t0)
        truth.append(frame.truth.joints)
    n = max(len(wall) - 1, 1)
    np.save(out, np.asarray(joints))
    err = 1000 * np.linalg.norm(np.asarray(joints) - np.asarray(truth), axis=2)
    return {
        "wall": float(np.median(wall[1:])),
        "cpu": (time.process_time() - cpu0) / n,
        "err": float(err.mean()),
        "stages": {k: (v - stages0[k]) / n for k, v in tracker.stage_seconds.items()},
    }


def _extract(rev: str, dest: Path) -> Path:
    """``src/`` of git revision ``rev`` under ``dest`` (reused when there)."""
    src = dest / rev / "src"
    if not src.is_dir():
        tar = subprocess.run(
            ["git", "-C", str(ROOT), "archive", rev, "src"], check=True, capture_output=True
        ).stdout
        with tarfile.open(fileobj=BytesIO(tar)) as t:
            t.extractall(dest / rev, filter="data")
    return src


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--base", default="cc55fea", help="git revision to compare against")
    ap.add_argument("--captures", nargs="+", default=["walk", "05_03", "16_01"])
    ap.add_argument("--frames", type=int, default=61)
    ap.add_argument("--repeats", type=int, default=1)
    ap.add_argument("--method", default="patch")
    ap.add_argument("--work", default="/tmp/meshmocap-versions")
    ap.add_argument("--one", nargs=3, metavar=("CAPTURE", "OUT", "JSON"), help=argparse.SUPPRESS)
    args = ap.parse_args()
    work = Path(args.work)
    if args.one:  # a child process: one run of the tree on sys.path
        name, out, result = args.one
        res = track_one(name, args.frames, args.method, work, Path(out))
        Path(result).write_text(json.dumps(res))
        return
    trees = {args.base: _extract(args.base, work / "trees"), "this": ROOT / "src"}
    print(
        f"{args.method}, neutral (12k vertices), humaneva4, {args.frames - 1} frames tracked "
        f"from the true first pose; base {args.base}; load {os.getloadavg()[0]:.1f} on "
        f"{os.cpu_count()} cores"
    )
    print("| capture | tree | s/frame wall | s/frame CPU | joint error mm | stages (ms, wall) |")
    print("|---|---|---:|---:|---:|---|")
    for name in args.captures:
        for _ in range(args.repeats):
            for label, src in trees.items():
                out = work / f"{name}-{label.replace('/', '_')}.npy"
                result = work / "result.json"
                env = dict(os.environ, PYTHONPATH=str(src), **THREADS)
                cmd = [sys.executable, __file__, "--work", str(work), "--frames", str(args.frames)]
                cmd += ["--method", args.method, "--one", name, str(out), str(result)]
                subprocess.run(cmd, env=env, check=True)
                d = json.loads(result.read_text())
                st = " ".join(f"{k} {1000 * v:.0f}" for k, v in d["stages"].items())
                print(
                    f"| {name} | {label} | {d['wall']:.3f} | {d['cpu']:.3f} | {d['err']:.2f} "
                    f"| {st} |",
                    flush=True,
                )
        a, b = (np.load(work / f"{name}-{k.replace('/', '_')}.npy") for k in trees)
        diff = 1000 * np.linalg.norm(a - b, axis=2)
        print(
            f"| {name} | joints, trees apart | | | mean {diff.mean():.3f}, max {diff.max():.3f} | |"
        )
    print(f"(load after: {os.getloadavg()[0]:.1f})")


if __name__ == "__main__":
    main()
