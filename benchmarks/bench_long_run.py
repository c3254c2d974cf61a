"""A long run: each tracker follows a 10,000-frame synthetic stream; memory stays flat.

Protocol: the procedural walk on ``neutral_5k`` with its root held in place (x = y = 0, the
height kept), one pass of the clip at 30 fps (121 frames) rendered in the 4-camera studio
and carved at 1 cm; the stream plays those frames in a loop, read from disk every time as
a live capture would be, for ``--frames`` frames: forward then backward (``--loop mirror``,
the default: frame k shows hull 0, 1, ..., 120, 119, ..., 1, 0, 1, ...; the body never
jumps) or over again from the start (``--loop wrap``: hull k mod 121; from the walk's last
frame to its first one joint jumps ~0.75 m in a frame, a fault no tracker is meant to
follow). Each tracker
starts from the first frame's true pose and writes its track folder frame by frame through
the usual driver. Resident memory (``VmRSS``) is sampled at every frame and appended to
``WORK/rss_<tracker>.tsv`` (frame, MB, seconds, process id) as it goes; the table gives its
mean and maximum over the first and the last 1,000 frames (or tenth, for shorter runs),
the seconds per frame and the track's and the capture's disk use per frame.

Resumable and chunked, for slow or shared machines: a run stopped at any point (Ctrl-C,
``kill -9``, ``--seconds`` reached) keeps every finished frame, and the same command
resumes each track where it stopped (``--restart`` starts over). ``--seconds S`` stops
each tracker after S seconds of this process. On a bigger machine ``--parallel`` runs the
trackers at once, one process each (one thread each). The table says which processes ran
which frames, so a chunked run's "last 1,000" are read as such. Timings depend on the load.

Usage: ``python benchmarks/bench_long_run.py [--frames 10000] [--trackers patch cage
articulated_icp] [--limit patch=2000 ...] [--seconds 600] [--parallel] [--restart]
[--loop mirror|wrap] [--work DIR]``
"""

from __future__ import annotations

import argparse
import os
import shutil
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

from meshmocap.body.template import load_template
from meshmocap.io.cameras import write_cameras
from meshmocap.io.capture import Capture, CaptureFrame, write_meta, write_truth_faces
from meshmocap.io.clips import clip_on
from meshmocap.io.results import read_track
from meshmocap.studio.rigs import camera_rig
from meshmocap.studio.synth import SynthSpec, synth_frame
from meshmocap.trackers.driver import track_sequence
from meshmocap.trackers.options import TrackOptions
from meshmocap.trackers.registry import make_tracker


def rss_mb() -> float:
    """Resident memory of this process, MB (``/proc/self/status``)."""
    with open("/proc/self/status") as f:
        for line in f:
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) / 1024
    return float("nan")


def in_place_walk(out: Path, n: int | None = None) -> Capture:
    """The walk on the spot, one pass of the clip or its first ``n`` frames (made once, then
    reused)."""
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
    n = motion.n_frames if n is None else min(n, motion.n_frames)
    for f in range(n):
        synth_frame(out, subject, motion.rotations[f], root[f], cams, f, spec)
    write_meta(
        out / "capture.json",
        {"fps": 30.0, "frames": list(range(n)), "spec": {"in_place": "walk"}},
    )
    return Capture(out)


LOOPS = ("mirror", "wrap")


def looped(k: int, n: int, loop: str) -> int:
    """The base frame (of ``n``) that frame ``k`` of the stream shows (``--loop``)."""
    if loop == "wrap" or n < 2:
        return k % n
    p = k % (2 * n - 2)
    return p if p < n else 2 * n - 2 - p


class OutOfTime(BaseException):
    """``--seconds`` reached: raised when the driver asks for the next frame, so the tracker
    stops after its last whole frame (a BaseException: no per-frame handler of the driver
    takes it for a failed frame)."""


class LoopCapture:
    """``n`` frames of ``base`` played in a loop; each time a frame is read, the resident
    memory is appended to the file ``log`` (frame, MB, seconds since start, process id)."""

    def __init__(
        self,
        base: Capture,
        n: int,
        log: Path,
        *,
        seconds: float | None = None,
        loop: str = "mirror",
    ):
        self.base, self.path, self.cameras = base, base.path, base.cameras
        self.loop = loop
        self.indices = list(range(n))
        self.truth_faces, self.fps, self.meta = base.truth_faces, base.fps, {}
        self.log = log
        self.t0 = time.perf_counter()
        self.deadline = None if seconds is None else self.t0 + seconds

    def __len__(self) -> int:
        return len(self.indices)

    def __getitem__(self, k: int) -> CaptureFrame:
        if self.deadline is not None and time.perf_counter() > self.deadline:
            raise OutOfTime  # between two frames: every finished frame is on disk
        with self.log.open("a") as f:  # line by line: a killed run keeps its samples
            f.write(f"{k}\t{rss_mb():.1f}\t{time.perf_counter() - self.t0:.3f}\t{os.getpid()}\n")
        return _LoopFrame(k, self.base, looped(k, len(self.base), self.loop))


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

    @property
    def silhouettes(self) -> list[np.ndarray]:
        """The base frame's masks (the stream's frame numbers run past the clip's)."""
        return CaptureFrame(self._source, self.capture).silhouettes


def du(path: Path) -> int:
    return sum(p.stat().st_size for p in path.rglob("*") if p.is_file())


def run_one(
    name: str, n: int, work: Path, *, seconds: int | None, restart: bool, loop: str = "mirror"
) -> None:
    """Track (or resume) ``n`` frames of the stream with ``name`` into ``work/track_NAME``."""
    base = in_place_walk(work / "capture")
    out, log = work / f"track_{name}", work / f"rss_{name}.tsv"
    kind = work / f"loop_{name}.txt"
    if restart:
        shutil.rmtree(out, ignore_errors=True)
        log.unlink(missing_ok=True)
        kind.unlink(missing_ok=True)
    # a track made before --loop existed played the stream wrapped; no track, no constraint
    made = (kind.read_text().strip() if kind.is_file() else "wrap") if out.is_dir() else loop
    if made != loop:
        sys.exit(f"{out}: tracked with --loop {made}, asked to resume with --loop {loop}")
    kind.write_text(loop)
    template = load_template("neutral_5k")
    stream = LoopCapture(base, n, log, seconds=seconds, loop=loop)
    t0 = time.perf_counter()
    try:
        track_sequence(
            make_tracker(name, template=template),
            template,
            stream,
            out,
            TrackOptions(show_progress=None, vertices=False, init="truth"),
        )
        how = "done"
    except (OutOfTime, KeyboardInterrupt):
        how = "stopped (rerun to resume)"
    print(f"{name}: {how} after {time.perf_counter() - t0:.0f} s in process {os.getpid()}")


def summary(name: str, n: int, work: Path) -> tuple | None:
    """The row of ``name``: frames done, s/frame, RSS over the first and last windows."""
    log, out = work / f"rss_{name}.tsv", work / f"track_{name}"
    if not log.is_file():
        return None
    rows = np.loadtxt(log, ndmin=2)
    if not len(rows):
        return None
    done = len(list((out / "frames").glob("*.npz")))
    if not done:
        return None
    # the last sample of each frame (a resumed frame may have been read twice)
    frame, mb, sec, pid = rows.T
    keep = np.unique(frame[::-1], return_index=True)[1]
    keep = len(frame) - 1 - keep
    frame, mb, sec, pid = frame[keep], mb[keep], sec[keep], pid[keep]
    w = min(1000, max(1, len(frame) // 10))  # 1,000 frames, or a tenth of those done
    first, last = mb[:w], mb[-w:]
    steps = np.diff(sec)[np.diff(pid) == 0]  # seconds between frames of one process
    spf = float(np.median(steps)) if len(steps) else float("nan")
    procs = len(np.unique(pid))
    bad = int((~read_track(out, vertices=False).healthy).sum())
    return (
        name,
        done,
        n,
        spf,
        first.mean(),
        first.max(),
        last.mean(),
        last.max(),
        f"{int(frame[0])}–{int(frame[w - 1])} / {int(frame[-w])}–{int(frame[-1])}",
        procs,
        du(out) / max(done, 1),
        bad,
    )


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--frames", type=int, default=10_000)
    ap.add_argument("--trackers", nargs="+", default=["cage", "articulated_icp", "patch"])
    ap.add_argument("--limit", nargs="*", default=[], help="TRACKER=N: fewer frames for one")
    ap.add_argument("--work", default="long-run-work", help="capture and tracks (reused)")
    ap.add_argument("--seconds", type=int, help="stop each tracker after this long (resumable)")
    ap.add_argument("--parallel", action="store_true", help="one process per tracker, at once")
    ap.add_argument("--restart", action="store_true", help="start the tracks over")
    ap.add_argument(
        "--loop", choices=LOOPS, default="mirror", help="forward then back, or over again"
    )
    ap.add_argument(
        "--clip-frames", type=int, help="loop only the clip's first N frames (quick checks)"
    )
    ap.add_argument("--one", help=argparse.SUPPRESS)  # a --parallel child: this tracker alone
    args = ap.parse_args()
    limits = {k: int(v) for k, v in (item.split("=") for item in args.limit)}
    work = Path(args.work)
    if args.one:
        run_one(
            args.one,
            limits.get(args.one, args.frames),
            work,
            seconds=args.seconds,
            restart=args.restart,
            loop=args.loop,
        )
        return 0
    t0 = time.perf_counter()
    base = in_place_walk(work / "capture", args.clip_frames)
    cap_bytes = du(work / "capture") / len(base)
    hull_bytes = du(work / "capture" / "hulls") / len(base)
    print(
        f"capture: {len(base)} frames in place, {cap_bytes / 1e3:.0f} kB per frame "
        f"({hull_bytes / 1e3:.0f} kB of it the hull), {time.perf_counter() - t0:.0f} s",
        flush=True,
    )
    if args.parallel:
        env = {
            **os.environ,
            "OMP_NUM_THREADS": "1",
            "OPENBLAS_NUM_THREADS": "1",
            "NUMBA_NUM_THREADS": "1",
            "MKL_NUM_THREADS": "1",
        }
        rest = [a for a in sys.argv[1:] if a != "--parallel"]
        procs = [
            subprocess.Popen([sys.executable, __file__, *rest, "--one", name], env=env)
            for name in args.trackers
        ]
        for pr in procs:
            pr.wait()
    else:
        for name in args.trackers:
            run_one(
                name,
                limits.get(name, args.frames),
                work,
                seconds=args.seconds,
                restart=args.restart,
                loop=args.loop,
            )
    print(
        "\n| tracker | frames done / asked | s/frame (median) | RSS first window mean / max "
        "(MB) | RSS last window mean / max (MB) | windows (frames) | processes | track disk "
        "per frame | unhealthy |"
    )
    print("|---|---:|---:|---:|---:|---:|---:|---:|---:|")
    for name in args.trackers:
        row = summary(name, limits.get(name, args.frames), work)
        if row is None:
            print(f"| {name} | 0 / {limits.get(name, args.frames)} | | | | | | | |")
            continue
        name, done, n, spf, m0, x0, m1, x1, windows, procs, disk, bad = row
        print(
            f"| {name} | {done} / {n} | {spf:.3f} | {m0:.0f} / {x0:.0f} | {m1:.0f} / {x1:.0f} "
            f"| {windows} | {procs} | {disk / 1e3:.1f} kB | {bad} |"
        )
    print(
        f"\ncapture disk per frame: {cap_bytes / 1e3:.0f} kB (hull {hull_bytes / 1e3:.0f} kB); "
        f"load average {os.getloadavg()[0]:.1f}; {os.cpu_count()} cores"
    )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
