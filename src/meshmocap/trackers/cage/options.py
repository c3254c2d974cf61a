"""Settings of the cage tracker (:mod:`meshmocap.trackers.cage.tracker`) and the digest that
identifies its pose manifold in :meth:`~meshmocap.trackers.cage.tracker.CageTracker.options`."""

from __future__ import annotations

import hashlib
from dataclasses import dataclass
from typing import Literal, get_args

import numpy as np

from meshmocap._validate import check_choice
from meshmocap.errors import InputError
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
        The energy's terms (:mod:`~meshmocap.trackers.cage.terms`): the paper's distance
        field sum (Eq. 4) and variance regulariser (Eq. 5); the hull and silhouette coverage
        terms, the local adjustment's pull towards the manifold and its soft joints (ours).
        Each term's weight is the option of the same role below. ``"distance"`` is needed.
    space : {"latent", "quads"}
        Optimise in the learned latent space (the method) or directly on the quads (the
        ablation of Fig. 5a, which collapses without the manifold).
    variance_weight : float
        λσ of the variance regulariser (0: the ablation of Fig. 5b), against the mean
        half squared distance in m² (~1e-4 on a fitted frame).
    local_iters : int
        Levenberg–Marquardt iterations of the local adjustment in quad space (Eq. 12; 0:
        none).
    local_damping : float
        Pull of the local adjustment towards the manifold's configuration (weight of half
        its squared distance, metres and unit axis vectors): weak, the adjustment tracks
        from the previous frame (:mod:`~meshmocap.trackers.cage.tracker` notes).
    off_manifold : float
        A frame is off the manifold when the manifold's configuration fits it (data and
        silhouette terms) more than this many times worse than the best tracked start of the
        local adjustment; there the adjustment is not pulled towards the manifold and runs
        twice ``local_iters`` (0: never; energy ``off_manifold`` of each frame says).
    articulation : float
        Weight of the local adjustment's soft joints between consecutive quads (half
        their squared gaps, m²; :class:`~meshmocap.trackers.cage.energy.Articulation`).
    alternations, pose_iters, shape_iters : int
        Pose/shape alternations (§5.3) and Levenberg–Marquardt steps in each.
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
        cage cannot follow them (:mod:`~meshmocap.trackers.cage.energy`); ``inf``: keep
        all.
    outside_margin : float
        Distance, metres, outside the hull that the data term tolerates (0: none).
    outside_cap : float
        Distance, metres, outside the hull beyond which a point costs nothing (truncated
        data term: the hull lost that part, a hole carved by a noisy silhouette; 0: none).
    coverage_weight : float
        λc of the hull coverage term (0: none), against the data term: both are mean half
        squared distances (m²). Used only in frames without a silhouette term (no cameras
        or masks, or ``silhouette_weight`` 0): the hull's phantom volumes drag the model
        (:class:`~meshmocap.trackers.cage.energy.SilhouetteCoverage`).
    coverage_margin : float
        Distance, metres, from a hull surface sample to the nearest sampled model point
        that the coverage term tolerates.
    n_coverage : int
        Hull surface samples of the coverage term per frame.
    silhouette_weight : float
        Weight of the silhouette coverage term
        (:class:`~meshmocap.trackers.cage.energy.SilhouetteCoverage`; 0: none), in every
        step where the frame has cameras and silhouettes (as ``coverage_weight``: mean half
        squared distances, m²).
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
        Initial Levenberg–Marquardt damping (relative to the Hessian's diagonal).
    seed : int
        Seeds the choice of the sampled vertices.
    """

    terms: tuple[TermName, ...] = ALL_TERMS
    space: Space = "latent"
    variance_weight: float = 1e-5
    local_iters: int = 3
    local_damping: float = 3e-5
    articulation: float = 10.0
    off_manifold: float = 4.0
    alternations: int = 3
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
    damping: float = 1e-3
    seed: int = 0

    def __post_init__(self) -> None:
        check_choice("CageOptions", "space", self.space, get_args(Space))
        check_choice("CageOptions", "joints", self.joints, get_args(Joints))
        check_choice("CageOptions", "surface", self.surface, get_args(Surface))
        check_choice("CageOptions", "body", self.body, get_args(Body))
        terms = tuple(self.terms) if isinstance(self.terms, list | tuple) else (self.terms,)
        for t in terms:
            check_choice("CageOptions", "terms", t, ALL_TERMS)
        if "distance" not in terms or len(set(terms)) != len(terms):
            raise InputError(
                f"CageOptions: terms must hold 'distance' and no repeat, found {list(terms)}"
            )
        object.__setattr__(self, "terms", tuple(t for t in ALL_TERMS if t in terms))
        if self.variance_weight < 0 or self.n_sample < 10:
            raise InputError("CageOptions: variance_weight must be ≥ 0 and n_sample ≥ 10")
        if not 0 < self.inside_weight <= 1 or self.restarts < 0:
            raise InputError("CageOptions: inside_weight must lie in (0, 1] and restarts ≥ 0")
        if not (
            self.max_model_error > 0
            and self.coverage_weight >= 0
            and self.articulation >= 0
            and self.coverage_margin >= 0
            and self.n_coverage >= 1
            and self.field_spacing > 0
            and self.silhouette_weight >= 0
            and self.silhouette_margin >= 0
            and self.n_silhouette >= 1
            and self.outside_margin >= 0
            and self.off_manifold >= 0
            and self.outside_cap >= 0
            and self.silhouette_cap >= 0
            and 0 <= self.silhouette_clean < 1
        ):
            raise InputError(
                "CageOptions: max_model_error must be > 0, articulation, coverage_weight, "
                "coverage_margin, silhouette_weight, silhouette_margin, silhouette_cap, "
                "outside_margin, outside_cap and off_manifold ≥ 0, silhouette_clean in [0, 1), "
                "n_coverage and n_silhouette ≥ 1 and field_spacing > 0"
            )
