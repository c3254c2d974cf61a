"""A long run: each tracker follows a 10,000-frame synthetic stream; memory stays flat.

Protocol: the procedural walk on ``neutral_5k`` with its root held in place (x = y = 0, the
height kept), one pass of the clip at 30 fps (121 frames) rendered in the 4-camera studio
and carved at 1 cm; the stream plays those frames in a loop (frame k shows hull k mod 121,
read from disk every time, as a live capture would be) for ``--frames`` frames. Each tracker
starts from the first frame's true pose and writes its track folder frame by frame through
the usual driver. Resident memory (``VmRSS``) is sampled at every frame; the table gives its
mean and maximum over the first and the last 1,000 frames (or tenth, for shorter runs) and
the track's and the capture's disk use per frame. Timings depend on the machine's load.

Usage: ``python benchmarks/bench_long_run.py [--frames 10000] [--trackers patch cage
articulated_icp] [--limit patch=2000 ...] [--work DIR]``
"""

from __future__ import annotations

import argparse
import os
import shutil
import time
from pathlib import Path

import numpy as np

from meshmocap.body.template import load_template
from meshmocap.io.cameras import write_cameras
from meshmocap.io.capture import Capture, CaptureFrame, write_meta, write_truth_faces
from meshmocap.io.clips import clip_on
from meshmocap.studio.rigs import camera_rig
from meshmocap.studio.synth import SynthSpec, synth_frame
from meshmocap.trackers.driver import track_sequence
from meshmocap.trackers.registry import make_tracker


def rss_mb() -> float:
    """Resident memory of this process, MB (``/proc/self/status``)."""
    with open("/proc/self/status") as f:
        for line in f:
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) / 1024
    return float("nan")


def in_place_walk(out: Path) -> Capture:
    """The walk on the spot, one pass of the clip (made once, then reused)."""
    if (out / "capture.json").is_file():
        return Capture(out)
    subject = load_template("neutral_5k")
    motion = clip_on(subject, "walk", fps=30.0)
    spec = SynthSpec(motion="walk", template="neutral_5k", fps=30.0)
    cams = camera_rig("humaneva4")
    for sub in ["hulls", "truth", *(f"silhouettes/{c.name}" for c in cams)]:
        (out / sub).mkdir(parents=True, exist_ok=True)
    write_cameras(out / "cameras.json", cams)
    write_truth_faces(out, subject.F)
    root = motion.root_positions.copy()
    root[:, :2] = 0.0  # in place
    for f in range(motion.n_frames):
        synth_frame(out, subject, motion.rotations[f], root[f], cams, f, spec)
    write_meta(
        out / "capture.json",
        {"fps": 30.0, "frames": list(range(motion.n_frames)), "spec": {"in_place": "walk"}},
    )
    return Capture(out)


class LoopCapture:
    """``n`` frames of ``base`` played in a loop; samples memory each time a frame is read."""

    def __init__(self, base: Capture, n: int) -> None:
        self.base, self.path, self.cameras = base, base.path, base.cameras
        self.indices = list(range(n))
        self.truth_faces, self.fps, self.meta = base.truth_faces, base.fps, {}
        self.rss: list[tuple[int, float, float]] = []  # (frame, MB, seconds since start)
        self.t0 = time.perf_counter()

    def __len__(self) -> int:
        return len(self.indices)

    def __getitem__(self, k: int) -> CaptureFrame:
        self.rss.append((k, rss_mb(), time.perf_counter() - self.t0))
        return _LoopFrame(k, self.base, k % len(self.base))


class _LoopFrame(CaptureFrame):
    """Frame ``index`` of the stream, showing the base capture's frame ``source``."""

    def __init__(self, index: int, base: Capture, source: int) -> None:
        object.__setattr__(self, "index", index)
        object.__setattr__(self, "capture", base)
        object.__setattr__(self, "_source", base.indices[source])

    @property
    def _hull_path(self) -> Path:
        return self.capture.path / "hulls" / f"{self._source:05d}.npz"

    @property
    def truth(self):
        return CaptureFrame(self._source, self.capture).truth


def du(path: Path) -> int:
    return sum(p.stat().st_size for p in path.rglob("*") if p.is_file())


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--frames", type=int, default=10_000)
    ap.add_argument("--trackers", nargs="+", default=["cage", "articulated_icp", "patch"])
    ap.add_argument("--limit", nargs="*", default=[], help="TRACKER=N: fewer frames for one")
    ap.add_argument("--work", default="long-run-work", help="capture and tracks (reused)")
    args = ap.parse_args()
    limits = {k: int(v) for k, v in (item.split("=") for item in args.limit)}
    work = Path(args.work)
    t0 = time.perf_counter()
    base = in_place_walk(work / "capture")
    cap_bytes = du(work / "capture") / len(base)
    hull_bytes = du(work / "capture" / "hulls") / len(base)
    print(
        f"capture: {len(base)} frames in place, {cap_bytes / 1e3:.0f} kB per frame "
        f"({hull_bytes / 1e3:.0f} kB of it the hull), {time.perf_counter() - t0:.0f} s",
        flush=True,
    )
    template = load_template("neutral_5k")
    rows = []
    for name in args.trackers:
        n = limits.get(name, args.frames)
        stream = LoopCapture(base, n)
        out = work / f"track_{name}"
        shutil.rmtree(out, ignore_errors=True)
        tracker = make_tracker(name, template=template)
        rss_start = rss_mb()
        t0 = time.perf_counter()
        track = track_sequence(tracker, template, stream, out, show_progress=None, vertices=False)
        dt = time.perf_counter() - t0
        r = np.array([m for _, m, _ in stream.rss])
        w = min(1000, max(1, n // 10))
        disk = du(out) / n
        rows.append(
            (
                name,
                n,
                dt / n,
                r[:w].mean(),
                r[:w].max(),
                r[-w:].mean(),
                r[-w:].max(),
                w,
                disk,
                int((~track.healthy).sum()),
                rss_start,
            )
        )
        print(
            f"{name}: {n} frames in {dt:.0f} s ({dt / n:.3f} s/frame); RSS first {w}: "
            f"mean {r[:w].mean():.0f} MB max {r[:w].max():.0f}; last {w}: mean "
            f"{r[-w:].mean():.0f} MB max {r[-w:].max():.0f}; {disk / 1e3:.0f} kB/frame; "
            f"{rows[-1][9]} unhealthy",
            flush=True,
        )
        del track
    print(
        "\n| tracker | frames | s/frame | RSS first window mean / max (MB) | RSS last window "
        "mean / max (MB) | window | track disk per frame | unhealthy |"
    )
    print("|---|---:|---:|---:|---:|---:|---:|---:|")
    for name, n, spf, m0, x0, m1, x1, w, disk, bad, _ in rows:
        print(
            f"| {name} | {n} | {spf:.3f} | {m0:.0f} / {x0:.0f} | {m1:.0f} / {x1:.0f} | {w} | "
            f"{disk / 1e3:.1f} kB | {bad} |"
        )
    print(
        f"\ncapture disk per frame: {cap_bytes / 1e3:.0f} kB (hull {hull_bytes / 1e3:.0f} kB); "
        f"load average {os.getloadavg()[0]:.1f}"
    )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
