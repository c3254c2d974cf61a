"""Settings of the patch tracker (:mod:`meshmocap.trackers.patch.tracker`)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal, get_args

from meshmocap._validate import check_choice
from meshmocap.errors import InputError

Classifier = Literal["logistic", "svc", "none"]
Residual = Literal["point_to_point", "point_to_plane"]
Prediction = Literal["bones", "patches", "none"]
PartMatching = Literal["all", "on_bone", "none"]
JointReadout = Literal["blend", "skeleton", "surface"]


@dataclass(frozen=True)
class PatchOptions:
    """Settings of the patch tracker (defaults from the paper where it gives them).

    Parameters
    ----------
    n_patches : int
        Number of surface patches (the paper uses 150–250).
    joint_rigidity : float
        Scale of Er (Eq. 2) between neighbouring patches bound to different bones (1: as
        printed). Er penalises bending away from the rest pose, so across a joint it pulls
        limbs back towards the template's pose: on perfect observations (true surfaces)
        full weight leaves 30 mm joint errors after 20 frames, 0.3 about 10 mm.
    lambda_data, lambda_rigid, lambda_bone : float
        λd, λr, λb of Eq. (1) (the paper's 10, 1, 1).
    lambda_reverse : float
        Weight of a reverse data term (not in the paper; 0 turns it off): mean squared
        distance from template vertices
        (:data:`~meshmocap.trackers.patch.tracker.REVERSE_SAMPLES` of them) to their nearest
        compatible kept observation, ignoring pairs farther than ``reverse_cap``. Eq. (7)
        only pulls patches that observations pick as candidates, so a limb that moved
        further than its neighbours' vertices in one frame (a 10 cm kick at 30 fps) is
        left in empty space; this term pulls it back onto the data. First 40 frames of
        the crane: 29.5 → 20.9 mm per vertex (right foot 151 → 17 mm, frames 20–29);
        first 150 frames of CMU 05_01: 16.9 → 14.4 mm joint error.
    reverse_cap : float
        Largest vertex-to-observation distance (metres) the reverse term uses.
    reverse_scale : float
        Scale τ (metres) of the reverse term's Cauchy weights ``1 / (1 + (d/τ)²)``: a
        vertex 3 cm from the data pulls half as hard as one on it. Holes in the
        silhouettes carve tunnels into the hull that unweighted pulls follow (degraded
        05_01, 150 frames: 31.4 mm without the term, 57.2 unweighted, 34.8 at τ = 3 cm)
        while clean data hardly notices (150 frames of 05_01: 14.4 → 14.7 mm; crane,
        40 frames: 20.9 → 21.3 mm).
    lambda_length : float
        Weight of a bone-length prior (not in the paper; 0 turns it off): mean squared
        change of each bone's length (and of the hip-to-hip and shoulder-to-shoulder
        distances, :data:`~meshmocap.trackers.patch.tracker.RIGID_PAIRS`) from the first tracked
        frame, metres². Without it the joints drift with the patches over a long walk
        (bone-length std 29 mm on 120 frames of CMU 05_01; 0.1 mm with it, and a lower
        joint error).
    classifier : {"logistic", "svc", "none"}
        Body-part classifier sorting the observed points (§III-B); "svc" is the paper's
        linear SVM with Platt scaling, "none" the tracker without classification.
    keep_fraction : float
        Fraction of on-bone points kept (the speed/accuracy knob of Fig. 8). Default 1
        (all): on CMU 05_01 (humaneva4, 299 frames) 0.5 gave 21.5 mm mean joint error and
        a 59.5 mm worst frame, 1.0 16.3 mm and 34.0 mm; fewer points are faster.
    part_matching : {"all", "on_bone", "none"}
        Which kept points may only correspond to patches of their predicted body part:
        every one ("all"), the on-bone ones (near-joint points, whose label is uncertain by
        Eq. 6, match any patch), or none (the classifier only selects points; Eq. 7 sums
        over every patch).
    on_bone, outlier : float
        Probability thresholds of Eq. (6).
    max_distance : float or None
        Points farther than this (metres) from the previous fitted mesh are outliers too (a
        linear classifier is confident far from the body, where phantom volumes lie).
    max_points : int
        Observed points sampled from each hull before classification.
    max_iter : int
        EM iterations per frame; ``tol`` (metres): stop when no vertex moves more.
    fast_iter_scale, fast_motion : float
        EM iterations of a fast frame, as a multiple of ``max_iter`` (1 turns it off): a
        frame after one where a joint moved more than ``fast_motion`` metres.
        Correspondences to the nearest points close a gap of several centimetres only a
        fraction at a time, so a kick at 30 fps (12 cm per frame) outruns 10 iterations
        and is lost. Twice as many on fast frames: the crane (real data, 30 fps, 87 % of
        its frames fast) 35.6 → 31.2 mm per vertex (right foot in its last kick 163 → 30
        mm); CMU 09_01 (a run at 60 fps, all frames fast; 20 iterations throughout) 12.5 →
        11.2 mm, worst frame 26.2 → 17.8 mm. Slow captures hardly pay: 16 % of CMU 05_01's
        frames are fast, 2 % of 01_01's.
    coarse_iter : int
        EM iterations at the start of each frame (added to its budget) in which the
        patches of each body part move as one rigid group (a reduced Gauss–Newton step,
        :func:`~meshmocap.trackers.patch.solver.group_basis`) before every patch moves on
        its own; 0 turns it off. A limb that moved far since the last frame is pulled back
        whole by the points it still reaches, instead of patch by patch onto the nearest
        wrong points. (Matching every kept point freely in these iterations, as
        articulated ICP does, instead of by the classifier's parts: CMU 08_05 from its
        T-pose, with ``accel_gate=72``, 11.7 → 43.7 mm.)
    k_neighbours : int
        Candidate vertices per observed point.
    damping : float
        Levenberg–Marquardt damping of the Gauss–Newton steps (relative to the diagonal).
    prediction : {"bones", "patches", "none"}
        Warm start of each frame: constant-velocity extrapolation of the joints, each patch
        carried rigidly by its bone ("bones"); of every patch transform and joint on its
        own ("patches"); or the last frame as it is ("none"). Steps are clipped.
    accel_gate : float
        With ``prediction="bones"``: a joint whose velocity changed in the last frame by
        more than this acceleration (m/s², at the capture's frame rate) and more than
        half its speed is not extrapolated (0: every joint is). A velocity that just jumped
        comes from an abrupt start or a fit that slipped; extrapolating it throws the joint
        further off. Off by default: at 72 m/s² (``--method patch_gate``) clips that start
        from a T-pose gain (60 frames at 60 fps, 4 cameras, ``benchmarks/sweep_patch.py``:
        CMU 13_32 31.8 → 21.5 mm, 08_05 55.1 → 11.7 mm; without it the left forearm is
        thrown 0.5 m at frame 2 and then gets all its data from phantom volumes and other
        parts' points), but a run loses its feet (09_01: 11.9 → 34.5 mm, the right ankle
        up to 94 mm off for 25 frames: a foot's push-off exceeds the gate, and without
        its prediction the foot is left behind) and the held-out 05_03 loses (24.6 →
        31.0). In metres per frame² it would also gate ordinary motion at 30 fps.
    interior_scale : float
        Hull points inside the model (not in the paper; 0 turns it off). A visual hull
        contains the body, so a hull point deeper than
        :data:`~meshmocap.trackers.patch.tracker.INTERIOR_MARGIN` behind the model surface comes
        from a silhouette hole (which carves a tunnel through the hull: 16 % of the hull
        points of CMU 05_01 with the ``degraded`` silhouettes lie over 1 cm inside the
        true body, none with clean ones) or a model out of place. Each metre of depth
        beyond the margin counts as ``1 / interior_scale`` σ of distance in the E-step,
        so deep points fall to the outlier class.
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
        (:func:`~meshmocap.body.joint_regressor.joint_regressor`). "blend" (default): per
        joint, the surface read-out weighted by ``f² / (f² + s²)`` and the skeleton by the
        rest, where ``f`` is the skeleton's model floor for that joint (its error with
        exact patches on the template's own training poses,
        :func:`~meshmocap.trackers.patch.model.skeleton_floor`) and ``s`` the surface
        read-out's typical error on a tracked mesh
        (:data:`~meshmocap.trackers.patch.tracker.SURFACE_JOINT_ERROR`). The pelvis and thorax,
        which no patch follows rigidly (floors 30–40 mm), come from the surface; the
        limbs mostly from the skeleton. Both read-outs are then moved the least that keeps
        the skeleton's bone lengths (and the hip and shoulder spans) of the first frame.
    lambda_silhouette : float
        Weight of the silhouette coverage term (not in the paper; 0 turns it off; used
        where the capture has cameras and silhouettes): silhouette pixels that no model
        vertex covers pull their nearest projected vertex onto their viewing ray
        (:mod:`~meshmocap.trackers.patch.terms`). The hull's points cannot tell a limb on
        the true surface from one in a phantom wedge beside it; the silhouettes can.
    silhouette_scale : float
        Cauchy scale (metres) of the coverage term's weights: a pixel that far from the
        model pulls half as hard (spurious blobs far from the body pull little).
    lambda_temporal : float
        Weight of the temporal prior (not in the paper; 0 turns it off): mean squared
        distance of the joints from their constant-velocity prediction (an acceleration
        penalty), so that a limb coasts through a few frames without data.
    seed : int
        Patches and subsampling seed.
    """

    n_patches: int = 200
    joint_rigidity: float = 0.3
    lambda_data: float = 10.0
    lambda_rigid: float = 1.0
    lambda_bone: float = 1.0
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
    max_iter: int = 10
    fast_iter_scale: float = 2.0
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
    damping: float = 1e-4
    prediction: Prediction = "bones"
    accel_gate: float = 0.0
    joint_readout: JointReadout = "blend"
    lambda_silhouette: float = 0.0
    silhouette_scale: float = 0.05
    lambda_temporal: float = 0.0
    seed: int = 0

    def __post_init__(self) -> None:
        check_choice("PatchOptions", "classifier", self.classifier, get_args(Classifier))
        check_choice("PatchOptions", "residual", self.residual, get_args(Residual))
        check_choice("PatchOptions", "prediction", self.prediction, get_args(Prediction))
        check_choice("PatchOptions", "part_matching", self.part_matching, get_args(PartMatching))
        check_choice("PatchOptions", "joint_readout", self.joint_readout, get_args(JointReadout))
        if self.n_patches < 1:
            raise InputError(f"PatchOptions: n_patches must be ≥ 1, found {self.n_patches}")
        if not self.lambda_reverse >= 0:  # also rejects NaN
            raise InputError(
                f"PatchOptions: lambda_reverse must be ≥ 0, found {self.lambda_reverse}"
            )
        if self.coarse_iter < 0:
            raise InputError(f"PatchOptions: coarse_iter must be ≥ 0, found {self.coarse_iter}")
        if self.max_iter < 1:
            raise InputError(f"PatchOptions: max_iter must be ≥ 1, found {self.max_iter}")
        if not self.fast_iter_scale >= 1:
            raise InputError(
                f"PatchOptions: fast_iter_scale must be ≥ 1, found {self.fast_iter_scale}"
            )
        for name in ("lambda_silhouette", "lambda_temporal", "accel_gate", "interior_scale"):
            if not getattr(self, name) >= 0:  # also rejects NaN
                raise InputError(f"PatchOptions: {name} must be ≥ 0, found {getattr(self, name)}")
        for name, unit in (
            ("outlier_sigmas", ""),
            ("fast_motion", " metres"),
            ("reverse_cap", " metres"),
            ("reverse_scale", " metres"),
            ("silhouette_scale", " metres"),
        ):
            if not getattr(self, name) > 0:  # also rejects NaN
                raise InputError(
                    f"PatchOptions: {name} must be > 0{unit}, found {getattr(self, name)}"
                )
        if not 0 < self.keep_fraction <= 1:
            raise InputError(
                f"PatchOptions: keep_fraction must be in (0, 1], found {self.keep_fraction}"
            )
