"""What the numba kernels cost a fresh install, module by module: cold (an empty cache,
``NUMBA_CACHE_DIR`` pointed at a new folder: every kernel compiled) and warm (the same
folder again: every kernel loaded), old tree and new in one run.

Each run is a child process that imports each kernel module of
:data:`meshmocap.apps.kernels.KERNELS` and compiles each kernel with the argument types
tracking calls it with (the list is read from this checkout's file, so that an old tree
without it is measured on the same kernels), timing CPU seconds of the import and of each
kernel (compiling is single-threaded: its CPU time is its wall time on a quiet machine).
Wall seconds of the whole child beside it, and the load averages.

Run: ``python benchmarks/bench_compile.py [--old SRC] [--new SRC] [--trees old new]
[--repeats 1] [--work /tmp/meshmocap-compile]``.
"""

from __future__ import annotations

import argparse
import importlib.util
import json
import shutil
import sys
import time
from pathlib import Path

from _trees import ROOT, add_tree_args, load, run_child, tree_env

KERNELS_FILE = ROOT / "src" / "meshmocap" / "apps" / "kernels.py"


def child(out: str) -> None:
    """Compile every listed kernel in this process (the tree on ``PYTHONPATH``)."""
    spec = importlib.util.spec_from_file_location("kernel_list", KERNELS_FILE)
    kernels = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(kernels)  # the list and compile_kernels, not the tree's
    w0 = time.perf_counter()
    t0 = time.process_time()
    import numba  # noqa: F401 - its import is part of the first use

    numba_s = time.process_time() - t0
    seconds = kernels.compile_kernels()
    Path(out).write_text(
        json.dumps({"seconds": seconds, "numba": numba_s, "wall": time.perf_counter() - w0})
    )


def main() -> None:
    if "--child" in sys.argv:
        child(sys.argv[sys.argv.index("--child") + 1])
        return
    ap = argparse.ArgumentParser()
    ap.add_argument("--repeats", type=int, default=1)
    ap.add_argument("--work", default="/tmp/meshmocap-compile")
    add_tree_args(ap)
    args = ap.parse_args()
    work = Path(args.work)
    print(f"### numba kernels, cold and warm cache; {load()}", flush=True)
    runs: dict[tuple[str, str], list[dict]] = {}
    for rep in range(args.repeats):
        for tree in args.trees:
            env = tree_env(getattr(args, tree), work, tree)
            shutil.rmtree(env["NUMBA_CACHE_DIR"], ignore_errors=True)
            for state in ("cold", "warm"):
                res = run_child(__file__, [], env, work / f"{tree}-{state}.json")
                runs.setdefault((tree, state), []).append(res)
                print(
                    f"  {tree} {state} run {rep + 1}: {res['wall']:.1f} s wall, "
                    f"{sum(res['seconds'].values()):.1f} s CPU ({load()})",
                    flush=True,
                )
    cols = list(runs)
    rows: dict[str, dict] = {}
    for col, rs in runs.items():
        r = sorted(rs, key=lambda r: r["wall"])[len(rs) // 2]
        rows.setdefault("import numba", {})[col] = r["numba"]
        for name, s in r["seconds"].items():
            module = name.split(":")[0].removeprefix("meshmocap.")
            label = f"{module} (import)" if ":" not in name else f"&nbsp;&nbsp;{name.split(':')[1]}"
            rows.setdefault(label, {})[col] = s
        rows.setdefault("**all (CPU)**", {})[col] = r["numba"] + sum(r["seconds"].values())
        rows.setdefault("whole child (wall)", {})[col] = r["wall"]
    head = " | ".join(f"{t} {s} s" for t, s in cols)
    print(f"\n| kernel (CPU s) | {head} |\n|---" + "|---:" * len(cols) + "|")
    for label, vals in rows.items():
        print(f"| {label} | " + " | ".join(f"{vals.get(c, 0.0):.2f}" for c in cols) + " |")
    print(f"({load()})")


if __name__ == "__main__":
    main()
