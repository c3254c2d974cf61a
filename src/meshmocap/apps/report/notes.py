"""What a report says next to its numbers: why frames were not scored or were flagged, why a
value is missing, what a column means, and when a value is fixed by construction.

Plain strings and rows for :mod:`meshmocap.apps.report.page`'s tables.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from meshmocap.analysis.evaluate import Evaluation
from meshmocap.io.results import FRAME_FLAGS, Track, two_way_changes

#: Why a frame carries a flag (:data:`meshmocap.io.results.FRAME_FLAGS`), when the track's
#: own message is empty.
FLAG_REASONS = {
    "failed": "the fit raised a numerical error or gave non-finite values; the frame repeats "
    "the last good result",
    "missing": "the capture has no usable observation of the frame (dropped frame, empty "
    "hull); the tracker coasted across it",
    "lost": "the fit fell below the tracker's quality threshold",
    "reinit": "the tracker re-initialised the body or some limbs here",
}
#: Why frames were changed by the two-way pass (then where from, per stretch).
TWO_WAY_REASON = (
    "the forward pass had a limb lost there; replaced by a track from a whole-body search "
    "at a later or nearby keyframe, which the evidence preferred: "
)
OUT_OF_VIEW = (
    "the subject's true surface leaves a camera's image, so the visual hull is truncated "
    "there: the frames are not scored, rather than blamed on the tracker"
)
WORST_FRAME = (
    "worst frame: the frame with the largest mean error over the 15 joints (its mean error, "
    "and its position, counted from the track's first frame)"
)


def frame_ranges(frames: Sequence[int] | np.ndarray, *, limit: int = 12) -> str:
    """``"3–7, 12, 40–41"``: consecutive frame numbers as ranges (the first ``limit``)."""
    f = np.unique(np.asarray(frames, dtype=np.int64))
    if not len(f):
        return ""
    cut = np.flatnonzero(np.diff(f) != 1) + 1
    parts = [f"{r[0]}–{r[-1]}" if len(r) > 1 else f"{r[0]}" for r in np.split(f, cut)]
    more = f", … ({len(parts) - limit} more)" if len(parts) > limit else ""
    return ", ".join(parts[:limit]) + more


def frame_rows(ev: Evaluation, track: Track | None = None) -> list[tuple[str, int, str, str]]:
    """Rows (what, frame count, frames, why) of the frames an evaluation did not score and
    of the frames the track flagged; empty when every frame was scored and none flagged."""
    rows = []
    if len(ev.out_of_view):
        rows.append(
            (
                "not scored: out of view",
                len(ev.out_of_view),
                frame_ranges(ev.out_of_view),
                OUT_OF_VIEW,
            )
        )
    for r in (ev.joints, ev.correspondence):
        if r is not None and len(r.failed):
            why = "the track's joints or vertices are not finite there"
            rows.append(("not scored: failed", len(r.failed), frame_ranges(r.failed), why))
            break
    if track is not None and track.flags:
        for flag in FRAME_FLAGS:
            k = [i for i, f in enumerate(track.flags) if flag in f]
            if not k:
                continue
            said = list(dict.fromkeys(track.messages[i] for i in k if track.messages[i]))
            why = "; ".join(said[:3]) + (f"; … ({len(said) - 3} more)" if len(said) > 3 else "")
            rows.append(
                (
                    f"flagged: {flag}",
                    len(k),
                    frame_ranges(track.frames[k]),
                    why or FLAG_REASONS[flag],
                )
            )
    changed = two_way_changes(track.meta) if track is not None else {}
    k = [i for i, f in enumerate(track.frames.tolist()) if f in changed] if changed else []
    if k:
        said = list(dict.fromkeys(changed[int(track.frames[i])] for i in k))
        rows.append(
            (
                "changed: two-way pass",
                len(k),
                frame_ranges(track.frames[k]),
                TWO_WAY_REASON
                + "; ".join(said[:3])
                + (f"; … ({len(said) - 3} more)" if len(said) > 3 else ""),
            )
        )
    return rows


def bone_note(ev: Evaluation) -> str:
    """Why some bones' length spread is 0.0 (fixed by the tracker, not measured), or ``""``."""
    b = ev.bones
    if b is None:
        return ""
    fixed = [n for n, s in zip(b.names, b.std, strict=True) if s < 0.05]
    if not fixed:
        return ""
    if ev.method.startswith("patch"):
        how = (
            "the patch tracker's joint read-out keeps the bone lengths of its skeleton, set "
            "at the first frame, so they cannot vary"
        )
    elif ev.method == "articulated_icp":
        how = "articulated ICP moves a skeleton of rigid bones, so their lengths cannot vary"
    else:
        how = "this tracker keeps those bones' lengths fixed"
    which = "every bone" if len(fixed) == len(b.names) else f"{len(fixed)} of {len(b.names)} bones"
    return (
        f"std 0.0 for {which} by construction, not a bug: {how}. The spread measures "
        "nothing there; the joint errors show the accuracy."
    )


def silhouette_note(evaluations: Sequence[Evaluation], why: str) -> str:
    """Why the silhouette column reads n/a (``why``: the reason the caller knows), or ``""``."""
    if all(ev.silhouettes is not None for ev in evaluations):
        return ""
    return f"silhouette (%): n/a: not measured, {why}."
