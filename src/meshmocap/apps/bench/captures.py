"""The captures of ``meshmocap bench``: named sets, capture names ``BASE[+VARIANT...]``
resolved against the data folder, and the captures made (or resumed) in the work folder.
See :mod:`meshmocap.apps.bench.run` for the protocol."""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal, get_args

import numpy as np

from meshmocap._validate import check_choice
from meshmocap.body.procedural import PROCEDURAL_MOTIONS
from meshmocap.body.template import Template, bundled_templates, load_template
from meshmocap.errors import InputError, MeshmocapFileNotFoundError
from meshmocap.io.capture import Capture
from meshmocap.studio.degrade import Degradation
from meshmocap.studio.rigs import RigName
from meshmocap.studio.synth import SynthSpec, synthesize, synthesize_from_meshes

__all__ = [
    "CAPTURE_SETS",
    "CLIP_FPS",
    "CMU_CLIPS",
    "CRANE",
    "DEFAULT_KEEP_FRACTIONS",
    "DEGRADED",
    "BenchCapture",
    "CaptureSet",
    "capture_set",
    "make_capture",
    "mesh_template",
    "parse_capture",
]

SetName = Literal["quick", "standard", "full"]

#: CMU clip → (file in DATA/mocap/cmu, first frame, last frame) at 60 fps. The Daz BVH
#: 09_01 starts with a T-pose and blends out of it over its first 8 frames at 120 fps.
CMU_CLIPS: dict[str, tuple[str, int | None, int | None]] = {
    "05_01": ("05_01.amc", None, None),
    "09_01": ("09_01.bvh", 4, None),
    "01_01": ("01_01.amc", None, 600),
    "49_18": ("49_18.amc", None, None),  # balance on one leg, arms out: 551 frames
    "16_01": ("16_01.bvh", None, None),  # a jump in place: 161 frames (at its true 120 fps)
}
#: CMU clips whose header's frame rate is wrong → the true one (see the data README).
CLIP_FPS: dict[str, float] = {"16_01": 120.0}
#: The MIT crane sequence in DATA (175 frames, fixed connectivity, Y up).
CRANE = "meshes/crane/crane_mesh_0000-0174.tar.gz"
#: Silhouette degradations of the ``degraded`` variant (pixels).
DEGRADED = Degradation(jitter=1.5, holes=2, blobs=2)

#: Kept fractions of the patch tracker's classifier swept for Fig. 8.
DEFAULT_KEEP_FRACTIONS = (0.05, 0.1, 0.25, 0.5, 1.0)


@dataclass(frozen=True)
class CaptureSet:
    """A named set of captures and what runs on it by default.

    Attributes
    ----------
    captures : tuple of capture names (module docstring)
    frames : int or None, frames per capture (None: whole clips)
    methods : tuple of method names, or None for every registered method; names not
        registered are left out
    keep_fractions : tuple of float, the Fig. 8 sweep
    """

    captures: tuple[str, ...]
    frames: int | None
    methods: tuple[str, ...] | None = None
    keep_fractions: tuple[float, ...] = DEFAULT_KEEP_FRACTIONS


_STANDARD = (
    "walk",
    "jog",
    "squat",
    "walk+ring8",
    "walk+degraded",
    "walk+heavy_male",
    "05_01",
    "09_01",
    "crane",
)
_FULL = (
    *PROCEDURAL_MOTIONS,
    "walk+ring8",
    "walk+degraded",
    "walk+heavy_male",
    "walk+small_female",
    "jog+ring8+degraded",
    *CMU_CLIPS,
    "05_01+ring8",
    "05_01+degraded",
    "09_01+heavy_male",
    "crane",
)
#: The named sets. ``quick`` runs in minutes: each paper's method and the baselines (the
#: cage ablations are in the other sets) on 40 frames of a walk and a jog.
CAPTURE_SETS: dict[str, CaptureSet] = {
    "quick": CaptureSet(
        ("walk", "jog"),
        40,
        methods=("patch", "patch_noclf", "articulated_icp", "cage"),
        keep_fractions=(0.1, 0.25, 0.5, 1.0),  # 1.0: the patch tracker's default, reused
    ),
    "standard": CaptureSet(_STANDARD, 120),
    "full": CaptureSet(_FULL, None),
}


@dataclass(frozen=True)
class BenchCapture:
    """One capture of a benchmark, before it is made.

    Attributes
    ----------
    name : str, e.g. ``"walk+ring8"``
    kind : ``"synthetic"`` (a template plays a motion) or ``"meshes"`` (a real mesh
        sequence, skeleton-less, truth = its vertices)
    source : str, procedural motion name, absolute motion file, or mesh archive
    rig : str; subject : str or None (default: the template); degraded : bool
    start, stop : int or None, frame range at 60 fps (30 fps for the crane)
    source_fps : float or None, the motion file's true frame rate (:data:`CLIP_FPS`)
    """

    name: str
    kind: Literal["synthetic", "meshes"]
    source: str
    rig: str = "humaneva4"
    subject: str | None = None
    degraded: bool = False
    start: int | None = None
    stop: int | None = None
    source_fps: float | None = None

    @property
    def folder(self) -> str:
        """Folder name in the work folder (name and frame count)."""
        n = "all" if self.stop is None else f"{self.stop - (self.start or 0)}f"
        return f"{self.name}-{n}"


def capture_set(name: str) -> CaptureSet:
    """Return the set ``name`` (:data:`CAPTURE_SETS`)."""
    check_choice("bench", "set", name, list(CAPTURE_SETS))
    return CAPTURE_SETS[name]


def parse_capture(
    name: str, *, data: str | os.PathLike | None = None, frames: int | None = None
) -> BenchCapture:
    """Resolve a capture name ``BASE[+VARIANT...]`` (see the module docstring).

    Parameters
    ----------
    data : path, optional
        The shared data folder (``mocap/cmu``, ``meshes/crane``); needed by CMU clips and
        the crane.
    frames : int, optional
        Frames kept from the clip's first frame (default: all).
    """
    base, *variants = name.split("+")
    bases = [*PROCEDURAL_MOTIONS, *CMU_CLIPS, "crane"]
    check_choice("bench", "capture", base, bases)
    rigs, subjects = list(get_args(RigName)), [t for t in bundled_templates() if t != "neutral_5k"]
    opts: dict[str, Any] = {}
    for v in variants:
        check_choice(f"bench: capture {name!r}", "variant", v, [*rigs, "degraded", *subjects])
        key = "rig" if v in rigs else "degraded" if v == "degraded" else "subject"
        if key in opts:
            raise InputError(f"bench: capture {name!r} names two {key} variants")
        opts[key] = True if key == "degraded" else v
    if frames is not None and frames < 1:
        raise InputError(f"bench: frames must be ≥ 1, found {frames}")
    if base in PROCEDURAL_MOTIONS:
        return BenchCapture(name, "synthetic", base, stop=frames, **opts)
    if data is None:
        raise InputError(f"bench: capture {name!r} needs the data folder (--data DIR)")
    root = Path(data).resolve()
    if base == "crane":
        if "subject" in opts:
            raise InputError(f"bench: capture {name!r}: the crane has no subject variant")
        path = root / CRANE
        stop = min(175, frames or 175)
        kind, start = "meshes", None
        opts.setdefault("rig", "ring8")
    else:
        file, start, last = CMU_CLIPS[base]
        path = root / "mocap" / "cmu" / file
        limits = [x for x in (last, frames + (start or 0) if frames else None) if x]
        stop = min(limits) if limits else None
        kind = "synthetic"
    if not path.is_file():
        raise MeshmocapFileNotFoundError(f"bench: capture {name!r} needs {path}")
    fix = {"source_fps": CLIP_FPS[base]} if base in CLIP_FPS else {}
    return BenchCapture(name, kind, str(path), start=start, stop=stop, **opts, **fix)


def make_capture(
    spec: BenchCapture,
    work: str | os.PathLike,
    *,
    template: str = "neutral_5k",
    show_progress: bool | None = None,
) -> Capture:
    """Make (or resume) the capture ``spec`` in ``work/captures/`` and return it (folder
    :attr:`BenchCapture.folder`, plus ``@<template>`` for a synthetic capture made for
    another template than ``neutral_5k``)."""
    other = spec.kind == "synthetic" and template != "neutral_5k"
    out = Path(work) / "captures" / (f"{spec.folder}@{template}" if other else spec.folder)
    deg = DEGRADED if spec.degraded else Degradation()
    if spec.kind == "meshes":
        return synthesize_from_meshes(
            spec.source,
            out,
            rig=spec.rig,
            frames=range(spec.start or 0, spec.stop or 0),
            up="y",
            degradation=deg,
            show_progress=show_progress,
        )
    synth = SynthSpec(
        motion=spec.source,
        template=template,
        subject=spec.subject,
        rig=spec.rig,
        fps=60.0,
        start=spec.start,
        stop=spec.stop,
        degradation=deg,
        source_fps=spec.source_fps,
    )
    return synthesize(out, synth, show_progress=show_progress)


def mesh_template(capture: Capture, *, cache: str | os.PathLike | None = None) -> Template:
    """The tracking template of a skeleton-less capture (the crane): frame 0's true mesh
    rigged by :func:`~meshmocap.body.autorig.rig_mesh` (reference ``neutral``), so its rest
    pose is frame 0 and every tracker starts there (identity rotations at the rest root).
    Named after its sequence and frame (``crane_frame0``); read from / written to ``cache``
    (a ``.npz``) when given, and then returned as read back from it, as every later run
    reads it (the bone tails round to other ulps through the file)."""
    from meshmocap.body.autorig import rig_mesh
    from meshmocap.body.template import save_template
    from meshmocap.io.meshes import MeshSequence

    if cache is not None and Path(cache).is_file():
        return load_template(cache)
    spec = capture.meta["spec"]
    F = MeshSequence(spec["source"], frames=[capture.indices[0]], up=spec["up"])[0].F
    V = capture[0].truth.vertices.astype(np.float64)
    sequence = Path(spec["source"]).name.split(".")[0].split("_mesh")[0]  # crane_mesh_… → crane
    t = rig_mesh(V, F, name=f"{sequence}_frame{capture.indices[0]}")
    if cache is not None:
        Path(cache).parent.mkdir(parents=True, exist_ok=True)
        return load_template(save_template(cache, t))
    return t
