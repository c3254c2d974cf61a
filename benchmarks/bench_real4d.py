"""Real 4D captures end to end: hull folders and point clouds without a
template, files in millimetres and Y up, and the MIT crane scored per vertex.

Part 1, a synthetic capture's hulls as a studio hands them out. ``meshmocap synth`` makes a
short walk (``--frames`` frames at 30 fps, the ``neutral`` body, the 4-camera
``humaneva4`` rig, 1 cm hulls); its hull meshes are written as a folder of PLY meshes in
metres and Z up, the same in millimetres and Y up, and a folder of PLY point clouds (the
hulls' vertices, no faces, no normals). Each folder, and the capture folder itself, is
tracked by ``meshmocap track SOURCE --out T`` with default options (patch; no template:
the capture folder uses the one its capture.json names, the folders have the performer's
body fitted to their points), and scored against the capture's true joints (mean over
15 joints and all frames, mm; "first fifth" over the first fifth of the frames). "lost
while fine" counts frames flagged lost where no true joint error exceeds 100 mm.

Part 2 (``--crane``), the crane archive (../shared/data/meshes/crane, 175 frames, Y up;
``--crane-frames`` N: the first N): ``meshmocap track crane.tar.gz --up y --method M
--refine R`` (``--refines``: off, on, arap; ``arap`` is the default path), then scored as
``meshmocap eval`` scores: the per-vertex error of the tracked first frame's vertices
against the files, mean over the frames, the first and last fifths (and their ratio: the
target is ≤ 1.5), the worst frame, and the error's parts along the true surface's normal
and along the surface (tangential: a vertex slid to another point of the body; mean over
every 5th frame); the output surface refined towards the observations along its normals
(``on``), as rigidly as possible with its vertices anchored frame to frame (``arap``: the
skeleton is then held with the frame before's refined surface), and as the skeleton's skin
leaves it (``off``): one tracking per method and refinement, its seconds per frame
(median, frame 0 left out). ``--refit N``: then each method tracked again (the first
refinement of ``--refines``) with ``--template``, the tracked template whose skinning
weights are fitted to that first track's own refined surfaces of its first N frames in
their stored poses (a skinning decomposition with the skeleton given, no true surface:
:func:`~meshmocap.body.skinning.fit_weights`).

Part 3 (``--clean4d``), a synthetic clean 4D capture: the synthetic walk's true surfaces
(the performer's own connectivity) as a folder of PLY meshes, tracked like the crane
(patch and ICP, each refinement) and scored per vertex against the files.

Part 3b (``--clothed``), a synthetic clothed 4D capture: the same walk performed by
``neutral_5k`` in a skirt (``bench_cage_performers``' ``skirt``), its true surfaces as
PLY meshes, tracked and scored the same way.

Part 4 (``--peer K``), the peer: trimesh's non-rigid ICP (``nricp_amberg``, Amberg et al.
2007, default steps) from the crane's frame 0 file to each of the next K frames, each
frame starting from the last one's result, the per-vertex error against the files and
the CPU seconds per frame.

Run: ``python benchmarks/bench_real4d.py [--frames 24] [--crane] [--clean4d] [--clothed]
[--peer 3] [--refit 60] [--work DIR]``. Captures and tracks are cached in ``--work`` (runs
resume); the tables are printed. Timings are the tracker's seconds per frame (frame 0 left
out) and depend on the machine's load (printed).
"""

from __future__ import annotations

import argparse
import contextlib
import io
import os
import time
from pathlib import Path

import numpy as np
import trimesh

from meshmocap.analysis.evaluate import evaluate
from meshmocap.body.pose_fit import pose_from_surface
from meshmocap.cli import main
from meshmocap.geometry.mesh import vertex_normals
from meshmocap.io.capture import Capture
from meshmocap.io.meshes import write_mesh
from meshmocap.io.results import (
    open_tracked_capture,
    read_track,
    tracked_template,
)

CRANE = (
    Path(__file__).resolve().parents[1].parent
    / "shared/data/meshes/crane/crane_mesh_0000-0174.tar.gz"
)


def run(argv: list[str]) -> str:
    """``meshmocap ARGV`` in this process; its printed lines (raises on a non-zero exit)."""
    out = io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(out):
        status = main(argv)
    if status != 0:
        raise SystemExit(f"meshmocap {' '.join(argv)} failed:\n{out.getvalue()}")
    return out.getvalue()


def folders(cap: Capture, work: Path) -> dict[str, Path]:
    """The capture's hulls written as a studio's folders (module docstring)."""
    out = {
        "hull meshes (m, Z up)": work / "hulls_m",
        "hull meshes (mm, Y up)": work / "hulls_mm_yup",
        "point clouds (m, Z up)": work / "points",
    }
    if all(p.is_dir() for p in out.values()):
        return out
    for p in out.values():
        p.mkdir(parents=True, exist_ok=True)
    for f in cap:
        V, F = f.hull_mesh
        name = f"{f.index:05d}.ply"
        write_mesh(out["hull meshes (m, Z up)"] / name, V, F)
        write_mesh(out["hull meshes (mm, Y up)"] / name, V * 1000.0, F, up="y")
        cloud = trimesh.PointCloud(V).export(file_type="ply")
        (out["point clouds (m, Z up)"] / name).write_bytes(cloud)
    return out


def synthetic(args, work: Path) -> list[list]:
    cap_dir = work / "capture"
    if not (cap_dir / "capture.json").is_file():
        run(["synth", str(cap_dir), "--frames", f"0:{args.frames}", "--fps", "30"])
    cap = Capture(cap_dir)
    sources = {"capture folder": cap_dir, **folders(cap, work)}
    rows, base = [], None
    for label, src in sources.items():
        out = work / f"track_{src.name}"
        t0 = time.perf_counter()
        log = run(["track", str(src), "--out", str(out)])
        wall = time.perf_counter() - t0
        t = read_track(out)
        ev = evaluate(t, cap, silhouettes=False, surface_frames=0)
        e = ev.joints.errors  # (T, 15) mm
        fifth = max(1, len(e) // 5)
        lost = np.array(["lost" in f for f in t.flags])
        fine = _finite(np.max, e, axis=1) <= 100.0
        mean = _finite(np.mean, e)
        base = mean if base is None else base
        chosen = next((ln for ln in log.splitlines() if ln.startswith("template")), "")
        how = "named" if "capture.json names" in chosen else chosen.split(":")[1].split("(")[0]
        rows.append(
            [
                label,
                how.strip()[:40],
                ev.init.split(",")[0][:34],
                mean,
                mean - base,
                _finite(np.mean, e[:fifth]),
                _finite(np.max, e),
                f"{int((lost & fine).sum())}/{int(fine.sum())}",
                float(np.median(t.seconds[1:])),
                wall,
            ]
        )
    return rows


def _finite(f, x: np.ndarray, **kw):
    """``f`` of the finite values of ``x`` (NaN where there is none), without numpy's
    "Mean of empty slice" warning."""
    x = np.asarray(x, dtype=np.float64)
    if "axis" in kw:
        return np.array([_finite(f, r) for r in np.moveaxis(x, kw["axis"], -1)])
    x = x[np.isfinite(x)]
    return float(f(x)) if x.size else float("nan")


def per_vertex_rows(source: Path, label: str, args, work: Path, extra: list[str]) -> list[list]:
    """Each method of ``--crane-methods`` tracked on the mesh files ``source`` with each
    ``--refine`` of ``--refines``, and scored per vertex against the files (module
    docstring, part 2)."""
    rows = []
    runs = [(m, r, None) for m in args.crane_methods for r in args.refines]
    if args.refit:  # then each method again with the weights fitted on its first track
        runs += [(m, args.refines[0], args.refit) for m in args.crane_methods]
    for method, refine, refit in runs:
        out = work / f"{label}_{method}_refine-{refine}"
        argv = ["track", str(source), *extra, "--method", method, "--refine", refine]
        if refit:
            body = refitted(out, refit, work / f"{label}_{method}_refit{refit}.npz")
            argv += ["--template", str(body)]
            out = out.with_name(f"{out.name}_refit{refit}")
            refine = f"{refine}, refit {refit}"
        t0 = time.perf_counter()
        run([*argv, "--out", str(out)])
        wall = time.perf_counter() - t0
        t = read_track(out)
        step = float(np.median(t.seconds[1:])) if len(t.seconds) > 1 else np.nan
        ev = evaluate(t, open_tracked_capture(t.meta), silhouettes=False, surface_frames=0)
        c = ev.correspondence
        if c is None or not len(c.per_frame):
            rows.append([method, refine, "not scored (no file connectivity)"] + [""] * 11)
            continue
        per = c.per_frame
        fifth = max(1, len(per) // 5)
        first, last = float(per[:fifth].mean()), float(per[-fifth:].mean())
        normal, tangential = surface_split(t)
        rows.append(
            [
                method,
                refine,
                ev.cage_body or "-",
                len(per),
                c.overall.mean,
                first,
                last,
                last / first if first > 0 else float("nan"),
                float(per.max()),
                int(c.frames[int(np.argmax(per))]),
                normal,
                tangential,
                step,
                wall,
            ]
        )
    return rows


def refitted(track_dir: Path, frames: int, path: Path) -> Path:
    """The template of the track ``track_dir`` with its skinning weights fitted to the
    track's own refined surfaces of its first ``frames`` frames, in the poses stored with
    them (:func:`~meshmocap.body.skinning.fit_weights` over each vertex's
    :func:`~meshmocap.body.skinning.weight_candidates`; no true surface), saved to
    ``path``: a second tracking with it (``--template``) is the skinning decomposition's
    measure."""
    from dataclasses import replace

    from meshmocap.body.skeleton import forward_kinematics
    from meshmocap.body.skinning import fit_weights, skinning_transforms, weight_candidates
    from meshmocap.body.template import save_template
    from meshmocap.io.results import read_state

    t = read_track(track_dir)
    template = tracked_template(track_dir, t.meta)
    sk = template.skeleton
    A = []
    for i in t.frames[:frames]:
        st = read_state(track_dir, int(i))
        G, P = forward_kinematics(sk, st["pose_R"], st["pose_root"])
        A.append(skinning_transforms(G, P, sk.rest_positions))
    C = weight_candidates(template.weights, template.F, sk.parents)
    W = fit_weights(template.V, np.stack(A), t.vertices[:frames], template.weights, C)
    return save_template(path, replace(template, weights=W))


def surface_split(t, every: int = 5) -> tuple[float, float]:
    """The per-vertex error of a track against its files (every ``every``-th frame), split
    into its parts along the true surface's normal and along the surface (tangential: a
    vertex slid to another point of the body, which no refinement along the normals can
    see), mm, mean over vertices and frames."""
    cap = open_tracked_capture(t.meta)
    pos = {int(f): k for k, f in enumerate(cap.indices)}
    normal, tangential = [], []
    for k in range(0, len(t.frames), every):
        V, F = cap[pos[int(t.frames[k])]].hull_mesh
        N = vertex_normals(V, F)
        e = t.vertices[k] - V
        en = np.einsum("ij,ij->i", e, N)
        normal.append(np.abs(en).mean())
        tangential.append(np.linalg.norm(e - en[:, None] * N, axis=1).mean())
    return float(np.mean(normal)) * 1000.0, float(np.mean(tangential)) * 1000.0


def crane(args, work: Path) -> list[list]:
    if not CRANE.is_file():
        print(f"crane skipped: {CRANE} is absent")
        return []
    n = args.crane_frames
    return per_vertex_rows(CRANE, f"crane{n}", args, work, ["--up", "y", "--frames", f"0:{n}"])


def clean4d(args, work: Path) -> list[list]:
    """The synthetic walk's true surfaces as mesh files (module docstring, part 3)."""
    cap_dir = work / "capture"
    if not (cap_dir / "capture.json").is_file():
        run(["synth", str(cap_dir), "--frames", f"0:{args.frames}", "--fps", "30"])
    return per_vertex_rows(true_meshes(cap_dir, work / "true_meshes"), "clean4d", args, work, [])


def true_meshes(cap_dir: Path, folder: Path) -> Path:
    """The true surfaces of the capture ``cap_dir`` written as PLY meshes into ``folder``."""
    if not folder.is_dir():
        cap = Capture(cap_dir)
        folder.mkdir(parents=True)
        for f in cap:
            write_mesh(folder / f"{f.index:05d}.ply", f.truth.vertices, cap.truth_faces)
    return folder


def clothed(args, work: Path) -> list[list]:
    """The synthetic walk performed by ``neutral_5k`` in a skirt (``bench_cage_performers``'
    ``skirt``: the lower torso and thighs grown into a loose cone), its true surfaces as a
    folder of PLY meshes, tracked and scored like the clean walk (module docstring, part
    3): a performer whose surface no bundled body has."""
    from bench_cage_performers import skirt
    from meshmocap.body.template import load_template, save_template

    cap_dir = work / "capture_skirt"
    if not (cap_dir / "capture.json").is_file():
        body = save_template(work / "skirt.npz", skirt(load_template("neutral_5k")))
        frames = ["--frames", f"0:{args.frames}", "--fps", "30"]
        run(["synth", str(cap_dir), "--subject", str(body), *frames])
    return per_vertex_rows(true_meshes(cap_dir, work / "skirt_meshes"), "clothed", args, work, [])


def peer(args) -> list:
    """trimesh's nricp_amberg over the crane's first frames (module docstring, part 4)."""
    from trimesh.registration import nricp_amberg

    from meshmocap.io.capture import SequenceCapture

    seq = SequenceCapture(CRANE, up="y")
    V0, F = seq[0].hull_mesh
    src = trimesh.Trimesh(V0, F, process=False)
    err, cpu = [], []
    for k in range(1, args.peer + 1):
        V, Fk = seq[k].hull_mesh
        c0 = time.process_time()
        out = nricp_amberg(src, trimesh.Trimesh(V, Fk, process=False))
        cpu.append(time.process_time() - c0)
        err.append(float(np.linalg.norm(out - V, axis=1).mean() * 1000))
        src = trimesh.Trimesh(out, F, process=False)
    return [
        f"nricp_amberg (trimesh), frames 1–{args.peer}",
        float(np.mean(err)),
        float(np.mean(cpu)),
    ]


def rig_floor(track_dir: Path, every: int = 7) -> tuple[float, float]:
    """The per-vertex error (mm: mean, worst frame) of the tracked template's own rig posed
    to fit every ``every``-th true mesh with known correspondences
    (:func:`~meshmocap.body.pose_fit.pose_from_surface`): what no skeleton-driven tracker
    of that template can beat."""
    t = read_track(track_dir, vertices=False)
    template = tracked_template(track_dir, t.meta)
    cap = open_tracked_capture(t.meta)
    ks = list(range(0, len(cap), every))
    V = np.stack([cap[k].hull_mesh[0] for k in ks])
    fit = pose_from_surface(template, V, joint_weight=0.0)
    posed = np.stack(
        [template.pose(fit.rotations[i], fit.root_positions[i]).V for i in range(len(ks))]
    )
    err = np.linalg.norm(posed - V, axis=-1).mean(axis=1) * 1000.0
    return float(err.mean()), float(err.max())


def table(headers: list[str], rows: list[list]) -> str:
    cells = [[f"{v:.1f}" if isinstance(v, float) else str(v) for v in r] for r in rows]
    width = [max(len(h), *(len(r[k]) for r in cells)) for k, h in enumerate(headers)]

    def line(r: list[str]) -> str:
        return "| " + " | ".join(c.ljust(w) for c, w in zip(r, width, strict=True)) + " |"

    rule = "|" + "|".join("-" * (w + 2) for w in width) + "|"
    return "\n".join([line(headers), rule, *map(line, cells)])


def cli() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--frames", type=int, default=24, help="frames of the synthetic walk")
    ap.add_argument("--crane", action="store_true", help="also track the crane (minutes)")
    ap.add_argument("--crane-methods", nargs="+", default=["patch", "articulated_icp"])
    ap.add_argument("--crane-frames", type=int, default=175, help="the crane's first N frames")
    ap.add_argument(
        "--refines", nargs="+", default=["off", "on", "arap"], help="--refine values tracked"
    )
    ap.add_argument("--clean4d", action="store_true", help="the walk's true meshes as files")
    ap.add_argument("--clothed", action="store_true", help="the same, performed in a skirt")
    ap.add_argument(
        "--refit",
        type=int,
        default=0,
        help="then track again with weights fitted on the first track's first N frames",
    )
    ap.add_argument("--peer", type=int, default=0, help="nricp_amberg on K crane frames")
    ap.add_argument("--skip-synthetic", action="store_true")
    ap.add_argument("--work", default="/tmp/meshmocap-real4d")
    args = ap.parse_args()
    work = Path(args.work)
    work.mkdir(parents=True, exist_ok=True)
    if not args.skip_synthetic:
        rows = synthetic(args, work)
        print(
            f"\nSynthetic walk, {args.frames} frames at 30 fps (humaneva4 hulls, 1 cm), "
            "tracked with default options; joint errors against the truth, mm\n"
        )
        heads = [
            "input",
            "template",
            "first pose",
            "mean",
            "vs capture",
            "first fifth",
            "worst joint",
            "lost while fine",
            "s/frame",
            "wall s",
        ]
        print(table(heads, rows))
    heads = [
        "method",
        "refine",
        "cage on",
        "frames",
        "mean",
        "first fifth",
        "last fifth",
        "last/first",
        "worst frame",
        "(frame)",
        "normal",
        "tangential",
        "s/frame",
        "wall s",
    ]
    if args.clean4d:
        rows = clean4d(args, work)
        print(
            f"\nClean 4D stand-in: the synthetic walk's {args.frames} true meshes as PLY files, "
            f"track FOLDER --method M --refine R, then eval: per-vertex error, mm "
            f"(load {os.getloadavg()[0]:.1f})\n"
        )
        print(table(heads, rows))
    if args.clothed:
        rows = clothed(args, work)
        print(
            f"\nClothed 4D stand-in: the synthetic walk's {args.frames} true meshes of "
            "neutral_5k in a skirt as PLY files, track FOLDER --method M --refine R, then "
            f"eval: per-vertex error, mm (load {os.getloadavg()[0]:.1f})\n"
        )
        print(table(heads, rows))
    if args.crane:
        rows = crane(args, work)
        print(
            f"\nCrane ({args.crane_frames} frames, Y up): track crane.tar.gz --up y --method M "
            f"--refine R, then eval: per-vertex error against the files, mm "
            f"(load {os.getloadavg()[0]:.1f})\n"
        )
        print(table(heads, rows))
        if rows:
            first = args.crane_methods[0]
            mean, worst = rig_floor(
                work / f"crane{args.crane_frames}_{first}_refine-{args.refines[0]}"
            )
            print(
                f"\nthe rigged first frame's own skeleton and skinning, posed to each 7th true "
                f"mesh with known correspondences: {mean:.1f} mm per vertex (worst frame "
                f"{worst:.1f}), the floor of a skeleton-driven fit of that template"
            )

    if args.peer and CRANE.is_file():
        name, err, cpu = peer(args)
        print(
            f"\npeer: {name}: {err:.1f} mm per vertex, {cpu:.1f} s CPU per frame "
            f"(load {os.getloadavg()[0]:.1f})"
        )


if __name__ == "__main__":
    cli()
