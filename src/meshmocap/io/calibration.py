"""The calibration files studios already have, read into (and written from) cameras.

Every format becomes a list of :class:`~meshmocap.geometry.camera.Camera` in the project's
convention (OpenCV pinhole ``x = K (R X + t)``, pixel centres at integer coordinates,
distortion ``(k1, k2, p1, p2, k3)``, translations in metres, world Z up as the studio's
calibration defines it):

``qualisys`` (``.qca.txt``, ``.qca``)
    Qualisys Track Manager's XML export: one ``<camera serial=...>`` per camera with a
    ``<transform>`` (rotation ``r11 … r33``, whose rows as read, ``M[i][j] = r(i+1)(j+1)``,
    are the camera's x, −y and −z axes in the world, and the camera's position ``x, y, z``
    in millimetres), an ``<intrinsic>`` in sub-pixel units (64 per pixel: focal lengths,
    principal point, skew) with radial and tangential distortion, and ``<fov_video>`` (the
    pixel window of the video image, which gives the image size and shifts the principal
    point). The axes are Pose2Sim's (``calib_qca_fun``, Pagnon et al. 2022), the reader
    of the file the Pose2Sim demonstration ships: R = diag(1, −1, −1) · M. The distortion
    coefficients are OpenCV's as they stand, on normalised image coordinates: Pose2Sim's
    converter divides them by 64 like the intrinsics, which leaves ~1/64 of the lens'
    distortion; the charuco calibration of the same four cameras in the Pose2Sim
    demonstration (``Calib_scene.toml``) gives k1 −0.03 … −0.05 and k2 0.01 … 0.15, the
    magnitudes the ``.qca.txt`` holds (−0.046 … −0.048, 0.135 … 0.140).
``toml`` (``Calib.toml``)
    Pose2Sim, anipose and FreeMoCap: one table per camera with ``name``, ``size``
    ``[width, height]``, ``matrix`` (3×3), ``distortions`` (4 or 5 numbers), ``rotation``
    (axis-angle, ``cv::Rodrigues``, world → camera) and ``translation`` (Pose2Sim writes
    metres; anipose and FreeMoCap write the calibration board's unit, often millimetres:
    pass ``unit=``); ``fisheye = true`` cameras are refused (another lens model); other
    tables (``[metadata]``) are ignored.
``opencv`` (``.yml``, ``.yaml``) and ``json``
    EasyMocap's ``intri.yml`` (+ ``extri.yml`` as ``extrinsics=``), OpenCV FileStorage YAML
    and meshmocap's ``cameras.json``: see :mod:`meshmocap.io.cameras`.

:func:`write_calibration` writes every format back (Qualisys: the fields above only).

References
----------
- D. Pagnon, M. Domalain, L. Reveret, *Pose2Sim: an open-source Python package for
  multiview markerless kinematics*, Journal of Open Source Software, 2022.
  https://doi.org/10.21105/joss.04362
"""

from __future__ import annotations

import math
import os
import re
import tomllib
import xml.etree.ElementTree as ET
from collections.abc import Sequence
from pathlib import Path
from typing import Literal, get_args

import numpy as np

from meshmocap._atomic import write_text_atomic
from meshmocap._validate import check_choice
from meshmocap.errors import FormatError, InputError
from meshmocap.geometry.camera import Camera
from meshmocap.geometry.rotations import so3_exp, so3_log
from meshmocap.io.cameras import (
    check_unique,
    checked_camera,
    read_cameras,
    read_text,
    write_cameras,
)

#: Calibration file formats; ``"auto"`` picks by suffix, then by content.
CalibrationFormat = Literal["auto", "json", "opencv", "qualisys", "toml"]
#: Length unit of the translations in a TOML or OpenCV file.
CalibrationUnit = Literal["m", "cm", "mm"]
_UNIT = {"m": 1.0, "cm": 0.01, "mm": 0.001}
_SUBPIXEL = 64.0  # Qualisys intrinsics: sub-pixel units per pixel
_FLIP = np.diag([1.0, -1.0, -1.0])  # Qualisys camera axes (optical axis −z) → OpenCV's


def read_calibration(
    path: str | os.PathLike[str],
    *,
    format: CalibrationFormat = "auto",
    unit: CalibrationUnit = "m",
    extrinsics: str | os.PathLike[str] | None = None,
) -> list[Camera]:
    """Read a studio's calibration file (see the module docstring for the formats).

    Parameters
    ----------
    path : str or path-like
        ``.qca.txt`` (Qualisys), ``.toml`` (Pose2Sim, anipose, FreeMoCap), ``.yml`` /
        ``.yaml`` (OpenCV, EasyMocap's ``intri.yml``) or ``.json`` (meshmocap).
    format : {"auto", "json", "opencv", "qualisys", "toml"}
        ``"auto"``: by suffix, then by content.
    unit : {"m", "cm", "mm"}
        Unit of the translations of TOML and OpenCV files (Qualisys files are in
        millimetres and JSON files in metres whatever this says).
    extrinsics : str or path-like, optional
        EasyMocap's ``extri.yml`` beside ``intri.yml``.

    Returns
    -------
    list of Camera
        In file order; translations in metres.

    Raises
    ------
    MeshmocapFileNotFoundError
        A file is absent.
    FormatError
        Malformed file: one line naming the file, the camera and the field.
    """
    check_choice("read_calibration", "format", format, get_args(CalibrationFormat))
    check_choice("read_calibration", "unit", unit, get_args(CalibrationUnit))
    text = read_text(path)
    fmt = _detect(path, text, format)
    if fmt in ("json", "opencv"):
        if fmt == "json":
            if extrinsics is not None:
                raise InputError("read_calibration: extrinsics= applies to OpenCV files only")
            return read_cameras(path, format="json")
        return read_cameras(path, format="opencv", unit=unit, extrinsics=extrinsics)
    if extrinsics is not None:
        raise InputError("read_calibration: extrinsics= applies to OpenCV files only")
    if fmt == "qualisys":
        return _read_qualisys(path, text)
    return _read_toml(path, text, _UNIT[unit])


def write_calibration(
    path: str | os.PathLike[str],
    cameras: Sequence[Camera],
    *,
    format: CalibrationFormat = "auto",
    unit: CalibrationUnit = "m",
) -> None:
    """Write cameras as a calibration file, atomically.

    Parameters
    ----------
    path : str or path-like
        Destination; ``format="auto"`` picks by suffix (``.qca.txt``/``.qca``, ``.toml``,
        ``.yml``/``.yaml``, ``.json``).
    cameras : sequence of Camera
        Distinct names.
    format : {"auto", "json", "opencv", "qualisys", "toml"}
    unit : {"m", "cm", "mm"}
        Unit of the translations of TOML and OpenCV files.
    """
    check_choice("write_calibration", "format", format, get_args(CalibrationFormat))
    check_choice("write_calibration", "unit", unit, get_args(CalibrationUnit))
    fmt = _detect(path, None, format)
    if fmt in ("json", "opencv"):
        write_cameras(path, cameras, format=fmt, unit=unit)
        return
    cameras = list(cameras)
    if not cameras or not all(isinstance(c, Camera) for c in cameras):
        raise InputError("write_calibration: cameras must be a non-empty sequence of Camera")
    names = [c.name for c in cameras]
    if len(set(names)) != len(names) or not all(names):
        raise InputError(f"write_calibration: camera names must be distinct and set: {names}")
    text = _qualisys_text(cameras) if fmt == "qualisys" else _toml_text(cameras, _UNIT[unit])
    write_text_atomic(path, text)


# ----------------------------------------------------------------------------- Qualisys
def _read_qualisys(path, text: str) -> list[Camera]:
    try:
        root = ET.fromstring(text.encode("utf-8") if text.lstrip().startswith("<?") else text)
    except ET.ParseError as e:
        raise FormatError(f"{path}:{e.position[0]}: not valid XML: {e.msg}") from None
    nodes = root.findall("cameras/camera")
    if root.tag != "calibration" or not nodes:
        raise FormatError(
            f"{path}: not a Qualisys calibration (expected <calibration> with "
            f"<cameras><camera>...), found <{root.tag}> with {len(nodes)} cameras"
        )
    cams = []
    for i, node in enumerate(nodes):
        name = node.get("serial") or f"cam{i}"
        where = f"{path}: camera {name!r}"
        fov, tr, intr = (node.find(tag) for tag in ("fov_video", "transform", "intrinsic"))
        for tag, el in (("fov_video", fov), ("transform", tr), ("intrinsic", intr)):
            if el is None:
                raise FormatError(f"{where}: missing <{tag}>")
        left, top, right, bottom = (
            _attr(fov, k, where, "fov_video") for k in ("left", "top", "right", "bottom")
        )
        width, height = right - left + 1, bottom - top + 1
        if width != int(width) or height != int(height) or width <= 0 or height <= 0:
            raise FormatError(f"{where}: <fov_video> is not a pixel window: {fov.attrib}")
        M = np.array([[_attr(tr, f"r{a}{b}", where, "transform") for b in "123"] for a in "123"])
        pos = np.array([_attr(tr, k, where, "transform") for k in "xyz"]) / 1000.0
        q = {k: _attr(intr, k, where, "intrinsic") for k in _Q_INTRINSIC}
        q |= {k: _attr(intr, k, where, "intrinsic", 0.0) for k in _Q_OPTIONAL}
        K = (
            np.array(
                [
                    [q["focalLengthU"], q["skew"], q["centerPointU"] - left * _SUBPIXEL],
                    [0.0, q["focalLengthV"], q["centerPointV"] - top * _SUBPIXEL],
                    [0.0, 0.0, _SUBPIXEL],
                ]
            )
            / _SUBPIXEL
        )
        dist = np.array([q[k] for k in _Q_DIST])  # normalised coordinates: not sub-pixels
        R = _FLIP @ M
        cams.append(checked_camera(where, name, K, R, -R @ pos, dist, int(width), int(height)))
    check_unique(path, cams)
    return cams


_Q_INTRINSIC = ("focalLengthU", "focalLengthV", "centerPointU", "centerPointV")
_Q_DIST = (
    "radialDistortion1",
    "radialDistortion2",
    "tangentalDistortion1",
    "tangentalDistortion2",
    "radialDistortion3",
)
_Q_OPTIONAL = ("skew", *_Q_DIST)


def _attr(el, key: str, where: str, tag: str, default: float | None = None) -> float:
    raw = el.get(key)
    if raw is None:
        if default is not None:
            return default
        raise FormatError(f"{where}: <{tag}> has no attribute {key!r}")
    try:
        value = float(raw)
    except ValueError:
        value = math.nan
    if not math.isfinite(value):
        raise FormatError(f"{where}: <{tag}> {key}={raw!r} is not a finite number")
    return value


def _qualisys_text(cameras: list[Camera]) -> str:
    lines = [
        "<?xml version='1.0' encoding='ASCII'?>",
        '<calibration source="meshmocap" type="regular">',
        "  <cameras>",
    ]
    for c in cameras:
        M = _FLIP @ c.R
        pos = c.centre * 1000.0
        rot = " ".join(f'r{a + 1}{b + 1}="{float(M[a, b])!r}"' for a in range(3) for b in range(3))
        xyz = " ".join(f'{k}="{v!r}"' for k, v in zip("xyz", pos.tolist(), strict=True))
        K, d = c.K * _SUBPIXEL, c.dist
        fov = f'bottom="{c.height - 1}" left="0" right="{c.width - 1}" top="0"'
        intr = {
            "centerPointU": K[0, 2],
            "centerPointV": K[1, 2],
            "focalLengthU": K[0, 0],
            "focalLengthV": K[1, 1],
            "skew": K[0, 1],
            **dict(zip(_Q_DIST, d.tolist(), strict=True)),
        }
        attrs = " ".join(f'{k}="{float(v)!r}"' for k, v in intr.items())
        lines += [
            f'    <camera active="1" serial="{_xml_name(c.name)}">',
            f"      <fov_video {fov}/>",
            f"      <transform {rot} {xyz}/>",
            f"      <intrinsic {attrs}/>",
            "    </camera>",
        ]
    return "\n".join([*lines, "  </cameras>", "</calibration>"]) + "\n"


def _xml_name(name: str) -> str:
    if not re.fullmatch(r"[A-Za-z0-9_.\- ]+", name):
        raise InputError(
            f"write_calibration: Qualisys camera names must be letters, digits, '_', '.', "
            f"'-' or spaces, found {name!r}"
        )
    return name


# ----------------------------------------------------------------------------- TOML
def _read_toml(path, text: str, scale: float) -> list[Camera]:
    try:
        doc = tomllib.loads(text)
    except tomllib.TOMLDecodeError as e:
        raise FormatError(f"{path}: not valid TOML: {e}") from None
    tables = {k: v for k, v in doc.items() if isinstance(v, dict) and "matrix" in v}
    if not tables:
        raise FormatError(
            f"{path}: no cameras found, expected tables with keys name, size, matrix, "
            f"distortions, rotation, translation (Pose2Sim/anipose Calib.toml)"
        )
    cams = []
    for key, t in tables.items():
        name = t.get("name", key)
        where = f"{path}: camera [{key}]"
        if not isinstance(name, str) or not name:
            raise FormatError(f"{where}: 'name' must be a string, found {name!r}")
        if t.get("fisheye", False):
            raise FormatError(f"{where}: fisheye = true: the fisheye lens model is not supported")
        for field in ("size", "matrix", "rotation", "translation"):
            if field not in t:
                raise FormatError(f"{where}: missing key {field!r}")
        size = _toml_numbers(t["size"], where, "size", (2,), "[width, height]")
        if np.any(size <= 0) or np.any(size != np.round(size)):
            raise FormatError(f"{where}: 'size' must be whole positive pixels, found {t['size']}")
        K = _toml_numbers(t["matrix"], where, "matrix", (9,), "a 3×3 matrix").reshape(3, 3)
        dist = _toml_numbers(t.get("distortions", []), where, "distortions", (0, 4, 5), "4 or 5")
        rvec = _toml_numbers(t["rotation"], where, "rotation", (3, 9), "an axis-angle 3-vector")
        R = so3_exp(rvec) if rvec.size == 3 else rvec.reshape(3, 3)
        tr = _toml_numbers(t["translation"], where, "translation", (3,), "3 numbers")
        cams.append(checked_camera(where, name, K, R, tr * scale, dist, int(size[0]), int(size[1])))
    check_unique(path, cams)
    return cams


def _toml_numbers(value, where, key, sizes, what) -> np.ndarray:
    try:
        arr = np.array(value, dtype=np.float64).ravel()
    except (TypeError, ValueError):
        raise FormatError(f"{where}: {key!r} must be {what}, found {value!r}") from None
    if arr.size not in sizes or not np.all(np.isfinite(arr)):
        raise FormatError(f"{where}: {key!r} must be {what} (finite numbers), found {value!r}")
    return arr


def _toml_text(cameras: list[Camera], scale: float) -> str:
    def arr(a) -> str:
        return "[ " + ", ".join(repr(float(x)) for x in np.asarray(a).ravel()) + ",]"

    out = []
    for c in cameras:
        key = c.name if re.fullmatch(r"[A-Za-z0-9_\-]+", c.name) else f'"{c.name}"'
        rows = ", ".join(arr(row) for row in c.K)
        out += [
            f"[{key}]",
            f'name = "{c.name}"',
            f"size = {arr([c.width, c.height])}",
            f"matrix = [ {rows},]",
            f"distortions = {arr(c.dist)}",
            f"rotation = {arr(so3_log(c.R))}",
            f"translation = {arr(c.t / scale)}",
            "fisheye = false",
            "",
        ]
    return "\n".join([*out, "[metadata]", "adjusted = false", "error = 0.0", ""])


# ----------------------------------------------------------------------------- helpers
def _detect(path, text: str | None, fmt: str) -> str:
    if fmt != "auto":
        return fmt
    name = Path(path).name.lower()
    if name.endswith((".qca.txt", ".qca")):
        return "qualisys"
    suffix = Path(path).suffix.lower()
    known = {".toml": "toml", ".json": "json", ".yml": "opencv", ".yaml": "opencv"}
    if suffix in known:
        return known[suffix]
    if text is not None:
        head = text.lstrip()[:2000]
        if head.startswith("<") and "<calibration" in head:
            return "qualisys"
        if head[:1] in ("{", "["):
            return "json" if head[:1] == "{" or not re.match(r"\[\s*[\w\"]", head) else "toml"
        if re.search(r"^\s*matrix\s*=", text, re.M):
            return "toml"
        return "opencv"
    raise InputError(
        f"write_calibration: cannot tell the format of {path} from its suffix (.qca.txt, "
        f".toml, .yml, .yaml, .json); pass format="
    )
