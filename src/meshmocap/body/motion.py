"""Motions: a skeleton posed over time, with axis/unit conversion and resampling."""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np

from meshmocap._tolerances import ROUNDING_SLACK, SAME_FPS
from meshmocap.body.skeleton import Skeleton, forward_kinematics
from meshmocap.errors import InputError
from meshmocap.geometry.rotations import slerp_matrices

#: Rotation taking a Y-up frame (BVH, ASF/AMC: x left of the subject, y up, z forward) to
#: meshmocap's Z-up world frame: (x, y, z) → (x, −z, y). Right-handed; forward becomes −Y.
Y_UP_TO_Z_UP = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])


@dataclass(frozen=True, eq=False)
class Motion:
    """A skeleton animated over ``T`` frames.

    Parameters
    ----------
    skeleton : Skeleton
        ``J`` joints with world-aligned rest frames.
    rotations : (T, J, 3, 3) float64
        Local rotation of every joint, relative to its rest frame.
    root_positions : (T, 3) float64
        World position of the root joint per frame, metres.
    fps : float
        Frames per second.
    """

    skeleton: Skeleton
    rotations: np.ndarray
    root_positions: np.ndarray
    fps: float

    def __post_init__(self) -> None:
        R = np.asarray(self.rotations, dtype=np.float64)
        t = np.asarray(self.root_positions, dtype=np.float64)
        J = self.skeleton.n_joints
        if R.ndim != 4 or R.shape[1:] != (J, 3, 3):
            raise InputError(f"motion: rotations must have shape (T, {J}, 3, 3), found {R.shape}")
        if t.shape != (R.shape[0], 3):
            raise InputError(
                f"motion: root_positions must have shape ({R.shape[0]}, 3), found {t.shape}"
            )
        if not (np.isfinite(self.fps) and self.fps > 0):
            raise InputError(f"motion: fps must be a positive number, found {self.fps}")
        if not (np.all(np.isfinite(R)) and np.all(np.isfinite(t))):
            raise InputError("motion: rotations or root positions contain NaN or infinite values")
        object.__setattr__(self, "rotations", R)
        object.__setattr__(self, "root_positions", t)
        object.__setattr__(self, "fps", float(self.fps))

    @property
    def n_frames(self) -> int:
        """Number of frames ``T``."""
        return self.rotations.shape[0]

    @property
    def duration(self) -> float:
        """Seconds from the first to the last frame."""
        return (self.n_frames - 1) / self.fps

    @property
    def times(self) -> np.ndarray:
        """(T,) float64: time of each frame in seconds, starting at 0."""
        return np.arange(self.n_frames) / self.fps

    @cached_property
    def _fk(self) -> tuple[np.ndarray, np.ndarray]:
        return forward_kinematics(self.skeleton, self.rotations, self.root_positions)

    @property
    def global_rotations(self) -> np.ndarray:
        """(T, J, 3, 3) float64: world rotation of every joint per frame."""
        return self._fk[0]

    @property
    def joint_positions(self) -> np.ndarray:
        """(T, J, 3) float64: world position of every joint per frame, metres."""
        return self._fk[1]

    def frames(self, index: slice | np.ndarray | list[int]) -> Motion:
        """Return the motion restricted to ``index`` (a slice or frame indices).

        A slice with a step keeps the frame rate consistent (``fps / step``).
        """
        step = index.step if isinstance(index, slice) and index.step else 1
        R = self.rotations[index]
        if R.shape[0] == 0:
            raise InputError(f"motion: frame selection {index} selects no frame of {self.n_frames}")
        return Motion(self.skeleton, R, self.root_positions[index], self.fps / step)

    def transformed(self, C: np.ndarray, *, scale: float = 1.0) -> Motion:
        """Return the motion expressed in another world frame.

        Local rotations become ``C R Cᵀ`` so that world positions become ``scale · C x``.

        Parameters
        ----------
        C : (3, 3) float64
            Rotation from this motion's world frame to the new one (e.g. :data:`Y_UP_TO_Z_UP`).
        scale : float
            Length factor (e.g. a unit conversion to metres).
        """
        C = np.asarray(C, dtype=float)
        R = C @ self.rotations @ C.T
        sk = self.skeleton.transformed(C).scaled(scale)
        return Motion(sk, R, scale * self.root_positions @ C.T, self.fps)


def resample(motion: Motion, fps: float) -> Motion:
    """Return ``motion`` resampled to ``fps`` frames per second.

    Rotations are interpolated by slerp, root positions linearly; the new clip spans the same
    duration (its last frame is at or before the original's last frame).

    Parameters
    ----------
    motion : Motion
    fps : float
        Target frame rate, > 0.
    """
    if not (np.isfinite(fps) and fps > 0):
        raise InputError(f"resample: fps must be a positive number, found {fps}")
    if abs(fps - motion.fps) < SAME_FPS:
        return motion
    times = motion.times
    n = int(np.floor(motion.duration * fps + ROUNDING_SLACK)) + 1
    new_times = np.arange(n) / fps
    R = slerp_matrices(motion.rotations, times, new_times)
    t = np.stack([np.interp(new_times, times, motion.root_positions[:, k]) for k in range(3)], 1)
    return Motion(motion.skeleton, R, t, fps)
