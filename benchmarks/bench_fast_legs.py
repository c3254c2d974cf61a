"""Lost flags on fast legs: how many frames a patch track of the gait guide's walk flags.

Protocol: the procedural walk on ``neutral_5k`` at 30 fps (every other frame of 60 fps,
frames 0–108: 55 frames, as ``docs/guide/gait.rst`` makes it), ``humaneva4`` rig, 1 cm
hulls; tracked by ``patch`` from the capture alone (the template the capture names, the
first pose searched), recovery on, re-seating off (the defaults of ``meshmocap track``).
Reported: frames flagged ``lost`` (count, share, longest run and the limbs named), the
largest joint error of any frame (mm, against the truth), CPU seconds, the load, and the
BLAS kernel OpenBLAS chose for this CPU (``OPENBLAS_CORETYPE`` overrides it: the flags
change with it, which is why this count is measured here and not asserted in a test).
Target: at most a tenth of the frames flagged, no run longer than
``SEEN_AGAIN`` + 2 frames, no joint 100 mm off.

Run: ``python benchmarks/bench_fast_legs.py [--work /tmp/meshmocap-fast-legs]
[--restart]``; the capture is kept in ``--work``, the track made again unless it is there.
"""

from __future__ import annotations

import argparse
import os
import time
from pathlib import Path

import numpy as np

from meshmocap.cli import main as meshmocap
from meshmocap.estimate.recovery.reinit import SEEN_AGAIN
from meshmocap.io.capture import open_capture
from meshmocap.io.results import read_track


def blas_kernel() -> str:
    """The kernel family OpenBLAS chose (threadpoolctl), e.g. ``Haswell``."""
    from threadpoolctl import threadpool_info

    found = [i.get("architecture") for i in threadpool_info() if i.get("user_api") == "blas"]
    return ", ".join(sorted({str(a) for a in found})) or "?"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--work", default="/tmp/meshmocap-fast-legs")
    ap.add_argument("--restart", action="store_true", help="track again")
    args = ap.parse_args()
    work = Path(args.work)
    cap, out = work / "walk", work / "track"
    if not (cap / "capture.json").is_file():
        spec = ["--motion", "walk", "--template", "neutral_5k", "--frames", "0:110:2"]
        assert meshmocap(["synth", str(cap), *spec]) == 0
    t0 = time.process_time()
    argv = ["track", str(cap), "--method", "patch", "--out", str(out)]
    assert meshmocap([*argv, *(["--restart"] if args.restart else [])]) == 0
    cpu = time.process_time() - t0
    track = read_track(out, vertices=False)
    c = open_capture(cap)
    truth = np.stack([c[k].truth.joints for k in range(len(c))])
    worst = 1000 * np.linalg.norm(track.joints - truth, axis=2).max()
    lost = np.array(["lost" in f for f in track.flags])
    edges = np.diff(np.r_[0, lost.astype(int), 0])
    runs = np.flatnonzero(edges == -1) - np.flatnonzero(edges == 1)
    limbs = sorted(
        {m.removeprefix("lost ") for m, x in zip(track.messages, lost, strict=True) if x}
    )
    print(f"BLAS kernel {blas_kernel()}; load {os.getloadavg()[0]:.1f}; {cpu:.0f} s CPU")
    print(
        f"{int(lost.sum())} of {len(lost)} frames flagged lost ({lost.mean():.1%}; target "
        f"≤ 10%), frames {np.flatnonzero(lost).tolist()}, longest run {runs.max(initial=0)} "
        f"(target ≤ {SEEN_AGAIN + 2}); worst joint {worst:.0f} mm (target < 100)"
    )
    for m in limbs:
        print(f"  {m}")


if __name__ == "__main__":
    main()
