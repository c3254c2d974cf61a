"""Build the bundled pose library (``meshmocap.body.pose_library``) from CMU clips.

Run from the repository root::

    python tools/make_pose_library.py [--library ../shared/data/mocap/cmu/library]
        [--out src/meshmocap/body/data/poses/cmu_poses.npz] [--n 2400] [--fps 30]

What it does: every clip of the library folder (BVH, or AMC with its ASF) except the
held-out trials (:data:`HELD_OUT`: another benchmark evaluates on them, so they must train
nothing) is read, resampled to ``--fps``, retargeted onto the bundled ``neutral`` skeleton
(``floor="none"``); each frame's feature is its joint positions (the fingers left out)
relative to the root (the root's rotation and position removed, metres). Farthest-point
sampling over the pooled frames (start: the frame nearest the pool's mean) picks ``--n``
poses in order, each the one farthest (RMS over the joints) from those already picked; the
file stores their local rotations as int16 quaternions, category, trial, frame and pick
radius (format in ``meshmocap.body.pose_library``). Deterministic; about a minute on 2 cores.

Categories (:data:`CATEGORIES`) come from CMU's subject descriptions (mocap.cs.cmu.edu),
checked against each clip's root motion (speed, height range): subject 2, 3, 6, 7, 8, 10
and 12's trials in the folder are straight walks (0.6–1.6 m/s), 9's runs, 5's modern
dance, 60/61's salsa; subject 13's trials 39–42 are jumps (root height 0.44–1.33 m), its
others and subject 14's are everyday actions. The evaluation clips of the benchmarks
(05_01, 09_01, 01_01, 49_18, 16_01, 07_01, 35_xx) are not in the folder.

The data used here was obtained from mocap.cs.cmu.edu. The database was created with
funding from NSF EIA-0196217.
"""

from __future__ import annotations

import argparse
import re
import time
from pathlib import Path

import numpy as np

from meshmocap.body.pose_library import LIBRARY_FORMAT, QUATERNION_SCALE
from meshmocap.body.retarget import retarget
from meshmocap.body.skeleton import forward_kinematics
from meshmocap.body.template import load_template
from meshmocap.geometry.rotations import matrix_to_quat
from meshmocap.io.clips import load_clip

#: Trials of the library folder that train nothing (held out for loss-recovery tests).
HELD_OUT = ("05_03", "60_01", "61_01")
#: Evaluation clips of the benchmarks: refused if ever found in the folder.
EVALUATION = ("05_01", "09_01", "01_01", "49_18", "16_01", "07_01")
#: Category of a trial: by subject, with per-trial exceptions (module docstring).
SUBJECTS = {
    "02": "walk",
    "03": "walk",
    "05": "modern dance",
    "06": "walk",
    "07": "walk",
    "08": "walk",
    "09": "run",
    "10": "walk",
    "12": "walk",
    "13": "everyday",
    "14": "everyday",
    "60": "salsa",
    "61": "salsa",
}
TRIALS = {"13_39": "jump", "13_40": "jump", "13_41": "jump", "13_42": "jump"}
SKELETON = "neutral"
SOURCE = (
    "CMU Graphics Lab Motion Capture Database (mocap.cs.cmu.edu; created with funding "
    "from NSF EIA-0196217): subjects 05, 60, 61 as ASF/AMC (laneenget/ants-can-dance "
    "@ 573d6aa1), the others as 'Daz-friendly' BVH (Przestr/motion-capture @ c200c310)"
)


def category(trial: str) -> str:
    return TRIALS.get(trial, SUBJECTS.get(trial.split("_")[0], "other"))


#: Joints left out of the features: the fingers (noisy in the sources, and no quad follows
#: them), whose positions would otherwise decide a third of the picks.
FINGERS = (
    "LeftFingerBase",
    "LeftHandIndex1",
    "LThumb",
    "RightFingerBase",
    "RightHandIndex1",
    "RThumb",
)


def features(skeleton, R: np.ndarray) -> np.ndarray:
    """(N, J', 3) positions of the joints but the fingers, with the root at the origin and
    its rotation removed, metres."""
    R = R.copy()
    R[:, 0] = np.eye(3)
    keep = [j for j, n in enumerate(skeleton.names) if n not in FINGERS]
    return forward_kinematics(skeleton, R, np.zeros((len(R), 3)))[1][:, keep]


def farthest_points(X: np.ndarray, n: int) -> tuple[np.ndarray, np.ndarray]:
    """Indices of ``n`` rows of ``X`` (M, d) by farthest-point sampling (start: nearest the
    mean) and the distance at which each was picked."""
    d = np.linalg.norm(X - X.mean(0), axis=1)
    pick, radius = [int(np.argmin(d))], [np.inf]
    d = np.linalg.norm(X - X[pick[0]], axis=1)
    for _ in range(n - 1):
        k = int(np.argmax(d))
        pick.append(k)
        radius.append(float(d[k]))
        d = np.minimum(d, np.linalg.norm(X - X[k], axis=1))
    return np.array(pick), np.array(radius)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--library", default="../shared/data/mocap/cmu/library")
    ap.add_argument("--out", default="src/meshmocap/body/data/poses/cmu_poses.npz")
    ap.add_argument("--n", type=int, default=2400)
    ap.add_argument("--fps", type=float, default=30.0)
    args = ap.parse_args()
    t0 = time.perf_counter()
    folder = Path(args.library)
    template = load_template(SKELETON)
    sk = template.skeleton
    files = sorted(p for p in folder.iterdir() if p.suffix.lower() in (".bvh", ".amc"))
    names, rots, trial_ids, frames = [], [], [], []
    for p in files:
        trial = p.stem
        if not re.fullmatch(r"\d+_\d+", trial):
            continue
        if trial in EVALUATION:
            raise SystemExit(f"{p}: an evaluation clip is in the library folder")
        if trial in HELD_OUT:
            print(f"  {trial}: held out")
            continue
        m = retarget(load_clip(p, fps=args.fps), template, floor="none")
        names.append(trial)
        rots.append(m.rotations)
        trial_ids.append(np.full(m.n_frames, len(names) - 1))
        frames.append(np.arange(m.n_frames))
        print(f"  {trial}: {m.n_frames} frames, {category(trial)}")
    R = np.concatenate(rots)
    trial_of, frame_of = np.concatenate(trial_ids), np.concatenate(frames)
    X = features(sk, R)
    X = X.reshape(len(R), -1) / np.sqrt(X.shape[1])  # distances: RMS over the joints
    pick, radius = farthest_points(X, min(args.n, len(R)))
    q = matrix_to_quat(R[pick])
    q *= np.where(q[..., 3:] < 0, -1.0, 1.0)  # scalar part ≥ 0
    cats = sorted({category(t) for t in names})
    cat_of = np.array([cats.index(category(names[t])) for t in trial_of[pick]], dtype=np.uint8)
    radius[0] = radius[1] if len(radius) > 1 else 0.0
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    np.savez_compressed(
        out,
        format=np.str_(LIBRARY_FORMAT),
        skeleton=np.str_(SKELETON),
        joint_names=np.array(sk.names),
        quaternions=np.rint(q * QUATERNION_SCALE).astype(np.int16),
        categories=np.array(cats),
        category=cat_of,
        trials=np.array(names),
        trial=trial_of[pick].astype(np.uint16),
        frame=frame_of[pick].astype(np.uint16),
        radius=radius.astype(np.float32),
        held_out=np.array(HELD_OUT),
        source=np.str_(SOURCE),
    )
    counts = {c: int(np.sum(cat_of == i)) for i, c in enumerate(cats)}
    pool = {
        c: int(sum(np.sum(trial_of == i) for i, t in enumerate(names) if category(t) == c))
        for c in cats
    }
    print(
        f"wrote {out} ({out.stat().st_size / 1e3:.0f} kB): {len(pick)} of {len(R)} poses "
        f"from {len(names)} trials in {time.perf_counter() - t0:.0f} s"
    )
    print(
        "  picked / pooled per category: " + ", ".join(f"{c} {counts[c]}/{pool[c]}" for c in cats)
    )
    for k in (100, 200, 400, 800, 1600):
        if k < len(pick):  # the next pick's distance: how far the farthest pose is left
            print(f"  first {k:5d}: every pooled pose within {radius[k] * 1000:.0f} mm RMS")


if __name__ == "__main__":
    main()
