"""Evaluation joints read off a template's surface: a sparse linear regressor ``X = A V``.

A rigged template defines its joints through its skeleton; a tracker that deforms the
template's surface (patches, a cage) can read the joints back off the deformed surface with
a fixed linear map, as body models do (SMPL's joint regressor, Loper et al. 2015). Each
joint is an affine combination of the rest-pose vertices within ``radius`` of it (weights
summing to 1, so the read-out moves with any rigid motion of the surface), fitted by ridge
regression on the template posed by its own rig through the procedural motions, plain and
with random joint rotations added. The installed package alone therefore learns it, for any
template, in a second or two.

With the template's own skinning the read-out is exact to a millimetre (see the tests); on
a tracked surface it inherits the surface's errors.

References
----------
- M. Loper, N. Mahmood, J. Romero, G. Pons-Moll, M. J. Black, *SMPL: a skinned
  multi-person linear model*, ACM Transactions on Graphics 34(6) (SIGGRAPH Asia
  2015). https://doi.org/10.1145/2816795.2818013
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from meshmocap.body.procedural import PROCEDURAL_MOTIONS, procedural_motion
from meshmocap.body.template import Template
from meshmocap.errors import InputError
from meshmocap.geometry.rotations import so3_exp

#: At most this many support vertices per joint (a seeded random subsample beyond it):
#: bounds the ridge systems of dense templates.
MAX_SUPPORT = 400


def training_poses(
    template: Template, *, step: int = 3, noise: float = 0.3, seed: int = 0
) -> tuple[np.ndarray, np.ndarray]:
    """The template posed by its rig through every procedural motion (every ``step``-th
    frame), once as generated and once with every joint turned by a random rotation (axis
    angle ~ N(0, σ² I) per component, σ = ``noise`` radians).

    Returns
    -------
    V : (T, n, 3) float64, posed vertices, metres, world frame (Z up)
    X : (T, K, 3) float64, the evaluation joints of those poses
    """
    rng = np.random.default_rng(seed)
    Vs, Xs = [], []
    for name in PROCEDURAL_MOTIONS:
        motion = procedural_motion(name, template)
        R, root = motion.rotations[::step], motion.root_positions[::step]
        for jitter in (0.0, noise):
            Rj = R if jitter == 0 else so3_exp(rng.normal(0.0, jitter, R.shape[:-1])) @ R
            posed = template.pose(Rj, root)
            Vs.append(posed.V)
            Xs.append(posed.eval_joints)
    return np.concatenate(Vs), np.concatenate(Xs)


def joint_regressor(
    template: Template,
    *,
    radius: float = 0.15,
    ridge: float = 1e-3,
    poses: tuple[np.ndarray, np.ndarray] | None = None,
    seed: int = 0,
) -> sp.csr_matrix:
    """Fit the surface-to-joint regressor of ``template`` (see the module docstring).

    Parameters
    ----------
    template : Template
        ``n`` vertices, ``K`` evaluation joints.
    radius : float
        Support of each joint: rest vertices closer than this, metres (> 0). A joint with
        fewer than 4 vertices that close uses its 4 nearest.
    ridge : float
        Ridge weight (≥ 0) per training pose on the squared coefficients: keeps the
        weights small so that surface noise is not amplified.
    poses : (V, X) or None
        Training poses as :func:`training_poses` returns them (computed when None).
    seed : int
        Seeds the random rotations of the training poses and the support subsample.

    Returns
    -------
    A : (K, n) scipy.sparse.csr_matrix, float64
        ``X = A @ V`` gives the (K, 3) joints of a (n, 3) surface; every row sums to 1.
    """
    if not (np.isscalar(radius) and np.isfinite(radius) and radius > 0):
        raise InputError(
            f"joint_regressor: radius must be a positive float (metres), found {radius!r}"
        )
    if not (np.isscalar(ridge) and np.isfinite(ridge) and ridge >= 0):
        raise InputError(f"joint_regressor: ridge must be a float ≥ 0, found {ridge!r}")
    V, X = training_poses(template, seed=seed) if poses is None else poses
    rng = np.random.default_rng(seed)
    V0, X0 = template.V, template.eval_skeleton.rest_positions
    rows, cols, vals = [], [], []
    for j in range(len(X0)):  # 15 small ridge problems
        dist = np.linalg.norm(V0 - X0[j], axis=1)
        S = np.flatnonzero(dist < radius)
        if len(S) < 4:
            S = np.argsort(dist)[:4]
        if len(S) > MAX_SUPPORT:
            S = np.sort(rng.choice(S, MAX_SUPPORT, replace=False))
        # X_j = mean_S + Σ a_s (V_s − mean_S): affine in V for any a (weights sum to 1)
        mean = V[:, S].mean(axis=1)
        M = (V[:, S] - mean[:, None]).transpose(0, 2, 1).reshape(-1, len(S))  # (3T, |S|)
        b = (X[:, j] - mean).reshape(-1)
        a = np.linalg.solve(M.T @ M + ridge * len(V) * np.eye(len(S)), M.T @ b)
        rows.append(np.full(len(S), j))
        cols.append(S)
        vals.append(a + (1.0 - a.sum()) / len(S))
    A = sp.csr_matrix(
        (np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))),
        shape=(len(X0), len(V0)),
    )
    return A
