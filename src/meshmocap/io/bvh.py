"""BVH (Biovision Hierarchy) motion files: read into a :class:`Motion`, write one back.

Conventions of the format, as read and written here:

* Rotation channels are intrinsic Euler angles in degrees, composed in the order the
  channels are listed: ``Zrotation Xrotation Yrotation`` gives ``R = Rz @ Rx @ Ry``
  (:func:`~meshmocap.geometry.rotations.euler_matrix`). Any order, and any number of
  rotation channels per joint, is accepted.
* Rest frames are world-aligned: ``P[j] = P[parent] + G[parent] @ OFFSET[j]``. The root's
  world position is its ``OFFSET`` plus its position channels (missing ones count as 0).
* Position channels of non-root joints (rare) are added to the joint's ``OFFSET``. A
  :class:`~meshmocap.body.skeleton.Skeleton` has fixed offsets, so they are supported only
  when constant over the file (they are then folded into the offset); animated ones raise
  :class:`~meshmocap.errors.FormatError`.
* ``End Site`` blocks become the parent joint's ``end_offsets`` (the first one if a joint has
  several, zeros if it has none); they are not joints.
* Files are Y up (``up="y"``, the usual case) or Z up (``up="z"``) in a length unit given by
  ``unit``. :func:`read_bvh` returns metres, Z up: (x, y, z) → (x, −z, y) for Y-up files
  (:data:`~meshmocap.body.motion.Y_UP_TO_Z_UP`); :func:`write_bvh` converts back.
* ``Frame Time`` values that are within 1e-4 (relative) of the inverse of a whole frame rate
  (``.0083333`` → 120 fps) give that whole frame rate.

References
----------
- M. Meredith, S. Maddock, *Motion capture file formats explained*, Department of
  Computer Science, University of Sheffield, 2001.
"""

from __future__ import annotations

import math
import os
import re
import warnings
from dataclasses import dataclass, field
from pathlib import Path
from typing import Literal, get_args

import numpy as np

from meshmocap._atomic import write_text_atomic
from meshmocap._tolerances import ROUNDING_SLACK
from meshmocap._validate import check_choice
from meshmocap.body.motion import Y_UP_TO_Z_UP, Motion
from meshmocap.body.skeleton import Skeleton
from meshmocap.errors import FormatError, InputError, MeshmocapFileNotFoundError, where
from meshmocap.geometry.rotations import euler_matrix, matrix_to_euler
from meshmocap.io._text import (
    FrameSelection,
    frame_index,
    parse_floats,
    read_bytes,
    scan_tokens,
)

#: Length units of mocap files.
LengthUnit = Literal["m", "cm", "mm", "inch", "cmu"]
#: ``unit`` option of :func:`read_bvh`: a :data:`LengthUnit` or ``"auto"``.
BvhUnit = Literal["auto", "m", "cm", "mm", "inch", "cmu"]
#: Up axis of a BVH file.
UpAxis = Literal["y", "z"]
#: Euler orders :func:`write_bvh` can write.
EulerOrder = Literal["XYZ", "XZY", "YXZ", "YZX", "ZXY", "ZYX"]
#: A frame selection: a slice (``slice(0, None, 4)``) or integer frame indices.

#: Metres per unit. ``cmu`` = 1/0.45 inch, the unit of CMU ASF files (``:units length 0.45``)
#: and of the CMU BVH conversions (MotionBuilder-friendly and raw amc2bvh).
UNIT_METRES: dict[str, float] = {
    "m": 1.0,
    "cm": 0.01,
    "mm": 0.001,
    "inch": 0.0254,
    "cmu": 0.0254 / 0.45,
}
#: Height (metres) of the rest skeleton that ``unit="auto"`` aims for.
AUTO_UNIT_HEIGHT = 1.7

_CHANNELS = {
    f"{a}{kind}": (kind[0], i) for kind in ("position", "rotation") for i, a in enumerate("xyz")
}
_CHANNEL_NAMES = "Xposition, Yposition, Zposition, Xrotation, Yrotation, Zrotation"


def _up_rotation(up: str) -> np.ndarray:
    return Y_UP_TO_Z_UP if up == "y" else np.eye(3)


# ----------------------------------------------------------------------------- hierarchy
@dataclass
class _Joint:
    name: str
    parent: int
    line: int
    offset: np.ndarray | None = None
    end: np.ndarray | None = None
    channels: list[tuple[str, int]] = field(default_factory=list)  # (kind "p"/"r", axis 0..2)
    channel_line: int = 0
    first_channel: int = 0


def _parse_hierarchy(text: str, path: object) -> list[_Joint]:
    """Parse the HIERARCHY section (``text`` ends before MOTION) into joints in file order."""
    toks = [(t, n) for n, line in enumerate(text.split("\n"), 1) for t in line.split()]
    if not toks or toks[0][0].upper() != "HIERARCHY":
        found = f"found {toks[0][0]!r}" if toks else "found nothing before MOTION"
        raise FormatError(
            f"{where(path, toks[0][1] if toks else None)}: expected HIERARCHY, {found}"
        )
    joints: list[_Joint] = []
    names: dict[str, int] = {}
    stack: list[tuple[int, bool, int]] = []  # (joint, inside an End Site, line of '{')
    i, n_tok = 1, len(toks)

    def fail(line: int, msg: str) -> FormatError:
        return FormatError(f"{where(path, line)}: {msg}")

    def numbers(k: int, line: int, what: str) -> np.ndarray:
        vals = [t for t, ln in toks[i : i + k] if ln == line]
        try:
            out = np.array([float(v) for v in vals])
        except ValueError:
            out = np.zeros(0)
        if out.shape != (k,) or not np.all(np.isfinite(out)):
            raise fail(line, f"{what} expects {k} numbers, found {' '.join(vals)!r}")
        return out

    def open_brace(line: int, what: str) -> None:
        nonlocal i
        if i >= n_tok or toks[i][0] != "{":
            found = repr(toks[i][0]) if i < n_tok else "the end of the hierarchy"
            at = toks[i][1] if i < n_tok else line
            raise fail(at, f"expected '{{' after {what}, found {found}")
        i += 1

    while i < n_tok:
        tok, line = toks[i]
        key = tok.upper()
        i += 1
        inside_end = bool(stack) and stack[-1][1]
        if key in ("ROOT", "JOINT"):
            if key == "ROOT" and joints:
                raise fail(line, "several ROOT hierarchies are not supported")
            if key == "JOINT" and (not stack or inside_end):
                raise fail(line, "JOINT outside a ROOT or JOINT block (unbalanced braces?)")
            parts = []
            while i < n_tok and toks[i][1] == line and toks[i][0] != "{":
                parts.append(toks[i][0])
                i += 1
            if not parts:
                raise fail(line, f"{tok} without a joint name")
            name = " ".join(parts)
            if name in names:
                raise fail(line, f"duplicate joint name {name!r} (line {joints[names[name]].line})")
            names[name] = len(joints)
            joints.append(_Joint(name, stack[-1][0] if stack else -1, line))
            brace_line = toks[i][1] if i < n_tok else line
            open_brace(line, f"{tok} {name}")
            stack.append((len(joints) - 1, False, brace_line))
        elif key == "END":
            if not stack or inside_end:
                raise fail(line, "End Site outside a joint block")
            if i < n_tok and toks[i][0].upper() == "SITE":
                i += 1
            brace_line = toks[i][1] if i < n_tok else line
            open_brace(line, "End Site")
            stack.append((stack[-1][0], True, brace_line))
        elif key == "OFFSET":
            if not stack:
                raise fail(line, "OFFSET outside a joint block")
            value = numbers(3, line, "OFFSET")
            i += 3
            joint = joints[stack[-1][0]]
            if not inside_end:
                joint.offset = value
            elif joint.end is None:
                joint.end = value
        elif key == "CHANNELS":
            if not stack or inside_end:
                raise fail(line, "CHANNELS outside a ROOT or JOINT block")
            joint = joints[stack[-1][0]]
            try:
                count = int(toks[i][0]) if i < n_tok else -1
            except ValueError:
                count = -1
            if count < 0:
                raise fail(line, "CHANNELS expects a channel count")
            names_ = [t for t, _ in toks[i + 1 : i + 1 + count]]
            if len(names_) < count:
                raise fail(line, f"CHANNELS declares {count} channels, found {len(names_)}")
            for t, ln in toks[i + 1 : i + 1 + count]:
                if t.lower() not in _CHANNELS:
                    raise fail(ln, f"unknown channel {t!r} (expected one of {_CHANNEL_NAMES})")
            joint.channels = [_CHANNELS[t.lower()] for t in names_]
            pos_axes = [a for k, a in joint.channels if k == "p"]
            if len(set(pos_axes)) != len(pos_axes):
                raise fail(line, f"joint {joint.name!r} repeats a position channel")
            joint.channel_line = line
            i += 1 + count
        elif tok == "}":
            if not stack:
                raise fail(line, "unbalanced braces: unexpected '}'")
            j, was_end, _ = stack.pop()
            if not was_end and joints[j].offset is None:
                raise fail(joints[j].line, f"joint {joints[j].name!r} has no OFFSET")
        else:
            raise fail(line, f"unexpected {tok!r} in HIERARCHY")
    if stack:
        j, _, brace_line = stack[-1]
        raise fail(brace_line, f"unbalanced braces: '{{' of {joints[j].name!r} is never closed")
    if not joints:
        raise fail(toks[0][1], "HIERARCHY has no ROOT")
    first = 0
    for joint in joints:
        joint.first_channel = first
        first += len(joint.channels)
    return joints


# ----------------------------------------------------------------------------- motion block
_FRAMES_RE = re.compile(rb"[ \t]*MOTION[^\n]*\n\s*Frames\s*:?[ \t]*([^\s]*)[^\n]*(?:\n|\Z)", re.I)
_TIME_RE = re.compile(rb"\s*Frame\s+Time\s*:?[ \t]*([^\s]*)[^\n]*(?:\n|\Z)", re.I)


def _parse_motion(
    block: bytes, line0: int, n_channels: int, path: object
) -> tuple[np.ndarray, float]:
    """Parse the MOTION block (starting at the MOTION line, file line ``line0``).

    Returns the channel values (T, n_channels) and the frame rate.
    """
    m = _FRAMES_RE.match(block)
    if m is None:
        raise FormatError(f"{where(path, line0 + 1)}: expected 'Frames: <count>' after MOTION")
    frames_line = line0 + block.count(b"\n", 0, m.start(1))
    try:
        n_frames = int(m.group(1))
    except ValueError:
        n_frames = -1
    if n_frames < 1:
        found = m.group(1).decode("utf-8", errors="replace")
        raise FormatError(
            f"{where(path, frames_line)}: expected a positive frame count, found {found!r}"
        )
    t = _TIME_RE.match(block, m.end())
    if t is None:
        line = line0 + block.count(b"\n", 0, m.end())
        raise FormatError(f"{where(path, line)}: expected 'Frame Time: <seconds>' after Frames")
    time_line = line0 + block.count(b"\n", 0, t.start(1))
    try:
        dt = float(t.group(1))
    except ValueError:
        dt = math.nan
    if not (math.isfinite(dt) and dt > 0):
        found = t.group(1).decode("utf-8", errors="replace")
        raise FormatError(
            f"{where(path, time_line)}: expected a positive Frame Time, found {found!r}"
        )
    fps = 1.0 / dt
    if round(fps) >= 1 and abs(fps - round(fps)) <= 1e-4 * fps:
        fps = float(round(fps))

    data = block[t.end() :]
    data_line = line0 + block.count(b"\n", 0, t.end())  # file line of data's first line
    if n_channels == 0:
        return np.zeros((n_frames, 0)), fps
    tok_line = scan_tokens(data)[1]
    counts = np.bincount(tok_line) if tok_line.size else np.zeros(0, dtype=np.int64)
    filled = np.flatnonzero(counts)
    bad = filled[counts[filled] != n_channels]
    if bad.size:
        raise FormatError(
            f"{where(path, data_line + int(bad[0]))}: expected {n_channels} values per frame "
            f"(channel count), found {int(counts[bad[0]])}"
        )
    if filled.size != n_frames:
        state = "truncated file? " if filled.size < n_frames else ""
        raise FormatError(
            f"{where(path, frames_line)}: {state}header declares {n_frames} frames, "
            f"found {filled.size} frame lines"
        )
    values = parse_floats(data.split(), tok_line + data_line, path)
    return values.reshape(n_frames, n_channels), fps


# ----------------------------------------------------------------------------- read
def read_bvh(
    path: str | os.PathLike[str],
    *,
    unit: BvhUnit = "auto",
    up: UpAxis = "y",
    frames: FrameSelection = None,
) -> Motion:
    """Read a BVH file into a :class:`Motion` in metres, Z up.

    Parameters
    ----------
    path : str or path-like
        The ``.bvh`` file (any line endings, tabs or spaces).
    unit : {"auto", "m", "cm", "mm", "inch", "cmu"}
        Length unit of the file. ``"auto"`` picks the unit that makes the rest skeleton's
        height (range of the rest joint and End Site positions along the up axis) closest to
        :data:`AUTO_UNIT_HEIGHT` (1.7 m) in log ratio. ``"cmu"`` is 1/0.45 inch.
    up : {"y", "z"}
        Up axis of the file.
    frames : slice or (k,) int, optional
        Frames to keep (all by default); a slice step divides the frame rate.

    Returns
    -------
    Motion
        ``J`` joints in file order (End Sites are ``end_offsets``, not joints);
        rotations (T, J, 3, 3) local; root_positions (T, 3) float64, metres, world frame
        (Z up); fps from ``Frame Time``.

    Raises
    ------
    MeshmocapFileNotFoundError
        ``path`` does not exist.
    FormatError
        The file does not follow the format (one line naming the file and line).
    InputError
        An invalid option.
    """
    check_choice("read_bvh", "unit", unit, get_args(BvhUnit))
    check_choice("read_bvh", "up", up, get_args(UpAxis))
    data = read_bytes(path)
    if not data.strip():
        raise FormatError(f"{path}: empty file, expected a BVH HIERARCHY")
    m = re.search(rb"^[ \t]*MOTION\b", data, re.M)
    header = data[: m.start()] if m else data
    joints = _parse_hierarchy(header.decode("utf-8", errors="replace"), path)
    if m is None:
        raise FormatError(f"{path}: no MOTION section after the HIERARCHY (truncated file?)")
    n_channels = sum(len(j.channels) for j in joints)
    values, fps = _parse_motion(data[m.start() :], header.count(b"\n") + 1, n_channels, path)

    J = len(joints)
    offsets = np.stack([j.offset for j in joints])
    ends = np.stack([j.end if j.end is not None else np.zeros(3) for j in joints])
    for j, jt in enumerate(joints[1:], start=1):  # constant non-root position channels fold in
        for c, (kind, axis) in enumerate(jt.channels):
            if kind == "p":
                v = values[:, jt.first_channel + c]
                if np.ptp(v) > ROUNDING_SLACK * max(1.0, float(np.abs(v).max())):
                    raise FormatError(
                        f"{where(path, jt.channel_line)}: joint {jt.name!r} has animated position "
                        "channels; only the root may translate (unsupported)"
                    )
                offsets[j, axis] += v[0]
    skeleton = Skeleton(tuple(j.name for j in joints), [j.parent for j in joints], offsets, ends)

    idx, step = frame_index(values.shape[0], frames, "read_bvh")
    values = values[idx]
    T = values.shape[0]
    # Build rotations directly in the output frame: C R(a, axis) Cᵀ = R(±a, C axis).
    C = _up_rotation(up)
    target = np.abs(C).argmax(axis=0)
    sign = C[target, np.arange(3)]
    R = np.empty((T, J, 3, 3))
    R[...] = np.eye(3)
    groups: dict[str, tuple[list[int], list[list[int]]]] = {}
    for j, jt in enumerate(joints):
        rot = [(jt.first_channel + c, a) for c, (kind, a) in enumerate(jt.channels) if kind == "r"]
        if rot:
            g = groups.setdefault("".join("XYZ"[a] for _, a in rot), ([], []))
            g[0].append(j)
            g[1].append([c for c, _ in rot])
    for order, (js, cols) in groups.items():
        axes = ["XYZ".index(a) for a in order]
        angles = np.deg2rad(values[:, np.array(cols)]) * sign[axes]
        R[:, js] = euler_matrix(angles, "".join("XYZ"[target[a]] for a in axes))
    root = np.broadcast_to(offsets[0], (T, 3)).copy()
    for c, (kind, axis) in enumerate(joints[0].channels):
        if kind == "p":
            root[:, axis] += values[:, c]

    if unit == "auto":
        up_axis = 1 if up == "y" else 2
        P = skeleton.rest_positions
        heights = np.concatenate([P[:, up_axis], P[:, up_axis] + ends[:, up_axis]])
        height = float(np.ptp(heights))
        if not height > 0:
            raise FormatError(f"{path}: cannot detect the unit of a flat rest skeleton; pass unit=")
        unit = min(
            UNIT_METRES, key=lambda u: abs(math.log(height * UNIT_METRES[u] / AUTO_UNIT_HEIGHT))
        )
    s = UNIT_METRES[unit]
    return Motion(skeleton.transformed(C).scaled(s), R, s * root @ C.T, fps / step)


# ----------------------------------------------------------------------------- write
def _check_name(name: str) -> None:
    if not name or any(ch.isspace() or ch in "{}" for ch in name):
        raise InputError(
            f"write_bvh: joint names must be non-empty without spaces or braces, found {name!r}"
        )


def write_bvh(
    path: str | os.PathLike[str],
    motion: Motion,
    *,
    order: EulerOrder = "ZXY",
    unit: LengthUnit = "cm",
    up: UpAxis = "y",
) -> Path:
    """Write ``motion`` as a BVH file, atomically (a temporary file, then :func:`os.replace`).

    Parameters
    ----------
    path : str or path-like
        Destination; its folder must exist. Never left half-written.
    motion : Motion
        Metres, world frame Z up.
    order : {"XYZ", "XZY", "YXZ", "YZX", "ZXY", "ZYX"}
        Rotation channel order of every joint (intrinsic, first listed outermost).
    unit : {"m", "cm", "mm", "inch", "cmu"}
        Length unit of the file.
    up : {"y", "z"}
        Up axis of the file (BVH files are normally Y up).

    Returns
    -------
    Path
        ``path``.

    Notes
    -----
    Joints are written depth first from the root, so a reader sees them in that order (the
    order of ``motion`` when parents precede children along each branch, as in BVH files).
    The root has 6 channels (``Xposition Yposition Zposition`` then rotations), other joints
    3; its ``OFFSET`` is zero and its position channels are absolute, so readers that add
    the root's offset to them (this library's) and readers that ignore it (Blender's) agree.
    Leaves get an ``End Site`` at ``end_offsets`` (those of other joints are not written).
    Numbers are written with 8 decimals.
    """
    if not isinstance(motion, Motion):
        raise InputError(f"write_bvh: motion must be a Motion, found {type(motion).__name__}")
    check_choice("write_bvh", "order", order, get_args(EulerOrder))
    check_choice("write_bvh", "unit", unit, get_args(LengthUnit))
    check_choice("write_bvh", "up", up, get_args(UpAxis))
    folder = Path(path).parent
    if not folder.is_dir():
        raise MeshmocapFileNotFoundError(f"{path}: folder {folder} does not exist")
    for name in motion.skeleton.names:
        _check_name(name)
    m = motion.transformed(_up_rotation(up).T, scale=1.0 / UNIT_METRES[unit])
    sk = m.skeleton
    axes = " ".join(f"{a}rotation" for a in order)
    lines = ["HIERARCHY"]
    file_order: list[int] = []

    def emit(j: int, pad: str) -> None:
        file_order.append(j)
        kw, ch = (
            ("ROOT", f"6 Xposition Yposition Zposition {axes}")
            if j == 0
            else ("JOINT", f"3 {axes}")
        )
        x, y, z = sk.offsets[j] if j else (0.0, 0.0, 0.0)  # root: absolute positions
        lines.extend(
            [f"{pad}{kw} {sk.names[j]}", f"{pad}{{", f"{pad}\tOFFSET {x:.8f} {y:.8f} {z:.8f}"]
        )
        lines.append(f"{pad}\tCHANNELS {ch}")
        for k in sk.children[j]:
            emit(k, pad + "\t")
        if not sk.children[j]:
            x, y, z = sk.end_offsets[j]
            lines.extend(
                [f"{pad}\tEnd Site", f"{pad}\t{{", f"{pad}\t\tOFFSET {x:.8f} {y:.8f} {z:.8f}"]
            )
            lines.append(f"{pad}\t}}")
        lines.append(f"{pad}}}")

    emit(0, "")
    T = m.n_frames
    R = m.rotations[:, file_order]
    with warnings.catch_warnings():  # gimbal lock: scipy zeroes the third angle, still exact
        warnings.simplefilter("ignore", UserWarning)
        angles = matrix_to_euler(R, order, degrees=True)
    table = np.concatenate([m.root_positions, angles.reshape(T, -1)], axis=1)
    row = " ".join(["%.8f"] * table.shape[1])
    lines += ["MOTION", f"Frames: {T}", f"Frame Time: {1.0 / m.fps:.10g}"]
    text = "\n".join(lines) + "\n" + ("\n".join([row] * T) % tuple(table.ravel().tolist())) + "\n"
    write_text_atomic(path, text)
    return Path(path)
