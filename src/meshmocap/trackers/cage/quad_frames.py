"""Small pure helpers of the cage tracker (:mod:`meshmocap.trackers.cage.tracker`): Gram–Schmidt
frames of the quads' ``(u, v)`` columns and their derivative, the pelvis update, and the
per-stage wall clock. Shapes as documented; rotations act on column vectors."""

from __future__ import annotations

import time

import numpy as np

from meshmocap.geometry.rotations import cross, so3_exp
from meshmocap.trackers.cage.kernels import gram_schmidt_frames
from meshmocap.trackers.cage.oqr import QUAD_NAMES

#: The limbs (their quads) and the trunk quad (pelvis 0, chest 2) each hangs from.
LIMBS = tuple(
    (QUAD_NAMES.index(b), np.array([QUAD_NAMES.index(f"{side}_{q}") for q in qs]))
    for b, qs in (
        ("chest", ("shoulder", "elbow", "wrist", "hand")),
        ("pelvis", ("hip", "knee", "ankle", "toe")),
    )
    for side in ("left", "right")
)
_DU = np.hstack([np.eye(3), np.zeros((3, 3))]).T.copy()  # the 6 unit directions of (u, v)
_DV = np.hstack([np.zeros((3, 3)), np.eye(3)]).T.copy()


def gram_schmidt_forward(a, b, da, db):
    """Gram–Schmidt ``R = [u v u×v]`` of columns ``a, b`` (Q, 3) and its derivative along
    ``da, db`` (forward mode)."""
    na = np.linalg.norm(a, axis=1, keepdims=True)
    u = a / na
    du = (da - u * np.sum(u * da, axis=1, keepdims=True)) / na
    ub = np.sum(u * b, axis=1, keepdims=True)
    w = b - ub * u
    dw = (
        db
        - (np.sum(du * b, axis=1, keepdims=True) + np.sum(u * db, axis=1, keepdims=True)) * u
        - ub * du
    )
    nw = np.linalg.norm(w, axis=1, keepdims=True)
    v = w / nw
    dv = (dw - v * np.sum(v * dw, axis=1, keepdims=True)) / nw
    n, dn = cross(u, v), cross(du, v) + cross(u, dv)
    return np.stack([u, v, n], axis=2), np.stack([du, dv, dn], axis=2)


def gram_schmidt(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Gram–Schmidt ``R = [u v u×v]`` (Q, 3, 3) of columns ``a, b`` (Q, 3), in a compiled
    loop (:func:`~meshmocap.trackers.cage.kernels.gram_schmidt_frames`: called ~70 times a
    frame on 20 quads; the numbers of :func:`gram_schmidt_reference`)."""
    return gram_schmidt_frames(
        np.ascontiguousarray(a, dtype=np.float64), np.ascontiguousarray(b, dtype=np.float64)
    )


def gram_schmidt_reference(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """:func:`gram_schmidt` as array code (the compiled version's reference in the tests)."""
    R = np.empty((len(a), 3, 3))
    u, v = R[:, :, 0], R[:, :, 1]
    np.divide(a, np.sqrt(np.add.reduce(a * a, axis=1, keepdims=True)), out=u)
    w = b - np.add.reduce(u * b, axis=1, keepdims=True) * u
    np.divide(w, np.sqrt(np.add.reduce(w * w, axis=1, keepdims=True)), out=v)
    R[:, :, 2] = cross(u, v)
    return R


def move_pelvis(s, d):
    """Pelvis transform ``s = (R, c)`` moved by ``d = (ω, dt)`` (world axes, about c)."""
    return so3_exp(d[:3]) @ s[0], s[1] + d[3:]


def orthonormalised(y: np.ndarray) -> np.ndarray:
    """Configuration ``y`` (180,) with each quad's ``u, v`` made orthonormal (Gram–Schmidt;
    the same quads)."""
    Y = y.reshape(-1, 3, 3)
    R = gram_schmidt(Y[:, 1], Y[:, 2])
    return np.stack([Y[:, 0], R[:, :, 0], R[:, :, 1]], axis=1).reshape(-1)


class StageClock:
    """Wall time per stage of :meth:`CageTracker.step`, added to ``totals``; building the
    distance field (``field.seconds``) is booked to ``"distance"``."""

    def __init__(self, totals: dict[str, float]) -> None:
        self.totals, self.t, self.field, self.f0 = totals, time.perf_counter(), None, 0.0

    def lap(self, stage: str) -> None:
        t = time.perf_counter()
        spent = self.field.seconds if self.field is not None else 0.0
        fill, self.f0 = spent - self.f0, spent
        self.totals[stage] += t - self.t - fill
        self.totals["distance"] += fill
        self.t = t


def graft(y: np.ndarray, donor: np.ndarray, base: int, quads: np.ndarray) -> np.ndarray:
    """Configuration ``y`` (180,) with the quads ``quads`` (indices 1…20) taken from
    ``donor`` (180,), carried rigidly from the donor's quad ``base`` onto ``y``'s (0: the
    pelvis, where both are the identity): a limb of one pose hung on another's trunk.
    Both pelvis-relative, ``(c, u, v)`` per quad, orthonormal ``u, v`` expected."""
    Y, D = y.reshape(-1, 3, 3).copy(), donor.reshape(-1, 3, 3)
    k = np.asarray(quads) - 1
    if base == 0:
        Y[k] = D[k]
    else:
        b = base - 1
        M = (
            gram_schmidt(Y[b : b + 1, 1], Y[b : b + 1, 2])[0]
            @ gram_schmidt(D[b : b + 1, 1], D[b : b + 1, 2])[0].T
        )
        Y[k, 0] = (D[k, 0] - D[b, 0]) @ M.T + Y[b, 0]
        Y[k, 1:] = D[k, 1:] @ M.T
    return Y.reshape(-1)


def rig(y, Rp, cp, quad, loc, derivatives=False):
    """The cage (85, 3) at configuration ``y`` (180,) and pelvis transform ``Rp, cp``, the
    quads' pelvis-relative rotations (20, 3, 3) and, with ``derivatives``, ``M`` (85, 3, 9):
    each cage vertex's derivative with respect to the 9 numbers ``(c, u, v)`` of its own
    quad (zero on the pelvis quad). ``quad`` (85,): each vertex's quad (0: the pelvis);
    ``loc`` (85, 3): its position in that quad's frame. Each vertex is bound to one quad
    only (§5.2: "dV/dy follows trivially"), so ``M`` is all of dV/dy."""
    Y = y.reshape(-1, 3, 3)
    if derivatives:  # Gram–Schmidt along the 6 unit directions of (u, v) per quad
        n = len(Y)
        R6, dR = gram_schmidt_forward(
            np.repeat(Y[:, 1], 6, 0),
            np.repeat(Y[:, 2], 6, 0),
            np.tile(_DU, (n, 1)),
            np.tile(_DV, (n, 1)),
        )
        R, dR = R6[::6], dR.reshape(n, 6, 3, 3)
    else:
        R = gram_schmidt(Y[:, 1], Y[:, 2])
    Rw = np.empty((len(R) + 1, 3, 3))  # world quad rotations, the pelvis's first (no
    Rw[0] = Rp  # concatenation with an identity: ~40 calls a frame)
    np.matmul(Rp, R, out=Rw[1:])
    cw = np.concatenate([np.zeros((1, 3)), Y[:, 0]]) @ Rp.T + cp
    cage = np.einsum("vij,vj->vi", Rw[quad], loc) + cw[quad]
    if not derivatives:
        return cage, None, R
    M = np.zeros((len(quad), 3, 9))
    on = quad > 0
    M[on, :, :3] = Rp
    M[on, :, 3:] = np.einsum("ij,vmjk,vk->vim", Rp, dR[quad[on] - 1], loc[on])
    return cage, M, R


def pose_jacobian(P: np.ndarray, g: np.ndarray, cp: np.ndarray) -> np.ndarray:
    """(6, n) Jacobian of the residuals along the pelvis rotation (about its centre ``cp``,
    world axes) and translation (Eq. 11). Green coordinates follow similarities of the cage
    exactly (x' = R x + t), so a rigid motion of the cage moves the points ``P`` rigidly:
    dx = ω × (x − cp) + dt, and dr = g·dx."""
    return np.concatenate([cross(P - cp, g), g], axis=1).T
