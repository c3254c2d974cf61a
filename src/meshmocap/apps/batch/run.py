"""Many captures at once (``meshmocap batch``): hulls, tracking and evaluation as tasks on
Dask, from one machine to a cluster, or one after another without Dask.

Layout of a batch folder::

    OUT/
      batch.json             the items (capture, method, template, frames) and settings
      summary.csv            one row per capture (:data:`SUMMARY_COLUMNS`)
      summary.md             the same as a markdown table
      <name>/track/          the capture's track folder (as ``meshmocap track`` writes it)
      <name>/eval/           its evaluation (summary.txt, CSV, PNG) where the capture has truth
      <name>/attempts.log    one line per attempt at tracking it (a retry adds a line)
      <name>/result.json     the capture's summary row, written when it is done

Work per capture: the visual hulls a capture folder lacks are carved first (one task per
chunk of frames, so a long capture spreads over the workers), then the capture is tracked
(one task: frames depend on each other), then evaluated where it has ground truth. A
capture that fails records its one-line error and does not stop the others. Every frame
file is written atomically, so a worker killed mid-run loses only its unfinished frame:
Dask reschedules the task and the track resumes. Rerunning a batch redoes only what is
missing (finished captures are read back from ``result.json``).
"""

from __future__ import annotations

import json
import os
import time
import traceback
from collections.abc import Callable, Iterator, Sequence
from dataclasses import asdict, dataclass, replace
from pathlib import Path
from typing import Any

from meshmocap._atomic import write_text_atomic
from meshmocap._progress import progress
from meshmocap._validate import frame_positions, frame_slice
from meshmocap.apps.batch.items import BatchItem
from meshmocap.apps.batch.summary import (
    CaptureSummary,
    read_summary,
    summary_line,
    write_result,
    write_summary,
)
from meshmocap.errors import InputError, MeshmocapError

__all__ = [
    "MALLOC",
    "ONE_THREAD",
    "QUIET_DASK",
    "BatchResult",
    "available_cores",
    "have_dask",
    "run_batch",
    "tune_worker",
]

#: Frames of hull carving per task.
HULL_CHUNK = 20


@dataclass(frozen=True)
class BatchResult:
    """What :func:`run_batch` did: one summary per item (in the items' order), the files it
    wrote, the wall time, how it ran (``"dask"`` or ``"serial"``) and the Dask dashboard's
    address (empty when there is none)."""

    summaries: tuple[CaptureSummary, ...]
    files: tuple[Path, ...]
    seconds: float
    mode: str
    dashboard: str = ""


# ------------------------------------------------------------------------------ tasks
def _hull_chunks(item: BatchItem) -> list[list[int]]:
    """Frames of a capture folder that have silhouettes but no hull yet, in chunks."""
    path = Path(item.capture)
    if not (path / "silhouettes").is_dir():
        return []
    from meshmocap.io.cameras import read_cameras
    from meshmocap.io.capture import frame_name
    from meshmocap.studio.hulls import camera_file, silhouette_frames

    cameras = read_cameras(camera_file(path))
    todo = [
        f
        for f in silhouette_frames(path, [c.name for c in cameras])
        if not (path / "hulls" / f"{frame_name(f)}.npz").is_file()
    ]
    return [todo[i : i + HULL_CHUNK] for i in range(0, len(todo), HULL_CHUNK)]


def _checked_chunks(
    item: BatchItem, out: Path, results: dict[str, CaptureSummary], log: Callable[[str], None]
) -> list[list[int]] | None:
    """:func:`_hull_chunks`, or None when the capture cannot be read (a corrupt
    ``cameras.json``): the capture is then recorded as failed with the one-line reason,
    and the batch goes on with the others."""
    try:
        return _hull_chunks(item)
    except MeshmocapError as exc:
        summary = CaptureSummary(
            item.name,
            item.capture,
            item.method,
            item.template or "default",
            "failed",
            error=_one_line(exc),
        )
        (out / item.name).mkdir(parents=True, exist_ok=True)
        write_result(out / item.name / "result.json", summary)
        results[item.name] = summary
        log(summary_line(summary))
        return None


def _carve(capture: str, frames: list[int]) -> int:
    """Task: carve the hulls of ``frames`` of a capture folder; returns how many."""
    from meshmocap.studio.hulls import compute_hulls

    tune_worker()
    compute_hulls(capture, frames=frames, show_progress=False)
    return len(frames)


def _one_line(exc: BaseException) -> str:
    text = str(exc).strip().splitlines()[0] if str(exc).strip() else ""
    if isinstance(exc, MeshmocapError):
        return text[:300]
    return f"{type(exc).__name__}: {text}"[:300]  # a defect: say where it came from


def _track(item: BatchItem, out: str, *_hulls: int) -> dict[str, Any]:
    """Task: track (and evaluate) one capture into ``out/<name>``; never raises for a
    capture's fault, returns its :class:`CaptureSummary` as a dict."""
    tune_worker()
    folder = Path(out) / item.name
    folder.mkdir(parents=True, exist_ok=True)
    with (folder / "attempts.log").open("a") as log:  # the retry count survives a kill
        log.write(f"{time.strftime('%Y-%m-%dT%H:%M:%S')} pid {os.getpid()}\n")
    attempts = len((folder / "attempts.log").read_text().splitlines())
    template = item.template or "default"
    base = CaptureSummary(
        item.name, item.capture, item.method, template, "failed", attempts=attempts
    )
    try:
        summary = _track_and_score(item, folder, base)
    except Exception as exc:  # one capture's failure must not stop the batch
        summary = replace(base, error=_one_line(exc))
        if not isinstance(exc, MeshmocapError):
            write_text_atomic(folder / "traceback.txt", traceback.format_exc())
    write_result(folder / "result.json", summary)
    return asdict(summary)


def _track_and_score(item: BatchItem, folder: Path, base: CaptureSummary) -> CaptureSummary:
    from meshmocap.analysis.evaluate import evaluate
    from meshmocap.apps.files.evaluation import write_evaluation
    from meshmocap.body.light import tracking_body
    from meshmocap.estimate.performer.tracking_template import tracking_template
    from meshmocap.io.axes import open_oriented
    from meshmocap.io.capture import Capture
    from meshmocap.io.results import template_label
    from meshmocap.trackers.driver import track_sequence
    from meshmocap.trackers.options import TrackOptions
    from meshmocap.trackers.registry import make_tracker

    capture, _ = open_oriented(item.capture)  # mesh files: up axis and units as track reads
    choice = tracking_template(capture, item.template or None, folder / "track")
    template = choice.template
    tracker = make_tracker(item.method, template=tracking_body(template).light)  # as tracked
    # frame numbers, as track reads them
    frames = frame_slice(item.frames, what="batch: frames") if item.frames else None
    track = track_sequence(
        tracker,
        template,
        capture,
        folder / "track",
        TrackOptions(frames=frames, show_progress=False, template_info=choice.info),
    )
    flags = track.flags or tuple(() if h else ("failed",) for h in track.healthy)
    steady = track.seconds[1:] if len(track.seconds) > 1 else track.seconds
    summary = replace(
        base,
        status="ok",
        frames=len(track.frames),
        template=template_label(track.meta),
        flagged=sum(1 for f in flags if f),
        lost=sum("lost" in f for f in flags),
        missing=sum("missing" in f for f in flags),
        seconds_per_frame=float(steady.mean()),
    )
    if isinstance(capture, Capture) and (Path(capture.path) / "truth").is_dir():
        ev = evaluate(track, capture, silhouettes=False, surface_frames=0)
        write_evaluation(ev, folder / "eval")
        errs = ev.joints if ev.joints is not None else ev.correspondence
        if errs is not None and errs.per_frame.size:
            summary = replace(
                summary,
                mean_mm=float(errs.overall.mean),
                worst_frame_mm=float(errs.per_frame.max()),
            )
    return summary


# ------------------------------------------------------------------------------ running
def _frames_done(out: Path, items: Sequence[BatchItem]) -> int:
    return sum(len(list((out / it.name / "track" / "frames").glob("*.npz"))) for it in items)


def _frame_total(item: BatchItem) -> int:
    """Frames the capture will give (for the progress bar; 0 when it cannot be opened:
    the task reports why)."""
    try:
        from meshmocap.io.capture import open_capture

        cap = open_capture(item.capture)
        if not item.frames:
            return len(cap)
        return len(frame_positions([int(i) for i in cap.indices], frame_slice(item.frames)))
    except MeshmocapError:
        return 0


def _watch(done: Callable[[], int], finished: Callable[[], bool]) -> Iterator[None]:
    """Yield once per newly finished frame until ``finished()`` (polled every 0.5 s)."""
    seen = done()
    while True:
        now = done()
        for _ in range(max(now - seen, 0)):
            yield
        seen = max(seen, now)
        if finished():
            return
        time.sleep(0.5)


def _client(workers: int | None, scheduler: str | None):
    """A Dask client: on ``scheduler``, or on a new local cluster of worker processes."""
    from distributed import Client, LocalCluster

    if scheduler:
        try:
            return Client(scheduler, timeout="10s"), None
        except OSError as exc:
            raise InputError(
                f"batch: --scheduler {scheduler}: no Dask scheduler answers there ({exc})"
            ) from None
    # the dashboard on a free port, shown or not: None still binds 8787, so a second batch
    # on the same machine would fail to start
    cluster = LocalCluster(
        n_workers=workers or available_cores(),
        threads_per_worker=1,
        processes=True,
        dashboard_address=":0",
        # set before the worker process starts: its imports and its malloc see them
        env={**ONE_THREAD, **{k: str(v) for k, v in MALLOC.items()}},
    )
    return Client(cluster), cluster


#: Environment of a worker process: one thread for every pool (BLAS, OpenMP, numba), so
#: W workers keep W cores busy, not W × threads fighting over them.
ONE_THREAD = {
    v: "1"
    for v in (
        "OMP_NUM_THREADS",
        "OPENBLAS_NUM_THREADS",
        "MKL_NUM_THREADS",
        "BLIS_NUM_THREADS",
        "NUMBA_NUM_THREADS",
        "MESHMOCAP_THREADS",
    )
}

#: glibc malloc settings of a worker (bytes). Dask's nanny starts workers with
#: ``MALLOC_TRIM_THRESHOLD_=65536``, which also fixes the mmap threshold at 128 kB: every
#: array above it is mapped and unmapped, and the tracker's short-lived arrays cost a page
#: fault per 4 kB touched (a frame tracked in a worker took twice the CPU, half of it in the
#: kernel). A top of 128 MB and arrays up to 32 MB stay on the heap.
MALLOC = {"MALLOC_TRIM_THRESHOLD_": 1 << 27, "MALLOC_MMAP_THRESHOLD_": 1 << 25}

_TUNED: list[int] = []

#: Dask settings of a local cluster: no statistical profiler in the workers (a thread that
#: wakes every 10 ms to walk the running task's stack) and the resource monitors polled
#: every 5 s instead of 0.5 s, which halves what an idle cluster of 2 workers costs.
QUIET_DASK = {
    "distributed.worker.profile.enabled": False,
    "distributed.admin.system-monitor.interval": "5s",
    "distributed.admin.tick.interval": "100ms",
}


def tune_worker() -> None:
    """Give this process the batch worker's settings, once: every thread pool at one thread
    (threadpoolctl, for pools already started) and the :data:`MALLOC` thresholds (glibc's
    ``mallopt``, which overrides what the process was started with). Run at the start of
    each task, so workers started by any cluster (``dask worker``, dask-jobqueue) get them."""
    if os.getpid() in _TUNED:
        return
    try:
        from threadpoolctl import threadpool_limits

        threadpool_limits(1)
    except ImportError:  # pragma: no cover (threadpoolctl is optional)
        pass
    try:
        import ctypes

        libc = ctypes.CDLL("libc.so.6")
        libc.mallopt(-1, MALLOC["MALLOC_TRIM_THRESHOLD_"])  # M_TRIM_THRESHOLD
        libc.mallopt(-3, MALLOC["MALLOC_MMAP_THRESHOLD_"])  # M_MMAP_THRESHOLD
    except (OSError, AttributeError):  # pragma: no cover (not glibc: nothing to fix)
        pass
    _TUNED[:] = [os.getpid()]


def available_cores() -> int:
    """Cores this process may run on (its CPU affinity; all cores where unknown)."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # pragma: no cover (macOS, Windows)
        return os.cpu_count() or 1


def have_dask() -> bool:
    """Whether ``dask.distributed`` is installed (``pip install -e ".[cluster]"``)."""
    try:
        import distributed  # noqa: F401
    except ImportError:
        return False
    return True


def run_batch(
    items: Sequence[BatchItem],
    out: str | os.PathLike,
    *,
    workers: int | None = None,
    scheduler: str | None = None,
    client: Any = None,
    serial: bool = False,
    dashboard: bool = True,
    show_progress: bool | None = None,
    log: Callable[[str], None] = lambda line: None,
) -> BatchResult:
    """Carve missing hulls, track and evaluate every item; write the summaries to ``out``.

    Parameters
    ----------
    items : sequence of BatchItem
        From :func:`batch_items`.
    out : path
        Batch folder (see the module docstring); a rerun redoes only what is missing.
    workers : int, optional
        Worker processes of the local Dask cluster (default: the number of cores).
    scheduler : str, optional
        Address of an existing Dask scheduler (``tcp://host:8786``) to send the work to.
    client : distributed.Client, optional
        An existing client to use (for tests and notebooks); it is not closed.
    serial : bool
        Run in this process, one capture after another, without Dask (the default when
        Dask is not installed).
    dashboard : bool
        Give the local cluster's dashboard address (in the result and the log).
    log : callable
        Receives one line per finished capture and the run's setup.
    """
    if not items:
        raise InputError("batch: no captures to run")
    if workers is not None and (not isinstance(workers, int) or workers < 1):
        raise InputError(f"batch: --workers must be an integer ≥ 1, found {workers!r}")
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    write_text_atomic(
        out / "batch.json",
        json.dumps({"format": "meshmocap-batch-1", "items": [asdict(i) for i in items]}, indent=2)
        + "\n",
    )
    t0 = time.perf_counter()
    results: dict[str, CaptureSummary] = {}
    todo = []
    for it in items:
        old = read_summary(out / it.name / "result.json")
        if old is not None and old.status == "ok" and old.capture == it.capture:
            results[it.name] = old
        else:
            todo.append(it)
    if results:
        log(f"{len(results)} capture(s) already done, {len(todo)} to run")
    total = sum(_frame_total(it) for it in todo)
    done = lambda: _frames_done(out, todo)  # noqa: E731
    mode, link = "serial", ""
    if todo and not serial and (client is not None or scheduler or have_dask()):
        import dask

        mode = "dask"
        with dask.config.set(QUIET_DASK):  # the local cluster's processes inherit it
            own_client, cluster = (
                (client, None) if client is not None else _client(workers, scheduler)
            )
            try:
                link = getattr(own_client, "dashboard_link", "") or "" if dashboard else ""
                info = own_client.scheduler_info().get("workers", {})
                n, threads = len(info), sum(int(w.get("nthreads", 1)) for w in info.values())
                where = f"{available_cores()} available here" if cluster else "on the cluster"
                log(
                    f"running {len(todo)} capture(s) on Dask: {n} workers, {threads} cores used "
                    f"({where})" + (f"; dashboard {link}" if link else "")
                )
                futures = {}
                for it in todo:
                    chunks = _checked_chunks(it, out, results, log)
                    if chunks is None:
                        continue
                    hulls = [own_client.submit(_carve, it.capture, c, pure=False) for c in chunks]
                    futures[it.name] = own_client.submit(_track, it, str(out), *hulls, pure=False)
                pending = set(futures)
                name_of = {f.key: n for n, f in futures.items()}

                def finished() -> bool:
                    for f in list(futures.values()):
                        if f.done() and name_of[f.key] in pending:
                            pending.discard(name_of[f.key])
                            results[name_of[f.key]] = _collect(f, name_of[f.key], todo, out)
                            log(summary_line(results[name_of[f.key]]))
                    return not pending

                for _ in progress(
                    _watch(done, finished), total=total, label="batch", enabled=show_progress
                ):
                    pass
            finally:
                if client is None:
                    own_client.close()
                    if cluster is not None:
                        cluster.close()
    elif todo:
        if not serial and not have_dask():
            log(
                "batch: Dask is not installed, running the captures one after another in this "
                'process; pip install -e ".[cluster]" runs them in parallel'
            )
        bar = iter(progress(range(total), total=total, label="batch", enabled=show_progress))
        for it in todo:
            chunks = _checked_chunks(it, out, results, log)
            if chunks is None:
                continue
            for chunk in chunks:
                _carve(it.capture, chunk)
            before = done()
            results[it.name] = CaptureSummary(**_track(it, str(out)))
            for _ in range(done() - before):
                next(bar, None)
            log(summary_line(results[it.name]))
        for _ in bar:  # finish the bar (frames counted beforehand but not tracked)
            pass
    summaries = tuple(results[it.name] for it in items)
    files = write_summary(out, summaries)
    return BatchResult(summaries, files, time.perf_counter() - t0, mode, link)


def _collect(future: Any, name: str, todo: Sequence[BatchItem], out: Path) -> CaptureSummary:
    """The summary of a finished future; a task that Dask gave up on (its workers kept
    dying) is a failed capture with that reason."""
    try:
        return CaptureSummary(**future.result())
    except Exception as exc:
        it = next(i for i in todo if i.name == name)
        log_file = out / name / "attempts.log"
        attempts = len(log_file.read_text().splitlines()) if log_file.is_file() else 0
        return CaptureSummary(
            name,
            it.capture,
            it.method,
            it.template,
            "failed",
            error=_one_line(exc),
            attempts=attempts,
        )
