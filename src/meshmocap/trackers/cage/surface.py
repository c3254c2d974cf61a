"""The template surface the cage tracker fits: where a quad configuration puts the sampled
template vertices, and the derivatives the tracker's three problems need.

Two models of the same quads (:mod:`meshmocap.trackers.cage.tracker`, option ``surface``):

* :class:`GreenSurface`, the paper's (cage-manifold-tracking Eq. (1)): the cage built from
  the quads deforms the template through 3D Green coordinates;
* :class:`SkinnedSurface` (default): every quad follows a rig joint rigidly (§3), so the
  quads are joint frames, and the template's own linear-blend skinning poses it from them
  (:class:`~meshmocap.trackers.cage.oqr_skinning.QuadSkinning`).

Green coordinates put the sampled vertices centimetres from the skinned body they stand
for, and fitted to visual hulls from the true pose the local adjustment moves the joints
to trade them for surface (figures: ``docs/guide/cage.rst``). Skinning from the quads
reproduces the body exactly on retargeted poses but for the fingers (no quad follows
them: their vertices leave the data term, :attr:`SkinnedSurface.fitted`).

Both give, for a configuration ``y`` (180,), pelvis rotation ``Rp`` and centre ``cp``:
``points`` (n, 3) world positions of the sampled vertices; ``points_batch`` for several
configurations; ``directions`` (k, n, 3): their derivatives along configuration directions
``dy`` (180, k) (the latent step, Eq. (6)); ``quad_rows`` (120, n): the Gauss–Newton rows of
residuals with point gradients ``g`` (n, 3) along each quad's centre and rotation in the
pelvis frame (the local adjustment, Eq. (12)); ``vertices``: every template vertex.
Metres, world frame (Z up).

References
----------
- E. Duveau, S. Courtemanche, L. Reveret, E. Boyer, *Cage-based motion recovery
  using manifold learning*, International Conference on 3D Imaging, Modeling,
  Processing, Visualization and Transmission (3DIMPVT), 2012.
- Y. Lipman, D. Levin, D. Cohen-Or, *Green coordinates*, ACM Transactions on Graphics
  27(3) (SIGGRAPH 2008). https://doi.org/10.1145/1360612.1360677
- N. Magnenat-Thalmann, R. Laperrière, D. Thalmann, *Joint-dependent local
  deformations for hand animation and object grasping*, Graphics Interface, 26–33, 1988.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from meshmocap.body.skinning import apply_skinning, skinning_operator
from meshmocap.body.template import Template
from meshmocap.geometry.green import GreenDeformer
from meshmocap.geometry.rotations import cross, skew
from meshmocap.trackers.cage.kernels import (
    local_normal_equations,
    skinned_directions,
    skinned_points,
)
from meshmocap.trackers.cage.oqr import OQR
from meshmocap.trackers.cage.oqr_skinning import QuadSkinning
from meshmocap.trackers.cage.quad_frames import gram_schmidt, gram_schmidt_forward, rig

__all__ = ["GreenSurface", "SkinnedSurface"]

#: Sampled vertices whose skinning weight on joints that no quad determines (the
#: fingers, which :class:`QuadSkinning` keeps straight) exceeds this leave the data term.
_FREE_WEIGHT = 0.3


class GreenSurface:
    """The template in the cage, through Green coordinates (the paper's model)."""

    kind = "green"

    def __init__(self, oqr: OQR, template: Template, sample: np.ndarray) -> None:
        self.oqr = oqr
        rest = oqr.rest_vertices
        self.deform = GreenDeformer(rest, oqr.faces, template.V[sample])
        self._all: GreenDeformer | None = None
        self._template = template
        self.fitted = np.ones(len(sample), dtype=bool)
        quad = oqr.vertex_quad  # each quad's cage vertices, padded (mask 0 on the padding)
        slots = [np.flatnonzero(quad == k) for k in range(1, quad.max() + 1)]
        width = max(len(v) for v in slots)
        self._slots = np.array([np.resize(v, width) for v in slots])  # (20, width)
        self._slot_mask = np.array([np.arange(width) < len(v) for v in slots], dtype=float)

    def cage(self, y, Rp, cp):
        return rig(y, Rp, cp, self.oqr.vertex_quad, self.oqr.vertex_local)[0]

    def points(self, y, Rp, cp):
        return self.deform.deform(self.cage(y, Rp, cp))

    def points_batch(self, Y, Rp, cp):
        return self.deform.deform(np.stack([self.cage(y, Rp, cp) for y in Y]))

    def vertices(self, y, Rp, cp):
        if self._all is None:
            self._all = GreenDeformer(self.oqr.rest_vertices, self.oqr.faces, self._template.V)
        return self._all.deform(self.cage(y, Rp, cp))

    def directions(self, y, Rp, cp, dy):
        """Eq. (6): (k, n, 3) along configuration directions ``dy`` (180, k)."""
        cage, M, _ = rig(y, Rp, cp, self.oqr.vertex_quad, self.oqr.vertex_local, True)
        quad = self.oqr.vertex_quad
        on = quad > 0
        D = np.zeros((len(quad), 3, dy.shape[1]))
        D[on] = M[on] @ dy.reshape(-1, 9, dy.shape[1])[quad[on] - 1]
        return self.deform.jvp(cage, D.transpose(2, 0, 1))

    def quad_rows(self, y, Rp, cp, G):
        """Eq. (12): (120, s n) for point gradients ``G`` (s, n, 3); each quad vertex moves
        by ``Rp (dc + ω × R_q l)``."""
        cage, _, R = rig(y, Rp, cp, self.oqr.vertex_quad, self.oqr.vertex_local)
        slots = self._slots
        arm = np.einsum("qij,qvj->qvi", R, self.oqr.vertex_local[slots])  # (20, w, 3)
        M6 = np.concatenate([np.broadcast_to(Rp, (*arm.shape[:2], 3, 3)), Rp @ -skew(arm)], 3)
        M6 *= self._slot_mask[..., None, None]
        nq, k = slots.shape
        out = []
        for g in G:
            n = len(g)
            W = self.deform.pointwise_vjp(cage, g).transpose(1, 2, 0)  # (85, 3, n)
            Jq = np.matmul(
                M6.reshape(nq, 3 * k, 6).transpose(0, 2, 1), W[slots].reshape(nq, 3 * k, n)
            )
            out.append(Jq.reshape(6 * nq, n))
        return np.concatenate(out, axis=1)


class SkinnedSurface:
    """The template posed by its own skinning from the quads' joint frames (module notes).

    Derivatives (``directions``, ``quad_rows``) are exact for the vertices skinned only to
    joints that own a quad (``exact``); a vertex weighted on a quad-less joint (hip
    joints, Spine1, Neck1, clavicles) moves, in them, rigidly with the nearest ancestor
    quad, though that joint also turns towards the quads below it: a Gauss–Newton
    approximation (the energies are evaluated exactly, so Levenberg–Marquardt still only
    accepts steps that lower them). On ``neutral_5k`` the approximated directions are within
    a fifth of central differences (tests/trackers/cage/test_derivatives.py).

    Attributes
    ----------
    fitted : (n,) bool
        Sampled vertices the quads place (not finger-dominated).
    exact : (n,) bool
        Sampled vertices skinned only to joints that own a quad.
    """

    kind = "skinned"

    def __init__(self, oqr: OQR, template: Template, sample: np.ndarray) -> None:
        self.oqr, self.template = oqr, template
        self.skin = QuadSkinning(oqr, template)
        W = sp.csr_matrix(template.weights[sample])
        self._S = skinning_operator(template.V[sample], W)
        sk = template.skeleton
        own = np.zeros(sk.n_joints, dtype=bool)
        own[oqr.quads.joint_indices] = True
        free = np.zeros(sk.n_joints, dtype=bool)  # joints that keep their parent's rotation
        for j in range(1, sk.n_joints):
            free[j] = not own[j] and not self._has_quad_below(j, own, sk.parents)
        self.fitted = np.asarray(W[:, free].sum(axis=1)).ravel() <= _FREE_WEIGHT
        self.exact = np.asarray(W[:, ~own].sum(axis=1)).ravel() == 0
        Wc = W.tocoo()
        self._pi, self._pj, self._pw = Wc.row.astype(np.intp), Wc.col.astype(np.intp), Wc.data
        self._pb = self.skin.joint_quad[self._pj]  # the quad each (point, joint) pair moves with
        self._X = np.concatenate([template.V[sample][self._pi], np.ones((len(self._pi), 1))], 1)
        n = len(sample)
        self.n = n
        # the pairs that move with a quad ≥ 1, by point (local_normal_equations)
        on = self._pb > 0
        self._on = on
        self._on_quad = np.ascontiguousarray(self._pb[on] - 1, dtype=np.int64)
        self._on_w = np.ascontiguousarray(self._pw[on], dtype=np.float64)
        self._on_ptr = np.searchsorted(self._pi[on], np.arange(n + 1)).astype(np.int64)

    @staticmethod
    def _has_quad_below(j, own, parents) -> bool:
        stack = [c for c in range(len(parents)) if parents[c] == j]
        while stack:
            c = stack.pop()
            if own[c]:
                return True
            stack += [d for d in range(len(parents)) if parents[d] == c]
        return False

    def frames(self, y, Rp, cp):
        """World quad centres (21, 3) and rotations (21, 3, 3), and the pelvis-relative
        rotations (20, 3, 3)."""
        Y = y.reshape(-1, 3, 3)
        R = gram_schmidt(Y[:, 1], Y[:, 2])
        Rw = np.empty((len(R) + 1, 3, 3))
        Rw[0] = Rp
        np.matmul(Rp, R, out=Rw[1:])
        cw = np.concatenate([np.zeros((1, 3)), Y[:, 0]]) @ Rp.T + cp
        return cw, Rw, R

    def transforms(self, y, Rp, cp):
        cw, Rw, _ = self.frames(y, Rp, cp)
        return self.skin.transforms(cw, Rw), cw

    def points(self, y, Rp, cp):
        S = self._S  # apply_skinning's product, compiled (the same numbers, tens of calls)
        return skinned_points(S.indptr, S.indices, S.data, self.transforms(y, Rp, cp)[0], self.n)

    def points_batch(self, Y, Rp, cp):
        A = np.stack([self.transforms(y, Rp, cp)[0] for y in Y])
        return apply_skinning(self._S, A)

    def vertices(self, y, Rp, cp):
        return apply_skinning(self.template._skinning, self.transforms(y, Rp, cp)[0])

    def _pairs(self, y, Rp, cp):
        """World positions (m, 3) of every (point, joint) pair, ``A_j [x_i; 1]``."""
        A, cw = self.transforms(y, Rp, cp)
        return np.einsum("mab,mb->ma", A[self._pj], self._X), cw

    def directions(self, y, Rp, cp, dy):
        """(k, n, 3) along configuration directions ``dy`` (180, k): each pair moves with
        its quad, ``Rp (dc_b + dR_b l)`` (``l`` its position in the quad's frame)."""
        V, cw = self._pairs(y, Rp, cp)
        Y = y.reshape(-1, 3, 3)
        k = dy.shape[1]
        D = dy.reshape(-1, 3, 3, k)  # (20, (c, a, b), 3, k)
        a = np.repeat(Y[:, 1], k, 0)
        b = np.repeat(Y[:, 2], k, 0)
        R, dR = gram_schmidt_forward(
            a,
            b,
            D[:, 1].transpose(0, 2, 1).reshape(-1, 3),
            D[:, 2].transpose(0, 2, 1).reshape(-1, 3),
        )
        R, dR = R.reshape(-1, k, 3, 3)[:, 0], dR.reshape(-1, k, 3, 3)
        return skinned_directions(  # pair by pair, compiled (equal to rounding)
            np.ascontiguousarray(V),
            np.ascontiguousarray(cw),
            np.ascontiguousarray(Rp, dtype=np.float64),
            np.ascontiguousarray(R),
            np.ascontiguousarray(dR),
            np.ascontiguousarray(D[:, 0].transpose(0, 2, 1)),
            self._pi,
            self._pb,
            self._pw,
            self.n,
        )

    def quad_rows(self, y, Rp, cp, G):
        """(120, s n) for point gradients ``G`` (s, n, 3): pair (i, j) moving with quad
        b ≥ 1 adds ``w_ij [Rpᵀ g_i, Rpᵀ ((v_ij − c_b) × g_i)]`` to the columns of quad b
        (pelvis-frame ``dc``, ``ω``) in row i of each block."""
        V, cw = self._pairs(y, Rp, cp)
        on = self._pb > 0
        i, b, w = self._pi[on], self._pb[on] - 1, self._pw[on]
        arm = V[on] - cw[b + 1]
        s, n = len(G), self.n
        gi = G[:, i]  # (s, m', 3)
        vals = np.concatenate([gi @ Rp, cross(arm, gi) @ Rp], axis=2) * w[:, None]
        rows = (np.arange(s)[:, None] * n + i).ravel()  # (s m',)
        idx = ((6 * np.tile(b, s))[:, None] + np.arange(6)) * (s * n) + rows[:, None]
        return np.bincount(idx.ravel(), vals.reshape(-1, 6).ravel(), minlength=120 * s * n).reshape(
            120, s * n
        )

    def local_normal_equations(self, y, Rp, cp, G, P, r):
        """``Jᵀ r`` (126,) and ``Jᵀ J`` (126, 126) of the local adjustment, ``J`` the rows of
        :meth:`quad_rows` over :func:`~meshmocap.trackers.cage.quad_frames.pose_jacobian`'s
        (the pelvis's 6 columns last), for point gradients ``G`` (s, n, 3) at the points
        ``P`` (n, 3) and residuals ``r`` (s n,): each point row touches the few quads its
        skinning pairs move with, so the products are summed row by row in a compiled loop
        (:func:`~meshmocap.trackers.cage.kernels.local_normal_equations`) instead of over a
        dense (126, s n) ``J`` (equal to rounding)."""
        V, cw = self._pairs(y, Rp, cp)
        arm = V[self._on] - cw[self._on_quad + 1]
        return local_normal_equations(
            np.ascontiguousarray(G, dtype=np.float64),
            np.ascontiguousarray(r, dtype=np.float64),
            np.ascontiguousarray(P, dtype=np.float64),
            np.ascontiguousarray(cp, dtype=np.float64),
            np.ascontiguousarray(Rp, dtype=np.float64),
            self._on_ptr,
            self._on_quad,
            self._on_w,
            np.ascontiguousarray(arm),
            len(self.oqr.quads.centres) - 1,
        )
