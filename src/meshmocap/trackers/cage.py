"""The cage tracker of cage-manifold-tracking.txt (Duveau, Boyer et al., 3DIMPVT 2012).

The template sits in a cage built from 21 Oriented Quads (:mod:`meshmocap.body.oqr`) and
follows it through 3D Green coordinates (Eq. 1). Plausible quad configurations lie on a
GPLVM manifold learned from motion capture (§4). Each frame minimises

    E(x, Γ) = Σ_i d_DF(M_i(x, Γ))² / n  +  λσ · log σ²(x)                         # Eq. (4)–(5)

over the latent point ``x`` (shape, Eq. 6: chain rule through the GPLVM mean, the
quads, the cage and the Green coordinates) and the pelvis transform ``Γ`` (pose, Eq. 11),
alternated (§5.3), then adjusts the quads locally (Eq. 12). Joints follow the cage through
their own Green coordinates taken on the first frame (§6.2).

Choices where the paper is silent or ambiguous (each stated where it is coded):
- Eq. (4) sums distance-field values; we sum their squares (signed distance, so points
  inside the hull are pulled out to its surface too, and Gauss–Newton applies).
- Eq. (5) as printed subtracts log σ², which would *reward* unlikely poses; we add it,
  penalising latent points where the manifold is uncertain (the paper's stated intent:
  "this variance as a regularization term to ensure that the shape ... is likely").
- Steps are Levenberg–Marquardt (Gauss–Newton) on the residuals d_DF, not plain gradient
  descent: same energy, far fewer iterations.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from typing import Literal, get_args

import numpy as np

from meshmocap._validate import check_choice
from meshmocap.body.motion import Motion
from meshmocap.body.oqr import (
    OQR,
    build_oqr,
    cage_vertices,
    configuration_from_vector,
    configuration_vector,
    quads_from_pose,
)
from meshmocap.body.template import Template
from meshmocap.errors import InputError
from meshmocap.geometry.carving import distance_grid
from meshmocap.geometry.green import GreenDeformer
from meshmocap.geometry.rotations import so3_exp
from meshmocap.io.capture import CaptureFrame
from meshmocap.io.results import FrameResult
from meshmocap.models.gplvm import GPLVM

Space = Literal["latent", "quads"]


def learn_manifold(
    template: Template,
    motions: list[Motion],
    *,
    n_components: int = 2,
    n_samples: int = 120,
    oqr: OQR | None = None,
    random_state: int = 0,
) -> GPLVM:
    """Learn the pose manifold (§4, §6.2) from motions on ``template``'s skeleton.

    Every motion frame maps the quads rigidly to the skeleton (:func:`quads_from_pose`);
    ``n_samples`` configurations evenly spread over all frames train a back-constrained
    GPLVM with ``n_components`` latent dimensions.
    """
    if not motions:
        raise InputError("learn_manifold: no motions given")
    oqr = oqr or build_oqr(template)
    R = np.concatenate([m.rotations for m in motions])
    t = np.concatenate([m.root_positions for m in motions])
    pick = np.unique(np.linspace(0, len(R) - 1, min(n_samples, len(R))).round().astype(int))
    c, Q = quads_from_pose(oqr, template, R[pick], t[pick])
    Y = configuration_vector(c, Q)
    return GPLVM(n_components, back_constraint="rbf", random_state=random_state).fit(Y)


@dataclass(frozen=True)
class CageOptions:
    """Settings of the cage tracker.

    Parameters
    ----------
    space : {"latent", "quads"}
        Optimise in the learned latent space (the method) or directly on the quads (the
        ablation of Fig. 5a, which collapses without the manifold).
    variance_weight : float
        λσ of the variance regulariser (0: the ablation of Fig. 5b).
    local_iters : int
        Gauss–Newton iterations of the local adjustment in quad space (Eq. 12; 0: none).
    local_damping : float
        Pull of the local adjustment towards the manifold's configuration.
    alternations, pose_iters, shape_iters : int
        Pose/shape alternations (§5.3) and Gauss–Newton steps in each.
    n_sample : int
        Template vertices in the energy (the output deforms all of them).
    damping : float
        Levenberg–Marquardt damping.
    seed : int
    """

    space: Space = "latent"
    variance_weight: float = 1e-4
    local_iters: int = 3
    local_damping: float = 1e-2
    alternations: int = 3
    pose_iters: int = 2
    shape_iters: int = 3
    n_sample: int = 800
    damping: float = 1e-3
    seed: int = 0

    def __post_init__(self) -> None:
        check_choice("CageOptions", "space", self.space, get_args(Space))
        if self.variance_weight < 0 or self.n_sample < 10:
            raise InputError("CageOptions: variance_weight must be ≥ 0 and n_sample ≥ 10")


def _gs_forward(a, b, da, db):
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
    n, dn = np.cross(u, v), np.cross(du, v) + np.cross(u, dv)
    return np.stack([u, v, n], axis=2), np.stack([du, dv, dn], axis=2)


class CageTracker:
    """Cage-based tracker with a GPLVM pose manifold (see the module docstring).

    Parameters
    ----------
    manifold : GPLVM
        A fitted pose manifold (:func:`learn_manifold`) of the tracking template.
    options : CageOptions
    """

    name = "cage"

    def __init__(self, manifold: GPLVM, options: CageOptions = CageOptions()):
        self.gp = manifold
        self.opts = options
        self.template: Template | None = None

    def options(self) -> dict:
        """JSON-ready settings."""
        return {**asdict(self.opts), "n_components": int(self.gp.X_.shape[1])}

    def setup(self, template: Template) -> None:
        """Build the rig and the Green coordinates of the template (all and sampled)."""
        o = self.opts
        self.template = template
        self.oqr = build_oqr(template)
        rest = self.oqr.rest_vertices
        self.deform_all = GreenDeformer(rest, self.oqr.faces, template.V)
        rng = np.random.default_rng(o.seed)
        self.sample = np.sort(
            rng.choice(template.n_vertices, min(o.n_sample, template.n_vertices), replace=False)
        )
        self.deform_sample = GreenDeformer(rest, self.oqr.faces, template.V[self.sample])
        self.joint_deformer: GreenDeformer | None = None

    # -------------------------------------------------------------- state
    def init(
        self, template: Template, frame: CaptureFrame, R: np.ndarray, root: np.ndarray
    ) -> FrameResult:
        """Start from the quads of a known pose; joints get Green coordinates in its cage."""
        if self.template is not template:
            self.setup(template)
        c, Q = quads_from_pose(self.oqr, template, R, root)
        self.pelvis_R, self.pelvis_c = Q[0].copy(), c[0].copy()
        y = configuration_vector(c, Q)
        self.x = self.gp.transform(y[None])[0]
        self.local = y.copy()  # the quads after local adjustment (relative to the pelvis)
        joints = template.pose(R, root).eval_joints
        cage0 = cage_vertices(self.oqr, c, Q)
        self.joint_deformer = GreenDeformer(cage0, self.oqr.faces, joints)
        self.cage0 = cage0
        return self._result(frame.index, {}, 0)

    def set_state(self, state: dict[str, np.ndarray]) -> None:
        """Restore latent point, pelvis transform, local quads and the joints' cage."""
        self.x, self.local = state["x"].copy(), state["local"].copy()
        self.pelvis_R, self.pelvis_c = state["pelvis_R"].copy(), state["pelvis_c"].copy()
        self.cage0 = state["cage0"].copy()
        self.joint_deformer = GreenDeformer(self.cage0, self.oqr.faces, state["joints0"])

    def _cage(self, y: np.ndarray, pelvis_R: np.ndarray, pelvis_c: np.ndarray) -> np.ndarray:
        c, Q = configuration_from_vector(y, pelvis_c, pelvis_R)
        return cage_vertices(self.oqr, c, Q)

    def _result(self, index: int, energies: dict[str, float], n_iter: int) -> FrameResult:
        cage = self._cage(self.local, self.pelvis_R, self.pelvis_c)
        joints = self.joint_deformer.deform(cage)
        # "cage": this frame's cage vertices (85, 3), replayed by motion transfer
        state = {"x": self.x, "local": self.local, "pelvis_R": self.pelvis_R,
                 "pelvis_c": self.pelvis_c, "cage0": self.cage0,
                 "joints0": self.joint_deformer.deform(self.cage0), "cage": cage}  # fmt: skip
        return FrameResult(index=index, joints=joints, vertices=self.deform_all.deform(cage),
                           energies=energies, n_iter=n_iter, state=state)  # fmt: skip

    # -------------------------------------------------------------- derivatives
    def _cage_directions(
        self, y: np.ndarray, dys: np.ndarray, pose: bool
    ) -> tuple[np.ndarray, np.ndarray]:
        """Cage at ``y`` and its derivatives along config directions ``dys`` (k, D) and,
        with ``pose``, along the 6 pelvis directions (rotation about the pelvis, translation)."""
        Y = y.reshape(-1, 3, 3)
        dY = dys.reshape(len(dys), len(Y), 3, 3)
        Rp, cp = self.pelvis_R, self.pelvis_c
        loc, quad = self.oqr.vertex_local, self.oqr.vertex_quad
        c_rel = np.concatenate([np.zeros((1, 3)), Y[:, 0]])
        R_all = np.concatenate(
            [np.eye(3)[None], _gs_forward(Y[:, 1], Y[:, 2], Y[:, 1], Y[:, 2])[0]]
        )
        Rw = Rp @ R_all  # world quad rotations
        cw = c_rel @ Rp.T + cp
        cage = np.einsum("vij,vj->vi", Rw[quad], loc) + cw[quad]
        cols = []
        for d in dY:
            dR = _gs_forward(Y[:, 1], Y[:, 2], d[:, 1], d[:, 2])[1]
            dc = np.concatenate([np.zeros((1, 3)), d[:, 0]]) @ Rp.T
            dRw = Rp @ np.concatenate([np.zeros((1, 3, 3)), dR])
            cols.append(np.einsum("vij,vj->vi", dRw[quad], loc) + dc[quad])
        if pose:
            arm = cage - cp
            for a in range(3):
                e = np.zeros(3)
                e[a] = 1.0
                cols.append(np.cross(e, arm))  # rotation about the pelvis centre
            for a in range(3):
                e = np.zeros(3)
                e[a] = 1.0
                cols.append(np.broadcast_to(e, cage.shape).copy())
        return cage, np.array(cols)

    def _residuals(self, field, cage, dcages):
        """Residuals d_DF at the sampled vertices and their Jacobian columns."""
        P = self.deform_sample.deform(cage)
        r, g = field.value_and_gradient(P)
        J = (
            np.stack([np.sum(g * self.deform_sample.jvp(cage, d), axis=1) for d in dcages], 1)
            if len(dcages)
            else np.zeros((len(r), 0))
        )
        return r, J

    def _gn(self, r, J, extra_g=None, extra_H=None):
        n = len(r)
        H = J.T @ J / n
        g = J.T @ r / n
        if extra_g is not None:
            g = g + extra_g
            H = H + extra_H
        H = H + np.diag(self.opts.damping * np.diag(H) + 1e-12)
        return np.linalg.solve(H, -g)

    # -------------------------------------------------------------- tracking
    def step(self, frame: CaptureFrame) -> FrameResult:
        """Fit ``frame``: alternate pose and latent shape, then adjust the quads locally."""
        o = self.opts
        field = distance_grid(frame.hull, pad=0.05)
        q = self.x.size
        it = 0
        if o.space == "latent":
            y = self.gp.predict(self.x[None])[0]
            for _ in range(o.alternations):
                for _ in range(o.pose_iters):  # Eq. (11): pelvis transform
                    cage, dc = self._cage_directions(y, np.zeros((0, y.size)), pose=True)
                    r, J = self._residuals(field, cage, dc)
                    self._apply_pose(self._gn(r, J))
                    it += 1
                for _ in range(o.shape_iters):  # Eq. (6): latent shape
                    mean, dmean, var, dvar = self.gp.predict_with_gradient(self.x)
                    cage, dc = self._cage_directions(mean, dmean.T, pose=False)
                    r, J = self._residuals(field, cage, dc)
                    var = max(var, 1e-12)
                    gv = (
                        o.variance_weight * dvar / var
                    )  # d(λ log σ²)/dx, Eq. (5) (sign: see module)
                    Hv = o.variance_weight * np.outer(dvar, dvar) / var**2
                    self.x = self.x + self._gn(r, J, gv, Hv)
                    it += 1
                y = self.gp.predict(self.x[None])[0]
            self.local = y.copy()
        for _ in range(
            o.local_iters
            if o.space == "latent"
            else o.alternations * (o.pose_iters + o.shape_iters)
        ):
            self._local_step(field, o.space == "latent")  # Eq. (12)
            it += 1
        r, _ = self._residuals(field, self._cage(self.local, self.pelvis_R, self.pelvis_c), [])
        var = float(self.gp.predict(self.x[None], return_var=True)[1][0]) if q else 0.0
        energies = {"distance": float(np.mean(r**2)), "variance": var}
        return self._result(frame.index, energies, it)

    def _apply_pose(self, d: np.ndarray) -> None:
        self.pelvis_R = so3_exp(d[:3]) @ self.pelvis_R
        self.pelvis_c = self.pelvis_c + d[3:]

    def _local_step(self, field, anchored: bool) -> None:
        """One Gauss–Newton step on every quad's centre and in-plane axes (Eq. 12) and the
        pelvis, pulled towards the manifold's configuration when ``anchored``."""
        y = self.local
        D = y.size
        eye = np.eye(D)
        cage, dc = self._cage_directions(y, eye, pose=True)
        r, J = self._residuals(field, cage, dc)
        n = len(r)
        H = J.T @ J / n
        g = J.T @ r / n
        if anchored:
            anchor = self.gp.predict(self.x[None])[0]
            w = self.opts.local_damping
            H[:D, :D] += w * np.eye(D)
            g[:D] += w * (y - anchor)
        H += np.diag(self.opts.damping * np.diag(H) + 1e-9)
        d = np.linalg.solve(H, -g)
        self.local = y + d[:D]
        self._apply_pose(d[D:])
