"""Camera rigs on disk: meshmocap's JSON format and OpenCV FileStorage YAML.

Both formats hold a list of :class:`~meshmocap.geometry.camera.Camera` in the OpenCV
convention (``x = K (R X + t)``, world frame Z up, pixel centres at integer coordinates,
distortion ``(k1, k2, p1, p2, k3)``).

JSON (``.json``)
----------------
Always metres. Written as::

    {
      "format": "meshmocap.cameras",
      "version": 1,
      "unit": "m",
      "cameras": [
        {"name": "C1", "width": 640, "height": 480,
         "K": [[fx, s, cx], [0, fy, cy], [0, 0, 1]],
         "R": [[...], [...], [...]],
         "t": [tx, ty, tz],
         "dist": [k1, k2, p1, p2, k3]}
      ]
    }

Read back: that object, or a bare list of camera objects. ``name`` (default ``cam<i>``)
and ``dist`` (default zeros, 4 or 5 numbers) are optional; ``format``, ``version`` and
``unit`` are optional but checked when present; unknown keys are errors (typos would
otherwise pass silently). Numbers are written with Python's shortest exact ``repr``, so a
round trip is bit-exact.

OpenCV YAML (``.yml``, ``.yaml``)
---------------------------------
The files ``cv::FileStorage`` writes and calibration tools (EasyMocap, multi-camera
calibrators) use: a ``%YAML:1.0`` header, matrices as ``!!opencv-matrix`` mappings with
``rows``, ``cols``, ``dt`` and row-major ``data``. Plain YAML lists and numbers are accepted
wherever a matrix is (``imgSize_C1: [640, 480]``). Accepted layouts:

* **Per-camera keys** ``<field>_<name>``, for the cameras listed under ``names`` (a YAML
  list) or, without ``names``, for every key ``K_<name>`` in file order. Fields, with the
  aliases tried in this order:

  * ``K`` (3×3): ``K``, ``camera_matrix``, ``cameraMatrix``, ``intrinsic``;
  * ``dist`` (0–5 numbers, default zeros): ``dist``, ``D``, ``distCoeffs``,
    ``distortion_coefficients``;
  * ``R`` (3×3, or 3 numbers: axis-angle as ``cv::Rodrigues``): ``Rot``, ``R``, ``rvec``;
  * ``t`` (3 numbers, in ``unit``): ``t``, ``T``, ``tvec``;
  * image size: ``imgSize``, ``image_size`` or ``imageSize`` as ``[width, height]``, or
    numbers ``W``/``H``, ``width``/``height``, ``image_width``/``image_height``.

  ``R`` and ``t`` are required (EasyMocap keeps them in a second file: pass it as
  ``extrinsics=``). Longer OpenCV distortion vectors (8, 12, 14 numbers) are accepted when
  the extra coefficients are zero.
* **One camera, unsuffixed keys** (``camera_matrix``, ``distortion_coefficients``,
  ``image_width``, ``image_height``, as OpenCV's calibration sample writes): one camera
  named after the file; without ``R``/``t`` it sits at the world origin.

The image size may come from ``image_size=`` when the file lacks it. Rotations off
orthonormal by 1e-6 to 1e-3 (rounded files) are replaced by the nearest rotation; worse
ones are errors.
Written files use the per-camera layout with ``names``, ``K``, ``dist`` (5×1), ``R``
(3×3), ``t`` (3×1) and ``imgSize``, numbers in shortest exact form (bit-exact round trips
in metres). OpenCV's XML FileStorage is not supported.

PyYAML reads the YAML (after dropping the ``%YAML:1.0`` directive PyYAML rejects, and with
a constructor for ``!!opencv-matrix``); writing needs no library.

References
----------
- G. Bradski, *The OpenCV library*, Dr. Dobb's Journal of Software Tools, 2000.
"""

from __future__ import annotations

import functools
import json
import os
import re
from collections.abc import Sequence
from pathlib import Path
from typing import Literal, get_args

import numpy as np

from meshmocap._atomic import write_text_atomic
from meshmocap._tolerances import ROTATION_SLACK
from meshmocap._validate import check_choice
from meshmocap.errors import FormatError, InputError, MeshmocapFileNotFoundError
from meshmocap.geometry.camera import Camera
from meshmocap.geometry.rotations import so3_exp

#: File formats of camera rigs; ``"auto"`` picks by suffix, then by content.
CameraFormat = Literal["auto", "json", "opencv"]
#: Length unit of the translations in an OpenCV file.
CameraUnit = Literal["m", "cm", "mm"]
_UNIT = {"m": 1.0, "cm": 0.01, "mm": 0.001}
_FIELDS = {
    "K": ("K", "camera_matrix", "cameraMatrix", "intrinsic"),
    "dist": ("dist", "D", "distCoeffs", "distortion_coefficients"),
    "R": ("Rot", "R", "rvec"),
    "t": ("t", "T", "tvec"),
    "size": ("imgSize", "image_size", "imageSize"),
    "width": ("W", "width", "image_width"),
    "height": ("H", "height", "image_height"),
}
_JSON_KEYS = {"name", "width", "height", "K", "R", "t", "dist"}
_NAME = re.compile(r"[A-Za-z0-9][A-Za-z0-9_.\-]*\Z")
_TAG = "tag:yaml.org,2002:opencv-matrix"


# ----------------------------------------------------------------------------- public API
def read_cameras(
    path: str | os.PathLike[str],
    *,
    format: CameraFormat = "auto",
    unit: CameraUnit = "m",
    extrinsics: str | os.PathLike[str] | None = None,
    image_size: tuple[int, int] | None = None,
) -> list[Camera]:
    """Read a camera rig (see the module docstring for the formats).

    Parameters
    ----------
    path : str or path-like
        A ``.json`` or OpenCV ``.yml``/``.yaml`` file.
    format : {"auto", "json", "opencv"}
        ``"auto"``: by suffix, else by content (``{``/``[`` → JSON).
    unit : {"m", "cm", "mm"}
        Length unit of the translations of an OpenCV file; JSON files are in metres.
    extrinsics : str or path-like, optional
        A second OpenCV file whose keys (typically ``R_<name>``, ``T_<name>``) complete
        those of ``path`` (EasyMocap's ``intri.yml`` + ``extri.yml``).
    image_size : (width, height), optional
        Image size, pixels, for OpenCV files that do not store it.

    Returns
    -------
    list of Camera
        In file order; translations in metres.

    Raises
    ------
    MeshmocapFileNotFoundError
        A file is absent.
    FormatError
        Malformed file: one line naming the file, the key and what was expected.
    """
    check_choice("read_cameras", "format", format, get_args(CameraFormat))
    check_choice("read_cameras", "unit", unit, get_args(CameraUnit))
    text = read_text(path)
    fmt = _detect(path, text, format, "read_cameras")
    if fmt == "json":
        if unit != "m" or extrinsics is not None:
            raise InputError("read_cameras: unit= and extrinsics= apply to OpenCV files only")
        return _read_json(path, text)
    doc = _load_yaml(path, text)
    label = path
    if extrinsics is not None:
        extra = _load_yaml(extrinsics, read_text(extrinsics))
        doc = {**doc, **{k: v for k, v in extra.items() if k != "names"}}
        label = f"{path} (+ {extrinsics})"
    size = None
    if image_size is not None:
        size = tuple(int(s) for s in image_size)
        if len(size) != 2 or min(size) <= 0:
            raise InputError(f"read_cameras: image_size must be (width, height), found {size}")
    return _cameras_from_opencv(label, doc, _UNIT[unit], size, Path(path).stem)


def write_cameras(
    path: str | os.PathLike[str],
    cameras: Sequence[Camera],
    *,
    format: CameraFormat = "auto",
    unit: CameraUnit = "m",
) -> None:
    """Write a camera rig atomically (a temporary file, then :func:`os.replace`).

    Parameters
    ----------
    path : str or path-like
        Destination; its folder must exist. Never left half-written.
    cameras : sequence of Camera
        Distinct names; for OpenCV files, names made of letters, digits, ``_.-``.
    format : {"auto", "json", "opencv"}
        ``"auto"``: ``.json`` → JSON, ``.yml``/``.yaml`` → OpenCV.
    unit : {"m", "cm", "mm"}
        Length unit of the translations of an OpenCV file (JSON is always metres).
    """
    check_choice("write_cameras", "format", format, get_args(CameraFormat))
    check_choice("write_cameras", "unit", unit, get_args(CameraUnit))
    cameras = list(cameras)
    bad = [type(c).__name__ for c in cameras if not isinstance(c, Camera)]
    if not cameras or bad:
        raise InputError(
            f"write_cameras: cameras must be a non-empty sequence of Camera, found "
            f"{len(cameras)} items{' including ' + bad[0] if bad else ''}"
        )
    names = [c.name for c in cameras]
    dup = sorted({n for n in names if names.count(n) > 1})
    if dup:
        raise InputError(f"write_cameras: camera names must be distinct, found {dup} twice")
    fmt = _detect(path, None, format, "write_cameras")
    if fmt == "json":
        if unit != "m":
            raise InputError("write_cameras: unit= applies to OpenCV files; JSON is in metres")
        text = _json_text(cameras)
    else:
        odd = [n for n in names if not _NAME.match(n)]
        if odd:
            raise InputError(
                f"write_cameras: OpenCV camera names must be letters, digits, '_', '.', '-' "
                f"(they become keys such as K_<name>), found {odd[0]!r}"
            )
        text = _opencv_text(cameras, _UNIT[unit])
    write_text_atomic(path, text)


# ----------------------------------------------------------------------------- JSON
def _read_json(path, text: str) -> list[Camera]:
    try:
        doc = json.loads(text)
    except json.JSONDecodeError as e:
        raise FormatError(f"{path}:{e.lineno}: not valid JSON: {e.msg}") from None
    if isinstance(doc, dict):
        for key, want in (("format", "meshmocap.cameras"), ("version", 1), ("unit", "m")):
            if key in doc and doc[key] != want:
                raise FormatError(f"{path}: key {key!r} must be {want!r}, found {doc[key]!r}")
        if "cameras" not in doc:
            raise FormatError(f"{path}: missing key 'cameras' (a list of camera objects)")
        doc = doc["cameras"]
    if not isinstance(doc, list) or not doc:
        raise FormatError(f"{path}: expected a non-empty list of cameras, found {_short(doc)}")
    cams = []
    for i, c in enumerate(doc):
        if not isinstance(c, dict):
            raise FormatError(f"{path}: camera {i} must be an object, found {_short(c)}")
        name = c.get("name", f"cam{i}")
        where = f"{path}: camera {i} ({name!r})"
        if not isinstance(name, str):
            raise FormatError(f"{path}: camera {i}: key 'name' must be a string, found {name!r}")
        unknown = sorted(set(c) - _JSON_KEYS)
        if unknown:
            raise FormatError(f"{where}: unknown keys {unknown}, expected {sorted(_JSON_KEYS)}")
        for key in ("K", "R", "t", "width", "height"):
            if key not in c:
                raise FormatError(f"{where}: missing key {key!r}")
        K = _numbers(c["K"], where, "K", (9,), "a 3×3 matrix").reshape(3, 3)
        R = _numbers(c["R"], where, "R", (9,), "a 3×3 rotation").reshape(3, 3)
        t = _numbers(c["t"], where, "t", (3,), "3 numbers (metres)")
        dist = _numbers(c.get("dist", []), where, "dist", (0, 4, 5), "4 or 5 numbers")
        size = [_integer(c[k], where, k) for k in ("width", "height")]
        cams.append(checked_camera(where, name, K, R, t, dist, *size))
    check_unique(path, cams)
    return cams


def _json_text(cameras: list[Camera]) -> str:
    def num(x) -> str:
        return json.dumps(np.asarray(x, dtype=float).tolist())

    items = []
    for c in cameras:
        items.append(
            "    {\n"
            f'      "name": {json.dumps(c.name)},\n'
            f'      "width": {c.width},\n      "height": {c.height},\n'
            f'      "K": {num(c.K)},\n'
            f'      "R": {num(c.R)},\n'
            f'      "t": {num(c.t)},\n'
            f'      "dist": {num(c.dist)}\n'
            "    }"
        )
    return (
        '{\n  "format": "meshmocap.cameras",\n  "version": 1,\n  "unit": "m",\n'
        '  "cameras": [\n' + ",\n".join(items) + "\n  ]\n}\n"
    )


# ----------------------------------------------------------------------------- OpenCV YAML
def _load_yaml(path, text: str) -> dict:
    try:
        import yaml
    except ImportError:  # pragma: no cover - PyYAML is a dependency
        raise InputError(f"{path}: reading OpenCV YAML needs PyYAML (pip install pyyaml)") from None

    class Loader(yaml.SafeLoader):
        pass

    def matrix(loader, node):
        m = loader.construct_mapping(node, deep=True)
        return _OpenCVMatrix(m)

    Loader.add_constructor(_TAG, matrix)
    Loader.add_constructor("tag:yaml.org,2002:opencv-nd-matrix", matrix)
    if text.lstrip().startswith("<"):
        raise FormatError(f"{path}: OpenCV XML FileStorage is not supported, expected YAML")
    # PyYAML rejects OpenCV's "%YAML:1.0" directive: blank it (line numbers stay right).
    text = re.sub(r"\A(\ufeff)?%YAML:[^\n]*", "", text)
    try:
        doc = yaml.load(text, Loader=Loader)  # a SafeLoader subclass
    except yaml.YAMLError as e:
        mark = getattr(e, "problem_mark", None)
        line = f":{mark.line + 1}" if mark is not None else ""
        problem = getattr(e, "problem", None) or str(e).splitlines()[0]
        raise FormatError(f"{path}{line}: not valid YAML: {problem}") from None
    if not isinstance(doc, dict):
        raise FormatError(f"{path}: expected a YAML mapping of keys, found {_short(doc)}")
    return {str(k): v for k, v in doc.items()}


class _OpenCVMatrix(dict):
    """The mapping of an ``!!opencv-matrix`` node (rows, cols, dt, data)."""


def _cameras_from_opencv(path, doc: dict, scale: float, size, stem: str) -> list[Camera]:
    K_keys = _FIELDS["K"]
    if "names" in doc:
        names = doc["names"]
        if isinstance(names, str) or not isinstance(names, list) or not names:
            raise FormatError(
                f"{path}: key 'names' must be a non-empty list, found {_short(names)}"
            )
        names = [str(n) for n in names]
        suffixed = True
    else:
        names = [m.group(2) for k in doc if (m := re.match(rf"({'|'.join(K_keys)})_(.+)\Z", k))]
        suffixed = bool(names)
        if not names:
            if not any(k in doc for k in K_keys):
                raise FormatError(
                    f"{path}: no cameras found, expected a 'names' list or keys K_<name> "
                    f"(or camera_matrix for one camera)"
                )
            names = [str(doc.get("name", stem))]
    if len(set(names)) != len(names):
        raise FormatError(f"{path}: key 'names' lists a camera twice: {names}")
    cams = []
    for name in names:
        get = functools.partial(_lookup, doc, name if suffixed else None)
        where = f"{path}: camera {name!r}"
        key, K = get("K")
        if key is None:
            raise FormatError(f"{where}: missing key 'K_{name}' (a 3×3 !!opencv-matrix)")
        K = _numbers(K, where, key, (9,), "a 3×3 matrix").reshape(3, 3)
        key, dist = get("dist")
        dist = np.zeros(5) if key is None else _numbers(dist, where, key, None, "numbers")
        if len(dist) > 5 and np.any(dist[5:]):
            raise FormatError(
                f"{where}: key {key!r}: only (k1, k2, p1, p2, k3) distortion is supported, "
                f"found {len(dist)} coefficients with non-zero k4..."
            )
        dist = dist[:5]
        rkey, R = get("R")
        tkey, t = get("t")
        if suffixed and (rkey is None or tkey is None):
            miss = f"R_{name}" if rkey is None else f"t_{name}"
            raise FormatError(
                f"{where}: missing key {miss!r} (or an alias; pass extrinsics= for a "
                f"separate extrinsics file)"
            )
        if rkey is None:
            R = np.eye(3)
        else:
            R = _numbers(R, where, rkey, (3, 9), "a 3×3 rotation or an axis-angle 3-vector")
            R = so3_exp(R) if R.size == 3 else R.reshape(3, 3)
        t = np.zeros(3) if tkey is None else _numbers(t, where, tkey, (3,), "3 numbers")
        wh = _image_size(where, get, size)
        cams.append(checked_camera(where, name, K, R, t * scale, dist, *wh))
    return cams


def _lookup(doc: dict, name: str | None, field: str) -> tuple[str | None, object]:
    """Return the first of ``field``'s aliases (suffixed ``_<name>``) in ``doc``, and its value."""
    for alias in _FIELDS[field]:
        key = alias if name is None else f"{alias}_{name}"
        if key in doc:
            return key, doc[key]
    return None, None


def _image_size(where, get, default) -> tuple[int, int]:
    key, value = get("size")
    if key is not None:
        wh = _numbers(value, where, key, (2,), "[width, height]")
        return tuple(_integer(float(v), where, key) for v in wh)
    (wkey, w), (hkey, h) = get("width"), get("height")
    if wkey is not None and hkey is not None:
        w = _numbers(w, where, wkey, (1,), "a number")[0]
        h = _numbers(h, where, hkey, (1,), "a number")[0]
        return _integer(w, where, wkey), _integer(h, where, hkey)
    if default is not None:
        return default
    raise FormatError(
        f"{where}: no image size (keys imgSize_<name> or W_<name>/H_<name>); pass image_size="
    )


def _opencv_text(cameras: list[Camera], scale: float) -> str:
    lines = ["%YAML:1.0", "---", "names:"]
    lines += [f"   - {json.dumps(c.name)}" for c in cameras]
    for c in cameras:
        n = c.name
        lines += _matrix_lines(f"K_{n}", c.K)
        lines += _matrix_lines(f"dist_{n}", c.dist.reshape(5, 1))
        lines += _matrix_lines(f"R_{n}", c.R)
        lines += _matrix_lines(f"t_{n}", (c.t / scale).reshape(3, 1))
        lines.append(f"imgSize_{n}: [ {c.width}, {c.height} ]")
    return "\n".join(lines) + "\n"


def _matrix_lines(key: str, A: np.ndarray) -> list[str]:
    vals = [_yaml_float(x) for x in A.ravel()]
    cols = A.shape[1] if A.shape[1] > 1 else len(vals)  # vectors on one line
    rows = [", ".join(vals[i : i + cols]) for i in range(0, len(vals), cols)]
    data = ",\n       ".join(rows)
    return [
        f"{key}: !!opencv-matrix",
        f"   rows: {A.shape[0]}",
        f"   cols: {A.shape[1]}",
        "   dt: d",
        f"   data: [ {data} ]",
    ]


def _yaml_float(x: float) -> str:
    """Shortest exact decimal, always with a '.', so that YAML 1.1 reads it as a float."""
    s = repr(float(x))
    if "e" in s and "." not in s:
        s = s.replace("e", ".0e")
    return s


# ----------------------------------------------------------------------------- helpers
def checked_camera(where, name, K, R, t, dist, width, height) -> Camera:
    """A :class:`Camera` read from a file: ``R`` rounded in the file (off by up to 1e-3) is
    replaced by the nearest rotation; problems raise :class:`FormatError` after ``where``."""
    dev = np.abs(R @ R.T - np.eye(3)).max()
    if dev > 1e-3 or np.linalg.det(R) <= 0:
        raise FormatError(f"{where}: R is not a rotation (|R Rᵀ − I| = {dev:.2g}, det ≤ 0?)")
    if dev > ROTATION_SLACK:  # rounded in the file (Camera accepts that much): the nearest rotation
        U, _, Vt = np.linalg.svd(R)
        R = U @ Vt
    try:
        return Camera(K, R, t, width, height, dist, name)
    except InputError as e:
        raise FormatError(f"{where}: {e}") from None


def _numbers(value, where, key, sizes, what) -> np.ndarray:
    """Return ``value`` (an !!opencv-matrix, a nested list or a number) as a flat float64."""
    if isinstance(value, _OpenCVMatrix):
        if "data" not in value:
            raise FormatError(f"{where}: key {key!r}: !!opencv-matrix without 'data'")
        data = value["data"]
        try:
            expect = int(value["rows"]) * int(value["cols"]) if "rows" in value else None
        except (KeyError, TypeError, ValueError):
            raise FormatError(f"{where}: key {key!r}: bad rows/cols in !!opencv-matrix") from None
        value = data if isinstance(data, list) else [data]
        if expect is not None and len(value) != expect:
            raise FormatError(
                f"{where}: key {key!r}: !!opencv-matrix has rows×cols = {expect} but "
                f"{len(value)} data values"
            )
    try:
        arr = np.array(value, dtype=np.float64).ravel()
    except (TypeError, ValueError):
        raise FormatError(f"{where}: key {key!r} must be {what}, found {_short(value)}") from None
    if (sizes is not None and arr.size not in sizes) or not np.all(np.isfinite(arr)):
        raise FormatError(f"{where}: key {key!r} must be {what} (finite), found {_short(value)}")
    return arr


def _integer(value, where, key) -> int:
    if isinstance(value, bool) or not isinstance(value, int | float) or value != int(value):
        raise FormatError(f"{where}: key {key!r} must be a whole number, found {value!r}")
    if value <= 0:
        raise FormatError(f"{where}: key {key!r} must be positive, found {value!r}")
    return int(value)


def check_unique(path, cams: list[Camera]) -> None:
    """Raise :class:`FormatError` naming ``path`` when two cameras share a name."""
    names = [c.name for c in cams]
    dup = sorted({n for n in names if names.count(n) > 1})
    if dup:
        raise FormatError(f"{path}: camera names must be distinct, found {dup} twice")


def _short(value, limit: int = 60) -> str:
    s = repr(value)
    return s if len(s) <= limit else s[: limit - 3] + "..."


def _detect(path, text: str | None, fmt: str, func: str) -> str:
    if fmt != "auto":
        return fmt
    suffix = Path(path).suffix.lower()
    if suffix == ".json":
        return "json"
    if suffix in (".yml", ".yaml"):
        return "opencv"
    if text is not None:
        return "json" if text.lstrip()[:1] in ("{", "[") else "opencv"
    raise InputError(
        f"{func}: cannot tell the format of {path} from its suffix (.json, .yml, .yaml); "
        f"pass format='json' or format='opencv'"
    )


def read_text(path) -> str:
    """The UTF-8 text of the file ``path`` (a BOM dropped); one-line errors naming it."""
    p = Path(path)
    if not p.is_file():
        what = "is a folder, not a file" if p.is_dir() else "no such file"
        raise MeshmocapFileNotFoundError(f"{path}: {what}")
    try:
        return p.read_text(encoding="utf-8-sig")
    except UnicodeDecodeError as e:
        raise FormatError(f"{path}: not a text file (byte {e.start} is not UTF-8)") from None
