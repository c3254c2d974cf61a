"""The main job on the bundled defaults (``meshmocap demo``): motions, retargeting and
rendering, then a synthetic capture tracked and scored end to end.

Everything runs from the installed package alone (bundled templates, procedural motions);
a user clip (BVH/AMC) can be added.
"""

from __future__ import annotations

import os
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from meshmocap._atomic import atomic_open
from meshmocap.analysis.evaluate import evaluate
from meshmocap.apps.evaluation_files import write_evaluation
from meshmocap.apps.player import player_from_tracks
from meshmocap.apps.render import render_motion
from meshmocap.apps.report import (
    Section,
    comparison_table,
    evaluation_section,
    gait_section,
    write_report,
)
from meshmocap.body.procedural import PROCEDURAL_MOTIONS, procedural_motion
from meshmocap.body.retarget import retarget
from meshmocap.body.template import load_template
from meshmocap.io.bvh import read_bvh, write_bvh
from meshmocap.io.clips import clip_on
from meshmocap.io.results import done_frames, frame_path
from meshmocap.studio.synth import SynthSpec, synthesize
from meshmocap.trackers.driver import track_sequence
from meshmocap.trackers.registry import make_tracker

#: Trackers the demo compares: both papers' methods and the skeleton-only baseline. The
#: cage tracker's pose manifold is learned on the spot from the procedural walk and jog.
DEMO_METHODS = ("patch", "cage", "articulated_icp")
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


def run_demo(
    out: str | os.PathLike,
    *,
    seconds: float = 4.0,
    track_frames: int = 120,
    clip: str | None = None,
    show_progress: bool | None = None,
) -> DemoResult:
    """Run the demo into the folder ``out``.

    Parameters
    ----------
    seconds : float
        Length of the procedural walk written as BVH and retargeted.
    track_frames : int
        Frames (60 fps) of the synthetic walk capture that the trackers follow; 0 skips
        tracking.
    clip : str, optional
        A BVH/AMC file to retarget and render as well.
    """
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    neutral = load_template("neutral")
    files: list[tuple[str, Path]] = []
    walk = procedural_motion("walk", neutral, duration=seconds, fps=30.0)
    bvh = write_bvh(out / "walk.bvh", walk)
    files.append(("walk.bvh (procedural walk, CMU MotionBuilder skeleton)", bvh))
    heavy = load_template("heavy_male")  # a CMU-style BVH onto another body shape
    res = render_motion(heavy, retarget(read_bvh(bvh), heavy), out / "walk_heavy_male", step=2,
                        frames=False, show_progress=show_progress)  # fmt: skip
    files.append(("walk retargeted onto heavy_male", res.sheet))
    if clip:
        m = clip_on(neutral, clip, fps=30.0)
        res = render_motion(neutral, m, out / "clip", step=max(1, m.n_frames // 60), frames=False,
                            show_progress=show_progress)  # fmt: skip
        files.append((f"{clip} retargeted onto neutral", res.sheet))
    for name in PROCEDURAL_MOTIONS:
        m = procedural_motion(name, neutral, duration=3.0, fps=20.0)
        res = render_motion(neutral, m, out / name, frames=False, show_progress=show_progress)
        files.append((f"{name} on neutral", res.sheet))
    scores: list[TrackerScore] = []
    players, sections, evaluations, tracks = [], [], [], []
    if track_frames > 0:
        template = load_template("neutral_5k")
        spec = SynthSpec(motion="walk", template="neutral_5k", rig="humaneva4", stop=track_frames)
        cap = synthesize(out / "capture", spec, show_progress=show_progress)
        files.append((f"synthetic capture ({len(cap)} frames, humaneva4)", cap.path))
        for method in DEMO_METHODS:
            tracker = (
                make_tracker(method, template=template)
                if method == "cage"
                else make_tracker(method)
            )
            track = track_sequence(tracker, template, cap, out / f"track_{method}",
                                   show_progress=show_progress)  # fmt: skip
            ev = evaluate(track, cap, surface_frames=0, silhouettes=False)
            written = write_evaluation(ev, out / f"eval_{method}")
            files.append((f"{method} track and evaluation", out / f"eval_{method}"))
            worst = float(ev.joints.per_frame.max())
            scores.append(TrackerScore(method, ev.joints.overall.mean, worst, ev.seconds.mean))
            tracks.append(track)
            evaluations.append(ev)
            plots = [p for p in written if p.suffix == ".png"]
            sections.append(evaluation_section(ev, images=plots, track=track))
            drop_resume_state(out / f"track_{method}")
        sections.append(gait_section(cap, tracks, list(DEMO_METHODS)))
        title = f"{', '.join(DEMO_METHODS)} on the synthetic walk ({len(cap)} frames)"
        players.append(player_from_tracks(cap, tracks, title=title))
        drop_hull_meshes(cap.path)
    sheets = tuple((what, p) for what, p in files if p is not None and p.suffix == ".png")
    report = write_report(
        out / "report.html", title="meshmocap demo", players=players,
        tables=[comparison_table(evaluations, no_silhouettes=NO_SILHOUETTES)] * bool(evaluations),
        sections=[*sections, Section("Motions rendered (contact sheets)", images=sheets)],
        intro="procedural motions, retargeting and a synthetic capture tracked and scored",
    )  # fmt: skip
    files.append(("report (tables, plots, 3D player; open in a browser)", report))
    return DemoResult(tuple(files), tuple(scores), time.perf_counter() - t0)


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
