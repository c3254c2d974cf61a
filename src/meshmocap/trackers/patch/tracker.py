"""The patch tracker of patch-skeleton-tracking.txt (Huang, Boyer, Ilic, 3DV 2013).

Per frame: a body-part classifier trained on the previous fitted mesh sorts the observed
points into on-bone, near-joint and outlier points (§III-B, Eq. 4–6); an EM loop then
alternates soft assignments of the kept points to patches plus an outlier class (E-step,
correspondences by distance and normal compatibility) with one Gauss–Newton step on every
patch rotation/centre and joint position of

    E(Θ, J) = λr Er(Θ) + λd Edata(Θ) + λb Ebone(Θ, J)                              # Eq. (1)

(M-step; :mod:`meshmocap.trackers.patch.solver`), warm-started from the previous frame.
Each term is normalised by its total weight, so the λs weigh mean squared residuals
(metres²) whatever the number of points, patches or vertices.

References
----------
- C.-H. Huang, E. Boyer, S. Ilic, *Robust human body shape and pose tracking*,
  International Conference on 3D Vision (3DV), 2013.
"""

from __future__ import annotations

import time
from dataclasses import replace

import numpy as np
from pykdtree.kdtree import KDTree

from meshmocap._tolerances import NORM_FLOOR
from meshmocap.body.articulated import MAX_STEP_ANGLE
from meshmocap.body.joint_regressor import joint_regressor, training_poses
from meshmocap.body.template import EvalSkeleton, Template
from meshmocap.errors import FitError
from meshmocap.estimate.recovery.observe import frame_points, observed
from meshmocap.geometry.levenberg_marquardt import DAMPING, damped_solve
from meshmocap.geometry.mesh import vertex_normals_at
from meshmocap.geometry.rotations import so3_exp, so3_log
from meshmocap.io.capture import CaptureFrame
from meshmocap.io.results import FrameResult
from meshmocap.models.bodyparts import ON_BONE, BodyPartClassifier, partition
from meshmocap.trackers.patch.energy import assemble, energy_terms, total_energy
from meshmocap.trackers.patch.kernels import assign_kernel, patch_points
from meshmocap.trackers.patch.model import (
    PatchModel,
    build_patch_model,
    fit_patches,
    rebind_bones,
    skeleton_floor,
)
from meshmocap.trackers.patch.nearest import NearestVertices, k_nearest, morton_codes
from meshmocap.trackers.patch.options import PatchOptions
from meshmocap.trackers.patch.solver import (
    System,
    group_basis,
    length_residuals,
    normal_pattern,
    rigidity_moments,
)
from meshmocap.trackers.patch.terms import Correspondences, FrameData, Iterate

#: Divergence guards (metres): no joint moves this far in one frame (10 m/s at 60 fps) ...
MAX_JOINT_JUMP = 0.5
#: ... and the patch centres' mean stays this close to the observed points' mean.
MAX_CENTRE_OFFSET = 0.3
#: Largest predicted displacement (metres) and rotation (radians) of a patch or joint.
MAX_PREDICTION = 0.06
MAX_PREDICTION_ANGLE = 0.3
#: Largest predicted displacement (metres) of a joint when patches follow their bones
#: (above a running foot's step per frame at 60 fps).
MAX_BONE_PREDICTION = 0.15
#: ``accel_gate``: a joint's velocity change beyond this multiple of its last speed (and
#: beyond ``accel_gate``) stops its extrapolation.
GATE_RATIO = 0.5
#: Frame rate assumed where a capture states none (``accel_gate``).
DEFAULT_FPS = 60.0
#: Stages of :attr:`PatchTracker.stage_seconds`: reading and subsampling the hull, body-part
#: classification (training and prediction), E-steps, building the normal equations,
#: solving them, and the output mesh with the frame's result.
STAGES = ("observations", "classify", "assign", "system", "solve", "output")
#: The damped solve of ``_held_lengths``: none (its system is positive definite).
UNDAMPED = DAMPING["none"]
#: Joint pairs of the evaluation skeleton held at their first-frame distance by the length
#: prior besides the bones: the pelvis and the shoulder girdle move as rigid triangles.
RIGID_PAIRS = (("left_hip", "right_hip"), ("left_shoulder", "right_shoulder"))
#: Horizontal offset (metres) between model and data beyond which a frame starts re-centred.
REACQUIRE_OFFSET = 0.15
#: Typical error (metres) of joints read off a tracked surface by the joint regressor
#: (measured: ``docs/patch.rst``); sets how much of each joint ``joint_readout="blend"``
#: takes from the surface (see PatchOptions).
SURFACE_JOINT_ERROR = 0.01
#: Every k-th training pose enters the skeleton's floor (skeleton_floor).
FLOOR_POSE_STEP = 4
#: Candidate vertices kept per observed point beyond ``k_neighbours``, re-ranked in later
#: iterations of a frame instead of a new k-d query (:mod:`~meshmocap.trackers.patch.nearest`).
NEAREST_SPARE = 8
#: Template vertices (every k-th) pulled to their nearest observed point by the reverse term.
REVERSE_SAMPLES = 2000
#: Depth (metres) inside the model below which a hull point is not yet suspect
#: (``interior_scale``): hull boundaries eroded by silhouette jitter, a model a little fat.
INTERIOR_MARGIN = 0.01
#: Template vertices (every k-th) whose projections must cover the silhouettes.
COVERAGE_SAMPLES = 6000


class PatchTracker:
    """Patch-based shape and skeleton tracker (see the module docstring).

    Parameters
    ----------
    options : PatchOptions

    Attributes
    ----------
    stage_seconds : dict of str → float
        Wall time spent in each of :data:`STAGES` over all :meth:`step` calls, seconds.
    n_steps : int
        Number of :meth:`step` calls.
    """

    name = "patch"

    def __init__(self, options: PatchOptions = PatchOptions()):
        self.opts = options
        self.model: PatchModel | None = None
        self.template: Template | None = None
        self.stage_seconds = dict.fromkeys(STAGES, 0.0)
        self.n_steps = 0
        self.logits: tuple[np.ndarray, np.ndarray] | None = None  # last classifier's logits

    def _lap(self, stage: str) -> None:
        t = time.perf_counter()
        self.stage_seconds[stage] += t - self._t
        self._t = t

    def options(self) -> dict:
        """JSON-ready settings."""
        from dataclasses import asdict

        return asdict(self.opts)

    # ------------------------------------------------------------------ state
    def setup(self, template: Template) -> None:
        """Cut ``template`` into patches and precompute the solver's constant parts."""
        o = self.opts
        self.template = template
        self.terms = energy_terms(o)
        self.model = build_patch_model(
            template, n_patches=o.n_patches, joint_rigidity=o.joint_rigidity, seed=o.seed
        )
        self.moments = rigidity_moments(self.model)
        m = self.model
        self.vertex_patch = m.labels.astype(np.int64)
        self.vertex_key = morton_codes(m.V0)  # each patch's vertices in compact chunks
        self.rest_offsets = np.ascontiguousarray(m.V0 - m.centres0[m.labels])  # v0 − c0_k
        self.pairs = _held_pairs(template.eval_skeleton)
        self.train_faces, self.train_bary, self.train_class = surface_training_sample(
            template.V, template.F, m.vertex_class, seed=o.seed
        )
        self.pattern = normal_pattern(self.model, len(template.eval_skeleton.names))
        n = len(self.model.V0)
        self.reverse_sample = np.arange(0, n, max(1, n // REVERSE_SAMPLES))
        # coverage vertices and the radius each covers: 1.5 × their median spacing at rest
        self.cover_sample = np.arange(0, n, max(1, n // COVERAGE_SAMPLES))
        d, _ = KDTree(self.model.V0[self.cover_sample]).query(self.model.V0[self.cover_sample], k=2)
        self.cover_radius = 1.5 * float(np.median(d[:, 1]))
        # Joint read-out (joint_readout): share of each reported joint taken from the surface
        self.regressor = None
        self.surface_weight = np.zeros(len(template.eval_skeleton.names))
        if o.joint_readout != "skeleton":
            V, X = training_poses(template, seed=o.seed)
            self.regressor = joint_regressor(template, poses=(V, X), seed=o.seed)
            self.surface_weight = np.ones(len(template.eval_skeleton.names))
            if o.joint_readout == "blend":
                f2 = skeleton_floor(self.model, V[::FLOOR_POSE_STEP], X[::FLOOR_POSE_STEP]) ** 2
                self.surface_weight = f2 / (f2 + SURFACE_JOINT_ERROR**2)

    def init(
        self, template: Template, frame: CaptureFrame, R: np.ndarray, root: np.ndarray
    ) -> FrameResult:
        """Place the patches on the template posed by ``R``, ``root`` (ground truth)."""
        if self.template is not template:
            self.setup(template)
        self._place(template.pose(R, root))
        self.lengths = _pair_lengths(self.X, self.pairs)
        self.model = rebind_bones(self.model, self.R, self.c, self.X)
        return self._result(frame.index, {}, 0)

    def reseat(self, frame: CaptureFrame, R: np.ndarray, root: np.ndarray) -> FrameResult:
        """Place the patches and joints on the template posed by ``R``, ``root`` (a
        re-initialisation), keeping the first frame's bone binding and lengths."""
        self._place(self.template.pose(R, root))
        return self._result(frame.index, {}, 0)

    def hold(
        self,
        frame: CaptureFrame,
        R: np.ndarray,
        root: np.ndarray,
        *,
        surface: np.ndarray | None = None,
    ) -> FrameResult:
        """Move the patches and joints onto the template posed by ``R``, ``root`` (the pose
        the driver held against the observations, :mod:`meshmocap.estimate.pose.hold`),
        keeping the motion's history (velocity, σ, the classifier's last fit).

        ``surface``: (n, 3) float64, metres, the body the hold fitted in that pose (on a
        clean 4D capture the frame before's refined surface at rest, skinned), which the
        patches are fitted to instead of the template's own skin; the joints stay the
        skeleton's."""
        posed = self.template.pose(R, root)
        self.R, self.c = fit_patches(self.model, posed.V if surface is None else surface)
        self.X = posed.eval_joints.copy()
        return self._result(frame.index, {}, 0)

    def _place(self, posed) -> None:
        """Patches and joints on a posed template; no velocity, a fresh classifier."""
        self.R, self.c = fit_patches(self.model, posed.V)
        self.X = posed.eval_joints.copy()
        self.sigma = self.opts.sigma0
        self.prev = (self.R.copy(), self.c.copy(), self.X.copy())
        self.X_prev2 = self.X.copy()  # joints two frames back (accel_gate)
        self.logits = None

    def set_state(self, state: dict[str, np.ndarray]) -> None:
        """Restore patch transforms, joints and σ saved with a frame."""
        self.R, self.c, self.X = state["R"].copy(), state["c"].copy(), state["X"].copy()
        self.sigma = float(state["sigma"])
        self.lengths = state["lengths"].copy()
        # the last classifier fit, the next fit's starting point (absent in older tracks)
        self.logits = (state["clf_coef"], state["clf_intercept"]) if "clf_coef" in state else None
        self.prev = (state["R_prev"].copy(), state["c_prev"].copy(), state["X_prev"].copy())
        self.X_prev2 = state.get("X_prev2", state["X_prev"]).copy()  # absent in older tracks
        self.model = replace(
            self.model, gamma=state["gamma"], delta0=state["delta0"], bone_w=state["bone_w"]
        )

    def _result(self, index: int, energies: dict[str, float], n_iter: int) -> FrameResult:
        Rp, cp, Xp = self.prev
        state = {
            "R": self.R,
            "c": self.c,
            "X": self.X,
            "sigma": np.float64(self.sigma),
            "R_prev": Rp,
            "c_prev": cp,
            "X_prev": Xp,
            "gamma": self.model.gamma,
            "delta0": self.model.delta0,
            "bone_w": self.model.bone_w,
            "lengths": self.lengths,
            "X_prev2": self.X_prev2,
        }
        if self.logits is not None:
            state["clf_coef"], state["clf_intercept"] = self.logits
        V = self.vertices()
        return FrameResult(
            index=index,
            joints=self.joints(V),
            vertices=V,
            energies=energies,
            n_iter=n_iter,
            state=state,
        )

    def joints(self, V: np.ndarray) -> np.ndarray:
        """The reported joints (K, 3) for the output mesh ``V`` (n, 3): the skeleton's, or
        the surface read-out or its per-joint blend with the skeleton (``joint_readout``),
        moved the least to keep the skeleton's bone lengths (``_held_lengths``)."""
        if self.regressor is None:
            return self.X.copy()
        w = self.surface_weight[:, None]
        # unheld, the read-out lets the spine chord wobble more than it does in truth;
        # holding the lengths also lowers the joint error (docs/patch.rst)
        return _held_lengths(
            (1.0 - w) * self.X + w * (self.regressor @ V), self.pairs, self.lengths
        )

    # ------------------------------------------------------------------ geometry
    def own_vertices(self) -> tuple[np.ndarray, np.ndarray]:
        """Each vertex as predicted by its own patch, and its normal: (n, 3), (n, 3)."""
        m = self.model
        return patch_points(self.R, self.c, self.vertex_patch, self.rest_offsets, m.N0)

    def vertices(self) -> np.ndarray:
        """The output mesh: patch predictions blended over neighbouring patches (n, 3).

        ``Σ_k α_k (R_k (v0 − c0_k) + c_k) = (Σ_k α_k R_k) v0 + Σ_k α_k (c_k − R_k c0_k)``:
        two sparse products with the (n, P) weights instead of one prediction per weight.
        """
        m = self.model
        M = (m.blend @ self.R.reshape(-1, 9)).reshape(-1, 3, 3)
        t = m.blend @ (self.c - np.einsum("kij,kj->ki", self.R, m.centres0))
        return np.einsum("nij,nj->ni", M, m.V0) + t

    # ------------------------------------------------------------------ tracking
    def observations(
        self, frame: CaptureFrame
    ) -> tuple[np.ndarray, np.ndarray, np.random.Generator]:
        """Observed points (hull vertices, subsampled), their normals, and the frame's
        random generator (seeded by frame, so resumed runs repeat exactly)."""
        o = self.opts
        rng = np.random.default_rng([o.seed, frame.index])  # reproducible, also when resumed
        obs = observed(frame)
        F = obs.hull_mesh[1]
        if F is not None and len(F) and len(obs.surface) > o.max_points:
            # a mesh: the normals of the sampled vertices only (the same values)
            V = obs.surface
            pick = rng.choice(len(V), o.max_points, replace=False)
            return V[pick], vertex_normals_at(V, F, pick), rng
        V, N = frame_points(frame)  # a mesh's vertex normals, a point cloud's own or estimated
        if len(V) > o.max_points:
            pick = rng.choice(len(V), o.max_points, replace=False)
            V, N = V[pick], N[pick]
        return V, N, rng

    def classify(self, V: np.ndarray, N: np.ndarray, rng: np.random.Generator):
        """Sort observed points by body part (§III-B, Eq. 4–6); returns the kept points,
        their normals and classes (None without a classifier)."""
        o = self.opts
        if o.classifier == "none":
            return V, N, None
        clf = BodyPartClassifier(o.classifier, random_state=o.seed)
        # trained on the previous fit (§III-B); logistic regression starts from the last
        # frame's solution (same optimum, 3–4 Newton Hessians instead of 12–14)
        coef, intercept = self.logits or (None, None)
        # trained on points spread evenly over the fitted surface, as the observed points
        # are, not on its vertices: a decimated body meshes flat parts (a forearm) sparsely
        V_fit = self.vertices()
        X = np.einsum("nk,nka->na", self.train_bary, V_fit[self.template.F[self.train_faces]])
        clf.fit(X, self.train_class, coef_init=coef, intercept_init=intercept)
        if o.classifier == "logistic":
            self.logits = (clf.coef_, clf.intercept_)
        part = partition(
            clf,
            V,
            on_bone=o.on_bone,
            outlier=o.outlier,
            keep_fraction=o.keep_fraction,
            max_distance=o.max_distance,
            random_state=rng.integers(1 << 31),
        )
        keep = part.keep
        self.last_partition = part  # for diagnostics (benchmarks/diag_patch.py)
        if o.part_matching == "none":
            return V[keep], N[keep], None
        labels = part.labels.copy()
        if o.part_matching == "on_bone":
            labels[part.kind != ON_BONE] = -1  # near-joint points: any patch
        return V[keep], N[keep], labels[keep]

    def frame_data(
        self, Y: np.ndarray, NY: np.ndarray, frame: CaptureFrame | None, X_hat: np.ndarray
    ) -> FrameData:
        """What the energy's terms read over one frame: the kept points ``Y`` (m, 3) and
        their normals ``NY`` (m, 3), the ``frame`` (its cameras and silhouettes; None: no
        cameras) and the joints' prediction ``X_hat`` (K, 3), metres."""
        return FrameData(
            model=self.model,
            moments=self.moments,
            Y=Y,
            NY=NY,
            cameras=list(getattr(frame, "cameras", [])),
            frame=frame,
            X_hat=X_hat,
            pairs=self.pairs,
            lengths=self.lengths,
            reverse_sample=self.reverse_sample,
            cover_sample=self.cover_sample,
            cover_radius=self.cover_radius,
            normal_cos=self.opts.normal_cos,
        )

    def step(self, frame: CaptureFrame) -> FrameResult:
        """Fit ``frame`` by EM + Gauss–Newton (see the module docstring)."""
        o, m = self.opts, self.model
        self._t = time.perf_counter()
        Y, NY, rng = self.observations(frame)
        if len(Y) < 10:
            raise FitError(f"only {len(Y)} observed points")
        last = (self.R.copy(), self.c.copy(), self.X.copy())
        # A fast frame gets more EM iterations: nearest-point correspondences close a gap
        # of several centimetres only a fraction at a time (see ``fast_iter_scale``).
        speed = float(np.linalg.norm(self.X - self.prev[2], axis=1).max())
        fast = speed > o.fast_motion
        budget = round(o.max_iter * (o.fast_iter_scale if fast else 1.0))
        # over-relaxed steps on slow frames only (``relaxation``)
        relaxation = 1.0 if fast else o.relaxation
        budget += o.coarse_iter
        self._warm_start(frame, Y, last)
        X_hat = self.X.copy()  # the temporal prior's prediction (TemporalTerm)
        self._lap("observations")
        Y, NY, ycls = self.classify(Y, NY, rng)
        self._lap("classify")
        if len(Y) < 10:
            raise FitError(f"only {len(Y)} observed points kept by the classifier")
        fd = self.frame_data(Y, NY, frame, X_hat)
        nearest = self.nearest_vertices(Y, spare=NEAREST_SPARE)
        self.sigma = o.sigma0  # EM restarts broad each frame: the new frame moved
        values: dict[str, float] = {}
        n_iter = 0
        while n_iter < budget:
            n_iter += 1
            Vc, Nc = self.own_vertices()
            corr = self.correspondences(Y, NY, ycls, Vc, Nc, nearest=nearest)
            self._lap("assign")
            sys = System.empty(self.pattern)
            it = Iterate(fd, self.R, self.c, self.X, Vc, Nc, corr)
            values = assemble(self.terms, sys, it)
            self._lap("system")
            if n_iter <= o.coarse_iter:  # body parts as rigid groups first (coarse_iter)
                S = group_basis(m.bone_of_patch, self.c, len(self.X))
                delta = sys.solve_grouped(o.damping, S)
            else:
                delta = sys.solve(o.damping)
            self._lap("solve")
            if n_iter > 1:  # over-relaxed after the first step (``relaxation``)
                delta = relaxation * delta
            self._apply(delta)
            # EM update of σ from the weighted residuals (one Gaussian per correspondence)
            self.sigma = float(np.clip(np.sqrt(values["data"] / 3), o.sigma_min, o.sigma_max))
            d = delta[: 6 * m.P].reshape(m.P, 6)  # largest move of a patch, 10 cm lever arm
            move = np.max(np.linalg.norm(d[:, 3:], axis=1) + 0.1 * np.linalg.norm(d[:, :3], axis=1))
            if move < o.tol and n_iter > o.coarse_iter:
                break
        energies = {**values, "sigma": self.sigma, "total": total_energy(self.terms, values)}
        # the last E-step and the kept points, for diagnostics (benchmarks/diag_patch.py)
        self.last_fit = {"Y": Y, "NY": NY, "ycls": ycls, "assign": corr, "frame": fd}
        self._check_divergence(Y, last[2])
        result = self._result(frame.index, energies, n_iter)
        self._lap("output")
        self.n_steps += 1
        return result

    def _warm_start(self, frame: CaptureFrame, Y: np.ndarray, last: tuple) -> None:
        """Start the frame from the last one (``prediction``), re-centred on the observed
        points ``Y`` (m, 3) where the model stands far from them; ``last`` (R, c, X) of
        the last frame becomes the velocity's reference."""
        o = self.opts
        if o.prediction == "bones":
            self._predict_by_bones(
                float(getattr(getattr(frame, "capture", None), "fps", DEFAULT_FPS))
            )
        elif o.prediction == "patches":
            # Constant velocity per patch and joint, each step clipped to MAX_PREDICTION
            # metres and MAX_PREDICTION_ANGLE radians: plain extrapolation doubles a local
            # slip (a patch that slipped 10 cm last frame would jump 20 cm).
            Rp, cp, Xp = self.prev
            self.c = self.c + _clip_rows(self.c - cp, MAX_PREDICTION)
            self.X = self.X + _clip_rows(self.X - Xp, MAX_PREDICTION)
            w = _clip_rows(so3_log(self.R @ np.swapaxes(Rp, 1, 2)), MAX_PREDICTION_ANGLE)
            self.R = so3_exp(w) @ self.R
        self.X_prev2 = self.prev[2].copy()
        self.prev = last
        # Re-acquisition after a lost frame: if the model stands far from the data (the
        # driver restored an old state), move it horizontally onto the observations' centre.
        shift = Y.mean(axis=0) - self.c.mean(axis=0)
        shift[2] = 0.0
        if np.linalg.norm(shift) > REACQUIRE_OFFSET:
            self.c, self.X = self.c + shift, self.X + shift

    def _predict_by_bones(self, fps: float = DEFAULT_FPS) -> None:
        """Constant-velocity joints (each step clipped to :data:`MAX_BONE_PREDICTION`), and
        every patch moved rigidly with its bone: the rotation turning the bone's old
        direction into its new one, about the patch's bone point Δ (Eq. 8). Joints average
        many patches, so a patch that slipped last frame is not thrown further."""
        m = self.model
        _, _, Xp = self.prev
        v = self.X - Xp
        gate = self.opts.accel_gate / fps**2  # m/s² → metres per frame²
        if gate > 0:  # no extrapolation of a velocity that just jumped
            v_old = Xp - self.X_prev2
            jump = np.linalg.norm(v - v_old, axis=1)
            v = v * (jump <= np.maximum(gate, GATE_RATIO * np.linalg.norm(v_old, axis=1)))[:, None]
        X_new = self.X + _clip_rows(v, MAX_BONE_PREDICTION)
        j, ch, g = m.bone_j, m.bone_child, m.gamma[:, None]
        a, b = self.X[ch] - self.X[j], X_new[ch] - X_new[j]
        R_b = _rotation_between(a, b)
        D_old = g * self.X[j] + (1 - g) * self.X[ch]
        D_new = g * X_new[j] + (1 - g) * X_new[ch]
        self.c = np.einsum("kij,kj->ki", R_b, self.c - D_old) + D_new
        self.R = R_b @ self.R
        self.X = X_new

    def _check_divergence(self, Y: np.ndarray, X_last: np.ndarray) -> None:
        """Raise (the driver flags the frame and restores the last good state) when the fit
        has left the observations: joints jumping more than :data:`MAX_JOINT_JUMP` in a
        frame, or the model's centre more than :data:`MAX_CENTRE_OFFSET` from the data's."""
        jump = float(np.linalg.norm(self.X - X_last, axis=1).max())
        offset = float(np.linalg.norm(self.c.mean(axis=0) - Y.mean(axis=0)))
        if jump > MAX_JOINT_JUMP or offset > MAX_CENTRE_OFFSET:
            raise FitError(f"diverged (joint jump {jump:.2f} m, centre offset {offset:.2f} m)")

    def nearest_vertices(self, Y: np.ndarray, *, spare: int) -> NearestVertices:
        """The nearest vertices of observed points ``Y`` (m, 3) over a frame's iterations,
        ``spare`` candidates kept beyond ``k_neighbours``."""
        m = self.model
        return NearestVertices(
            Y,
            m.labels,
            k=self.opts.k_neighbours,
            spare=spare,
            groups=m.bone_of_patch,
            key=self.vertex_key,
        )

    def correspondences(
        self,
        Y: np.ndarray,
        NY: np.ndarray,
        ycls: np.ndarray | None,
        Vc: np.ndarray,
        Nc: np.ndarray,
        *,
        nearest: NearestVertices | None = None,
    ) -> Correspondences:
        """E-step: soft assignments of observed points to patches (+ an outlier class).

        Parameters
        ----------
        Y : (m, 3) kept observed points, metres; NY : (m, 3) their unit normals
        ycls : (m,) int body part of each point (−1: any), or None (no classes)
        Vc : (n, 3) each vertex as its own patch predicts it; Nc : (n, 3) its normal
        nearest : NearestVertices of ``Y``, optional
            The frame's candidate vertices, re-used across its iterations where they
            provably are the nearest (default: a new k-d query).
        """
        o, m = self.opts, self.model
        if nearest is None:
            d, idx = k_nearest(Vc, Y, min(o.k_neighbours, len(Vc)))
        else:
            d, idx = nearest.query(Vc)
        if o.interior_scale > 0:  # the E-step with depth penalties, in numpy
            return self._assign_interior(Y, NY, ycls, Vc, Nc, d, idx)
        # per point, the nearest vertex per patch among those whose normals agree and, with
        # classes, on the point's body part (§III-B); posterior against an outlier class
        cls = np.zeros(0, np.int64) if ycls is None else np.asarray(ycls, dtype=np.int64)
        _, patch, v, w, y, ny = assign_kernel(
            np.ascontiguousarray(d, dtype=np.float64),
            idx,
            np.ascontiguousarray(Nc, dtype=np.float64),
            np.ascontiguousarray(Y, dtype=np.float64),
            np.ascontiguousarray(NY, dtype=np.float64),
            cls,
            np.ascontiguousarray(m.labels, dtype=np.int64),
            np.ascontiguousarray(m.bone_of_patch, dtype=np.int64),
            float(o.normal_cos),
            self.sigma**2,
            float(np.exp(-0.5 * o.outlier_sigmas**2)),
        )
        return Correspondences(patch, v, w, y, ny)

    def _assign_interior(self, Y, NY, ycls, Vc, Nc, d, idx) -> Correspondences:
        """:meth:`correspondences` with ``interior_scale``: each metre a point lies deeper than
        :data:`INTERIOR_MARGIN` behind its candidate vertex adds ``σ / interior_scale`` to
        their distance (in quadrature), so points deep inside the model fall to the outlier
        class."""
        o, m = self.opts, self.model
        ok = np.einsum("pkj,pj->pk", np.take(Nc, idx, axis=0), NY) > o.normal_cos
        if ycls is not None:  # only patches of the point's body part (§III-B)
            ok &= (m.bone_of_patch[m.labels[idx]] == ycls[:, None]) | (ycls[:, None] < 0)
        i, j = np.nonzero(ok)  # row-major: per point, candidates by increasing distance
        patch = m.labels[idx[i, j]]
        _, first = np.unique(i * m.P + patch, return_index=True)  # nearest per patch
        i, j, patch = i[first], j[first], patch[first]
        vx = idx[i, j]
        depth = np.einsum("ij,ij->i", Vc[vx] - Y[i], Nc[vx]) - INTERIOR_MARGIN
        d2 = d[i, j].astype(np.float64) ** 2
        d2 = d2 + (np.maximum(depth, 0.0) / o.interior_scale * self.sigma) ** 2
        p = np.exp(-0.5 * d2 / self.sigma**2)
        denom = np.bincount(i, p, minlength=len(Y)) + np.exp(-0.5 * o.outlier_sigmas**2)
        return Correspondences(patch, vx, p / denom[i], Y[i], NY[i])

    def _apply(self, delta: np.ndarray) -> None:
        P = self.model.P
        d = delta[: 6 * P].reshape(P, 6).copy()
        # trust region: no patch turns more than MAX_STEP_ANGLE radians in one step
        angle = np.linalg.norm(d[:, :3], axis=1, keepdims=True)
        d[:, :3] *= np.minimum(1.0, MAX_STEP_ANGLE / np.maximum(angle, NORM_FLOOR))
        self.R = so3_exp(d[:, :3]) @ self.R
        self.c = self.c + d[:, 3:]
        self.X = self.X + delta[6 * P :].reshape(-1, 3)


def surface_training_sample(
    V: np.ndarray, F: np.ndarray, vertex_class: np.ndarray, *, seed: int = 0
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Where the body-part classifier's training points lie on a mesh: as many points as
    vertices, spread uniformly over the rest surface ``V`` (n, 3), ``F`` (m, 3) (faces drawn
    in proportion to their area, barycentric coordinates uniform in each), each labelled
    with the class of its face's nearest corner (``vertex_class`` (n,)).

    The observed points are spread over the hull's surface by area, and the classifier
    should learn from the same spread: the vertices of a decimated body are not (quadric
    decimation keeps few on flat parts, a forearm, and not as many on one side as on the
    other: ``docs/patch.rst``), so trained on vertices a sparsely meshed part gets too
    small a share of the labels. Returns the faces (k,) int64, the
    barycentric coordinates (k, 3) float64 and the classes (k,) int64; the training points
    of a posed mesh ``X`` are ``einsum("nk,nka->na", bary, X[F[faces]])``."""
    E1, E2 = V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]]
    area = 0.5 * np.linalg.norm(np.cross(E1, E2), axis=1)
    rng = np.random.default_rng(seed)
    faces = rng.choice(len(F), size=len(V), p=area / area.sum())
    bary = rng.dirichlet(np.ones(3), size=len(V))
    labels = np.asarray(vertex_class)[F[faces, bary.argmax(axis=1)]]
    return faces.astype(np.int64), bary, labels.astype(np.int64)


def _held_pairs(ev: EvalSkeleton) -> np.ndarray:
    """(m, 2) joint pairs whose distance the length prior holds: every bone (child, parent)
    and :data:`RIGID_PAIRS` (without them a pelvis→hip bone can swing round the pelvis: a
    hip can flip to the other side for many frames)."""
    b = np.flatnonzero(ev.parents >= 0)
    extra = [
        (ev.names.index(a), ev.names.index(c))
        for a, c in RIGID_PAIRS
        if a in ev.names and c in ev.names
    ]
    return np.vstack([np.stack([b, ev.parents[b]], 1), np.reshape(extra, (-1, 2))]).astype(int)


def _held_lengths(
    B: np.ndarray, pairs: np.ndarray, lengths: np.ndarray, *, iters: int = 8
) -> np.ndarray:
    """The joints (K, 3) nearest to ``B`` (K, 3) whose ``pairs`` (m, 2) lie ``lengths`` (m,)
    apart: Gauss–Newton on ``|X − B|² + μ Σ (|X_a − X_b| − L)²`` with μ = 1e4 (lengths
    then hold to 1e-4 of their error in ``B``)."""
    mu, K, m = 1e4, len(B), len(pairs)
    X = B.copy()
    rows = np.repeat(np.arange(m), 6)
    cols = (3 * pairs[:, [0, 0, 0, 1, 1, 1]] + np.array([0, 1, 2, 0, 1, 2])).ravel()
    for _ in range(iters):
        u, r = length_residuals(X, pairs, lengths)
        J = np.zeros((m, 3 * K))
        J[rows, cols] = np.concatenate([u, -u], axis=1).ravel()
        H = np.eye(3 * K) + mu * J.T @ J  # positive definite: no damping
        g = (X - B).ravel() + mu * J.T @ r
        X = X + damped_solve(H, g, lam=UNDAMPED.lam, floor=UNDAMPED.floor).reshape(K, 3)
    return X


def _pair_lengths(X: np.ndarray, pairs: np.ndarray) -> np.ndarray:
    """Distance (m,) between the joints of each pair of ``X`` (K, 3)."""
    return np.linalg.norm(X[pairs[:, 0]] - X[pairs[:, 1]], axis=1)


def _rotation_between(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Smallest rotations (k, 3, 3) turning the directions of ``a`` (k, 3) into ``b``."""
    a = a / np.maximum(np.linalg.norm(a, axis=1, keepdims=True), NORM_FLOOR)
    b = b / np.maximum(np.linalg.norm(b, axis=1, keepdims=True), NORM_FLOOR)
    axis = np.cross(a, b)
    s = np.linalg.norm(axis, axis=1, keepdims=True)
    angle = np.arctan2(s[:, 0], np.sum(a * b, axis=1))
    return so3_exp(axis / np.maximum(s, NORM_FLOOR) * angle[:, None])


def _clip_rows(A: np.ndarray, limit: float) -> np.ndarray:
    """Rows of ``A`` (k, 3) scaled down to a norm of at most ``limit``."""
    n = np.linalg.norm(A, axis=1, keepdims=True)
    return A * np.minimum(1.0, limit / np.maximum(n, NORM_FLOOR))
