"""Articulated ICP: the skeleton-based baseline of patch-skeleton-tracking.txt §IV-B.

The paper compares its patch tracker with "a standard articulated ICP approach similar to
[7]": the template is driven by its skeleton through linear-blend skinning, and every
frame alternates closest-point correspondences with a pose update. Here, per frame:

1. warm start from the previous pose, optionally extrapolated at constant velocity
   (``predict``);
2. iterate (at most ``max_iter`` times, until no model point moves more than ``tol``, or
   than ``settle_tol`` where a step turns back; steps that continue the one before
   over-relaxed, ``extrapolate``):

   * pose a fixed subset of ``n_model_points`` template vertices (area-weighted sample) and
     their normals;
   * correspondences with the observed hull points (k-d trees,
     :mod:`meshmocap.geometry.point_tree`): each model point's nearest *compatible* observed
     point (model→data) and, with ``correspondences="both"``, each observed point's nearest
     compatible model point (data→model). Compatible: closer than ``max_distance`` and
     normals agreeing (``n_model · n_data > normal_cos``), the nearest such among
     ``k_neighbours`` candidates; each search starts from the iteration before's pairs;
   * one Levenberg–Marquardt-damped Gauss–Newton step
     (:func:`~meshmocap.body.articulated.articulated_step`, shared by every articulated fit)
     on the pose Θ = (root translation t, a rotation increment ω_j per free joint) for

         ``E(Θ) = E_md + w_dm E_dm + λ_pose Σ_j |log(R_j R̂_jᵀ)|² + λ_root |root − root̂|²``

     where E_md, E_dm are the mean squared residuals (metres²) of the model→data and
     data→model pairs, (R̂, root̂) the previous frame's pose, and the residuals are
     point-to-plane ``n_y · (v_i − y)`` with the observed point's normal (default) or
     point-to-point ``v_i − y``. The regulariser is linearised like the data term: the
     world-frame rotation error ``G_parent log(R_j R̂_jᵀ)`` moves by ω_j to first order.

Joints that motion capture does not animate (:data:`FIXED_JOINTS`) keep their rotation.

Defaults (measured on 40-frame synthetic walks and jogs, 4-camera hulls, see
``tests/trackers/test_articulated_icp.py``): point-to-plane both ways with λ_pose = 1e-3 and no
prediction is the most stable setting; point-to-point lets arms slide into the torso's
hull, model→data alone lets the legs drift into the phantom volume between them, a weak
λ_pose lets the pelvis yaw in its point-to-plane null space, and constant-velocity
prediction overshoots at the motion's jerks (the option is kept for faster motions).

The articulated model (model points, lever arms, increments, correspondences) lives in
:mod:`meshmocap.body.articulated`, which automatic rigging shares.

References
----------
- C.-H. Huang, E. Boyer, S. Ilic, *Robust human body shape and pose tracking*,
  International Conference on 3D Vision (3DV), 2013.
- P. J. Besl, N. D. McKay, *A method for registration of 3-D shapes*, IEEE
  Transactions on Pattern Analysis and Machine Intelligence 14(2):239–256, 1992.
  https://doi.org/10.1109/34.121791
- Y. Chen, G. Medioni, *Object modelling by registration of multiple range
  images*, Image and Vision Computing 10(3):145–155, 1992.
  https://doi.org/10.1016/0262-8856(92)90066-C
"""

from __future__ import annotations

import time
from dataclasses import asdict, dataclass
from numbers import Integral, Real
from typing import ClassVar, Literal, get_args

import numpy as np

from meshmocap._validate import Boolean, Constraint, Interval, Options, Strings, check_options
from meshmocap.body.articulated import (
    FIXED_JOINTS,
    ArticulatedModel,
    Residual,
    apply_increment,
    articulated_model,
    articulated_step,
    limit_step,
)
from meshmocap.body.articulated_system import (
    moment_plan,
    normal_equations,
    pair_moments,
    point_motion,
    posed_model,
    rotation_error,
)
from meshmocap.body.template import Template
from meshmocap.errors import FitError, InputError
from meshmocap.estimate.recovery.observe import frame_points
from meshmocap.geometry.levenberg_marquardt import DAMPING
from meshmocap.geometry.mesh import vertex_normals_at
from meshmocap.geometry.point_tree import PointTree, nearest_agreeing, point_tree
from meshmocap.io.capture import CaptureFrame
from meshmocap.io.results import FrameResult

Correspondences = Literal["model_to_data", "both"]

#: Stages of :attr:`ArticulatedICP.stage_seconds`: reading and sampling the hull with its
#: normals, closest points both ways, assembling the normal equations (posing included),
#: solving and updating the pose, the output (posing the whole template).
STAGES = ("observations", "correspondences", "system", "solve", "output")


@dataclass(frozen=True)
class ICPOptions:
    """Settings of the articulated ICP baseline.

    Parameters
    ----------
    n_model_points : int
        Template vertices used as model points (area-weighted sample, fixed per template).
    max_points : int
        Observed hull vertices sampled per frame.
    correspondences : {"model_to_data", "both"}
        Closest points from the model to the data only, or both ways.
    residual : {"point_to_plane", "point_to_point"}
        Point-to-plane residuals use the observed point's normal.
    data_to_model_weight : float
        Weight ``w_dm`` of the data→model mean squared residual (with ``"both"``).
    max_distance : float
        Pairs farther apart than this (metres) are rejected.
    normal_cos : float
        Pairs need ``n_model · n_data`` above this (in [−1, 1)).
    k_neighbours : int
        Candidates searched for the nearest compatible point.
    max_iter : int
        ICP iterations per frame; ``tol`` (metres): stop when no model point moves more.
    lambda_pose : float
        Weight (m²/rad²) of the squared rotation of every joint away from the previous
        frame's pose.
    lambda_root : float
        Weight (dimensionless) of the squared root displacement from the previous frame's.
    damping : float
        Levenberg–Marquardt λ of the Gauss–Newton steps, relative to the diagonal (the rule
        and its floor: :mod:`meshmocap.geometry.levenberg_marquardt`).
    predict : bool
        Warm-start by constant-velocity extrapolation of the last two poses (else: the last).
    extrapolate : float
        Longest over-relaxed step, as a multiple of the Gauss–Newton step (1: none). Where
        an iteration's step continues the one before (a slow slide along the fit's flat
        directions), it is lengthened towards where the sequence of steps would end
        (:func:`relaxation`). With ``settle_tol``, fewer iterations for as accurate a fit:
        on every ``bench_limbs`` trial (``docs/measurements.rst``, issue 43).
    settle_tol : float
        Also stop (metres) when no model point moves more than this and the step turns
        back against the one before, as an over-relaxed step's next does where it went past
        the end of the slide (0: never; plain steps seldom turn back).
    fixed_joints : tuple of str
        Rig joints whose local rotation is not estimated (kept from the first frame); names
        the template's skeleton lacks are ignored.
    seed : int
        Seed of the model-point sample and of the per-frame observation subsampling.
    """

    n_model_points: int = 1500
    max_points: int = 5000
    correspondences: Correspondences = "both"
    residual: Residual = "point_to_plane"
    data_to_model_weight: float = 1.0
    max_distance: float = 0.1
    normal_cos: float = 0.3
    k_neighbours: int = 8
    max_iter: int = 20
    tol: float = 1e-3
    lambda_pose: float = 1e-3
    lambda_root: float = 1e-4
    damping: float = DAMPING["icp"].lam
    predict: bool = False
    extrapolate: float = 3.0
    settle_tol: float = 2e-3
    fixed_joints: tuple[str, ...] = FIXED_JOINTS
    seed: int = 0

    #: Each option's constraint (checked by ``check_options`` in ``meshmocap._validate``).
    constraints: ClassVar[dict[str, Constraint | tuple]] = {
        "n_model_points": Interval(Integral, 1, None),
        "max_points": Interval(Integral, 1, None),
        "correspondences": Options(get_args(Correspondences)),
        "residual": Options(get_args(Residual)),
        "data_to_model_weight": Interval(Real, 0, None),
        "max_distance": Interval(Real, 0, None, closed="neither"),
        "normal_cos": Interval(Real, -1, 1, closed="left"),
        "k_neighbours": Interval(Integral, 1, None),
        "max_iter": Interval(Integral, 1, None),
        "tol": Interval(Real, 0, None, closed="neither"),
        "lambda_pose": Interval(Real, 0, None),
        "lambda_root": Interval(Real, 0, None),
        "damping": Interval(Real, 0, None),
        "predict": Boolean(),
        "extrapolate": Interval(Real, 1, None),
        "settle_tol": Interval(Real, 0, None),
        "fixed_joints": Strings("joint names"),
        "seed": Interval(Integral, 0, None),
    }

    def __post_init__(self) -> None:
        check_options("ICPOptions", self, self.constraints)
        object.__setattr__(self, "fixed_joints", tuple(self.fixed_joints))


# ---------------------------------------------------------------------- the tracker
class ArticulatedICP:
    """Skeleton-driven articulated ICP tracker (see the module docstring).

    Parameters
    ----------
    options : ICPOptions

    Attributes
    ----------
    stage_seconds : dict of str → float
        Wall time spent in each of :data:`STAGES` over all :meth:`step` calls, seconds.
    n_steps : int
        Number of :meth:`step` calls.
    """

    name = "articulated_icp"

    def __init__(self, options: ICPOptions = ICPOptions()):
        if not isinstance(options, ICPOptions):
            raise InputError(f"ArticulatedICP: options must be ICPOptions, found {options!r}")
        self.opts = options
        self.template: Template | None = None
        self.model: ArticulatedModel | None = None
        self.stage_seconds = dict.fromkeys(STAGES, 0.0)
        self.n_steps = 0

    def _lap(self, stage: str) -> None:
        t = time.perf_counter()
        self.stage_seconds[stage] += t - self._t
        self._t = t

    def options(self) -> dict:
        """JSON-ready settings."""
        return asdict(self.opts)

    # ------------------------------------------------------------------ state
    def setup(self, template: Template) -> None:
        """Sample the model points of ``template`` and precompute their weights."""
        self.template = template
        o = self.opts
        self.model = articulated_model(template, n_points=o.n_model_points, seed=o.seed)
        self.plan = moment_plan(self.model)
        sk = template.skeleton
        free = [j for j, name in enumerate(sk.names) if name not in self.opts.fixed_joints]
        #: estimated parameters: root translation, then the free joints' rotation increments
        self.active = np.concatenate(
            [np.arange(3), (3 + 3 * np.array(free, dtype=np.int64)[:, None] + np.arange(3)).ravel()]
        )

    def init(
        self, template: Template, frame: CaptureFrame, R: np.ndarray, root: np.ndarray
    ) -> FrameResult:
        """Start from local rotations ``R`` (J, 3, 3) and root position ``root`` (3,)."""
        J = template.skeleton.n_joints
        R = np.asarray(R, dtype=np.float64)
        root = np.asarray(root, dtype=np.float64)
        if R.shape != (J, 3, 3) or root.shape != (3,):
            raise InputError(
                f"ArticulatedICP.init: expected R ({J}, 3, 3) and root (3,), "
                f"found {R.shape} and {root.shape}"
            )
        if self.template is not template:
            self.setup(template)
        self.R, self.root = R.copy(), root.copy()
        self.prev = (R.copy(), root.copy())
        return self._result(frame.index, {}, 0)

    def reseat(self, frame: CaptureFrame, R: np.ndarray, root: np.ndarray) -> FrameResult:
        """Continue from the pose ``R`` (J, 3, 3), ``root`` (3,) with no velocity."""
        self.R = np.array(R, dtype=np.float64)
        self.root = np.array(root, dtype=np.float64)
        self.prev = (self.R.copy(), self.root.copy())
        return self._result(frame.index, {}, 0)

    #: Held on 4D captures only where the hold fits the frame before's refined surface (a
    #: clean 4D capture): held with the template's own skin, its pose is such a fit already
    hold_surface_only = True

    def hold(self, frame: CaptureFrame, R: np.ndarray, root: np.ndarray) -> FrameResult:
        """Continue from the pose ``R`` (J, 3, 3), ``root`` (3,) the driver held against
        the observations (:mod:`meshmocap.estimate.pose.hold`; 4D captures), keeping the
        pose before this frame's step for the next prediction."""
        self.R = np.array(R, dtype=np.float64)
        self.root = np.array(root, dtype=np.float64)
        return self._result(frame.index, {}, 0)

    def set_state(self, state: dict[str, np.ndarray]) -> None:
        """Restore the pose (and the previous one, for prediction) saved with a frame."""
        self.R, self.root = state["R"].astype(np.float64), state["root"].astype(np.float64)
        self.prev = (state["R_prev"].astype(np.float64), state["root_prev"].astype(np.float64))

    def _result(self, index: int, energies: dict[str, float], n_iter: int) -> FrameResult:
        posed = self.template.pose(self.R, self.root)
        state = {
            "R": self.R.copy(),
            "root": self.root.copy(),
            "R_prev": self.prev[0].copy(),
            "root_prev": self.prev[1].copy(),
        }
        return FrameResult(
            index=index,
            joints=posed.eval_joints,
            vertices=posed.V,
            energies=energies,
            n_iter=n_iter,
            state=state,
        )

    # ------------------------------------------------------------------ tracking
    def observations(self, frame: CaptureFrame) -> tuple[np.ndarray, np.ndarray]:
        """Observed points (p, 3) and unit normals (p, 3), at most ``max_points`` of the
        frame's hull vertices (seeded per frame, so a resumed run sees the same points)."""
        return self._observations(frame)[:2]

    def _observations(self, frame: CaptureFrame) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """:meth:`observations` and the order (p,) int64 in which to search them: the
        frame's own (a mesh's vertex order, spatially coherent; the sample is random)."""
        o = self.opts
        V, F = frame.hull_mesh
        V = np.asarray(V, dtype=np.float64)
        if F is None:  # a point cloud: its own normals, or estimated (estimate.recovery.observe)
            V, N = frame_points(frame)
        pick = np.arange(len(V))
        if len(V) > o.max_points:
            rng = np.random.default_rng([o.seed, frame.index])
            pick = rng.choice(len(V), o.max_points, replace=False)
        # a mesh: the normals of the sampled vertices only
        N = vertex_normals_at(V, F, pick) if F is not None else N[pick]
        return np.ascontiguousarray(V[pick]), N, np.argsort(pick)

    def step(self, frame: CaptureFrame) -> FrameResult:
        """Fit ``frame`` by articulated ICP (see the module docstring).

        Returns
        -------
        FrameResult
            Evaluation joints (K, 3) and posed template vertices (n, 3), metres, world frame;
            energies at the last linearisation point: ``model_to_data``, ``data_to_model``
            (mean squared residuals, m²), ``pose`` (``Σ_j |log(R_j R̂_jᵀ)|²``, rad²), ``root``
            (m²) and their weighted ``total``; iterations; state ``R`` (J, 3, 3), ``root``
            (3,) and the previous frame's ``R_prev``, ``root_prev``.
        """
        o = self.opts
        sk = self.template.skeleton
        self._t = time.perf_counter()
        self.n_steps += 1
        Y, NY, pick_order = self._observations(frame)
        # the data→model queries in the frame's own order (its search is faster that way)
        order = (pick_order, np.ascontiguousarray(Y[pick_order]), NY[pick_order])
        if len(Y) < 10:
            raise FitError(f"only {len(Y)} observed points")
        last = (self.R.copy(), self.root.copy())
        if o.predict:  # constant velocity: R ← (R R_prevᵀ) R, root ← 2 root − root_prev
            Rp, rp = self.prev
            self.R = self.R @ np.swapaxes(Rp, 1, 2) @ self.R
            self.root = 2 * self.root - rp
        self.prev = last
        R_ref, root_ref = last  # the regulariser pulls towards the previous pose
        data_tree = point_tree(Y, NY)
        # each iteration's pairs, the next one's guesses (the points move little between)
        matches = (None, None)
        self._lap("observations")
        energies: dict[str, float] = {}
        n_iter, scale, last_move = 0, 1.0, None
        while n_iter < o.max_iter:
            n_iter += 1
            posed = posed_model(self.plan, self.R, self.root)
            H, g, energies, matches = self._normal_equations(
                posed, data_tree, Y, NY, R_ref, root_ref, order, matches
            )
            act = self.active
            self._lap("system")
            R0, root0 = self.R, self.root
            self.R, self.root, delta = articulated_step(
                sk,
                self.R,
                self.root,
                H[np.ix_(act, act)],
                g[act],
                active=act,
                damping=o.damping,
                G=posed.G,
            )
            move = point_motion(self.plan, posed, delta)
            self._lap("solve")
            longest = np.max(np.einsum("mc,mc->m", move, move))
            if longest < o.tol * o.tol:
                break
            turned = last_move is not None and np.vdot(move, last_move) < 0.0
            if turned and longest < o.settle_tol**2:
                break
            scale, last_move = relaxation(move, last_move, scale, o.extrapolate)
            if scale > 1.0:  # the step continues the one before: lengthened
                self.R, self.root = apply_increment(
                    sk, R0, root0, limit_step(scale * delta), G=posed.G
                )
        out = self._result(frame.index, energies, n_iter)
        self._lap("output")
        return out

    def _normal_equations(self, posed, data_tree, Y, NY, R_ref, root_ref, order, matches):
        """Gauss–Newton system ``H δ = −g`` at the current pose, the energy terms, and each
        model point's observed point and each observed point's model point (−1: none; the
        last iteration's, ``matches``, the searches' guesses)."""
        o = self.opts
        v, nv = posed.v, posed.n
        cand = dict(k=o.k_neighbours, max_distance=o.max_distance, normal_cos=o.normal_cos)
        to_data = nearest_agreeing(data_tree, v, nv, hint=matches[0], **cand)  # model → data
        i = np.flatnonzero(to_data >= 0)
        parts = [(i, to_data[i], 1.0, "model_to_data")]
        to_model = matches[1]
        if o.correspondences == "both":
            to_model = data_to_model(point_tree(v, nv), *order, hint=matches[1], **cand)
            k2 = np.flatnonzero(to_model >= 0)
            parts.append((to_model[k2], k2, o.data_to_model_weight, "data_to_model"))
        self._lap("correspondences")
        if not any(len(p[0]) for p in parts):
            raise FitError("no compatible correspondences")
        # every pair weighs 1/len of its direction: the mean over pairs, metres² whatever
        # the sampling; both directions summed into per-model-point moments at once
        ii = np.concatenate([p[0] for p in parts])
        kk = np.concatenate([p[1] for p in parts])
        s = np.concatenate([np.full(len(p[0]), p[2] / max(len(p[0]), 1)) for p in parts])
        S, b, r2 = pair_moments(v, ii, Y[kk], NY[kk], s, o.residual)
        H, g = normal_equations(self.plan, posed, S, b)
        energies: dict[str, float] = {}
        total, start = 0.0, 0
        for i, _, weight, key in parts:
            r2_part = r2[start : start + len(i)]
            start += len(i)
            energies[key] = float(r2_part.sum()) / len(i) if len(i) else 0.0
            total += weight * energies[key]
        # regularisers, linearised: world-frame rotation error e_j + ω_j, root error + t
        J = self.template.skeleton.n_joints
        e = rotation_error(self.plan, posed, self.R, R_ref)
        H[np.arange(3, 3 + 3 * J), np.arange(3, 3 + 3 * J)] += o.lambda_pose
        g[3:] += o.lambda_pose * e.ravel()
        H[np.arange(3), np.arange(3)] += o.lambda_root
        g[:3] += o.lambda_root * (self.root - root_ref)
        energies["pose"] = float(np.sum(e * e))
        energies["root"] = float(np.sum((self.root - root_ref) ** 2))
        energies["total"] = (
            total + o.lambda_pose * energies["pose"] + o.lambda_root * energies["root"]
        )
        return H, g, energies, (to_data, to_model)


def relaxation(
    move: np.ndarray, last_move: np.ndarray | None, scale: float, longest: float
) -> tuple[float, np.ndarray]:
    """The length of an iteration's step, as a multiple of its Gauss–Newton step, where
    successive steps shrink geometrically along one direction (an over-relaxation; the
    Aitken extrapolation of that sequence).

    Parameters
    ----------
    move : (m, 3) float64, the model points' motion under this iteration's Gauss–Newton
        step, metres; ``last_move`` the same of the iteration before (None: none)
    scale : float, the multiple the step before was taken at
    longest : float, the largest multiple allowed (≥ 1)

    Returns
    -------
    The multiple (in [1, longest]) and ``move``, the next call's ``last_move``. If the
    steps shrink by ρ each when taken whole, a step taken at ``c`` gives the next
    ``r = 1 − c (1 − ρ)`` times as long; the multiple ``c / (1 − r) = 1 / (1 − ρ)`` goes
    the whole way (the sum of the steps' series).
    """
    if last_move is None or longest <= 1.0:
        return 1.0, move
    d = float(np.vdot(last_move, last_move))
    r = float(np.vdot(move, last_move)) / d if d > 0.0 else 0.0
    if r >= 1.0:
        return longest, move
    return float(np.clip(scale / (1.0 - r), 1.0, longest)), move


def data_to_model(
    tree: PointTree,
    perm: np.ndarray,
    Yo: np.ndarray,
    NYo: np.ndarray,
    *,
    k: int,
    max_distance: float,
    normal_cos: float,
    hint: np.ndarray | None = None,
) -> np.ndarray:
    """Each observed point's nearest agreeing model point
    (:func:`~meshmocap.geometry.point_tree.nearest_agreeing`), the observed points searched
    in another order than their own: the frame's (a mesh's vertex order, spatially
    coherent, which a k-d tree answers faster than the random order of the sample).

    Parameters
    ----------
    tree : PointTree of the model points (m, 3) and their unit normals
    perm : (p,) int64, a permutation of the observed points
    Yo, NYo : (p, 3) float64, the observed points (metres) and unit normals in that order
        (``Y[perm]``, ``NY[perm]``)
    k, max_distance, normal_cos : as for ``nearest_agreeing``
    hint : (p,) int64, optional, a guess of each observed point's model point in their own
        order (−1: none)

    Returns
    -------
    (p,) int64, each observed point's model point in their own order (−1: none), as
    ``nearest_agreeing(tree, Y, NY, ...)`` gives it.
    """
    cand = dict(k=k, max_distance=max_distance, normal_cos=normal_cos)
    found = np.empty(len(perm), dtype=np.int64)
    guess = None if hint is None else hint[perm]
    found[perm] = nearest_agreeing(tree, Yo, NYo, hint=guess, **cand)
    return found
