"""Silhouettes from calibrated multi-view footage: videos + calibration → a capture folder.

:func:`silhouettes_from_video` writes the capture folder that ``meshmocap hull``,
``track`` and ``report`` read (:mod:`meshmocap.io.capture`): ``cameras.json`` (from any
calibration :func:`~meshmocap.io.calibration.read_calibration` reads), ``capture.json``
(the frame rate, the frames, each camera's footage and frame offset) and
``silhouettes/<camera>/NNNNN.png``.

Per camera, the background is an empty-scene plate when one is given, otherwise learned
over the footage in two passes (:mod:`meshmocap.geometry.foreground`): a temporal median of
a sample of frames; the sample's masks made consistent across the cameras; then the median
again without the pixels where the other cameras' carved volume says the subject stood.
That second pass removes the ghost a slow subject leaves in a plain median (what one camera
cannot tell, the others can). With plates or without, the subject's colours are learned
from the sample's consistent masks (:func:`~meshmocap.geometry.foreground.colour_model`).
Each frame's masks are then made consistent across cameras (a pixel whose ray misses the
volume carved from all the other cameras is dropped), grown by the subject's colours where
differencing lost it, made consistent again, grown where the hull of all the other cameras
(1 cm) says a part is and the colour leans to the subject (a part this camera lost:
:func:`~meshmocap.geometry.foreground.others_silhouettes`), made consistent once more at
half the voxel (the first passes keep a margin of a voxel's image around the others'
volume), trimmed to the outline of the hull of all the other cameras at 1 cm, the
hull's own voxel (without margin: with ``misses`` 0 only), cleaned (holes filled, small
components dropped) and written at the calibration's image size.
Segmentation runs at ``scale`` of the image size (by default about 1000 pixels on the
longest side: 0.52 for 1920×1080 video) with the cameras scaled to match; the masks are
resampled to the full size.

Frames are matched by index: capture frame ``k`` is frame ``k + offsets[camera]`` of that
camera's footage. The run resumes: frames whose masks exist for every camera are kept (and
the learned backgrounds are cached in ``background/<camera>.npz``) unless ``overwrite``.

Image sizes: footage that is smaller than the calibration by less than 16 pixels in a
dimension is taken as the same image cropped by the encoder to its block size at the right
or bottom (H.264 stores 1088 rows or columns for 1080); the camera's image size is then the
footage's, the intrinsics unchanged, and the run's ``notes`` say so. Any other difference is
an error.
"""

from __future__ import annotations

import json
import os
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
from PIL import Image

from meshmocap._atomic import atomic_open
from meshmocap._progress import progress
from meshmocap.errors import FormatError, InputError, MeshmocapFileNotFoundError
from meshmocap.geometry.camera import Camera
from meshmocap.geometry.foreground import (
    ColourModel,
    clean_mask,
    colour_model,
    consistent_masks,
    foreground_mask,
    grow_mask,
    learn_background,
    others_reach,
    others_silhouettes,
)
from meshmocap.geometry.silhouette import silhouette
from meshmocap.io.calibration import read_calibration
from meshmocap.io.cameras import write_cameras
from meshmocap.io.capture import Capture, CaptureFrame, frame_name, read_meta, write_meta
from meshmocap.io.silhouettes import write_mask
from meshmocap.io.video import IMAGE_SUFFIXES, Footage, find_footage, open_footage, read_frames

_CODEC_CROP = 16  # largest encoder crop taken for the same image (macroblock size)
_SEGMENT_PX = 1000  # default segmentation resolution: the longest side, pixels
_OTHERS_VOXEL = 0.01  # metres: the others' hull (a part one camera lost; the last trim)
_MODEL_VERSION = 3  # of the cached backgrounds: 2 adds the colour models, 3 keeps large holes


@dataclass(frozen=True)
class VideoRun:
    """What :func:`silhouettes_from_video` did.

    Attributes
    ----------
    path : Path, the capture folder
    frames : list of int, the capture's frame numbers
    written : int, frames segmented by this run (the others were already there)
    cameras : list of Camera, as written to ``cameras.json``
    notes : list of str, what the user should know (image sizes adapted, empty masks)
    """

    path: Path
    frames: list[int]
    written: int
    cameras: list[Camera]
    notes: list[str]


def silhouettes_from_video(
    videos: str | os.PathLike[str] | Mapping[str, str | os.PathLike[str]],
    calibration: str | os.PathLike[str] | Sequence[Camera],
    out: str | os.PathLike[str],
    *,
    frames: slice | None = None,
    offsets: Mapping[str, int] | None = None,
    plates: str | os.PathLike[str] | None = None,
    scale: float | None = None,
    voxel_size: float = 0.03,
    misses: int = 0,
    model_frames: int = 60,
    overwrite: bool = False,
    show_progress: bool | None = None,
) -> VideoRun:
    """Segment every camera's footage and write a capture folder of silhouettes.

    Parameters
    ----------
    videos : path or mapping
        A folder with one video (``<camera>.mp4``, ``.avi``, ``.mov``...) or folder of
        images (``<camera>/``) per camera of the calibration, or a mapping camera name →
        video file or image folder.
    calibration : path or sequence of Camera
        A calibration file (Qualisys ``.qca.txt``, ``Calib.toml``, ``.yml``, ``.json``) or
        the cameras.
    out : path
        The capture folder to write (created; an interrupted run resumes).
    frames : slice, optional
        Capture frame numbers to segment (default: every frame all cameras have).
    offsets : mapping camera name → int, optional
        Capture frame ``k`` is frame ``k + offset`` of that camera (default 0).
    plates : path, optional
        A folder with an empty-scene image per camera (``<camera>.png``, ``.jpg``...).
    scale : float, optional
        Segmentation resolution relative to the images (0.1 to 1; default: the largest
        image's longest side brought to about 1000 pixels, no larger than the images).
    voxel_size : float
        Voxel edge of the multi-view consistency carving, metres.
    misses : int
        Other cameras that may miss a point the consistency keeps (0: a pixel's ray must
        meet the hull of all the other cameras, and the masks are trimmed at last to
        the outline of that hull at 1 cm; 1 keeps what one camera lost, and the clutter
        two cameras see, and skips the trim).
    model_frames : int
        Frames sampled (evenly) to learn a background without plate.
    overwrite : bool
        Segment again frames that have masks (and learn the backgrounds again).
    show_progress : bool, optional
        Progress on stderr (default: when it is a terminal, else a line now and then).

    Returns
    -------
    VideoRun

    Raises
    ------
    MeshmocapFileNotFoundError
        A camera without footage, an absent file or folder.
    FormatError
        An unreadable video or calibration, footage of another size than the calibration.
    InputError
        Bad options (an offset for an unknown camera, no frame in common).
    """
    if scale is not None and not (isinstance(scale, int | float) and 0.1 <= scale <= 1.0):
        raise InputError(f"silhouettes: scale must be between 0.1 and 1, found {scale!r}")
    if not (isinstance(voxel_size, int | float) and 0.005 <= voxel_size <= 0.2):
        raise InputError(f"silhouettes: voxel_size must be 0.005 to 0.2 m, found {voxel_size!r}")
    if not (isinstance(misses, int) and misses >= 0):
        raise InputError(f"silhouettes: misses must be a whole number ≥ 0, found {misses!r}")
    if not (isinstance(model_frames, int) and model_frames >= 3):
        raise InputError(f"silhouettes: model_frames must be at least 3, found {model_frames!r}")
    cams = (
        read_calibration(calibration)
        if isinstance(calibration, str | os.PathLike)
        else list(calibration)
    )
    names = [c.name for c in cams]
    if isinstance(videos, Mapping):
        unknown = sorted(set(videos) - set(names))
        if unknown:
            raise InputError(f"silhouettes: videos for cameras {unknown} not in the calibration")
        missing = [n for n in names if n not in videos]
        if missing:
            raise MeshmocapFileNotFoundError(
                f"silhouettes: the calibration's camera {missing[0]!r} has no video"
            )
        paths = {n: Path(videos[n]) for n in names}
    else:
        paths = find_footage(videos, names)
    offsets = dict(offsets or {})
    unknown = sorted(set(offsets) - set(names))
    if unknown:
        raise InputError(f"silhouettes: offsets for cameras {unknown} not in the calibration")
    footage = {n: open_footage(paths[n]) for n in names}
    notes: list[str] = []
    cams = [_fit_size(c, footage[c.name], notes) for c in cams]
    every = _capture_frames(footage, offsets, None)
    numbers = _capture_frames(footage, offsets, frames)
    root = Path(out)
    for sub in ["background", *(f"silhouettes/{n}" for n in names)]:
        (root / sub).mkdir(parents=True, exist_ok=True)
    if (root / "capture.json").is_file():
        old = read_meta(root)
        if old.get("source") not in (None, "video"):
            raise InputError(f"silhouettes: {root} holds another kind of capture; use a new folder")
    write_cameras(root / "cameras.json", cams)
    fps = next((f.fps for f in footage.values() if f.fps), None)
    meta = {
        "source": "video",
        "frames": numbers,
        "cameras": names,
        # where each camera's frames come from: the report draws the track over them
        "videos": {n: str(paths[n].resolve()) for n in names},
        "offsets": {n: int(offsets.get(n, 0)) for n in names},
    }
    write_meta(root / "capture.json", meta | ({"fps": fps} if fps else {}))
    todo = [
        k
        for k in numbers
        if overwrite
        or not all((root / "silhouettes" / n / f"{frame_name(k)}.png").is_file() for n in names)
    ]
    if not todo:
        return VideoRun(root, numbers, 0, cams, notes)
    if scale is None:
        scale = min(1.0, _SEGMENT_PX / max(max(c.width, c.height) for c in cams))
    small = [_scaled(c, scale) for c in cams]
    models = _backgrounds(
        root, cams, small, footage, offsets, every, plates, model_frames, voxel_size, overwrite
    )
    streams = {
        c.name: read_frames(
            footage[c.name], [k + offsets.get(c.name, 0) for k in todo], size=(s.width, s.height)
        )
        for c, s in zip(cams, small, strict=True)
    }
    empty = {n: 0 for n in names}
    for k in progress(todo, label="silhouettes", enabled=show_progress):
        images = [next(streams[n])[1] for n in names]
        masks = [
            clean_mask(foreground_mask(im, *models[n][:2]), keep=0.0)
            for im, n in zip(images, names, strict=True)
        ]
        masks = consistent_masks(masks, small, voxel_size=voxel_size, misses=misses)
        # the subject's colours where differencing lost it
        masks = [
            grow_mask(im, m, models[n][2]) for im, m, n in zip(images, masks, names, strict=True)
        ]
        masks = consistent_masks(masks, small, voxel_size=voxel_size, misses=misses)
        # a part every other camera sees: lost by this one (its colour evidence weaker)
        views = others_silhouettes(masks, small, voxel_size=_OTHERS_VOXEL)
        masks = [
            m if v is None else grow_mask(im, m, models[n][2], threshold=0.0, within=v)
            for im, m, n, v in zip(images, masks, names, views, strict=True)
        ]
        # carved again, finer: the first passes keep a margin of a voxel's image
        fine = max(voxel_size / 2, 0.01)
        masks = consistent_masks(masks, small, voxel_size=fine, misses=misses)
        if misses == 0:
            # and trimmed to the outline of the others' hull at the hull's 1 cm: the
            # margins above keep pixels no other camera confirms
            views = others_silhouettes(masks, small, voxel_size=_OTHERS_VOXEL)
            masks = [m if v is None else m & v for m, v in zip(masks, views, strict=True)]
        for cam, m in zip(cams, masks, strict=True):
            m = clean_mask(m, open_px=0, close_px=0)
            empty[cam.name] += not m.any()
            write_mask(root / "silhouettes" / cam.name / f"{frame_name(k)}.png", _full(m, cam))
    for n in names:
        if empty[n]:
            notes.append(f"{n}: {empty[n]} of {len(todo)} frames without foreground")
    return VideoRun(root, numbers, len(todo), cams, notes)


def silhouette_agreement(
    capture: str | os.PathLike[str], *, frames: Sequence[int] | None = None
) -> np.ndarray:
    """How well each camera's silhouette agrees with the reprojection of the visual hull.

    The check of footage without ground truth: the hull is carved from all the cameras,
    so a camera whose mask holds clutter the others do not see, or misses a limb they see,
    disagrees with it.

    Parameters
    ----------
    capture : path
        A capture folder with ``silhouettes/`` and ``hulls/`` (``meshmocap hull``).
    frames : sequence of int, optional
        Frame numbers (default: every frame with a hull).

    Returns
    -------
    (n_frames, n_cameras) float64
        Intersection over union of each mask and the hull's silhouette in that camera
        (NaN for a frame without hull).
    """
    cap = Capture(capture)
    numbers = cap.indices if frames is None else list(frames)
    out = np.full((len(numbers), len(cap.cameras)), np.nan)
    for i, k in enumerate(numbers):
        frame = CaptureFrame(k, cap)
        if frame.missing is not None:
            continue
        V, F = frame.hull_mesh
        for j, (cam, mask) in enumerate(zip(cap.cameras, frame.silhouettes, strict=True)):
            hull = silhouette(V, F, cam, assume_closed=True)
            out[i, j] = (hull & mask).sum() / max(int((hull | mask).sum()), 1)
    return out


# ----------------------------------------------------------------------------- helpers
def _fit_size(cam: Camera, fo: Footage, notes: list[str]) -> Camera:
    if (fo.width, fo.height) == (cam.width, cam.height):
        return cam
    dw, dh = cam.width - fo.width, cam.height - fo.height
    if 0 <= dw < _CODEC_CROP and 0 <= dh < _CODEC_CROP:
        notes.append(
            f"{cam.name}: {fo.path.name} is {fo.width}×{fo.height}, the calibration "
            f"{cam.width}×{cam.height}: taken as the same image cropped at the right/bottom"
        )
        return replace(cam, width=fo.width, height=fo.height)
    raise FormatError(
        f"{fo.path}: images of {fo.width}×{fo.height} pixels but the calibration's camera "
        f"{cam.name!r} is {cam.width}×{cam.height} (width×height)"
    )


def _capture_frames(footage: dict[str, Footage], offsets: dict, frames: slice | None) -> list[int]:
    lo = max(max(0, -offsets.get(n, 0)) for n in footage)
    hi = min(f.n_frames - offsets.get(n, 0) for n, f in footage.items())
    if hi <= lo:
        raise InputError(
            "silhouettes: the cameras' footage has no frame in common with these offsets "
            + ", ".join(f"{n}: {f.n_frames} frames" for n, f in footage.items())
        )
    numbers = list(range(lo, hi))
    if frames is not None:
        numbers = (
            numbers[frames]
            if frames.start is None
            else [k for k in range(*frames.indices(hi)) if k >= lo]
        )
        if not numbers:
            raise InputError(f"silhouettes: --frames selects none of the frames {lo}..{hi - 1}")
    return numbers


def _scaled(cam: Camera, s: float) -> Camera:
    """The camera of the image resampled by ``s`` (pixel centres stay centres)."""
    if s == 1.0:
        return cam
    w, h = max(1, round(cam.width * s)), max(1, round(cam.height * s))
    sx, sy = w / cam.width, h / cam.height
    K = cam.K.copy()
    K[0] *= sx
    K[1] *= sy
    K[0, 2] += 0.5 * sx - 0.5
    K[1, 2] += 0.5 * sy - 0.5
    return Camera(K, cam.R, cam.t, w, h, cam.dist, cam.name)


def _full(mask: np.ndarray, cam: Camera) -> np.ndarray:
    if mask.shape == cam.shape:
        return mask
    img = Image.fromarray(mask.astype(np.uint8) * 255).resize(
        (cam.width, cam.height), Image.BILINEAR
    )
    return np.asarray(img) > 127


def _plate(folder: Path, name: str, size: tuple[int, int]) -> np.ndarray:
    hits = [folder / f"{name}{s}" for s in IMAGE_SUFFIXES if (folder / f"{name}{s}").is_file()]
    if not hits:
        raise MeshmocapFileNotFoundError(
            f"{folder}: camera {name!r} has no empty-scene plate {name}.png (or .jpg, ...)"
        )
    return next(read_frames(hits[0], [0], size=size))[1]


def _backgrounds(
    root, cams, small, footage, offsets, numbers, plates, model_frames, voxel_size, overwrite
) -> dict[str, tuple[np.ndarray, np.ndarray, ColourModel | None]]:
    """Each camera's background, its noise, and its colour model."""
    models: dict[str, tuple[np.ndarray, np.ndarray, ColourModel | None]] = {}
    pick = np.unique(np.linspace(0, len(numbers) - 1, min(model_frames, len(numbers))).round())
    sample = [numbers[int(i)] for i in pick]
    if plates is not None:
        for c, s in zip(cams, small, strict=True):
            plate = _plate(Path(plates), c.name, (s.width, s.height)).astype(np.float32)
            models[c.name] = (plate, np.float32(3.0), None)
        stacks = _sample(cams, small, footage, offsets, sample)
        return _colours(models, stacks, cams, small, voxel_size)
    cache = {c.name: root / "background" / f"{c.name}.npz" for c in cams}
    key = json.dumps(
        [_MODEL_VERSION, [s.width for s in small], numbers[0], numbers[-1], model_frames]
    )
    if not overwrite and all(p.is_file() for p in cache.values()):
        try:
            for n, p in cache.items():
                with np.load(p) as z:
                    if str(z["key"]) != key:
                        raise KeyError
                    colour = ColourModel(z["log_ratio"], z["region"], int(z["bins"]))
                    models[n] = (z["background"], z["noise"], colour)
            return models
        except (KeyError, OSError, ValueError):
            models.clear()
    stacks = _sample(cams, small, footage, offsets, sample)
    first = {n: learn_background(st) for n, st in stacks.items()}
    # where the volume carved from the other cameras says the subject may stand
    keep = {n: np.zeros(st.shape[:3], bool) for n, st in stacks.items()}
    for j in range(len(sample)):
        masks = [clean_mask(foreground_mask(stacks[c.name][j], *first[c.name])) for c in cams]
        for c, r in zip(cams, others_reach(masks, small, voxel_size=voxel_size), strict=True):
            keep[c.name][j] = False if r is None else r
    for c in cams:
        st = stacks[c.name]
        models[c.name] = (*learn_background(st, masks=keep[c.name]), None)
    models = _colours(models, stacks, cams, small, voxel_size)
    for c in cams:
        bg, noise, colour = models[c.name]
        with atomic_open(cache[c.name]) as f:
            np.savez(
                f,
                background=bg,
                noise=noise,
                log_ratio=colour.log_ratio,
                region=colour.region,
                bins=colour.bins,
                key=np.array(key),
            )
    return models


def _sample(cams, small, footage, offsets, sample) -> dict[str, np.ndarray]:
    """Each camera's frames ``sample`` at the segmentation size, (n, h, w, 3) uint8."""
    stacks = {}
    for c, s in zip(cams, small, strict=True):
        off = offsets.get(c.name, 0)
        got = read_frames(footage[c.name], [k + off for k in sample], size=(s.width, s.height))
        stacks[c.name] = np.stack([im for _, im in got])
    return stacks


def _colours(models, stacks, cams, small, voxel_size):
    """``models`` with each camera's colour model, learned from 20 of the sample's masks
    made consistent across the cameras."""
    n = len(next(iter(stacks.values())))
    some = np.unique(np.linspace(0, n - 1, min(20, n)).round()).astype(int)
    found = {c.name: np.zeros((len(some), *stacks[c.name].shape[1:3]), bool) for c in cams}
    for i, j in enumerate(some):
        masks = [
            clean_mask(foreground_mask(stacks[c.name][j], *models[c.name][:2]), keep=0.0)
            for c in cams
        ]
        for c, m in zip(cams, consistent_masks(masks, small, voxel_size=voxel_size), strict=True):
            found[c.name][i] = clean_mask(m, open_px=0, close_px=0)
    return {
        c.name: (*models[c.name][:2], colour_model(stacks[c.name][some], found[c.name]))
        for c in cams
    }
