"""Synthetic captures with ground truth: a template plays a motion in front of virtual
cameras; silhouettes are rendered (optionally degraded), visual hulls carved, and the
truth (joints, posed vertices, pose parameters) stored beside them, frame by frame.

The result is a capture folder (:mod:`meshmocap.io.capture`) that trackers read like a
real one and that :mod:`meshmocap.analysis` scores against the truth.
"""

from __future__ import annotations

import dataclasses
import json
import os
import warnings
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from meshmocap._atomic import folder_lock
from meshmocap._parallel import Workers
from meshmocap._progress import progress
from meshmocap.body.template import Template, load_template
from meshmocap.errors import InputError, MeshmocapWarning, MissingFrameWarning
from meshmocap.geometry.camera import Camera
from meshmocap.geometry.silhouette import silhouette
from meshmocap.io.cameras import read_cameras, write_cameras
from meshmocap.io.capture import (
    Capture,
    Truth,
    frame_name,
    write_meta,
    write_truth,
    write_truth_faces,
)
from meshmocap.io.clips import clip_on
from meshmocap.io.silhouettes import write_mask
from meshmocap.studio.degrade import Degradation, degrade
from meshmocap.studio.hulls import carve_seen, frames_note, write_carved
from meshmocap.studio.rigs import camera_rig


@dataclass(frozen=True)
class SynthSpec:
    """What a synthetic capture is made of (stored in ``capture.json``).

    Parameters
    ----------
    motion : str
        A procedural motion name or a ``.bvh``/``.amc`` file.
    template : str
        The tracking template (name or ``.npz`` path) the capture is meant for.
    subject : str or None
        The body that performs (default: the tracking template); another body shape makes
        the subject differ from the template.
    rig : str
        ``"humaneva4"``, ``"ring8"`` or a camera file (JSON or OpenCV YAML).
    fps : float
        Frame rate the motion is resampled to.
    start, stop, step : int or None
        Frame range after resampling (Python slice semantics).
    degradation : Degradation
        Silhouette degradations (none by default).
    seed : int
        Seed of the degradations.
    voxel_size : float
        Visual-hull voxel edge, metres.
    heading : float
        Degrees: the whole motion turned about the vertical axis through the origin (the
        capture volume's centre), counter-clockwise seen from above.
    offset : (float, float)
        Metres: the whole motion shifted along x and y after the turn.
    source_fps : float or None
        The motion file's true frame rate where its header is wrong (CMU ``16_01.bvh``:
        30 in the header, 120 in fact); None: the header's.
    """

    motion: str = "walk"
    template: str = "neutral"
    subject: str | None = None
    rig: str = "humaneva4"
    fps: float = 60.0
    start: int | None = None
    stop: int | None = None
    step: int | None = None
    degradation: Degradation = field(default_factory=Degradation)
    seed: int = 0
    voxel_size: float = 0.01
    heading: float = 0.0
    offset: tuple[float, float] = (0.0, 0.0)
    source_fps: float | None = None

    def __post_init__(self) -> None:
        checks = (
            ("fps", self.fps, 0.0, 1000.0, "frames per second"),
            ("voxel_size", self.voxel_size, 0.002, 0.1, "metres"),
        )
        for name, v, lo, hi, unit in checks:
            ok = isinstance(v, int | float) and not isinstance(v, bool) and lo < v <= hi
            if not ok:
                raise InputError(
                    f"synth: {name} must be above {lo:g} up to {hi:g} {unit}, found {v!r}"
                )
        if not (isinstance(self.seed, int) and 0 <= self.seed < 2**32):
            raise InputError(
                f"synth: seed must be an integer from 0 to 2**32 - 1, found {self.seed!r}"
            )
        if not isinstance(self.degradation, Degradation):
            raise InputError(
                f"synth: degradation must be a Degradation, found {type(self.degradation).__name__}"
            )

    def as_dict(self) -> dict:
        """JSON-ready parameters (``heading`` and ``offset`` only where set, so captures
        made before they existed keep their parameters)."""
        d = dataclasses.asdict(self)
        d["motion"] = os.fspath(self.motion)
        d["degradation"] = self.degradation.as_dict()
        d["offset"] = [float(v) for v in self.offset]
        if not self.heading:
            del d["heading"]
        if not any(self.offset):
            del d["offset"]
        if d["source_fps"] is None:  # captures made before it existed keep their parameters
            del d["source_fps"]
        return d


def placed_motion(
    R: np.ndarray, root: np.ndarray, *, heading: float = 0.0, offset=(0.0, 0.0)
) -> tuple[np.ndarray, np.ndarray]:
    """A motion turned by ``heading`` degrees about the vertical axis through the origin and
    shifted by ``offset`` (x, y metres): local rotations ``R`` (T, J, 3, 3) (only the
    root's, whose parent is the world, changes) and root positions ``root`` (T, 3), world
    frame Z up. Returns new arrays."""
    off = np.asarray(offset, dtype=np.float64)
    if not (np.isfinite(heading) and off.shape == (2,) and np.all(np.isfinite(off))):
        raise InputError(
            f"synth: heading must be a number of degrees and offset two numbers "
            f"(x, y metres), found {heading!r} and {offset!r}"
        )
    a = np.deg2rad(float(heading))
    Rz = np.array([[np.cos(a), -np.sin(a), 0.0], [np.sin(a), np.cos(a), 0.0], [0.0, 0.0, 1.0]])
    R = np.array(R, dtype=np.float64)
    R[:, 0] = Rz @ R[:, 0]
    root = np.asarray(root, dtype=np.float64) @ Rz.T + np.array([*off, 0.0])
    return R, root


def _cameras(rig: str) -> list[Camera]:
    if Path(rig).suffix.lower() in (".json", ".yml", ".yaml"):
        return read_cameras(rig)
    return camera_rig(rig)  # validates the preset name


def synthesize(
    out: str | os.PathLike, spec: SynthSpec = SynthSpec(), *, show_progress: bool | None = None
) -> Capture:
    """Write a synthetic capture of ``spec`` to the folder ``out`` and return it.

    Frames already complete in ``out`` (from an interrupted run with the same ``spec``)
    are kept; a folder holding a capture of another ``spec`` is refused.

    Raises
    ------
    InputError
        ``out`` holds a capture made with other parameters, or the frame range is empty.
    """
    out = Path(out)
    subject = load_template(spec.subject or spec.template)
    fix = {"source_fps": spec.source_fps} if spec.source_fps is not None else {}
    motion = clip_on(subject, spec.motion, fps=spec.fps, **fix)
    rotations, roots = placed_motion(
        motion.rotations, motion.root_positions, heading=spec.heading, offset=spec.offset
    )
    frames = _check_range(spec, motion.n_frames, os.fspath(spec.motion))
    cameras = _cameras(spec.rig)
    if spec.degradation.missed_limb_joint is not None:  # checked before any frame is made
        hidden_faces(subject, spec.degradation.missed_limb_joint)
    meta = {
        "fps": motion.fps / (spec.step or 1),
        "frames": frames,
        "spec": spec.as_dict(),
        "cameras": [c.name for c in cameras],
        "eval_names": list(subject.eval_skeleton.names),
        "subject_vertices": subject.n_vertices,
    }
    meta_path = out / "capture.json"
    if meta_path.is_file():
        old = json.loads(meta_path.read_text())
        if old.get("spec") != json.loads(json.dumps(meta["spec"])):
            raise InputError(
                f"synth: {out} holds a capture made with other parameters; use a new folder"
            )
    for sub in ["hulls", "truth", *(f"silhouettes/{c.name}" for c in cameras)]:
        (out / sub).mkdir(parents=True, exist_ok=True)
    write_cameras(out / "cameras.json", cameras)
    write_meta(meta_path, meta)
    write_truth_faces(out, subject.F)
    todo = [f for f in frames if not (out / "truth" / f"{frame_name(f)}.npz").is_file()]
    notes = {}

    def make(f: int) -> str:
        return synth_frame(out, subject, rotations[f], roots[f], cameras, f, spec)

    # the frames side by side, one process a core (meshmocap._parallel): the same files
    with folder_lock(out, "synth"), Workers(make, len(todo)) as workers:
        made = progress(
            workers.imap([(f,) for f in todo]),
            total=len(todo),
            label="synth",
            enabled=show_progress,
        )
        for f, note in zip(todo, made, strict=True):
            notes[f] = note
    _warn_notes(notes)
    return Capture(out)


def _warn_notes(notes: dict[int, str]) -> None:
    """One warning for the frames carved from fewer cameras or left without hull."""
    partial = {f: n for f, n in notes.items() if n.startswith("carved from")}
    missing = {f: n for f, n in notes.items() if n and f not in partial}
    if partial or missing:
        warnings.warn(f"synth: {frames_note(partial, missing)}", MissingFrameWarning, stacklevel=3)


def _check_range(spec: SynthSpec, n_frames: int, source: str) -> list[int]:
    """The frames of ``spec``'s range; warns when STOP asks for more than the motion has."""
    for name in ("start", "stop"):
        v = getattr(spec, name)
        if v is not None and (not isinstance(v, int) or v < 0):
            raise InputError(f"synth: {name} must be a frame number ≥ 0, found {v!r}")
    if spec.step is not None and (not isinstance(spec.step, int) or spec.step < 1):
        raise InputError(f"synth: step must be an integer ≥ 1, found {spec.step!r}")
    frames = list(range(n_frames))[slice(spec.start, spec.stop, spec.step)]
    if not frames:
        raise InputError(
            f"synth: frame range {spec.start}:{spec.stop}:{spec.step} selects none of the "
            f"{n_frames} frames of {source}"
        )
    if spec.stop is not None and spec.stop > n_frames:
        warnings.warn(
            f"synth: frames {spec.start or 0}:{spec.stop} asked, but {source} has {n_frames} "
            f"frames at {spec.fps:g} fps: writing {len(frames)}",
            MeshmocapWarning,
            stacklevel=3,
        )
    return frames


def synth_frame(
    out: Path,
    subject: Template,
    R: np.ndarray,
    root: np.ndarray,
    cameras: list[Camera],
    index: int,
    spec: SynthSpec,
) -> str:
    """Pose the subject for one frame and write it (see :func:`write_frame`)."""
    posed = subject.pose(R, root)
    truth = Truth(posed.V, posed.eval_joints, R, root)
    deg = spec.degradation
    hidden = None
    if deg.missed_limb_joint is not None and deg.misses_limb(index):
        hidden = hidden_faces(subject, deg.missed_limb_joint)
    return write_frame(
        out,
        posed.V,
        subject.F,
        cameras,
        index,
        truth,
        degradation=spec.degradation,
        seed=spec.seed,
        voxel_size=spec.voxel_size,
        hidden=hidden,
    )


def hidden_faces(subject: Template, joint: str) -> np.ndarray:
    """(m,) bool: the faces of ``subject`` on the body parts of evaluation joint ``joint``
    and of the joints below it (a missed limb)."""
    ev = subject.eval_skeleton
    if joint not in ev.names:
        raise InputError(
            f"synth: missed_limb_joint must be one of {list(ev.names)}, found {joint!r}"
        )
    parts = {ev.names.index(joint)}
    for k in range(len(ev.names)):  # parents come first: one pass collects the subtree
        if ev.parents[k] in parts:
            parts.add(k)
    on = np.isin(subject.part_labels, sorted(parts))
    return on[subject.F].all(axis=1)


def write_frame(
    out: Path,
    V: np.ndarray,
    F: np.ndarray,
    cameras: list[Camera],
    index: int,
    truth: Truth,
    *,
    degradation: Degradation,
    seed: int,
    voxel_size: float,
    hidden: np.ndarray | None = None,
) -> str:
    """Render the silhouettes of mesh ``(V, F)``, degrade them, carve the hull and write the
    frame; the truth file is written last (it marks the frame complete). ``hidden`` (m,)
    bool: faces no camera sees (a missed limb: the silhouettes are those of the rest of
    the body, so the limb's pixels off the rest are lost in every view). Returns the hull's
    note (cameras left out because the subject left their view; empty when none)."""
    masks = []
    for c, cam in enumerate(cameras):
        if hidden is None:
            mask = silhouette(V, F, cam, assume_closed=True)
        else:  # the rest of the body, an open mesh: every face drawn
            mask = silhouette(V, F[~hidden], cam)
        if degradation != Degradation():
            mask = degrade(
                mask, degradation, seed=np.random.SeedSequence([seed, index, c]), frame=index
            )
        write_mask(out / "silhouettes" / cam.name / f"{frame_name(index)}.png", mask)
        masks.append(mask)
    # a subject that walks out of a camera's view is carved from the cameras that see it
    carved = carve_seen(masks, cameras, voxel_size=voxel_size)
    name = frame_name(index)
    write_carved(out / "hulls" / f"{name}.npz", carved)
    write_truth(out / "truth" / f"{name}.npz", truth)
    return carved.note


def synthesize_from_meshes(
    source: str | os.PathLike,
    out: str | os.PathLike,
    *,
    rig: str = "ring8",
    frames: range | slice | None = None,
    up: str = "y",
    degradation: Degradation | None = None,
    seed: int = 0,
    voxel_size: float = 0.01,
    show_progress: bool | None = None,
) -> Capture:
    """Make a capture of a real mesh sequence (e.g. the MIT crane): each frame is rendered
    into the rig's silhouettes and carved into a visual hull, so no coherence between frames
    is left; the original vertices are kept as truth (per-vertex correspondences when the
    sequence has fixed connectivity).

    The sequence is moved (one translation for all frames, stored as ``offset`` in
    ``capture.json``) so that frame 0 stands on z = 0 centred at x = y = 0, inside the rig.

    Parameters
    ----------
    source : path
        Folder, glob or archive of meshes (:class:`~meshmocap.io.meshes.MeshSequence`).
    up : {"y", "z"}
        Up axis of the files (the crane is Y up).
    """
    from meshmocap.io.meshes import MeshSequence

    degradation = degradation or Degradation()
    seq = MeshSequence(source, frames=frames, kind="mesh", up=up)
    out = Path(out)
    cameras = _cameras(rig)
    first = seq[0]
    offset = -np.array([*first.V[:, :2].mean(axis=0), first.V[:, 2].min()])
    meta = {
        "fps": 30.0,
        "frames": [int(i) for i in seq.indices],
        "offset": offset.tolist(),
        "spec": {
            "source": os.fspath(source),
            "rig": rig,
            "up": up,
            "seed": seed,
            "voxel_size": voxel_size,
            "degradation": degradation.as_dict(),
        },
        "cameras": [c.name for c in cameras],
        "subject_vertices": len(first.V),
    }
    meta_path = out / "capture.json"
    if meta_path.is_file() and json.loads(meta_path.read_text()).get("spec") != json.loads(
        json.dumps(meta["spec"])
    ):
        raise InputError(
            f"synth: {out} holds a capture made with other parameters; use a new folder"
        )
    for sub in ["hulls", "truth", *(f"silhouettes/{c.name}" for c in cameras)]:
        (out / sub).mkdir(parents=True, exist_ok=True)
    write_cameras(out / "cameras.json", cameras)
    write_meta(meta_path, meta)
    todo = [
        k
        for k, i in enumerate(seq.indices)
        if not (out / "truth" / f"{frame_name(int(i))}.npz").is_file()
    ]
    notes = {}
    for k in progress(todo, label="synth", enabled=show_progress):
        fr = seq[k]
        V = fr.V + offset
        notes[fr.index] = write_frame(
            out,
            V,
            fr.F,
            cameras,
            fr.index,
            Truth(V),
            degradation=degradation,
            seed=seed,
            voxel_size=voxel_size,
        )
    _warn_notes(notes)
    return Capture(out)
