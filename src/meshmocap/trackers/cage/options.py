"""Settings of the cage tracker (:mod:`meshmocap.trackers.cage.tracker`) and the digest that
identifies its pose manifold in :meth:`~meshmocap.trackers.cage.tracker.CageTracker.options`."""

from __future__ import annotations

import hashlib
import math
from dataclasses import dataclass
from numbers import Integral, Real
from typing import ClassVar, Literal, get_args

import numpy as np

from meshmocap._validate import Constraint, Interval, Names, Options, check_options
from meshmocap.errors import InputError
from meshmocap.geometry.levenberg_marquardt import DAMPING
from meshmocap.models.gplvm import GPLVM
from meshmocap.trackers.cage.terms import ALL_TERMS, TermName

Space = Literal["latent", "quads"]
Joints = Literal["green", "quads"]
Surface = Literal["skinned", "green"]
Body = Literal["auto", "template", "reference"]


def manifold_digest(gp: GPLVM) -> str:
    """16 hex digits of SHA-256 over everything a fitted GPLVM predicts from: its latent
    points ``X_``, centred and scaled data ``Y_``, ``Y_mean_``, the kernel and noise
    hyperparameters, the data scale and the back-constraint (``bc_gamma_``, ``A_`` or
    the MLP weights). Equal for a model and its :meth:`~GPLVM.save`/:meth:`~GPLVM.load`
    copy (bit-identical arrays), different for any other fit.

    Raises
    ------
    InputError
        ``gp`` is not a fitted GPLVM.
    """
    if not isinstance(gp, GPLVM) or not hasattr(gp, "X_"):
        raise InputError(f"manifold_digest: gp must be a fitted GPLVM, found {type(gp).__name__}")
    h = hashlib.sha256()
    scalars = [gp.alpha_, gp.gamma_, gp.beta_, gp.bc_gamma_, gp.Y_scale_]
    arrays = [gp.X_, gp.Y_, gp.Y_mean_, np.array(scalars, dtype=np.float64)]
    arrays += [gp.A_] if gp.A_ is not None else []
    arrays += list(gp.mlp_weights_ or ())
    for a in arrays:
        a = np.ascontiguousarray(a, dtype=np.float64)
        h.update(repr(a.shape).encode())
        h.update(a.tobytes())
    return h.hexdigest()[:16]


@dataclass(frozen=True, kw_only=True)
class CageOptions:
    """Settings of the cage tracker.

    A variant of the tracker is a term list (``terms``) plus these options.

    Parameters
    ----------
    terms : tuple of {"distance", "variance", "coverage", "silhouette", "anchor", "articulation"}
        The energy's terms (:mod:`~meshmocap.trackers.cage.terms`,
        :func:`~meshmocap.trackers.cage.energy.energy_terms`): the paper's distance field sum
        (Eq. 4) and variance regulariser (Eq. 5); the hull and silhouette coverage terms,
        the local adjustment's pull towards the manifold and its soft joints (ours). A term
        is on when it is in the list; its weight is the option of the same role below
        (> 0). ``"distance"`` is needed.
    space : {"latent", "quads"}
        Optimise in the learned latent space (the method) or directly on the quads (the
        ablation of Fig. 5a, which collapses without the manifold).
    variance_weight : float
        λσ of the variance regulariser (``"variance"``; without it in ``terms``: the
        ablation of Fig. 5b, ``cage_noreg``), against the mean half squared distance in m²
        (~1e-4 on a fitted frame).
    local_iters : int
        Levenberg–Marquardt iterations of the local adjustment in quad space (Eq. 12; 0:
        none).
    anchor_weight : float
        Weight of the ``"anchor"`` term: the pull of the local adjustment towards the
        manifold's configuration (half its squared distance, metres and unit axis vectors):
        weak, the adjustment tracks from the previous frame
        (:mod:`~meshmocap.trackers.cage.tracker` notes).
    off_manifold : float
        A frame is off the manifold when the manifold's configuration fits it (data and
        silhouette terms) more than this many times worse than the best tracked start of the
        local adjustment; there the adjustment is not pulled towards the manifold and runs
        twice ``local_iters`` (0: never; energy ``off_manifold`` of each frame says).
    articulation : float
        Weight of the ``"articulation"`` term: the local adjustment's soft joints between
        consecutive quads (half their squared gaps, m²;
        :class:`~meshmocap.trackers.cage.residuals.Articulation`).
    alternations, pose_iters, shape_iters : int
        Pose/shape alternations (§5.3) and Levenberg–Marquardt steps in each.
    off_alternations : int
        Pose/shape alternations on a frame that follows one off the manifold
        (``off_manifold``): there the latent point only proposes the local adjustment's
        start and the limbs grafted from it, and the adjustment is not pulled towards it.
    restarts : int
        Training poses, nearest to the previous frame's quads, tried as the latent
        starting point (0: only the previous latent point and the back-constraint's).
    inside_weight : float
        Weight, in (0, 1], of the squared distance of points inside the hull (module
        notes; 1: symmetric).
    joints : {"quads", "green"}
        Joints carried rigidly by the quad that follows their rig joint (the quads sit at
        the joints, §3; joints of no quad keep Green coordinates), or from the cage through
        Green coordinates (§6.2), which misplace them by a centimetre or two at the true
        quads (``docs/guide/cage.rst``).
    surface : {"skinned", "green"}
        The template surface the data term fits (:mod:`~meshmocap.trackers.cage.surface`):
        posed by its own skinning from the quads' joint frames, or deformed by the cage's
        Green coordinates (the paper's Eq. (1), centimetres from the skinned body).
    body : {"auto", "template", "reference"}
        The body the cage is built on (:mod:`~meshmocap.trackers.cage.body`): the template
        (the paper's), the bundled reference body posed on the template's skeleton, or the
        template where its cage builds without relaxing, else the reference body. The
        template's own vertices are bound to that cage.
    n_sample : int
        Template vertices in the energy, drawn by area (the output deforms all of them).
    max_model_error : float
        Sampled vertices that the cage places farther than this (metres) from their
        skinned position in the first frame's known pose get no data term (Eq. 4): the
        cage cannot follow them (:mod:`~meshmocap.trackers.cage.residuals`); ``inf``: keep
        all.
    outside_margin : float
        Distance, metres, outside the hull that the data term tolerates (0: none).
    outside_cap : float
        Distance, metres, outside the hull beyond which a point costs nothing (truncated
        data term: the hull lost that part, a hole carved by a noisy silhouette; 0: none).
    coverage_weight : float
        λc of the hull coverage term (``"coverage"``), against the data term: both are mean
        half squared distances (m²). Used only in frames without a silhouette term (no
        cameras or masks, or no ``"silhouette"`` in ``terms``): the hull's phantom volumes
        drag the model (:class:`~meshmocap.trackers.cage.residuals.SilhouetteCoverage`).
    coverage_margin : float
        Distance, metres, from a hull surface sample to the nearest sampled model point
        that the coverage term tolerates.
    n_coverage : int
        Hull surface samples of the coverage term per frame.
    silhouette_weight : float
        Weight of the silhouette coverage term (``"silhouette"``,
        :class:`~meshmocap.trackers.cage.residuals.SilhouetteCoverage`), in every step where
        the frame has cameras and silhouettes (as ``coverage_weight``: mean half squared
        distances, m²).
    silhouette_margin : float
        Pixels a silhouette contour sample may lie from the nearest projected model point.
    silhouette_cap : float
        Pixels beyond which a contour sample is an outlier (a spurious blob) and costs
        nothing (0: no cap).
    silhouette_clean : float
        Connected pieces of a silhouette smaller than this fraction of its largest are
        dropped before sampling its contour (spurious blobs; 0: none).
    n_silhouette : int
        Contour samples per camera and frame.
    field_spacing : float
        Spacing, metres, of the distance field's grid: the nearest multiple of the hull's
        voxel (:class:`~meshmocap.geometry.distance_field.LazyDistanceGrid` ``stride``).
    damping : float
        Initial Levenberg–Marquardt λ, relative to the diagonal (the rule and its floor:
        :mod:`meshmocap.geometry.levenberg_marquardt`).
    seed : int
        Seeds the choice of the sampled vertices.
    """

    terms: tuple[TermName, ...] = ALL_TERMS
    space: Space = "latent"
    variance_weight: float = 1e-5
    local_iters: int = 3
    anchor_weight: float = 3e-5
    articulation: float = 10.0
    off_manifold: float = 4.0
    alternations: int = 3
    off_alternations: int = 1
    pose_iters: int = 1
    shape_iters: int = 2
    restarts: int = 3
    inside_weight: float = 0.05
    outside_margin: float = 0.0
    outside_cap: float = 0.0
    joints: Joints = "quads"
    surface: Surface = "skinned"
    body: Body = "auto"
    n_sample: int = 800
    max_model_error: float = 0.03
    coverage_weight: float = 0.3
    coverage_margin: float = 0.02
    n_coverage: int = 500
    silhouette_weight: float = 0.3
    silhouette_margin: float = 1.0
    silhouette_cap: float = 15.0
    silhouette_clean: float = 0.02
    n_silhouette: int = 200
    field_spacing: float = 0.02
    damping: float = DAMPING["cage"].lam
    seed: int = 0

    #: Each option's constraint (checked by ``check_options`` in ``meshmocap._validate``).
    constraints: ClassVar[dict[str, Constraint | tuple]] = {
        "terms": Names(ALL_TERMS, required=("distance",)),
        "space": Options(get_args(Space)),
        "variance_weight": Interval(Real, 0, None, closed="neither"),
        "local_iters": Interval(Integral, 0, None),
        "anchor_weight": Interval(Real, 0, None, closed="neither"),
        "articulation": Interval(Real, 0, None, closed="neither"),
        "off_manifold": Interval(Real, 0, None),
        "alternations": Interval(Integral, 1, None),
        "off_alternations": Interval(Integral, 1, None),
        "pose_iters": Interval(Integral, 0, None),
        "shape_iters": Interval(Integral, 0, None),
        "restarts": Interval(Integral, 0, None),
        "inside_weight": Interval(Real, 0, 1, closed="right"),
        "outside_margin": Interval(Real, 0, None),
        "outside_cap": Interval(Real, 0, None),
        "joints": Options(get_args(Joints)),
        "surface": Options(get_args(Surface)),
        "body": Options(get_args(Body)),
        "n_sample": Interval(Integral, 10, None),
        "max_model_error": Interval(Real, 0, math.inf, closed="right"),
        "coverage_weight": Interval(Real, 0, None, closed="neither"),
        "coverage_margin": Interval(Real, 0, None),
        "n_coverage": Interval(Integral, 1, None),
        "silhouette_weight": Interval(Real, 0, None, closed="neither"),
        "silhouette_margin": Interval(Real, 0, None),
        "silhouette_cap": Interval(Real, 0, None),
        "silhouette_clean": Interval(Real, 0, 1, closed="left"),
        "n_silhouette": Interval(Integral, 1, None),
        "field_spacing": Interval(Real, 0, None, closed="neither"),
        "damping": Interval(Real, 0, None),
        "seed": Interval(Integral, 0, None),
    }

    def __post_init__(self) -> None:
        check_options("CageOptions", self, self.constraints)
        # the list in its canonical order (JSON lists and any order give the same options)
        object.__setattr__(self, "terms", tuple(t for t in ALL_TERMS if t in self.terms))
