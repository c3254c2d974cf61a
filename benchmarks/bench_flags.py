"""Calibration of the ``lost`` flag: does a flagged limb mean a joint
really off?

Protocol. Synthetic captures with truth (the first-frame captures of ``bench_init.py
--first-only`` and the captures of ``bench_limbs.py``, found in ``--captures`` folders),
performed by heavy_male and small_female, the template being the performer's own body.
Per frame (every ``--step``-th), ``--samples`` poses:

* **clean** — the true pose with every joint turned by a small random rotation (σ =
  ``--noise`` degrees about a random axis: what a tracker's residual error looks like);
* **off** — the same, and one limb (arm or leg, drawn) turned at its upper or lower joint
  by an angle drawn uniformly in 10–120°: from a limb slightly off to one lost.

Each pose is scored by :func:`~meshmocap.estimate.recovery.quality.fit_quality` with the frame's
silhouettes (the driver's check). Per sample: the largest joint error of each limb (mm)
and whether the check names that limb lost. Reported: for "a joint more than 100 mm off"
and "more than 150 mm off", the recall (samples with such a limb whose limb is named) and
the precision (named limbs that have such a joint), and the share of clean samples with a
limb named. Acceptance: recall ≥ 90 % for > 150 mm, ≤ 5 % of clean frames
flagged. Run: ``python benchmarks/bench_flags.py [--captures /tmp/limbs/init/captures]
[--step 10] [--samples 4]``.
"""

from __future__ import annotations

import argparse
import json
import os
from datetime import datetime
from pathlib import Path

import numpy as np

from meshmocap.body.template import load_template
from meshmocap.estimate.recovery.limbs import LIMBS
from meshmocap.estimate.recovery.observe import observed
from meshmocap.estimate.recovery.quality import LIMB_PARTS, fit_quality, limb_labels
from meshmocap.geometry.rotations import so3_exp
from meshmocap.io.capture import open_capture


def sample(t, labels, V, fr, err, kind: str, seed: int) -> dict:
    """One sample: the check of the vertices ``V`` on the frame ``fr`` and each limb's
    worst joint error (``err`` (K,) mm)."""
    q = fit_quality(
        V,
        labels,
        fr.points[0],
        fr.field,
        F=t.F,
        cameras=fr.cameras,
        masks=fr.silhouettes,
        seed=seed,
    )
    names = t.eval_skeleton.names
    worst = {limb: 0.0 for limb in LIMB_PARTS}
    for n, e in zip(names, err, strict=True):
        limb = next(k for k, v in LIMB_PARTS.items() if n in v)
        worst[limb] = max(worst[limb], float(e))
    return dict(kind=kind, worst=worst, lost=set(q.lost), q=q)


def samples(cap_dir: Path, args, rng) -> list[dict]:
    """The clean and off samples of one capture (module docstring)."""
    cap = open_capture(cap_dir)
    spec = json.loads((cap_dir / "capture.json").read_text())["spec"]
    t = load_template(spec.get("subject") or spec["template"])
    sk = t.skeleton
    labels = limb_labels(t)
    out = []
    for k in range(0, len(cap), args.step):
        fr = observed(cap[k])
        tr = fr.truth
        for s in range(args.samples):
            R = tr.rotations.copy()
            axis = rng.normal(size=(len(R), 3))
            axis /= np.linalg.norm(axis, axis=1, keepdims=True)
            noise = np.deg2rad(args.noise) * np.abs(rng.normal(size=(len(R), 1)))
            R = so3_exp(axis * noise) @ R
            kind = "clean" if s == 0 else "off"
            if kind == "off":
                limb = str(rng.choice(list(LIMBS)))
                js = LIMBS[limb][0]
                joint = js[int(rng.integers(2))]
                a = rng.normal(size=3)
                ang = np.deg2rad(rng.uniform(10, 120))
                j = sk.index(joint)
                R[j] = so3_exp(a / np.linalg.norm(a) * ang) @ R[j]
            posed = t.pose(R, tr.root)
            err = np.linalg.norm(posed.eval_joints - tr.joints, axis=1) * 1000
            out.append(sample(t, labels, posed.V, fr, err, kind, int(k)))
    return out


def relabelled(rows: list[dict], th: tuple[float, float, float]) -> list[dict]:
    """``rows`` with the limbs named by thresholds ``th`` (outside, buried, unexplained)."""
    return [
        dict(
            r,
            lost={
                k
                for k in LIMB_PARTS
                if r["q"].outside[k] > th[0]
                or r["q"].buried[k] > th[1]
                or r["q"].unexplained[k] > th[2]
            },
        )
        for r in rows
    ]


def report(rows: list[dict]) -> str:
    """Recall, precision and clean-frame flag rate (module docstring)."""
    lines = []
    for th in (100, 150):
        pos = [(r, limb) for r in rows for limb, e in r["worst"].items() if e > th]
        hit = sum(limb in r["lost"] for r, limb in pos)
        named = [(r, limb) for r in rows for limb in r["lost"]]
        good = sum(r["worst"][limb] > th for r, limb in named)
        frames = [r for r in rows if max(r["worst"].values()) > th]
        fhit = sum(bool(r["lost"]) for r in frames)
        lines.append(
            f"joint > {th} mm: limb recall {hit}/{len(pos)} ({100 * hit / max(len(pos), 1):.0f} %),"
            f" frame recall {fhit}/{len(frames)} ({100 * fhit / max(len(frames), 1):.0f} %), "
            f"precision {good}/{len(named)} ({100 * good / max(len(named), 1):.0f} %)"
        )
    clean = [r for r in rows if r["kind"] == "clean"]
    flagged = sum(bool(r["lost"]) for r in clean)
    worst = max((max(r["worst"].values()) for r in clean), default=0.0)
    lines.append(
        f"clean samples flagged: {flagged}/{len(clean)} ({100 * flagged / max(len(clean), 1):.0f}"
        f" %; their worst joint {worst:.0f} mm)"
    )
    why: dict[str, int] = {}
    for r in clean:
        q = r["q"]
        for limb in r["lost"]:
            for m in ("outside", "buried", "unexplained"):
                key = f"{limb} {m} {getattr(q, m)[limb]:.2f}"
                why[key] = why.get(key, 0) + 1
    if why:
        lines.append(
            "clean samples' flagged limbs: " + ", ".join(f"{k} {v}" for k, v in why.items())
        )
    return "\n".join(lines)


def calibrate(rows: list[dict], *, recall: float = 0.92) -> str:
    """The thresholds (outside, buried, unexplained) of the OR rule, on a grid, that name
    the fewest limbs whose joints are all within 100 mm while naming at least ``recall`` of
    the limbs with a joint more than 150 mm off."""
    X = np.array(
        [
            [r["q"].outside[k], r["q"].buried[k], r["q"].unexplained[k]]
            for r in rows
            for k in LIMB_PARTS
        ]
    )
    e = np.array([r["worst"][k] for r in rows for k in LIMB_PARTS])
    pos, neg = e > 150, e < 100
    best = None
    for to in (0.2, 0.25, 0.3, 0.4, 0.5, 0.6, 0.7, 0.8):
        for tb in (0.5, 0.6, 0.7, 0.8, 1.01):
            for tu in (0.02, 0.03, 0.05, 0.07, 0.1, 0.13, 0.16, 0.2, 0.3, 1.01):
                f = (X[:, 0] > to) | (X[:, 1] > tb) | (X[:, 2] > tu)
                rec = f[pos].mean()
                fp = f[neg].mean()
                if rec >= recall and (best is None or fp < best[0]):
                    best = (fp, rec, to, tb, tu)
    if best is None:
        return f"no grid point reaches {100 * recall:.0f} % recall"
    fp, rec, to, tb, tu = best
    return (
        f"calibrated: outside > {to}, buried > {tb}, unexplained > {tu}: limb recall (>150 mm)"
        f" {100 * rec:.0f} %, limbs within 100 mm named {100 * fp:.1f} %\n"
        + report(relabelled(rows, (to, tb, tu)))
    )


def track_rows(track_dir: Path, cap_dir: Path) -> list[dict]:
    """One row per frame of a track folder (with vertices) on its capture: each limb's
    worst joint error and the limbs :func:`fit_quality` names lost (``kind``: clean when
    every joint is within 100 mm)."""
    from meshmocap.io.results import read_track, tracked_template

    track = read_track(track_dir)
    cap = open_capture(cap_dir)
    try:
        t = tracked_template(track_dir, track.meta)
    except FileNotFoundError:  # bench_limbs keeps the estimated body beside, in subjects/
        t = load_template(track_dir.parents[2] / "subjects" / track_dir.parent.name / "subject.npz")
    labels = limb_labels(t)
    rows = []
    for k, index in enumerate(track.frames):
        fr = observed(cap[cap.indices.index(int(index))])
        err = np.linalg.norm(track.joints[k] - fr.truth.joints, axis=1) * 1000
        kind = "clean" if err.max() < 100 else "off"
        rows.append(sample(t, labels, track.vertices[k], fr, err, kind, int(index)))
    return rows


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--captures", nargs="+", default=["/tmp/limbs/init/captures"])
    ap.add_argument("--step", type=int, default=10)
    ap.add_argument("--samples", type=int, default=4, help="per frame: 1 clean, the rest off")
    ap.add_argument("--noise", type=float, default=1.5, help="degrees, every joint")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument(
        "--tracks",
        nargs="+",
        default=None,
        help="instead: score these tracks' own frames (bench_limbs work folder tracks/NAME/X,"
        " the capture in captures/NAME)",
    )
    args = ap.parse_args()
    if args.tracks:
        rows = []
        for tr in map(Path, args.tracks):
            rows += track_rows(tr, tr.parents[2] / "captures" / tr.parent.name)
        print(f"Lost flags on {len(args.tracks)} tracks, {len(rows)} frames\n\n{report(rows)}")
        return
    rng = np.random.default_rng(args.seed)
    dirs = sorted(
        d for c in args.captures for d in Path(c).iterdir() if (d / "capture.json").is_file()
    )
    load0 = os.getloadavg()[0]
    rows = []
    for d in dirs:
        rows += samples(d, args, rng)
    print(
        f"Lost-flag calibration: {len(dirs)} captures, {len(rows)} samples "
        f"({datetime.now():%Y-%m-%d %H:%M}, load {load0:.1f})\n\n{report(rows)}\n"
        f"{calibrate(rows)}"
    )


if __name__ == "__main__":
    main()
