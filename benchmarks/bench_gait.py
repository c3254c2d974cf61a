"""Validation of gait analysis on tracked joints: events, cadence and stride length from each
tracker's joints against the same quantities from the ground-truth joints.

Protocol: each clip (CMU walks and runs of ``../shared/data/mocap/cmu`` and its library,
chosen by CMU's own index, and the procedural walk and jog, their paths centred on the
studio) is retargeted onto
``neutral_5k``, resampled to 60 fps and played by it in a synthetic ``humaneva4`` studio
(4 cameras, silhouettes, 1 cm visual hulls; :func:`~meshmocap.studio.synth.synthesize`),
on the longest run of frames in which every camera sees the whole body (a CMU walk crosses
4–5 m, the studio's volume is 3 m across; the Daz BVHs' first 6 frames, a T-pose blend, are
left out). Each tracker (``patch``, ``cage`` with the pose manifold learned from the
procedural walk and jog, ``articulated_icp``) tracks those frames, starting from the truth's
first pose (the papers' protocol). :func:`~meshmocap.analysis.gait.track_gait` finds gait
events in the tracked joints, :func:`~meshmocap.analysis.gait.gait_analysis` in the true
joints of the same frames; :func:`~meshmocap.analysis.gait.compare_gaits` matches them
(same foot and kind, within 0.2 s). Columns: events of the truth and how many the track
matched (``+n``: spurious ones), mean and largest |offset| (frames at 60 fps), cadence and
stride-length error (% of the truth's). Acceptance: every event within 1 frame, cadence and
stride length within 2 %.

Run: ``nice -n 10 python benchmarks/bench_gait.py [--clips 05_01 walk ...] [--methods patch
...] [--max-frames N] [--work /tmp/meshmocap-gait]``. Captures and tracks are cached in
``--work`` (runs resume; a track folder is named by the tracker's options and a digest of the
code below ``analysis/``); the table is printed and written to ``--work``/results.md.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import os
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

import meshmocap
from meshmocap.analysis.gait import compare_gaits, gait_analysis, track_gait
from meshmocap.apps.bench.run import bench_manifold
from meshmocap.body.procedural import procedural_motion
from meshmocap.body.template import load_template
from meshmocap.geometry.camera import in_view
from meshmocap.io.bvh import write_bvh
from meshmocap.io.capture import Capture
from meshmocap.io.clips import clip_on
from meshmocap.io.results import read_track
from meshmocap.studio.rigs import camera_rig
from meshmocap.studio.synth import SynthSpec, synthesize
from meshmocap.trackers.driver import track_sequence
from meshmocap.trackers.options import TrackOptions
from meshmocap.trackers.registry import MANIFOLD_METHODS, make_tracker

#: clip name → (source: procedural motion or file under DATA/mocap/cmu, what CMU's index
#: calls it). CMU's index (Hahne's compilation of the trial descriptions) calls 02_01, 05_01,
#: 07_01, 12_01, 35_01 "walk", 07_04 "slow walk", 08_07 "walk, exaggerated stride", 09_01,
#: 09_03, 09_05 "run" (the library's other walks, 02_02, 06_01, 07_03–11, 08_02–11, 10_04,
#: 12_02–03, and runs, 09_04–11, are left out to keep the run under an hour).
CLIPS: dict[str, tuple[str, str]] = {
    "walk": ("walk", "procedural walk, 110 steps/min"),
    "jog": ("jog", "procedural jog, 160 steps/min"),
    "05_01": ("05_01.amc", "walk"),
    "35_01": ("35_01.amc", "walk"),
    "07_01": ("07_01.bvh", "walk"),
    "09_01": ("09_01.bvh", "run"),
    "02_01": ("library/02_01.bvh", "walk"),
    "07_04": ("library/07_04.bvh", "slow walk"),
    "08_07": ("library/08_07.bvh", "walk, exaggerated stride"),
    "12_01": ("library/12_01.bvh", "walk"),
    "09_03": ("library/09_03.bvh", "run"),
    "09_05": ("library/09_05.bvh", "run"),
}
METHODS = ("patch", "cage", "articulated_icp")
FPS = 60.0
TEMPLATE = "neutral_5k"
#: Frames of a Daz BVH's T-pose blend left out at 60 fps.
BVH_SKIP = 6


def track_digest() -> str:
    """Digest (8 hex digits) of the code that makes a capture and a track: every module
    below ``analysis/`` (the command line, analysis and apps left out, so that editing the
    gait analysis reuses the cached tracks)."""
    root = Path(meshmocap.__file__).resolve().parent
    h = hashlib.sha1()
    for p in sorted(root.rglob("*.py")):
        rel = p.relative_to(root).as_posix()
        if not rel.startswith(("analysis/", "apps/", "cli/")):
            h.update(rel.encode() + b"\0" + p.read_bytes())
    return h.hexdigest()[:8]


def procedural_bvh(name: str, template, work: Path) -> str:
    """The procedural motion ``name`` (6 s at 60 fps) on ``template``, its path centred on the
    studio (a procedural motion starts at the centre and would leave the volume after half
    of it), written as a BVH in ``work/motions``."""
    path = work / "motions" / f"{name}.bvh"
    if not path.is_file():
        m = procedural_motion(name, template, duration=6.0, fps=FPS)
        root = m.root_positions.copy()
        root[:, :2] -= 0.5 * (root[0, :2] + root[-1, :2])
        path.parent.mkdir(parents=True, exist_ok=True)
        write_bvh(path, replace(m, root_positions=root))
    return str(path.resolve())


def in_view_range(source: str, template, cameras, *, max_frames: int | None) -> tuple[int, int]:
    """``(start, stop)`` of the longest run of frames (at 60 fps) whose posed surface every
    camera sees, at most ``max_frames`` long (centred in the run)."""
    m = clip_on(template, source, fps=FPS)
    skip = BVH_SKIP if "/mocap/cmu/" in source and source.endswith(".bvh") else 0
    V = template.pose(m.rotations, m.root_positions).V[:, ::4]
    seen = np.array([in_view(v, cameras).all() for v in V])
    seen[:skip] = False
    d = np.diff(np.concatenate([[0], seen.astype(np.int8), [0]]))
    starts, ends = np.flatnonzero(d == 1), np.flatnonzero(d == -1)
    if not len(starts):
        raise SystemExit(f"{source}: the studio never sees the whole body")
    k = int(np.argmax(ends - starts))
    start, stop = int(starts[k]), int(ends[k])
    if max_frames and stop - start > max_frames:
        start += (stop - start - max_frames) // 2
        stop = start + max_frames
    return start, stop


def tracked(method: str, template, capture: Capture, work: Path, manifold) -> Path:
    """Track ``capture`` with ``method`` (resuming a cached track); return the folder."""
    opts = {"manifold": manifold} if method in MANIFOLD_METHODS else {}
    tracker = make_tracker(method, **opts)
    salt = hashlib.sha1(manifold.X_.tobytes()).hexdigest()[:8] if opts else ""
    key = [tracker.name, tracker.options(), template.name, salt, track_digest()]
    digest = hashlib.sha1(json.dumps(key, sort_keys=True).encode()).hexdigest()[:8]
    out = work / "tracks" / capture.path.name / f"{method}-{digest}"
    track_sequence(tracker, template, capture, out, TrackOptions(show_progress=False))
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--data", default="../shared/data", help="shared data folder")
    ap.add_argument("--clips", nargs="+", default=list(CLIPS), choices=list(CLIPS))
    ap.add_argument("--methods", nargs="+", default=list(METHODS), choices=list(METHODS))
    ap.add_argument("--max-frames", type=int, help="at most N frames per clip (development)")
    ap.add_argument(
        "--work", default=os.path.join(os.environ.get("TMPDIR", "/tmp"), "meshmocap-gait")
    )
    args = ap.parse_args()
    work, data = Path(args.work), Path(args.data) / "mocap" / "cmu"
    work.mkdir(parents=True, exist_ok=True)
    template = load_template(TEMPLATE)
    cameras = camera_rig("humaneva4")
    manifold = None
    if any(m in MANIFOLD_METHODS for m in args.methods):
        manifold = bench_manifold(None, template, work)
    head = (
        "| clip | what | frames | method | events matched | within 1 frame | mean offset "
        "(frames) | max offset (frames) | cadence truth (steps/min) | cadence error % | "
        "stride truth (m) | stride error % |"
    )
    lines = [head, "|" + "---|" * (head.count("|") - 1)]
    print(head, flush=True)
    print(lines[1], flush=True)
    t0 = time.perf_counter()
    totals = {m: [0, 0, 0, 0.0, 0.0] for m in args.methods}  # events, matched, ≤ 1, |errors|
    for name in args.clips:
        source, what = CLIPS[name]
        if source in ("walk", "jog"):
            source = procedural_bvh(source, template, work)
        else:
            path = data / source
            if not path.is_file():
                print(f"left out {name}: {path} is absent")
                continue
            source = str(path.resolve())
        start, stop = in_view_range(source, template, cameras, max_frames=args.max_frames)
        spec = SynthSpec(
            motion=source, template=TEMPLATE, rig="humaneva4", fps=FPS, start=start, stop=stop
        )
        cap = synthesize(work / "captures" / f"{name}-{start}-{stop}", spec, show_progress=False)
        names = cap.meta["eval_names"]
        truth = gait_analysis(
            np.stack([f.truth.joints for f in cap]), cap.fps, names, frames=np.asarray(cap.indices)
        )
        ref = truth.summary()
        for method in args.methods:
            track = tracked(method, template, cap, work, manifold)
            c = compare_gaits(track_gait(read_track(track), cap.fps), truth)
            extra = f" +{c.spurious}" if c.spurious else ""
            close = int((np.abs(c.offsets) <= 1.0).sum())
            t = totals[method]
            t[:3] = t[0] + c.reference_events, t[1] + c.matched, t[2] + close
            t[3] = np.nanmax([t[3], abs(c.cadence_error_pct)])
            t[4] = np.nanmax([t[4], abs(c.stride_length_error_pct)])
            row = (
                f"| {name} | {what} | {len(cap)} | {method} | {c.matched}/{c.reference_events}"
                f"{extra} | {close}/{c.matched} | {c.mean_offset:.2f} | {c.max_offset:.2f} | "
                f"{ref.cadence_steps_per_min:.1f} | {c.cadence_error_pct:+.2f} | "
                f"{ref.stride_length_m:.3f} | {c.stride_length_error_pct:+.2f} |"
            )
            lines.append(row)
            print(row, flush=True)
    for m, (n, matched, close, cad, stride) in totals.items():
        row = (
            f"| all | | | {m} | {matched}/{n} | {close}/{matched} | | | | ≤ {cad:.2f} | | "
            f"≤ {stride:.2f} |"
        )
        lines.append(row)
        print(row)
    load = os.getloadavg()
    tail = (
        f"\n{time.perf_counter() - t0:.0f} s; load average {load[0]:.1f} {load[1]:.1f} "
        f"{load[2]:.1f}; tracking code {track_digest()}"
    )
    print(tail)
    (work / "results.md").write_text("\n".join(lines) + "\n" + tail + "\n")


if __name__ == "__main__":
    main()
