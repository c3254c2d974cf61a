"""Acclaim ASF/AMC motion capture files (the CMU database's native format).

An ASF file describes a skeleton of bones; an AMC file gives, per frame, the values of each
bone's degrees of freedom (dof). The model, as read here:

* Joint ``j`` of the :class:`~meshmocap.body.skeleton.Skeleton` is the *start* of bone ``j``
  (joint ``"lfemur"`` is the hip, like ``LeftUpLeg`` in the CMU BVH conversions); joint 0 is
  ``"root"``. Joints follow the ASF ``:bonedata`` order (``"root"`` first) when every parent
  precedes its children there, else depth-first order of the ``:hierarchy``.
* A bone's rest offset is its parent bone's ``direction × length`` (bone directions are in
  world coordinates); children of the root start at the root (offset 0). Leaf bones get
  ``end_offsets = direction × length``. The root's rest position is ``:root position``.
* Local rotation of bone ``b``: ``L_b = C_b M_b C_bᵀ``. ``C_b`` comes from the ASF ``axis``
  angles, ``M_b`` from the AMC dof values; both apply their rotations one after the other
  about the fixed (parent) axes in the order listed (``axis XYZ`` and ``dof rx ry rz`` give
  ``Rz Ry Rx``, i.e. intrinsic ``ZYX``), the ASF/AMC convention used by the CMU converters
  (checked against the CMU BVH of the same trial in the tests). The root uses ``:root
  axis``/``orientation`` for ``C`` and the rotation dofs of ``:root order`` for ``M``; its
  world position is ``:root position`` plus its ``TX TY TZ`` values. Bones without rotation
  dofs do not rotate.
* Units: ``:units length L`` means one ASF unit is ``1/L`` inch (CMU: ``length 0.45``,
  0.056444 m); angles in degrees or radians (``:units angle``, overridden by an AMC
  ``:DEGREES``/``:RADIANS`` line). Files are Y up; readers return metres, Z up:
  (x, y, z) → (x, −z, y) (:data:`~meshmocap.body.motion.Y_UP_TO_Z_UP`).

References
----------
- M. Meredith, S. Maddock, *Motion capture file formats explained*, Department of
  Computer Science, University of Sheffield, 2001.
"""

from __future__ import annotations

import numbers
import os
from dataclasses import dataclass
from functools import cached_property
from operator import itemgetter
from pathlib import Path

import numpy as np

from meshmocap.body.motion import Y_UP_TO_Z_UP, Motion
from meshmocap.body.skeleton import Skeleton
from meshmocap.errors import FormatError, InputError, where
from meshmocap.geometry.rotations import euler_matrix
from meshmocap.io._text import (
    FrameSelection,
    frame_index,
    parse_floats,
    read_bytes,
    scan_tokens,
)

__all__ = ["AsfSkeleton", "motion_from_channels", "read_amc", "read_amc_channels", "read_asf"]

_DOFS = ("tx", "ty", "tz", "rx", "ry", "rz", "l")
_INCH = 0.0254


@dataclass(frozen=True, eq=False)
class AsfSkeleton:
    """An ASF skeleton and what is needed to decode AMC files recorded on it.

    Parameters
    ----------
    skeleton : Skeleton
        ``J`` joints (``"root"`` then one per bone, at the bone's start), metres, Z up.
    bones : tuple of str, length B
        Bone names in ASF ``:bonedata`` order, ``"root"`` first: the AMC channel order.
    dofs : tuple of tuple of str, length B
        Lower-case dof names of each bone (``"rx"``, ``"ty"``, ...) in AMC value order; the
        root's are its ``:root order``.
    axes : (B, 3, 3) float64
        Rotation ``C_b`` of each bone's ASF ``axis`` (root: ``orientation``), ASF frame (Y up).
    joints : (B,) int64
        Skeleton joint index of each bone.
    root_position : (3,) float64
        ``:root position``, ASF units, Y up.
    metres_per_unit : float
        Length of one ASF unit in metres (``0.0254 / length``).
    degrees : bool
        Whether angles are in degrees (``:units angle deg``).
    source : str
        The file it was read from (for messages).
    """

    skeleton: Skeleton
    bones: tuple[str, ...]
    dofs: tuple[tuple[str, ...], ...]
    axes: np.ndarray
    joints: np.ndarray
    root_position: np.ndarray
    metres_per_unit: float
    degrees: bool
    source: str

    @cached_property
    def channel_names(self) -> tuple[str, ...]:
        """``"bone.dof"`` of every AMC channel, in :func:`read_amc_channels` column order."""
        return tuple(f"{b}.{d}" for b, ds in zip(self.bones, self.dofs, strict=True) for d in ds)

    @property
    def n_channels(self) -> int:
        """Number of AMC channels (62 for the CMU skeletons)."""
        return len(self.channel_names)


def _extrinsic(angles: np.ndarray, axes: str) -> np.ndarray:
    """Rotation (3, 3) applying ``angles`` (radians) about fixed ``axes`` one after another."""
    return euler_matrix(np.asarray(angles[::-1], dtype=float), axes[::-1].upper())


def _sections(text: str, path: object) -> dict[str, tuple[int, list[tuple[int, list[str]]]]]:
    """Split ASF text into ``{keyword: (line, [(line, tokens), ...])}``; ``#`` starts a comment."""
    sections: dict[str, tuple[int, list[tuple[int, list[str]]]]] = {}
    current: list[tuple[int, list[str]]] | None = None
    for n, raw in enumerate(text.split("\n"), 1):
        toks = raw.split("#", 1)[0].split()
        if not toks:
            continue
        if toks[0].startswith(":"):
            current = []
            sections.setdefault(toks[0][1:].lower(), (n, current))
            if toks[1:]:
                current.append((n, toks[1:]))
        elif current is None:
            raise FormatError(f"{where(path, n)}: expected an ASF ':keyword', found {toks[0]!r}")
        else:
            current.append((n, toks))
    if not sections:
        raise FormatError(f"{path}: empty file, expected ASF sections (:units, :root, ...)")
    for key in ("root", "bonedata", "hierarchy"):
        if key not in sections:
            raise FormatError(f"{path}: no :{key} section")
    return sections


def _floats(toks: list[str], k: int, line: int, what: str, path: object) -> np.ndarray:
    try:
        out = np.array([float(t) for t in toks[:k]])
    except ValueError:
        out = np.zeros(0)
    if out.shape != (k,) or not np.all(np.isfinite(out)):
        raise FormatError(
            f"{where(path, line)}: {what} expects {k} numbers, found {' '.join(toks)!r}"
        )
    return out


def _axis_order(tok: str, line: int, path: object) -> str:
    if len(tok) != 3 or sorted(tok.upper()) != ["X", "Y", "Z"]:
        raise FormatError(f"{where(path, line)}: expected an axis order such as XYZ, found {tok!r}")
    return tok.upper()


def _parse_bones(lines: list[tuple[int, list[str]]], path: object) -> list[dict]:
    """Parse the ``:bonedata`` begin/end blocks into dicts (name, direction, length, ...)."""
    bones: list[dict] = []
    bone: dict | None = None
    for n, toks in lines:
        key = toks[0].lower()
        if key == "begin":
            if bone is not None:
                raise FormatError(
                    f"{where(path, n)}: 'begin' inside the bone begun at line {bone['line']}"
                )
            bone = {"line": n, "dof": (), "axis": np.zeros(3), "order": "XYZ"}
        elif key == "end":
            if bone is None:
                raise FormatError(f"{where(path, n)}: 'end' without 'begin'")
            for req in ("name", "direction", "length"):
                if req not in bone:
                    raise FormatError(f"{where(path, bone['line'])}: bone has no '{req}'")
            bones.append(bone)
            bone = None
        elif bone is None:
            raise FormatError(f"{where(path, n)}: expected 'begin' in :bonedata, found {toks[0]!r}")
        elif key == "name" and len(toks) == 2:
            bone["name"] = toks[1]
        elif key == "direction":
            bone["direction"] = _floats(toks[1:], 3, n, "direction", path)
        elif key == "length":
            bone["length"] = _floats(toks[1:], 1, n, "length", path)[0]
        elif key == "axis":
            bone["axis"] = _floats(toks[1:], 3, n, "axis", path)
            bone["order"] = _axis_order(toks[4] if len(toks) > 4 else "", n, path)
        elif key == "dof":
            dof = tuple(t.lower() for t in toks[1:])
            bad = [t for t in dof if t not in _DOFS]
            if bad or len(set(dof)) != len(dof):
                raise FormatError(
                    f"{where(path, n)}: bad dof list {' '.join(toks[1:])!r} (dofs are {_DOFS})"
                )
            bone["dof"] = dof
        elif key == "name":
            raise FormatError(
                f"{where(path, n)}: expected one bone name, found {' '.join(toks[1:])!r}"
            )
        # id, limits (and their continuation lines), bodymass, cofmass: not needed
    if bone is not None:
        raise FormatError(
            f"{where(path, bone['line'])}: bone 'begin' without 'end' (truncated file?)"
        )
    return bones


def read_asf(path: str | os.PathLike[str]) -> AsfSkeleton:
    """Read an Acclaim ASF skeleton.

    Parameters
    ----------
    path : str or path-like
        The ``.asf`` file (any line endings; ``#`` comments).

    Returns
    -------
    AsfSkeleton
        Its ``skeleton`` has ``J = B`` joints (root + bones), offsets in metres, Z up.

    Raises
    ------
    MeshmocapFileNotFoundError, FormatError
    """
    text = read_bytes(path).decode("utf-8", errors="replace")
    sec = _sections(text, path)
    units = {t[0].lower(): (n, t[1:]) for n, t in sec.get("units", (0, []))[1] if len(t) > 1}
    length_line, length = units.get("length", (None, ["1"]))
    length_scale = _floats(length, 1, length_line or 0, "length", path)[0]
    if not length_scale > 0:
        raise FormatError(f"{where(path, length_line)}: length unit must be positive")
    metres = _INCH / length_scale
    angle_line, angle = units.get("angle", (None, ["deg"]))
    if angle[0].lower() not in ("deg", "rad"):
        raise FormatError(
            f"{where(path, angle_line)}: angle unit must be deg or rad, found {angle[0]!r}"
        )
    degrees = angle[0].lower() == "deg"
    to_rad = np.deg2rad if degrees else np.asarray

    root_line, root_items = sec["root"]
    root = {t[0].lower(): (n, t[1:]) for n, t in root_items}
    order_line, order = root.get("order", (root_line, []))
    root_dofs = tuple(t.lower() for t in order)
    if any(d not in _DOFS[:6] for d in root_dofs) or len(set(root_dofs)) != len(root_dofs):
        raise FormatError(f"{where(path, order_line)}: bad root order {' '.join(order)!r}")
    n, tok = root.get("axis", (root_line, ["XYZ"]))
    root_axis = _axis_order(tok[0] if tok else "", n, path)
    n, tok = root.get("position", (root_line, ["0", "0", "0"]))
    position = _floats(tok, 3, n, "position", path)
    n, tok = root.get("orientation", (root_line, ["0", "0", "0"]))
    orientation = _floats(tok, 3, n, "orientation", path)

    bones = _parse_bones(sec["bonedata"][1], path)
    names = ["root"] + [b["name"] for b in bones]
    index = {}
    for i, name in enumerate(names):
        if name in index:
            raise FormatError(f"{where(path, bones[i - 1]['line'])}: duplicate bone name {name!r}")
        index[name] = i
    parent = [-2] * len(names)
    parent[0] = -1
    kids: list[list[int]] = [[] for _ in names]
    for n, toks in sec["hierarchy"][1]:
        if toks[0].lower() in ("begin", "end"):
            continue
        for t in toks:
            if t not in index:
                raise FormatError(f"{where(path, n)}: :hierarchy names unknown bone {t!r}")
        p = index[toks[0]]
        for t in toks[1:]:
            c = index[t]
            if parent[c] != -2 or c == 0:
                raise FormatError(f"{where(path, n)}: bone {t!r} has several parents")
            parent[c] = p
            kids[p].append(c)
    dfs, todo = [], [0]
    while todo:
        dfs.append(todo.pop())
        todo.extend(reversed(kids[dfs[-1]]))
    if len(dfs) != len(names) or len(set(dfs)) != len(dfs):
        lost = [names[i] for i in range(len(names)) if i not in set(dfs)]
        raise FormatError(f"{path}: bones {lost} are not attached to root in :hierarchy")
    valid = all(parent[i] < i for i in range(1, len(names)))
    order_ = list(range(len(names))) if valid else dfs
    joint_of = np.empty(len(names), dtype=np.int64)
    joint_of[order_] = np.arange(len(names))

    vec = np.zeros((len(names), 3))  # direction × length, ASF units, Y up
    vec[1:] = [b["direction"] * b["length"] for b in bones]
    offsets = np.zeros((len(names), 3))
    ends = np.zeros((len(names), 3))
    for b in range(1, len(names)):
        offsets[b] = vec[parent[b]] if parent[b] > 0 else 0.0
        ends[b] = 0.0 if kids[b] else vec[b]
    offsets[0] = position
    skeleton = Skeleton(
        tuple(names[b] for b in order_),
        [joint_of[parent[b]] if b else -1 for b in order_],
        offsets[order_],
        ends[order_],
    )
    axes = np.stack(
        [_extrinsic(to_rad(orientation), root_axis)]
        + [_extrinsic(to_rad(b["axis"]), b["order"]) for b in bones]
    )
    return AsfSkeleton(
        skeleton=skeleton.transformed(Y_UP_TO_Z_UP).scaled(metres),
        bones=tuple(names),
        dofs=(root_dofs, *(b["dof"] for b in bones)),
        axes=axes,
        joints=joint_of,
        root_position=position,
        metres_per_unit=float(metres),
        degrees=degrees,
        source=str(path),
    )


def _pick(tokens: list[bytes], idx: np.ndarray) -> list[bytes]:
    if idx.size == 1:
        return [tokens[int(idx[0])]]
    return list(itemgetter(*idx.tolist())(tokens)) if idx.size else []


def _read_table(path: str | os.PathLike[str], asf: AsfSkeleton) -> tuple[np.ndarray, bool]:
    """Return the raw AMC channel table (T, n_channels) and whether angles are in degrees."""
    if not isinstance(asf, AsfSkeleton):
        raise InputError(
            f"read_amc: asf must be an AsfSkeleton (read_asf), found {type(asf).__name__}"
        )
    data = read_bytes(path)
    tokens = data.split()
    if not tokens:
        raise FormatError(f"{path}: empty file, expected AMC frames")
    starts, tok_line = scan_tokens(data)
    first = np.flatnonzero(np.concatenate(([True], tok_line[1:] != tok_line[:-1])))
    count = np.diff(np.append(first, len(tokens)))  # tokens per non-blank line
    lead = np.frombuffer(data, dtype=np.uint8)[starts[first]]
    line_no = tok_line[first] + 1
    comment = lead == ord("#")
    keyword = lead == ord(":")
    degrees = asf.degrees
    for k in np.flatnonzero(keyword):
        word = tokens[first[k]].upper()
        degrees = True if word == b":DEGREES" else False if word == b":RADIANS" else degrees
    is_frame = (lead >= ord("0")) & (lead <= ord("9")) & ~comment & ~keyword
    bad = np.flatnonzero(is_frame & (count != 1))
    if bad.size:
        raise FormatError(
            f"{where(path, int(line_no[bad[0]]))}: expected a bone name or a frame number, "
            f"found {tokens[first[bad[0]]].decode('utf-8', errors='replace')!r}"
        )
    is_bone = ~(comment | keyword | is_frame)
    frame = np.cumsum(is_frame) - 1
    T = int(is_frame.sum())
    if T == 0:
        raise FormatError(f"{path}: no frames (expected frame numbers followed by bone lines)")
    bl = np.flatnonzero(is_bone)
    if bl.size and frame[bl[0]] < 0:
        raise FormatError(
            f"{where(path, int(line_no[bl[0]]))}: bone values before the first frame number"
        )
    names, inverse = np.unique(np.array(_pick(tokens, first[bl]), dtype=bytes), return_inverse=True)
    lookup = {n.encode(): i for i, n in enumerate(asf.bones)}
    bone_of_name = np.array([lookup.get(bytes(n), -1) for n in names], dtype=np.int64)
    bone = bone_of_name[inverse]
    if np.any(bone < 0):
        k = bl[np.flatnonzero(bone < 0)[0]]
        name = tokens[first[k]].decode("utf-8", errors="replace")
        asf_name = Path(asf.source).name
        raise FormatError(f"{where(path, int(line_no[k]))}: bone {name!r} is not in {asf_name}")
    n_dof = np.array([len(d) for d in asf.dofs], dtype=np.int64)
    wrong = np.flatnonzero(count[bl] - 1 != n_dof[bone])
    if wrong.size:
        k, b = bl[wrong[0]], bone[wrong[0]]
        raise FormatError(
            f"{where(path, int(line_no[k]))}: bone {asf.bones[b]!r} expects {n_dof[b]} values "
            f"({' '.join(asf.dofs[b])}), found {int(count[k]) - 1}"
        )
    B = len(asf.bones)
    seen = np.bincount(frame[bl] * B + bone, minlength=T * B).reshape(T, B)
    bad_f, bad_b = np.nonzero((seen > 1) | ((seen == 0) & (n_dof > 0)))
    if bad_f.size:
        f, b = int(bad_f[0]), int(bad_b[0])
        k = np.flatnonzero(is_frame)[f]
        label = tokens[first[k]].decode("utf-8", errors="replace")
        if seen[f, b] > 1:
            problem = f"repeats bone {asf.bones[b]!r}"
        else:
            problem = f"has no values for bone {asf.bones[b]!r}"
            problem += " (truncated file?)" if f == T - 1 else ""
        raise FormatError(f"{where(path, int(line_no[k]))}: frame {label} {problem}")
    # value tokens: every token of a bone line but the first
    per_line = np.repeat(np.arange(len(first)), count)
    pos = np.arange(len(tokens)) - first[per_line] - 1
    line_bone = np.full(len(first), -1, dtype=np.int64)
    line_bone[bl] = bone
    tb = line_bone[per_line]
    is_value = (tb >= 0) & (pos >= 0)
    vidx = np.flatnonzero(is_value)
    offset = np.concatenate(([0], np.cumsum(n_dof)[:-1]))
    C = int(n_dof.sum())
    slot = frame[per_line[vidx]] * C + offset[tb[vidx]] + pos[vidx]
    table = np.empty(T * C)
    table[slot] = parse_floats(_pick(tokens, vidx), tok_line[vidx] + 1, path)
    return table.reshape(T, C), degrees


def read_amc_channels(path: str | os.PathLike[str], asf: AsfSkeleton) -> np.ndarray:
    """Read the raw values of an AMC file.

    Parameters
    ----------
    path : str or path-like
        The ``.amc`` file.
    asf : AsfSkeleton
        Its skeleton (:func:`read_asf`).

    Returns
    -------
    (T, n_channels) float64
        Values as written (ASF units, degrees or radians as the file says), columns in
        ``asf.channel_names`` order: ASF ``:bonedata`` order (root first) × each bone's dofs.

    Raises
    ------
    MeshmocapFileNotFoundError, FormatError
    """
    return _read_table(path, asf)[0]


def read_amc(
    path: str | os.PathLike[str],
    asf: AsfSkeleton,
    *,
    frames: FrameSelection = None,
    fps: float = 120.0,
) -> Motion:
    """Read an AMC motion recorded on the skeleton ``asf``.

    Parameters
    ----------
    path : str or path-like
        The ``.amc`` file (``:FULLY-SPECIFIED``; ``#`` comment lines anywhere; any line endings).
    asf : AsfSkeleton
        Its skeleton (:func:`read_asf`).
    frames : slice or (k,) int, optional
        Frames to keep (all by default); a slice step divides the frame rate.
    fps : float
        Frame rate; AMC files do not store it (CMU: 120).

    Returns
    -------
    Motion
        On ``asf.skeleton``: rotations (T, J, 3, 3) local; root_positions (T, 3) float64,
        metres, world frame (Z up).

    Raises
    ------
    MeshmocapFileNotFoundError, FormatError, InputError
    """
    if not (isinstance(fps, numbers.Real) and np.isfinite(fps) and fps > 0):
        raise InputError(f"read_amc: fps must be a positive number, found {fps!r}")
    table, degrees = _read_table(path, asf)
    idx, step = frame_index(table.shape[0], frames, "read_amc")
    return motion_from_channels(table[idx], asf, fps=fps / step, degrees=degrees, source=path)


def motion_from_channels(
    table: np.ndarray,
    asf: AsfSkeleton,
    *,
    fps: float = 120.0,
    degrees: bool = True,
    source: object = "channels",
) -> Motion:
    """Decode raw AMC channel values into a :class:`Motion`.

    Parameters
    ----------
    table : (T, C) float64
        One row per frame, ``asf.channel_names`` order (as :func:`read_amc_channels`
        returns them, or as stored in CMU-derived ``.mat`` files such as cmu35WalkJog).
    asf : AsfSkeleton
    fps : float
        Frame rate of the rows.
    degrees : bool
        Angles in degrees (the ASF ``:units angle deg``).
    source : object
        Named in error messages.
    """
    table = np.asarray(table, dtype=np.float64)
    if table.ndim != 2 or table.shape[1] != asf.n_channels:
        raise InputError(
            f"{source}: expected (T, {asf.n_channels}) channel values, found shape {table.shape}"
        )
    if not np.all(np.isfinite(table)):
        raise InputError(f"{source}: channel values contain NaN or infinite values")
    T, J = table.shape[0], asf.skeleton.n_joints
    R = np.empty((T, J, 3, 3))
    R[...] = np.eye(3)
    t = np.broadcast_to(asf.root_position, (T, 3)).copy()
    groups: dict[str, tuple[list[int], list[list[int]]]] = {}
    col = 0
    for b, dofs in enumerate(asf.dofs):
        rot = []
        for d in dofs:
            if d[0] == "r":
                rot.append((col, d[1].upper()))
            elif b == 0 and d[0] == "t":
                t[:, "xyz".index(d[1])] += table[:, col]
            else:
                raise FormatError(
                    f"{source}: bone {asf.bones[b]!r} has a {d!r} dof (translation or length of a "
                    "non-root bone), which a Motion cannot represent; use read_amc_channels"
                )
            col += 1
        if rot:  # extrinsic in dof order = intrinsic in reverse order
            g = groups.setdefault("".join(a for _, a in rot[::-1]), ([], []))
            g[0].append(b)
            g[1].append([c for c, _ in rot[::-1]])
    D = Y_UP_TO_Z_UP @ asf.axes  # (B, 3, 3): L in Z up = D M Dᵀ
    for order, (bs, cols) in groups.items():
        angles = table[:, np.array(cols)]
        angles = np.deg2rad(angles) if degrees else angles
        RD = euler_matrix(angles, order, start=D[bs])
        R[:, asf.joints[bs]] = RD @ np.swapaxes(D[bs], -1, -2)
    root = asf.metres_per_unit * t @ Y_UP_TO_Z_UP.T
    return Motion(asf.skeleton, R, root, fps)
