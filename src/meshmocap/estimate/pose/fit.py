"""The articulated fit of a template to observed surface points: the Gauss–Newton of
:mod:`meshmocap.body.articulated` (root translation, a world-frame rotation increment per
free joint) on closest points **both ways** with agreeing normals, as
:func:`meshmocap.body.autorig.fit_skeleton` does for closed meshes, but on any points with
normals (visual-hull vertices, a point cloud), with a pull towards a reference pose and the
subject's size fixed (the template is the performer).

Per iteration, for pairs (model point i, observed point y with normal n_y)::

    E(Θ) = mean_md r² + w_dm mean_dm r² + μ (mean_md |v_i − y|² + mean_dm |v_i − y|²)
           + Σ_j λ_j |G_parent(j) log(R_j R_refᵀ_j)|²

with ``r = n_y · (v_i − y)`` (point-to-plane) and μ =
:data:`~meshmocap.body.articulated.POINT_MIX`, the pairs found within a distance shrinking
over the iterations; one Levenberg–Marquardt-damped step
(:func:`~meshmocap.body.articulated.articulated_step`, each joint's rotation clipped to
:data:`~meshmocap.body.articulated.MAX_STEP_ANGLE`). Metres and radians, world frame Z up.

:meth:`PoseFitter.score` is the symmetric closest-point distance a global search ranks candidate
poses by, and :class:`PoseFitter` keeps the observed points, their k-d tree and the model
points across the many fits of a search.

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

from dataclasses import dataclass

import numpy as np
from pykdtree.kdtree import KDTree

from meshmocap.body.articulated import (
    DAMPING,
    FIXED_JOINTS,
    ArticulatedModel,
    add_pose_pull,
    articulated_model,
    articulated_step,
    closest_pairs,
    pose_points,
)
from meshmocap.body.articulated_system import (
    closest_point_moments,
    moment_plan,
    normal_equations,
    pair_moments,
    posed_model,
    rotation_error,
)
from meshmocap.body.template import Template
from meshmocap.errors import FitError
from meshmocap.geometry.camera import Camera
from meshmocap.geometry.distance_field import DistanceGrid
from meshmocap.geometry.levenberg_marquardt import DAMPING as RULES
from meshmocap.geometry.silhouette import silhouette

__all__ = [
    "PoseFit",
    "PoseFitter",
    "pose_of_vertices",
    "silhouette_mismatch",
]

#: Damping of :func:`pose_of_vertices` (known correspondences: a lighter one than the
#: closest-point fits' :data:`~meshmocap.body.articulated.DAMPING`).
VERTEX_DAMPING = RULES["vertex"].lam
#: Distances (metres) beyond which :meth:`PoseFitter.score` counts a point as unexplained.
SCORE_CLIP = 0.15
#: Distance outside the observed solid (metres) beyond which a model point costs no more.
OUTSIDE_CLIP = 0.3


@dataclass(frozen=True, eq=False)
class PoseFit:
    """A pose fitted to observed points.

    Attributes
    ----------
    R : (J, 3, 3) float64, local joint rotations; ``root`` (3,) float64, metres
    score : float, :meth:`PoseFitter.score` of the pose (metres, lower is better)
    label : str, where the search started it (e.g. ``"t_pose@135°"``)
    """

    R: np.ndarray
    root: np.ndarray
    score: float
    label: str = ""


class PoseFitter:
    """Articulated fits of ``template`` to one set of observed points (module docstring).

    Parameters
    ----------
    template : Template
    Y, NY : (p, 3) float64
        Observed points (metres, world frame) and their outward unit normals.
    n_model_points : int
        Template vertices used (area-weighted sample).
    normal_cos : float
        Pairs need ``n_model · n_data`` above this.
    data_to_model_weight : float
        Weight ``w_dm`` of the data→model pairs.
    fixed_joints : tuple of str
        Joints kept at their starting rotation.
    field : DistanceGrid, optional
        Signed distance (metres, negative inside) of the observed solid, e.g. of a visual
        hull: :meth:`score` then measures how far model points stand *outside* it (a hull
        holds phantom volume, so a model point inside it proves nothing).
    seed : int
        Seed of the model-point sample.
    """

    def __init__(
        self,
        template: Template,
        Y: np.ndarray,
        NY: np.ndarray,
        *,
        n_model_points: int = 1000,
        normal_cos: float = 0.3,
        data_to_model_weight: float = 1.0,
        fixed_joints: tuple[str, ...] = FIXED_JOINTS,
        field: DistanceGrid | None = None,
        seed: int = 0,
    ):
        self.template = template
        self.field = field
        self.sk = template.skeleton
        self.Y = np.ascontiguousarray(Y, dtype=np.float64)
        self.NY = np.asarray(NY, dtype=np.float64)
        self.tree = KDTree(self.Y)
        self.model = articulated_model(template, n_points=n_model_points, seed=seed)
        self.plan = moment_plan(self.model)
        self.normal_cos = normal_cos
        self.w_dm = data_to_model_weight
        self.free = np.array(
            [j for j, n in enumerate(self.sk.names) if n not in fixed_joints], dtype=np.int64
        )

    def points(self, R: np.ndarray, root: np.ndarray) -> np.ndarray:
        """The posed model points (m, 3), metres."""
        return pose_points(self.model, R, root, jacobian=False)[0]

    def score(self, R: np.ndarray, root: np.ndarray) -> float:
        """Symmetric RMS distance (metres) between the posed model points and the observed
        points: each observed point's distance to the nearest model point (clipped at
        :data:`SCORE_CLIP`), and each model point's to the nearest observed point (clipped
        likewise) or, given ``field``, how far it stands outside the observed solid
        (clipped at :data:`OUTSIDE_CLIP`). A limb outside the observations and
        observations no limb explains both cost."""
        v = self.points(R, root)
        if self.field is not None:
            d1 = np.clip(self.field(v), 0.0, OUTSIDE_CLIP)
        else:
            d1 = np.minimum(self.tree.query(v, k=1)[0], SCORE_CLIP)
        d2 = np.minimum(KDTree(v).query(self.Y, k=1)[0], SCORE_CLIP)
        return float(np.sqrt(0.5 * (np.mean(d1**2) + np.mean(d2**2))))

    def fit(
        self,
        R: np.ndarray,
        root: np.ndarray,
        *,
        iterations: int = 20,
        max_distance: tuple[float, float] = (0.3, 0.05),
        R_ref: np.ndarray | None = None,
        lambda_pose: float | np.ndarray = 1e-4,
        joints: np.ndarray | None = None,
        move_root: bool = True,
        damping: float = DAMPING,
        label: str = "",
    ) -> PoseFit:
        """Fit the pose from ``(R, root)``.

        Parameters
        ----------
        R : (J, 3, 3) float64, local rotations; ``root`` (3,) float64, metres: the start.
        iterations : int
            Gauss–Newton iterations.
        max_distance : (float, float)
            Pairs farther apart are ignored, metres: the first value at the first
            iteration, shrinking geometrically to the second at the last.
        R_ref : (J, 3, 3) float64, optional
            Rotations the pose is pulled towards (default: the start ``R``).
        lambda_pose : float or (J,) float64
            Weight (m²/rad²) of each joint's squared rotation away from ``R_ref`` (the
            root's turn included when it is given per joint; a scalar leaves the root free).
        joints : (k,) int64, optional
            The joints whose rotation is estimated (default: every joint not fixed).
        move_root : bool
            Estimate the root translation.
        damping : float
            Levenberg–Marquardt damping (relative to the diagonal).
        label : str
            Stored in the result.
        """
        J = self.sk.n_joints
        R = np.array(R, dtype=np.float64)
        root = np.array(root, dtype=np.float64)
        R_ref = R.copy() if R_ref is None else np.asarray(R_ref, dtype=np.float64)
        lam = np.broadcast_to(np.asarray(lambda_pose, dtype=np.float64), (J,)).copy()
        if np.ndim(lambda_pose) == 0:
            lam[0] = 0.0
        free = self.free if joints is None else np.intersect1d(joints, self.free)
        # the estimated parameters: the root's translation (if it moves), the free rotations
        rot = (3 + 3 * free[:, None] + np.arange(3)).ravel()
        active = np.concatenate([np.arange(3), rot]) if move_root else rot
        d0, d1 = max_distance
        for it in range(iterations):
            d = d0 * (d1 / d0) ** (it / max(iterations - 1, 1))
            system = self._system(R, root, d, R_ref, lam, free, move_root)
            if system is None:  # no pair left
                break
            H, g, G = system
            try:
                R, root, _ = articulated_step(
                    self.sk, R, root, H, g, active=active, damping=damping, G=G
                )
            except FitError:  # a singular system: keep the pose reached
                break
        return PoseFit(R, root, self.score(R, root), label)

    def _system(self, R, root, max_distance, R_ref, lam, joints, move_root):
        """The Gauss–Newton system (H, g) of the root (if ``move_root``) and the rotations of
        ``joints``, or None without any pair. Only the model points those move, and their
        pairs, enter (the others' residuals do not change). Assembled from per-point
        moments (:mod:`~meshmocap.body.articulated_system`, compiled): the same system as
        the dense Jacobian's of :func:`~meshmocap.body.articulated.closest_point_system`,
        to rounding."""
        posed = posed_model(self.plan, R, root)
        moving = None if move_root else self.model.W_acc[:, joints].sum(1) > 0
        pairs = closest_pairs(
            self.tree,
            self.Y,
            self.NY,
            posed.v,
            posed.n,
            max_distance=max_distance,
            normal_cos=self.normal_cos,
            moving=moving,
        )
        if not any(len(i) for i, _ in pairs):
            return None
        S, b = closest_point_moments(posed.v, pairs, (1.0, self.w_dm), self.Y, self.NY)
        H, g = normal_equations(self.plan, posed, S, b)
        # the pull towards the reference pose, linearised in world-frame rotation errors, on
        # the estimated rotations only; then the estimated parameters: the root's
        # translation (if it moves), the rotations of ``joints``
        pull = np.zeros_like(lam)
        pull[joints] = lam[joints]
        add_pose_pull(H, g, rotation_error(self.plan, posed, R, R_ref), pull)
        rot = (3 + 3 * joints[:, None] + np.arange(3)).ravel()
        cols = np.concatenate([np.arange(3), rot]) if move_root else rot
        return H[np.ix_(cols, cols)], g[cols], posed.G


def silhouette_mismatch(
    V: np.ndarray, F: np.ndarray, cameras: list[Camera], masks: list[np.ndarray]
) -> float:
    """Mean over cameras of the pixels where the mesh's silhouette and the observed one
    disagree, as a fraction of the observed silhouette's pixels (0: identical).

    Parameters
    ----------
    V : (n, 3) float64, metres, world frame; ``F`` (m, 3) int, a closed mesh
    cameras : list of Camera; ``masks`` : list of (height, width) bool, one per camera
    """
    err = []
    for cam, mask in zip(cameras, masks, strict=True):
        model = silhouette(V, F, cam, assume_closed=True)
        err.append(np.count_nonzero(model ^ mask) / max(np.count_nonzero(mask), 1))
    return float(np.mean(err)) if err else 0.0


def pose_of_vertices(
    template: Template,
    V: np.ndarray,
    R: np.ndarray,
    root: np.ndarray,
    *,
    iterations: int = 6,
    n_points: int = 600,
    fixed_joints: tuple[str, ...] = FIXED_JOINTS,
    tol: float = 1e-4,
    model: ArticulatedModel | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """The template pose whose skinned vertices are nearest to ``V`` (the template's own
    vertices, e.g. a tracker's output, in any deformation): Gauss–Newton on the
    point-to-point residuals of ``n_points`` vertices, with the correspondences known.

    Parameters
    ----------
    V : (n, 3) float64, the template's vertices, metres, world frame
    R : (J, 3, 3) float64, ``root`` (3,) float64: the starting pose (e.g. the last one)
    iterations : int
        At most this many steps.
    tol : float
        Stop once a step moves the root by less than this (metres) and turns no joint by
        more than this (radians): warm-started from the last frame's pose, the fit has
        converged after a few steps.
    model : ArticulatedModel, optional
        ``articulated_model(template, n_points=n_points, seed=0)``, where the caller keeps
        it (a fit on every frame: building it costs as much as a step).

    Returns
    -------
    R : (J, 3, 3) float64, local rotations; root : (3,) float64, metres
    """
    if model is None:
        model = articulated_model(template, n_points=n_points, seed=0)
    plan = moment_plan(model)
    sk = template.skeleton
    target = np.ascontiguousarray(np.asarray(V, dtype=np.float64)[model.sample])
    free = [j for j, n in enumerate(sk.names) if n not in fixed_joints]
    act = np.concatenate([np.arange(3), (3 + 3 * np.array(free)[:, None] + np.arange(3)).ravel()])
    R, root = np.array(R, dtype=np.float64), np.array(root, dtype=np.float64)
    i = np.arange(len(model.sample))
    ones = np.ones(len(i))
    for _ in range(iterations):
        # Σ JᵀJ and Σ Jᵀr of the point-to-point residuals v_i − V_i from per-point moments
        # (:mod:`~meshmocap.body.articulated_system`): the dense Jacobian's, to rounding
        posed = posed_model(plan, R, root)
        S, b, _ = pair_moments(posed.v, i, target, target, ones, "point_to_point")
        H, g = normal_equations(plan, posed, S, b)
        try:
            R, root, delta = articulated_step(
                sk,
                R,
                root,
                H[np.ix_(act, act)],
                g[act],
                active=act,
                damping=VERTEX_DAMPING,
                G=posed.G,
            )
        except FitError:  # a singular system: keep the pose reached
            break
        if np.abs(delta).max() < tol:
            break
    return R, root
