"""Is the input what it claims to be? Checks that turn silent nonsense into one line.

* Silhouettes: the subject fills a minority of each image, and about as much in every
  camera of a frame. Masks drawn the other way round (the subject black on white) fill
  most of the image and carve a hull of the whole studio, metres across
  (:func:`mask_problems`).
* An observation (a hull or a mesh frame): a person fits in a box a few metres across
  (:func:`observation_problem`).
* A body: a mesh ``subject`` rigs or fits is human-like when it stands 0.8–2.5 m tall and
  fills a small part of its bounding box: limbs leave most of it empty, where a sphere
  fills 52 % and a box all of it (:func:`body_problem`).

Every check returns ``None`` when nothing is wrong, else the reason in a few words; the
caller decides whether that is a warning, a flagged frame or a refusal.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from meshmocap._tolerances import ZERO_EXTENT

__all__ = [
    "MAX_BODY_FILL",
    "MAX_EXTENT",
    "MAX_FOREGROUND",
    "MAX_OBSERVED_VERTICES",
    "body_problem",
    "body_warnings",
    "check_observations",
    "mask_problems",
    "observation_problem",
    "partial_hulls",
]

#: Largest share of an image a subject's silhouette plausibly covers.
MAX_FOREGROUND = 0.5
#: Largest edge, metres, of the box around a plausible observation of one person (arms
#: raised, a jump, a hull's phantom volumes included).
MAX_EXTENT = 3.0
#: Largest share of its bounding box a human body's volume fills (the bundled bodies in
#: the procedural motions stay below a quarter; a sphere fills 0.52).
MAX_BODY_FILL = 0.4
#: Heights, metres, of a plausible performer.
BODY_HEIGHT = (0.8, 2.5)


def mask_problems(masks: Sequence[np.ndarray | None], names: Sequence[str]) -> dict[str, str]:
    """Cameras whose mask is implausible, with why: ``{name: reason}`` (empty: all fine).

    A mask covering more than :data:`MAX_FOREGROUND` of its image is inverted (the subject
    black on a white background) or not a silhouette; the reason gives its foreground share
    and the median of the plausible cameras' (a rig sees the subject alike in each).

    Parameters
    ----------
    masks : sequence of C (H, W) bool arrays or None (no file)
    names : sequence of C str, camera names
    """
    share = np.array([np.nan if m is None else float(np.mean(m)) for m in masks])
    bad = np.flatnonzero(share > MAX_FOREGROUND)
    out = {}
    for k in bad:
        others = np.delete(share, k)
        others = others[np.isfinite(others) & (others <= MAX_FOREGROUND)]
        rest = f", the others {np.median(others):.0%}" if len(others) else ""
        out[str(names[k])] = f"{share[k]:.0%} foreground{rest}: inverted?"
    return out


def observation_problem(V: np.ndarray) -> str | None:
    """Why the observed surface ``V`` ((n, 3) float64, metres) cannot be one person (None
    when it can): a box edge over :data:`MAX_EXTENT`."""
    V = np.asarray(V, dtype=np.float64)
    if not len(V):
        return None
    ext = V.max(axis=0) - V.min(axis=0)
    if ext.max() > MAX_EXTENT:
        dims = " × ".join(f"{e:.1f}" for e in ext)
        return (
            f"the observed surface spans {dims} m, more than one person ({MAX_EXTENT:g} m at "
            "most): inverted silhouettes (white background) or the whole scene?"
        )
    return None


def _volume(V: np.ndarray, F: np.ndarray) -> float:
    """Enclosed volume of a closed triangle mesh (divergence theorem), m³."""
    a, b, c = V[F[:, 0]], V[F[:, 1]], V[F[:, 2]]
    return abs(float(np.einsum("ij,ij->i", a, np.cross(b, c)).sum()) / 6.0)


def body_problem(V: np.ndarray, F: np.ndarray | None, *, up: int = 2) -> str | None:
    """Why the mesh ``(V, F)`` is not human-like (None when it is).

    Parameters
    ----------
    V : (n, 3) float64, metres; F : (m, 3) int triangles, or None for a point cloud
        (then only the height is checked)
    up : int, the vertical axis (2: Z up)
    """
    V = np.asarray(V, dtype=np.float64)
    ext = V.max(axis=0) - V.min(axis=0)
    height = float(ext[up])
    lo, hi = BODY_HEIGHT
    if not lo <= height <= hi:
        return f"it is {height:.2f} m tall (a person: {lo:g}–{hi:g} m)"
    if F is None or not len(F):
        return None
    fill = _volume(V, np.asarray(F)) / float(np.prod(np.maximum(ext, ZERO_EXTENT)))
    if fill > MAX_BODY_FILL:
        return (
            f"it fills {fill:.0%} of its bounding box, a solid blob (a body with its limbs: "
            f"under {MAX_BODY_FILL:.0%}; a sphere: 52%)"
        )
    return None


#: Vertices of an observed frame above which tracking is less accurate (its surface is
#: sampled down unevenly); such a capture is tracked with a warning.
MAX_OBSERVED_VERTICES = 500_000


def check_observations(
    capture, positions: Sequence[int] | None = None, *, command: str = "track"
) -> list[str]:
    """Check a capture before it is tracked or scored; return warnings (one line each).

    The first frame with an observation among ``positions`` (default: all) must be one
    person (:func:`observation_problem`), else :class:`~meshmocap.errors.InputError`; a frame
    of more than :data:`MAX_OBSERVED_VERTICES` vertices is warned about, and so are frames
    of a capture folder carved from fewer cameras than the rig has (their notes).

    ``capture``: a :class:`~meshmocap.io.capture.Capture` or ``SequenceCapture``.
    """
    from meshmocap.errors import FormatError, InputError, MeshError, MeshmocapFileNotFoundError

    pos = list(range(len(capture))) if positions is None else list(positions)
    out: list[str] = []
    first_missing = None
    for k in pos:
        try:
            frame = capture[k]  # a mesh sequence reads the file here
            why = getattr(frame, "missing", None)
            V = None if why else frame.hull_mesh[0]
        except (MeshmocapFileNotFoundError, FormatError, MeshError) as exc:
            why = f"{type(exc).__name__}: {exc}"  # unreadable: the driver flags it missing
        if why:
            first_missing = first_missing or (capture.indices[k], why)
            continue
        why = observation_problem(V)
        if why is not None:
            raise InputError(
                f"{command}: {capture.path}: frame {capture.indices[k]}: {why} Expected the "
                "subject white on black; invert the masks and rerun 'meshmocap hull "
                "--overwrite'"
            )
        if len(V) > MAX_OBSERVED_VERTICES:
            out.append(
                f"{command}: frame {capture.indices[k]} of {capture.path} has {len(V):,} "
                f"vertices; above {MAX_OBSERVED_VERTICES:,} tracking is less accurate "
                "(decimate the meshes first: docs/guide/faults.rst)"
            )
        break
    else:
        if first_missing is not None:
            i, why = first_missing
            raise InputError(  # the driver's words, before the template is estimated
                f"{command}: no frame of {capture.path} has an observation to start from "
                f"(frame {i}: {why})"
            )
    note = partial_hulls(capture, [int(capture.indices[k]) for k in pos], command=command)
    return [*out, note] if note else out


def partial_hulls(capture, frames: Sequence[int], *, command: str = "eval") -> str | None:
    """One line naming the ``frames`` (frame numbers) of a capture folder whose hulls were
    carved from fewer cameras than the rig has, with the first one's note (None: none)."""
    notes = capture.notes() if hasattr(capture, "notes") else {}
    wanted = set(frames)
    partial = {i: n for i, n in notes.items() if i in wanted and n.startswith("carved from")}
    if not partial:
        return None
    first = min(partial)
    return (
        f"{command}: {len(partial)} of {len(wanted)} frames were carved from fewer than "
        f"the {len(capture.cameras)} cameras (first {first}: {partial[first]}); their hulls "
        "are coarser, and their silhouettes are scored only in the cameras that saw the subject"
    )


def body_warnings(capture, *, command: str = "subject") -> list[str]:
    """Warnings (one line each) when the first observed frame of ``capture`` is not
    human-like (:func:`body_problem`): the body estimated from it would be made up."""
    for k in range(len(capture)):
        frame = capture[k]
        if getattr(frame, "missing", None):
            continue
        V, F = frame.hull_mesh
        why = body_problem(V, F)
        if why is None:
            return []
        return [
            f"{command}: frame {capture.indices[k]} of {capture.path} is not human-like: "
            f"{why}; the body estimated from it is not a performer's"
        ]
    return []
