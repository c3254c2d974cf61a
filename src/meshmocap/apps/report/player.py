"""The 3D player of HTML reports: what it shows of tracks and their capture, encoded for
``assets/player.js``, a three.js viewer (three.js is vendored as
``assets/three.min.js``, MIT licence in ``assets/three.LICENSE.txt``).

Each track is shown as **what a user exports**: the template as a skinned mesh with the
skeleton animation of :func:`meshmocap.apps.files.export.track_gltf` (the same GLB as
``meshmocap export --out x.glb``), with its 15 tracked joints as a skeleton, the
ground-truth joints when the capture has them, and the observed visual hull as points
(surface voxels of ``hulls/NNNNN.npz``, else vertices of the frame's mesh). Tracks sit side
by side (one lane each, with its own copy of the truth and the hull) or overlaid. Controls:
play/pause, frame slider, speed, layer switches; drag to orbit, right-drag to pan, wheel
to zoom. With ``?screenshot`` in the page address only the first player's canvas shows,
at 800 × 600 pixels (for headless screenshots); ``frame=N`` (``?screenshot&frame=3``)
opens the players at their frame N (counted from 0). The page records its errors in
``<html data-mm-errors>`` and each player sets ``data-mm-ready`` once it has drawn.

Everything is Y up (glTF's frame: the library's (x, y, z) → (x, z, −y)), metres.
Data size: joints and hull points are quantised to int16 around a shared origin (step =
largest half-extent / 32000, e.g. 0.03 mm for a 2 m scene) and base64-encoded; each
track's GLB is its template (a few hundred kB) plus 31 int16 quaternions per frame. A
player shows **every frame of the tracks** and thins the hull points of each frame to fit
``max_megabytes`` of per-frame data; only where the tracks alone (joints, animation, and
at least :data:`MIN_HULL_POINTS` hull points a frame) cannot fit does it keep a regular
stride of frames, and it says so (:attr:`Player.note`, shown beside the frame slider).
"""

from __future__ import annotations

import base64
import math
import os
from collections.abc import Sequence
from dataclasses import dataclass
from importlib import resources
from pathlib import Path

import numpy as np

from meshmocap._tolerances import ZERO_EXTENT
from meshmocap.apps.files.export import track_fps, track_gltf, track_template
from meshmocap.body.template import Template
from meshmocap.errors import InputError, MeshmocapFileNotFoundError
from meshmocap.io.capture import Capture, SequenceCapture, frame_name, read_hull
from meshmocap.io.gltf import Z_UP_TO_Y_UP, gltf_bytes, morph_gltf
from meshmocap.io.results import Track, tracked_template, two_way_changes

#: Colours of the player's tracks (RGB), in order: blue, crimson, amber, purple, dark cyan.
PALETTE = ((50, 100, 220), (210, 50, 110), (225, 150, 20), (130, 70, 200), (0, 140, 170))
#: Colour of the ground-truth joints and of the hull points.
TRUTH_COLOR, HULL_COLOR = (20, 160, 60), (120, 120, 120)
#: Hull points a frame keeps at least before the player drops frames to fit its budget.
MIN_HULL_POINTS = 300
#: Encoded bytes a frame of a rigged track's animation takes in its GLB (31 int16
#: quaternions and a float32 root position, base64).
ANIMATION_BYTES = 4 * (31 * 8 + 12) // 3


@dataclass(frozen=True, eq=False)
class PlayerTrack:
    """One track as the player shows it.

    Attributes
    ----------
    name : str
    glb : bytes, the skinned template and its animation (time 0 at ``first``), Y up
    first : int, capture frame number at the animation's time 0
    joints : (R, K, 3) float32, tracked evaluation joints, metres, Y up, one row per shown
        frame that the track has
    rows : (T,) int64, row of each player frame in ``joints``; -1: not tracked
    parents : tuple of int or None, parent of each joint (-1: root)
    vertex_error_mm : float, mean distance of the shown mesh to the tracked one
    marks : (T,) int8, each player frame's mark on the timeline (:data:`MARKS`; 0: none)
    """

    name: str
    glb: bytes
    first: int
    joints: np.ndarray
    rows: np.ndarray
    parents: tuple[int, ...] | None
    vertex_error_mm: float = float("nan")
    marks: np.ndarray | None = None


#: What a timeline mark means (:attr:`PlayerTrack.marks`): bit 1 the frame is flagged
#: ``lost``, bit 2 the two-way pass replaced it (:mod:`meshmocap.trackers.two_way`).
MARKS = {1: "flagged lost", 2: "changed by the two-way pass"}


@dataclass(frozen=True, eq=False)
class Player:
    """The data of one 3D player (see :func:`player_from_tracks`).

    Attributes
    ----------
    title : str
    frames : (T,) int64, capture frame numbers shown
    fps : float, playback rate: the capture's frame rate divided by the stride
    capture_fps : float, the capture's frame rate (the animations' clock)
    tracks : tuple of PlayerTrack
    truth : (T, K, 3) float32 or None, ground-truth evaluation joints, metres, Y up
    truth_parents : tuple of int or None
    hull : tuple of T arrays (P_t, 3) float32, or None, observed hull points, metres, Y up
    n_tracked : int, frames the tracks have together (T when every one is shown)
    note : str, what the player shows, for its viewer (every frame, or which)
    """

    title: str
    frames: np.ndarray
    fps: float
    capture_fps: float
    tracks: tuple[PlayerTrack, ...]
    truth: np.ndarray | None = None
    truth_parents: tuple[int, ...] | None = None
    hull: tuple[np.ndarray, ...] | None = None
    n_tracked: int = 0
    note: str = ""


def surface_voxels(occupancy: np.ndarray) -> np.ndarray:
    """(P, 3) int64 indices of the occupied voxels with an empty 6-neighbour (or on the grid's
    border), in C order; ``occupancy`` (nx, ny, nz) bool."""
    occ = np.asarray(occupancy, dtype=bool)
    spans = [np.flatnonzero(occ.any(axis=tuple(a for a in range(3) if a != k))) for k in range(3)]
    if not all(len(s) for s in spans):
        return np.zeros((0, 3), np.int64)
    lo = np.array([s[0] for s in spans])
    sub = np.pad(occ[tuple(slice(s[0], s[-1] + 1) for s in spans)], 1)
    c = sub[1:-1, 1:-1, 1:-1]
    inner = c & sub[:-2, 1:-1, 1:-1] & sub[2:, 1:-1, 1:-1] & sub[1:-1, :-2, 1:-1]
    inner &= sub[1:-1, 2:, 1:-1] & sub[1:-1, 1:-1, :-2] & sub[1:-1, 1:-1, 2:]
    return np.argwhere(c & ~inner) + lo


def _hull_points(capture, pos: int, limit: int) -> np.ndarray:
    """Up to ``limit`` points (Z up) of the observed hull of capture frame position ``pos``."""
    frame = capture[pos]
    npz = Path(capture.path) / "hulls" / f"{frame_name(frame.index)}.npz"
    if isinstance(capture, Capture) and npz.is_file():  # surface voxels: faster than the .ply
        h = read_hull(npz)
        P = h.origin + surface_voxels(h.occupancy) * h.voxel_size
    else:
        try:
            P = np.asarray(frame.hull_mesh[0], dtype=np.float64)
        except MeshmocapFileNotFoundError:
            return np.zeros((0, 3), np.float32)
    if len(P) > limit:
        pick = np.random.default_rng(frame.index).choice(len(P), limit, replace=False)
        P = P[np.sort(pick)]
    return P.astype(np.float32)


def _rig(track: Track, template) -> Template | None:
    """The template that skins ``track``, or None when it cannot be had (a template file
    that is not bundled and was not given, another vertex count)."""
    try:
        return track_template(track, template)
    except (MeshmocapFileNotFoundError, InputError):
        return None


def track_templates(folders: Sequence[str | os.PathLike]) -> list[Template | None]:
    """The template each track folder deformed (an estimated body from its file, see
    :func:`~meshmocap.io.results.tracked_template`), None where it cannot be had: what
    :func:`player_from_tracks` takes as ``templates``."""
    found: list[Template | None] = []
    for folder in folders:
        try:
            found.append(tracked_template(folder))
        except (MeshmocapFileNotFoundError, InputError, OSError, ValueError):
            found.append(None)
    return found


def _y_up(X: np.ndarray) -> np.ndarray:
    return (np.asarray(X, dtype=np.float64) @ Z_UP_TO_Y_UP.T).astype(np.float32)


def player_from_tracks(
    capture: Capture | SequenceCapture,
    tracks: Sequence[Track],
    *,
    names: Sequence[str] | None = None,
    title: str = "",
    max_frames: int | None = None,
    max_megabytes: float = 8.0,
    hull_points: int = 1500,
    truth: bool = True,
    templates: Sequence[Template | str | None] | None = None,
) -> Player:
    """Gather what the player shows of ``tracks`` over ``capture``.

    Parameters
    ----------
    capture : Capture or SequenceCapture, the capture the tracks followed
    tracks : sequence of Track, one or more, over frames of ``capture``
    names : sequence of str, optional, one per track (default: each track's method)
    max_frames : int, optional
        At most this many frames (a regular stride over the union of the tracks' frames).
        Default: every frame, as far as ``max_megabytes`` allows.
    max_megabytes : float
        Budget of the per-frame data (joints, animations, hull points; base64). Hull points
        are thinned to fit, down to :data:`MIN_HULL_POINTS` a frame; past that a regular
        stride of frames is kept (one frame is always kept).
    hull_points : int
        Hull points kept per frame at most (0: no hull layer).
    truth : bool
        Include the ground-truth joints when every shown frame has them.
    templates : sequence, optional
        Each track's template when it is not the bundled one named in its ``track.json``
        (:func:`track_templates` reads an estimated body from the track's folder). A track
        whose template cannot be had is shown as its tracked meshes (morph targets, 12
        bytes per vertex and frame, counted in ``max_megabytes``).

    Raises
    ------
    InputError : no track, mismatched names, a track frame missing from the capture.
    """
    if not tracks:
        raise InputError("player_from_tracks: expected at least one track, found none")
    if max_frames is not None and max_frames < 1:
        raise InputError(f"max_frames: expected a positive count, found {max_frames}")
    if names is None:
        names = [str(t.meta.get("method", f"track {k}")) for k, t in enumerate(tracks)]
    if len(names) != len(tracks):
        raise InputError(f"names: expected {len(tracks)} names, found {len(names)}")
    templates = templates or [None] * len(tracks)
    position = {int(i): k for k, i in enumerate(capture.indices)}
    for name, t in zip(names, tracks, strict=True):
        missing = sorted(set(t.frames.tolist()) - set(position))
        if missing:
            raise InputError(f"track {name!r}: frames {missing[:5]} are not in the capture")
    every = np.unique(np.concatenate([t.frames for t in tracks]))
    rigs = [_rig(t, tpl) for t, tpl in zip(tracks, templates, strict=True)]
    # bytes a frame takes without the hull: joints (int16 x 3, base64), truth, animations
    essential = 8 * (sum(t.joints.shape[1] for t in tracks) + 15) + 8
    essential += sum(
        16 * t.vertices.shape[1] if r is None else ANIMATION_BYTES
        for t, r in zip(tracks, rigs, strict=True)
    )
    budget = max_megabytes * 1e6
    least = essential + 8 * min(hull_points, MIN_HULL_POINTS)
    fit = max(1, int(budget // least))
    stride = math.ceil(len(every) / min(max_frames or len(every), fit))
    frames = every[::stride]
    hull_points = int(min(hull_points, max(0.0, (budget / len(frames) - essential) / 8)))
    fps = float(getattr(capture, "fps", 0.0) or track_fps(tracks[0])[0])
    ptracks = []
    for k, (name, t) in enumerate(zip(names, tracks, strict=True)):
        rows = np.flatnonzero(np.isin(t.frames, frames))
        player_rows = np.full(len(frames), -1, np.int64)
        player_rows[np.searchsorted(frames, t.frames[rows])] = np.arange(len(rows))
        glb, first, err = b"", int(frames[0]), float("nan")
        color = tuple(c / 255.0 for c in PALETTE[k % len(PALETTE)])
        if len(rows) and rigs[k] is not None:
            g, fitted = track_gltf(t, rigs[k], rows, fps, color=color, name=name)
            glb, first = gltf_bytes(g), int(t.frames[rows[0]])
            err = float(fitted.vertex_error.mean() * 1e3)
        elif len(rows):  # no template to skin: the tracked meshes themselves, as morph targets
            times = (t.frames[rows] - t.frames[rows[0]]) / fps
            g = morph_gltf(t.vertices[rows], t.faces, times, name=name, color=color)
            glb, first, err = gltf_bytes(g), int(t.frames[rows[0]]), 0.0
        parents = t.meta.get("eval_parents")
        shown = rows[player_rows[player_rows >= 0]]  # the track's row of each shown frame
        lost = np.array([bool(t.flags) and "lost" in t.flags[r] for r in shown], dtype=np.int8)
        changed = np.isin(t.frames[shown], list(two_way_changes(t.meta)))
        marks = np.zeros(len(frames), np.int8)
        marks[player_rows >= 0] = lost + 2 * changed
        ptracks.append(
            PlayerTrack(
                name,
                glb,
                first,
                _y_up(t.joints[rows]),
                player_rows,
                tuple(int(p) for p in parents) if parents else None,
                err,
                marks,
            )
        )
    true_J = parents = None
    if truth:
        truths = [capture[position[int(i)]].truth for i in frames]
        if all(x is not None and x.joints is not None for x in truths):
            true_J = _y_up(np.stack([x.joints for x in truths]))
            K = true_J.shape[1]
            parents = next((p.parents for p in ptracks if p.joints.shape[1] == K), None)
    hull = None
    if hull_points > 0:
        hull = tuple(_y_up(_hull_points(capture, position[int(i)], hull_points)) for i in frames)
        if not any(len(h) for h in hull):
            hull = None
    n = len(every)
    if stride == 1:
        note = f"all {n} tracked frames"
    else:
        why = "--max-frames" if max_frames is not None and max_frames < fit else "size budget"
        note = f"every {_ordinal(stride)} of {n} tracked frames ({why}; exports hold them all)"
    if hull is not None:
        note += f"; hull: up to {hull_points} points a frame"
    return Player(
        title,
        frames.astype(np.int64),
        fps / stride,
        fps,
        tuple(ptracks),
        true_J,
        parents,
        hull,
        n,
        note,
    )


def _ordinal(k: int) -> str:
    """2nd, 3rd, 4th, 11th, 21st..."""
    end = "th" if 10 <= k % 100 <= 20 else {1: "st", 2: "nd", 3: "rd"}.get(k % 10, "th")
    return f"{k}{end}"


def encode_array(a: np.ndarray, *, origin: np.ndarray | None = None, step: float = 0.0) -> dict:
    """Encode an array for the player: ``{"dtype", "shape", "data"}`` (base64, little-endian).

    With ``step > 0`` the positions ``a`` (..., 3) are quantised to int16 around ``origin``
    (non-finite values become the origin) and the entry also holds ``origin`` and ``step``.
    """
    a = np.asarray(a)
    entry: dict = {"shape": list(a.shape)}
    if step > 0:
        q = np.rint((np.nan_to_num(a - origin, nan=0.0, posinf=0.0, neginf=0.0)) / step)
        a = np.clip(q, -32767, 32767).astype("<i2")
        entry |= {"origin": [float(x) for x in origin], "step": float(step)}
    else:
        a = a.astype(a.dtype.newbyteorder("<"))
    entry |= {"dtype": a.dtype.name, "data": base64.b64encode(a.tobytes()).decode("ascii")}
    return entry


def decode_array(entry: dict) -> np.ndarray:
    """Inverse of :func:`encode_array` (quantised positions come back as float64)."""
    a = np.frombuffer(
        base64.b64decode(entry["data"]), dtype=np.dtype(entry["dtype"]).newbyteorder("<")
    )
    a = a.reshape(entry["shape"])
    if entry.get("step"):
        return np.asarray(entry["origin"]) + a * float(entry["step"])
    return a


def player_payload(player: Player) -> dict:
    """The JSON-ready data of ``player`` that ``player.js`` reads (arrays encoded; Y up)."""
    parts = [t.joints.reshape(-1, 3) for t in player.tracks]
    parts += [player.truth.reshape(-1, 3)] if player.truth is not None else []
    parts += list(player.hull or ())
    P = np.concatenate(parts).astype(np.float64)
    P = P[np.isfinite(P).all(axis=1)]
    lo, hi = P.min(axis=0), P.max(axis=0)
    origin = (lo + hi) / 2
    step = max(float((hi - lo).max()) / 2 / 32000, ZERO_EXTENT)
    shown = [t for t in player.tracks if len(t.joints)]
    root = shown[0].joints[:, 0, [0, 2]].astype(np.float64)  # the pelvis on the floor plane
    travel = root[-1] - root[0]
    axis = travel / np.linalg.norm(travel) if np.linalg.norm(travel) > 0.2 else np.array([1.0, 0])
    lane = np.array([-axis[1], axis[0]])  # side by side: across the direction of travel,
    lane = lane if lane[0] - 0.5 * lane[1] >= 0 else -lane  # left to right seen from the camera
    tracks = []
    for k, t in enumerate(player.tracks):
        tracks.append(
            {
                "name": t.name,
                "color": list(PALETTE[k % len(PALETTE)]),
                "glb": base64.b64encode(t.glb).decode("ascii"),
                "first": t.first,
                "n_joints": int(t.joints.shape[1]),
                "parents": list(t.parents) if t.parents else None,
                "joints": encode_array(t.joints, origin=origin, step=step),
                "rows": encode_array(t.rows.astype(np.int32)),
            }
        )
    out = {
        "title": player.title,
        "note": player.note,
        "n_tracked": player.n_tracked,
        "frames": [int(i) for i in player.frames],
        "fps": player.fps,
        "capture_fps": player.capture_fps,
        "center": [float(x) for x in origin],
        "floor": float(lo[1]),
        "extent": float((hi - lo).max()),
        "lane": [float(x) for x in lane],
        "tracks": tracks,
        "truth": None,
        "hull": None,
        "colors": {"truth": list(TRUTH_COLOR), "hull": list(HULL_COLOR)},
    }
    if player.truth is not None:
        out["truth"] = {
            "n_joints": int(player.truth.shape[1]),
            "parents": list(player.truth_parents) if player.truth_parents else None,
            "joints": encode_array(player.truth, origin=origin, step=step),
        }
    if player.hull is not None:
        offsets = np.concatenate([[0], np.cumsum([len(h) for h in player.hull])]).astype(np.int32)
        out["hull"] = {
            "points": encode_array(np.concatenate(player.hull), origin=origin, step=step),
            "offsets": encode_array(offsets),
        }
    return out


def _asset(name: str) -> str:
    return resources.files("meshmocap.apps.report").joinpath(f"assets/{name}").read_text("utf-8")


def player_js() -> str:
    """The player's JavaScript: the vendored three.js build (with its licence notice), then
    ``assets/player.js``."""
    return f"{_asset('three.min.js')}\n{_asset('player.js')}"
