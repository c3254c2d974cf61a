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
   capture (:func:`~meshmocap.estimate.subject.estimate_subject`) and cached as
   ``subject.npz`` in the track folder: a resumed run reuses it.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

from meshmocap.body.template import Template, load_template, save_template
from meshmocap.estimate.capture_cache import cached_subject
from meshmocap.estimate.subject import estimate_subject

__all__ = ["SUBJECT_FILE", "TemplateChoice", "tracking_template"]

#: The estimated subject's file in a track folder.
SUBJECT_FILE = "subject.npz"


@dataclass(frozen=True, eq=False)
class TemplateChoice:
    """The tracking template and how it was chosen.

    Attributes
    ----------
    template : Template
    info : dict, for ``track.json`` (``template_source``: ``"given"``, ``"capture"`` or
        ``"estimated"``; ``template_file`` for an estimated one)
    note : str, one line for the user
    """

    template: Template
    info: dict
    note: str


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
    kind : {"auto", "hull", "mesh"}
        How to estimate (:func:`~meshmocap.estimate.subject.estimate_subject`).
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
    info = {"template_source": "estimated", "template_file": SUBJECT_FILE}
    if path.is_file() and not refresh:
        t = load_template(path)
        return TemplateChoice(t, info, f"template estimated from the capture, reused from {path}")
    # estimated once per capture and cached with it (meshmocap.estimate.capture_cache)
    est = cached_subject(capture, kind=kind, estimate=estimate_subject, refresh=refresh)
    path.parent.mkdir(parents=True, exist_ok=True)
    save_template(path, est.template)
    # tracked as read back from the file, as a resumed run will read it: the same template
    # to the bit, so the resumed run's settings (a cage manifold's digest) are the same
    t = load_template(path)
    note = (
        f"template estimated from the capture ({est.kind} kind, frames "
        f"{', '.join(map(str, est.frames))}; height {est.height:.3f} m; "
        f"{est.seconds:.0f} s): {path}"
    )
    return TemplateChoice(t, info, note)
