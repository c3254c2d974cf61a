"""Every method on every input (real meshes, hulls, point clouds): the command line as
a user runs it, in-process (``meshmocap.cli.main``), default options.

**Real meshes.** ``meshmocap track ../shared/data/meshes/crane/crane_mesh_0000-0174.tar.gz
--up y --method M --out t`` for the clean MIT crane meshes (175 frames, 10,002 vertices, Y
up, metres), default options: the template is the capture's own first frame rigged
(:func:`~meshmocap.estimate.performer.subject.estimate_subject`, mesh kind:
:func:`~meshmocap.body.autorig.rig_mesh`), the first pose found automatically
(``--init auto``). Per-vertex error: each tracked template
vertex against the same vertex of the crane's frame (fixed connectivity; mm: mean, median,
95th percentile, worst frame's mean), as in ``bench_crane.py``. Acceptance: ≤ 20 mm for
``patch`` and ``cage``.

**Inputs.** The true meshes of a 12-frame synthetic CMU 05_01 walk on ``neutral_5k``
written as files in several forms, each tracked (``--frames 0:N``) by ``patch``,
``articulated_icp`` and ``cage`` with default options: a folder of OBJ meshes, a glob, a
``.tar.gz`` archive, millimetres, Y up, a PLY point cloud with normals and one without, and
the meshes moved 1000 km from the origin. Each row gives the exit status, the command's
last line (the refusal, or the summary with its flags) and the mean joint error against the
walk's truth. Acceptance: each tracked correctly or refused in one line; none exits 0 with
unhealthy frames and no word why.

Run: ``python benchmarks/bench_inputs.py [--crane-frames 175] [--frames 12]
[--methods patch cage articulated_icp] [--skip-crane] [--skip-inputs]
[--work /tmp/meshmocap-inputs]``. Files and tracks are cached in ``--work``; the tables are
printed and written to ``--work``/results.md.
"""

from __future__ import annotations

import argparse
import contextlib
import io
import os
import tarfile
import time
from datetime import datetime
from pathlib import Path

import numpy as np

from meshmocap.body.template import load_template
from meshmocap.cli import main as cli
from meshmocap.geometry.mesh import vertex_normals
from meshmocap.io.meshes import MeshSequence, write_mesh
from meshmocap.io.results import read_track
from meshmocap.studio.synth import SynthSpec, synthesize

DATA = Path(__file__).resolve().parents[1].parent / "shared" / "data"
CRANE = DATA / "meshes" / "crane" / "crane_mesh_0000-0174.tar.gz"


def run(args: list[str]) -> tuple[int, str, float]:
    """Exit status, the last line printed (stdout or stderr) and the wall time of a
    command."""
    out, err = io.StringIO(), io.StringIO()
    t0 = time.perf_counter()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        try:
            status = cli(args)
        except SystemExit as exc:
            status = int(exc.code or 0)
    lines = [ln for ln in (out.getvalue() + err.getvalue()).splitlines() if ln.strip()]
    return status, lines[-1] if lines else "", time.perf_counter() - t0


def crane(args, work: Path) -> list[str]:
    """The real-meshes table (module docstring)."""
    n = min(args.crane_frames, 175)
    truth = np.stack([f.V for f in MeshSequence(CRANE, frames=range(n), up="y")])
    rows = [
        "| method | status | mean mm | median mm | p95 mm | worst frame mm | flagged lost "
        "| s/frame | the command's last line |",
        "|---|--:|--:|--:|--:|--:|--:|--:|---|",
    ]
    for m in args.methods:
        out = work / "tracks" / f"crane-{m}-{n}"
        status, last, _ = run(
            [
                "track",
                str(CRANE),
                "--up",
                "y",
                "--method",
                m,
                "--frames",
                f"0:{n}",
                "--out",
                str(out),
            ]
        )
        if status != 0:
            rows.append(f"| {m} | {status} | | | | | | | {last} |")
            continue
        tr = read_track(out)
        e = np.linalg.norm(tr.vertices - truth[: len(tr.frames)], axis=2) * 1000
        lost = sum("lost" in f for f in tr.flags)
        rows.append(
            f"| {m} | 0 | {e.mean():.1f} | {np.median(e):.1f} | "
            f"{np.percentile(e, 95):.1f} | {e.mean(axis=1).max():.1f} | {lost} | "
            f"{np.median(tr.seconds[1:]):.2f} | {last[:90]}… |"
        )
        print(rows[-1], flush=True)
    return rows


def inputs(args, work: Path) -> list[str]:
    """The inputs table (module docstring)."""
    t = load_template("neutral_5k")
    spec = SynthSpec(
        motion=str(DATA / "mocap" / "cmu" / "05_01.amc"),
        template="neutral_5k",
        start=100,
        stop=100 + args.frames,
    )
    cap = synthesize(work / "walk", spec, show_progress=False)
    truth = np.stack([f.truth.joints for f in cap])
    forms = {}

    def folder(name: str) -> Path:
        p = work / "inputs" / name
        p.mkdir(parents=True, exist_ok=True)
        return p

    for k, f in enumerate(cap):
        V = f.truth.vertices
        write_mesh(folder("obj") / f"f{k:03d}.obj", V, t.F)
        write_mesh(folder("mm") / f"f{k:03d}.obj", V * 1000, t.F)
        write_mesh(folder("yup") / f"f{k:03d}.obj", V, t.F, up="y")
        write_mesh(folder("far") / f"f{k:03d}.obj", V + [1e6, 0.0, 0.0], t.F)
        for name, normals in (("cloud", True), ("cloud_no_normals", False)):
            cols = [V, vertex_normals(V, t.F)] if normals else [V]
            props = [f"property float {c}" for c in ("x", "y", "z", "nx", "ny", "nz")]
            head = [
                "ply",
                "format ascii 1.0",
                f"element vertex {len(V)}",
                *props[: 6 if normals else 3],
                "end_header",
            ]
            body = "\n".join(" ".join(f"{x:.6f}" for x in row) for row in np.hstack(cols))
            (folder(name) / f"f{k:03d}.ply").write_text("\n".join(head) + "\n" + body + "\n")
    archive = work / "inputs" / "walk.tar.gz"
    if not archive.is_file():
        with tarfile.open(archive, "w:gz") as tf:
            for p in sorted(folder("obj").glob("*.obj")):
                tf.add(p, arcname=p.name)
    forms = {
        "mesh folder": folder("obj"),
        "glob": f"{folder('obj')}/f0*.obj",
        "archive": archive,
        "millimetres": folder("mm"),
        "Y up": folder("yup"),
        "point cloud": folder("cloud"),
        "point cloud, no normals": folder("cloud_no_normals"),
        "1000 km away": folder("far"),
    }
    rows = [
        "| input | method | status | mean joint mm | worst frame mm | the command's last line |",
        "|---|---|--:|--:|--:|---|",
    ]
    for name, src in forms.items():
        for m in args.methods:
            out = work / "tracks" / f"{name.replace(' ', '_').replace(',', '')}-{m}"
            status, last, _ = run(["track", str(src), "--method", m, "--out", str(out)])
            err = worst = ""
            if status == 0:
                tr = read_track(out)
                e = np.linalg.norm(tr.joints - truth[: len(tr.frames)], axis=2).mean(axis=1)
                err, worst = f"{1000 * e.mean():.1f}", f"{1000 * e.max():.1f}"
            rows.append(f"| {name} | {m} | {status} | {err} | {worst} | {last[:160]} |")
            print(rows[-1], flush=True)
    return rows


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--crane-frames", type=int, default=175)
    ap.add_argument("--frames", type=int, default=12)
    ap.add_argument("--methods", nargs="+", default=["patch", "cage", "articulated_icp"])
    ap.add_argument("--skip-crane", action="store_true")
    ap.add_argument("--skip-inputs", action="store_true")
    ap.add_argument("--work", default="/tmp/meshmocap-inputs")
    args = ap.parse_args()
    work = Path(args.work)
    work.mkdir(parents=True, exist_ok=True)
    stamp = datetime.now().strftime("%Y-%m-%d %H:%M")
    load0, t0 = os.getloadavg()[0], time.perf_counter()
    text = []
    if not args.skip_crane:
        if CRANE.is_file():
            text += [
                "## Real meshes: the MIT crane, clean meshes, per-vertex error",
                "",
                *crane(args, work),
                "",
            ]
        else:
            text += [f"crane skipped: {CRANE} is absent", ""]
    if not args.skip_inputs:
        if (DATA / "mocap" / "cmu" / "05_01.amc").is_file():
            text += [
                f"## Inputs: CMU 05_01 frames 100–{100 + args.frames - 1} as files",
                "",
                *inputs(args, work),
            ]
        else:
            text += ["inputs skipped: the CMU clips are absent"]
    text = [
        f"bench_inputs, measured {stamp}, load average {load0:.1f}→"
        f"{os.getloadavg()[0]:.1f} on {os.cpu_count()} cores, "
        f"{time.perf_counter() - t0:.0f} s",
        "",
        *text,
    ]
    print("\n" + "\n".join(text))
    (work / "results.md").write_text("\n".join(text) + "\n")


if __name__ == "__main__":
    main()
