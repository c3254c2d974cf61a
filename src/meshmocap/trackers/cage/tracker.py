"""The cage tracker of cage-manifold-tracking.txt (Duveau, Boyer et al., 3DIMPVT 2012).

The template sits in a cage built from 21 Oriented Quads (:mod:`meshmocap.trackers.cage.oqr`) and
follows it through 3D Green coordinates (Eq. 1; ``surface="green"``) or, by default, by its
own skinning from the quads' joint frames (:mod:`~meshmocap.trackers.cage.surface`: Green
coordinates put the surface centimetres from the body the quads stand for; the
measurements behind this and the other choices below are in ``docs/guide/cage.rst``). Plausible quad
configurations lie on a GPLVM manifold learned from motion capture (§4; by default from
the bundled CMU pose library, :func:`~meshmocap.trackers.cage.manifold.default_manifold`).
Each frame minimises

    E(x, Γ) = ½ Σ_i w_i d_DF(M_i(x, Γ))² / n  +  λσ · log σ²(x)  [+ λc E_c]        # Eq. (4)–(5)

over the latent point ``x`` (shape, Eq. 6: chain rule through the GPLVM mean, the
quads, the cage and the Green coordinates) and the pelvis transform ``Γ`` (pose, Eq. 11),
alternated (§5.3), then adjusts the quads locally (Eq. 12). Joints follow their quads
rigidly (``joints="quads"``) or the cage through Green coordinates taken on the first
frame (§6.2). ``E_c`` is a silhouette coverage term where the frame has silhouettes, else
the hull's. A frame whose manifold configuration fits far worse than the tracked quads
is off the manifold (``off_manifold``): its adjustment is not pulled back and runs longer,
and the next frame alternates pose and shape once (``off_alternations``): off the manifold
the latent point only proposes the adjustment's start and the limbs grafted from it.

Choices where the paper is silent or ambiguous (each stated where it is coded):

- Eq. (4) sums distance-field values; we sum their squares (signed distance, so points
  inside the hull are pulled out to its surface too, and Gauss–Newton applies), with a
  weight ``w_i = inside_weight`` (default 0.05) on points inside the hull: a visual hull
  contains the body plus phantom volume (on the synthetic captures the true surface lies
  millimetres to centimetres inside it), and pulling every point out
  to the hull inflates the fit and drags quads into phantom volume.
- Eq. (5) as printed subtracts log σ², which would *reward* unlikely poses; we add it,
  penalising latent points where the manifold is uncertain (the paper's stated intent:
  "this variance as a regularization term to ensure that the shape ... is likely"). σ² is
  Eq. (9) plus the manifold's noise variance: Eq. (9) alone vanishes at the training
  points, where log σ² is a bottomless well of rounding noise that traps the latent point.
- Steps are Levenberg–Marquardt on the residuals, each kept only if it lowers the energy
  (a trust region), not plain gradient descent: same energy, far fewer iterations, no
  blow-up where the Gauss–Newton model is poor (a quad seen by few points).
- Each frame the shape steps start from the best (lowest energy) of: the previous latent
  point, the back-constraint's image of the previous frame's adjusted quads, and the
  ``restarts`` training poses nearest to those quads. A walk's two half-cycles can sit far
  apart in the latent space; gradient steps alone cannot jump between them.
- The local adjustment moves each quad by a centre and a rotation (6 numbers) instead of
  the 9 numbers of the configuration vector, 3 of which (the lengths of ``u, v`` and
  their dot product) do not change the quad: free directions Gauss–Newton would wander in.
- The sum runs over ``n_sample`` template vertices drawn by area; those the cage cannot
  place (farther than ``max_model_error`` from their skinned position in the first
  frame's known pose: a head bent inside the neck–head tube, fingers) get ``w_i = 0``; a
  coverage term ``E_c`` makes hull left unexplained cost
  (:mod:`~meshmocap.trackers.cage.energy`, with the measurements behind each) in the pose and
  shape steps and in the choice of the local adjustment's start, not in the adjustment
  itself: quads free of the manifold follow it into the hull's phantom volumes.
- The local adjustment (Eq. 12) tracks: it starts from whichever fits the frame best
  (data and coverage terms) of the manifold's configuration and the previous frame's
  adjusted quads, still and moved on at their last velocity (each with its own pelvis
  fit, Eq. 11); a weak pull (``anchor_weight``) towards the manifold and soft joints
  between consecutive quads (``articulation``) replace the manifold's hold. A manifold
  learned on another subject (CMU 35 for 05's walk or 09's run) sits 0.1 m and more from
  the true quads; held to it, the adjustment restarted from it every frame never got
  there, and a run's feet move 0.1 m a frame. Each limb of the
  manifold's configuration is then tried on that start, hung from its trunk quad, and
  kept if it fits better: an arm lost into the trunk's hull comes back.
- If the first frame's cage folds over itself (Green coordinates taken in it do not give
  the joints back), the joints' coordinates are taken in the rest cage instead.

Cost per frame (template vertices ``N``, ``n_sample`` points ``n``, cage of 85 vertices):
the distance field is evaluated at the grid points the lookups touch, inside compiled
lookups (:class:`~meshmocap.trackers.cage.field.HullDistanceField`), as are the silhouette
term and the quads' skinning (:mod:`~meshmocap.trackers.cage.kernels`); pose Jacobians are the
rigid motion of the points (no cage derivative), the latent shape's come from one batched
:meth:`~meshmocap.geometry.green.GreenDeformer.jvp`, the local adjustment's from each
point's gradient with respect to the cage vertices
(:meth:`~meshmocap.geometry.green.GreenDeformer.pointwise_vjp`) and each quad's own
vertices; the output deforms the N vertices once. ``stage_seconds`` keeps the breakdown.

References
----------
- E. Duveau, S. Courtemanche, L. Reveret, E. Boyer, *Cage-based motion recovery
  using manifold learning*, International Conference on 3D Imaging, Modeling,
  Processing, Visualization and Transmission (3DIMPVT), 2012.
"""

from __future__ import annotations

from dataclasses import asdict

import numpy as np

from meshmocap._tolerances import ROUNDING_SLACK
from meshmocap.body.template import Template
from meshmocap.errors import FormatError, MeshmocapFileNotFoundError
from meshmocap.estimate.recovery.observe import frame_hull
from meshmocap.geometry.green import GreenDeformer
from meshmocap.geometry.levenberg_marquardt import DAMPING, AdaptiveDamping, damped_solve
from meshmocap.geometry.rotations import so3_exp, so3_log
from meshmocap.io.capture import CaptureFrame
from meshmocap.io.results import FrameResult
from meshmocap.models.gplvm import GPLVM
from meshmocap.trackers.cage.body import cage_body
from meshmocap.trackers.cage.energy import assemble, energy_terms, stage_terms, total_energy
from meshmocap.trackers.cage.field import HullDistanceField
from meshmocap.trackers.cage.manifold import learn_manifold
from meshmocap.trackers.cage.options import CageOptions, Joints, Space, manifold_digest
from meshmocap.trackers.cage.oqr import (
    OQR,
    cage_vertices,
    configuration_from_vector,
    configuration_vector,
    quads_from_pose,
)
from meshmocap.trackers.cage.quad_frames import LIMBS as _LIMBS
from meshmocap.trackers.cage.quad_frames import (
    StageClock,
    graft,
    gram_schmidt,
    move_pelvis,
    orthonormalised,
    pose_jacobian,
    rig,
)
from meshmocap.trackers.cage.residuals import (
    Articulation,
    HullCoverage,
    SilhouetteCoverage,
    placement_errors,
    surface_sample,
)
from meshmocap.trackers.cage.surface import GreenSurface, SkinnedSurface
from meshmocap.trackers.cage.terms import FrameData, Iterate, System

__all__ = ["STAGES", "CageOptions", "CageTracker", "Joints", "Space", "learn_manifold"]
#: Stages of :attr:`CageTracker.stage_seconds`.
STAGES = ("distance", "pose", "shape", "local", "output")
_PAD = 0.05  # empty space around the hull in the distance field, metres
_REPRODUCED = 1e-4  # metres: Green coordinates taken in a valid cage give the joints back
_MAX_STEP = 1.0  # no step moves a parameter by more (metres, radians, latent units)
_CONVERGED = 1e-4  # stop when a step promises less than this relative energy decrease
_TINY = 1e-9  # ... or than this (m²: ½ mean r² of a fitted frame is ~3e-5)
_LM_KEYS = (0, 1, 2, None)  # _lm's problems: pose, shape, re-posed starts, local
_SUB = slice(None, None, 4)  # sampled vertices that rank the latent restarts
_JOINT_GAP = 0.005  # metres: soft-joint gaps this small count as closed (Articulation)
_RETRIES = 4  # Levenberg–Marquardt: at most this many λ × 10 retries of a step
#: The floor of the damped solves (:mod:`meshmocap.geometry.levenberg_marquardt`).
_FLOOR = DAMPING["cage"].floor


class CageTracker:
    """Cage-based tracker with a GPLVM pose manifold (see the module docstring).

    Parameters
    ----------
    manifold : GPLVM
        A fitted pose manifold (:func:`learn_manifold`) of the tracking template.
    options : CageOptions, optional
        Default ``CageOptions()``.

    Attributes
    ----------
    stage_seconds : dict of str → float
        Wall time spent in each of :data:`STAGES` over all :meth:`step` calls, seconds
        (lazy distance-field evaluations count as ``"distance"``).
    n_steps : int
        :meth:`step` calls so far.
    """

    name = "cage"

    def __init__(self, manifold: GPLVM, options: CageOptions | None = None):
        self.gp = manifold
        self.opts = options if options is not None else CageOptions()
        self.template: Template | None = None
        self.stage_seconds = dict.fromkeys(STAGES, 0.0)
        self.n_steps = 0

    def options(self) -> dict:
        """JSON-ready settings, with the manifold's latent dimension and its
        :func:`~meshmocap.trackers.cage.options.manifold_digest` (a run resumed with another
        manifold is refused by the driver)."""
        return {
            **asdict(self.opts),
            "n_components": int(self.gp.X_.shape[1]),
            "manifold": manifold_digest(self.gp),
        }

    @property
    def built_on(self) -> str | None:
        """What the cage is built on: ``"template"`` (the performer's own surface) or
        ``"reference"`` (the reference body posed on its skeleton, the template bound to
        its cage; :mod:`~meshmocap.trackers.cage.body`); None before :meth:`setup`."""
        if self.template is None:
            return None
        return "template" if self.body is self.template else "reference"

    def setup(self, template: Template, *, rig: tuple[Template, OQR] | None = None) -> None:
        """Build the rig (on the body of :func:`~meshmocap.trackers.cage.body.cage_body`,
        or ``rig`` when given: that body and its OQR) and bind the template to it."""
        o = self.opts
        self.template = template
        self.body, self.oqr = cage_body(template, body=o.body) if rig is None else rig
        self.sample = surface_sample(template.V, template.F, o.n_sample, seed=o.seed)
        surface = SkinnedSurface if o.surface == "skinned" else GreenSurface
        self.surface = surface(self.oqr, template, self.sample)
        self._set_keep(self.surface.fitted)
        self.terms = energy_terms(o)  # the energy: a list of terms (CageOptions.terms)
        self._stages = {s: stage_terms(self.terms, s) for s in ("pose", "shape", "start", "local")}
        q, sk = self.oqr.quads, self.body.skeleton
        self._articulation = Articulation(
            q.centres, q.rotations, q.joint_indices, sk.rest_positions, sk.parents
        )
        c, R = configuration_from_vector(self.gp.Y_ * self.gp.Y_scale_ + self.gp.Y_mean_)
        self._articulation.calibrate(c, R, _JOINT_GAP)  # pairs the training poses hold
        self.joint_deformer: GreenDeformer | None = None
        # joints="quads": the quad following each evaluation joint's rig joint, and the
        # joint in that quad's frame (constant: quads follow their joints rigidly)
        ev, jq = template.eval_skeleton, self.oqr.quads.joint_indices
        one = [np.flatnonzero(w) for w in ev.weights]
        self._joint_quad = np.array(
            [np.r_[np.flatnonzero(jq == j[0]), -1][0] if len(j) == 1 else -1 for j in one]
        )
        q = np.maximum(self._joint_quad, 0)
        rel = ev.rest_positions - self.oqr.quads.centres[q]
        self._joint_offset = np.einsum("kji,kj->ki", self.oqr.quads.rotations[q], rel)

    # -------------------------------------------------------------- state
    def init(
        self, template: Template, frame: CaptureFrame, R: np.ndarray, root: np.ndarray
    ) -> FrameResult:
        """Start from the quads of a known pose; joints get Green coordinates in its cage
        (§6.2), or in the rest cage when that first cage folds over itself. Sampled
        vertices the cage places more than ``max_model_error`` from their skinned position
        in this pose leave the data term (module notes)."""
        if self.template is not template:
            self.setup(template)
        c, Q = self._place(R, root)
        posed = template.pose(R, root)
        joints = posed.eval_joints
        cage0 = cage_vertices(self.oqr, c, Q)
        model = self.surface.points(configuration_vector(c, Q), Q[0], c[0])
        keep = placement_errors(model, posed.V[self.sample]) <= self.opts.max_model_error
        keep &= self.surface.fitted
        self._set_keep(keep if keep.any() else np.ones_like(keep))
        self._set_joints(cage0, joints)
        if np.abs(self.joint_deformer.deform(cage0) - joints).max() > _REPRODUCED:
            # The first frame's cage folds over itself (e.g. a thigh tube through the pelvis
            # "pants" in a stride): Green coordinates taken in it do not encode the joints
            # (metres off). Take them in the rest cage, which encloses the rest skeleton.
            self._set_joints(self.oqr.rest_vertices.copy(), template.eval_skeleton.rest_positions)
        return self._result(frame.index, {}, 0)

    def reseat(self, frame: CaptureFrame, R: np.ndarray, root: np.ndarray) -> FrameResult:
        """Put the quads at the pose ``R``, ``root`` (a re-initialisation), keeping the
        first frame's cage coordinates of the joints and the data term's vertices."""
        self._place(R, root)
        return self._result(frame.index, {}, 0)

    def _place(self, R: np.ndarray, root: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Quads, pelvis and latent point of a pose, no velocity; returns the quads'
        centres (21, 3) and rotations (21, 3, 3)."""
        c, Q = quads_from_pose(self.oqr, self.body, R, root)
        self.pelvis_R, self.pelvis_c = Q[0].copy(), c[0].copy()
        y = configuration_vector(c, Q)
        self.x = self.gp.transform(y[None])[0]
        self.local = y.copy()  # the quads after local adjustment (relative to the pelvis)
        self._velocity = (np.zeros_like(y), np.zeros(3), np.zeros(3))  # last frame's motion
        self._lam: dict = {}  # Levenberg–Marquardt damping per problem (_lm's key)
        self._off = False  # the last frame was off the manifold (fewer alternations)
        return c, Q

    def _set_keep(self, keep: np.ndarray) -> None:
        """Sampled vertices in the data term (bool, n); their weights √(1 / kept)."""
        self._keep = keep.astype(bool)
        self._data_w = self._keep / np.sqrt(self._keep.sum())

    def _set_joints(self, cage0: np.ndarray, joints0: np.ndarray) -> None:
        self.cage0, self.joints0 = cage0, joints0
        self.joint_deformer = GreenDeformer(cage0, self.oqr.faces, joints0)

    def set_state(self, state: dict[str, np.ndarray]) -> None:
        """Restore latent point, pelvis transform, local quads and their last motion, the
        joints' cage and the vertices in the data term."""
        self.x, self.local = state["x"].copy(), state["local"].copy()
        self._set_keep(state["keep"] if "keep" in state else np.ones(len(self.sample), bool))
        self.pelvis_R, self.pelvis_c = state["pelvis_R"].copy(), state["pelvis_c"].copy()
        self._set_joints(state["cage0"].copy(), state["joints0"].copy())
        lam = state.get("lm_damping", np.full(len(_LM_KEYS), np.nan))
        self._lam = {k: float(v) for k, v in zip(_LM_KEYS, lam, strict=True) if np.isfinite(v)}
        v = [state.get(f"velocity_{k}") for k in "ywc"]
        self._velocity = (
            tuple(a.copy() for a in v)
            if v[0] is not None
            else (np.zeros_like(self.local), np.zeros(3), np.zeros(3))
        )
        self._off = bool(state.get("off_manifold", False))

    def _result(self, index: int, energies: dict[str, float], n_iter: int) -> FrameResult:
        cage = self._rig(self.local, self.pelvis_R, self.pelvis_c)[0]
        joints = self.joint_deformer.deform(cage)
        on = self._joint_quad >= 0
        if self.opts.joints == "quads" and on.any():
            c, R = configuration_from_vector(self.local, self.pelvis_c, self.pelvis_R)
            q = self._joint_quad[on]
            joints[on] = np.einsum("kij,kj->ki", R[q], self._joint_offset[on]) + c[q]
        # "cage": this frame's cage vertices (85, 3), replayed by motion transfer
        state = {
            "x": self.x,
            "local": self.local,
            "pelvis_R": self.pelvis_R,
            "pelvis_c": self.pelvis_c,
            "cage0": self.cage0,
            "joints0": self.joints0,
            "cage": cage,
            "keep": self._keep,
            "velocity_y": self._velocity[0],
            "velocity_w": self._velocity[1],
            "velocity_c": self._velocity[2],
            "lm_damping": np.array([self._lam.get(k, np.nan) for k in _LM_KEYS]),
            "off_manifold": np.array(self._off),
        }
        V = self.surface.vertices(self.local, self.pelvis_R, self.pelvis_c)
        return FrameResult(
            index=index, joints=joints, vertices=V, energies=energies, n_iter=n_iter, state=state
        )

    # -------------------------------------------------------------- the model
    def _rig(self, y, Rp, cp, *, derivatives=False):
        """The cage, quad rotations and dV/dy of
        :func:`~meshmocap.trackers.cage.quad_frames.rig`."""
        return rig(y, Rp, cp, self.oqr.vertex_quad, self.oqr.vertex_local, derivatives)

    def _frame_data(self, frame: CaptureFrame, field: HullDistanceField) -> FrameData:
        """What the terms read this frame: the distance field, the data term's point weights
        and, where the term list has them, the coverage samples: the silhouettes' where the
        frame has cameras and masks and the list a ``"silhouette"`` term, else the hull's
        (``"coverage"``); samples seeded by the frame (the same on a resumed run)."""
        o, on = self.opts, set(self.opts.terms)
        sil = hull = None
        if "silhouette" in on:
            try:
                cams, masks = frame.cameras, frame.silhouettes
            except (MeshmocapFileNotFoundError, FormatError):
                cams, masks = [], None
            if cams and masks and len(masks) == len(cams):
                sil = SilhouetteCoverage(
                    cams,
                    masks,
                    o.n_silhouette,
                    o.silhouette_margin,
                    seed=[o.seed, frame.index, 1],
                    cap=o.silhouette_cap,
                    min_component=o.silhouette_clean,
                )
                sil = sil if len(sil) else None
        if "coverage" in on and sil is None:  # hull surface samples
            B = field.boundary
            pick = np.random.default_rng([o.seed, frame.index]).choice(
                len(B), min(o.n_coverage, len(B)), replace=False
            )
            hull = HullCoverage(B[pick], o.coverage_margin)
        return FrameData(
            field=field,
            point_weights=self._data_w,
            noise=self.gp.Y_scale_**2 / self.gp.beta_,  # the manifold's noise variance
            articulation=self._articulation,
            hull=hull,
            silhouettes=sil,
        )

    def _evaluate(self, stage: str, it: Iterate, n: int) -> tuple[float, System, dict]:
        """The terms of problem ``stage`` at ``it`` over ``n`` parameters: the energy, the
        system of their rows and each term's value by name."""
        terms = self._stages[stage]
        sys = System.empty(n)
        values = assemble(terms, sys, it)
        return total_energy(terms, values), sys, values

    # -------------------------------------------------------------- optimisation
    def _lm(self, state, n_iter, evaluate, linearise, update, key=None):
        """Levenberg–Marquardt on a problem's energy: ``evaluate(state) -> (E, cache)``,
        ``linearise(state, cache) -> (gradient, Gauss–Newton matrix)``, ``update(state, d)
        -> state``; each step solves the damped normal equations by the rule of
        :mod:`meshmocap.geometry.levenberg_marquardt`. A step is kept only if it does not
        raise ``E`` (else λ × 10 and retry, at most ``_RETRIES`` times, then stop: a trust
        region); λ starts where the last call with the same ``key`` left it (÷ 10 at each
        new frame, never below ``damping``: the latent problem's first steps were rejected
        three times a frame from a fresh ``damping``) and ÷ 10 after each kept step
        (:class:`~meshmocap.geometry.levenberg_marquardt.AdaptiveDamping`); steps whose
        quadratic model promises less than ``_CONVERGED`` relative decrease end it. Returns
        the state, its energy and cache, and the number of linearisations.

        Raises
        ------
        FitError
            Singular normal equations even with more damping.
        """
        E, cache = evaluate(state)
        lam, it = AdaptiveDamping(self._lam.get(key, self.opts.damping)), 0
        for _ in range(n_iter):
            g, H = linearise(state, cache)
            it += 1
            kept = None
            for k in range(_RETRIES + 1):
                d = damped_solve(H, g, lam=lam.lam, floor=_FLOOR, what="cage normal equations")
                if k == 0 and -(g @ d + 0.5 * d @ H @ d) <= _CONVERGED * abs(E) + _TINY:
                    break  # the model promises no real decrease: converged
                if np.abs(d).max() < _MAX_STEP:
                    new = update(state, d)
                    E_new, c_new = evaluate(new)
                    if E_new <= E:
                        kept = new, E_new, c_new
                        break
                if not lam.rejected():
                    break
            if kept is None:
                break
            state, E, cache = kept
            lam.accepted()
        self._lam[key] = lam.lam
        return state, E, cache, it

    def _pose_problem(self, fd: FrameData, y):
        """Eq. (11): the pelvis transform ``(R, c)`` with the quads at ``y``. Green
        coordinates follow rigid motions of the cage exactly, so the points are deformed
        once in the pelvis frame and then moved rigidly."""
        P0 = self.surface.points(y, np.eye(3), np.zeros(3))

        def evaluate(s):
            P = P0 @ s[0].T + s[1]
            E, sys, _ = self._evaluate("pose", Iterate(fd, P), 6)
            return E, (sys, P)

        def linearise(s, cache):
            sys, P = cache
            r, g = sys.point_rows()
            J = pose_jacobian(np.tile(P, (len(r) // len(P), 1)), g, s[1])
            return J @ r + sys.grad, J @ J.T + sys.H

        return evaluate, linearise, move_pelvis

    def _shape_problem(self, fd: FrameData):
        """Eq. (5)–(6): the latent point ``x`` (quads at its mean pose), pelvis fixed. The
        variance term (Eq. 5, sign: module notes) sees σ² with the manifold's noise variance:
        Eq. (9) alone vanishes at training points, where its log is a singular well of
        rounding noise (K near singular) trapping the point."""
        q = len(self.x)

        def evaluate(x):
            mean, dmean, var, dvar = self.gp.predict_with_gradient(x)
            P = self.surface.points(mean, self.pelvis_R, self.pelvis_c)
            E, sys, _ = self._evaluate("shape", Iterate(fd, P, var=var, dvar=dvar), q)
            return E, (sys, mean, dmean)

        def linearise(x, cache):
            sys, mean, dmean = cache
            r, g = sys.point_rows()
            dx = self.surface.directions(mean, self.pelvis_R, self.pelvis_c, dmean)  # Eq. (6)
            J = np.einsum("kpa,spa->ksp", dx, g.reshape(-1, *dx.shape[1:])).reshape(len(dx), -1)
            return J @ r + sys.grad, J @ J.T + sys.H

        return evaluate, linearise, lambda x, d: x + d

    def _local_problem(self, fd: FrameData, anchor, *, pull=True, stage="local"):
        """Eq. (12): every quad's centre and orientation (6 numbers: no Gram–Schmidt gauge)
        and the pelvis transform, pulled towards ``anchor`` (orthonormal configuration, the
        ``"anchor"`` term; not when ``pull`` is False: off the manifold) and held together by
        soft joints (the ``"articulation"`` term); ``anchor`` None: free, the quads
        ablation. ``stage="start"``: the point terms that choose the adjustment's start."""
        I0 = np.eye(3)[None]
        n = len(self.local) // 9 * 6 + 6

        def evaluate(s):
            y, Rp, cp = s
            P = self.surface.points(y, Rp, cp)
            quads = None
            if anchor is not None:  # pelvis-relative quads, the pelvis's included
                Y = y.reshape(-1, 3, 3)
                R = gram_schmidt(Y[:, 1], Y[:, 2])  # pelvis-relative quad rotations
                quads = (np.concatenate([np.zeros((1, 3)), Y[:, 0]]), np.concatenate([I0, R]))
            it = Iterate(fd, P, y=y, anchor=anchor if pull else None, quads=quads)
            E, sys, _ = self._evaluate(stage, it, n)
            return E, (sys, P)

        def linearise(s, cache):
            y, Rp, cp = s
            sys, P = cache
            r, g = sys.point_rows()
            G = g.reshape(-1, len(P), 3)  # data rows, then coverage rows
            if self.surface.kind == "skinned":  # the few quads of each row (compiled)
                gJ, H = self.surface.local_normal_equations(y, Rp, cp, G, P, r)
                return gJ + sys.grad, H + sys.H
            J = np.concatenate(
                [
                    self.surface.quad_rows(y, Rp, cp, G),
                    pose_jacobian(np.tile(P, (len(G), 1)), g, cp),
                ]
            )
            return J @ r + sys.grad, J @ J.T + sys.H

        def update(s, d):
            y, Rp, cp = s
            Y = y.reshape(-1, 3, 3)
            dq = d[:-6].reshape(-1, 6)
            R = so3_exp(dq[:, 3:]) @ gram_schmidt(Y[:, 1], Y[:, 2])
            Yn = np.stack([Y[:, 0] + dq[:, :3], R[:, :, 0], R[:, :, 1]], axis=1)
            return (Yn.reshape(-1), *move_pelvis((Rp, cp), d[-6:]))

        return evaluate, linearise, update

    # -------------------------------------------------------------- tracking
    def step(self, frame: CaptureFrame) -> FrameResult:
        """Fit ``frame``: alternate pose and latent shape (§5.3), then adjust the quads
        locally (Eq. 12)."""
        o = self.opts
        clock = StageClock(self.stage_seconds)
        hull = frame_hull(frame)  # a capture's hull, or the solid a mesh or point cloud bounds
        k = 1 + int(np.ceil(_PAD / hull.voxel_size - ROUNDING_SLACK))  # as distance_grid(pad=_PAD)
        stride = max(1, round(o.field_spacing / hull.voxel_size))
        field = clock.field = HullDistanceField(
            hull.occupancy, hull.origin, hull.voxel_size, pad=k, stride=stride
        )
        clock.lap("distance")
        it, anchor, off = 0, None, False
        # LM damping per problem (_LM_KEYS): a tenth of where the last frame left it
        self._lam = {k: max(v / 10.0, o.damping) for k, v in self._lam.items()}
        fd = self._frame_data(frame, field)
        pelvis = (self.pelvis_R, self.pelvis_c)
        previous = (orthonormalised(self.local), *pelvis)  # last frame's adjusted quads
        if o.space == "latent":
            self.x = self._restart(fd)
            for _ in range(o.off_alternations if self._off else o.alternations):
                y = self.gp.predict(self.x[None])[0]
                pelvis, _, _, n = self._lm(pelvis, o.pose_iters, *self._pose_problem(fd, y), key=0)
                self.pelvis_R, self.pelvis_c = pelvis
                it += n
                clock.lap("pose")
                self.x, _, _, n = self._lm(self.x, o.shape_iters, *self._shape_problem(fd), key=1)
                it += n
                clock.lap("shape")
            anchor = orthonormalised(self.gp.predict(self.x[None])[0])
        n_local = (
            o.local_iters
            if o.space == "latent"
            else o.alternations * (o.pose_iters + o.shape_iters)
        )
        state = previous  # or the start that fits best, coverage included (module notes)
        if anchor is not None and not n_local:  # no adjustment (Table 1): the manifold's
            state = (anchor, *pelvis)
        elif anchor is not None:  # the last quads, still and moving on, get a pelvis fit
            starts = [(anchor, *pelvis)]
            dy, dw, dc = self._velocity  # (the pelvis turns by exp(dw): a rotation, exactly)
            for y, R, c in [
                previous,
                (orthonormalised(previous[0] + dy), so3_exp(dw) @ previous[1], previous[2] + dc),
            ][: 1 + bool(np.any(dy))]:
                moved, _, _, n = self._lm((R, c), o.pose_iters, *self._pose_problem(fd, y), key=2)
                starts.append((y, *moved))
                it += n
            fit = self._local_problem(fd, None, stage="start")[0]
            E = [fit(s)[0] for s in starts]
            state, best = starts[int(np.argmin(E))], min(E)
            # off the manifold: its configuration explains the frame far worse than the
            # tracked quads do; then no pull back to it and a wider adjustment
            off = o.off_manifold > 0 and E[0] > o.off_manifold * best
            for base, quads in _LIMBS:  # the manifold's limbs, each tried on that start
                y = graft(state[0], anchor, base, quads)
                e = fit((y, *state[1:]))[0]
                if e < best:
                    state, best = (y, *state[1:]), e
        self._off = off
        if off:
            n_local *= 2
        (self.local, self.pelvis_R, self.pelvis_c), _, cache, n = self._lm(
            state, n_local, *self._local_problem(fd, anchor, pull=not off)
        )
        U, _, Vt = np.linalg.svd(self.pelvis_R)  # no rounding drift from a rotation
        self.pelvis_R = U @ Vt
        self._velocity = (
            self.local - previous[0],
            so3_log(self.pelvis_R @ previous[1].T),
            self.pelvis_c - previous[2],
        )
        it += n
        # the point terms at the final fit: Eq. (4)'s Σ w r² and each coverage term's mean
        # ρ² (m²) where the frame has one
        _, _, values = self._evaluate("start", Iterate(fd, cache[1]), 0)
        var = float(self.gp.predict(self.x[None], return_var=True)[1][0])
        energies = {"distance": 2 * values["distance"], "variance": var, "off_manifold": float(off)}
        for name, cov in (("silhouette", fd.silhouettes), ("coverage", fd.hull)):
            if cov is not None:
                energies[name] = 2 * values[name]
        clock.lap("local")
        out = self._result(frame.index, energies, it)
        clock.lap("output")
        self.n_steps += 1
        return out

    def _restart(self, fd: FrameData) -> np.ndarray:
        """The latent starting point of a frame: the lowest shape energy (the ``"shape"``
        terms on a quarter of the sampled vertices) among the previous latent point, the
        back-constraint's image of the previous frame's quads and the ``restarts`` training
        poses nearest to those quads (module notes)."""
        gp = self.gp
        cands = [self.x, gp.transform(self.local[None])[0]]
        if self.opts.restarts:
            if not hasattr(self, "_train_y"):
                self._train_y = gp.Y_ * gp.Y_scale_ + gp.Y_mean_
            d2 = np.sum((self._train_y - self.local) ** 2, axis=1)
            cands += list(gp.X_[np.argsort(d2)[: self.opts.restarts]])
        X = np.array(cands)
        Y, var = gp.predict(X, return_var=True)
        P = self.surface.points_batch(Y, self.pelvis_R, self.pelvis_c)
        E = [  # a quarter of the points suffices to rank
            self._evaluate("shape", Iterate(fd, p[_SUB], _SUB, var=float(v)), 0)[0]
            for p, v in zip(P, var, strict=True)
        ]
        return X[np.argmin(E)].copy()
