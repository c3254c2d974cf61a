"""The main job on the bundled defaults (``meshmocap demo``): motions, retargeting and
rendering, then a synthetic capture tracked as a user would track their own, exported and
analysed, and scored against the truth that only the studio knows.

The capture walks the real user's path: its performer (``heavy_male``) is a body the
trackers are not told about, so the tracking template is estimated from the hulls
(:func:`~meshmocap.estimate.performer.tracking_template.tracking_template`), and the first pose is
found from the capture (the trackers' default ``init="auto"``). The ground truth is read
only to score. The patch track is exported to BVH, C3D, TRC, glTF and CSV and its gait
analysed, as ``meshmocap export`` and ``meshmocap gait`` do.

Everything runs from the installed package alone (bundled templates, procedural motions);
a user clip (BVH/AMC) can be added.
"""

from __future__ import annotations

import functools
import hashlib
import os
import shutil
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from meshmocap._atomic import atomic_open
from meshmocap._parallel import Workers, job_count
from meshmocap._progress import phase
from meshmocap.analysis.evaluate import Evaluation, evaluate
from meshmocap.apps.figures.render import render_motion
from meshmocap.apps.files.evaluation import write_evaluation
from meshmocap.apps.files.export import export_track
from meshmocap.apps.files.gait import gait_of, write_gait
from meshmocap.apps.kernels import compiling_only, start_compiling
from meshmocap.apps.report.page import (
    Section,
    comparison_table,
    evaluation_section,
    gait_section,
    write_report,
)
from meshmocap.apps.report.player import player_from_tracks
from meshmocap.body.light import tracking_body
from meshmocap.body.procedural import PROCEDURAL_MOTIONS, procedural_motion
from meshmocap.body.retarget import retarget
from meshmocap.body.template import bundled_templates, load_template
from meshmocap.errors import InputError, MeshError
from meshmocap.estimate.performer.first_frame import start_of_frame
from meshmocap.estimate.performer.tracking_template import (
    SUBJECT_FILE,
    TemplateChoice,
    tracking_template,
)
from meshmocap.io.bvh import read_bvh, write_bvh
from meshmocap.io.capture import Capture
from meshmocap.io.clips import clip_on
from meshmocap.io.results import (
    LIGHT_FILE,
    Track,
    done_frames,
    frame_path,
    read_track,
    tracked_template,
)
from meshmocap.io.start import Start
from meshmocap.studio.synth import SynthSpec, synthesize
from meshmocap.trackers.driver import first_pose, track_sequence
from meshmocap.trackers.options import TrackOptions
from meshmocap.trackers.registry import make_tracker

#: Trackers the demo compares: both papers' methods and the skeleton-only baseline. The
#: cage tracker's pose manifold is learned on the spot from the procedural walk and jog.
DEMO_METHODS = ("patch", "cage", "articulated_icp")
#: The demo capture's subject (performer): a bundled body the trackers are not told about.
DEMO_SUBJECT = "heavy_male"
#: Frame numbers (60 fps) of the synthetic walk the demo's trackers follow.
DEMO_FRAMES = slice(0, 120)
#: Budget of the player's per-frame data in the demo's report, MB (the plots and the
#: meshes come on top).
PLAYER_MB = 5.0
#: Formats the demo's first track is exported to (``meshmocap export``).
DEMO_EXPORTS = ("bvh", "c3d", "trc", "glb", "csv")
#: Why the demo's comparison has no silhouette error (rendering every frame in every camera
#: would double its run time).
NO_SILHOUETTES = "the demo skips it to save time; `meshmocap report CAPTURE TRACK...` measures it"


@dataclass(frozen=True)
class TrackerScore:
    """One tracker's result on the demo capture: mean/max joint error (mm), s per frame."""

    method: str
    mean_mm: float
    max_mm: float
    seconds: float


@dataclass(frozen=True)
class DemoResult:
    """What the demo wrote (description, path) and how the trackers scored."""

    files: tuple[tuple[str, Path], ...]
    scores: tuple[TrackerScore, ...]
    seconds: float
    notes: tuple[str, ...] = ()


def run_demo(
    out: str | os.PathLike,
    *,
    seconds: float = 4.0,
    frames: slice | None = DEMO_FRAMES,
    clip: str | None = None,
    subject: str = DEMO_SUBJECT,
    template: str = "auto",
    show_progress: bool | None = None,
) -> DemoResult:
    """Run the demo into the folder ``out``.

    Parameters
    ----------
    seconds : float
        Length of the procedural walk written as BVH and retargeted.
    frames : slice or None
        Frame numbers (60 fps) of the synthetic walk capture that the trackers follow
        (``START:STOP:STEP``, as ``--frames``); None skips the capture and tracking.
    clip : str, optional
        A BVH/AMC file to retarget and render as well.
    subject : str
        Bundled body that performs in the synthetic capture (``synth --subject``).
    template : str
        Tracking template: ``"auto"`` estimates the performer's body from the hulls (what a
        user without a body scan has); a bundled name or ``.npz`` file tracks with that body
        (``neutral_5k`` is the fastest).
    """
    if subject not in bundled_templates():
        raise InputError(
            f"demo: --subject must be one of {sorted(bundled_templates())}, found {subject!r}"
        )
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    if frames is not None:  # a fresh install's kernels compile in the background while the
        start_compiling()  # capture is made and the body estimated
    neutral = load_template("neutral")
    files: list[tuple[str, Path]] = []
    if frames is None:  # with a capture, the motions render beside the report's pieces
        with phase("rendering the motions (contact sheets)", enabled=show_progress):
            _render_motions(out, neutral, seconds, clip, files, show_progress)
    scores: list[TrackerScore] = []
    players, sections, evaluations, notes = [], [], [], []
    if frames is not None:
        cap = synthesize(out / "capture", demo_spec(frames, subject), show_progress=show_progress)
        files.append((f"synthetic capture ({len(cap)} frames, humaneva4, {subject})", cap.path))
        choice, done, refused = demo_tracks(
            cap, out, template=template, show_progress=show_progress
        )
        notes += [f"{method} not tracked: {why}" for method, why in refused]
        side = min(job_count(), len(DEMO_METHODS))
        if side > 1:  # the seconds a frame are wall seconds on shared cores
            notes.append(
                f"the trackers ran {side} at a time, so their seconds a frame are shared "
                "cores' (MESHMOCAP_JOBS=1 runs them one after the other)"
            )
        methods = [method for method, _, _, _ in done]
        notes.append(f"performer {subject!r}, not told to the trackers; {choice.note}")
        folders = [folder for _, folder, _, _ in done]
        tracks = [track for _, _, track, _ in done]
        evaluations = [ev for _, _, _, ev in done]
        title = f"{', '.join(methods)} on the synthetic walk ({len(cap)} frames)"
        # the report holds the player's frames: a budget that keeps it under 10 MB
        templates = [choice.template] * len(tracks)
        first = DEMO_METHODS[0]

        def part(what: str, k: int):  # one piece of the report, in a worker
            if what == "motions":
                sheets: list = []
                with phase("rendering the motions (contact sheets)", enabled=show_progress):
                    _render_motions(out, neutral, seconds, clip, sheets, False)
                return sheets
            if what == "evaluation":
                method, folder, _, ev = done[k]
                with phase(f"plotting the {method} track's evaluation", enabled=show_progress):
                    written = write_evaluation(ev, out / f"eval_{method}")
                    drop_resume_state(folder)
                return written
            if what == "exports":
                files: list = []
                with phase(f"exporting the {first} track and analysing its gait"):
                    lines = _exports_and_gait(folders[0], out, first, files)
                return lines, files
            if what == "gaits":
                with phase("comparing the tracks' gaits", enabled=show_progress):
                    return gait_section(cap, tracks, methods)
            with phase("building the 3D player", enabled=show_progress):
                return player_from_tracks(
                    cap, tracks, title=title, templates=templates, max_megabytes=PLAYER_MB
                )

        # independent pieces, the longest first, side by side (meshmocap._parallel)
        pieces = [("exports", 0), ("player", 0), ("motions", 0), ("gaits", 0)]
        pieces += [("evaluation", k) for k in range(len(done))]
        with Workers(part, len(pieces)) as workers:
            made = dict(zip(pieces, workers.map(pieces), strict=True))
        files[:0] = made["motions", 0]  # first, as they were made first before
        for k, (method, _, track, ev) in enumerate(done):
            written = made["evaluation", k]
            files.append((f"{method} track and evaluation", out / f"eval_{method}"))
            worst = float(ev.joints.per_frame.max())
            scores.append(TrackerScore(method, ev.joints.overall.mean, worst, ev.seconds.mean))
            plots = [p for p in written if p.suffix == ".png"]
            sections.append(evaluation_section(ev, images=plots, track=track))
        notes.append(f"first pose: {_first_pose(tracks[0])}; the ground truth only scores")
        lines, exported = made["exports", 0]
        notes += lines
        files += exported
        sections.append(made["gaits", 0])
        players.append(made["player", 0])
        with phase("dropping the hull meshes (rebuilt when read)", enabled=show_progress):
            drop_hull_meshes(cap.path)
        shared = [f / n for f in folders for n in (SUBJECT_FILE, LIGHT_FILE, "faces.npy")]
        link_duplicates([*shared, cap.path / "truth" / "faces.npy"])
    sheets = tuple((what, p) for what, p in files if p is not None and p.suffix == ".png")
    with phase("writing the report"):
        report = _report(out, players, evaluations, sections, sheets, notes)
    files.append(("report (tables, plots, 3D player; open in a browser)", report))
    return DemoResult(tuple(files), tuple(scores), time.perf_counter() - t0, tuple(notes))


def _render_motions(out: Path, neutral, seconds: float, clip, files: list, show_progress) -> None:
    """The demo's motions: the procedural walk as BVH, retargeted onto ``heavy_male``, a
    user ``clip``, every procedural motion on ``neutral``, rendered as contact sheets into
    ``out``; what was written appended to ``files``."""
    walk = procedural_motion("walk", neutral, duration=seconds, fps=30.0)
    bvh = write_bvh(out / "walk.bvh", walk)
    files.append(("walk.bvh (procedural walk, CMU MotionBuilder skeleton)", bvh))
    heavy = load_template("heavy_male")  # a CMU-style BVH onto another body shape
    res = render_motion(
        heavy,
        retarget(read_bvh(bvh), heavy),
        out / "walk_heavy_male",
        step=2,
        frames=False,
        show_progress=show_progress,
    )
    files.append(("walk retargeted onto heavy_male", res.sheet))
    if clip:
        m = clip_on(neutral, clip, fps=30.0)
        res = render_motion(
            neutral,
            m,
            out / "clip",
            step=max(1, m.n_frames // 60),
            frames=False,
            show_progress=show_progress,
        )
        files.append((f"{clip} retargeted onto neutral", res.sheet))
    for name in PROCEDURAL_MOTIONS:
        m = procedural_motion(name, neutral, duration=3.0, fps=20.0)
        res = render_motion(neutral, m, out / name, frames=False, show_progress=show_progress)
        files.append((f"{name} on neutral", res.sheet))


def demo_spec(frames: slice = DEMO_FRAMES, subject: str = DEMO_SUBJECT) -> SynthSpec:
    """The demo capture's recipe: the procedural walk performed by ``subject``, frames
    ``frames`` at 60 fps, seen by the 4 cameras of ``humaneva4`` (:func:`run_demo`)."""
    return SynthSpec(
        motion="walk",
        template="neutral_5k",
        subject=subject,
        rig="humaneva4",
        start=frames.start,
        stop=frames.stop,
        step=frames.step,
    )


def demo_tracks(
    cap: Capture,
    out: str | os.PathLike,
    *,
    template: str = "auto",
    methods: tuple[str, ...] = DEMO_METHODS,
    show_progress: bool | None = None,
) -> tuple[TemplateChoice, list[tuple[str, Path, Track, Evaluation]], list[tuple[str, str]]]:
    """Track the demo capture ``cap`` with each of ``methods`` into ``out/track_<method>``
    as the demo does and score each against the truth the studio kept (joints only).

    The tracking template is chosen once (:func:`tracking_template`: ``"auto"`` estimates the
    performer's body, cached for the capture) and kept in every track folder; each method
    runs on the default path: the light body the driver tracks (:mod:`meshmocap.body.light`),
    default options, the automatic first pose (the search's, cached for the capture, or
    the pose the body was fitted in, by the silhouettes' evidence:
    :mod:`~meshmocap.estimate.performer.first_frame`; found once, :func:`first_start`, and
    given to each), the recovery checks. The methods run side by side, one per core (at
    most ``MESHMOCAP_JOBS`` processes; 1: one after the other, with their progress), the
    same tracks either way. ``benchmarks/bench_demo_guard.py`` guards these figures.

    Returns
    -------
    choice : TemplateChoice
    tracks : list of (method, track folder, Track, Evaluation)
    refused : list of (method, reason)
        Methods after the first whose tracker cannot be set up for the estimated body (the
        cage that cannot enclose it, :mod:`meshmocap.trackers.cage.body`): said in the
        report's notes, the others still tracked.
    """
    out = Path(out)
    folders = [out / f"track_{method}" for method in methods]
    # the background compiler holds the trackers' kernels back until the body and the
    # first pose, which use both cores, are done (meshmocap.apps.kernels)
    with compiling_only():
        choice = tracking_template(cap, template, folders[0])
        for folder in folders[1:]:
            if "template_file" in choice.info:  # each track keeps its template
                folder.mkdir(parents=True, exist_ok=True)
                shutil.copyfile(folders[0] / SUBJECT_FILE, folder / SUBJECT_FILE)
        start = first_start(cap, choice)  # once for every method
    jobs = min(job_count(), len(methods))
    # side by side, the trackers' progress lines would mix: the parent says what runs
    progress = show_progress if jobs == 1 else False

    def track(method: str, folder: Path):
        # the light body the driver tracks (meshmocap.body.light)
        try:
            with phase(f"setting up the {method} tracker", enabled=progress):
                tracker = make_tracker(method, template=tracking_body(choice.template).light)
        except MeshError as exc:  # the cage refuses a body it cannot enclose: said, not fatal
            if method == methods[0]:
                raise
            return method, folder, None, str(exc)
        track = track_sequence(
            tracker,
            choice.template,
            cap,
            folder,
            TrackOptions(show_progress=progress, template_info=choice.info, start=start),
        )
        with phase(f"scoring the {method} track", enabled=progress):
            ev = evaluate(track, cap, surface_frames=0, silhouettes=False)
        return method, folder, track, ev

    done, refused = [], []
    with Workers(track, len(methods)) as workers:  # one tracker a core (meshmocap._parallel)
        what = f"tracking with {', '.join(methods)}, {workers.jobs} at a time"
        with phase(what, enabled=show_progress if workers.jobs > 1 else False):
            for method, folder, track_, ev in workers.map(list(zip(methods, folders, strict=True))):
                if track_ is None:
                    refused.append((method, ev))
                else:
                    done.append((method, folder, track_, ev))
    return choice, done, refused


def first_start(cap: Capture, choice: TemplateChoice) -> Start:
    """The start of the demo capture's first frame for the template ``choice``, as the
    tracking driver finds it with ``init="auto"`` (the search's pose or the one the body
    was fitted in, by the silhouettes' evidence:
    :func:`~meshmocap.estimate.performer.first_frame.start_of_frame`); given to each
    tracker, which then starts there without searching again."""
    frame = cap[0]
    given = choice.start if choice.start is not None and choice.start.frame == frame.index else None
    search = functools.partial(first_pose, choice.template, frame, "auto", capture=cap)
    return start_of_frame(choice.template, frame, given, search)


def _report(out: Path, players, evaluations, sections, sheets, notes) -> Path:
    """Write the demo's ``report.html``."""
    return write_report(
        out / "report.html",
        title="meshmocap demo",
        players=players,
        tables=[comparison_table(evaluations, no_silhouettes=NO_SILHOUETTES)] * bool(evaluations),
        sections=[*sections, Section("Motions rendered (contact sheets)", images=sheets)],
        intro="procedural motions, retargeting, and a synthetic capture tracked as a user "
        "tracks their own: " + "; ".join(notes)
        if notes
        else "procedural motions and retargeting",
    )


def _first_pose(track) -> str:
    """How ``track``'s first pose was found, from its ``track.json``."""
    init = str(track.meta.get("init", "truth"))
    return {
        "auto": "found from the capture (init auto)",
        "truth": "copied from the ground truth (init truth, the papers' protocol)",
    }.get(init, f"init {init}")


def _exports_and_gait(track: Path, out: Path, method: str, files: list) -> list[str]:
    """Export ``track`` in every :data:`DEMO_EXPORTS` format into ``out/exports`` and write
    its gait analysis into ``out/gait``; append what was written to ``files`` and return
    one line each for the report."""
    (out / "exports").mkdir(parents=True, exist_ok=True)
    sizes = []
    tr = read_track(track)  # read once for the five (the same files as reading it each time)
    template = tracked_template(track, tr.meta)
    fit = None  # the rig's poses, fitted once for BVH and GLB
    for fmt in DEMO_EXPORTS:
        rig = fmt in ("bvh", "gltf", "glb")
        res = export_track(
            tr,
            out / "exports" / f"walk_{method}.{fmt}",
            template=template if rig else None,
            fit=fit if rig else None,
        )
        fit = res.fit if rig else fit
        files.append((f"{method} track as {fmt.upper()}", res.path))
        sizes.append(f"{fmt.upper()} {res.size_bytes / 1e6:.1f} MB")
    lines = [f"{method} track exported ({', '.join(sizes)}; meshmocap export)"]
    try:
        run = gait_of(track)
    except InputError as exc:  # too few frames for a gait
        return [*lines, f"{method} gait: none ({exc})"]
    if run.gait.found:
        written = write_gait(run.gait, out / "gait", reference=run.reference, title=method)
        files.append((f"{method} gait: cycles, events, curves (CSV) and plots", written[0].parent))
        s = run.gait.summary()
        lines.append(
            f"{method} gait: {s.cadence_steps_per_min:.1f} steps/min, stride "
            f"{s.stride_length_m:.2f} m (meshmocap gait)"
        )
    else:
        lines.append(f"{method} gait: none found ({run.gait.message})")
    return lines


def drop_resume_state(track: str | os.PathLike) -> int:
    """Rewrite a finished track's frame files without the tracker state stored to resume an
    interrupted run (``state_*`` arrays: 45 kB a frame for the patch tracker), except the
    last frame's, from which tracking can still be extended. Returns the files rewritten."""
    files = [frame_path(track, i) for i in done_frames(track)][:-1]
    return sum(_drop_arrays(p, "state_") for p in files)


def drop_hull_meshes(capture: str | os.PathLike) -> int:
    """Rewrite a capture's hull files (``hulls/NNNNN.npz``) without their surface mesh
    (``mesh_*`` arrays, 0.22 MB a frame at 1 cm), keeping the voxel occupancy (12 kB) from
    which reading the capture rebuilds the same mesh by marching cubes
    (:func:`~meshmocap.io.capture.read_hull_mesh`). Returns the files rewritten."""
    return sum(_drop_arrays(p, "mesh_") for p in sorted((Path(capture) / "hulls").glob("*.npz")))


def link_duplicates(paths) -> int:
    """Make each of the files ``paths`` whose bytes equal an earlier one's a hard link to
    it (the demo's tracks each keep the estimated body, its light copy and the faces, the
    same files), atomically; where a link cannot be made the copy stays. Returns the bytes
    no longer stored twice."""
    first: dict[tuple[int, bytes], Path] = {}
    saved = 0
    for p in map(Path, paths):
        if not p.is_file():
            continue
        data = p.read_bytes()
        key = (len(data), hashlib.sha256(data).digest())
        if key not in first:
            first[key] = p
            continue
        if os.path.samefile(first[key], p):
            continue
        tmp = p.with_name(f".{p.name}.link")
        try:
            tmp.unlink(missing_ok=True)
            os.link(first[key], tmp)
            os.replace(tmp, p)
        except OSError:  # a file system without hard links: the copy stays
            tmp.unlink(missing_ok=True)
            continue
        saved += len(data)
    return saved


def _drop_arrays(path: Path, prefix: str) -> bool:
    """Rewrite the ``.npz`` at ``path`` without its arrays named ``prefix…``, atomically;
    whether there were any."""
    with np.load(path, allow_pickle=False) as z:
        keep = {k: z[k] for k in z.files if not k.startswith(prefix)}
        if len(keep) == len(z.files):
            return False
    with atomic_open(path) as f:
        np.savez_compressed(f, **keep)
    return True
