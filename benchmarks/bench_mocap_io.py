"""Speed of the mocap readers and writer on real CMU clips.

Target: load a 3,000-frame AMC in ≤ 1 s. 01_01.amc has 2,751 frames;
the table also shows the time scaled to 3,000 frames (parsing is linear in the frames).

Run: ``python benchmarks/bench_mocap_io.py`` (needs ../shared/data/mocap/cmu; prints why
and exits 0 where it is absent). Times are the best of 5 runs.
"""

from __future__ import annotations

import sys
import tempfile
from pathlib import Path

from meshmocap._threads import limit_blas_threads

limit_blas_threads()

from _timing import best_of  # noqa: E402
from meshmocap.io.asf_amc import read_amc, read_amc_channels, read_asf  # noqa: E402
from meshmocap.io.bvh import read_bvh, write_bvh  # noqa: E402

CMU = Path(__file__).resolve().parents[1].parent / "shared" / "data" / "mocap" / "cmu"
AMC_TARGET_S = 1.0  # per 3,000 frames


def main() -> int:
    if not (CMU / "01_01.amc").is_file():
        print(f"skipped: CMU clips not available ({CMU} is absent)")
        return 0
    asf = read_asf(CMU / "01.asf")
    rows: list[tuple[str, int, float]] = []
    t, _ = best_of(lambda: read_asf(CMU / "01.asf"))
    rows.append(("read_asf 01.asf", 0, t))
    t, table = best_of(lambda: read_amc_channels(CMU / "01_01.amc", asf))
    rows.append(("read_amc_channels 01_01.amc", table.shape[0], t))
    t, amc = best_of(lambda: read_amc(CMU / "01_01.amc", asf))
    rows.append(("read_amc 01_01.amc", amc.n_frames, t))
    amc_per_3000 = t / amc.n_frames * 3000
    t, bvh = best_of(lambda: read_bvh(CMU / "01_01.bvh"))
    rows.append(("read_bvh 01_01.bvh", bvh.n_frames, t))
    with tempfile.TemporaryDirectory() as tmp:
        t, _ = best_of(lambda: write_bvh(Path(tmp) / "out.bvh", bvh, unit="cm"))
    rows.append(("write_bvh (01_01, cm)", bvh.n_frames, t))

    print(f"{'operation':32s} {'frames':>7s} {'best of 5':>10s} {'per 3000 fr':>12s}")
    for name, frames, secs in rows:
        per = f"{secs / frames * 3000 * 1e3:9.0f} ms" if frames else f"{'':>12s}"
        print(f"{name:32s} {frames:7d} {secs * 1e3:7.1f} ms {per}")
    verdict = "meets" if amc_per_3000 <= AMC_TARGET_S else "MISSES"
    print(
        f"AMC target: 3,000 frames in <= {AMC_TARGET_S:.1f} s -> "
        f"{amc_per_3000:.2f} s ({verdict} the target)"
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
