"""Tracking results, written frame by frame so a long run can stop and resume.

Layout (``track.json`` holds ``"format": "meshmocap-track-1"``)::

    TRACK/
      track.json        method, template, capture, evaluation-joint names and parents, options,
                        once the first frame is done, how it started ("start": a Start), and
                        the frames skipped for want of an observation ("skipped": number →
                        the reason)
      faces.npy         the template's triangles (m, 3), so the tracked meshes stand alone
      frames/NNNNN.npz  one file per frame: joints (K, 3), vertices (n, 3) float32 (stored
                        byte-shuffled as vertices.f4s, meshmocap._npz; older files hold
                        them plain), energy terms, iterations, seconds, health flag, flags
                        and message
      light.npz         only for a track of a light body (meshmocap.body.light): the frames
                        hold the light body's vertices, and this binding reads the
                        template's out of them (read_track does)

A frame file is written atomically once the frame is done: the folder always holds whole
frames, and :func:`done_frames` tells a resumed run where to continue.

How the first pose was found is a record (:class:`~meshmocap.io.start.Start`), written into
``track.json`` by :func:`write_start` and read back by :func:`read_start` (and
:attr:`Track.start`); a track folder written before it was recorded has none (its start is
unknown: nothing is read out of its first frame's message).
"""

from __future__ import annotations

import json
import os
import shutil
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from meshmocap._atomic import atomic_open, write_text_atomic
from meshmocap._npz import SHUFFLED, read_npz, shuffled_float32, write_npz
from meshmocap.body.light import SurfaceBinding, bound_vertices
from meshmocap.body.template import Template, load_template
from meshmocap.errors import FormatError, InputError, MeshmocapFileNotFoundError
from meshmocap.io.start import Start, start_json, start_of_json

FORMAT = "meshmocap-track-1"

#: What may have happened to a frame, besides a normal fit (:attr:`FrameResult.flags`):
#:
#: * ``failed``: the fit raised a numerical error or gave non-finite values; the frame
#:   repeats the last good result (``healthy`` is False);
#: * ``missing``: the capture has no usable observation of the frame (a dropped frame, an
#:   empty hull); the tracker coasted across it (``healthy`` is False);
#: * ``lost``: the fit is below the quality threshold (``message`` names the body parts), or
#:   the frame is an uncertain start (:attr:`~meshmocap.io.start.Start.confident`);
#: * ``reinit``: the tracker re-initialised the body, or some limbs, at this frame.
FRAME_FLAGS = ("failed", "missing", "lost", "reinit")


@dataclass(frozen=True, eq=False)
class FrameResult:
    """What a tracker returns for one frame.

    Attributes
    ----------
    index : int, frame number in the capture
    joints : (K, 3) float64, evaluation joints, metres, world frame (Z up)
    vertices : (n, 3) float64, the deformed template's vertices
    energies : dict of str → float, final value of each energy term
    n_iter : int, iterations used
    seconds : float, wall time of the frame
    healthy : bool, False when the frame failed or was missing and the state was carried over
    message : str, why a frame is unhealthy or flagged (empty otherwise)
    flags : tuple of str, from :data:`FRAME_FLAGS` (empty for a normal fit)
    state : dict of str → array, the tracker's state after the frame (to resume a run)
    """

    index: int
    joints: np.ndarray
    vertices: np.ndarray
    energies: dict[str, float] = field(default_factory=dict)
    n_iter: int = 0
    seconds: float = 0.0
    healthy: bool = True
    message: str = ""
    state: dict[str, np.ndarray] = field(default_factory=dict)
    flags: tuple[str, ...] = ()

    def __post_init__(self) -> None:
        unknown = set(self.flags) - set(FRAME_FLAGS)
        if unknown:
            raise InputError(
                f"FrameResult: flags must be among {FRAME_FLAGS}, found {sorted(unknown)}"
            )


@dataclass(frozen=True, eq=False)
class Track:
    """A whole tracking result, frames stacked.

    Attributes
    ----------
    meta : dict, the contents of ``track.json``
    faces : (m, 3) int64, the template's triangles
    frames : (T,) int64, frame numbers
    joints : (T, K, 3) float64; vertices : (T, n, 3) float64
    energies : dict of str → (T,) float64
    n_iter : (T,) int64; seconds : (T,) float64; healthy : (T,) bool
    flags : tuple of T tuples of str, each frame's :attr:`FrameResult.flags`
    messages : tuple of T str, each frame's :attr:`FrameResult.message`
    start : Start or None, how the first pose was found (:func:`read_start`; None: the
        track folder does not record it)
    """

    meta: dict
    faces: np.ndarray
    frames: np.ndarray
    joints: np.ndarray
    vertices: np.ndarray
    energies: dict[str, np.ndarray]
    n_iter: np.ndarray
    seconds: np.ndarray
    healthy: np.ndarray
    flags: tuple[tuple[str, ...], ...] = ()
    messages: tuple[str, ...] = ()
    start: Start | None = None


def frame_path(track: str | os.PathLike, index: int) -> Path:
    """Path of frame ``index``'s result file."""
    return Path(track) / "frames" / f"{index:05d}.npz"


#: How a track's template was chosen (``track.json``'s ``template_source``; absent: given).
TEMPLATE_SOURCES = {
    "given": "given",
    "capture": "named by capture.json",
    "estimated": "estimated from the capture",
}


def template_label(meta: dict) -> str:
    """``"NAME (how it was chosen)"`` of the template a track used, from its ``track.json``
    (e.g. ``"subject (estimated from the capture)"``; ``"neutral_5k (given)"``)."""
    source = str(meta.get("template_source", "given"))
    return f"{meta.get('template', '?')} ({TEMPLATE_SOURCES.get(source, source)})"


def tracked_template(path: str | os.PathLike, meta: dict | None = None) -> Template:
    """The template the track folder ``path`` deformed: the file its ``track.json`` names
    (``template_file``, relative to the folder: an estimated subject), else the bundled
    template named there.

    Raises :class:`MeshmocapFileNotFoundError` when neither can be found (the message says
    to pass the template's file)."""
    path = Path(path)
    if meta is None:
        meta = json.loads((path / "track.json").read_text())
    name = str(meta.get("template"))
    file = meta.get("template_file")
    if file:
        if not (path / str(file)).is_file():
            raise MeshmocapFileNotFoundError(
                f"{path}: tracked with the template in {file}, which is missing from the track "
                "folder; pass the template's file (template=, --template)"
            )
        return load_template(path / str(file))
    try:
        return load_template(name)
    except MeshmocapFileNotFoundError:
        raise MeshmocapFileNotFoundError(
            f"{path}: tracked with template {name!r}, which is not bundled; pass its file "
            "(template=, --template)"
        ) from None


@dataclass(frozen=True)
class InputFrame:
    """How a track's input files relate to the world frame the track is in (``track.json``:
    ``input`` and ``fps``). A file point ``x`` is the world point
    ``scale · turn_up(x) − offset`` (metres, Z up), ``turn_up`` the rotation of
    :func:`~meshmocap.io.meshes.read_mesh` for Y-up files.

    Attributes
    ----------
    up : {"z", "y"}, the files' up axis
    units : str, their length unit (``"m"``, ``"cm"``, ``"mm"``)
    scale : float, metres per file unit
    offset : (3,) float64, metres subtracted after scaling
    fps : float or None, frames per second (None: the track does not say)
    """

    up: str = "z"
    units: str = "m"
    scale: float = 1.0
    offset: tuple[float, float, float] = (0.0, 0.0, 0.0)
    fps: float | None = None

    def describe(self) -> str:
        """One phrase: ``"Y up, mm, 30 fps"``."""
        rate = f", {self.fps:g} fps" if self.fps else ""
        shift = f", offset {', '.join(f'{v:g}' for v in self.offset)} m" if any(self.offset) else ""
        return f"{self.up.upper()} up, {self.units}{rate}{shift}"


def input_meta(capture) -> dict:
    """What ``track.json`` records of how ``capture``'s files were read (see
    :class:`InputFrame`): ``input`` (``up``, ``units``, ``scale``, ``offset``) and ``fps``
    where the rate is known (given for a mesh sequence, in a capture folder's
    ``capture.json``); a capture folder is metres and Z up by its format."""
    given = getattr(capture, "fps_given", None)
    if given is None:  # a capture folder: its capture.json says, or not
        given = "fps" in getattr(capture, "meta", {})
    info = {
        "up": str(getattr(capture, "up", "z")),
        "units": str(getattr(capture, "units", "m")),
        "scale": float(getattr(capture, "scale", 1.0)),
        "offset": [float(v) for v in getattr(capture, "offset", np.zeros(3))],
    }
    return {"input": info, **({"fps": float(capture.fps)} if given else {})}


def planned_frames(meta: dict) -> list[int]:
    """The frame numbers a track's ``track.json`` contents ``meta`` planned to track
    (``frames``); empty for a live track, which tracks frames as they come (``"live":
    true``; tracks written by older versions said ``"frames": "follow"``)."""
    frames = meta.get("frames")
    if not isinstance(frames, list):
        return []
    try:
        return [int(i) for i in frames]
    except (TypeError, ValueError) as exc:
        raise FormatError(f"track.json: 'frames' must be frame numbers ({exc})") from None


def input_frame(meta: dict) -> InputFrame:
    """The :class:`InputFrame` a track's ``track.json`` contents ``meta`` record (tracks
    written before it was recorded: Z up, metres, the ``fps`` they hold, if any).

    Raises
    ------
    FormatError
        A recorded value of the wrong kind (names ``track.json``'s key).
    """
    info = meta.get("input") or {}
    try:
        up = str(info.get("up", "z"))
        scale = float(info.get("scale", 1.0))
        offset = tuple(float(v) for v in info.get("offset", (0.0, 0.0, 0.0)))
        fps = meta.get("fps")
        fps = None if fps is None else float(fps)
    except (TypeError, ValueError, AttributeError) as exc:
        raise FormatError(f"track.json: a bad 'input' or 'fps' ({exc})") from None
    bad = up not in ("z", "y") or not scale > 0 or len(offset) != 3
    if bad or not np.all(np.isfinite(offset)) or (fps is not None and not fps > 0):
        raise FormatError(
            f"track.json: 'input' must hold up z|y, a scale > 0 and a 3-vector offset, and "
            f"'fps' a rate > 0; found {info}, fps {meta.get('fps')}"
        )
    units = str(info.get("units", "m"))
    return InputFrame(up, units, scale, offset, fps)  # type: ignore[arg-type]


def open_tracked_capture(meta: dict, source: str | os.PathLike | None = None):
    """The capture a track was made from, read as the track read it: ``source`` (default:
    ``track.json``'s ``capture``) in the up axis, units, offset and frame rate that
    ``meta`` records (:func:`input_frame`), so scores, reports and exports are in the
    track's frame. A capture folder is opened as it is.

    Raises
    ------
    MeshmocapFileNotFoundError : no ``source`` given and the recorded one is gone.
    """
    from meshmocap.io.capture import SequenceCapture, open_capture

    if source is None:
        source = str(meta.get("capture") or "")
        if not source or not Path(source).exists():
            raise MeshmocapFileNotFoundError(
                f"track: its capture {source or '(not recorded)'} is gone; give the capture"
            )
    raw = open_capture(source)
    if not isinstance(raw, SequenceCapture):
        return raw
    f = input_frame(meta)
    return SequenceCapture(source, up=f.up, scale=f.scale, fps=f.fps, offset=f.offset)


def start_track(
    path: str | os.PathLike, meta: dict, faces: np.ndarray, *, resume: bool = True
) -> list[int]:
    """Create (or reopen) a track folder and return the frames already done.

    ``faces`` (m, 3) are the template's triangles (stored as ``faces.npy``). A resumed
    folder keeps the start it recorded (:func:`write_start`).

    Raises :class:`FormatError` when resuming a folder written with other metadata.
    """
    path = Path(path)
    (path / "frames").mkdir(parents=True, exist_ok=True)
    meta_path = path / "track.json"
    full = {"format": FORMAT, **meta}
    if meta_path.is_file() and resume:
        old = _read_json(meta_path)
        found = {k: old.pop(k) for k in (START_KEY, SKIPPED_KEY, TWO_WAY_KEY) if k in old}
        now = json.loads(json.dumps(full))
        old = as_made_now(old, now)
        # the passes may change: a forward track is resumed by adding the two-way pass
        differ = _difference(_but(old, PASSES_KEY), _but(now, PASSES_KEY))
        if differ:
            raise FormatError(
                f"{meta_path}: holds a track made with other settings ({differ}); "
                "use another folder"
            )
        full.update(found)
    else:
        for p in (path / "frames").glob("*.npz"):
            p.unlink()
        shutil.rmtree(path / TWO_WAY_FOLDER, ignore_errors=True)  # an earlier run's pass
    write_text_atomic(meta_path, json.dumps(full, indent=2) + "\n")
    with atomic_open(path / "faces.npy") as f:
        np.save(f, np.asarray(faces, dtype=np.int32))
    return done_frames(path)


#: Settings ``track.json`` no longer records, with the value that tracked as a track made
#: now does: a folder written with that value resumes, one written otherwise does not
#: (``reseat``: the limb-only re-seat, removed; off, a track was the tracker's alone).
RETIRED_SETTINGS = {"reseat": False}

#: Settings ``track.json`` records now and a folder written before them lacks, with the
#: value every track was made with then: such a folder resumes where the run now has that
#: value and is refused otherwise (``passes``: the forward pass alone; ``hold_skeleton``,
#: ``refine_surface``: neither the skeleton hold nor the surface refinement ran).
ADDED_SETTINGS = {"passes": "forward", "hold_skeleton": False, "refine_surface": False}

#: Tracker options (``track.json``'s ``"options"``) added since, with the value the tracker
#: used before they were options (the patch tracker's fixed term scales).
ADDED_OPTIONS = {"rigidity_scale": 10.0, "bone_scale": 100.0}

#: Tracker options renamed since, old name → new name (the cage's anchor term's weight).
RENAMED_OPTIONS = {"local_damping": "anchor_weight"}

#: What ``track.json`` records of how the run was set up rather than asked for (the body the
#: cage built on, decided by its options and the template): a folder written before it was
#: recorded takes the value found now.
ADDED_RECORDS = ("cage_body",)


def as_made_now(old: dict, now: dict) -> dict:
    """``track.json``'s settings ``old`` (a folder's) as a track made now would record them:
    retired settings at the value they had dropped (:data:`RETIRED_SETTINGS`), settings and
    tracker options added since given the value tracks were made with before
    (:data:`ADDED_SETTINGS`, :data:`ADDED_OPTIONS`, :data:`RENAMED_OPTIONS`), records added
    since taken from ``now`` (:data:`ADDED_RECORDS`). Only keys that ``now`` has are added;
    ``old`` is not changed."""
    old = dict(old)
    for key, value in RETIRED_SETTINGS.items():  # a setting that is gone, as it was
        if key in old and old[key] == value:
            del old[key]
    for key, value in ADDED_SETTINGS.items():
        if key in now and key not in old:
            old[key] = value
    for key in ADDED_RECORDS:
        if key in now and key not in old:
            old[key] = now[key]
    options, options_now = old.get("options"), now.get("options")
    if isinstance(options, dict) and isinstance(options_now, dict):
        options = dict(options)
        for name, renamed in RENAMED_OPTIONS.items():
            if name in options and renamed in options_now and renamed not in options:
                options[renamed] = options.pop(name)
        for name, value in ADDED_OPTIONS.items():
            if name in options_now and name not in options:
                options[name] = value
        old["options"] = options
    return old


def _difference(old: dict, now: dict, prefix: str = "") -> str:
    """The first setting where ``old`` and ``now`` differ, as ``key: A there, B now``
    (nested dicts named ``options.key``); empty where they agree."""
    for key in sorted(set(old) | set(now)):
        a, b = old.get(key, _ABSENT), now.get(key, _ABSENT)
        if a == b:
            continue
        if isinstance(a, dict) and isinstance(b, dict):
            return _difference(a, b, f"{prefix}{key}.")
        return f"{prefix}{key}: {_short(a)} there, {_short(b)} now"
    return ""


_ABSENT = object()


def _short(value) -> str:
    if value is _ABSENT:
        return "absent"
    if isinstance(value, list) and len(value) > 4:
        return f"{len(value)} values"
    text = json.dumps(value)
    return text if len(text) <= 40 else text[:37] + "..."


#: The key of ``track.json`` that holds the start (:func:`write_start`).
START_KEY = "start"
#: The key of ``track.json`` that names the frames skipped for want of a usable observation
#: (flagged ``missing``: a dropped frame, an unreadable file, another performer's mesh),
#: frame number → the reason (:func:`write_frame`).
SKIPPED_KEY = "skipped"


def write_start(path: str | os.PathLike, start: Start) -> None:
    """Record ``start`` (how the first pose was found) in the ``track.json`` of the track
    folder ``path`` (made by :func:`start_track`), atomically."""
    meta_path = Path(path) / "track.json"
    meta = {**_read_json(meta_path), START_KEY: start_json(start)}
    write_text_atomic(meta_path, json.dumps(meta, indent=2) + "\n")


#: The key of ``track.json`` that records the two-way pass (:func:`write_two_way`).
TWO_WAY_KEY = "two_way"
#: The folder of a track folder that holds the two-way pass's searches and tracks.
TWO_WAY_FOLDER = "two_way"
#: The key of ``track.json`` that says which passes the track was made with.
PASSES_KEY = "passes"


def _but(meta: dict, key: str) -> dict:
    return {k: v for k, v in meta.items() if k != key}


def write_two_way(path: str | os.PathLike, record: dict) -> None:
    """Record what the two-way pass did (:mod:`meshmocap.trackers.two_way`, a JSON-ready
    dict) in the ``track.json`` of the track folder ``path``, atomically."""
    meta_path = Path(path) / "track.json"
    meta = {**_read_json(meta_path), TWO_WAY_KEY: record}
    write_text_atomic(meta_path, json.dumps(meta, indent=2) + "\n")


def read_two_way(path: str | os.PathLike) -> dict | None:
    """The two-way pass's record in the ``track.json`` of the track folder ``path`` (None:
    no pass has finished there)."""
    meta_path = Path(path) / "track.json"
    if not meta_path.is_file():
        return None
    record = _read_json(meta_path).get(TWO_WAY_KEY)
    return record if isinstance(record, dict) else None


def two_way_changes(meta: dict) -> dict[int, str]:
    """The frames the two-way pass replaced, from a track's ``track.json`` contents
    ``meta``: frame number → where from (``"keyframe K, backward: left_arm"``, and each
    limb grafted from another track: ``"right_arm from the keyframe K forward track"``);
    empty when no pass changed any."""
    record = meta.get(TWO_WAY_KEY)
    out: dict[int, str] = {}
    if not isinstance(record, dict):
        return out
    for c in record.get("changed", ()):
        try:
            first, last = (int(v) for v in c["frames"])
            limbs = ", ".join(str(n) for n in c.get("limbs", ()))
            why = f"keyframe {int(c['keyframe'])}, {c['direction']}" + (
                f": {limbs}" if limbs else ""
            )
        except (KeyError, TypeError, ValueError) as exc:
            raise FormatError(f"track.json: a bad two-way change {c!r} ({exc})") from None
        out.update({i: why for i in range(first, last + 1)})
    for g in record.get("grafted", ()):  # a limb taken from another track
        try:
            first, last = (int(v) for v in g["frames"])
            why = f"{g['limb']} from the {g['track']} track"
        except (KeyError, TypeError, ValueError) as exc:
            raise FormatError(f"track.json: a bad two-way graft {g!r} ({exc})") from None
        for i in range(first, last + 1):
            out[i] = f"{out[i]}; {why}" if i in out else why
    return out


def read_start(path: str | os.PathLike) -> Start | None:
    """How the track in folder ``path`` started (its ``track.json``'s start), or None for a
    track folder that does not record it (made before starts were recorded, or not yet
    started): its start is unknown.

    Raises
    ------
    MeshmocapFileNotFoundError : ``path`` has no ``track.json``.
    FormatError : its start is not a start record.
    """
    meta_path = Path(path) / "track.json"
    if not meta_path.is_file():
        raise MeshmocapFileNotFoundError(f"track: {path} has no track.json")
    return _start_of_meta(_read_json(meta_path), meta_path)


def _start_of_meta(meta: dict, meta_path: Path) -> Start | None:
    record = meta.get(START_KEY)
    return None if record is None else start_of_json(record, f"{meta_path}: '{START_KEY}'")


def done_frames(path: str | os.PathLike) -> list[int]:
    """Frame numbers whose results exist in the track folder ``path``."""
    return sorted(int(p.stem) for p in (Path(path) / "frames").glob("*.npz") if p.stem.isdigit())


def write_frame(path: str | os.PathLike, r: FrameResult) -> None:
    """Write one frame's result atomically; a frame flagged ``missing`` is also named, with
    its reason, in ``track.json`` (:data:`SKIPPED_KEY`), first."""
    if "missing" in r.flags:
        meta_path = Path(path) / "track.json"
        meta = _read_json(meta_path)
        meta[SKIPPED_KEY] = {**meta.get(SKIPPED_KEY, {}), str(int(r.index)): r.message}
        write_text_atomic(meta_path, json.dumps(meta, indent=2) + "\n")
    extra = {f"energy_{k}": np.float64(v) for k, v in r.energies.items()}
    extra.update({f"state_{k}": np.asarray(v) for k, v in r.state.items()})
    with atomic_open(frame_path(path, r.index)) as f:
        write_npz(
            f,
            index=r.index,
            joints=r.joints,
            **{f"vertices{SHUFFLED}": shuffled_float32(r.vertices)},
            n_iter=r.n_iter,
            seconds=r.seconds,
            healthy=r.healthy,
            message=np.str_(r.message),
            flags=np.str_(",".join(r.flags)),
            **extra,
        )


def read_state(path: str | os.PathLike, index: int) -> dict[str, np.ndarray]:
    """The tracker state stored with frame ``index`` (empty if the tracker stored none)."""
    z = read_npz(frame_path(path, index), "frame result")
    return {k[6:]: v for k, v in z.items() if k.startswith("state_")}


def read_track(path: str | os.PathLike, *, vertices: bool = True) -> Track:
    """Read every frame of a track folder, stacked in frame order.

    ``vertices=False`` leaves the tracked vertices out (``Track.vertices`` is (T, 0, 3)):
    a 10,000-frame track of a 12k-vertex template holds 3 GB of them.
    """
    path = Path(path)
    meta_path = path / "track.json"
    if not meta_path.is_file():
        raise MeshmocapFileNotFoundError(f"track: {path} has no track.json")
    meta = _read_json(meta_path)
    if meta.get("format") != FORMAT:
        raise FormatError(f"{meta_path}: expected format {FORMAT!r}, found {meta.get('format')!r}")
    frames = done_frames(path)
    if not frames:
        raise MeshmocapFileNotFoundError(f"track: {path / 'frames'} holds no frame results")
    rows = [read_frame_arrays(path, i) for i in frames]
    if not vertices:
        for r in rows:
            r["vertices"] = r["vertices"][:0]
    binding = read_light_binding(path) if vertices else None
    if binding is not None:  # tracked on a light body: the template's vertices read out
        for r in rows:
            r["vertices"] = bound_vertices(binding, r["vertices"].astype(np.float64))
    keys = sorted({k for r in rows for k in r if k.startswith("energy_")})
    faces = _read_faces(path / "faces.npy")
    shapes = {(r["joints"].shape, r["vertices"].shape) for r in rows}
    if len(shapes) > 1:
        raise FormatError(f"track: {path / 'frames'} holds frames of different shapes {shapes}")
    n = rows[0]["vertices"].shape[0]
    if vertices and len(faces) and (faces.min() < 0 or faces.max() >= n):
        raise FormatError(f"{path / 'faces.npy'}: face indices outside the {n} vertices")
    try:
        energies = {k[7:]: np.array([float(r.get(k, 0.0)) for r in rows]) for k in keys}
        scalars = {key: np.array([cast(r[key]) for r in rows]) for key, cast in _SCALARS.items()}
    except (TypeError, ValueError) as exc:
        raise FormatError(f"track: {path / 'frames'}: a frame holds a bad value ({exc})") from None
    return Track(
        meta=meta,
        faces=faces,
        frames=np.array(frames),
        joints=np.stack([r["joints"] for r in rows]).astype(np.float64),
        vertices=np.stack([r["vertices"] for r in rows]).astype(np.float64),
        # 0 where a frame has no such term (the initial frame, a baseline without it)
        energies=energies,
        **scalars,
        flags=tuple(frame_flags(r) for r in rows),
        messages=tuple(str(r["message"]) for r in rows),
        start=_start_of_meta(meta, meta_path),
    )


#: The binding of a track made on a light body (module docstring).
LIGHT_FILE = "light.npz"


def write_light_binding(path: str | os.PathLike, binding: SurfaceBinding) -> None:
    """Write ``binding`` (:mod:`meshmocap.body.light`) into the track folder ``path``."""
    with atomic_open(Path(path) / LIGHT_FILE) as f:
        np.savez_compressed(
            f,
            F=binding.F.astype(np.int32),
            tri=binding.tri.astype(np.int32),
            bary=binding.bary,
            offset=binding.offset,
        )


def read_light_binding(path: str | os.PathLike) -> SurfaceBinding | None:
    """The binding of a track folder made on a light body, or None."""
    file = Path(path) / LIGHT_FILE
    if not file.is_file():
        return None
    z = read_npz(file, "light body binding")
    try:
        return SurfaceBinding(
            z["F"].astype(np.int64),
            z["tri"].astype(np.int64),
            z["bary"].astype(np.float64),
            z["offset"].astype(np.float64),
        )
    except KeyError as exc:
        raise FormatError(f"{file}: not a light body binding (no {exc})") from None


_SCALARS = {"n_iter": int, "seconds": float, "healthy": bool}
_FRAME_KEYS = ("index", "joints", "vertices", "n_iter", "seconds", "healthy", "message")


def read_frame_arrays(path: str | os.PathLike, index: int) -> dict[str, np.ndarray]:
    """The arrays of frame ``index``'s result file in the track folder ``path``, checked:
    finite (K, 3) joints and (n, 3) vertices, scalar counts.

    Raises
    ------
    FormatError
        Not a readable frame file, a missing key, a bad shape or a NaN.
    """
    p = frame_path(path, index)
    z = read_npz(p, "frame result", keys=_FRAME_KEYS)
    for key in ("joints", "vertices"):
        a = z[key]
        if a.ndim != 2 or a.shape[1] != 3 or a.dtype.kind not in "fiu" or not len(a):
            raise FormatError(f"{p}: {key} must be (n, 3) numbers, found {a.shape} {a.dtype}")
        if not np.isfinite(a).all():
            raise FormatError(f"{p}: {key} hold NaN or infinite values")
    for key in (*_SCALARS, "message", "index"):
        if z[key].ndim != 0:
            raise FormatError(f"{p}: {key} must be a scalar, found shape {z[key].shape}")
    return z


def _read_faces(path: Path) -> np.ndarray:
    if not path.is_file():
        raise MeshmocapFileNotFoundError(f"track: {path.parent} has no faces.npy")
    try:
        F = np.load(path, allow_pickle=False)
    except (OSError, ValueError, EOFError) as exc:
        raise FormatError(f"{path}: not a readable .npy array ({exc})") from None
    if F.ndim != 2 or F.shape[1] != 3 or F.dtype.kind not in "iu":
        raise FormatError(f"{path}: expected (m, 3) integer triangles, found {F.shape} {F.dtype}")
    return F.astype(np.int64)


def _read_json(path: Path) -> dict:
    try:
        meta = json.loads(path.read_text(encoding="utf-8"))
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise FormatError(f"{path}: not valid JSON ({exc})") from None
    if not isinstance(meta, dict):
        raise FormatError(f"{path}: expected a JSON object, found {type(meta).__name__}")
    return meta


def frame_flags(z: dict | np.lib.npyio.NpzFile) -> tuple[str, ...]:
    """The flags of a frame file's contents (files written before flags existed: ``failed``
    for an unhealthy frame, else none)."""
    if "flags" in z:
        text = str(z["flags"])
        flags = tuple(text.split(",")) if text else ()
        return tuple(f for f in flags if f in FRAME_FLAGS)
    return () if bool(z["healthy"]) else ("failed",)
