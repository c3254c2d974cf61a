"""Fuzz every loader with hypothesis at scale: ≥ 10,000 mutated files in all.

Protocol: the loaders, seeds and mutations of ``tests/fuzzing.py`` (valid files made in
code, mutated at the byte level and, for ``.npz`` files, at the array level); each example
must read into a well-formed result or raise a meshmocap error (one line). Every other
exception, a stray warning or a garbage result is a defect; the run collects them all
(grouped by loader and message) instead of stopping at the first. Seeded: the same run
gives the same examples.

Usage: ``python benchmarks/bench_fuzz.py [--examples N] [--only NAME ...]``
(``--examples``: per loader, default 400, i.e. 10,000 over the 25 loaders).
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from collections import Counter, defaultdict
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))

from hypothesis import HealthCheck, given, seed, settings

from fuzzing import Defect, loaders, manifold_loader, run_one


def _manifold(work: Path) -> Path:
    from meshmocap.body.template import load_template
    from meshmocap.trackers.cage.manifold import fit_pose_manifold
    from meshmocap.trackers.cage.oqr import build_oqr
    from meshmocap.trackers.cage.training_poses import load_pose_sources

    t = load_template("neutral_5k")
    oqr = build_oqr(t)
    poses = load_pose_sources(["walk"], t, oqr=oqr, duration=0.4, fps=15.0)
    return fit_pose_manifold(poses, t, oqr=oqr, n_samples=6, max_iter=20).save(work / "m.npz")


def _property(loader, work: Path, counts: Counter, slowest: list, defects: dict):
    """The fuzz property of ``loader``, counting outcomes instead of stopping at a defect."""

    @settings(
        max_examples=EXAMPLES[0],
        deadline=None,
        database=None,
        suppress_health_check=list(HealthCheck),
    )
    @given(data=loader.strategy)
    def prop(data: bytes) -> None:
        t0 = time.perf_counter()
        try:
            counts[run_one(loader, data, work)] += 1
        except Defect as exc:
            counts["defect"] += 1
            defects[loader.name][str(exc)[:160]] += 1
            if SAVE:
                SAVE[0].mkdir(parents=True, exist_ok=True)
                (SAVE[0] / f"{loader.name}_{counts['defect']}{loader.suffix}").write_bytes(data)
        slowest[0] = max(slowest[0], time.perf_counter() - t0)

    return prop


EXAMPLES = [400]
SAVE: list[Path] = []


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--examples", type=int, default=400, help="examples per loader")
    ap.add_argument("--only", nargs="+", help="loader names")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--save", help="folder to keep each defect's input in")
    args = ap.parse_args()
    EXAMPLES[0] = args.examples
    if args.save:
        SAVE.append(Path(args.save))
    with tempfile.TemporaryDirectory() as d:
        work = Path(d)
        todo = loaders(work) + [manifold_loader(_manifold(work))]
        if args.only:
            todo = [ld for ld in todo if ld.name in args.only]
        rows, defects = [], defaultdict(Counter)
        t_all = time.perf_counter()
        for loader in todo:
            counts, slowest = Counter(), [0.0]
            t0 = time.perf_counter()
            seed(args.seed)(_property(loader, work, counts, slowest, defects))()
            n = sum(counts.values())
            rows.append(
                (
                    loader.name,
                    n,
                    counts["ok"],
                    counts["error"],
                    counts["defect"],
                    time.perf_counter() - t0,
                    slowest[0],
                )
            )
            print(
                f"{loader.name:<20} {n:6d} examples: {counts['ok']:5d} read, "
                f"{counts['error']:5d} meshmocap errors, {counts['defect']:4d} defects "
                f"({rows[-1][5]:.0f} s, slowest {slowest[0]:.2f} s)",
                flush=True,
            )
        total = sum(r[1] for r in rows)
        print("\n| loader | examples | read | meshmocap error | defects | s | slowest s |")
        print("|---|---:|---:|---:|---:|---:|---:|")
        for r in rows:
            print(f"| {r[0]} | {r[1]} | {r[2]} | {r[3]} | {r[4]} | {r[5]:.0f} | {r[6]:.2f} |")
        print(
            f"| **all** | **{total}** | {sum(r[2] for r in rows)} | "
            f"{sum(r[3] for r in rows)} | {sum(r[4] for r in rows)} | "
            f"{time.perf_counter() - t_all:.0f} | |"
        )
        for name, found in defects.items():
            print(f"\n{name}:")
            for text, k in found.most_common():
                print(f"  {k:5d} × {text}")
    return 1 if defects else 0


if __name__ == "__main__":
    sys.exit(main())
