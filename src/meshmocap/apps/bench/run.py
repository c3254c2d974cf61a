"""Both papers side by side in one reproducible run (``meshmocap bench``).

Every method, ablation and baseline of :data:`~meshmocap.trackers.registry.METHODS` tracks
every capture of a named set; each (capture, method) pair is scored by
:func:`~meshmocap.analysis.evaluate.evaluate` and written as ``results.csv``,
``results.md`` and plots (:mod:`meshmocap.apps.bench.report`).

``meshmocap bench`` (this module and the rest of :mod:`meshmocap.apps.bench`: ``captures``,
``rows``, ``report``, ``plots``) is the product's comparison of the methods, shipped and
run by users. The scripts in the project's ``benchmarks/`` folder are developers' tools
(speed, long runs, real-data acceptance, old tree against new), not shipped; one that
reproduces a paper's table calls :func:`run_bench` (``benchmarks/README.md`` lists them).

Protocol: synthetic captures from the studio at 60 fps, tracking template ``neutral_5k``,
subject = template unless a variant names another body, first frame initialised from
ground truth (``init="auto"``: found from the capture alone; the crane starts in its
template's rest pose, its frame 0), visual
hulls carved at 1 cm; joint errors over the 15 evaluation joints,
bone-length spread over the tracked evaluation skeleton, silhouette overlap error against
the input silhouettes, seconds per frame as timed by the driver on this machine (frame 0,
the initialisation, left out).

Captures are named ``BASE[+VARIANT...]``, e.g. ``walk``, ``walk+ring8+degraded``,
``05_01+heavy_male``:

* BASE: a procedural motion (always available), a CMU clip of ``DATA/mocap/cmu``
  (:data:`CMU_CLIPS`), or ``crane``: the MIT crane meshes of ``DATA/meshes/crane`` turned
  into ``ring8`` visual hulls (real geometry; scored by per-vertex correspondence error),
  tracked with frame 0's true mesh rigged by :func:`~meshmocap.body.autorig.rig_mesh` as
  template, started from that template's own pose, the cage methods with a manifold of 16
  poses fitted to the sequence (:func:`mesh_manifold`; not applicable where
  :func:`~meshmocap.trackers.cage.oqr.build_oqr` fails on the rigged frame);
* VARIANT: a rig (``humaneva4``, the default, or ``ring8``), ``degraded`` silhouettes
  (:data:`DEGRADED`) or another subject body (``heavy_male``, ``small_female``).

Sets (:data:`CAPTURE_SETS`; captures needing ``data`` are left out without it):
``quick`` (walk and jog, 40 frames; patch, patch_noclf, articulated_icp and cage: minutes,
run it first), ``standard`` (procedural motions, each variant on the walk, two CMU clips,
the crane; 120 frames; every method), ``full`` (everything, whole clips).

The work folder caches everything and a re-run resumes: ``captures/<capture>-<N>f/``
(:func:`~meshmocap.studio.synth.synthesize` resumes), ``tracks/<capture>-<N>f/
<method>-<key>/`` (:func:`~meshmocap.trackers.driver.track_sequence` resumes) with the
scores cached beside the frames, the cage trackers' pose manifold
``manifold-<template>-<key>.npz``, and for a mesh capture its rigged first frame
``templates/<capture>.npz`` (named after the sequence, e.g. ``crane_frame0``) and manifold
``manifold-<capture>-<key>.npz``. Every key is a digest of all the settings that make the
cached thing (options, template, frames, manifold) and of the tracking code
(:func:`settings_key`), so a run in a fresh folder reproduces a cached one. The report
folder gets ``settings.json`` beside the results: every setting, the track folders, the
code digest, the library versions and the machine.
"""

from __future__ import annotations

import functools
import hashlib
import json
import math
import os
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from meshmocap._atomic import write_text_atomic
from meshmocap._validate import check_choice
from meshmocap.analysis.evaluate import evaluate
from meshmocap.apps.bench.captures import (
    CAPTURE_SETS,
    DEFAULT_KEEP_FRACTIONS,
    capture_set,
    make_capture,
    mesh_template,
    parse_capture,
)
from meshmocap.apps.bench.report import write_report
from meshmocap.apps.bench.rows import (
    BenchRow,
    TradeoffPoint,
    not_applicable,
    row_from_evaluation,
)
from meshmocap.body.procedural import PROCEDURAL_MOTIONS
from meshmocap.body.template import Template, load_template
from meshmocap.errors import InputError
from meshmocap.io.capture import Capture
from meshmocap.io.results import done_frames
from meshmocap.trackers.cage.manifold import template_digest
from meshmocap.trackers.driver import track_sequence
from meshmocap.trackers.options import TrackOptions
from meshmocap.trackers.registry import MANIFOLD_METHODS, METHODS, make_tracker

_EVAL_CACHE = "bench_eval.json"
_EVAL_VERSION = 1


def mesh_manifold(
    capture: Capture,
    template: Template,
    work: str | os.PathLike,
    *,
    n_poses: int = 16,
    n_components: int = 10,
) -> tuple[Any, str]:
    """The cage trackers' pose manifold of a skeleton-less capture, as in
    cage-manifold-tracking §6.1 but fitted automatically: ``template``'s skeleton fitted to
    the true meshes of ``n_poses`` frames evenly spread over the capture
    (:func:`~meshmocap.body.autorig.fit_sequence`), the quads mapped rigidly to each fitted
    skeleton, an ``n_components``-D GPLVM learned; cached as ``work/manifold-<capture>-
    <key>.npz`` (the key: the template, the frames, the settings and the tracking code).
    Returns ``(GPLVM, "")``, or ``(None, why)`` when the template's quad rigging cannot be
    built (:func:`~meshmocap.trackers.cage.oqr.build_oqr` fails)."""
    from meshmocap.body.autorig import fit_sequence
    from meshmocap.errors import MeshError
    from meshmocap.trackers.cage.manifold import PoseManifold, fit_pose_manifold
    from meshmocap.trackers.cage.oqr import build_oqr, configuration_vector, quads_from_pose
    from meshmocap.trackers.cage.training_poses import PoseSet

    try:
        oqr = build_oqr(template)
    except MeshError as exc:
        return None, f"build_oqr fails on the rigged frame 0 ({exc})"
    key = settings_key(template_digest(template), list(capture.indices), n_poses, n_components)
    path = Path(work) / f"manifold-{capture.path.name}-{key}.npz"
    if path.is_file():
        pm = PoseManifold.load(path)
        pm.check(template, oqr, source=path)
        return pm.gp, ""
    pick = np.unique(np.linspace(0, len(capture) - 1, n_poses).round().astype(np.int64))
    if len(pick) < 3:  # a q-D GPLVM needs at least q + 2 poses
        return None, f"a pose manifold needs at least 3 frames, the capture has {len(pick)}"
    meshes = [(capture[int(k)].truth.vertices.astype(np.float64), template.F) for k in pick]
    fits = fit_sequence(template, meshes)
    R, root = np.stack([f.R for f in fits]), np.stack([f.root for f in fits])
    Y = configuration_vector(*quads_from_pose(oqr, template, R, root))
    trials = np.array([f"{capture.path.name}:{capture[int(k)].index}" for k in pick])
    poses = PoseSet(Y, trials, np.full(len(pick), "fitted"), template.name, ("fitted poses",))
    pm = fit_pose_manifold(
        poses, template, oqr=oqr, n_components=min(n_components, len(pick) - 2), n_samples=len(pick)
    )
    pm.save(path)
    return pm.gp, ""


def bench_manifold(manifold: Any, template: Template, work: str | os.PathLike) -> Any:
    """The pose manifold shared by every cage method (:data:`MANIFOLD_METHODS`), resolved
    once and checked against ``template``: ``manifold`` as given (GPLVM, PoseManifold or
    path), or None: learned on the fly as the cage tracker learns it
    (:func:`~meshmocap.trackers.cage.manifold.resolve_manifold`) and cached as
    ``work/manifold-<template>-<key>.npz`` (the key: the template, the pose library and the
    tracking code).
    Returns the fitted GPLVM."""
    from meshmocap.body.pose_library import load_pose_library
    from meshmocap.trackers.cage.manifold import PoseManifold, resolve_manifold

    key = settings_key(template_digest(template), "default manifold", load_pose_library().digest)
    path = Path(work) / f"manifold-{template.name}-{key}.npz"
    if manifold is None and path.is_file():
        manifold = path
    pm = resolve_manifold(manifold, template)
    if manifold is None:
        pm.save(path)
    return pm.gp if isinstance(pm, PoseManifold) else pm


@dataclass(frozen=True, eq=False)
class BenchResult:
    """What :func:`run_bench` measured and wrote.

    Attributes
    ----------
    rows : one per (capture, method), in the order run (not applicable ones included)
    tradeoff : Fig. 8 points (patch tracker, each kept fraction) on ``tradeoff_capture``
    tradeoff_capture : str or None
    files : written files (CSV, markdown, PNG)
    skipped : (capture, reason) of set captures left out (e.g. no data folder)
    tracked, evaluated : ``capture/track`` names tracked or scored by this run (empty when
        everything was reused)
    seconds : wall time of the run
    """

    rows: tuple[BenchRow, ...]
    tradeoff: tuple[TradeoffPoint, ...]
    tradeoff_capture: str | None
    files: tuple[Path, ...]
    skipped: tuple[tuple[str, str], ...]
    tracked: tuple[str, ...]
    evaluated: tuple[str, ...]
    seconds: float


@dataclass
class _Run:
    """Mutable state of one :func:`run_bench` call."""

    work: Path
    show_progress: bool | None
    log: Callable[[str], None]
    tracked: list[str] = field(default_factory=list)
    evaluated: list[str] = field(default_factory=list)

    def track_and_score(
        self,
        name: str,
        label: str,
        tracker: Any,
        template: Template,
        capture: Capture,
        *,
        salt: str = "",
        init: str = "truth",
    ) -> BenchRow:
        """Track (or resume) and score ``tracker`` on ``capture`` (named ``name``) as
        method ``label``. The track folder is named by a digest of the tracker's options,
        the template, ``salt`` (e.g. the manifold's) and the tracking code
        (:func:`code_digest`); scores are cached beside it."""
        digest = settings_key(
            tracker.name, tracker.options(), template.name, template_digest(template), salt, init
        )
        out = self.work / "tracks" / capture.path.name / f"{label.split('[')[0]}-{digest}"
        key = f"{capture.path.name}/{out.name}"
        before = len(done_frames(out)) if (out / "frames").is_dir() else 0
        track = track_sequence(
            tracker,
            template,
            capture,
            out,
            TrackOptions(show_progress=self.show_progress, init=init),
        )
        if len(track.frames) > before:
            self.tracked.append(key)
        cache = out / _EVAL_CACHE
        stamp = _stamp(out)
        if cache.is_file():
            cached = json.loads(cache.read_text())
            if cached.get("stamp") == stamp:
                return BenchRow.from_json(cached["row"], capture=name, method=label)
        ev = evaluate(track, capture, surface_frames=0, silhouettes=True)
        row = row_from_evaluation(name, label, ev, track=out)
        write_text_atomic(cache, json.dumps({"stamp": stamp, "row": row.to_json()}) + "\n")
        self.evaluated.append(key)
        return row


def settings_key(*parts: Any) -> str:
    """Digest (8 hex digits) of everything that makes a cached result: the settings (any
    JSON-ready values) and the tracking code (:func:`code_digest`)."""
    text = json.dumps([*parts, code_digest()], sort_keys=True, default=str)
    return hashlib.sha1(text.encode()).hexdigest()[:8]


@functools.cache
def code_digest() -> str:
    """Digest (8 hex digits) of the package's source outside ``analysis/`` and ``apps/``:
    the code that makes a track. A benchmark keys its cached tracks by it, so an edited tracker
    re-tracks instead of resuming a track made by the old code."""
    root = Path(__file__).resolve().parents[2]  # src/meshmocap
    h = hashlib.sha1()
    for p in sorted(root.rglob("*.py")):
        rel = p.relative_to(root).as_posix()
        if not rel.startswith(("analysis/", "apps/")):
            h.update(rel.encode() + b"\0" + p.read_bytes())
    return h.hexdigest()[:8]


def _versions() -> dict[str, str]:
    """Versions of meshmocap, Python and the numerical libraries (for settings.json)."""
    import platform
    from importlib.metadata import PackageNotFoundError, version

    out = {"python": platform.python_version()}
    for name in ("meshmocap", "numpy", "scipy", "scikit-learn", "pykdtree", "trimesh"):
        try:
            out[name] = version(name)
        except PackageNotFoundError:
            out[name] = "not installed"
    return out


def _machine() -> dict[str, Any]:
    """Where the timings come from: the platform, cores and load average."""
    import platform

    load = os.getloadavg() if hasattr(os, "getloadavg") else (math.nan,) * 3
    return {
        "platform": platform.platform(),
        "processor": platform.processor(),
        "cores": os.cpu_count(),
        "load_average": [round(x, 2) for x in load],
        "date": time.strftime("%Y-%m-%d %H:%M:%S %Z"),
    }


def _stamp(track: Path) -> str:
    """Fingerprint of a track's frame files (names, sizes, modification times)."""
    files = sorted((track / "frames").glob("*.npz"))
    parts = [f"{p.name}:{p.stat().st_size}:{p.stat().st_mtime_ns}" for p in files]
    return hashlib.sha1(f"{_EVAL_VERSION}|{'|'.join(parts)}".encode()).hexdigest()


def run_bench(
    out: str | os.PathLike,
    *,
    captures: str | Sequence[str] = "quick",
    methods: Sequence[str] | None = None,
    data: str | os.PathLike | None = None,
    work: str | os.PathLike | None = None,
    max_frames: int | None = None,
    keep_fractions: Sequence[float] | None = None,
    tradeoff_capture: str | None = None,
    template: str = "neutral_5k",
    method_options: Mapping[str, Mapping[str, Any]] | None = None,
    manifold: Any = None,
    init: str = "truth",
    show_progress: bool | None = None,
    log: Callable[[str], None] | None = None,
) -> BenchResult:
    """Run every method on every capture and write the report into the folder ``out``.

    Parameters
    ----------
    out : path
        Report folder: ``results.csv``, ``results.md``, ``frame_errors.csv``,
        ``bone_lengths.csv``, ``keep_fraction.csv`` and PNG plots.
    captures : str or sequence of str
        A set name (:data:`CAPTURE_SETS`) or capture names (module docstring).
    methods : sequence of str, optional
        Names in :data:`~meshmocap.trackers.registry.METHODS` (default: the set's, else
        every registered method, in order).
    data : path, optional
        The shared data folder (CMU clips, crane); captures of a set that need it are left
        out without it.
    work : path, optional
        Cache of captures, tracks and scores (default ``out/work``); share it between runs.
    max_frames : int, optional
        At most this many frames per capture (a set's own count applies too).
    keep_fractions : sequence of float, optional
        Kept fractions of the patch tracker's classifier (Fig. 8; default: the set's, else
        :data:`DEFAULT_KEEP_FRACTIONS`), run on
        ``tradeoff_capture`` (default: the first synthetic capture) when ``"patch"`` is
        among ``methods``; empty to skip.
    template : str
        Tracking template.
    method_options : mapping of method → options, optional
        Extra tracker options per method (e.g. ``{"patch": {"n_patches": 120}}``).
    manifold : GPLVM, path or None
        Pose manifold of the methods that take one (the cage trackers); None: learned once
        from the procedural motions and cached in ``work`` (:func:`bench_manifold`).
    init : {"truth", "auto"}
        First pose of the synthetic captures: from ground truth (the papers' protocol) or
        found from the capture (:func:`~meshmocap.trackers.driver.track_sequence`); a mesh
        capture (the crane) starts in its template's rest pose, its frame 0. Each row says
        which (``BenchRow.init``).
    show_progress : bool, optional
        Progress bars on stderr (default: when stderr is a terminal).
    log : callable, optional
        Called with one line per stage (e.g. ``print``).
    """
    t0 = time.perf_counter()
    check_choice("bench", "init", init, ["truth", "auto"])
    cs = capture_set(captures) if isinstance(captures, str) else None
    if methods is None:
        methods = [m for m in (cs.methods if cs and cs.methods else METHODS) if m in METHODS]
    methods = list(methods)
    if not methods:
        raise InputError(f"bench: no methods given; methods are {sorted(METHODS)}")
    for m in methods:
        check_choice("bench", "method", m, sorted(METHODS))
    method_options = dict(method_options or {})
    for m in method_options:
        check_choice("bench: method_options", "method", m, sorted(METHODS))
    if keep_fractions is None:
        keep_fractions = cs.keep_fractions if cs else DEFAULT_KEEP_FRACTIONS
    for f in keep_fractions:
        if not 0 < f <= 1:
            raise InputError(f"bench: keep fractions must lie in (0, 1], found {f}")
    names, frames = (cs.captures, cs.frames) if cs else (tuple(captures), None)
    if not names:
        raise InputError(f"bench: no captures given; sets are {list(CAPTURE_SETS)}")
    if max_frames is not None:
        frames = max_frames if frames is None else min(frames, max_frames)
    skipped, specs = [], []
    for name in dict.fromkeys(names):
        needs_data = name.split("+")[0] not in PROCEDURAL_MOTIONS
        if cs and data is None and needs_data:
            skipped.append((name, "needs --data"))
            continue
        specs.append(parse_capture(name, data=data, frames=frames))
    if tradeoff_capture is not None:
        check_choice("bench", "tradeoff_capture", tradeoff_capture, [s.name for s in specs])
    synthetic = [s for s in specs if s.kind == "synthetic"]
    sweep = keep_fractions and "patch" in methods and synthetic
    sweep_on = tradeoff_capture or (synthetic[0].name if sweep else None)
    out, work = Path(out), Path(work) if work is not None else Path(out) / "work"
    work.mkdir(parents=True, exist_ok=True)
    run = _Run(work, show_progress, log or (lambda _: None))
    tmpl = load_template(template)
    salt = {}  # method → what else makes its track (the manifold's digest)
    if any(m in MANIFOLD_METHODS for m in methods):
        run.log(f"pose manifold of {', '.join(m for m in methods if m in MANIFOLD_METHODS)}")
        manifold = bench_manifold(manifold, tmpl, work)
        gp_digest = hashlib.sha1(np.ascontiguousarray(manifold.X_).tobytes()).hexdigest()[:8]
        salt = {m: f"manifold {gp_digest}" for m in MANIFOLD_METHODS}

    def tracker(m: str, **extra: Any) -> Any:
        opts = {**method_options.get(m, {}), **extra}
        if m in MANIFOLD_METHODS:  # the GPLVM, checked; the driver sets the tracker up
            opts["manifold"] = manifold
        return make_tracker(m, **opts)

    rows: list[BenchRow] = []
    tradeoff: list[TradeoffPoint] = []
    for c, spec in enumerate(specs, start=1):
        run.log(f"[{c}/{len(specs)}] capture {spec.name} ({spec.folder})")
        capture = make_capture(spec, work, template=template, show_progress=show_progress)
        track_template, track_salt, why = tmpl, salt, ""
        if spec.kind == "synthetic":
            trackers = {m: tracker(m) for m in methods}
        else:  # skeleton-less (the crane): frame 0 rigged; cage methods get its own manifold
            run.log(f"  rigging frame 0 of {spec.name}")
            cached = work / "templates" / f"{capture.path.name}.npz"
            track_template = mesh_template(capture, cache=cached)
            trackers = {m: tracker(m) for m in methods if m not in MANIFOLD_METHODS}
            cage = [m for m in methods if m in MANIFOLD_METHODS]
            if cage:
                run.log(f"  pose manifold of frame 0's rig for {', '.join(cage)}")
                gp, why = mesh_manifold(capture, track_template, work)
                for m in cage if gp is not None else ():
                    trackers[m] = make_tracker(m, **method_options.get(m, {}), manifold=gp)
                gp_digest = "" if gp is None else hashlib.sha1(gp.X_.tobytes()).hexdigest()[:8]
                track_salt = {m: f"manifold {gp_digest}" for m in cage}
        for m in methods:
            if m not in trackers:  # a cage method without a quad rigging
                rows.append(not_applicable(spec.name, m, why))
                continue
            run.log(f"  {m}")
            rows.append(
                run.track_and_score(
                    spec.name,
                    m,
                    trackers[m],
                    track_template,
                    capture,
                    salt=track_salt.get(m, ""),
                    init=init,
                )
            )
        if spec.name == sweep_on:
            for f in keep_fractions:
                run.log(f"  patch, kept fraction {f:g} (Fig. 8)")
                t = tracker("patch", keep_fraction=f)
                r = run.track_and_score(
                    spec.name, f"patch[keep={f:g}]", t, tmpl, capture, init=init
                )
                tradeoff.append(TradeoffPoint(float(f), r))
    files = write_report(out, rows, tradeoff, sweep_on, skipped=skipped, template=template)
    settings = {
        "captures": [asdict(s) for s in specs],
        "skipped": skipped,
        "methods": methods,
        "method_options": method_options,
        "template": template,
        "init": init,
        "template_digest": template_digest(tmpl),
        "keep_fractions": list(keep_fractions),
        "tradeoff_capture": sweep_on,
        "tracks": {f"{r.capture}/{r.method}": r.track for r in [*rows, *(t.row for t in tradeoff)]},
        "manifolds": {k: v for k, v in salt.items()},
        "code_digest": code_digest(),
        "versions": _versions(),
        "machine": _machine(),
    }
    write_text_atomic(out / "settings.json", json.dumps(settings, indent=2, default=str) + "\n")
    files.append(out / "settings.json")
    return BenchResult(
        tuple(rows),
        tuple(tradeoff),
        sweep_on,
        tuple(files),
        tuple(skipped),
        tuple(run.tracked),
        tuple(run.evaluated),
        time.perf_counter() - t0,
    )
