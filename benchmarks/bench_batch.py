"""Batch speed-up: N synthetic captures tracked by ``meshmocap batch`` on W Dask workers
against the same captures tracked by ``meshmocap track`` one after another (one process
each), with the same per-process thread settings (one BLAS/OpenMP/numba thread).

Usage::

    python benchmarks/bench_batch.py [--captures 8] [--frames 60] [--workers 2]
                                     [--method patch] [--work DIR] [--rounds 1]

Captures are the procedural motions (walk, jog, squat, arm_raises, jumping_jacks, turn,
then again with silhouette jitter) on ``neutral_5k`` at 60 fps through the 4-camera rig,
synthesised once into ``--work`` (reused by later runs). Serially each capture is tracked
and then evaluated (``meshmocap eval``), the work ``batch`` does for each. Each round runs
serial then batch back to back (``--rounds 2`` alternates: serial, batch, batch, serial),
so both meet the same load. For each run it prints the wall time, the CPU time of all its
processes (user + system, from ``RUSAGE_CHILDREN``), the cores busy on average (CPU /
wall) against the cores available, and the load average before and after; and it checks
that both give the same joints, bit for bit. Other jobs on the same cores make the
speed-up pessimistic: the CPU times say how much of the machine each mode had.
"""

from __future__ import annotations

import argparse
import os
import resource
import shutil
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

from meshmocap.apps.batch.run import ONE_THREAD  # the workers' thread settings, used by both
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


def _cpu() -> float:
    r = resource.getrusage(resource.RUSAGE_CHILDREN)
    return r.ru_utime + r.ru_stime


def run(cmds: list[list[str]]) -> tuple[float, float, float, float]:
    """Run ``cmds`` one after another; wall and CPU seconds, load before and after."""
    env = {**os.environ, **ONE_THREAD}
    load0, c0, t0 = os.getloadavg()[0], _cpu(), time.perf_counter()
    for cmd in cmds:
        subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL, env=env)
    return time.perf_counter() - t0, _cpu() - c0, load0, os.getloadavg()[0]


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--captures", type=int, default=8)
    p.add_argument("--frames", type=int, default=60)
    p.add_argument("--workers", type=int, default=2)
    p.add_argument("--method", default="patch")
    p.add_argument("--work", default="bench-batch-work")
    p.add_argument("--rounds", type=int, default=1, help="serial/batch pairs, alternating")
    a = p.parse_args()
    work = Path(a.work)
    t0 = time.perf_counter()
    caps = captures(work, a.captures, a.frames)
    print(f"{len(caps)} captures of {a.frames} frames ready in {time.perf_counter() - t0:.0f} s")
    exe = [sys.executable, "-m", "meshmocap.cli"]  # the meshmocap command

    def serial(k: int) -> list[list[str]]:
        """Each capture tracked, then evaluated as batch evaluates it (no silhouettes, no
        surfaces; tables and plots written): the same work, one process after another."""
        out = work / f"serial{k}"
        shutil.rmtree(out, ignore_errors=True)
        cmds = []
        for c in caps:
            track, ev = str(out / c.name), str(out / f"{c.name}-eval")
            cmds.append([*exe, "track", str(c), "--method", a.method, "--out", track])
            cmds.append(
                [*exe, "eval", str(c), track, "--no-silhouettes", "--surface-frames", "0"]
                + ["--out", ev]
            )
        return cmds

    def batch(k: int) -> list[list[str]]:
        out = work / f"batch{k}"
        shutil.rmtree(out, ignore_errors=True)
        return [
            [
                *exe,
                "batch",
                *map(str, caps),
                "--method",
                a.method,
                "--workers",
                str(a.workers),
                "--out",
                str(out),
                "--no-dashboard",
            ]
        ]

    order = []
    for k in range(a.rounds):
        order += [("serial", k), ("batch", k)] if k % 2 == 0 else [("batch", k), ("serial", k)]
    rows = []
    for mode, k in order:
        wall, cpu, l0, l1 = run(serial(k) if mode == "serial" else batch(k))
        rows.append((mode, k, wall, cpu, l0, l1))
        print(f"{mode} round {k}: {wall:.1f} s wall, {cpu:.1f} s CPU", flush=True)
    same = all(
        np.array_equal(
            read_track(work / f"serial{k}" / c.name).joints,
            read_track(work / f"batch{k}" / c.name / "track").joints,
        )
        for k in range(a.rounds)
        for c in caps
    )
    cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count()
    print(
        f"\n{a.method}, {len(caps)} captures x {a.frames} frames; {cores} cores available; "
        f"one thread per process (BLAS, OpenMP, numba)"
    )
    print("| mode | round | wall s | CPU s | cores busy | load before/after | speed-up |")
    print("|---|--:|--:|--:|--:|--:|--:|")
    walls = {(m, k): w for m, k, w, *_ in rows}
    for m, k, w, cpu, l0, l1 in rows:
        name = (
            f"`meshmocap track` x {len(caps)}"
            if m == "serial"
            else f"`batch --workers {a.workers}`"
        )
        up = walls[("serial", k)] / w
        print(
            f"| {name} | {k} | {w:.1f} | {cpu:.1f} | {cpu / w:.2f} of {cores} "
            f"| {l0:.1f}/{l1:.1f} | {up:.2f} |"
        )
    total_s = sum(w for (m, _), w in walls.items() if m == "serial")
    total_b = sum(w for (m, _), w in walls.items() if m == "batch")
    print(
        f"\nspeed-up over all rounds: {total_s / total_b:.2f}; joints identical: "
        f"{'yes' if same else 'NO'}"
    )


if __name__ == "__main__":
    main()
