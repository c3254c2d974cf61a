"""Settings of the patch tracker (:mod:`meshmocap.trackers.patch.tracker`)."""

from __future__ import annotations

from dataclasses import dataclass
from numbers import Integral, Real
from typing import ClassVar, Literal, get_args

from meshmocap._validate import Constraint, Interval, Options, check_options
from meshmocap.geometry.levenberg_marquardt import DAMPING

Classifier = Literal["logistic", "svc", "none"]
Residual = Literal["point_to_point", "point_to_plane"]
Prediction = Literal["bones", "patches", "none"]
PartMatching = Literal["all", "on_bone", "none"]
JointReadout = Literal["blend", "skeleton", "surface"]


#: The paper's method alone (``patch_paper``): Eq. (1)'s three terms with the paper's
#: weights, the linear SVM of §III-B with Eq. (6)'s thresholds, Eq. (2) as printed across
#: joints, frame-to-frame tracking from the last fit, the skeleton's joints; every term and
#: option beyond the paper off.
PAPER: dict[str, object] = {
    "classifier": "svc",  # §III-B: linear SVM, Platt probabilities
    "on_bone": 0.9,  # Eq. (6)
    "outlier": 0.5,
    "max_distance": None,  # Eq. (6) alone decides the outliers
    "lambda_data": 10.0,  # Eq. (1): λd = 10, λr = 1, λb = 1
    "lambda_rigid": 1.0,
    "lambda_bone": 1.0,
    "rigidity_scale": 1.0,  # the paper's coefficients as they are (no scale of ours)
    "bone_scale": 1.0,
    "joint_rigidity": 1.0,  # Eq. (2) as printed, across joints too
    "residual": "point_to_point",  # Eq. (7)
    "lambda_reverse": 0.0,
    "lambda_length": 0.0,
    "lambda_silhouette": 0.0,
    "lambda_temporal": 0.0,
    "interior_scale": 0.0,
    "prediction": "none",
    "accel_gate": 0.0,
    "fast_iter_scale": 1.0,
    "relaxation": 1.0,
    "max_iter": 10,  # the EM's steps as solved need 10 to reach what 8 over-relaxed do
    "coarse_iter": 0,
    "joint_readout": "skeleton",  # the joints of Eq. (8)-(11)
}


@dataclass(frozen=True)
class PatchOptions:
    """Settings of the patch tracker (defaults from the paper where it gives them).

    The energy is a list of terms (:func:`~meshmocap.trackers.patch.energy.energy_terms`):
    Eq. (1)'s three, each with its λ, and the extensions beyond the paper, each left out
    with a zero weight. :data:`PAPER` lists the settings that give the paper's method
    alone. The measurements behind the defaults are in ``docs/patch.rst``.

    Parameters
    ----------
    n_patches : int
        Number of surface patches (the paper uses 150–250).
    joint_rigidity : float
        Scale of Er (Eq. 2) between neighbouring patches bound to different bones (1: as
        printed). Er penalises bending away from the rest pose, so across a joint it pulls
        limbs back towards the template's pose; the bone binding already holds such
        patches together through their shared joint.
    lambda_data, lambda_rigid, lambda_bone : float
        λd, λr, λb of Eq. (1) (the paper's 10, 1, 1): the weights of
        :class:`~meshmocap.trackers.patch.terms.DataTerm`,
        :class:`~meshmocap.trackers.patch.terms.RigidityTerm` and
        :class:`~meshmocap.trackers.patch.terms.BoneTerm`.
    rigidity_scale, bone_scale : float
        Factors on ``lambda_rigid`` and ``lambda_bone`` (ours; 1 in the paper's row,
        :data:`PAPER`). Each term is a mean squared residual (normalised by its total
        weight), and neighbouring patches' predictions and the bone points stay within
        millimetres where the data stay within centimetres: with the paper's λr = λb = 1
        against λd = 10 on those means, patches drift apart. The defaults (10 and 100,
        tuned on synthetic walks, ``benchmarks/bench_patch.py``) make the coefficients
        10 : 10 : 100.
    lambda_reverse : float
        Weight of the reverse data term (not in the paper; 0 leaves it out,
        :class:`~meshmocap.trackers.patch.terms.ReverseTerm`): mean squared distance from
        sampled template vertices (:data:`~meshmocap.trackers.patch.tracker.REVERSE_SAMPLES`)
        to their nearest compatible kept observation. Eq. (7) only pulls patches that
        observations pick as candidates, so a limb that moved further than its neighbours'
        vertices in one frame (a fast kick) is left in empty space; this term pulls it back
        onto the data.
    reverse_cap : float
        Largest vertex-to-observation distance (metres) the reverse term uses.
    reverse_scale : float
        Scale τ (metres) of the reverse term's Cauchy weights ``1 / (1 + (d/τ)²)``: a
        vertex τ from the data pulls half as hard as one on it, so the term does not follow
        the tunnels that silhouette holes carve into the hull.
    lambda_length : float
        Weight of the bone-length prior (not in the paper; 0 leaves it out,
        :class:`~meshmocap.trackers.patch.terms.LengthTerm`): mean squared change of each
        bone's length (and of the hip-to-hip and shoulder-to-shoulder distances,
        :data:`~meshmocap.trackers.patch.tracker.RIGID_PAIRS`) from the first tracked
        frame, metres². Without it the joints drift with the patches over a long walk.
    classifier : {"logistic", "svc", "none"}
        Body-part classifier sorting the observed points (§III-B); "svc" is the paper's
        linear SVM with Platt scaling, "logistic" a multinomial logistic regression (as
        accurate, faster, warm-started from the last frame), "none" the tracker without
        classification.
    keep_fraction : float
        Fraction of on-bone points kept (the speed/accuracy knob of Fig. 8; 1: all).
    part_matching : {"all", "on_bone", "none"}
        Which kept points may only correspond to patches of their predicted body part:
        every one ("all"), the on-bone ones (near-joint points, whose label is uncertain by
        Eq. 6, match any patch), or none (the classifier only selects points; Eq. 7 sums
        over every patch).
    on_bone, outlier : float
        Probability thresholds of Eq. (6) (the paper's 0.9 and 0.5).
    max_distance : float or None
        Points farther than this (metres) from the previous fitted mesh are outliers too (not
        in the paper: a linear classifier is confident far from the body, where phantom
        volumes lie); None: no distance test.
    max_points : int
        Observed points sampled from each hull before classification.
    max_iter : int
        EM iterations per frame (E-step, then one Gauss–Newton step).
    relaxation : float
        Over-relaxation of the EM (not in the paper; 1 turns it off): on a frame that is
        not fast (``fast_motion``), every Gauss–Newton step after the frame's first is
        taken this many times over. With the correspondences fixed, a step reaches its
        quadratic model's minimum, but the correspondences then move only part of the way
        with it (nearest points close a gap a fraction at a time), so the EM creeps
        towards its fixed point by nearly the same fraction each iteration; a longer step
        covers more of that way per E-step. A fast frame's steps are taken as solved:
        over-relaxed there, the steps overshoot onto wrong points (measured:
        ``docs/patch.rst``).
    tol : float
        Stop a frame's EM early when no patch moves more than this in one step (metres:
        translation plus a 10 cm lever arm times the rotation, radians).
    sigma0 : float
        σ (metres) of the E-step's Gaussians at the start of each frame: EM restarts broad,
        the new frame having moved.
    sigma_min, sigma_max : float
        Bounds (metres) of σ, re-estimated after each step from the data term's weighted
        residuals (one Gaussian per correspondence).
    outlier_sigmas : float
        Width of the outlier class of Eq. (7): a point farther than this many σ from its
        candidates is more likely an outlier than theirs (the class's likelihood is that
        of a candidate ``outlier_sigmas`` σ away).
    fast_iter_scale, fast_motion : float
        EM iterations of a fast frame, as a multiple of ``max_iter`` (1 turns it off, not in
        the paper): a frame after one where a joint moved more than ``fast_motion`` metres.
        Correspondences to the nearest points close a gap of several centimetres only a
        fraction at a time, so a fast kick outruns ``max_iter`` iterations and is lost.
    coarse_iter : int
        EM iterations at the start of each frame (added to its budget) in which the
        patches of each body part move as one rigid group (a reduced Gauss–Newton step,
        :func:`~meshmocap.trackers.patch.solver.group_basis`) before every patch moves on
        its own (not in the paper; 0 turns it off). A limb that moved far since the last
        frame is pulled back whole by the points it still reaches, instead of patch by
        patch onto the nearest wrong points.
    k_neighbours : int
        Candidate vertices per observed point (its nearest ones, among which the E-step
        keeps the nearest compatible vertex of each patch).
    damping : float
        Levenberg–Marquardt λ of the Gauss–Newton steps, relative to the diagonal (the rule
        and its floor: :mod:`meshmocap.geometry.levenberg_marquardt`).
    prediction : {"bones", "patches", "none"}
        Warm start of each frame: constant-velocity extrapolation of the joints, each patch
        carried rigidly by its bone ("bones"); of every patch transform and joint on its
        own ("patches"); or the last frame as it is ("none", the paper's frame-to-frame
        tracking). Steps are clipped.
    accel_gate : float
        With ``prediction="bones"``: a joint whose velocity changed in the last frame by
        more than this acceleration (m/s², at the capture's frame rate) and more than
        half its speed is not extrapolated (0: every joint is; not in the paper). A
        velocity that just jumped comes from an abrupt start or a fit that slipped;
        extrapolating it throws the joint further off. Off by default (``patch_gate``
        turns it on): it helps clips that start from a T-pose but leaves a runner's feet
        behind at push-off.
    interior_scale : float
        Hull points inside the model (not in the paper; 0 turns it off). A visual hull
        contains the body, so a hull point deeper than
        :data:`~meshmocap.trackers.patch.tracker.INTERIOR_MARGIN` behind the model surface
        comes from a silhouette hole (which carves a tunnel through the hull) or a model out
        of place. Each metre of depth beyond the margin counts as ``1 / interior_scale`` σ of
        distance in the E-step, so deep points fall to the outlier class.
    normal_cos : float
        Correspondences need ``n_vertex · n_point`` above this (normal compatibility).
    residual : {"point_to_point", "point_to_plane"}
        Data residuals: the paper's Euclidean distances (Eq. 7), or distances along the
        observed normals (plus a tenth of the Euclidean pull), which lets patches slide along
        the surface towards their place.
    joint_readout : {"blend", "skeleton", "surface"}
        The joints reported per frame (tracking itself always runs on the skeleton of
        Eq. 8–11). "skeleton": the paper's, bound to the patches by Ebone. "surface": read
        off the output mesh by the template's joint regressor
        (:func:`~meshmocap.body.joint_regressor.joint_regressor`). "blend" (default, not in
        the paper): per joint, the surface read-out weighted by ``f² / (f² + s²)`` and the
        skeleton by the rest, where ``f`` is the skeleton's model floor for that joint (its
        error with exact patches on the template's own training poses,
        :func:`~meshmocap.trackers.patch.model.skeleton_floor`) and ``s`` the surface
        read-out's typical error on a tracked mesh
        (:data:`~meshmocap.trackers.patch.tracker.SURFACE_JOINT_ERROR`). The pelvis and
        thorax, which no patch follows rigidly, come from the surface; the limbs mostly
        from the skeleton. Both read-outs are then moved the least that keeps the
        skeleton's bone lengths (and the hip and shoulder spans) of the first frame.
    lambda_silhouette : float
        Weight of the silhouette coverage term (not in the paper; 0 leaves it out,
        :class:`~meshmocap.trackers.patch.terms.SilhouetteTerm`; used where the capture
        has cameras and silhouettes): silhouette pixels that no model vertex covers pull
        their nearest projected vertex onto their viewing ray
        (:mod:`~meshmocap.trackers.patch.residuals`). The hull's points cannot tell a limb on
        the true surface from one in a phantom wedge beside it; the silhouettes can.
    silhouette_scale : float
        Cauchy scale (metres) of the coverage term's weights: a pixel that far from the
        model pulls half as hard (spurious blobs far from the body pull little).
    lambda_temporal : float
        Weight of the temporal prior (not in the paper; 0 leaves it out,
        :class:`~meshmocap.trackers.patch.terms.TemporalTerm`): mean squared distance of
        the joints from their constant-velocity prediction (an acceleration penalty), so
        that a limb coasts through a few frames without data.
    seed : int
        Patches and subsampling seed.
    """

    n_patches: int = 200
    joint_rigidity: float = 0.3
    lambda_data: float = 10.0
    lambda_rigid: float = 1.0
    lambda_bone: float = 1.0
    rigidity_scale: float = 10.0
    bone_scale: float = 100.0
    lambda_reverse: float = 10.0
    reverse_cap: float = 0.3
    reverse_scale: float = 0.03
    lambda_length: float = 100.0
    classifier: Classifier = "logistic"
    keep_fraction: float = 1.0
    part_matching: PartMatching = "all"
    on_bone: float = 0.9
    outlier: float = 0.5
    max_distance: float | None = 0.1
    max_points: int = 6000
    max_iter: int = 8
    relaxation: float = 1.5
    fast_iter_scale: float = 2.5
    fast_motion: float = 0.05
    tol: float = 2e-4
    sigma0: float = 0.03
    sigma_min: float = 0.005
    sigma_max: float = 0.05
    outlier_sigmas: float = 3.0
    coarse_iter: int = 0
    k_neighbours: int = 8
    interior_scale: float = 0.0
    normal_cos: float = 0.0
    residual: Residual = "point_to_point"
    damping: float = DAMPING["patch"].lam
    prediction: Prediction = "bones"
    accel_gate: float = 0.0
    joint_readout: JointReadout = "blend"
    lambda_silhouette: float = 0.0
    silhouette_scale: float = 0.05
    lambda_temporal: float = 0.0
    seed: int = 0

    #: Each option's constraint (checked by ``check_options`` in ``meshmocap._validate``).
    constraints: ClassVar[dict[str, Constraint | tuple]] = {
        "n_patches": Interval(Integral, 1, None),
        "joint_rigidity": Interval(Real, 0, None),
        "lambda_data": Interval(Real, 0, None),
        "lambda_rigid": Interval(Real, 0, None),
        "lambda_bone": Interval(Real, 0, None),
        "rigidity_scale": Interval(Real, 0, None, closed="neither"),
        "bone_scale": Interval(Real, 0, None, closed="neither"),
        "lambda_reverse": Interval(Real, 0, None),
        "reverse_cap": Interval(Real, 0, None, closed="neither"),
        "reverse_scale": Interval(Real, 0, None, closed="neither"),
        "lambda_length": Interval(Real, 0, None),
        "classifier": Options(get_args(Classifier)),
        "keep_fraction": Interval(Real, 0, 1, closed="right"),
        "part_matching": Options(get_args(PartMatching)),
        "on_bone": Interval(Real, 0, 1, closed="both"),
        "outlier": Interval(Real, 0, 1, closed="both"),
        "max_distance": (Interval(Real, 0, None, closed="neither"), None),
        "max_points": Interval(Integral, 1, None),
        "max_iter": Interval(Integral, 1, None),
        "relaxation": Interval(Real, 0, None, closed="neither"),
        "fast_iter_scale": Interval(Real, 1, None),
        "fast_motion": Interval(Real, 0, None, closed="neither"),
        "tol": Interval(Real, 0, None),
        "sigma0": Interval(Real, 0, None, closed="neither"),
        "sigma_min": Interval(Real, 0, None, closed="neither"),
        "sigma_max": Interval(Real, 0, None, closed="neither"),
        "outlier_sigmas": Interval(Real, 0, None, closed="neither"),
        "coarse_iter": Interval(Integral, 0, None),
        "k_neighbours": Interval(Integral, 1, None),
        "interior_scale": Interval(Real, 0, None),
        "normal_cos": Interval(Real, -1, 1, closed="left"),
        "residual": Options(get_args(Residual)),
        "damping": Interval(Real, 0, None),
        "prediction": Options(get_args(Prediction)),
        "accel_gate": Interval(Real, 0, None),
        "joint_readout": Options(get_args(JointReadout)),
        "lambda_silhouette": Interval(Real, 0, None),
        "silhouette_scale": Interval(Real, 0, None, closed="neither"),
        "lambda_temporal": Interval(Real, 0, None),
        "seed": Interval(Integral, 0, None),
    }

    def __post_init__(self) -> None:
        check_options("PatchOptions", self, self.constraints)
