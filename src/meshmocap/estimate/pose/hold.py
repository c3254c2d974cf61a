"""The skeleton held by the observed surface: each frame's articulated pose fitted against
the observations, from the pose of the tracker's surface, for 4D captures.

On a clean 4D capture (one closed mesh per frame) a tracker's surface stays on the
observations while its skeleton slides inside it: nearest-point data terms leave motion
along the surface unconstrained, most of all for a cloud of patches, each free to slide as
long as its neighbours follow (``docs/guide/own_4d.rst`` has the measurements).
:class:`SkeletonHold` re-fits the pose every frame, starting from the pose of the
tracker's own surface ``V`` (known correspondences,
:func:`~meshmocap.estimate.pose.fit.pose_of_vertices`), by Gauss–Newton on::

    E(Θ) = E_md + E_dm + μ (1/m) Σ_i |v_i(Θ) − V_i|² + λ Σ_j |log(R_j R̂_jᵀ)|²

where ``E_md``, ``E_dm`` are the mean squared point-to-plane residuals of the closest
compatible pairs both ways between the skinned model points ``v_i(Θ)`` and the observed
points (plus a tenth point-to-point, :func:`~meshmocap.body.articulated.closest_point_system`),
within a reach shrinking over the iterations; the third term an optional pull towards the
tracker's surface (its vertex correspondences; off by default: the tracker's surface is
what slid) and the last a weak pull towards the pose of that surface ``R̂``. The whole
skinned body is one rigid-per-part shape: a part cannot move along the surface without
another leaving it.

The skinned body is the template's own surface, or (``rest``) another rest surface with
the template's weights: the refined surface of the frame before, moved back to the rest
pose by the inverse of each vertex's blended transform
(:meth:`~meshmocap.estimate.pose.hold.SkeletonHold.unposed`).
Far from the template's own pose a skin leaves the body (the template's rig cannot follow
a real performer's muscles and clothes), and fitted against the observations it slides to
make up for it; the frame before's surface, where the refinement anchored each vertex to
its place, is this frame's body one frame of motion away. Its offset from the template's
rest surface is kept at a share ``β`` (:meth:`SkeletonHold.rest_of`): that offset also
holds, the other way round, any slide of the skeleton inside the body on the frame before,
which the next fit, against the surface alone, would carry on unchanged. Before that share
is taken, each part's own translation is taken out of the offset where the part's skin
moved rigidly with it (:func:`rigid_part_translations`): a skeleton slid along a limb
leaves the limb's skin translated as a whole, which the fit would otherwise hold on to,
while a skin hung off a bone that does not follow it (a skirt's cone on the thighs) keeps
its offset.

On a clean 4D capture the driver fits the patch tracker's frame from three starts: the
pose of the patches' surface, the last held pose, and the last held pose fitted first with
the template's own skin (as articulated ICP's step fits it), and keeps the fit of lowest
:meth:`SkeletonHold.cost` (the patches can slide along a loose surface, a skirt, far
enough that a fit started from their pose does not come back). The tracking driver then
moves the tracker onto the held pose (its ``hold`` method: the patch tracker re-places its
patches on the body the hold fitted, skinned in the held pose with each part's own
translation kept, keeping its velocity; articulated ICP takes the pose as its own).

Units: metres and radians, world frame Z up.

References
----------
- P. J. Besl, N. D. McKay, *A method for registration of 3-D shapes*, IEEE
  Transactions on Pattern Analysis and Machine Intelligence 14(2):239–256, 1992.
  https://doi.org/10.1109/34.121791
- Y. Chen, G. Medioni, *Object modelling by registration of multiple range
  images*, Image and Vision Computing 10(3):145–155, 1992.
  https://doi.org/10.1016/0262-8856(92)90066-C
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import scipy.sparse as sp
from pykdtree.kdtree import KDTree

from meshmocap.body.articulated import (
    FIXED_JOINTS,
    articulated_model,
    articulated_step,
    nearest_compatible,
)
from meshmocap.body.articulated_system import (
    closest_point_moments,
    moment_plan,
    normal_equations,
    pair_moments,
    posed_model,
    rotation_error,
)
from meshmocap.body.skeleton import forward_kinematics
from meshmocap.body.skinning import skinning_transforms
from meshmocap.body.template import Template
from meshmocap.errors import FitError, InputError
from meshmocap.estimate.pose.fit import pose_of_vertices
from meshmocap.geometry.mesh import vertex_normals

__all__ = ["BETA", "RIGID_REACH", "SkeletonHold", "rigid_part_translations"]

#: The share of the frame before's refined surface's offset from the template kept in the
#: body the hold fits (:meth:`SkeletonHold.rest_of`); chosen on the crane and the two
#: synthetic 4D walks (``docs/guide/own_capture.rst``).
BETA = 0.7

#: Metres: a vertex whose offset from the template lies within this of its parts'
#: translation is taken as moving rigidly with its part (:func:`rigid_part_translations`);
#: chosen on the crane and the two synthetic 4D walks (``docs/guide/own_capture.rst``).
RIGID_REACH = 0.01


def rigid_part_translations(D: np.ndarray, W, *, reach: float) -> np.ndarray:
    """The share of a rest surface's offset that each body part's translation carries, on
    the vertices that moved rigidly with their part.

    ``D`` (n, 3) float64: per vertex, a rest surface's offset from the template's (metres);
    ``W`` (n, J) sparse or dense: the template's skinning weights. The parts'
    translations ``t`` (J, 3) are the least-squares fit of ``D ≈ W t`` (each vertex
    blending its joints' translations by its weights), first over all the vertices, then
    again over those within ``reach`` (metres) of the first fit; the vertices within reach
    of the second are the rigid ones. Returns (n, 3) float64: ``W t`` on the rigid
    vertices, zero on the others (their offset is their own: a loose skin, a skirt)."""
    W = sp.csr_matrix(W, dtype=np.float64)
    D = np.asarray(D, dtype=np.float64)
    if D.shape != (W.shape[0], 3):
        raise InputError(
            f"rigid_part_translations: D must be ({W.shape[0]}, 3) like W's rows, found {D.shape}"
        )
    if not (np.isfinite(reach) and reach > 0):
        raise InputError(f"rigid_part_translations: reach must be > 0, found {reach!r}")
    rigid = np.ones(len(D), dtype=bool)
    for _ in range(2):
        Wr = W[rigid]
        # the normal equations; their least-norm solution (a part with no vertex: t = 0)
        t = np.linalg.lstsq((Wr.T @ Wr).toarray(), Wr.T @ D[rigid], rcond=None)[0]  # (J, 3)
        moved = W @ t
        rigid = np.linalg.norm(D - moved, axis=1) < reach
    return np.where(rigid[:, None], moved, 0.0)


class SkeletonHold:
    """The per-frame pose fit of a tracked template against its observations (module
    docstring).

    Parameters
    ----------
    template : Template
        The tracked template (the driver's light body).
    n_model_points : int
        Template vertices fitted (area-weighted sample).
    max_points : int
        Observed points used at most (an even subsample).
    iterations : int
        Gauss–Newton iterations per frame.
    max_distance : (float, float)
        Metres: pairs farther apart are ignored, from the first value at the first
        iteration shrinking geometrically to the second.
    normal_cos : float
        Pairs need ``n_model · n_data`` above this.
    surface_weight : float
        ``μ``: weight of the pull towards the tracker's surface (against the data terms'
        mean squared residuals).
    lambda_pose : float
        ``λ``: weight of each joint's squared rotation away from the tracker's (m²/rad²).
    surface : bool
        Whether the driver fits the frame before's refined surface where there is one
        (``rest`` of :meth:`fit`), or always the template's own.
    rest_share : float
        ``β`` in [0, 1]: the share of that surface's offset from the template's rest
        surface kept in the body fitted (:meth:`rest_of`).
    rigid_reach : float or None
        Metres: the parts' translations are taken out of that offset on the vertices
        within this of them (:func:`rigid_part_translations`); None keeps the whole offset.

    Attributes
    ----------
    model_ : ArticulatedModel, the fitted points' skinning
    last : (R (J, 3, 3), root (3,)), the last held pose (the driver's; the rest pose at first)
    key : int or None, the frame number of ``last`` where the driver knows it
    """

    def __init__(
        self,
        template: Template,
        *,
        n_model_points: int = 1500,
        max_points: int = 4000,
        iterations: int = 10,
        max_distance: tuple[float, float] = (0.1, 0.02),
        normal_cos: float = 0.3,
        surface_weight: float = 0.0,
        lambda_pose: float = 1e-5,
        surface: bool = True,
        rest_share: float = BETA,
        rigid_reach: float | None = RIGID_REACH,
    ):
        if int(iterations) < 1 or int(n_model_points) < 1 or int(max_points) < 1:
            raise InputError(
                "SkeletonHold: iterations, n_model_points and max_points must be ≥ 1, found "
                f"{iterations}, {n_model_points}, {max_points}"
            )
        for name, v in (("surface_weight", surface_weight), ("lambda_pose", lambda_pose)):
            if not (np.isfinite(v) and v >= 0):
                raise InputError(f"SkeletonHold: {name} must be ≥ 0, found {v!r}")
        if not (np.isfinite(rest_share) and 0.0 <= rest_share <= 1.0):
            raise InputError(f"SkeletonHold: rest_share must be in [0, 1], found {rest_share!r}")
        if rigid_reach is not None and not (np.isfinite(rigid_reach) and rigid_reach > 0):
            raise InputError(
                f"SkeletonHold: rigid_reach must be > 0 or None, found {rigid_reach!r}"
            )
        self.rest_share = float(rest_share)
        self.rigid_reach = None if rigid_reach is None else float(rigid_reach)
        self.template = template
        self.model_ = articulated_model(template, n_points=int(n_model_points), seed=0)
        self.plan_ = moment_plan(self.model_)
        self.max_points = int(max_points)
        self.iterations = int(iterations)
        self.max_distance = (float(max_distance[0]), float(max_distance[1]))
        self.normal_cos = float(normal_cos)
        self.mu, self.lam = float(surface_weight), float(lambda_pose)
        self.surface = bool(surface)
        sk = template.skeleton
        self.free = np.array(
            [j for j, n in enumerate(sk.names) if n not in FIXED_JOINTS], dtype=np.int64
        )
        self.active = np.concatenate(
            [np.arange(3), (3 + 3 * self.free[:, None] + np.arange(3)).ravel()]
        )
        #: the last held pose (R, root), where the next frame's start is searched from
        self.last = (np.tile(np.eye(3), (sk.n_joints, 1, 1)), sk.rest_positions[0].copy())
        #: the frame number of ``last`` (set by the driver; None: not known)
        self.key: int | None = None

    def start(self, V: np.ndarray, R: np.ndarray, root: np.ndarray):
        """The pose (R (J, 3, 3), root (3,)) whose skinning is nearest to the tracker's
        surface ``V`` (n, 3), from ``R``, ``root`` (e.g. the last held pose)."""
        return pose_of_vertices(self.template, V, R, root, model=self.model_)

    def unposed(self, X: np.ndarray, R: np.ndarray, root: np.ndarray) -> np.ndarray:
        """The rest surface (n, 3) float64 that the template's skinning in the pose ``R``
        (J, 3, 3), ``root`` (3,) carries onto the surface ``X`` (n, 3) (the template's
        vertices elsewhere, metres): each vertex moved back by the inverse of its blended
        transform ``Σ_j w_ij A_j``."""
        sk = self.template.skeleton
        G, P = forward_kinematics(sk, np.asarray(R, dtype=np.float64), root)
        A = skinning_transforms(G, P, sk.rest_positions)  # (J, 3, 4)
        B = np.asarray(self.template.weights @ A.reshape(len(A), 12)).reshape(-1, 3, 4)
        X = np.asarray(X, dtype=np.float64)
        return np.linalg.solve(B[:, :, :3], (X - B[:, :, 3])[..., None])[..., 0]

    def rest_of(
        self, X: np.ndarray, R: np.ndarray, root: np.ndarray, *, rigid: bool = True
    ) -> np.ndarray:
        """The rest surface (n, 3) float64 the hold skins for a surface ``X`` (n, 3) held in
        the pose ``R`` (J, 3, 3), ``root`` (3,) (metres): :meth:`unposed`, its offset ``D``
        from the template's rest surface ``V`` less the parts' translations ``T`` on the
        vertices that moved rigidly with their part (:func:`rigid_part_translations`,
        within ``rigid_reach``; none where it is None), kept at the share ``rest_share``
        ``β``::

            rest = V + β (D − T)

        ``D`` holds what the template's rig cannot carry (the performer's clothes and
        muscles), but also, turned the other way, any slide of the skeleton inside the
        body: fitted against the surface alone, that skin is held at the same slid pose on
        the next frame. A part's skin slid as a whole (``T``) is taken out; with ``β`` < 1
        the rest of a slide is forgotten at that rate frame by frame instead of carried
        on. ``rigid=False``: ``T`` is kept (``V + β D``, the body the patches are placed on:
        :func:`~meshmocap.trackers.frame_step.held`)."""
        V0 = self.template.V
        D = self.unposed(X, R, root) - V0
        if rigid and self.rigid_reach is not None:
            D = D - rigid_part_translations(D, self.template.weights, reach=self.rigid_reach)
        return V0 + self.rest_share * D

    def fit(
        self,
        Y: np.ndarray,
        NY: np.ndarray,
        V: np.ndarray,
        R: np.ndarray,
        root: np.ndarray,
        *,
        rest: np.ndarray | None = None,
    ) -> tuple[np.ndarray, np.ndarray]:
        """The held pose.

        Parameters
        ----------
        Y, NY : (p, 3) float64, the frame's observed points (metres) and outward unit normals
        V : (n, 3) float64, the tracker's surface (the template's vertices), metres
        R : (J, 3, 3) float64, ``root`` (3,): the pose of ``V`` (:meth:`start`), where the
            fit starts and which it is pulled towards
        rest : (n, 3) float64, optional
            The rest surface skinned instead of the template's (module docstring; e.g.
            :meth:`unposed` of the frame before's refined surface), metres.

        Returns
        -------
        R : (J, 3, 3) float64, local rotations; root : (3,) float64, metres
        """
        Y, NY = self._observed(Y, NY)
        tree = KDTree(Y)
        sk = self.template.skeleton
        plan = self._plan(rest)
        R_ref = np.array(R, dtype=np.float64)
        R, root = R_ref.copy(), np.array(root, dtype=np.float64)
        target = np.asarray(V, dtype=np.float64)[self.model_.sample]
        m = len(target)
        idx = np.arange(m)
        d0, d1 = self.max_distance
        act, rot = self.active, self.active[3:]
        for it in range(self.iterations):
            d = d0 * (d1 / d0) ** (it / max(self.iterations - 1, 1))
            posed = posed_model(plan, R, root)
            v, nv = posed.v, posed.n
            cand = dict(k=8, max_distance=d, normal_cos=self.normal_cos)
            i1, k1 = nearest_compatible(tree, NY, v, nv, **cand)  # model → data
            k2, i2 = nearest_compatible(KDTree(v), nv, Y, NY, **cand)  # data → model
            if not (len(i1) or len(i2)):
                break
            # closest_point_system's energy as per-model-point moments (they add), both
            # directions weighted alike, and the optional pull towards the tracker's surface
            S, b = closest_point_moments(v, [(i1, k1), (i2, k2)], (1.0, 1.0), Y, NY)
            if self.mu > 0:  # the tracker's surface, correspondences known
                w = np.full(m, self.mu / m)
                S3, b3, _ = pair_moments(v, idx, target, target, w, "point_to_point")
                S, b = S + S3, b + b3
            H, g = normal_equations(plan, posed, S, b)
            e = rotation_error(plan, posed, R, R_ref)  # (J, 3)
            H[rot, rot] += self.lam
            g[rot] += self.lam * e.ravel()[rot - 3]
            try:
                R, root, _ = articulated_step(
                    sk, R, root, H[np.ix_(act, act)], g[act], active=act, G=posed.G
                )
            except FitError:  # a singular system: keep the pose reached
                break
        return R, root

    def cost(
        self,
        Y: np.ndarray,
        NY: np.ndarray,
        R: np.ndarray,
        root: np.ndarray,
        *,
        rest: np.ndarray | None = None,
    ) -> float:
        """How well the pose ``R`` (J, 3, 3), ``root`` (3,) fits the observed points ``Y``
        (p, 3) with outward unit normals ``NY`` (p, 3) (the points :meth:`fit` uses, the
        body ``rest`` as there), m²: the mean squared point-to-plane distance of each
        skinned model point to its nearest compatible observed point plus that of each
        observed point to its nearest compatible model point, within the fit's last reach
        (the reach's square where there is none, and at most that): two fits from
        different starts compared on the same frame."""
        Y, NY = self._observed(Y, NY)
        d = self.max_distance[1]
        posed = posed_model(self._plan(rest), R, root)
        v, nv = posed.v, posed.n
        cand = dict(k=8, max_distance=d, normal_cos=self.normal_cos)
        i1, k1 = nearest_compatible(KDTree(Y), NY, v, nv, **cand)  # model → data
        k2, i2 = nearest_compatible(KDTree(v), nv, Y, NY, **cand)  # data → model
        r1 = np.einsum("ij,ij->i", v[i1] - Y[k1], NY[k1])
        r2 = np.einsum("ij,ij->i", Y[k2] - v[i2], nv[i2])
        c1 = np.minimum(r1**2, d**2).sum() + (len(v) - len(i1)) * d**2
        c2 = np.minimum(r2**2, d**2).sum() + (len(Y) - len(k2)) * d**2
        return float(c1 / len(v) + c2 / max(len(Y), 1))

    def _observed(self, Y: np.ndarray, NY: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The observed points and normals the fit uses (at most ``max_points``, evenly)."""
        Y = np.asarray(Y, dtype=np.float64)
        NY = np.asarray(NY, dtype=np.float64)
        if len(Y) > self.max_points:
            pick = np.linspace(0, len(Y) - 1, self.max_points).astype(np.int64)
            Y, NY = Y[pick], NY[pick]
        return np.ascontiguousarray(Y), NY

    def _plan(self, rest: np.ndarray | None):
        """The model points' moment plan on the template, or the same points and weights on
        another rest surface ``rest`` (n, 3)."""
        if rest is None:
            return self.plan_
        rest = np.asarray(rest, dtype=np.float64)
        pick = self.model_.sample
        N0 = vertex_normals(rest, self.template.F)[pick]
        return moment_plan(replace(self.model_, X=rest[pick], N0=N0))
