"""Per-frame diagnostics of the patch tracker on a synthetic capture with ground truth
(why does it drift where articulated ICP does not?)

Tracks a capture with the patch tracker (first frame from the truth) and, after every
frame, measures against the truth:

* joints: mean and worst reported joint error (mm), the worst joint's name;
* energies: each term of Eq. (1) as it enters the total (λ × mean residual, m²), σ, EM
  iterations;
* the classifier (§III-B): observed points kept, share of kept points that are phantom
  (farther than ``--phantom`` from the true surface), share of true-surface points thrown
  away, label accuracy of the kept true-surface points (the truth's label: the body part of
  the nearest true vertex);
* the E-step: share of assignment weight on phantom points, and on patches of another body
  part than the point's true part;
* forces on the worst body part: for the patches bound to the bone of the worst joint,
  each term's pull (minus its gradient, summed over the part's patch centres) projected on
  the direction from the tracked part to the true one (positive: towards the truth), in
  units of the data term's Gauss–Newton stiffness (≈ millimetres of pull).

Capture: ``--motion`` (a CMU file of ../shared/data/mocap/cmu, or a procedural motion),
``--start/--stop/--step`` frames at 60 fps (``--step 2``: 30 fps, large steps),
``--rig``, ``--degrade``; made once in ``--work``. Options of the tracker with
``--set NAME=VALUE``. Writes ``--out`` (CSV, one row per frame) and prints the frames whose
mean error is above ``--report`` mm.
"""

from __future__ import annotations

import argparse
import ast
import csv
from pathlib import Path

import numpy as np
from pykdtree.kdtree import KDTree

from meshmocap.apps.bench.captures import DEGRADED
from meshmocap.body.template import load_template
from meshmocap.errors import FitError
from meshmocap.geometry.proximity import point_to_surface
from meshmocap.studio.degrade import Degradation
from meshmocap.studio.synth import SynthSpec, synthesize
from meshmocap.trackers.patch.solver import System
from meshmocap.trackers.patch.terms import Iterate
from meshmocap.trackers.patch.tracker import PatchOptions, PatchTracker

DATA = Path(__file__).resolve().parents[1].parent / "shared" / "data"


def capture_of(args):
    motion = args.motion
    if not motion.replace("_", "").isalpha():
        hits = sorted((DATA / "mocap" / "cmu").glob(f"{motion}.*"))
        hits += sorted((DATA / "mocap" / "cmu" / "library").glob(f"{motion}.*"))
        motion = str(next(h for h in hits if h.suffix in (".amc", ".bvh")))
    # a file whose header misstates its rate (16_01: 30 for 120 fps) is resampled so that
    # its true motion plays at 60 fps
    fps = 60.0 * (args.header_fps / args.source_fps if args.source_fps else 1.0)
    spec = SynthSpec(
        motion=motion,
        template=args.template,
        rig=args.rig,
        fps=fps,
        start=args.start,
        stop=args.stop,
        step=args.step,
        degradation=DEGRADED if args.degrade else Degradation(),
    )
    name = f"{Path(args.motion).stem}-{args.rig}-{args.start}-{args.stop}-{args.step}"
    name += "-deg" if args.degrade else ""
    return synthesize(Path(args.work) / name, spec, show_progress=True)


def forces(tr: PatchTracker, frame, part_patches: np.ndarray, lag: np.ndarray) -> dict:
    """Each term's pull on the patches ``part_patches`` along the unit vector ``lag``
    (mm of the data term's stiffness), at the last iteration's correspondences."""
    m, fit = tr.model, tr.last_fit
    it = Iterate(fit["frame"], tr.R, tr.c, tr.X, *tr.own_vertices(), fit["assign"])
    out, stiff = {}, 1e-12
    for term in tr.terms:
        sys = System.empty(tr.pattern)
        term.add(sys, it)
        g = sys.g[: 6 * m.P].reshape(m.P, 6)[part_patches, 3:].sum(axis=0)
        out[term.name] = float(-g @ lag)
        if term.name == "data":  # stiffness: Σ of the translation diagonal on these patches
            stiff = max(float(np.trace(sys.D[part_patches, 3:, 3:].sum(axis=0)) / 3), 1e-12)
    return {k: 1000 * v / stiff for k, v in out.items()}


def baseline(args, cap, t) -> None:
    """Per-frame joint errors of another method (``--method``) on the same capture."""
    from meshmocap.trackers.driver import track_sequence
    from meshmocap.trackers.options import TrackOptions
    from meshmocap.trackers.registry import make_tracker

    n = len(cap) if args.frames is None else min(len(cap), args.frames)
    out = Path(args.out).with_suffix("")
    track = track_sequence(
        make_tracker(args.method),
        t,
        cap,
        out,
        TrackOptions(positions=range(n), resume=False, show_progress=False),
    )
    true = np.stack([cap[i].truth.joints for i in range(n)])
    e = np.linalg.norm(track.joints - true, axis=2) * 1000
    for i in range(1, n):
        if e[i].mean() > args.report or i % 25 == 0:
            print(f"frame={cap[i].index} mean_mm={e[i].mean():.1f} worst_mm={e[i].max():.0f}")
    print(
        f"{args.method}: {n - 1} frames: mean {e[1:].mean():.1f} mm, worst frame "
        f"{e[1:].mean(axis=1).max():.1f} mm, worst joint {e[1:].max():.0f} mm"
    )


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--motion", default="05_01")
    ap.add_argument("--start", type=int, default=None)
    ap.add_argument("--stop", type=int, default=300)
    ap.add_argument("--step", type=int, default=None)
    ap.add_argument("--rig", default="humaneva4")
    ap.add_argument("--source-fps", type=float, default=None, help="true rate of the file")
    ap.add_argument("--header-fps", type=float, default=30.0, help="rate its header states")
    ap.add_argument("--template", default="neutral_5k")
    ap.add_argument("--degrade", action="store_true")
    ap.add_argument("--phantom", type=float, default=0.02, help="metres off the true surface")
    ap.add_argument("--set", nargs="*", default=[], help="PatchOptions NAME=VALUE")
    ap.add_argument("--frames", type=int, default=None, help="track only the first N")
    ap.add_argument("--work", default="/tmp/meshmocap-diag")
    ap.add_argument("--out", default="/tmp/meshmocap-diag/diag.csv")
    ap.add_argument("--report", type=float, default=40.0)
    ap.add_argument("--method", default="patch", help="another method: joint errors only")
    args = ap.parse_args()
    cap = capture_of(args)
    t = load_template(args.template)
    if args.method != "patch":
        baseline(args, cap, t)
        return
    opts = {k: ast.literal_eval(v) for k, v in (s.split("=", 1) for s in args.set)}
    tr = PatchTracker(PatchOptions(**opts))
    tr.last_partition = None
    f0 = cap[0]
    tr.init(t, f0, f0.truth.rotations, f0.truth.root)
    m = tr.model
    names = t.eval_skeleton.names
    cls_joint = m.classes  # class index → evaluation joint starting the bone
    rows = []
    n = len(cap) if args.frames is None else min(len(cap), args.frames)
    for i in range(1, n):
        fr = cap[i]
        Y0, _, _ = tr.observations(fr)
        try:
            res = tr.step(fr)
        except FitError as exc:
            print(f"frame {fr.index}: {exc}")
            continue
        truth = fr.truth
        e = np.linalg.norm(res.joints - truth.joints, axis=1) * 1000
        e_skel = np.linalg.norm(tr.X - truth.joints, axis=1) * 1000
        Vt = truth.vertices.astype(np.float64)
        # truth of the observed points: nearest true vertex's part, distance to the surface
        d_all, _ = point_to_surface(Y0, Vt, t.F)
        _, near = KDTree(Vt).query(Y0, k=1)
        cls_all = m.vertex_class[near.astype(np.int64)]
        part = getattr(tr, "last_partition", None)
        on = d_all < args.phantom
        kept = part.keep if part is not None else np.ones(len(Y0), bool)
        lab_ok = part.labels == cls_all if part is not None else np.zeros(len(Y0), bool)
        # E-step against the truth
        k = tr.last_fit["assign"]
        patch, w, y = k.patch, k.weight, k.point
        dy, _ = point_to_surface(y, Vt, t.F)
        _, ny = KDTree(Vt).query(y, k=1)
        ycls_true = m.vertex_class[ny.astype(np.int64)]
        wrong = (m.bone_of_patch[patch] != ycls_true) & (dy < args.phantom)
        wsum = max(float(w.sum()), 1e-12)
        # forces on the worst joint's part (the bone the joint starts, or ends for a leaf)
        jw = int(np.argmax(e))
        cands = np.flatnonzero((m.bone_j == jw) | (m.bone_child == jw))
        V_out = res.vertices
        row = {
            "frame": fr.index,
            "mean_mm": e.mean(),
            "worst_mm": e.max(),
            "worst_joint": names[jw],
            "skel_mean_mm": e_skel.mean(),
            "n_iter": res.n_iter,
            "sigma_mm": 1000 * res.energies.get("sigma", np.nan),
            "n_obs": len(Y0),
            "n_kept": int(kept.sum()),
            "kept_phantom": float((~on[kept]).mean()) if kept.any() else np.nan,
            "true_dropped": float((~kept[on]).mean()) if on.any() else np.nan,
            "label_acc": float(lab_ok[kept & on].mean()) if (kept & on).any() else np.nan,
            "w_phantom": float(w[dy >= args.phantom].sum() / wsum),
            "w_wrong_part": float(w[wrong].sum() / wsum),
            "surface_mm": 1000 * float(np.mean(np.linalg.norm(V_out - Vt, axis=1))),
        }
        # each term's share of the total: coefficient × value, over the tracker's terms
        row.update({f"E_{t.name}": t.coefficient * res.energies[t.name] for t in tr.terms})
        if len(cands):
            part_patches = cands
            pv = np.isin(m.labels, part_patches)
            lag = Vt[pv].mean(axis=0) - V_out[pv].mean(axis=0)
            row["lag_mm"] = 1000 * float(np.linalg.norm(lag))
            lag = lag / max(np.linalg.norm(lag), 1e-12)
            for k, val in forces(tr, fr, part_patches, lag).items():
                row[f"F_{k}"] = val
            # share of the part's data weight on phantom points, and on other parts' points
            sel = np.isin(patch, part_patches)
            ws = max(float(w[sel].sum()), 1e-12)
            row["part_w_phantom"] = float(w[sel & (dy >= args.phantom)].sum() / ws)
            row["part_w_wrong"] = float(w[sel & wrong].sum() / ws)
        rows.append(row)
        if e.mean() > args.report or i % 25 == 0:
            print(
                " ".join(
                    f"{k}={v:.3g}" if isinstance(v, float) else f"{k}={v}" for k, v in row.items()
                ),
                flush=True,
            )
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    keys = list(dict.fromkeys(k for r in rows for k in r))
    with out.open("w", newline="") as fh:
        wr = csv.DictWriter(fh, keys)
        wr.writeheader()
        wr.writerows(rows)
    E = np.array([r["mean_mm"] for r in rows])
    print(
        f"{len(rows)} frames: mean {E.mean():.1f} mm, worst frame {E.max():.1f} mm; "
        f"classes {[names[j] for j in cls_joint]}; wrote {out}"
    )


if __name__ == "__main__":
    main()
