"""Real-data acceptance of both trackers: the MIT crane sequence (../shared/data/meshes/crane).

Protocol: the crane frames (175, 10,002 vertices with the same connectivity in every
frame, 30 fps) are rendered into the ``ring8`` rig's silhouettes and carved into visual
hulls at 1 cm (:func:`~meshmocap.studio.synth.synthesize_from_meshes`: no coherence is
left); the tracking template is frame 0's true mesh rigged by
:func:`~meshmocap.body.autorig.rig_mesh` (reference ``neutral``); the first frame is
initialised from the template's own pose (identity rotations at the rest root: the
template *is* frame 0); every method tracks the first ``--frames`` frames; the error is
per vertex, on the crane's own 10,002 vertices against their true positions (mm: mean,
median, 95th percentile, worst frame's mean, largest), and "surface", the mean distance
from each tracked vertex to the nearest true vertex (how far off the true surface the
result is; the rest of the correspondence error is sliding along it, e.g. a limb's twist,
which the hull's geometry does not show); seconds per frame are the driver's (frame 0
left out).

Methods: ``patch`` (target: mean ≤ 15 mm), ``patch_noclf`` and ``articulated_icp`` track
the full 10,002-vertex frame 0, their vertices compared one to one. ``cage`` follows
cage-manifold-tracking §6.1: its template is frame 0 decimated to ``--cage-vertices``
(4000; ``rig_mesh(decimate=)``: skeleton fitted to the full mesh, quadric decimation),
its pose manifold a ``--latent``-D GPLVM (10) learned from the quads of ``--poses`` (16)
frames evenly spaced over the tracked ones, placed automatically instead of by hand
(``--poses-from truth``, :func:`placed_quads`: each quad follows the rigid motion of the
true vertices its rig joint owns, from frame 0 to that frame; as in §6.1 the training
frames are frames of the tracked sequence), or from the template's skeleton fitted to
those true meshes (``fit``, :func:`~meshmocap.body.autorig.fit_sequence`: 41 mm RMS
fits on the crane's kicks, a poor manifold). **Cage error protocol**: the full
10,002-vertex frame 0 is put in the decimated template's rest cage (Green coordinates,
Lipman et al. 2008: the cage deforms any point inside it, §6.3's motion transfer) and
each frame's tracked cage (saved with the frame) deforms it; those positions are
compared with the truth. Full-resolution vertices outside the rest cage (the decimated
surface lies within 3.4 mm of the full one; the cage encloses it 4 mm deep) would follow
the exterior continuation of :mod:`meshmocap.geometry.green`; their number is printed.
Where :func:`~meshmocap.trackers.cage.oqr.build_oqr` fails on the template, the row says why.

Run: ``python benchmarks/bench_crane.py [--frames 175] [--methods patch cage ...]
[--work /tmp/meshmocap-crane]``. Captures, rigged templates, the manifold and tracks are
cached in ``--work`` (runs resume; a track folder is named by the tracker's options,
which identify the cage's manifold); the table is printed and written to
``--work``/results.md.
"""

from __future__ import annotations

import argparse
import hashlib
import time
from datetime import datetime
from pathlib import Path

import numpy as np
from pykdtree.kdtree import KDTree

from meshmocap.analysis.metrics import correspondence_error
from meshmocap.apps.bench.run import code_digest
from meshmocap.body.autorig import fit_sequence, rig_mesh
from meshmocap.body.template import Template, load_template, save_template
from meshmocap.errors import MeshError
from meshmocap.geometry.green import GreenDeformer
from meshmocap.io.meshes import MeshSequence
from meshmocap.io.results import read_state
from meshmocap.studio.synth import synthesize_from_meshes
from meshmocap.trackers.cage.cage_mesh import winding_numbers
from meshmocap.trackers.cage.manifold import PoseManifold, fit_pose_manifold, template_digest
from meshmocap.trackers.cage.oqr import (
    OQR,
    build_oqr,
    cage_vertices,
    configuration_vector,
    quads_from_pose,
)
from meshmocap.trackers.cage.training_poses import PoseSet
from meshmocap.trackers.driver import track_sequence
from meshmocap.trackers.options import TrackOptions
from meshmocap.trackers.registry import make_tracker

CRANE = (
    Path(__file__).resolve().parents[1].parent
    / "shared/data/meshes/crane/crane_mesh_0000-0174.tar.gz"
)
METHODS = ("patch", "patch_noclf", "articulated_icp", "cage")


def rigged(path: Path, V: np.ndarray, F: np.ndarray, name: str, decimate: int | None):
    """Frame 0 rigged by rig_mesh (cached in ``path``)."""
    if path.is_file():
        return load_template(path)
    t0 = time.perf_counter()
    tmpl = rig_mesh(V, F, name=name, decimate=decimate)
    save_template(path, tmpl)
    print(f"rigged frame 0 ({tmpl.n_vertices} v) in {time.perf_counter() - t0:.1f} s → {path}")
    return tmpl


def placed_quads(oqr: OQR, full: Template, meshes: np.ndarray) -> tuple[np.ndarray, ...]:
    """Quads placed on each training frame from the sequence's own correspondence (the
    automatic stand-in for §6.1's hand placement): each quad moves with the rigid motion
    (Kabsch) that best maps the full-resolution frame-0 vertices of its rig joint (with
    its descendants' where it owns fewer than 100) onto the same vertices in the frame.

    ``meshes`` (K, 10002, 3) true vertices, metres; returns centres (K, 21, 3) and
    rotations (K, 21, 3, 3) in world coordinates.
    """
    sk = full.skeleton
    owner = np.asarray(full.weights.argmax(axis=1)).ravel()
    c, R = [], []
    for q, j in enumerate(oqr.quads.joint_indices):
        joints, k = {int(j)}, 0
        while (np.isin(owner, list(joints)).sum() < 100) and k < 3:  # add a generation
            joints |= {c for p in joints for c in sk.children[p]}
            k += 1
        sel = np.isin(owner, list(joints))
        X0, Xk = full.V[sel], meshes[:, sel]
        m0, mk = X0.mean(axis=0), Xk.mean(axis=1)
        U, _, Wt = np.linalg.svd(np.einsum("vi,kvj->kij", X0 - m0, Xk - mk[:, None]))
        D = np.ones((len(meshes), 3))
        D[:, 2] = np.sign(np.linalg.det(U @ Wt))
        G = np.einsum("kji,kj,klj->kil", Wt, D, U)  # Wᵀ diag(D) Uᵀ: X0 → Xk
        c.append(np.einsum("kij,j->ki", G, oqr.quads.centres[q] - m0) + mk)
        R.append(G @ oqr.quads.rotations[q])
    return np.stack(c, axis=1), np.stack(R, axis=1)


def cage_tracker(
    tmpl: Template, full: Template, capture, F: np.ndarray, positions: list[int], args, work
):
    """The cage tracker with a manifold of ``--poses`` automatically placed poses (cached in
    ``work``) and its OQR, or the reason why there is none (build_oqr fails)."""
    t0 = time.perf_counter()
    try:
        oqr = build_oqr(tmpl)
    except MeshError as exc:
        return None, None, f"build_oqr fails on the rigged frame 0: {exc}"
    print(f"  OQR of {tmpl.name} ({tmpl.n_vertices} v) in {time.perf_counter() - t0:.0f} s")
    pick = np.unique(np.linspace(positions[0], positions[-1], args.poses).round().astype(int))
    key = f"{template_digest(tmpl)[:8]}-{args.poses_from}-{len(pick)}p{pick[-1]}-{args.latent}d"
    path = work / f"crane-manifold-{key}.npz"
    if path.is_file():
        pm = PoseManifold.load(path)
    else:
        t0 = time.perf_counter()
        meshes = np.stack([capture[int(k)].truth.vertices for k in pick]).astype(np.float64)
        if args.poses_from == "truth":
            Y = configuration_vector(*placed_quads(oqr, full, meshes))
            what = "placed from the true meshes"
        else:
            fits = fit_sequence(tmpl, [(V, F) for V in meshes])
            R, root = np.stack([f.R for f in fits]), np.stack([f.root for f in fits])
            Y = configuration_vector(*quads_from_pose(oqr, tmpl, R, root))
            rms = np.array([f.rms for f in fits]) * 1000
            what = f"from skeleton fits (RMS {rms.mean():.1f} mm, worst {rms.max():.1f})"
        labels = np.array([f"crane:{k}" for k in pick])
        poses = PoseSet(
            Y, labels, np.full(len(pick), "crane"), tmpl.name, (f"crane poses {args.poses_from}",)
        )
        pm = fit_pose_manifold(poses, tmpl, oqr=oqr, n_components=args.latent, n_samples=len(pick))
        pm.save(path)
        dt = time.perf_counter() - t0
        print(f"  cage manifold: {len(pick)} poses {what}, {args.latent}-D GPLVM, {dt:.0f} s")
    return make_tracker("cage", manifold=pm, template=tmpl), oqr, ""


def full_resolution(oqr: OQR, V0: np.ndarray, out: Path, indices: list[int]) -> np.ndarray:
    """(T, n, 3): the full-resolution frame 0 ``V0`` (n, 3) deformed by each tracked
    frame's cage through its Green coordinates in the rest cage (module docstring)."""
    gd = GreenDeformer(oqr.rest_vertices, oqr.faces, V0)
    outside = int((np.abs(winding_numbers(V0, oqr.rest_vertices, oqr.faces) - 1) > 1e-6).sum())
    print(f"  full-resolution frame 0: {outside} of {len(V0)} vertices outside the rest cage")
    return np.stack([gd.deform(read_state(out, i)["cage"]) for i in indices])


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--frames", type=int, default=175, help="first N frames (≤ 175)")
    ap.add_argument("--methods", nargs="+", default=list(METHODS), choices=METHODS)
    ap.add_argument("--poses", type=int, default=16, help="fitted poses of the cage manifold")
    ap.add_argument("--latent", type=int, default=10, help="latent dimension of the manifold")
    ap.add_argument(
        "--cage-vertices",
        type=int,
        default=4000,
        help="vertices of the cage's decimated template (0: full)",
    )
    ap.add_argument(
        "--poses-from",
        choices=("truth", "fit"),
        default="truth",
        help="training quads: from the true meshes or skeleton fits",
    )
    ap.add_argument("--work", default="/tmp/meshmocap-crane")
    args = ap.parse_args()
    if not CRANE.is_file():
        print(f"skipped: {CRANE} is absent")
        return
    work = Path(args.work)
    N = min(max(args.frames, 2), 175)
    stamp = datetime.now().strftime("%Y-%m-%d %H:%M")
    t0 = time.perf_counter()
    capture = synthesize_from_meshes(
        CRANE,
        work / "captures" / "crane-ring8",
        rig="ring8",
        frames=range(175),
        up="y",
        show_progress=True,
    )
    print(f"capture: {len(capture)} ring8 hulls ({time.perf_counter() - t0:.0f} s)")
    F = MeshSequence(CRANE, frames=[0], up="y")[0].F
    V0 = capture[0].truth.vertices.astype(np.float64)
    full = rigged(work / "crane_frame0.npz", V0, F, "crane_frame0", None)
    n_cage = args.cage_vertices or None
    small = (
        rigged(work / f"crane_frame0_{n_cage}v.npz", V0, F, f"crane_frame0_{n_cage}v", n_cage)
        if n_cage
        else full
    )
    positions = list(range(N))
    truth = np.stack([capture[k].truth.vertices for k in positions]).astype(np.float64)
    indices = [capture[k].index for k in positions]
    rows, notes = [], []
    for m in args.methods:
        print(f"{m}:")
        tmpl = small if m == "cage" else full
        if m == "cage":
            tracker, oqr, why = cage_tracker(tmpl, full, capture, F, positions, args, work)
            if tracker is None:
                print(f"  not applicable: {why}")
                rows.append((m, None, why))
                continue
        else:
            tracker = make_tracker(m)
        key = repr(sorted(tracker.options().items())) + code_digest()  # new code: new track
        opts = hashlib.sha1(key.encode()).hexdigest()[:8]
        out = work / "tracks" / f"{m}-{N}f-{template_digest(tmpl)[:8]}-{opts}"
        track = track_sequence(
            tracker, tmpl, capture, out, TrackOptions(positions=positions, show_progress=True)
        )
        V = (
            track.vertices[:N]
            if m != "cage" or n_cage is None
            else full_resolution(oqr, V0, out, indices)
        )
        e = correspondence_error(V, truth).errors  # (T, 10002) mm
        sec = track.seconds[1:N]
        off = [KDTree(T).query(X, k=1)[0].mean() for X, T in zip(V, truth, strict=True)]
        stats = (
            e.mean(),
            np.median(e),
            np.percentile(e, 95),
            e.mean(axis=1).max(),
            e.max(),
            float(np.median(sec)),
            int((~track.healthy[:N]).sum()),
            1000 * float(np.mean(off)),
        )
        worst = int(np.argmax(e.mean(axis=1)))
        print(
            f"  per-frame mean error: frame 0 {e[0].mean():.2f} mm, worst frame "
            f"{indices[worst]} {e[worst].mean():.1f} mm"
        )
        np.save(out / "vertex_errors_mm.npy", e.astype(np.float32))
        rows.append((m, stats, ""))
        if m == "cage":  # the deformation model's floor: truth-placed quads on every frame
            gd = GreenDeformer(oqr.rest_vertices, oqr.faces, full.V)
            cages = cage_vertices(oqr, *placed_quads(oqr, full, truth))
            floor = correspondence_error(np.stack([gd.deform(c) for c in cages]), truth).errors
            worst = floor.mean(axis=1).max()
            notes.append(
                f"cage model floor (quads placed from the truth on every frame, same "
                f"cage and Green coordinates): mean {floor.mean():.1f} mm, median "
                f"{np.median(floor):.1f}, worst frame {worst:.1f}"
            )
            print(f"  {notes[-1]}")
    head = (
        "| method | template | mean mm | median mm | p95 mm | worst frame mm | max mm "
        "| surface mm | s/frame | flagged |\n"
        "|---|---|---:|---:|---:|---:|---:|---:|---:|---:|"
    )
    lines = [
        f"crane, ring8 hulls at 1 cm, frames 0–{N - 1}, per-vertex error on the "
        f"{full.n_vertices} true vertices, measured {stamp}",
        "",
        head,
    ]
    for m, s, why in rows:
        tv = (small if m == "cage" else full).n_vertices
        if s is None:
            lines.append(f"| {m} | {tv} v | n/a | | | | | | | |  \n  {m}: {why}")
        else:
            lines.append(
                f"| {m} | {tv} v | {s[0]:.1f} | {s[1]:.1f} | {s[2]:.1f} | {s[3]:.1f} | "
                f"{s[4]:.0f} | {s[7]:.1f} | {s[5]:.2f} | {s[6]} |"
            )
    if "cage" in args.methods and n_cage:
        lines.append(
            f"\ncage: template decimated to {small.n_vertices} v; error of the "
            f"{full.n_vertices} full-resolution vertices carried by the tracked cage "
            "through their Green coordinates in the rest cage"
        )
    lines.append(
        "\nsurface mm: mean distance from each tracked vertex to the nearest true vertex "
        "(the part of the error off the true surface; the rest of the correspondence "
        "error is sliding along it)"
    )
    lines += notes
    text = "\n".join(lines)
    print("\n" + text)
    (work / "results.md").write_text(text + "\n")


if __name__ == "__main__":
    main()
