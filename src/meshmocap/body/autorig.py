"""Automatic rigging of a captured human mesh: fit a reference template's skeleton to the
mesh, then transfer its rig (skeleton, skinning weights, body parts, evaluation joints).

A real capture such as the MIT crane sequence has no skeleton, so neither tracker can run
on it. :func:`rig_mesh` turns any closed human mesh, in roughly any upright pose, into a
:class:`~meshmocap.body.template.Template` whose **rest pose is the mesh itself**:

1. **Global alignment.** The reference (a bundled template, rest pose facing −Y) is scaled
   by the ratio of surface areas (``sqrt(area_mesh / area_ref)``, insensitive to the pose),
   centred on the mesh's area centroid and turned about Z by ``n_yaws`` candidate headings:
   the mesh's principal horizontal axis matched to the reference's (shoulder) axis, both
   ways, plus the angles in between. Z is up for both (house convention); the heading is
   free.
2. **Articulated fit** (:func:`fit_skeleton`): Gauss–Newton on the root translation, a
   world-frame rotation increment per free joint (the parametrisation, model points and
   lever arms of :mod:`meshmocap.body.articulated`) and the log of a global scale
   about the root; closest points **both ways** (so a limb cannot collapse into the trunk
   while part of the mesh stays unexplained), point-to-plane plus a tenth of
   point-to-point, with agreeing normals, within a distance shrinking over the iterations;
   a weak pull of every joint but the root towards its rest rotation. Every heading is
   fitted coarsely, the two best are refined, the lower symmetric RMS distance wins.
3. **Re-resting** (:func:`rest_in_pose`): the fitted reference becomes a template of its
   own whose rest pose is the fitted pose (world-aligned rest frames at the fitted joint
   positions; bone tails turned with their joints).
4. **Transfer** (:func:`transfer_rig`): every mesh vertex takes the skinning weights and
   body-part label of its nearest point on the fitted reference surface (normals
   agreeing), interpolated barycentrically; at most ``max_weights`` weights are kept and
   renormalised; :func:`rig_mesh` then diffuses them over the mesh's edges (``smooth``).
   The skeleton and the evaluation joints are the fitted reference's.

Everything is in metres, world frame Z up. The rigged template faces wherever the mesh
faces: its rest frames are world-aligned and its local rotations are relative to the
mesh's pose, so a tracker started with identity rotations at the rest root starts on the
mesh (what :func:`~meshmocap.trackers.driver.track_sequence` does for a capture without a
known pose). Code that assumes the canonical rest pose (an A-pose facing −Y, left +X)
does not hold for such a template: retargeting and the procedural motions set world bone
directions (they would play in the canonical heading). ``decimate=`` fits the full mesh and
rigs it decimated (cage-manifold-tracking §6.1: 4000 vertices; not the capture's vertices).

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

import os
from dataclasses import dataclass, replace

import numpy as np
import scipy.sparse as sp
from pykdtree.kdtree import KDTree

from meshmocap._tolerances import UNDERFLOW_FLOOR
from meshmocap.body.articulated import (
    FIXED_JOINTS,
    add_pose_pull,
    articulated_model,
    articulated_step,
    closest_pairs,
)
from meshmocap.body.articulated_system import (
    PosedModel,
    closest_point_moments,
    moment_plan,
    normal_equations,
    posed_model,
    rotation_error,
)
from meshmocap.body.skeleton import Skeleton, forward_kinematics
from meshmocap.body.skinning import smooth_weights
from meshmocap.body.template import EvalSkeleton, Template, load_template, template_problems
from meshmocap.errors import FitError, InputError, MeshError
from meshmocap.geometry.decimate import decimate_mesh
from meshmocap.geometry.mesh import face_normals, mesh_problems, signed_volume, vertex_normals
from meshmocap.geometry.proximity import closest_points_on_triangles, sample_surface
from meshmocap.geometry.rotations import so3_exp

#: Gram determinant (m⁴: a triangle's squared doubled area) below which a triangle is flat.
_FLAT_TRIANGLE = 1e-20

__all__ = [
    "MIN_VERTICES",
    "MeshSamples",
    "SkeletonFit",
    "fit_sequence",
    "fit_skeleton",
    "mesh_samples",
    "nearest_surface_points",
    "rest_in_pose",
    "rig_mesh",
    "transfer_rig",
]

#: Fewest vertices of a mesh to rig (a human needs far more; this rejects toys and typos).
MIN_VERTICES = 100


# ------------------------------------------------------------------------------ inputs
def _check_mesh(func: str, V: object, F: object) -> tuple[np.ndarray, np.ndarray]:
    """Finite (n ≥ MIN_VERTICES, 3) vertices, a closed 2-manifold, faces turned outwards."""
    V = np.asarray(V, dtype=np.float64)
    F = np.asarray(F)
    if V.ndim != 2 or V.shape[1] != 3 or len(V) < MIN_VERTICES:
        raise MeshError(
            f"{func}: V must have shape (n, 3) with n ≥ {MIN_VERTICES}, found {V.shape}"
        )
    if F.ndim != 2 or F.shape[1] != 3 or F.dtype.kind not in "iu":
        raise MeshError(f"{func}: F must be an integer (m, 3) array, found {F.dtype} {F.shape}")
    problems = mesh_problems(V, F)
    if problems:
        raise MeshError(f"{func}: the mesh is not a closed 2-manifold: {'; '.join(problems)}")
    F = F.astype(np.int64)
    if signed_volume(V, F) < 0:  # inward faces: flip them so normals point out
        F = F[:, ::-1].copy()
    return V, F


def _surface(V: np.ndarray, F: np.ndarray, n: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """``n`` area-uniform surface points (n, 3) and their unit face normals (n, 3)."""
    P, face = sample_surface(V, F, n, seed=seed)
    return np.ascontiguousarray(P), face_normals(V, F)[face]


def _area_centre(V: np.ndarray, F: np.ndarray) -> tuple[float, np.ndarray]:
    """Surface area (m²) and area centroid (3,) of a triangle mesh."""
    T = V[F]
    a = 0.5 * np.linalg.norm(np.cross(T[:, 1] - T[:, 0], T[:, 2] - T[:, 0]), axis=1)
    return float(a.sum()), (T.mean(axis=1).T @ a) / a.sum()


# ------------------------------------------------------------------------------ fitting
@dataclass(frozen=True, eq=False)
class MeshSamples:
    """Area-uniform samples of a closed mesh that :func:`fit_skeleton` fits to, made once
    (:func:`mesh_samples`) where several fits share a mesh (e.g. fits from several headings).

    Attributes
    ----------
    Y : (p, 3) float64, surface points, metres
    NY : (p, 3) float64, their unit face normals (outwards)
    tree : KDTree of ``Y``
    """

    Y: np.ndarray
    NY: np.ndarray
    tree: KDTree


def mesh_samples(V: np.ndarray, F: np.ndarray, n_points: int = 4000, *, seed: int = 0):
    """:class:`MeshSamples` of ``n_points`` points of the closed mesh ``V`` (n, 3) float64,
    metres, ``F`` (m, 3) int (seeded by ``seed``): what :func:`fit_skeleton` samples with
    ``n_data_points=n_points``, the same points.

    Raises
    ------
    MeshError
        The mesh is not a closed 2-manifold of at least :data:`MIN_VERTICES` vertices.
    """
    V, F = _check_mesh("mesh_samples", V, F)
    Y, NY = _surface(V, F, n_points, seed)
    return MeshSamples(Y, NY, KDTree(Y))


@dataclass(frozen=True, eq=False)
class SkeletonFit:
    """A template's pose (and size) fitted to a mesh by :func:`fit_skeleton`.

    Attributes
    ----------
    R : (J, 3, 3) float64
        Local joint rotations relative to the template's rest frames.
    root : (3,) float64
        World position of the root joint, metres.
    scale : float
        Size of the template about its root (1: as it is).
    rms : float
        Symmetric RMS closest-point distance between the posed template and the mesh
        (both ways, each distance clipped at 0.2 m), metres.
    n_iter : int
        Gauss–Newton iterations run.
    """

    R: np.ndarray
    root: np.ndarray
    scale: float
    rms: float
    n_iter: int

    def joints(self, template: Template) -> np.ndarray:
        """(J, 3) float64: the fitted rig joint positions, metres, world frame."""
        _, P = forward_kinematics(template.skeleton, self.R, self.root)
        return self.root + self.scale * (P - self.root)


class _Fitter:
    """State shared by the Gauss–Newton iterations of :func:`fit_skeleton`."""

    def __init__(
        self,
        template,
        samples,
        *,
        n_model_points,
        lambda_pose,
        fixed_joints,
        fit_scale,
        seed,
    ):
        self.t = template
        self.sk = template.skeleton
        self.model = articulated_model(template, n_points=n_model_points, seed=seed)
        self.plan = moment_plan(self.model)
        self.rest = np.tile(np.eye(3), (self.sk.n_joints, 1, 1))
        self.Y, self.NY, self.tree = samples.Y, samples.NY, samples.tree
        self.lambda_pose = lambda_pose
        J = self.sk.n_joints
        free = [j for j, name in enumerate(self.sk.names) if name not in fixed_joints]
        act = [np.arange(3), (3 + 3 * np.array(free, dtype=np.int64)[:, None] + np.arange(3))]
        if fit_scale:
            act.append(np.array([3 + 3 * J]))
        self.active = np.concatenate([a.ravel() for a in act])

    def posed(self, R, root, s) -> PosedModel:
        """The model points posed and scaled by ``s`` about the root: every nonzero
        weight's part ``q_e`` and every joint moved as the points are, so that the lever
        arms of :func:`~meshmocap.body.articulated_system.normal_equations` are the
        unscaled ones times ``s``."""
        p = posed_model(self.plan, R, root)
        w = self.model.W.data[:, None]
        return PosedModel(
            G=p.G,
            P=root + s * (p.P - root),
            q=w * root + s * (p.q - w * root),
            v=root + s * (p.v - root),
            n=p.n,
        )

    def rms(self, R, root, s) -> float:
        v = self.posed(R, root, s).v
        d1 = np.minimum(self.tree.query(v, k=1)[0], 0.2)
        d2 = np.minimum(KDTree(v).query(self.Y, k=1)[0], 0.2)
        return float(np.sqrt(0.5 * (np.mean(d1**2) + np.mean(d2**2))))

    def step(self, R, root, s, max_distance, normal_cos):
        """One damped Gauss–Newton step; returns the new (R, root, s)."""
        J = self.sk.n_joints
        p = self.posed(R, root, s)
        pairs = closest_pairs(
            self.tree, self.Y, self.NY, p.v, p.n, max_distance=max_distance, normal_cos=normal_cos
        )
        if not any(len(i) for i, _ in pairs):
            raise FitError("fit_skeleton: no compatible closest points")
        # closest_point_system's energy, from per-model-point moments
        S, b = closest_point_moments(p.v, pairs, (1.0, 1.0), self.Y, self.NY)
        H = np.zeros((4 + 3 * J, 4 + 3 * J))
        g = np.zeros(4 + 3 * J)
        H[:-1, :-1], g[:-1] = normal_equations(self.plan, p, S, b)
        # the log of the scale moves a point along its arm e from the root: its column of
        # H is Σ Jᵀ S e, the pose's g of the moments b = S e
        e = p.v - root
        Se = np.einsum("mab,mb->ma", S, e)
        H[:-1, -1] = H[-1, :-1] = normal_equations(self.plan, p, S, Se)[1]
        H[-1, -1] = float(np.sum(e * Se))
        g[-1] = float(np.sum(e * b))
        # weak pull of every non-root joint towards the rest pose (world-frame error)
        lam = np.full(J, self.lambda_pose)
        lam[0] = 0.0
        add_pose_pull(H, g, rotation_error(self.plan, p, R, self.rest), lam)
        act = self.active
        R, root, delta = articulated_step(
            self.sk,
            R,
            root,
            H[np.ix_(act, act)],
            g[act],
            active=act,
            n_params=4 + 3 * J,
            G=p.G,
        )
        return R, root, s * float(np.exp(np.clip(delta[-1], -0.1, 0.1)))


def fit_skeleton(
    template: Template,
    V: np.ndarray,
    F: np.ndarray,
    *,
    R: np.ndarray | None = None,
    root: np.ndarray | None = None,
    scale: float = 1.0,
    fit_scale: bool = False,
    iterations: int = 40,
    max_distance: tuple[float, float] = (0.25, 0.04),
    normal_cos: float = 0.3,
    lambda_pose: float = 1e-4,
    n_model_points: int = 2000,
    n_data_points: int = 4000,
    fixed_joints: tuple[str, ...] = FIXED_JOINTS,
    seed: int = 0,
    samples: MeshSamples | None = None,
) -> SkeletonFit:
    """Fit a template's skeleton pose (and optionally its size) to a closed mesh.

    Minimises the mean squared closest-point residuals both ways between
    ``n_model_points`` skinned template points and ``n_data_points`` samples of the mesh
    (module docstring, step 2) by damped Gauss–Newton.

    Parameters
    ----------
    template : Template
        The rigged body to pose (e.g. a bundled reference, or a template rigged by
        :func:`rig_mesh` to fit other frames of its sequence).
    V : (n, 3) float64
        Mesh vertices, metres, world frame (Z up); ``F`` : (m, 3) int, a closed 2-manifold.
    R : (J, 3, 3) float64, optional
        Starting local rotations (default: the rest pose).
    root : (3,) float64, optional
        Starting root position, metres (default: the rest root).
    scale : float
        Starting size of the template about its root.
    fit_scale : bool
        Also fit the size (a different subject); else ``scale`` stays.
    iterations : int
        Gauss–Newton iterations.
    max_distance : (float, float)
        Pairs farther apart are ignored, metres: the first value at the first iteration,
        shrinking geometrically to the second at the last.
    normal_cos : float
        Pairs need ``n_template · n_mesh`` above this.
    lambda_pose : float
        Weight (m²/rad²) of every non-root joint's squared rotation away from its rest.
    n_model_points, n_data_points : int
        Template vertices used (area-weighted sample) and mesh surface samples.
    fixed_joints : tuple of str
        Joints kept at their starting rotation (default: the articulated ICP's).
    seed : int
        Seed of both samples.
    samples : MeshSamples, optional
        The mesh's samples where the caller made them once for several fits
        (:func:`mesh_samples` of ``V``, ``F``: then ``V``, ``F`` and ``n_data_points`` are
        not read, and the mesh is not checked again).

    Returns
    -------
    SkeletonFit
    """
    func = "fit_skeleton"
    if not isinstance(template, Template):
        raise InputError(f"{func}: template must be a Template, found {type(template).__name__}")
    if samples is None:
        V, F = _check_mesh(func, V, F)
        Y, NY = _surface(V, F, n_data_points, seed)
        samples = MeshSamples(Y, NY, KDTree(Y))
    J = template.skeleton.n_joints
    R = np.tile(np.eye(3), (J, 1, 1)) if R is None else np.array(R, dtype=np.float64)
    root = template.skeleton.rest_positions[0] if root is None else root
    root = np.array(root, dtype=np.float64)
    if R.shape != (J, 3, 3) or root.shape != (3,):
        raise InputError(
            f"{func}: expected R ({J}, 3, 3) and root (3,), found {R.shape} and {root.shape}"
        )
    if not (isinstance(iterations, int | np.integer) and iterations >= 0):
        raise InputError(f"{func}: iterations must be an integer ≥ 0, found {iterations!r}")
    d0, d1 = (float(x) for x in max_distance)
    if not (0 < d1 <= d0 and np.isfinite(d0)):
        raise InputError(
            f"{func}: max_distance must be (start, end) with start ≥ end > 0, "
            f"found {max_distance!r}"
        )
    if not (np.isfinite(scale) and scale > 0):
        raise InputError(f"{func}: scale must be a positive number, found {scale!r}")
    fitter = _Fitter(
        template,
        samples,
        n_model_points=n_model_points,
        lambda_pose=lambda_pose,
        fixed_joints=tuple(fixed_joints),
        fit_scale=fit_scale,
        seed=seed,
    )
    s = float(scale)
    for it in range(iterations):
        d = d0 * (d1 / d0) ** (it / max(iterations - 1, 1))
        R, root, s = fitter.step(R, root, s, d, normal_cos)
    return SkeletonFit(R, root, s, fitter.rms(R, root, s), int(iterations))


def fit_sequence(
    template: Template,
    meshes: list[tuple[np.ndarray, np.ndarray]],
    *,
    iterations: int = 30,
    max_distance: tuple[float, float] = (0.25, 0.03),
    seed: int = 0,
) -> list[SkeletonFit]:
    """Fit a template's skeleton pose to each mesh of a sequence (e.g. evenly spaced frames
    of a capture, to learn a pose manifold from, as in cage-manifold-tracking §6.1).

    Each mesh is fitted (:func:`fit_skeleton`, size fixed) twice: warm-started from the
    previous mesh's fit, and from the rest pose moved onto the mesh's area centroid; the
    lower RMS distance wins (frames far apart can move more than a warm start recovers).

    Parameters
    ----------
    template : Template
        E.g. a template rigged from the sequence's first frame by :func:`rig_mesh`.
    meshes : list of (V (n, 3) float64, F (m, 3) int)
        Closed meshes, metres, world frame (Z up).
    iterations, max_distance, seed
        As in :func:`fit_skeleton`.

    Returns
    -------
    list of SkeletonFit, one per mesh (``scale`` = 1).
    """
    sk = template.skeleton
    rest = np.tile(np.eye(3), (sk.n_joints, 1, 1))
    _, c_t = _area_centre(template.V, template.F)
    prev: SkeletonFit | None = None
    fits = []
    opts = dict(iterations=iterations, max_distance=max_distance, seed=seed)
    for V, F in meshes:
        V, F = _check_mesh("fit_sequence", V, F)
        root = sk.rest_positions[0] + _area_centre(V, F)[1] - c_t
        cand = [fit_skeleton(template, V, F, R=rest, root=root, **opts)]
        if prev is not None:
            cand.append(fit_skeleton(template, V, F, R=prev.R, root=prev.root, **opts))
        prev = min(cand, key=lambda f: f.rms)
        fits.append(prev)
    return fits


def _yaw_candidates(V: np.ndarray, F: np.ndarray, ref: Template, n: int) -> np.ndarray:
    """``n`` headings (radians about Z) from the one turning the reference's principal
    horizontal axis onto the mesh's."""

    def axis_angle(X: np.ndarray) -> float:
        XY = X[:, :2] - X[:, :2].mean(axis=0)
        _, U = np.linalg.eigh(XY.T @ XY)
        return float(np.arctan2(U[1, -1], U[0, -1]))

    base = axis_angle(V) - axis_angle(ref.V)
    return base + 2 * np.pi * np.arange(n) / n


def rig_mesh(
    V: np.ndarray,
    F: np.ndarray,
    *,
    reference: str | os.PathLike | Template = "neutral",
    name: str = "rigged",
    decimate: int | None = None,
    n_yaws: int = 8,
    iterations: int = 40,
    max_weights: int = 4,
    smooth: int = 0,
    seed: int = 0,
) -> Template:
    """Rig a closed human mesh with a reference template's skeleton (module docstring).

    Parameters
    ----------
    V : (n, 3) float64
        Vertices, metres, world frame (Z up); the subject upright-ish, any heading, any
        size, roughly any limb pose. At least :data:`MIN_VERTICES`.
    F : (m, 3) int
        Triangles of a closed 2-manifold (inward-oriented faces are flipped).
    reference : str, path or Template
        Rigged template whose skeleton is fitted (a bundled name, a ``.npz`` file, or a
        Template with CMU MotionBuilder joints, rest pose facing −Y).
    name : str
        Name of the new template.
    decimate : int, optional
        Vertices to decimate the mesh to after the fit (``geometry.decimate.decimate_mesh``).
    n_yaws : int
        Candidate headings of the global alignment (≥ 2; 8 covers any heading).
    iterations : int
        Gauss–Newton iterations of the final fit (each heading gets a quarter).
    max_weights : int
        Skinning weights kept per vertex (1–4 typical).
    smooth : int
        Passes of diffusion of the transferred weights over the mesh's edges
        (:func:`~meshmocap.body.skinning.smooth_weights`; 0: as transferred). A vertex
        takes the weights of its nearest point on the fitted reference, so they jump
        where neighbours found different parts (an armpit, the crotch); smoothed, the
        rig's skin follows a real capture's frames more closely (``docs/guide/own_4d.rst``).
        Off by default: the cage places its quads by each vertex's largest weight, and
        on the crane's first frame the diffused weights leave vertices within its
        enclosure margin at the chest (:func:`~meshmocap.trackers.cage.oqr.build_oqr`
        refuses it).
    seed : int
        Seed of the fit's point samples.

    Returns
    -------
    Template
        ``V``, ``F`` (as given or decimated, faces outwards), the fitted skeleton as rest
        skeleton, transferred weights and part labels, the fitted evaluation joints;
        passes :func:`~meshmocap.body.template.template_problems`.

    Raises
    ------
    MeshError
        The mesh is not a finite, closed 2-manifold of at least :data:`MIN_VERTICES`
        vertices, or the rig could not be transferred.
    InputError
        Bad options.
    """
    func = "rig_mesh"
    V, F = _check_mesh(func, V, F)
    try:  # decimate_mesh validates the count and checks the result is a closed 2-manifold
        out = (V, F) if decimate is None else decimate_mesh(V, F, n_vertices=decimate)
    except InputError as exc:
        raise InputError(f"{func}: decimate: {exc}") from None
    if not (isinstance(n_yaws, int | np.integer) and n_yaws >= 1):
        raise InputError(f"{func}: n_yaws must be an integer ≥ 1, found {n_yaws!r}")
    if not (isinstance(smooth, int | np.integer) and smooth >= 0):
        raise InputError(f"{func}: smooth must be an integer ≥ 0, found {smooth!r}")
    ref = reference if isinstance(reference, Template) else load_template(reference)
    sk = ref.skeleton
    (a_mesh, c_mesh), (a_ref, c_ref) = _area_centre(V, F), _area_centre(ref.V, ref.F)
    s0 = float(np.sqrt(a_mesh / a_ref))
    root_ref = sk.rest_positions[0]
    coarse = max(iterations // 4, 1)
    opts = dict(fit_scale=True, seed=seed)
    fits = []
    for yaw in _yaw_candidates(V, F, ref, int(n_yaws)):
        R = np.tile(np.eye(3), (sk.n_joints, 1, 1))
        R[0] = so3_exp(np.array([0.0, 0.0, yaw]))
        root = c_mesh - s0 * R[0] @ (c_ref - root_ref)
        fits.append(
            fit_skeleton(
                ref,
                V,
                F,
                R=R,
                root=root,
                scale=s0,
                iterations=coarse,
                max_distance=(0.3, 0.1),
                n_model_points=600,
                n_data_points=1500,
                **opts,
            )
        )
    best = sorted(fits, key=lambda f: f.rms)[:2]
    final = [
        fit_skeleton(
            ref,
            V,
            F,
            R=f.R,
            root=f.root,
            scale=f.scale,
            iterations=iterations,
            max_distance=(0.1, 0.02),
            **opts,
        )
        for f in best
    ]
    fit = min(final, key=lambda f: f.rms)
    fitted = rest_in_pose(ref, fit.R, fit.root, scale=fit.scale, name=f"{ref.name}_fitted")
    t = transfer_rig(fitted, *out, name=name, max_weights=max_weights)
    if not smooth:
        return t
    W = smooth_weights(t.weights, t.F, iterations=smooth, max_weights=max_weights)
    return replace(t, weights=W)


# ------------------------------------------------------------------------------ transfer
def rest_in_pose(
    template: Template, R: np.ndarray, root: np.ndarray, *, scale: float = 1.0, name: str
) -> Template:
    """Return ``template`` posed by ``(R, root)`` and scaled about the root, as a template
    whose rest pose is that pose.

    The new skeleton has the same joints with world-aligned rest frames at the posed joint
    positions (bone tails turned with their joints); weights, part labels and evaluation
    weights are kept, the evaluation joints' rest positions are the posed ones. Posing the
    new template with identity rotations at its rest root gives the posed mesh.

    Parameters
    ----------
    R : (J, 3, 3) float64, local rotations; ``root`` (3,) float64, metres; ``scale`` float.
    """
    sk = template.skeleton
    G, P = forward_kinematics(sk, R, root)
    root = np.asarray(root, dtype=np.float64)
    P = root + scale * (P - root)
    posed = template.pose(R, root)
    V = root + scale * (posed.V - root)
    E = root + scale * (posed.eval_joints - root)
    off = P - np.where((sk.parents >= 0)[:, None], P[np.maximum(sk.parents, 0)], 0.0)
    end = scale * np.einsum("jab,jb->ja", G, sk.end_offsets)
    skel = Skeleton(sk.names, sk.parents, off, end)
    ev = template.eval_skeleton
    eval_sk = EvalSkeleton(ev.names, ev.parents.copy(), E, ev.weights.copy())
    return Template(
        name,
        V,
        template.F.copy(),
        skel,
        template.weights.copy(),
        template.part_labels.copy(),
        eval_sk,
    )


def _barycentric(Q: np.ndarray, A: np.ndarray, B: np.ndarray, C: np.ndarray) -> np.ndarray:
    """(n, 3) barycentric coordinates of points ``Q`` in triangles ``(A, B, C)``, clipped to
    ≥ 0 and normalised (degenerate triangles: the nearest corner)."""
    v0, v1, v2 = B - A, C - A, Q - A
    d00, d01, d11 = (np.einsum("ij,ij->i", x, y) for x, y in ((v0, v0), (v0, v1), (v1, v1)))
    d20, d21 = np.einsum("ij,ij->i", v2, v0), np.einsum("ij,ij->i", v2, v1)
    den = d00 * d11 - d01 * d01
    ok = np.abs(den) > _FLAT_TRIANGLE
    safe = np.where(ok, den, 1.0)
    b = (d11 * d20 - d01 * d21) / safe
    c = (d00 * d21 - d01 * d20) / safe
    W = np.clip(np.stack([1 - b - c, b, c], axis=1), 0.0, None)
    corner = np.argmin(np.stack([((Q - X) ** 2).sum(1) for X in (A, B, C)], 1), axis=1)
    W[~ok] = np.eye(3)[corner[~ok]]
    return W / np.maximum(W.sum(axis=1, keepdims=True), UNDERFLOW_FLOOR)


def nearest_surface_points(
    P: np.ndarray,
    N: np.ndarray,
    V: np.ndarray,
    F: np.ndarray,
    *,
    k: int = 16,
    normal_cos: float = 0.0,
) -> tuple[np.ndarray, np.ndarray]:
    """Nearest point of a triangle mesh to each query point, preferring agreeing normals.

    Among the triangles of the ``k`` nearest triangle centroids, the nearest one whose
    normal agrees with the query's (``n_tri · n > normal_cos``); the nearest overall when
    none agrees.

    Parameters
    ----------
    P, N : (p, 3) float64, query points (metres) and their unit normals
    V, F : (n, 3) float64, (m, 3) int, the mesh (outward faces)

    Returns
    -------
    tri : (p,) int64, the triangle of each nearest point
    bary : (p, 3) float64, its barycentric coordinates in that triangle
    """
    T = V[F]
    k = int(min(k, len(F)))
    _, cand = KDTree(np.ascontiguousarray(T.mean(axis=1))).query(P, k=k)
    cand = np.asarray(cand, dtype=np.int64).reshape(len(P), k)
    flat = cand.ravel()
    Pr = np.repeat(P, k, axis=0)
    Q = closest_points_on_triangles(Pr, T[flat, 0], T[flat, 1], T[flat, 2])
    d = np.linalg.norm(Q - Pr, axis=1).reshape(len(P), k)
    agree = (face_normals(V, F)[cand] @ N[:, :, None])[..., 0] > normal_cos
    score = d + np.where(agree, 0.0, 1e3)
    best = np.argmin(score, axis=1)
    pick = np.arange(len(P)) * k + best
    tri = flat[pick]
    return tri, _barycentric(Q[pick], T[tri, 0], T[tri, 1], T[tri, 2])


def transfer_rig(
    source: Template,
    V: np.ndarray,
    F: np.ndarray,
    *,
    name: str,
    max_weights: int = 4,
) -> Template:
    """Rig a mesh that overlaps ``source`` (same pose, same place) with ``source``'s rig.

    Each vertex takes the barycentric blend of the skinning weights and of the one-hot
    body-part labels of its nearest point on ``source``'s surface (normals agreeing,
    :func:`nearest_surface_points`); the ``max_weights`` largest weights are kept and
    renormalised, the label is the heaviest part. Skeleton and evaluation joints are
    ``source``'s (its rest pose must be the mesh's pose: see :func:`rest_in_pose`).

    Parameters
    ----------
    source : Template
    V : (n, 3) float64, metres, world frame; ``F`` (m, 3) int, closed 2-manifold
    name : str
    max_weights : int, ≥ 1

    Raises
    ------
    MeshError
        A bad mesh, or a result failing the template checks.
    """
    func = "transfer_rig"
    V, F = _check_mesh(func, V, F)
    if not (isinstance(max_weights, int | np.integer) and max_weights >= 1):
        raise InputError(f"{func}: max_weights must be an integer ≥ 1, found {max_weights!r}")
    n, J = len(V), source.skeleton.n_joints
    tri, bary = nearest_surface_points(V, vertex_normals(V, F), source.V, source.F)
    rows = np.repeat(np.arange(n), 3)
    B = sp.csr_matrix((bary.ravel(), (rows, source.F[tri].ravel())), (n, source.n_vertices))
    W = np.asarray((B @ source.weights).todense())  # (n, J): J is small
    keep = min(int(max_weights), J)
    cut = np.argpartition(-W, keep - 1, axis=1)[:, :keep]
    Wk = np.zeros_like(W)
    rows = np.arange(n)[:, None]
    Wk[rows, cut] = W[rows, cut]
    Wk /= np.maximum(Wk.sum(axis=1, keepdims=True), UNDERFLOW_FLOOR)
    ev = source.eval_skeleton
    onehot = np.eye(len(ev.names))[source.part_labels]  # (n_source, K)
    labels = np.argmax(B @ onehot, axis=1).astype(np.int64)
    ev = EvalSkeleton(ev.names, ev.parents.copy(), ev.rest_positions.copy(), ev.weights.copy())
    t = Template(name, V, F, source.skeleton, sp.csr_matrix(Wk), labels, ev)
    problems = template_problems(t)
    if problems:
        raise MeshError(f"{func}: template {name!r}: {'; '.join(problems)}")
    return t
