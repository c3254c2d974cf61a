"""Estimate once per capture: the performer's body and the first pose, cached for the capture.

Estimating the body (:func:`~meshmocap.estimate.performer.subject.estimate_subject`) and searching
the first pose (:func:`~meshmocap.estimate.pose.first_pose.initial_pose`) are the slow steps before
tracking, and every track of a capture (each method of the demo, each item of a batch, a
restarted run) needs the same answers. They are stored in the user's cache folder, never in
the capture (reading a capture never changes it: it may be on a read-only mount or an
archive): ``$MESHMOCAP_CACHE/captures/<capture name>-<key of its resolved path>/``
(``MESHMOCAP_CACHE`` defaults to ``$XDG_CACHE_HOME/meshmocap``, else
``~/.cache/meshmocap``; ``off`` caches nothing), under a key made of everything they
depend on:

* the capture's content (:func:`capture_digest`: the bytes of the files the estimators
  read — cameras, silhouettes, and hulls or mesh files — not their dates);
* the options of the call;
* the code: the source of the estimator's modules (:func:`code_digest`), so a changed
  estimator never reuses an old answer;
* for the first pose, the template (its rest mesh, skeleton and weights).

A cache entry is written atomically and read back as it was written; anything unreadable
is recomputed.
"""

from __future__ import annotations

import hashlib
import importlib
import inspect
import json
import os
import re
from collections.abc import Callable
from pathlib import Path

import numpy as np

from meshmocap._atomic import atomic_open
from meshmocap._progress import phase
from meshmocap._version import __version__
from meshmocap.body.template import Template, load_template, save_template
from meshmocap.estimate.performer.subject import SubjectEstimate
from meshmocap.io.start import Start, start_json, start_of_json

__all__ = [
    "CACHE_ENV",
    "CACHE_FOLDER",
    "cache_folder",
    "cached_first_pose",
    "cached_subject",
    "capture_digest",
    "code_digest",
    "template_key",
    "user_cache",
]

#: The cache's folder inside a capture folder, where earlier versions wrote it: skipped when
#: a capture's files are digested (the cache now lives outside, :func:`cache_folder`).
CACHE_FOLDER = ".meshmocap"
#: Environment variable naming the user's meshmocap cache folder (``off``: no cache).
CACHE_ENV = "MESHMOCAP_CACHE"
#: Modules whose source keys the body estimate.
SUBJECT_CODE = (
    "meshmocap.estimate.performer.subject",
    "meshmocap.estimate.performer.point_subject",
    "meshmocap.estimate.performer.shape_fit",
    "meshmocap.body.autorig",
    "meshmocap.body.articulated",
    "meshmocap.body.shape_space",
    "meshmocap.models.shape_space",
    "meshmocap.geometry.decimate",
    "meshmocap.geometry.silhouette",
)
#: Modules whose source keys the first-pose search.
FIRST_POSE_CODE = (
    "meshmocap.estimate.pose.first_pose",
    "meshmocap.estimate.pose.library",
    "meshmocap.estimate.pose.start",
    "meshmocap.estimate.pose.pose_search",
    "meshmocap.estimate.pose.fit",
    "meshmocap.estimate.recovery.limbs",
    "meshmocap.estimate.recovery.observe",
    "meshmocap.estimate.recovery.quality",
    "meshmocap.io.start",
    "meshmocap.body.articulated",
    "meshmocap.body.pose_library",
    "meshmocap.geometry.silhouette",
    "meshmocap.geometry.distance_field",
)
#: Sub-folders of a capture folder that no estimator reads (``hulls/`` is read only when
#: there are no silhouettes: they determine the hulls).
_SKIP = {CACHE_FOLDER, "truth"}

#: Digests computed in this process, by capture folder and the files' sizes and dates.
_DIGESTS: dict[tuple, str] = {}


def _files(capture) -> list[Path]:
    """The files the estimators read of ``capture``, sorted."""
    root = Path(capture.path)
    if root.is_file():  # an archive of meshes
        return [root]
    if hasattr(capture, "seq"):  # a mesh sequence: its frame files, cameras and masks
        files = [Path(p) for p in capture.seq.paths if os.path.isfile(p)]
        if getattr(capture, "silhouette_dir", None) is not None:
            files += sorted(p for p in Path(capture.silhouette_dir).rglob("*") if p.is_file())
        return sorted(files)
    skip = set(_SKIP)
    if (root / "silhouettes").is_dir():
        skip.add("hulls")  # derived from the silhouettes (and rewritten by the demo)
    return sorted(
        p
        for p in root.rglob("*")
        if p.is_file()
        and p.relative_to(root).parts[0] not in skip
        and p.suffix != ".lock"
        and not p.name.startswith(".")  # a file being written (live), renamed away anytime
    )


def capture_digest(capture) -> str:
    """16 hex digits of SHA-256 over the names (relative to the capture) and bytes of the
    files the estimators read: equal for a copy of the capture, different when a frame,
    a mask or a camera changes."""
    root = Path(capture.path)
    files = _files(capture)
    stats = tuple((str(p), p.stat().st_size, p.stat().st_mtime_ns) for p in files)
    key = (str(root.resolve()), stats)
    if key in _DIGESTS:
        return _DIGESTS[key]
    h = hashlib.sha256(repr(getattr(capture, "scale", 1.0)).encode())
    if hasattr(capture, "seq"):  # archive members are named, not read
        h.update("\0".join(capture.seq.paths).encode())
    for p in files:
        name = p.relative_to(root).as_posix() if root.is_dir() and root in p.parents else p.name
        h.update(name.encode() + b"\0")
        with open(p, "rb") as f:
            for chunk in iter(lambda: f.read(1 << 20), b""):
                h.update(chunk)
    digest = h.hexdigest()[:16]
    _DIGESTS[key] = digest
    return digest


def code_digest(modules: tuple[str, ...]) -> str:
    """16 hex digits of SHA-256 over the source of ``modules`` and the package version."""
    h = hashlib.sha256(__version__.encode())
    for name in modules:
        h.update(inspect.getsource(importlib.import_module(name)).encode())
    return h.hexdigest()[:16]


def template_key(template: Template) -> str:
    """16 hex digits of SHA-256 over a template's rest mesh, skeleton and weights."""
    h = hashlib.sha256()
    sk = template.skeleton
    w = template.weights.tocsr()
    for a in (template.V, template.F, sk.rest_positions, sk.parents, w.data, w.indices, w.indptr):
        h.update(np.ascontiguousarray(a).tobytes())
    h.update("\0".join(sk.names).encode())
    return h.hexdigest()[:16]


def user_cache() -> Path | None:
    """The user's meshmocap cache folder: ``$MESHMOCAP_CACHE``, else
    ``$XDG_CACHE_HOME/meshmocap``, else ``~/.cache/meshmocap``; None when
    ``MESHMOCAP_CACHE`` is ``off`` (or empty): nothing is cached."""
    env = os.environ.get(CACHE_ENV)
    if env is not None:
        return None if env.strip().lower() in ("off", "") else Path(env)
    xdg = os.environ.get("XDG_CACHE_HOME")
    return (Path(xdg) if xdg else Path.home() / ".cache") / "meshmocap"


def cache_folder(capture) -> Path | None:
    """Where ``capture``'s cache lives, outside the capture:
    ``<user cache>/captures/<name>-<key>``, the key 16 hex digits of SHA-256 over the
    capture's resolved path (its entries are keyed by its content, :func:`capture_digest`);
    None when caching is off (:func:`user_cache`)."""
    base = user_cache()
    if base is None:
        return None
    root = Path(capture.path).resolve()
    key = hashlib.sha256(os.fsencode(root)).hexdigest()[:16]
    name = re.sub(r"[^\w.-]", "_", root.name)[:40] or "capture"
    return base / "captures" / f"{name}-{key}"


def _key(*parts: object) -> str:
    return hashlib.sha256(json.dumps(parts, sort_keys=True, default=str).encode()).hexdigest()[:16]


def cached_subject(
    capture,
    *,
    estimate: Callable[..., SubjectEstimate] | None = None,
    refresh: bool = False,
    **options,
) -> SubjectEstimate:
    """The performer's body of ``capture`` (``estimate(capture, **options)``, by default
    :func:`~meshmocap.estimate.performer.subject.estimate_subject`), estimated once and then read
    from the capture's cache; ``refresh`` estimates again (and replaces the entry)."""
    if estimate is None:
        from meshmocap.estimate.performer.subject import estimate_subject as estimate
    folder = cache_folder(capture)
    if folder is None:  # caching is off
        with phase("estimating the performer's body"):
            return estimate(capture, **options)
    key = _key("subject", capture_digest(capture), options, code_digest(SUBJECT_CODE))
    body, fit = folder / f"subject-{key}.npz", folder / f"subject-{key}-fit.npz"
    if not refresh and body.is_file() and fit.is_file():
        try:
            with np.load(fit, allow_pickle=False) as z:
                meta = json.loads(str(z["meta"]))
                return SubjectEstimate(
                    load_template(body),
                    meta["kind"],
                    tuple(meta["frames"]),
                    z["z"] if "z" in z.files else None,
                    z["R"],
                    z["root"],
                    float(meta["rms"]),
                    float(meta["seconds"]),
                    meta["notes"],
                )
        except (OSError, ValueError, KeyError):  # damaged: estimate again
            pass
    with phase("estimating the performer's body (once per capture)"):
        est = estimate(capture, **options)
    try:
        folder.mkdir(parents=True, exist_ok=True)
        save_template(body, est.template)
        meta = {
            "kind": est.kind,
            "frames": [int(i) for i in est.frames],
            "rms": float(est.rms),
            "seconds": float(est.seconds),
            "notes": est.notes,
        }
        arrays = {"R": est.R, "root": est.root, "meta": np.array(json.dumps(meta, default=float))}
        if est.z is not None:
            arrays["z"] = est.z
        with atomic_open(fit) as f:
            np.savez(f, **arrays)
    except OSError:  # a read-only place: the estimate is still returned
        pass
    return est


def cached_first_pose(
    capture,
    template: Template,
    index: int,
    find: Callable[[], Start],
    *,
    options: dict | None = None,
) -> Start:
    """The start (:class:`~meshmocap.io.start.Start`: the first pose and how it was found)
    of frame ``index`` of ``capture`` for ``template`` (searched with ``options``):
    ``find()`` once, then read from the capture's cache (the pose bit for bit)."""
    folder = cache_folder(capture)
    if folder is None:  # caching is off
        with phase("finding the first pose"):
            return find()
    key = _key(
        "first_pose",
        capture_digest(capture),
        int(index),
        template_key(template),
        options or {},
        code_digest(FIRST_POSE_CODE),
    )
    path = folder / f"first_pose-{key}.npz"
    if path.is_file():
        try:
            with np.load(path, allow_pickle=False) as z:
                return start_of_json(json.loads(str(z["start"])), str(path))
        except (OSError, ValueError, KeyError):  # damaged (FormatError is a ValueError)
            pass
    with phase("finding the first pose (once per capture and template)"):
        start = find()
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        with atomic_open(path) as f:
            np.savez(f, start=np.array(json.dumps(start_json(start))))
    except OSError:
        pass
    return start
