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
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Literal, get_args

import numpy as np

from meshmocap._timing import StageTimer
from meshmocap._validate import check_choice, check_type
from meshmocap.analysis.evaluate import Evaluation
from meshmocap.analysis.evaluate import evaluate as evaluate_track
from meshmocap.analysis.evaluate import summary as evaluation_summary
from meshmocap.analysis.gait import Gait, track_gait
from meshmocap.apps.files.export import ExportFormat, ExportResult, export_track, track_fps
from meshmocap.apps.kernels import kernels_of, start_compiling
from meshmocap.body.light import tracking_body
from meshmocap.body.template import Template
from meshmocap.errors import InputError
from meshmocap.estimate.performer.tracking_template import SUBJECT_FILE, tracking_template
from meshmocap.io.axes import UNITS as UNIT_METRES
from meshmocap.io.axes import Axes, open_oriented
from meshmocap.io.capture import (
    Capture,
    SequenceCapture,
    Truth,
    frame_name,
    write_meta,
    write_truth,
    write_truth_faces,
)
from meshmocap.io.guards import check_resumable, check_track_capture
from meshmocap.io.live import LiveCapture
from meshmocap.io.meshes import frame_files, write_mesh
from meshmocap.io.results import (
    FrameResult,
    Track,
    input_meta,
    open_tracked_capture,
    read_track,
    tracked_template,
)
from meshmocap.trackers.driver import track_sequence
from meshmocap.trackers.follow import body_capture, open_live
from meshmocap.trackers.options import TrackOptions
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

#: What the functions below take as a capture: one opened, or what :func:`open_capture` opens.
AnyCapture = Capture | SequenceCapture | LiveCapture

_PATH = (str, os.PathLike)
_NUMBER = (int, float, np.integer, np.floating)


def _check_source(func: str, name: str, source: object) -> list:
    """``source`` as a list of paths, or one line naming what it is instead."""
    if isinstance(source, _PATH):
        return [source]
    what = "a path (str or os.PathLike) or a sequence of paths"
    if isinstance(source, bytes) or not isinstance(source, Sequence | np.ndarray):
        check_type(func, name, source, _PATH, what)
    items = list(source)
    for k, item in enumerate(items):
        check_type(func, f"{name}[{k}]", item, _PATH, "a path (str or os.PathLike)")
    return items


def _check_optional(func: str, name: str, value: object, types, expected: str) -> None:
    if value is not None:
        check_type(func, name, value, types, f"{expected} or None")


def _check_rate(func: str, name: str, value: object) -> None:
    """``value``: None or a positive finite number of frames (or seconds) per second."""
    _check_optional(func, name, value, _NUMBER, "a number")
    if value is not None and not (np.isfinite(value) and value > 0):
        raise InputError(f"{func}: {name} must be a positive number, found {value!r}")


def capture_and_axes(
    source: Source,
    *,
    up: Literal["auto", "z", "y"] = "auto",
    units: Literal["auto", "m", "cm", "mm"] = "auto",
    fps: float | None = None,
    follow: bool = False,
    idle: float | None = None,
    stop: Callable[[], bool] | None = None,
) -> tuple[AnyCapture, Axes | None]:
    """:func:`open_capture`, and the up axis and units it read from a mesh sequence's first
    frame (None for a capture folder, which is metres and Z up by its format)."""
    func = "open_capture"
    sources = _check_source(func, "source", source)
    check_choice(func, "up", up, ("auto", "z", "y"))
    check_choice(func, "units", units, ("auto", *UNIT_METRES))
    _check_rate(func, "fps", fps)
    check_type(func, "follow", follow, bool, "True or False")
    _check_rate(func, "idle", idle)
    _check_optional(func, "stop", stop, Callable, "a callable")
    if not sources:
        raise InputError("open_capture: expected a capture folder or mesh files, found none")
    if follow:
        if len(sources) != 1:
            raise InputError(
                f"track --follow: give one folder (a capture or meshes), found {len(sources)}"
            )
        return open_live(sources[0], up=up, units=units, fps=fps, idle=idle, stop=stop)
    if idle is not None or stop is not None:
        raise InputError("open_capture: idle and stop go with follow=True")
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
    follow: bool = False,
    idle: float | None = None,
    stop: Callable[[], bool] | None = None,
) -> AnyCapture:
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
    follow : bool
        ``source`` is one folder that a studio is still writing frames into (live mode,
        ``track --follow``): wait for its first frame with a body and return a
        :class:`~meshmocap.io.live.LiveCapture`, whose length grows as frames appear;
        :func:`track` tracks each as it comes (:mod:`meshmocap.trackers.follow`).
    idle : float, optional
        With ``follow``: the capture ends after this many seconds without a new frame
        (default: never; Ctrl-C stops).
    stop : callable, optional
        With ``follow``: asked while waiting for frames; the capture ends when it returns
        True.

    Returns
    -------
    Capture, SequenceCapture or LiveCapture
        ``len(capture)`` frames; ``capture[k]`` reads frame ``k`` when asked.
    """
    return capture_and_axes(
        source, up=up, units=units, fps=fps, follow=follow, idle=idle, stop=stop
    )[0]


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
        ``.csv``): :func:`meshmocap.apps.files.export.export_track`, options included."""
        check_type("TrackResult.export", "out", out, _PATH, "a file path (str or os.PathLike)")
        if format is not None:
            check_choice("TrackResult.export", "format", format, get_args(ExportFormat))
        options.setdefault("template", self.template)
        return export_track(self.path, out, format=format, **options)

    def to_bvh(self, out: str | os.PathLike, **options) -> ExportResult:
        """Write the template's rig and its motion as a BVH file (Y up, centimetres)."""
        check_type("TrackResult.to_bvh", "out", out, _PATH, "a file path (str or os.PathLike)")
        return self.export(out, format="bvh", **options)

    def to_glb(self, out: str | os.PathLike, **options) -> ExportResult:
        """Write the template as a skinned, animated mesh (binary glTF, Y up, metres)."""
        check_type("TrackResult.to_glb", "out", out, _PATH, "a file path (str or os.PathLike)")
        return self.export(out, format="glb", **options)

    def gait(self, *, fps: float | None = None) -> Gait:
        """Gait events, cycles and flexion curves (:func:`~meshmocap.analysis.gait.
        track_gait`) at ``fps`` (default: :attr:`fps`)."""
        _check_rate("TrackResult.gait", "fps", fps)
        return track_gait(self.data, fps or self.fps)


def track(
    capture: AnyCapture | Source,
    *,
    method: str = "patch",
    out: str | os.PathLike | None = None,
    template: str | os.PathLike | None = None,
    manifold: str | os.PathLike | None = None,
    options: TrackOptions | None = None,
    frames: Sequence[int] | slice | None = None,
    positions: Sequence[int] | slice | None = None,
    init: Literal["auto", "truth"] = "auto",
    resume: bool = True,
    recover: bool = True,
    refine: Literal["auto", "on", "arap", "off"] = "auto",
    passes: Literal["two-way", "forward"] = "two-way",
    vertices: bool = True,
    show_progress: bool | None = None,
    log: Callable[[str], object] | None = None,
    on_frame: Callable[[FrameResult], object] | None = None,
    timer: StageTimer | None = None,
    **tracker_options,
) -> TrackResult:
    """Track a capture, as ``meshmocap track`` does.

    How to track is one record, :class:`~meshmocap.trackers.options.TrackOptions`, which
    the command line and the driver share: give it as ``options``, or give its fields as
    keywords (``frames``, ``positions``, ``init``, ``resume``, ``recover``, ``refine``,
    ``passes``, ``vertices``, ``show_progress``), which build it; a keyword set to other than its
    default replaces that field of a given record.

    Parameters
    ----------
    capture : Capture, SequenceCapture, LiveCapture or what :func:`open_capture` opens
        A :class:`~meshmocap.io.live.LiveCapture` (``open_capture(folder, follow=True)``)
        is tracked as its frames appear, until it stops growing (live mode, ``track
        --follow``); the performer's body is then estimated from its first frames
        (:func:`~meshmocap.trackers.follow.body_capture`).
    method : str
        A tracker of :data:`meshmocap.trackers.registry.METHODS`: ``patch`` (default),
        ``cage``, ``articulated_icp`` and their variants.
    out : path, optional
        The track folder (frame-by-frame results; an interrupted run resumes there). Default:
        a new temporary folder, kept (``result.path``).
    template : name or .npz path, optional
        The tracking template; ``"auto"`` estimates the performer's body. Default: the one
        the capture's ``capture.json`` names, else ``"auto"``.
    manifold : path, optional
        Cage methods: a pose manifold from ``meshmocap learn`` (default: learned once).
    options : TrackOptions, optional
        How to track (default: built from the keywords below).
    frames : sequence of int or slice, optional
        The frame NUMBERS to track, in the order given (default: all), as ``--frames`` on
        the command line: ``slice(3, 9)`` is frames 3 to 8 wherever the capture starts.
    positions : sequence of int or slice, optional
        The frames to track by their positions in the capture (0: its first frame),
        instead of ``frames``.
    init : {"auto", "truth"}
        The first pose: found from the capture, or copied from its ground truth.
    resume : bool
        Continue a run in ``out`` instead of starting over (False also re-estimates).
    recover : bool
        Score frames and flag lost limbs
        (:class:`~meshmocap.estimate.recovery.reinit.Recovery`).
    refine : {"auto", "on", "arap", "off"}
        Refine each frame's output surface towards its observations
        (:class:`~meshmocap.trackers.options.TrackOptions`: along the normals, or as
        rigidly as possible; ``"auto"``: ``"arap"`` for mesh and point-cloud files, not
        a capture folder's visual hulls); ``"off"`` outputs the tracked skeleton's surface
        as it is.
    passes : {"two-way", "forward"}
        After the forward pass, the two-way pass over the frames it flagged lost
        (:mod:`meshmocap.trackers.two_way`; not for a live capture), or the forward pass
        alone.
    vertices : bool
        Read the tracked vertices back into the result (False for long runs: ``vertices``
        is then empty; exports read them from the folder).
    show_progress : bool, optional
        Progress lines while tracking (default: where the output is not a terminal, every
        few seconds).
    log : callable, optional
        Called with one line on how the template was chosen (the CLI prints it).
    on_frame : callable, optional
        Called with each frame's :class:`~meshmocap.io.results.FrameResult` once it is
        written (live mode prints them).
    timer : StageTimer, optional
        Records each frame's seconds per stage (read, observe, step, checks, write;
        :mod:`meshmocap._timing`): ``timer.summary()`` says where a frame's time goes.
    **tracker_options
        Options of the method's tracker (``n_patches``, ``max_iter``, ...).

    Returns
    -------
    TrackResult
    """
    _check_track_arguments(locals())
    opts = track_options(
        options,
        frames=frames,
        positions=positions,
        init=init,
        resume=resume,
        recover=recover,
        refine=refine,
        passes=passes,
        vertices=vertices,
        show_progress=show_progress,
    )
    if not isinstance(capture, AnyCapture):
        capture = open_capture(capture)
    live = isinstance(capture, LiveCapture)
    chosen = opts.positions_in(capture)
    folder = Path(out) if out is not None else Path(tempfile.mkdtemp(prefix="meshmocap-track-"))
    if resume:  # not the track of another capture (its body would be reused)
        check_resumable(folder, capture, out="out", restart="resume=False")
    # a fresh install's kernels compile in the background while the body is estimated and
    # the first pose found (meshmocap.apps.kernels)
    start_compiling(kernels_of(method))
    # a live capture's body is estimated from its first frames, as an ordinary capture
    shown = capture
    if live and _estimates(capture, template, folder, opts.resume):
        shown = body_capture(capture)
    choice = tracking_template(shown, template, folder, refresh=not opts.resume)
    say = log or (lambda line: None)
    say(choice.note)
    start = opts.start or choice.start  # a template made from a frame starts in its pose
    if start is not None and chosen is not None and capture.indices[chosen[0]] != start.frame:
        start = None
    if method in MANIFOLD_METHODS and manifold is None:
        say(
            f"{method}: no --manifold given: the default pose manifold of the tracked body "
            "(learned from the bundled CMU pose library at first use, then cached)"
        )
    # tracked on a light copy of the template, unless a manifold learned for the template
    # itself is given (meshmocap.body.light)
    light = None if manifold is not None else opts.light
    tracked = tracking_body(choice.template, n_vertices=light).light
    tracker = make_tracker(method, manifold=manifold, template=tracked, **tracker_options)
    opts = replace(
        opts,
        light=light,
        start=start,
        template_info={**choice.info, **input_meta(capture), **(opts.template_info or {})},
    )
    t0 = time.perf_counter()
    data = track_sequence(
        tracker, choice.template, capture, folder, opts, on_frame=on_frame, timer=timer
    )
    return TrackResult(folder, data, choice.template, choice.note, time.perf_counter() - t0)


def track_options(options: TrackOptions | None = None, **fields) -> TrackOptions:
    """``options`` (default: the defaults) with each of ``fields`` (fields of
    :class:`~meshmocap.trackers.options.TrackOptions`) that is not its default put in:
    how :func:`track` builds its record from its keywords."""
    if options is None:
        return TrackOptions(**fields)
    check_type("track", "options", options, TrackOptions, "a TrackOptions or None")
    defaults = TrackOptions()
    changed = {k: v for k, v in fields.items() if not _same(v, getattr(defaults, k))}
    return replace(options, **changed) if changed else options


def _same(a: object, b: object) -> bool:
    """Whether a keyword's value is its default (None, a flag or a choice)."""
    return a is b or (type(a) is type(b) and isinstance(a, bool | str) and a == b)


def _check_track_arguments(given: dict) -> None:
    """:func:`track`'s own arguments, each of its type (one line naming the first that is
    not); the record's fields are checked by the record."""
    func = "track"
    if not isinstance(given["capture"], AnyCapture):
        _check_source(func, "capture", given["capture"])
    check_type(func, "method", given["method"], str, "a method name (str)")
    if given["method"] not in METHODS:
        raise InputError(
            f"track: method must be one of {sorted(METHODS)}, found {given['method']!r}"
        )
    for name in ("out", "template", "manifold"):
        _check_optional(func, name, given[name], _PATH, "a path or name (str or os.PathLike)")
    for name in ("log", "on_frame"):
        _check_optional(func, name, given[name], Callable, "a callable")
    _check_optional(func, "timer", given["timer"], StageTimer, "a StageTimer")


def _estimates(capture, template, folder: Path, resume: bool) -> bool:
    """Whether :func:`tracking_template` will estimate the performer's body of ``capture``
    (no template given or named by ``capture.json``, none kept in ``folder`` to resume)."""
    if template is not None and os.fspath(template) != "auto":
        return False
    if template is None and (capture.meta.get("spec") or {}).get("template"):
        return False
    return not (resume and (folder / SUBJECT_FILE).is_file())


def open_track(path: str | os.PathLike, *, template: Template | str | None = None) -> TrackResult:
    """A track folder written by ``meshmocap track`` or :func:`track`.

    ``template`` is needed only for a template that is neither bundled nor saved in the
    folder (an estimated body is saved there)."""
    check_type("open_track", "path", path, _PATH, "a track folder (str or os.PathLike)")
    _check_optional(
        "open_track", "template", template, (Template, *_PATH), "a Template, name or path"
    )
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
    capture: AnyCapture | Source,
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
    func = "evaluate"
    if not isinstance(capture, AnyCapture):
        _check_source(func, "capture", capture)
    check_type(func, "track", track, (TrackResult, Track, *_PATH), "a TrackResult, Track or path")
    check_type(func, "silhouettes", silhouettes, bool, "True or False")
    check_type(func, "surface_frames", surface_frames, (int, np.integer), "an int")
    if surface_frames < 0:
        raise InputError(f"evaluate: surface_frames must be ≥ 0, found {surface_frames}")
    check_type(func, "force", force, bool, "True or False")
    if isinstance(capture, LiveCapture):  # the frames it holds now
        capture = capture.snapshot()
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


def summary(evaluation: Evaluation) -> str:
    """The table ``meshmocap eval`` prints of an :func:`evaluate` result
    (:func:`meshmocap.analysis.evaluate.summary`)."""
    check_type("summary", "evaluation", evaluation, Evaluation, "an Evaluation (evaluate())")
    return evaluation_summary(evaluation)


#: Metres per unit of :func:`example_capture`'s mesh files.
UNITS = UNIT_METRES


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

    func = "example_capture"
    check_type(func, "out", out, _PATH, "a folder path (str or os.PathLike)")
    check_type(func, "motion", motion, str, "a motion name (str)")
    check_type(func, "n_frames", n_frames, (int, np.integer), "an int")
    check_type(func, "fps", fps, _NUMBER, "a number")
    check_type(func, "performer", performer, str, "a template name (str)")
    check_choice(func, "units", units, tuple(UNITS))
    check_choice(func, "up", up, ("y", "z"))
    if not (1 <= n_frames <= 10_000 and np.isfinite(fps) and fps > 0):
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
