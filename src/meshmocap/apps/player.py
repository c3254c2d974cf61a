"""The 3D player of HTML reports: its data, gathered from tracks and their capture, and its
encoding for ``report_assets/player.js`` (a dependency-free canvas-2D viewer).

The player shows, frame by frame, every track's template mesh (painter's algorithm, flat
Lambert shading), its evaluation skeleton, the ground-truth joints when the capture has
them and the observed visual hull as translucent points (surface voxels of
``hulls/NNNNN.npz``, else vertices of the frame's mesh). Controls: play/pause, frame slider,
speed, layer switches, side-by-side or overlaid tracks; drag to orbit, shift-drag to pan,
wheel to zoom, double-click to reset. With ``?screenshot`` in the page address only the
first player's canvas shows, at 800 × 600 pixels (for headless screenshots); ``frame=N``
(``?screenshot&frame=3``) opens the players at their frame N (counted from 0).

Data size: positions are quantised to int16 around a shared origin (step = largest
half-extent / 32000, e.g. 0.03 mm for a 2 m scene) and base64-encoded; a player keeps at
most ``max_frames`` frames (a regular stride over long tracks) and at most
``max_megabytes`` of encoded data (default 30 MB; the stride grows to fit). A 60-frame,
two-track player on a 5000-vertex template is about 6 MB.
"""

from __future__ import annotations

import base64
import math
from collections.abc import Sequence
from dataclasses import dataclass
from importlib import resources
from pathlib import Path

import numpy as np

from meshmocap.errors import InputError, MeshmocapFileNotFoundError
from meshmocap.io.capture import Capture, SequenceCapture, frame_name, read_hull
from meshmocap.io.results import Track

#: Mesh colours of the player's tracks (RGB), in order; the hull is orange, the truth green.
PALETTE = ((80, 130, 210), (150, 100, 200), (40, 160, 150), (200, 90, 130), (150, 120, 70))


@dataclass(frozen=True, eq=False)
class PlayerTrack:
    """One track as the player shows it.

    Attributes
    ----------
    name : str
    faces : (m, 3) int64, triangles, oriented outwards when the mesh is closed
    vertices : (R, n, 3) float32, metres, world frame (Z up), one row per shown frame
    joints : (R, K, 3) float32, evaluation joints, same frames
    rows : (T,) int64, row of each player frame in ``vertices``/``joints``; -1: not tracked
    parents : tuple of int or None, parent of each joint (-1: root)
    closed : bool, every edge has two faces (the player then culls back faces)
    """

    name: str
    faces: np.ndarray
    vertices: np.ndarray
    joints: np.ndarray
    rows: np.ndarray
    parents: tuple[int, ...] | None
    closed: bool


@dataclass(frozen=True, eq=False)
class Player:
    """The data of one 3D player (see :func:`player_from_tracks`).

    Attributes
    ----------
    title : str
    frames : (T,) int64, capture frame numbers shown
    fps : float, playback rate, frames per second of the capture divided by the stride
    tracks : tuple of PlayerTrack
    truth : (T, K, 3) float32 or None, ground-truth evaluation joints, metres
    truth_parents : tuple of int or None
    hull : tuple of T arrays (P_t, 3) float32, or None, observed hull points, metres
    """

    title: str
    frames: np.ndarray
    fps: float
    tracks: tuple[PlayerTrack, ...]
    truth: np.ndarray | None = None
    truth_parents: tuple[int, ...] | None = None
    hull: tuple[np.ndarray, ...] | None = None


def _closed_outward(faces: np.ndarray, V: np.ndarray) -> tuple[np.ndarray, bool]:
    """Faces oriented outwards (by the signed volume) and whether the mesh is closed."""
    edges = np.sort(faces[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2), axis=1)
    _, counts = np.unique(edges, axis=0, return_counts=True)
    closed = bool(len(counts)) and bool(np.all(counts == 2))
    a, b, c = (V[faces[:, k]].astype(np.float64) for k in range(3))
    if np.einsum("ij,ij->", a, np.cross(b, c)) < 0:
        faces = faces[:, [0, 2, 1]]
    return faces, closed


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
    """Up to ``limit`` points of the observed hull of capture frame position ``pos``."""
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


def player_from_tracks(
    capture: Capture | SequenceCapture,
    tracks: Sequence[Track],
    *,
    names: Sequence[str] | None = None,
    title: str = "",
    max_frames: int = 120,
    max_megabytes: float = 30.0,
    hull_points: int = 2500,
    truth: bool = True,
) -> Player:
    """Gather what the player shows of ``tracks`` over ``capture``.

    Parameters
    ----------
    capture : Capture or SequenceCapture, the capture the tracks followed
    tracks : sequence of Track, one or more, over frames of ``capture``
    names : sequence of str, optional, one per track (default: each track's method)
    max_frames : int
        Frames kept: a regular stride over the union of the tracks' frames.
    max_megabytes : float
        Budget of the encoded data (base64); the stride grows until it fits (one frame
        is always kept, whatever its size).
    hull_points : int
        Hull points kept per frame (0: no hull layer).
    truth : bool
        Include the ground-truth joints when every shown frame has them.

    Raises
    ------
    InputError : no track, mismatched names, a track frame missing from the capture.
    """
    if not tracks:
        raise InputError("player_from_tracks: expected at least one track, found none")
    if max_frames < 1:
        raise InputError(f"max_frames: expected a positive count, found {max_frames}")
    if names is None:
        names = [str(t.meta.get("method", f"track {k}")) for k, t in enumerate(tracks)]
    if len(names) != len(tracks):
        raise InputError(f"names: expected {len(tracks)} names, found {len(names)}")
    position = {int(i): k for k, i in enumerate(capture.indices)}
    for name, t in zip(names, tracks, strict=True):
        missing = sorted(set(t.frames.tolist()) - set(position))
        if missing:
            raise InputError(f"track {name!r}: frames {missing[:5]} are not in the capture")
    every = np.unique(np.concatenate([t.frames for t in tracks]))
    per_frame = sum(6 * (t.vertices.shape[1] + t.joints.shape[1]) + 4 for t in tracks)
    per_frame += 6 * (hull_points + tracks[0].joints.shape[1])
    fixed = sum((2 if t.vertices.shape[1] < 65536 else 4) * t.faces.size for t in tracks)
    budget = max_megabytes * 1e6 * 3 / 4 - fixed
    fit = max(1, int(budget // per_frame))
    stride = math.ceil(len(every) / min(max_frames, fit))
    frames = every[::stride]
    ptracks = []
    for name, t in zip(names, tracks, strict=True):
        sel = np.isin(t.frames, frames)
        rows = np.full(len(frames), -1, np.int64)
        rows[np.searchsorted(frames, t.frames[sel])] = np.arange(int(sel.sum()))
        V = t.vertices[sel].astype(np.float32)
        faces, closed = _closed_outward(np.asarray(t.faces, np.int64), t.vertices[0])
        parents = t.meta.get("eval_parents")
        ptracks.append(
            PlayerTrack(
                name,
                faces,
                V,
                t.joints[sel].astype(np.float32),
                rows,
                tuple(int(p) for p in parents) if parents else None,
                closed,
            )
        )
    true_J = parents = None
    if truth:
        truths = [capture[position[int(i)]].truth for i in frames]
        if all(x is not None and x.joints is not None for x in truths):
            true_J = np.stack([x.joints for x in truths]).astype(np.float32)
            K = true_J.shape[1]
            parents = next((p.parents for p in ptracks if p.joints.shape[1] == K), None)
    hull = None
    if hull_points > 0:
        hull = tuple(_hull_points(capture, position[int(i)], hull_points) for i in frames)
        if not any(len(h) for h in hull):
            hull = None
    fps = float(getattr(capture, "fps", 30.0)) / stride
    return Player(title, frames.astype(np.int64), fps, tuple(ptracks), true_J, parents, hull)


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
    """The JSON-ready data of ``player`` that ``player.js`` reads (arrays encoded)."""
    parts = [t.vertices.reshape(-1, 3) for t in player.tracks]
    parts += [t.joints.reshape(-1, 3) for t in player.tracks]
    parts += [player.truth.reshape(-1, 3)] if player.truth is not None else []
    parts += list(player.hull or ())
    P = np.concatenate(parts).astype(np.float64)
    P = P[np.isfinite(P).all(axis=1)]
    lo, hi = P.min(axis=0), P.max(axis=0)
    origin = (lo + hi) / 2
    step = max(float((hi - lo).max()) / 2 / 32000, 1e-9)
    shown = [t for t in player.tracks if len(t.vertices)]  # a track may miss every frame
    same = len({t.vertices.shape[1] for t in shown}) == 1  # templates of one size
    V = np.concatenate([t.vertices for t in shown]) if same else shown[0].vertices
    floor = float(np.nanmin(np.concatenate([t.vertices[..., 2].ravel() for t in shown])))
    height = float(np.nanmax(np.ptp(V[..., 2], axis=1)))
    root = shown[0].joints[:, 0, :2].astype(np.float64)
    travel = root[-1] - root[0]
    axis = travel / np.linalg.norm(travel) if np.linalg.norm(travel) > 0.2 else np.array([1.0, 0])
    spacing = float(np.nanmax(np.ptp(V[..., :2] @ axis, axis=1))) + 0.3
    centre = [float(origin[0]), float(origin[1]), floor + height / 2]
    tracks = []
    for k, t in enumerate(player.tracks):
        small = t.vertices.shape[1] < 65536
        tracks.append(
            {
                "name": t.name,
                "color": list(PALETTE[k % len(PALETTE)]),
                "cull": t.closed,
                "n_vertices": int(t.vertices.shape[1]),
                "n_joints": int(t.joints.shape[1]),
                "parents": list(t.parents) if t.parents else None,
                "faces": encode_array(t.faces.astype(np.uint16 if small else np.uint32)),
                "vertices": encode_array(t.vertices, origin=origin, step=step),
                "joints": encode_array(t.joints, origin=origin, step=step),
                "rows": encode_array(t.rows.astype(np.int32)),
            }
        )
    out = {
        "title": player.title,
        "frames": [int(i) for i in player.frames],
        "fps": player.fps,
        "center": centre,
        "floor": floor,
        "height": height,
        "spacing": spacing,
        "axis": [float(axis[0]), float(axis[1])],
        "tracks": tracks,
        "truth": None,
        "hull": None,
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


def player_js() -> str:
    """The player's JavaScript source (``report_assets/player.js``)."""
    src = resources.files("meshmocap.apps").joinpath("report_assets/player.js")
    return src.read_text(encoding="utf-8")
