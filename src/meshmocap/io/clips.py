"""One entry point for motion sources: a BVH file, an AMC file (with its ASF), or the name
of a procedural motion."""

from __future__ import annotations

import os
import re
from pathlib import Path

import numpy as np

from meshmocap.body.motion import Motion, resample
from meshmocap.body.procedural import PROCEDURAL_MOTIONS, procedural_motion
from meshmocap.body.retarget import retarget
from meshmocap.body.skeleton import Skeleton
from meshmocap.body.template import Template
from meshmocap.errors import InputError, MeshmocapFileNotFoundError


def find_asf(amc: Path) -> Path:
    """Return the ASF skeleton of a CMU AMC file: ``SS.asf`` beside ``SS_TT.amc``."""
    m = re.match(r"(\d+)_\d+", amc.stem)
    candidates = [amc.with_name(f"{m.group(1)}.asf")] if m else []
    candidates += sorted(amc.parent.glob("*.asf"))
    for c in candidates:
        if c.is_file():
            return c
    raise MeshmocapFileNotFoundError(f"{amc}: no ASF skeleton found beside it; pass asf=PATH")


def load_clip(
    source: str | os.PathLike,
    *,
    asf: str | os.PathLike | None = None,
    fps: float | None = None,
    source_fps: float | None = None,
) -> Motion:
    """Load a motion in metres, world frame Z up.

    Parameters
    ----------
    source : str or path
        A ``.bvh`` file, an ``.amc`` file, or a procedural motion name
        (:data:`~meshmocap.body.procedural.PROCEDURAL_MOTIONS`, posed on the bundled
        ``neutral`` template's skeleton).
    asf : path, optional
        Skeleton of an AMC file (default: ``SS.asf`` in the AMC's folder).
    fps : float, optional
        Resample to this frame rate.
    source_fps : float, optional
        The file's true frame rate, where its header is wrong (CMU ``16_01.bvh`` says 30
        fps; its data is 120 fps): replaces the header's before resampling.
    """
    from meshmocap.body.template import load_template
    from meshmocap.io.asf_amc import read_amc, read_asf
    from meshmocap.io.bvh import read_bvh

    name = os.fspath(source)
    if name in PROCEDURAL_MOTIONS:
        motion = procedural_motion(name, load_template("neutral"), fps=fps or 60.0)  # type: ignore[arg-type]
    else:
        path = Path(name)
        suffix = path.suffix.lower()
        if suffix not in (".bvh", ".amc"):
            raise InputError(
                "clip: expected a .bvh or .amc file or one of "
                f"{list(PROCEDURAL_MOTIONS)}, found {name!r}"
            )
        if not path.is_file():
            raise MeshmocapFileNotFoundError(f"clip: {path} does not exist")
        if suffix == ".bvh":
            motion = read_bvh(path)
        else:
            motion = read_amc(path, read_asf(Path(asf) if asf else find_asf(path)))
        if source_fps is not None:
            if not (np.isfinite(source_fps) and source_fps > 0):
                raise InputError(f"clip: source_fps must be a positive number, found {source_fps}")
            motion = Motion(motion.skeleton, motion.rotations, motion.root_positions, source_fps)
    return resample(motion, fps) if fps else motion


def clip_on(target: Template | Skeleton, source: str | os.PathLike, **kwargs) -> Motion:
    """Load ``source`` (see :func:`load_clip`) and retarget it onto ``target``.

    Procedural motions are generated directly on ``target`` (no retargeting needed).
    """
    name = os.fspath(source)
    if name in PROCEDURAL_MOTIONS:
        fps = kwargs.get("fps") or 60.0
        return procedural_motion(name, target, fps=fps)  # type: ignore[arg-type]
    return retarget(load_clip(source, **kwargs), target)
