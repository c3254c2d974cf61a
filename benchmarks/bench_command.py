"""The time a user waits for a whole command, phase by phase, old tree and new in one run.

Each command (``demo``: ``meshmocap demo`` on its defaults; ``track``: ``meshmocap track``
of a synthetic walk of the 12k ``neutral`` body, its body estimated and its first pose
found, as a user without a scan has it) runs as a user runs it, in a child process per
tree (``--old``, ``--new``: ``src/`` folders, default ``../base/src`` and this checkout),
trees alternating, ``--repeats`` times. The child times the functions the command calls
for each phase (:data:`PHASES`: the body estimate, the first pose, each track, the
evaluation, the plots, the player, the report...), wall and CPU seconds of its own
process, each phase without the phases inside it; what no phase covers is ``other``
(importing, loading templates). The parent stamps every line the command prints: a gap
of more than 2 s with nothing printed is a **silent phase**, listed with
the lines before and after it and the CPU seconds it took (a gap between two lines of a
progress bar, which logs every few seconds, or inside a phase that said what it does, is
not silent).

``--cold``: every run starts without compiled kernels (``NUMBA_CACHE_DIR`` and the
meshmocap cache, ``MESHMOCAP_CACHE``, emptied: a fresh machine's first run); without it the
first run of each tree warms them and the table is of the later runs (``--repeats`` ≥ 2,
or a warm cache left in ``--work`` by an earlier run).

Load makes wall time on a shared machine meaningless: CPU seconds are printed beside wall
seconds, and the load averages with every table. The tables are markdown.

Run: ``python benchmarks/bench_command.py [demo|track ...] [--repeats 1] [--cold]
[--old SRC] [--new SRC] [--trees old new] [--frames 60] [--work /tmp/meshmocap-command]``.
"""

from __future__ import annotations

import argparse
import importlib
import json
import os
import re
import shutil
import subprocess
import sys
import time
from pathlib import Path

from _trees import add_tree_args, load, python_in, tree_env

#: Phases of each command: ``module:function`` → label, the label formatted with the
#: call's arguments (``{0}``: the first). A function the tree lacks is left out (noted).
PHASES: dict[str, dict[str, str]] = {
    "demo": {
        "meshmocap.apps.demo:procedural_motion": "motions: write, retarget, render",
        "meshmocap.apps.demo:write_bvh": "motions: write, retarget, render",
        "meshmocap.apps.demo:read_bvh": "motions: write, retarget, render",
        "meshmocap.apps.demo:retarget": "motions: write, retarget, render",
        "meshmocap.apps.demo:render_motion": "motions: write, retarget, render",
        "meshmocap.apps.demo:synthesize": "capture: synthesize",
        "meshmocap.apps.demo:tracking_template": "body estimate",
        "meshmocap.apps.demo:make_tracker": "tracker set-up: {0}",
        "meshmocap.apps.demo:track_sequence": "track: {0.name}",
        "meshmocap.trackers.driver:first_pose": "first pose",
        "meshmocap.trackers.driver:initialise_tracker": "first frame: {0.name}",
        "meshmocap.apps.demo:evaluate": "evaluate",
        "meshmocap.apps.demo:write_evaluation": "evaluation files, plots",
        "meshmocap.apps.demo:drop_resume_state": "drop resume state",
        "meshmocap.apps.demo:_exports_and_gait": "exports, gait",
        "meshmocap.apps.demo:gait_section": "gait section",
        "meshmocap.apps.demo:player_from_tracks": "player",
        "meshmocap.apps.demo:drop_hull_meshes": "drop hull meshes",
        "meshmocap.apps.demo:_report": "report",
    },
    "track": {
        "meshmocap.api:capture_and_axes": "open capture",
        "meshmocap.io.plausibility:check_observations": "observation checks",
        "meshmocap.estimate.plausibility:check_observations": "observation checks",  # old tree
        "meshmocap.api:tracking_template": "body estimate",
        "meshmocap.api:make_tracker": "tracker set-up",
        "meshmocap.trackers.driver:first_pose": "first pose",
        "meshmocap.trackers.driver:initialise_tracker": "first frame",
        "meshmocap.trackers.driver:track_frame": "frames: track",
        "meshmocap.trackers.driver:write_frame": "frames: write",
        "meshmocap.trackers.driver:read_track": "read the track back",
    },
}
#: A gap between two printed lines longer than this (wall seconds) is a silent phase.
SILENT_SECONDS = 2.0


# ----------------------------------------------------------------------------- child


class Phases:
    """Wall and CPU seconds of each labelled call, without the labelled calls inside it."""

    def __init__(self) -> None:
        self.own: dict[str, list[float]] = {}
        self.stack: list[list[float]] = []  # per open call: [inner wall, inner cpu]
        self.missing: list[str] = []

    def wrap(self, fn, label: str):
        def timed(*a, **k):
            w0, c0 = time.perf_counter(), time.process_time()
            self.stack.append([0.0, 0.0])
            try:
                return fn(*a, **k)
            finally:
                inner = self.stack.pop()
                w, c = time.perf_counter() - w0, time.process_time() - c0
                try:
                    name = label.format(*a, **k)
                except (AttributeError, IndexError, KeyError):
                    name = label.split(":")[0]
                rec = self.own.setdefault(name, [0.0, 0.0, 0])
                rec[0] += w - inner[0]
                rec[1] += c - inner[1]
                rec[2] += 1
                if self.stack:
                    self.stack[-1][0] += w
                    self.stack[-1][1] += c

        return timed

    def install(self, phases: dict[str, str]) -> None:
        for target, label in phases.items():
            module, name = target.split(":")
            try:
                mod = importlib.import_module(module)
                fn = getattr(mod, name)
            except (ImportError, AttributeError):
                self.missing.append(target)
                continue
            setattr(mod, name, self.wrap(fn, label))


def child(out: str, command: str, argv: list[str]) -> int:
    """Run ``meshmocap ARGV`` in this process with :data:`PHASES` timed; JSON to ``out``."""
    w0, c0 = time.perf_counter(), time.process_time()
    phases = Phases()
    phases.install(PHASES[command])
    from meshmocap.cli import main

    try:
        rc = main(argv)
    finally:
        res = {
            "phases": phases.own,
            "missing": phases.missing,
            "wall": time.perf_counter() - w0,
            "cpu": time.process_time() - c0,
        }
        Path(out).write_text(json.dumps(res))
    return rc


# ---------------------------------------------------------------------------- parent


def _cpu_of(pid: int) -> float:
    """CPU seconds of process ``pid`` and its waited-for children so far (Linux)."""
    try:
        fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
        return sum(int(x) for x in fields[11:15]) / os.sysconf("SC_CLK_TCK")
    except (OSError, IndexError, ValueError):
        return float("nan")


def run(command: str, argv: list[str], env: dict, log: Path) -> dict:
    """Run one command in a child; its phases, its totals and its silent gaps."""
    out = log.with_suffix(".json")
    out.unlink(missing_ok=True)
    cmd = [sys.executable, "-u", __file__, "--child", str(out), command, "--", *argv]
    t0 = time.perf_counter()
    p = subprocess.Popen(cmd, env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    lines, last, gaps = [], (0.0, 0.0, "(start)"), []
    with log.open("w", buffering=1) as f:  # line by line, to follow a long run
        for line in p.stdout:
            now, cpu = time.perf_counter() - t0, _cpu_of(p.pid)
            text = line.rstrip()
            f.write(f"{now:8.1f} cpu {cpu:7.1f} | {text}\n")
            if now - last[0] > SILENT_SECONDS and not _said(last[2], text):
                gaps.append((now - last[0], cpu - last[1], last[2], text))
            last = (now, cpu, text)
            lines.append(text)
    rc = p.wait()
    if rc != 0 or not out.is_file():
        raise RuntimeError(f"{' '.join(cmd)} failed ({rc}); its output: {log}")
    res = json.loads(out.read_text())
    res["gaps"] = gaps
    res["children_cpu"] = _children_cpu()
    return res


def _said(before: str, after: str) -> bool:
    """Whether a gap between two lines is covered by what the first said: two lines of
    the same progress bar (logged every few seconds), or a phase's start and its end."""
    bar = re.compile(r"([\w ]+): \d+/\d+")
    a, b = bar.match(before), bar.match(after)
    if a and b and a[1] == b[1]:
        return True
    return before.endswith(" ...") and after.startswith(before[:-4] + ": done")


_CHILDREN = [0.0]


def _children_cpu() -> float:
    """CPU seconds of the last child and everything it waited for (a background compile)."""
    import resource

    r = resource.getrusage(resource.RUSAGE_CHILDREN)
    total = r.ru_utime + r.ru_stime
    spent, _CHILDREN[0] = total - _CHILDREN[0], total
    return spent


def _argv(command: str, args, work: Path, tree: str) -> list[str]:
    out = work / f"{command}-{tree}"
    shutil.rmtree(out, ignore_errors=True)
    if command == "demo":
        return ["demo", "--out", str(out)]
    walk = _walk(args, work)
    # its body and first pose, cached: in the capture by older trees, in the cache by newer
    shutil.rmtree(walk / ".meshmocap", ignore_errors=True)
    shutil.rmtree(work / f"cache-{tree}" / "captures", ignore_errors=True)
    return ["track", str(walk), "--out", str(out), "--template", "auto"]


def _walk(args, work: Path) -> Path:
    """The synthetic walk ``track`` tracks, made once by the first tree (the old one: a
    newer tree reads older captures)."""
    path = work / f"walk{args.frames}@neutral"
    code = (
        "from meshmocap.studio.synth import SynthSpec, synthesize; "
        f"spec = SynthSpec(motion='walk', template='neutral', stop={args.frames}); "
        f"print(synthesize({str(path)!r}, spec, show_progress=False).path)"
    )
    first = args.trees[0]
    return Path(python_in(tree_env(getattr(args, first), work, first), code))


def table(command: str, runs: dict[str, list[dict]]) -> str:
    """The markdown table of one command: a row per phase, wall and CPU seconds per tree
    (the median run by wall time), then the totals."""
    pick = {}
    for tree, rs in runs.items():
        rs = sorted(rs, key=lambda r: r["wall"])
        pick[tree] = rs[len(rs) // 2]
    labels = list(dict.fromkeys(k for r in pick.values() for k in r["phases"]))
    head = " | ".join(f"{t} wall s | {t} CPU s" for t in pick)
    out = [f"| {command} phase | {head} |", "|---" + "|---:" * (2 * len(pick)) + "|"]

    def cells(get) -> str:
        row = []
        for r in pick.values():
            v = get(r)
            row += ["", ""] if v is None else [f"{v[0]:.1f}", f"{v[1]:.1f}"]
        return " | ".join(row)

    for k in labels:
        out.append(f"| {k} | {cells(lambda r, k=k: r['phases'].get(k))} |")
    out.append(f"| other (imports, templates, ...) | {cells(lambda r: _other(r))} |")
    out.append(f"| **whole command** | {cells(lambda r: (r['wall'], r['cpu']))} |")
    bg = " | ".join(f" | {r['children_cpu'] - r['cpu']:.1f}" for r in pick.values())
    out.append(f"| child processes (CPU) | {bg} |")
    return "\n".join(out)


def _other(r: dict) -> tuple[float, float]:
    w = r["wall"] - sum(v[0] for v in r["phases"].values())
    c = r["cpu"] - sum(v[1] for v in r["phases"].values())
    return w, c


def silent(runs: dict[str, list[dict]]) -> str:
    """The silent gaps (> :data:`SILENT_SECONDS` wall) of each tree's median run."""
    out = []
    for tree, rs in runs.items():
        r = sorted(rs, key=lambda r: r["wall"])[len(rs) // 2]
        out.append(f"\n{tree}: {len(r['gaps'])} silent gaps > {SILENT_SECONDS:g} s")
        for wall, cpu, before, after in r["gaps"]:
            out.append(
                f"- {wall:.1f} s wall, {cpu:.1f} s CPU: after `{before[:90]}`, "
                f"before `{after[:90]}`"
            )
        if r["missing"]:
            out.append(f"  (phases this tree lacks: {', '.join(r['missing'])})")
    return "\n".join(out)


def main() -> None:
    if "--child" in sys.argv:  # --child OUT COMMAND -- ARGV...
        k = sys.argv.index("--child")
        out, command = sys.argv[k + 1], sys.argv[k + 2]
        argv = sys.argv[sys.argv.index("--") + 1 :]
        sys.exit(child(out, command, argv))
    ap = argparse.ArgumentParser()
    ap.add_argument("commands", nargs="*", default=["demo", "track"], choices=list(PHASES))
    ap.add_argument("--repeats", type=int, default=1)
    ap.add_argument("--cold", action="store_true", help="empty the caches before every run")
    ap.add_argument("--frames", type=int, default=60, help="frames of the track command's walk")
    ap.add_argument("--work", default="/tmp/meshmocap-command")
    add_tree_args(ap)
    args = ap.parse_args()
    work = Path(args.work)
    work.mkdir(parents=True, exist_ok=True)
    for command in args.commands:
        runs: dict[str, list[dict]] = {t: [] for t in args.trees}
        print(
            f"\n### meshmocap {command} ({'cold' if args.cold else 'warm'} caches); {load()}",
            flush=True,
        )
        for rep in range(args.repeats):
            for tree in args.trees:
                caches = {"MESHMOCAP_CACHE": str(work / f"cache-{tree}")}
                env = tree_env(getattr(args, tree), work, tree, **caches)
                if args.cold:
                    for d in (env["NUMBA_CACHE_DIR"], caches["MESHMOCAP_CACHE"]):
                        shutil.rmtree(d, ignore_errors=True)
                log = work / f"{command}-{tree}-{rep}.log"
                res = run(command, _argv(command, args, work, tree), env, log)
                runs[tree].append(res)
                print(
                    f"  {tree} run {rep + 1}: {res['wall']:.0f} s wall, {res['cpu']:.0f} s "
                    f"CPU ({load()}); lines stamped in {log}",
                    flush=True,
                )
        print(table(command, runs))
        print(silent(runs))
        print(f"({load()})", flush=True)


if __name__ == "__main__":
    main()
