"""meshmocap in a few calls, for notebooks and scripts.

>>> import meshmocap
>>> cap = meshmocap.open_capture("walk-cap")                  # doctest: +SKIP
>>> track = meshmocap.track(cap, method="patch")              # doctest: +SKIP
>>> track.joints.shape                                        # doctest: +SKIP
(6, 15, 3)
>>> track.to_bvh("walk.bvh")                                  # doctest: +SKIP
>>> print(meshmocap.summary(meshmocap.evaluate(cap, track)))  # doctest: +SKIP

Each call is the one the command line makes: ``meshmocap track`` opens its capture with
:func:`open_capture` and tracks it with :func:`track`, ``meshmocap eval`` scores it with
:func:`evaluate` and prints :func:`summary`, so the numbers are the same.
``import meshmocap`` stays light: these names load on first use.
"""

from __future__ import annotations

import os
import tempfile
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Literal

import numpy as np

from meshmocap._timing import StageTimer
from meshmocap.analysis.evaluate import Evaluation, summary
from meshmocap.analysis.evaluate import evaluate as evaluate_track
from meshmocap.analysis.gait import Gait, track_gait
from meshmocap.apps.export import ExportFormat, ExportResult, export_track, track_fps
from meshmocap.apps.kernels import kernels_of, start_compiling
from meshmocap.body.light import LIGHT_VERTICES, tracking_body
from meshmocap.body.template import Template
from meshmocap.errors import InputError
from meshmocap.estimate.axes import Axes, open_oriented
from meshmocap.estimate.tracking_template import tracking_template
from meshmocap.io.capture import (
    Capture,
    SequenceCapture,
    Truth,
    frame_name,
    write_meta,
    write_truth,
    write_truth_faces,
)
from meshmocap.io.guards import check_track_capture
from meshmocap.io.meshes import frame_files, write_mesh
from meshmocap.io.results import (
    Track,
    input_meta,
    open_tracked_capture,
    read_track,
    tracked_template,
)
from meshmocap.trackers.driver import track_sequence
from meshmocap.trackers.registry import MANIFOLD_METHODS, METHODS, make_tracker

__all__ = [
    "TrackResult",
    "capture_and_axes",
    "evaluate",
    "example_capture",
    "open_capture",
    "open_track",
    "summary",
    "track",
]

#: What :func:`open_capture` takes: a capture folder, a mesh or point-cloud file, folder,
#: quoted glob or archive, or several mesh files and folders.
Source = str | os.PathLike | Sequence[str | os.PathLike]


def capture_and_axes(
    source: Source,
    *,
    up: Literal["auto", "z", "y"] = "auto",
    units: Literal["auto", "m", "cm", "mm"] = "auto",
    fps: float | None = None,
) -> tuple[Capture | SequenceCapture, Axes | None]:
    """:func:`open_capture`, and the up axis and units it read from a mesh sequence's first
    frame (None for a capture folder, which is metres and Z up by its format)."""
    sources = [source] if isinstance(source, str | os.PathLike) else list(source)
    if not sources:
        raise InputError("open_capture: expected a capture folder or mesh files, found none")
    if len(sources) == 1:
        return open_oriented(sources[0], up=up, units=units, fps=fps)
    folders = [
        s for s in sources if (Path(s) / "capture.json").is_file() or (Path(s) / "hulls").is_dir()
    ]
    if folders:
        raise InputError(
            f"track: give one capture folder, or several mesh files and folders; "
            f"{folders[0]} is a capture folder"
        )
    return open_oriented(frame_files(sources), up=up, units=units, fps=fps)


def open_capture(
    source: Source,
    *,
    up: Literal["auto", "z", "y"] = "auto",
    units: Literal["auto", "m", "cm", "mm"] = "auto",
    fps: float | None = None,
) -> Capture | SequenceCapture:
    """Open what ``meshmocap track`` tracks, in metres with Z up.

    Parameters
    ----------
    source : path or sequence of paths
        A capture folder (``meshmocap synth``, ``meshmocap hull``), or mesh or point-cloud
        files (OBJ, PLY, OFF, STL, ...): a folder of them, a quoted glob, an archive, or
        several files and folders.
    up : {"auto", "z", "y"}
        Mesh files: their up axis (default: detected from the first frame).
    units : {"auto", "m", "cm", "mm"}
        Mesh files: their length unit (default: detected from the body's size).
    fps : float, optional
        Mesh files: their frame rate (default: 30, recorded as assumed).

    Returns
    -------
    Capture or SequenceCapture
        ``len(capture)`` frames; ``capture[k]`` reads frame ``k`` when asked.
    """
    return capture_and_axes(source, up=up, units=units, fps=fps)[0]


@dataclass(frozen=True, eq=False)
class TrackResult:
    """A track folder and what it holds (:func:`track`, :func:`open_track`).

    Attributes
    ----------
    path : Path, the track folder (``meshmocap report``, ``export`` and ``gait`` read it)
    data : Track, its results read back (:class:`~meshmocap.io.results.Track`)
    template : Template, the tracking template (the estimated body, if it was estimated)
    note : str, how the template was chosen (one line)
    seconds : float, wall time of the run (0 for a track opened from disk)
    """

    path: Path
    data: Track
    template: Template
    note: str = ""
    seconds: float = 0.0

    @property
    def joints(self) -> np.ndarray:
        """(F, 15, 3) float64, the evaluation joints per frame, metres, Z up."""
        return self.data.joints

    @property
    def vertices(self) -> np.ndarray:
        """(F, n, 3) float64, the template's vertices per frame, metres, Z up."""
        return self.data.vertices

    @property
    def faces(self) -> np.ndarray:
        """(m, 3) int64, the template's triangles."""
        return self.data.faces

    @property
    def frames(self) -> np.ndarray:
        """(F,) int64, the capture frame number of each row."""
        return self.data.frames

    @property
    def healthy(self) -> np.ndarray:
        """(F,) bool, frames the tracker trusts (``data.flags`` says why not)."""
        return self.data.healthy

    @property
    def parents(self) -> np.ndarray:
        """(15,) int64, each evaluation joint's parent in :attr:`joints` (-1: the root)."""
        return np.asarray(self.data.meta.get("eval_parents", ()), dtype=np.int64)

    @property
    def method(self) -> str:
        """The tracker (``patch``, ``cage``, ``articulated_icp``, ...)."""
        return str(self.data.meta.get("method", ""))

    @property
    def fps(self) -> float:
        """Frames per second: the capture's (``capture.json``), else 30."""
        return track_fps(self.data)[0]

    def export(
        self, out: str | os.PathLike, *, format: ExportFormat | None = None, **options
    ) -> ExportResult:
        """Write the track as ``out`` (``.bvh``, ``.glb``, ``.gltf``, ``.c3d``, ``.trc``,
        ``.csv``): :func:`meshmocap.apps.export.export_track`, options included."""
        options.setdefault("template", self.template)
        return export_track(self.path, out, format=format, **options)

    def to_bvh(self, out: str | os.PathLike, **options) -> ExportResult:
        """Write the template's rig and its motion as a BVH file (Y up, centimetres)."""
        return self.export(out, format="bvh", **options)

    def to_glb(self, out: str | os.PathLike, **options) -> ExportResult:
        """Write the template as a skinned, animated mesh (binary glTF, Y up, metres)."""
        return self.export(out, format="glb", **options)

    def gait(self, *, fps: float | None = None) -> Gait:
        """Gait events, cycles and flexion curves (:func:`~meshmocap.analysis.gait.
        track_gait`) at ``fps`` (default: :attr:`fps`)."""
        return track_gait(self.data, fps or self.fps)


def track(
    capture: Capture | SequenceCapture | Source,
    *,
    method: str = "patch",
    out: str | os.PathLike | None = None,
    template: str | os.PathLike | None = None,
    frames: Sequence[int] | slice | None = None,
    init: Literal["auto", "truth"] = "auto",
    resume: bool = True,
    recover: bool = True,
    reseat: bool = False,
    manifold: str | os.PathLike | None = None,
    vertices: bool = True,
    show_progress: bool | None = None,
    log: Callable[[str], object] | None = None,
    timer: StageTimer | None = None,
    **options,
) -> TrackResult:
    """Track a capture, as ``meshmocap track`` does.

    Parameters
    ----------
    capture : Capture, SequenceCapture or what :func:`open_capture` opens
    method : str
        A tracker of :data:`meshmocap.trackers.registry.METHODS`: ``patch`` (default),
        ``cage``, ``articulated_icp`` and their variants.
    out : path, optional
        The track folder (frame-by-frame results; an interrupted run resumes there). Default:
        a new temporary folder, kept (``result.path``).
    template : name or .npz path, optional
        The tracking template; ``"auto"`` estimates the performer's body. Default: the one
        the capture's ``capture.json`` names, else ``"auto"``.
    frames : sequence of int or slice, optional
        Positions in the capture to track (default: all).
    init : {"auto", "truth"}
        The first pose: found from the capture, or copied from its ground truth.
    resume : bool
        Continue a run in ``out`` instead of starting over (False also re-estimates).
    recover, reseat : bool
        Score frames and flag lost limbs; re-seat lost limbs
        (:func:`~meshmocap.trackers.driver.track_sequence`).
    manifold : path, optional
        Cage methods: a pose manifold from ``meshmocap learn`` (default: learned once).
    vertices : bool
        Read the tracked vertices back into the result (False for long runs: ``vertices``
        is then empty; exports read them from the folder).
    show_progress : bool, optional
        Progress lines while tracking (default: where the output is not a terminal, every
        few seconds).
    log : callable, optional
        Called with one line on how the template was chosen (the CLI prints it).
    timer : StageTimer, optional
        Records each frame's seconds per stage (read, observe, step, checks, write;
        :mod:`meshmocap._timing`): ``timer.summary()`` says where a frame's time goes.
    **options
        Options of the method's tracker (``n_patches``, ``max_iter``, ...).

    Returns
    -------
    TrackResult
    """
    if method not in METHODS:
        raise InputError(f"track: method must be one of {sorted(METHODS)}, found {method!r}")
    if not isinstance(capture, Capture | SequenceCapture):
        capture = open_capture(capture)
    if isinstance(frames, slice):
        frames = range(len(capture))[frames]
    folder = Path(out) if out is not None else Path(tempfile.mkdtemp(prefix="meshmocap-track-"))
    # a fresh install's kernels compile in the background while the body is estimated and
    # the first pose found (meshmocap.apps.kernels)
    start_compiling(kernels_of(method))
    choice = tracking_template(capture, template, folder, refresh=not resume)
    say = log or (lambda line: None)
    say(choice.note)
    start = choice.start  # a template made from a frame starts in that frame's pose
    if start is not None and frames is not None and capture.indices[frames[0]] != start[0]:
        start = None
    if method in MANIFOLD_METHODS and manifold is None:
        say(
            f"{method}: no --manifold given: the default pose manifold of the tracked body "
            "(learned from the bundled CMU pose library at first use, then cached)"
        )
    # tracked on a light copy of the template, unless a manifold learned for the template
    # itself is given (meshmocap.body.light)
    light = None if manifold is not None else LIGHT_VERTICES
    tracked = tracking_body(choice.template, n_vertices=light).light
    tracker = make_tracker(method, manifold=manifold, template=tracked, **options)
    t0 = time.perf_counter()
    data = track_sequence(
        tracker,
        choice.template,
        capture,
        folder,
        frames=frames,
        resume=resume,
        init=init,
        recover=recover,
        reseat=reseat,
        vertices=vertices,
        show_progress=show_progress,
        template_info={**choice.info, **input_meta(capture)},
        light=light,
        start=start,
        timer=timer,
    )
    return TrackResult(folder, data, choice.template, choice.note, time.perf_counter() - t0)


def open_track(path: str | os.PathLike, *, template: Template | str | None = None) -> TrackResult:
    """A track folder written by ``meshmocap track`` or :func:`track`.

    ``template`` is needed only for a template that is neither bundled nor saved in the
    folder (an estimated body is saved there)."""
    data = read_track(path)
    if template is None:
        body = tracked_template(path, data.meta)
    elif isinstance(template, Template):
        body = template
    else:
        from meshmocap.body.template import load_template

        body = load_template(template)
    return TrackResult(Path(path), data, body, note=f"template {body.name!r}")


def evaluate(
    capture: Capture | SequenceCapture | Source,
    track: TrackResult | Track | str | os.PathLike,
    *,
    silhouettes: bool = True,
    surface_frames: int = 8,
    force: bool = False,
) -> Evaluation:
    """Score ``track`` against ``capture``'s ground truth, as ``meshmocap eval`` does.

    Parameters
    ----------
    capture : Capture, or a capture folder or the mesh files tracked
        Mesh files are read in the up axis, units and frame rate the track records
        (:func:`~meshmocap.io.results.open_tracked_capture`).
    track : TrackResult, Track, or a track folder
    silhouettes : bool
        Also re-project the tracked mesh into every camera (Table II of the patch paper).
    surface_frames : int
        Frames on which surface distances are sampled (0: none).
    force : bool
        Score against a capture other than the one the track names (refused otherwise,
        :class:`~meshmocap.errors.CaptureMismatchError`).

    Returns
    -------
    Evaluation
        Joint errors in millimetres (``.joints.overall.mean``...), bone lengths, silhouette
        and surface errors, per-vertex errors for a mesh sequence of fixed connectivity.
        Absent parts (no truth, no cameras) are None; :func:`summary` gives the table
        ``meshmocap eval`` prints.
    """
    if isinstance(track, TrackResult):
        label, track = str(track.path), track.data
    elif isinstance(track, Track):
        label = "the track"
    else:
        label, track = str(track), read_track(track)
    if not isinstance(capture, Capture | SequenceCapture):
        capture = open_tracked_capture(track.meta, capture)
    check_track_capture(label, track.meta, capture, force=force, command="eval")
    return evaluate_track(track, capture, silhouettes=silhouettes, surface_frames=surface_frames)


#: Metres per unit of :func:`example_capture`'s mesh files.
UNITS = {"m": 1.0, "cm": 0.01, "mm": 0.001}


def example_capture(
    out: str | os.PathLike,
    *,
    motion: str = "walk",
    n_frames: int = 60,
    fps: float = 30.0,
    performer: str = "neutral_5k",
    up: Literal["y", "z"] = "y",
    units: Literal["m", "cm", "mm"] = "cm",
) -> Path:
    """Write a small 4D capture as studios export them, to try the tools on.

    ``out/meshes/frame_000.obj``, ...: the body ``performer`` doing ``motion`` (a procedural
    motion: walk, jog, squat, ...), one OBJ file per frame in ``units`` with ``up`` up (a
    studio's meshes come in its own axes and units; ``meshmocap track`` detects them), and
    ``out/reference/``: its ground truth as a capture folder (``capture.json`` with the
    rate, ``truth/NNNNN.npz``: the surface in metres with Z up and the 15 evaluation joints),
    which ``meshmocap eval`` scores a track of the meshes against.

    Returns
    -------
    Path
        ``out``.
    """
    from meshmocap.body.procedural import procedural_motion
    from meshmocap.body.template import load_template

    if units not in UNITS or up not in ("y", "z"):
        raise InputError(
            f"example_capture: units must be one of {list(UNITS)} and up 'y' or 'z', "
            f"found {units!r}, {up!r}"
        )
    if not (isinstance(n_frames, int) and 1 <= n_frames <= 10_000 and fps > 0):
        raise InputError(
            f"example_capture: expected 1 to 10000 frames at a positive rate, found "
            f"{n_frames!r} at {fps!r}"
        )
    body = load_template(performer)
    m = procedural_motion(motion, body, duration=n_frames / fps, fps=fps)
    posed = body.pose(m.rotations[:n_frames], m.root_positions[:n_frames])
    root = Path(out)
    (root / "meshes").mkdir(parents=True, exist_ok=True)
    (root / "reference" / "truth").mkdir(parents=True, exist_ok=True)
    write_meta(root / "reference" / "capture.json", {"fps": float(fps), "source": performer})
    write_truth_faces(root / "reference", body.F)
    for k in range(len(posed.V)):
        write_mesh(root / "meshes" / f"frame_{k:03d}.obj", posed.V[k] / UNITS[units], body.F, up=up)
        truth = Truth(posed.V[k], posed.eval_joints[k])
        write_truth(root / "reference" / "truth" / f"{frame_name(k)}.npz", truth)
    return root
