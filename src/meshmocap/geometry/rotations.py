"""Rotations as arrays: axis-angle (so3 exp/log), Euler angles, quaternions, interpolation.

All functions are vectorised over leading dimensions. Rotation matrices act on column
vectors (``x' = R @ x``); ``R`` has shape ``(..., 3, 3)``. Axis-angle vectors ``w`` have
shape ``(..., 3)``, radians, direction = axis, norm = angle. Quaternions are ``(..., 4)``
in scalar-last order ``(x, y, z, w)`` like scipy.

References
----------
- O. Rodrigues, *Des lois géométriques qui régissent les déplacements d'un système
  solide dans l'espace, et de la variation des coordonnées provenant de ces
  déplacements considérés indépendamment des causes qui peuvent les produire*,
  Journal de Mathématiques Pures et Appliquées 5:380–440, 1840.
- K. Shoemake, *Animating rotation with quaternion curves*, SIGGRAPH 1985.
  https://doi.org/10.1145/325165.325242
"""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

from meshmocap._tolerances import ANTIPARALLEL, DEGENERATE_AXIS, NORM_FLOOR, SMALL_ANGLE, SMALL_SINE


def skew(w: np.ndarray) -> np.ndarray:
    """Return the cross-product matrices ``[w]_x`` of ``w`` (..., 3) as (..., 3, 3)."""
    w = np.asarray(w, dtype=float)
    S = np.zeros((*w.shape[:-1], 3, 3))
    S[..., 0, 1], S[..., 0, 2] = -w[..., 2], w[..., 1]
    S[..., 1, 0], S[..., 1, 2] = w[..., 2], -w[..., 0]
    S[..., 2, 0], S[..., 2, 1] = -w[..., 1], w[..., 0]
    return S


def cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``a × b`` along the last axis of (..., 3) arrays (``np.cross`` has ~0.1 ms of
    overhead a call, which adds up in small per-iteration products)."""
    return a[..., [1, 2, 0]] * b[..., [2, 0, 1]] - a[..., [2, 0, 1]] * b[..., [1, 2, 0]]


def so3_exp(w: np.ndarray) -> np.ndarray:
    """Return rotation matrices (..., 3, 3) for axis-angle vectors ``w`` (..., 3), radians.

    Rodrigues' formula, with Taylor expansions below 1e-6 rad so that it is exact to
    float64 precision at zero.
    """
    w = np.asarray(w, dtype=float)
    theta2 = np.sum(w * w, axis=-1)
    theta = np.sqrt(theta2)
    small = theta < SMALL_ANGLE
    safe = np.where(small, 1.0, theta)
    a = np.where(small, 1.0 - theta2 / 6.0, np.sin(safe) / safe)
    b = np.where(small, 0.5 - theta2 / 24.0, (1.0 - np.cos(safe)) / (safe * safe))
    K = skew(w)
    return np.eye(3) + a[..., None, None] * K + b[..., None, None] * (K @ K)


def so3_log(R: np.ndarray) -> np.ndarray:
    """Return axis-angle vectors (..., 3), radians in [0, π], of rotation matrices (..., 3, 3)."""
    return (
        Rotation.from_matrix(np.asarray(R, dtype=float).reshape(-1, 3, 3))
        .as_rotvec()
        .reshape(*np.shape(R)[:-2], 3)
    )


def euler_matrix(
    angles: np.ndarray, order: str, *, degrees: bool = False, start: np.ndarray | None = None
) -> np.ndarray:
    """Return rotation matrices (..., 3, 3) from intrinsic Euler angles.

    Each factor rotates two columns of the running product in place instead of multiplying
    3×3 matrices, which is several times faster on large stacks (every joint of a clip).

    Parameters
    ----------
    angles : (..., k) float
        One angle per axis of ``order``, in the order the axes are named.
    order : str
        Upper-case axis letters, e.g. ``"ZXY"``: ``R = Rz(a0) @ Rx(a1) @ Ry(a2)``, the
        BVH/ASF convention (the first named rotation is outermost).
    degrees : bool
        Angles in degrees instead of radians.
    start : (..., 3, 3) float, optional
        Left factor: returns ``start @ R`` (default identity).
    """
    angles = np.asarray(angles, dtype=float)
    if degrees:
        angles = np.deg2rad(angles)
    R = np.empty((*angles.shape[:-1], 3, 3))
    R[...] = np.eye(3) if start is None else start
    for k, axis in enumerate(order):
        i = "XYZ".index(axis)
        j, l = (i + 1) % 3, (i + 2) % 3
        c = np.cos(angles[..., k])[..., None]
        s = np.sin(angles[..., k])[..., None]
        a, b = R[..., :, j].copy(), R[..., :, l].copy()
        R[..., :, j] = a * c + b * s
        R[..., :, l] = b * c - a * s
    return R


def axis_rotation(angle: np.ndarray, axis: str) -> np.ndarray:
    """Return rotations (..., 3, 3) by ``angle`` (...,) radians about the coordinate ``axis``."""
    angle = np.asarray(angle, dtype=float)
    c, s = np.cos(angle), np.sin(angle)
    R = np.zeros((*angle.shape, 3, 3))
    i = "XYZ".index(axis.upper())
    j, k = (i + 1) % 3, (i + 2) % 3
    R[..., i, i] = 1.0
    R[..., j, j] = c
    R[..., k, k] = c
    R[..., j, k] = -s
    R[..., k, j] = s
    return R


def matrix_to_euler(R: np.ndarray, order: str, *, degrees: bool = False) -> np.ndarray:
    """Inverse of :func:`euler_matrix`: intrinsic Euler angles (..., 3) of ``R`` (..., 3, 3)."""
    R = np.asarray(R, dtype=float)
    e = Rotation.from_matrix(R.reshape(-1, 3, 3)).as_euler(order.upper(), degrees=degrees)
    return e.reshape(*R.shape[:-2], 3)


def rotation_between(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Return the smallest rotations (..., 3, 3) that turn directions ``a`` into ``b`` (..., 3).

    Antiparallel pairs rotate by π about an axis orthogonal to ``a``.
    """
    a = np.asarray(a, dtype=float)
    b = np.asarray(b, dtype=float)
    a = a / np.maximum(np.linalg.norm(a, axis=-1, keepdims=True), NORM_FLOOR)
    b = b / np.maximum(np.linalg.norm(b, axis=-1, keepdims=True), NORM_FLOOR)
    axis = np.cross(a, b)
    s = np.linalg.norm(axis, axis=-1)
    c = np.sum(a * b, axis=-1)
    angle = np.arctan2(s, c)
    # antiparallel: any axis orthogonal to a
    anti = (s < ANTIPARALLEL) & (c < 0)
    ortho = np.cross(a, np.array([1.0, 0.0, 0.0]))
    ortho = np.where(
        np.linalg.norm(ortho, axis=-1, keepdims=True) < DEGENERATE_AXIS,
        np.cross(a, [0.0, 1.0, 0.0]),
        ortho,
    )
    axis = np.where(anti[..., None], ortho, axis)
    n = np.maximum(np.linalg.norm(axis, axis=-1, keepdims=True), NORM_FLOOR)
    return so3_exp(axis / n * angle[..., None])


def matrix_to_quat(R: np.ndarray) -> np.ndarray:
    """Return unit quaternions (..., 4), scalar last, of rotation matrices (..., 3, 3)."""
    R = np.asarray(R, dtype=float)
    return Rotation.from_matrix(R.reshape(-1, 3, 3)).as_quat().reshape(*R.shape[:-2], 4)


def quat_to_matrix(q: np.ndarray) -> np.ndarray:
    """Return rotation matrices (..., 3, 3) of quaternions (..., 4), scalar last."""
    q = np.asarray(q, dtype=float)
    return Rotation.from_quat(q.reshape(-1, 4)).as_matrix().reshape(*q.shape[:-1], 3, 3)


def slerp_matrices(R: np.ndarray, times: np.ndarray, new_times: np.ndarray) -> np.ndarray:
    """Spherically interpolate rotation tracks, vectorised over tracks and query times.

    Parameters
    ----------
    R : (T, ..., 3, 3) float
        Rotations sampled at ``times`` (any number of independent tracks after axis 0).
    times : (T,) float
        Increasing sample times, seconds.
    new_times : (T2,) float
        Query times; clipped to ``[times[0], times[-1]]``.

    Returns
    -------
    (T2, ..., 3, 3) float
    """
    R = np.asarray(R, dtype=float)
    times = np.asarray(times, dtype=float)
    new_times = np.clip(np.asarray(new_times, dtype=float), times[0], times[-1])
    if len(times) == 1:
        return np.broadcast_to(R[:1], (len(new_times), *R.shape[1:])).copy()
    i = np.clip(np.searchsorted(times, new_times, side="right") - 1, 0, len(times) - 2)
    u = (new_times - times[i]) / (times[i + 1] - times[i])
    q = matrix_to_quat(R)
    q0, q1 = q[i], q[i + 1]
    dot = np.sum(q0 * q1, axis=-1)
    q1 = np.where(dot[..., None] < 0, -q1, q1)  # shortest arc
    dot = np.abs(dot).clip(max=1.0)
    omega = np.arccos(dot)
    u = u.reshape(-1, *([1] * (q.ndim - 2)))
    sin_omega = np.sin(omega)
    near = sin_omega < SMALL_SINE
    safe = np.where(near, 1.0, sin_omega)
    w0 = np.where(near, 1.0 - u, np.sin((1.0 - u) * omega) / safe)
    w1 = np.where(near, u, np.sin(u * omega) / safe)
    qi = w0[..., None] * q0 + w1[..., None] * q1
    qi /= np.linalg.norm(qi, axis=-1, keepdims=True)
    return quat_to_matrix(qi)
