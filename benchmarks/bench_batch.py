"""Batch speed-up: N synthetic captures tracked by ``meshmocap batch`` on W Dask workers
against the same captures tracked by serial ``meshmocap track`` calls (one process each).

Usage::

    python benchmarks/bench_batch.py [--captures 8] [--frames 60] [--workers 2]
                                     [--method patch] [--work DIR]

Captures are the procedural motions (walk, jog, squat, arm_raises, jumping_jacks, turn,
then again with silhouette jitter) on ``neutral_5k`` at 60 fps through the 4-camera rig,
synthesised once into ``--work`` (reused by later runs). Both modes use one BLAS thread per
process. The script checks that both give the same joints, bit for bit, and prints wall
times, the speed-up, the cores this process may use and the load average. Run it on a
quiet machine: other jobs on the same cores distort the speed-up.
"""

from __future__ import annotations

import argparse
import os
import shutil
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

from meshmocap.io.results import read_track
from meshmocap.studio.degrade import Degradation
from meshmocap.studio.synth import SynthSpec, synthesize

MOTIONS = ("walk", "jog", "squat", "arm_raises", "jumping_jacks", "turn")


def captures(work: Path, n: int, frames: int) -> list[Path]:
    out = []
    for k in range(n):
        motion = MOTIONS[k % len(MOTIONS)]
        jitter = 0.0 if k < len(MOTIONS) else 1.0
        path = work / "captures" / f"{k:02d}_{motion}{'_jitter' if jitter else ''}"
        spec = SynthSpec(
            motion=motion,
            template="neutral_5k",
            stop=frames,
            degradation=Degradation(jitter=jitter),
            seed=k,
        )
        synthesize(path, spec, show_progress=False)
        out.append(path)
    return out


def run(cmd: list[str]) -> float:
    t0 = time.perf_counter()
    subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL)
    return time.perf_counter() - t0


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--captures", type=int, default=8)
    p.add_argument("--frames", type=int, default=60)
    p.add_argument("--workers", type=int, default=2)
    p.add_argument("--method", default="patch")
    p.add_argument("--work", default="bench-batch-work")
    a = p.parse_args()
    work = Path(a.work)
    t0 = time.perf_counter()
    caps = captures(work, a.captures, a.frames)
    print(f"{len(caps)} captures of {a.frames} frames ready in {time.perf_counter() - t0:.0f} s")
    exe = [sys.executable, "-m", "meshmocap.cli"]  # the meshmocap command
    for d in ("serial", "batch"):
        shutil.rmtree(work / d, ignore_errors=True)
    serial = sum(
        run([*exe, "track", str(c), "--method", a.method, "--out", str(work / "serial" / c.name)])
        for c in caps
    )
    batch = run(
        [
            *exe,
            "batch",
            *map(str, caps),
            "--method",
            a.method,
            "--workers",
            str(a.workers),
            "--out",
            str(work / "batch"),
            "--no-dashboard",
        ]
    )
    same = all(
        np.array_equal(
            read_track(work / "serial" / c.name).joints,
            read_track(work / "batch" / c.name / "track").joints,
        )
        for c in caps
    )
    cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count()
    load = os.getloadavg()[0]
    print(
        f"\n{a.method}, {len(caps)} captures x {a.frames} frames; {cores} cores available; "
        f"load average {load:.2f}"
    )
    print("| mode | wall s | s per capture | speed-up | joints identical |")
    print("|---|--:|--:|--:|---|")
    print(
        f"| serial `meshmocap track` x {len(caps)} | {serial:.1f} | {serial / len(caps):.1f} "
        "| 1.00 | |"
    )
    print(
        f"| `meshmocap batch --workers {a.workers}` | {batch:.1f} | {batch / len(caps):.1f} | "
        f"{serial / batch:.2f} | {'yes' if same else 'NO'} |"
    )


if __name__ == "__main__":
    main()
