"""The bundled pose library: a few thousand diverse human poses from the CMU motion-capture
database, for learning broad pose priors (the cage tracker's default pose manifold).

The poses were drawn by ``tools/make_pose_library.py`` from the CMU clips of many motion
categories (walks, runs, jumps, modern dance, salsa, everyday actions), retargeted onto the
bundled ``neutral`` skeleton (:func:`~meshmocap.body.retarget.retarget`), taken at 30 fps
and ordered by farthest-point sampling of their pelvis-relative joint positions: every
prefix of the library is a diverse subset (pose ``k`` is the one farthest from poses
``0 … k − 1``, at ``radius[k]``), so a learner that needs ``N`` poses takes the first ``N``.
The data was obtained from mocap.cs.cmu.edu; the database was created with funding from NSF
EIA-0196217.

File format (``.npz``, ``format = "meshmocap-pose-library-1"``):

===================  ====================  ==================================================
key                  shape / dtype         meaning
===================  ====================  ==================================================
format               str                   ``"meshmocap-pose-library-1"``
skeleton             str                   the bundled template whose skeleton the
                                           rotations drive (``"neutral"``)
joint_names          (J,) str              its joints, in its order
quaternions          (N, J, 4) int16       local joint rotations relative to the rest
                                           frames (:func:`~meshmocap.body.skeleton.
                                           forward_kinematics`), unit quaternions scalar
                                           last, times 32767, scalar part ≥ 0
categories           (C,) str              motion categories
category             (N,) uint8            each pose's category
trials               (T,) str              source trials (CMU ``SS_TT``)
trial                (N,) uint16           each pose's trial
frame                (N,) uint16           its frame in the trial at 30 fps
radius               (N,) float32          farthest-point distance at which it was picked:
                                           RMS over the joints of the distance to the
                                           nearest earlier pose, metres
held_out             (H,) str              trials of the source folder deliberately left out
source               str                   where the clips come from
===================  ====================  ==================================================

Root positions are not stored (the poses are pelvis-relative); the root's rotation is.
"""

from __future__ import annotations

import functools
import os
from dataclasses import dataclass
from importlib import resources
from pathlib import Path

import numpy as np

from meshmocap._npz import read_npz
from meshmocap.body.template import Template, load_template
from meshmocap.errors import FormatError, InputError
from meshmocap.geometry.rotations import quat_to_matrix

__all__ = ["LIBRARY_FORMAT", "QUATERNION_SCALE", "PoseLibrary", "library_path", "load_pose_library"]

LIBRARY_FORMAT = "meshmocap-pose-library-1"
#: The library stores unit quaternions as int16: each component times this.
QUATERNION_SCALE = 32767.0


def library_path() -> Path:
    """The bundled library file."""
    return Path(str(resources.files("meshmocap.body") / "data" / "poses" / "cmu_poses.npz"))


@dataclass(frozen=True, eq=False)
class PoseLibrary:
    """Poses on one skeleton, in farthest-point order (module docstring).

    Attributes
    ----------
    rotations : (N, J, 3, 3) float64
        Local joint rotations of ``skeleton``'s joints.
    skeleton : str
        The bundled template whose skeleton they drive.
    joint_names : tuple of str
    categories : (N,) str
        Each pose's motion category.
    trials : (N,) str
        Each pose's source trial.
    frames : (N,) int64
        Its frame in the trial (30 fps).
    radius : (N,) float64
        Farthest-point distance at which each pose was picked, metres.
    held_out : tuple of str
        Trials of the source left out of the library.
    digest : str
        16 hex digits of SHA-256 of the file's bytes (what a cache keys on).
    """

    rotations: np.ndarray
    skeleton: str
    joint_names: tuple[str, ...]
    categories: np.ndarray
    trials: np.ndarray
    frames: np.ndarray
    radius: np.ndarray
    held_out: tuple[str, ...]
    digest: str

    def __len__(self) -> int:
        return len(self.rotations)

    def on(self, template: Template, n: int | None = None) -> np.ndarray:
        """Local rotations (n, J', 3, 3) of ``template``'s skeleton for the first ``n`` poses
        (all by default): retargeted from the library's skeleton
        (:class:`~meshmocap.body.retarget.Retargeter`: every bone points where the
        library's does), identity where the skeletons are the same."""
        from meshmocap.body.motion import Motion
        from meshmocap.body.retarget import Retargeter

        R = self.rotations[: len(self) if n is None else int(n)]
        source = load_template(self.skeleton).skeleton
        if source.names != template.skeleton.names:
            raise InputError(
                f"pose library: template {template.name!r} has other joints than "
                f"the library's {self.skeleton!r} skeleton"
            )
        if np.array_equal(source.offsets, template.skeleton.offsets):
            return R.copy()
        m = Motion(source, R, np.zeros((len(R), 3)), 30.0)
        return Retargeter(source, template)(m, floor="none").rotations


@functools.cache
def _load(path: str, stamp: float) -> PoseLibrary:
    import hashlib

    p = Path(path)
    d = read_npz(p, "pose library", keys=("format", "skeleton", "joint_names", "quaternions"))
    if str(d["format"]) != LIBRARY_FORMAT:
        raise FormatError(f"{p}: expected format {LIBRARY_FORMAT!r}, found {str(d['format'])!r}")
    try:
        q = d["quaternions"]
        names = tuple(str(s) for s in d["joint_names"])
        if q.dtype != np.int16 or q.ndim != 3 or q.shape[1:] != (len(names), 4) or not len(q):
            raise ValueError(
                f"quaternions must be (N, {len(names)}, 4) int16, found {q.shape} {q.dtype}"
            )
        qf = q.astype(np.float64) / QUATERNION_SCALE
        norm = np.linalg.norm(qf, axis=-1, keepdims=True)
        if np.abs(norm - 1).max() > 1e-3:
            raise ValueError("quaternions are not unit")
        R = quat_to_matrix(qf / norm)
        n = len(q)
        cats, trials = d["categories"].astype(str), d["trials"].astype(str)
        category, trial = d["category"].astype(np.int64), d["trial"].astype(np.int64)
        if category.shape != (n,) or trial.shape != (n,) or d["frame"].shape != (n,):
            raise ValueError("category, trial and frame need one entry per pose")
        out = PoseLibrary(
            R,
            str(d["skeleton"]),
            names,
            cats[category],
            trials[trial],
            d["frame"].astype(np.int64),
            d["radius"].astype(np.float64),
            tuple(str(s) for s in d["held_out"]),
            hashlib.sha256(p.read_bytes()).hexdigest()[:16],
        )
    except (KeyError, ValueError, TypeError, IndexError) as exc:
        raise FormatError(f"{p}: corrupt pose library ({type(exc).__name__}: {exc})") from None
    for a in (out.rotations, out.categories, out.trials, out.frames, out.radius):
        a.setflags(write=False)
    return out


def load_pose_library(path: str | os.PathLike | None = None) -> PoseLibrary:
    """Read the bundled pose library (or a file in its format); cached per file.

    Raises
    ------
    FormatError
        Not a pose library, or a corrupt one.
    """
    p = Path(path) if path is not None else library_path()
    stamp = p.stat().st_mtime if p.is_file() else 0.0
    return _load(str(p), stamp)
