"""Speed of the body: retarget + skin one frame of the ~14k-vertex template, and mocap loading.

Targets: retarget + skin one frame of the ~14k-vertex template
≤ 2 ms; load a 3,000-frame AMC ≤ 1 s (see bench_mocap_io.py for the loaders alone).

Run: ``python benchmarks/bench_body.py`` (uses ../shared/data when present, else a
procedural walk written to and read back from a BVH).
"""

from __future__ import annotations

import tempfile
import time
from pathlib import Path

import numpy as np

from _timing import per_call
from meshmocap.body.procedural import walk
from meshmocap.body.retarget import Retargeter, retarget
from meshmocap.body.template import load_template
from meshmocap.io.bvh import read_bvh, write_bvh

CMU = Path(__file__).resolve().parents[1].parent / "shared" / "data" / "mocap" / "cmu"


def main() -> None:
    rows = []
    for name in ("neutral", "neutral_5k"):
        t = load_template(name)
        if (CMU / "35_01.amc").is_file():
            from meshmocap.io.asf_amc import read_amc, read_asf

            t0 = time.perf_counter()
            src = read_amc(CMU / "35_01.amc", read_asf(CMU / "35.asf"))
            load = time.perf_counter() - t0
            label = f"35_01.amc ({src.n_frames} frames, load {load * 1e3:.0f} ms)"
        else:
            with tempfile.TemporaryDirectory() as tmp:
                path = write_bvh(Path(tmp) / "walk.bvh", walk(t, duration=4.0))
                src = read_bvh(path)
            label = f"procedural walk via BVH ({src.n_frames} frames)"
        one = src.frames(slice(100, 101))
        # Streaming use: the mapping is precomputed once per clip; the floor shift is a
        # per-clip constant computed on the whole clip, so one frame skips it.
        rt = Retargeter(src.skeleton, t)

        def frame(one=one, t=t, rt=rt):
            m = rt(one, floor="none")
            return t.pose(m.rotations[0], m.root_positions[0]).V

        per_frame = min(per_call(frame))
        t0 = time.perf_counter()
        m = retarget(src, t)
        V = t.pose(m.rotations, m.root_positions).V
        batch = (time.perf_counter() - t0) / src.n_frames
        assert np.isfinite(V).all()
        rows.append((name, t.n_vertices, label, per_frame * 1e3, batch * 1e3))
    print(
        f"{'template':<11} {'vertices':>8}  {'one frame ms':>12}  {'batched ms/frame':>16}  source"
    )
    for name, n, label, one_ms, batch_ms in rows:
        print(f"{name:<11} {n:>8}  {one_ms:>12.3f}  {batch_ms:>16.3f}  {label}")
    print("target: retarget + skin one frame of the ~14k template <= 2 ms")


if __name__ == "__main__":
    main()
