"""Score a track against its capture: joints, bones, silhouettes, surfaces, correspondences.

Protocol (stated in every report): joint errors are Euclidean distances between tracked
and true evaluation joints (15 joints, and the 14-joint variant without the pelvis of the
patch-tracking paper); bone lengths are over the tracked skeleton; the silhouette overlap
error re-projects the tracked mesh into every camera and compares it with the *input*
silhouettes (Table II); surface distances compare the tracked mesh with the true surface
(synthetic captures), with the visual hull (a capture folder without truth) or with the
input meshes themselves (a folder of mesh files: a 4D capture) on evenly spaced frames; the
per-vertex error needs a template with the subject's connectivity (a synthetic capture's
truth, or a mesh sequence of fixed connectivity whose own first frame was rigged: each
tracked vertex against the same vertex of the file). Joints and vertices are
scored only on frames where the true surface lies inside every camera's image: a subject
leaving the studio (a CMU walk or run crosses 4–5 m) leaves a truncated hull, and those
frames are listed as out of view rather than blamed on the tracker.

References
----------
- C.-H. Huang, E. Boyer, S. Ilic, *Robust human body shape and pose tracking*,
  International Conference on 3D Vision (3DV), 2013.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from meshmocap.analysis.metrics import (
    BoneLengths,
    CorrespondenceErrors,
    JointErrors,
    SilhouetteErrors,
    Stats,
    bone_length_stats,
    correspondence_error,
    joint_errors,
    mesh_silhouette_errors,
    surface_distance,
)
from meshmocap.analysis.tables import format_table, table
from meshmocap.errors import FormatError, InputError, MeshError, MeshmocapFileNotFoundError
from meshmocap.estimate.pose.start import start_description
from meshmocap.geometry.camera import in_view
from meshmocap.io.capture import Capture, SequenceCapture, SequenceFrame, Truth
from meshmocap.io.results import Track, template_label
from meshmocap.io.start import Start


@dataclass(frozen=True)
class SurfaceErrors:
    """Two-sided surface distances on sampled frames, millimetres.

    Attributes
    ----------
    frames : (S,) frame numbers
    against : ``"truth"``, ``"hull"`` (a capture folder's visual hulls) or ``"input meshes"``
        (the mesh files tracked: a 4D capture)
    mean, hausdorff : (S,) symmetric mean distance and sampled Hausdorff distance per frame
    """

    frames: np.ndarray
    against: str
    mean: np.ndarray
    hausdorff: np.ndarray


@dataclass(frozen=True, eq=False)
class Evaluation:
    """Everything :func:`evaluate` measured; absent parts are None (no truth, no cameras)."""

    method: str
    n_frames: int
    unhealthy: int
    seconds: Stats
    joints: JointErrors | None
    joints14: JointErrors | None
    bones: BoneLengths | None
    silhouettes: SilhouetteErrors | None
    surface: SurfaceErrors | None
    correspondence: CorrespondenceErrors | None
    out_of_view: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    #: How the track's first pose was found (:func:`track_init`: in words, from its
    #: record, which ``start`` holds: :attr:`~meshmocap.io.results.Track.start`, None where
    #: the track does not record it), and its frames flagged ``lost`` and ``reinit``.
    init: str = ""
    lost: int = 0
    reinit: int = 0
    template: str = ""
    start: Start | None = None
    #: What the cage was built on (``track.json``'s ``cage_body``: ``"template"``, the
    #: performer's own surface, or ``"reference"``, the reference body bound to it); empty
    #: for the other trackers.
    cage_body: str = ""


def track_init(track: Track) -> str:
    """How a track's first pose was found, in words, from its start record
    (:func:`~meshmocap.estimate.pose.start.start_description`: ``"truth: …"``, or
    ``"auto: …"`` with the search's winner). A track that does not record its start (made
    before starts were recorded) says only how it was asked to start (``track.json``'s
    ``init``; tracks made before ``init`` existed started from ground truth) and that the
    start is unknown: nothing is read out of its messages."""
    if track.start is not None:
        return start_description(track.start)
    return f"{track.meta.get('init', 'truth')} (start {start_description(None)})"


def evaluate(
    track: Track,
    capture: Capture,
    *,
    silhouettes: bool = True,
    surface_frames: int = 8,
    surface_samples: int = 5000,
    in_view_only: bool = True,
) -> Evaluation:
    """Evaluate ``track`` on ``capture`` (see the module docstring for the protocol).

    Parameters
    ----------
    silhouettes : bool
        Compute the silhouette overlap error (renders every frame in every camera).
    surface_frames : int
        Frames (evenly spaced) on which surface distances are sampled; 0 to skip.
    surface_samples : int
        Samples per direction and frame.
    in_view_only : bool
        Score joints and correspondences only on frames whose true surface lies inside
        every camera's image (a subject running out of the studio leaves a truncated hull);
        the others are listed in ``Evaluation.out_of_view`` and counted as skipped.
    """
    tracked = set(track.frames.tolist())
    frames = [_frame(capture, k) for k, i in enumerate(capture.indices) if i in tracked]
    if len(frames) != len(track.frames):
        missing = sorted(set(track.frames.tolist()) - set(capture.indices))
        raise InputError(
            f"evaluate: track frames {missing[:5]} are not in the capture {capture.path}"
        )
    truths = [f.truth for f in frames]
    if all(t is None for t in truths):  # a 4D mesh sequence: its files are the truth
        truths = _file_truths(frames, track) or truths
    hidden = out_of_view_frames(truths, capture.cameras) if in_view_only else np.zeros(0, np.int64)
    for k in hidden:  # scored as skipped frames (truth NaN): the cameras did not see it all
        truths[k] = replace(
            truths[k],
            vertices=np.full_like(truths[k].vertices, np.nan),
            joints=None if truths[k].joints is None else np.full_like(truths[k].joints, np.nan),
        )
    have_joints = all(t is not None and t.joints is not None for t in truths)
    names = track.meta.get("eval_names")
    parents = track.meta.get("eval_parents")
    je = je14 = bones = corr = None
    if have_joints and names:
        true_J = np.stack([t.joints for t in truths])
        je = joint_errors(track.joints, true_J, names=names)
        je14 = je.excluding("pelvis") if "pelvis" in names else None
    if names and parents and len(names) > 1:
        bones = bone_length_stats(track.joints, parents, names=names)
    if all(t is not None for t in truths) and track.vertices.shape[1] == len(truths[0].vertices):
        corr = correspondence_error(track.vertices, np.stack([t.vertices for t in truths]))
    sil = None
    if silhouettes and capture.cameras:
        meshes = ((V, track.faces) for V in track.vertices)
        sil = mesh_silhouette_errors(
            meshes, (f.silhouettes for f in frames), capture.cameras, skip=hidden
        )
    surf = None
    F_true = capture.truth_faces
    against = "truth" if F_true is not None and all(t is not None for t in truths) else "hull"
    if against == "hull" and isinstance(capture, SequenceCapture):
        against = "input meshes"  # the files themselves, not a hull carved from images
    usable = _surface_frames(frames, truths, against)
    usable = usable[np.isfinite(track.vertices[usable]).all(axis=(1, 2))]  # not a failed fit
    if surface_frames > 0 and len(usable):
        pick = np.linspace(0, len(frames) - 1, min(surface_frames, len(frames))).round()
        # a pick the cameras did not see (or without hull) moves to the nearest usable frame
        nearest = np.abs(usable[None, :] - pick.astype(int)[:, None]).argmin(axis=1)
        pick = np.unique(usable[nearest])
        means, hd = [], []
        for k in pick:
            Vb, Fb = (truths[k].vertices, F_true) if against == "truth" else frames[k].hull_mesh
            d = surface_distance(
                track.vertices[k], track.faces, Vb, Fb, n_samples=surface_samples, seed=int(k)
            )
            means.append(d.mean * 1e3)
            hd.append(d.hausdorff * 1e3)
        surf = SurfaceErrors(track.frames[pick], against, np.array(means), np.array(hd))
    steady = track.seconds[1:] if len(track.seconds) > 1 else track.seconds  # frame 0: init
    return Evaluation(
        method=str(track.meta.get("method", "?")),
        n_frames=len(track.frames),
        unhealthy=int((~track.healthy).sum()),
        seconds=Stats.of(steady),
        joints=je,
        joints14=je14,
        bones=bones,
        silhouettes=sil,
        surface=surf,
        correspondence=corr,
        out_of_view=track.frames[hidden] if len(hidden) else np.zeros(0, np.int64),
        init=track_init(track),
        start=track.start,
        lost=sum("lost" in f for f in track.flags),
        reinit=sum("reinit" in f for f in track.flags),
        template=template_label(track.meta),
        cage_body=str(track.meta.get("cage_body", "")),
    )


def _frame(capture, k: int):
    """Frame position ``k`` of ``capture``; a mesh file that cannot be read is a frame
    without observation (``missing`` names the file and why), as the track skipped it."""
    try:
        return capture[k]
    except (MeshmocapFileNotFoundError, FormatError, MeshError) as exc:
        why = (str(exc).splitlines() or ["unreadable"])[0]
        return SequenceFrame(int(capture.indices[k]), (np.zeros((0, 3)), None), None, missing=why)


def _file_truths(frames: list, track: Track) -> list[Truth] | None:
    """Each frame's file vertices as its truth, where the files are a mesh sequence of the
    tracked template's connectivity (a 4D capture whose first frame was rigged as it
    stands: tracked vertex ``i`` is the file's vertex ``i``); a missing frame's vertices are
    NaN (not scored). None where the connectivity differs (hulls, point clouds, another
    template)."""
    n = track.vertices.shape[1]
    out = []
    for f in frames:
        if getattr(f, "missing", None):
            out.append(None)
            continue
        V, F = f.hull_mesh
        if F is None or len(V) != n or not np.array_equal(F, track.faces):
            return None
        out.append(Truth(np.asarray(V, np.float64)))
    if all(t is None for t in out):
        return None
    nan = np.full((n, 3), np.nan)
    return [Truth(nan) if t is None else t for t in out]


def _surface_frames(frames: list, truths: list, against: str) -> np.ndarray:
    """Positions of the frames whose surface can be compared: the truth in view (not set to
    NaN), or a hull mesh that exists (not a dropped frame, not a point cloud)."""
    if against == "truth":
        ok = [np.isfinite(t.vertices).all() for t in truths]
    else:
        ok = [getattr(f, "missing", None) is None and f.hull_mesh[1] is not None for f in frames]
    return np.flatnonzero(ok)


def out_of_view_frames(truths: list, cameras: list) -> np.ndarray:
    """(k,) int64: positions in ``truths`` of frames whose true surface leaves an image of
    ``cameras`` (or passes behind one): a hull of a partly seen subject is not a fair test."""
    if not cameras:
        return np.zeros(0, np.int64)
    out = [
        k for k, t in enumerate(truths) if t is not None and not in_view(t.vertices, cameras).all()
    ]
    return np.asarray(out, dtype=np.int64)


#: ``track.json``'s ``cage_body`` in words.
_BODIES = {"template": "performer's template", "reference": "reference body"}


def summary(ev: Evaluation) -> str:
    """A short plain-text report of an evaluation."""
    out = [
        f"method {ev.method}, template {ev.template}: {ev.n_frames} frames, "
        f"{ev.unhealthy} flagged unhealthy, "
        f"{ev.seconds.mean:.3f} s per frame (median {ev.seconds.median:.3f})"
    ]
    if ev.init:
        out[0] += f"; init {ev.init}"
    if ev.cage_body:
        out[0] += f"; cage built on the {_BODIES.get(ev.cage_body, ev.cage_body)}"
    if ev.lost:
        out[0] += f"; {ev.lost} frames with a limb lost ({ev.reinit} re-initialised)"
    if len(ev.out_of_view):
        f = ev.out_of_view
        out.append(
            f"{len(f)} frames not scored: the subject leaves a camera's view "
            f"(frames {f[0]}..{f[-1]})"
        )
    if ev.joints is not None:
        out.append(table(ev.joints))
        if ev.joints14 is not None:
            o = ev.joints14.overall
            out.append(
                f"14 joints (no pelvis): mean {o.mean:.1f} mm, median {o.median:.1f}, "
                f"std {o.std:.1f}, max {o.max:.1f}"
            )
    if ev.bones is not None:
        out.append(table(ev.bones))
    if ev.silhouettes is not None:
        out.append(table(ev.silhouettes))
    if ev.surface is not None:
        s = ev.surface
        rows = [[int(f), m, h] for f, m, h in zip(s.frames, s.mean, s.hausdorff, strict=True)]
        rows.append(["mean", float(s.mean.mean()), float(s.hausdorff.mean())])
        out.append(
            format_table(
                ["frame", "mean (mm)", "hausdorff (mm)"],
                rows,
                digits=1,
                title=f"Surface distance to the {s.against}, mm",
            )
        )
    if ev.correspondence is not None:
        out.append(table(ev.correspondence))
    return "\n\n".join(out)
