"""The template's own skinning driven by an Oriented Quads Rigging configuration.

Every quad follows a rig joint rigidly (cage-manifold-tracking §3, §6.2:
:func:`~meshmocap.trackers.cage.oqr.quads_from_pose` maps ``R_q = G_j R_q⁰``, ``c_q = P_j + G_j
(c_q⁰ − P_j⁰)``), so a quad configuration *is* the global frame of its joint::

    G_j = R_q R_q⁰ᵀ,    P_j = c_q + G_j (P_j⁰ − c_q⁰)

and the template can be posed by its own linear-blend skinning from those frames, exactly
as the skeleton poses it wherever every joint that moves has a quad. The joints without a
quad (the CMU rig's hip joints, Spine1, Neck1, clavicles and fingers) get their frames
from their neighbours (:class:`QuadSkinning`): their position from their parent's frame,
their rotation the one that best carries their rest offsets to the quad joints hanging
below them (Kabsch's orthogonal Procrustes fit for several, the smallest turn from the
parent's frame for one), or their parent's rotation when no quad hangs below (fingers).
On poses whose quad-less joints do not bend on their own (retargeted CMU clips: hip joints
and clavicles keep their rest orientation) this reproduces skinning exactly; where Spine1 or
Neck1 bend on their own in the source, their frames are recovered from the neck, shoulders
and head only approximately (millimetres to a centimetre or two at a vertex; exact at
vertices skinned to quad joints only; figures in ``docs/guide/cage.rst``).

Why: the cage's Green coordinates place the template's surface centimetres from where
skinning puts it in the same pose, so a tracker fitting that surface to a hull trades the
joints for the surface (:mod:`meshmocap.trackers.cage.tracker`).

Frames and units: world frame (Z up), metres.

References
----------
- E. Duveau, S. Courtemanche, L. Reveret, E. Boyer, *Cage-based motion recovery
  using manifold learning*, International Conference on 3D Imaging, Modeling,
  Processing, Visualization and Transmission (3DIMPVT), 2012.
- W. Kabsch, *A solution for the best rotation to relate two sets of vectors*,
  Acta Crystallographica A32(5):922–923, 1976.
  https://doi.org/10.1107/S0567739476001873
- N. Magnenat-Thalmann, R. Laperrière, D. Thalmann, *Joint-dependent local
  deformations for hand animation and object grasping*, Graphics Interface, 26–33, 1988.
"""

from __future__ import annotations

import numpy as np

from meshmocap._tolerances import ANTIPARALLEL, DEGENERATE_AXIS, DIVISOR_FLOOR
from meshmocap.body.template import Template
from meshmocap.errors import InputError
from meshmocap.trackers.cage.kernels import quad_skinning_transforms
from meshmocap.trackers.cage.oqr import OQR

__all__ = ["QuadSkinning"]


def _turn(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Smallest rotations (k, 3, 3) turning directions ``a`` onto ``b`` (k, 3) (Rodrigues;
    antiparallel pairs turn by π about an axis orthogonal to ``a``)."""
    a = a / np.linalg.norm(a, axis=1, keepdims=True)
    b = b / np.linalg.norm(b, axis=1, keepdims=True)
    v = np.cross(a, b)
    c = np.einsum("ij,ij->i", a, b)
    K = np.zeros((len(a), 3, 3))
    K[:, 0, 1], K[:, 0, 2], K[:, 1, 2] = -v[:, 2], v[:, 1], -v[:, 0]
    K -= K.transpose(0, 2, 1)
    f = 1.0 / np.maximum(1.0 + c, DIVISOR_FLOOR)
    R = np.eye(3) + K + (K @ K) * f[:, None, None]
    anti = c < -1 + ANTIPARALLEL
    if anti.any():  # π about any axis orthogonal to a
        o = np.cross(a[anti], [1.0, 0.0, 0.0])
        o = np.where(
            np.linalg.norm(o, axis=1, keepdims=True) < DEGENERATE_AXIS,
            np.cross(a[anti], [0.0, 1.0, 0.0]),
            o,
        )
        o /= np.linalg.norm(o, axis=1, keepdims=True)
        R[anti] = 2 * o[:, :, None] * o[:, None, :] - np.eye(3)
    return R


class QuadSkinning:
    """Joint frames of the template's rig from a quad configuration (module docstring).

    A precomputed solver: built once per template and rigging.

    Parameters
    ----------
    oqr : OQR
        The rigging of ``template``.
    template : Template

    Attributes
    ----------
    joint_quad : (J,) int64
        The quad whose frame each joint follows (its own; for a joint without one, the
        quad of its nearest ancestor that has one: the frame a Gauss–Newton step moves it
        with).
    """

    def __init__(self, oqr: OQR, template: Template) -> None:
        sk = template.skeleton
        J, parents = sk.n_joints, np.asarray(sk.parents)
        jq = np.asarray(oqr.quads.joint_indices)
        if jq.max() >= J or tuple(sk.names[j] for j in jq) != oqr.quads.joints:
            raise InputError(
                f"QuadSkinning: template {template.name!r} does not have the OQR's rig joints"
            )
        own = np.full(J, -1)
        for q in range(len(jq) - 1, -1, -1):  # a joint with two quads follows the first
            own[jq[q]] = q
        if own[0] < 0:
            raise InputError("QuadSkinning: the root joint has no quad")
        bind = own.copy()
        order = np.concatenate(sk.levels)
        for j in order:
            if bind[j] < 0:
                bind[j] = bind[parents[j]]
        self.joint_quad = bind
        self._own = own_j = np.flatnonzero(own >= 0)
        self._own_quad = own_q = own[self._own]
        P0 = sk.rest_positions
        self._P0 = P0
        R0, c0 = oqr.quads.rotations, oqr.quads.centres
        self._R0T = np.swapaxes(R0[self._own_quad], 1, 2)
        self._off = P0[self._own] - c0[self._own_quad]  # P_j⁰ − c_q⁰
        children = [[] for _ in range(J)]
        for j in range(1, J):
            children[parents[j]].append(j)

        def below(j):  # the nearest joints with a quad under j, through quad-less joints
            out = []
            for c in children[j]:
                out += [c] if own[c] >= 0 else below(c)
            return out

        # quad-less joints in parent-first order, each with its targets; grouped by depth
        # among quad-less joints (a group needs only the groups before it)
        depth = np.zeros(J, dtype=int)
        steps: dict[int, list] = {}
        for j in order:
            if own[j] >= 0:
                continue
            depth[j] = depth[parents[j]] + 1 if own[parents[j]] < 0 else 1
            steps.setdefault(depth[j], []).append((j, below(j)))
        self._steps = []
        for d in sorted(steps):
            swing = [(j, t[0]) for j, t in steps[d] if len(t) == 1]
            fit = [(j, t) for j, t in steps[d] if len(t) > 1]
            keep = [j for j, t in steps[d] if not t]
            self._steps.append(
                (
                    np.array([j for j, _ in swing], dtype=np.int64),
                    np.array([k for _, k in swing], dtype=np.int64),
                    fit,
                    np.array(keep, dtype=np.int64),
                )
            )
        self._parents = parents
        # the same steps as rows (joint, kind, target or start of targets) for the kernel
        plan, targets = [], []
        for swing, target, fit, keep in self._steps:
            plan += [(j, 1, t) for j, t in zip(swing, target, strict=True)]
            plan += [(j, 0, -1) for j in keep]
            for j, t in fit:
                plan.append((j, 2, len(targets)))
                targets += [*t, -1]
        self._plan = np.array(plan, dtype=np.int64).reshape(-1, 3)
        self._fit_targets = np.array(targets + [-1], dtype=np.int64)
        self._own_R0T = np.ascontiguousarray(self._R0T)
        self._parents64 = np.asarray(parents, dtype=np.int64)
        self._own64, self._own_quad64 = (np.asarray(a, dtype=np.int64) for a in (own_j, own_q))

    def transforms(self, centres: np.ndarray, rotations: np.ndarray) -> np.ndarray:
        """Skinning transforms ``A_j = [G_j | P_j − G_j P_j⁰]`` (J, 3, 4) of a configuration.

        Parameters
        ----------
        centres : (21, 3) float64
            World quad centres, metres.
        rotations : (21, 3, 3) float64
            World quad orientations (proper rotations).

        Returns
        -------
        (J, 3, 4) float64
            For :func:`~meshmocap.body.skinning.apply_skinning`.
        """
        return quad_skinning_transforms(
            np.ascontiguousarray(centres, dtype=np.float64),
            np.ascontiguousarray(rotations, dtype=np.float64),
            self._P0,
            self._parents64,
            self._own64,
            self._own_quad64,
            self._own_R0T,
            self._off,
            self._plan,
            self._fit_targets,
        )

    def transforms_reference(self, centres: np.ndarray, rotations: np.ndarray) -> np.ndarray:
        """:meth:`transforms` as array expressions (the kernel's reference in the tests)."""
        J, P0, par = len(self._P0), self._P0, self._parents
        G = np.empty((J, 3, 3))
        P = np.empty((J, 3))
        own, q = self._own, self._own_quad
        G[own] = rotations[q] @ self._R0T
        P[own] = centres[q] + np.einsum("kij,kj->ki", G[own], self._off)
        for swing, target, fit, keep in self._steps:
            for idx in (swing, keep, np.array([j for j, _ in fit], dtype=np.int64)):
                if idx.size:  # position from the parent's frame
                    p = par[idx]
                    P[idx] = P[p] + np.einsum("kij,kj->ki", G[p], P0[idx] - P0[p])
            if swing.size:
                Gp = G[par[swing]]
                a = np.einsum("kij,kj->ki", Gp, P0[target] - P0[swing])
                G[swing] = _turn(a, P[target] - P[swing]) @ Gp
            if keep.size:
                G[keep] = G[par[keep]]
            for j, t in fit:  # Kabsch: rest offsets onto the targets' current ones
                H = (P0[t] - P0[j]).T @ (P[t] - P[j])
                U, _, Vt = np.linalg.svd(H)
                d = np.sign(np.linalg.det(Vt.T @ U.T))
                G[j] = Vt.T @ np.diag([1.0, 1.0, d]) @ U.T
        t = P - np.einsum("jab,jb->ja", G, P0)
        return np.concatenate([G, t[:, :, None]], axis=2)
