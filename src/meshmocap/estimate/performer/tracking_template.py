"""Which body a capture is tracked with (the template defaults of ``meshmocap track``).

In order:

1. a template the caller names (``--template NAME|FILE``) is used as it is; a capture whose
   ``capture.json`` names another one gets a note saying so (never silently);
2. ``"auto"`` forces the estimate (3);
3. otherwise, a capture made for a template (a synthetic capture: ``capture.json``'s
   ``spec.template``) is tracked with that template, and the note says so: the capture was
   made to be tracked with it (the papers' protocol, where the performer is the template,
   or a deliberate mismatch), and tracking it with another body silently would change the
   experiment;
4. otherwise (a real capture, a mesh folder) the performer's body is estimated from the
   capture and cached as ``subject.npz`` in the track folder: a resumed run reuses it. How
   depends on what the frames are (:func:`frames_kind`):

   * ``"hull"``: a studio capture (cameras and silhouettes): the shape space fitted to
     the silhouettes (:func:`~meshmocap.estimate.performer.subject.estimate_subject`);
   * ``"mesh"``: closed 2-manifold meshes of one connectivity in every frame (a clean 4D
     capture): the first frame rigged as it stands;
   * ``"points"``: anything else without cameras (visual hulls, never quite manifold,
     holed meshes, meshes whose connectivity changes, point clouds): the shape space
     fitted to the points (:func:`~meshmocap.estimate.performer.point_subject.fit_body_to_points`).

   A template made from a frame knows that frame's pose (the rest pose of a rigged first
   frame, the pose fitted with the body to the points or to the silhouettes):
   :attr:`TemplateChoice.start` holds it (kept beside the template as
   ``subject_pose.npz``). Where that frame is the first tracked, tracking starts there
   instead of searching; on a studio capture the search runs too and the better of the
   two by the silhouettes' evidence is kept (:mod:`~meshmocap.estimate.performer.first_frame`).
"""

from __future__ import annotations

import json
import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from meshmocap._atomic import atomic_open
from meshmocap._threads import blas_threads
from meshmocap._validate import check_choice
from meshmocap.body.template import Template, load_template, save_template
from meshmocap.estimate.performer.capture_cache import cached_subject
from meshmocap.estimate.performer.point_subject import fit_body_to_points, readable_frame
from meshmocap.estimate.performer.subject import estimate_subject, subject_kind
from meshmocap.geometry.mesh import mesh_problems
from meshmocap.io.start import Start, start_json, start_of_json

__all__ = [
    "FRAME_KINDS",
    "POSE_FILE",
    "SUBJECT_FILE",
    "TemplateChoice",
    "frames_kind",
    "tracking_template",
]

#: The estimated subject's file in a track folder.
SUBJECT_FILE = "subject.npz"
#: The pose of the frame the subject was estimated from, beside it.
POSE_FILE = "subject_pose.npz"
#: How a subject may be estimated (:func:`frames_kind`), and ``"auto"``.
FRAME_KINDS = ("auto", "hull", "mesh", "points")
#: What each kind of estimate does, for the user.
_HOW = {
    "hull": "the shape space fitted to the silhouettes",
    "mesh": "closed meshes of one connectivity (a clean 4D capture): the first frame rigged "
    "as it stands",
    "points": "hulls or points (not closed meshes of one connectivity): the shape space "
    "fitted to the points",
}


@dataclass(frozen=True, eq=False)
class TemplateChoice:
    """The tracking template and how it was chosen.

    Attributes
    ----------
    template : Template
    info : dict, for ``track.json`` (``template_source``: ``"given"``, ``"capture"`` or
        ``"estimated"``; ``template_file`` for an estimated one)
    note : str, one line for the user
    start : Start or None, the pose of the frame an estimated template was made from
        (module docstring; source ``"subject-rest"`` or ``"subject-fit"``)
    """

    template: Template
    info: dict
    note: str
    start: Start | None = None


def frames_kind(capture) -> str:
    """How the performer's body is estimated from ``capture`` (module docstring, 4):
    ``"hull"`` with cameras and silhouettes, else ``"mesh"`` where the first frame is a
    closed 2-manifold mesh and the second and last frames have its connectivity, else
    ``"points"``."""
    if subject_kind(capture) == "hull":
        return "hull"
    pos = next((k for k in range(len(capture)) if readable_frame(capture, k)), None)
    if pos is None:
        return "points"
    V, F = capture[pos].hull_mesh
    if F is None or mesh_problems(V, F):
        return "points"
    for k in sorted({min(pos + 1, len(capture) - 1), len(capture) - 1} - {pos}):
        other = readable_frame(capture, k)  # an unreadable frame is the driver's missing one
        if other is None:
            continue
        V2, F2 = other.hull_mesh
        if F2 is None or len(V2) != len(V) or not np.array_equal(F2, F):
            return "points"
    return "mesh"


def _points_body(capture, *, kind: str):
    """:func:`~meshmocap.estimate.performer.point_subject.fit_body_to_points` in the signature of
    :func:`~meshmocap.estimate.performer.capture_cache.cached_subject`'s estimators."""
    return fit_body_to_points(capture)


def _save_start(path: Path, start: Start) -> None:
    with atomic_open(path) as f:
        np.savez(f, start=np.str_(json.dumps(start_json(start))))


def _load_start(path: Path) -> Start | None:
    """The start kept beside a cached subject, or None (absent, unreadable, or written
    before starts were records: search)."""
    try:
        with np.load(path, allow_pickle=False) as z:
            return start_of_json(json.loads(str(z["start"])), str(path))
    except (OSError, ValueError, KeyError, EOFError):  # FormatError is a ValueError
        return None


def _named_by(capture) -> str | None:
    spec = getattr(capture, "meta", {}).get("spec") or {}
    name = spec.get("template")
    return str(name) if name else None


def tracking_template(
    capture,
    template: str | os.PathLike | None,
    out: str | os.PathLike,
    *,
    refresh: bool = False,
    kind: str = "auto",
) -> TemplateChoice:
    """Choose the template to track ``capture`` with (module docstring).

    Parameters
    ----------
    capture : Capture or SequenceCapture
    template : str or path or None
        A bundled name or ``.npz`` file; ``"auto"`` to estimate; None for the default.
    out : path
        The track folder (where an estimated subject is cached).
    refresh : bool
        Estimate again even when the track folder holds one (a restarted track).
    kind : {"auto", "hull", "mesh", "points"}
        How to estimate (module docstring; ``"auto"``: :func:`frames_kind`).
    """
    named = _named_by(capture)
    if template is not None and os.fspath(template) != "auto":
        t = load_template(template)
        note = f"template {t.name!r} (given)"
        if named is not None and named != os.fspath(template):
            note += f"; note: capture.json says this capture was made for {named!r}"
        return TemplateChoice(t, {}, note)
    if template is None and named is not None:
        t = load_template(named)
        note = (
            f"template {t.name!r}, the one capture.json names (--template NAME|FILE to "
            "use another, --template auto to estimate the performer's body)"
        )
        return TemplateChoice(t, {"template_source": "capture"}, note)
    path = Path(out) / SUBJECT_FILE
    pose_path = Path(out) / POSE_FILE
    info = {"template_source": "estimated", "template_file": SUBJECT_FILE}
    if path.is_file() and not refresh:
        t = load_template(path)
        start = _load_start(pose_path)
        note = f"template estimated from the capture, reused from {path}"
        return TemplateChoice(t, info, note, start)
    check_choice("tracking_template", "kind", kind, FRAME_KINDS)
    chosen = frames_kind(capture) if kind == "auto" else kind
    # estimated once per capture and cached for it (meshmocap.estimate.performer.capture_cache);
    # hull and mesh: estimate_subject's own choice ("auto") is frames_kind's
    # one BLAS (and k-d tree OpenMP) thread, as the commands and the tracking driver run
    # (meshmocap._threads): a caller of the Python API (a benchmark, a notebook) otherwise
    # estimates with every pool spinning on a shared machine
    with blas_threads():
        if chosen == "points":
            est = cached_subject(capture, kind="points", estimate=_points_body, refresh=refresh)
        else:
            est = cached_subject(capture, kind=kind, estimate=estimate_subject, refresh=refresh)
    path.parent.mkdir(parents=True, exist_ok=True)
    save_template(path, est.template)
    # the first fitted frame's own pose (hull: a candidate the search competes with,
    # meshmocap.estimate.performer.first_frame)
    R, root = est.R[0], est.root[0]
    if est.kind == "mesh":  # rigged as it stands: rest rotations at the rest root
        R = np.tile(np.eye(3), (est.template.skeleton.n_joints, 1, 1))
        root = est.template.skeleton.rest_positions[0]
    source = "subject-rest" if est.kind == "mesh" else "subject-fit"
    start = Start(int(est.frames[0]), R, root, source)
    _save_start(pose_path, start)
    # tracked as read back from the file, as a resumed run will read it: the same template
    # to the bit, so the resumed run's settings (a cage manifold's digest) are the same
    t = load_template(path)
    note = (
        f"template estimated from the capture: {_HOW.get(est.kind, est.kind)} (frames "
        f"{', '.join(map(str, est.frames))}; height {est.height:.3f} m; "
        f"{est.seconds:.0f} s): {path}"
    )
    return TemplateChoice(t, info, note, start)
