"""Running the same measurement on two source trees in one run (the benchmarks' old vs new).

A tree is a ``src/`` folder: this checkout's (``new``) and an earlier one (``old``, default
``../base/src``, a worktree of the main the change started from). Each measurement runs in
a child process with the tree first on ``PYTHONPATH`` and its own numba cache folder
(``NUMBA_CACHE_DIR``, so that neither tree writes into the other's ``__pycache__`` nor
reads the other's compiled kernels), and hands back JSON.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
#: The trees compared by default: the main this checkout started from, and this checkout.
TREES = {"old": ROOT.parent / "base" / "src", "new": ROOT / "src"}


def add_tree_args(ap) -> None:
    """``--old SRC``, ``--new SRC`` and ``--trees old new`` (which to run)."""
    ap.add_argument("--old", default=str(TREES["old"]), help="the old tree's src/ folder")
    ap.add_argument("--new", default=str(TREES["new"]), help="the new tree's src/ folder")
    ap.add_argument("--trees", nargs="+", default=["old", "new"], choices=["old", "new"])


def tree_env(src: str | os.PathLike, work: Path, name: str, **extra: str) -> dict[str, str]:
    """The environment of a child running tree ``src``: its numba cache in ``work``."""
    env = dict(os.environ)
    env["PYTHONPATH"] = str(Path(src).resolve())
    env["NUMBA_CACHE_DIR"] = str(work / f"numba-{name}")
    env.update(extra)
    return env


def run_child(script: str, args: list[str], env: dict[str, str], out: Path) -> dict:
    """Run ``python SCRIPT --child OUT ARGS`` and return the JSON it wrote to ``out``
    (stderr passes through; a failure raises with the child's last lines)."""
    out.unlink(missing_ok=True)
    cmd = [sys.executable, script, "--child", str(out), *args]
    p = subprocess.run(cmd, env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    if p.returncode != 0 or not out.is_file():
        tail = "\n".join(p.stdout.splitlines()[-15:])
        raise RuntimeError(f"{' '.join(cmd)} failed ({p.returncode}):\n{tail}")
    return json.loads(out.read_text())


def python_in(env: dict[str, str], code: str) -> str:
    """Run ``python -c CODE`` with ``env`` (a tree's, :func:`tree_env`); its last line of
    output. Inputs both trees read are made by the oldest (a newer tree reads older files;
    the reverse is not promised)."""
    p = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True)
    if p.returncode != 0:
        raise RuntimeError(f"python -c {code!r} failed:\n{p.stderr[-2000:]}")
    return p.stdout.strip().splitlines()[-1]


def load() -> str:
    """The load averages, to print beside any timing."""
    a, b, c = os.getloadavg()
    return f"load average {a:.2f} {b:.2f} {c:.2f} on {os.cpu_count()} cores"
