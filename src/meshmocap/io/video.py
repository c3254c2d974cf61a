"""Camera footage: video files (decoded by PyAV, which bundles FFmpeg) or folders of images.

A camera's footage is either a video file (``.mp4``, ``.avi``, ``.mov``, ``.mkv``, any
codec FFmpeg decodes) or a folder of images (``.png``, ``.jpg``, ``.jpeg``, ``.bmp``,
``.tif``, ``.tiff``) whose frame order is the natural order of the file names
(``img2.png`` before ``img10.png``). Frame ``k`` is the ``k``-th decoded picture
(0-based), whatever the container's timestamps say. Frames are ``(height, width, 3)``
uint8 RGB arrays, row 0 at the top (the pixel grid of :mod:`meshmocap.geometry.camera`).

:func:`find_footage` matches the cameras of a calibration to the footage in a folder by
name (``cam01.mp4`` or ``cam01/`` for camera ``cam01``, case ignored).
"""

from __future__ import annotations

import os
import re
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from PIL import Image, UnidentifiedImageError

from meshmocap.errors import FormatError, InputError, MeshmocapFileNotFoundError

#: Suffixes of the video files read (through PyAV).
VIDEO_SUFFIXES = (".mp4", ".avi", ".mov", ".mkv", ".m4v", ".webm")
#: Suffixes of the images of a folder of frames.
IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff")


@dataclass(frozen=True)
class Footage:
    """One camera's footage.

    Attributes
    ----------
    path : Path, the video file or the folder of images
    n_frames : int, number of frames (a video's is counted by decoding when its header
        does not say it)
    width, height : int, pixels
    fps : float or None, frames per second (None for a folder of images)
    """

    path: Path
    n_frames: int
    width: int
    height: int
    fps: float | None


def open_footage(path: str | os.PathLike[str]) -> Footage:
    """Describe a camera's footage (a video file or a folder of images).

    Raises
    ------
    MeshmocapFileNotFoundError
        No such file or folder, or a folder without images.
    FormatError
        A file that is not a readable video (one line naming it).
    """
    p = Path(path)
    if p.is_dir():
        files = _images(p)
        first = _read_image(files[0])
        return Footage(p, len(files), first.shape[1], first.shape[0], None)
    if not p.is_file():
        raise MeshmocapFileNotFoundError(f"{path}: no such video file or folder of images")
    av = _av()
    try:
        with av.open(str(p)) as container:
            if not container.streams.video:
                raise FormatError(f"{path}: holds no video stream")
            stream = container.streams.video[0]
            n = int(stream.frames or 0)
            width, height = stream.codec_context.width, stream.codec_context.height
            rate = stream.average_rate or stream.base_rate
            fps = float(rate) if rate else None
            if n <= 0 or not width:  # the header does not say: count by decoding
                n = 0
                for frame in container.decode(video=0):
                    n += 1
                    width, height = frame.width, frame.height
    except av.error.FFmpegError as e:
        raise FormatError(f"{path}: not a readable video ({_first_line(e)})") from None
    if n == 0:
        raise FormatError(f"{path}: a video without frames")
    return Footage(p, n, int(width), int(height), fps)


def read_frames(
    footage: Footage | str | os.PathLike[str],
    frames: Sequence[int] | None = None,
    *,
    size: tuple[int, int] | None = None,
) -> Iterator[tuple[int, np.ndarray]]:
    """Yield ``(k, image)`` for the footage's frames ``k`` in ``frames`` (default: all).

    Parameters
    ----------
    footage : Footage or path
    frames : sequence of int, optional
        Frame indices (0-based), any order: yielded in increasing order, each once. A video
        is decoded from its start to the last one asked for.
    size : (width, height), optional
        Resample every frame to this size (bilinear), pixels.

    Yields
    ------
    k : int
    image : (height, width, 3) uint8, RGB

    Raises
    ------
    InputError
        An index outside the footage.
    FormatError
        A video that stops decoding early, or an unreadable image.
    """
    fo = footage if isinstance(footage, Footage) else open_footage(footage)
    wanted = sorted(set(range(fo.n_frames) if frames is None else (int(k) for k in frames)))
    if not wanted:
        return
    if wanted[0] < 0 or wanted[-1] >= fo.n_frames:
        bad = wanted[0] if wanted[0] < 0 else wanted[-1]
        raise InputError(f"{fo.path}: frame {bad} asked for, the footage has {fo.n_frames}")
    if fo.path.is_dir():
        files = _images(fo.path)
        for k in wanted:
            img = _read_image(files[k])
            if size is not None and (img.shape[1], img.shape[0]) != tuple(size):
                img = np.asarray(Image.fromarray(img).resize(tuple(size), Image.BILINEAR))
            yield k, img
        return
    av = _av()
    want = set(wanted)
    last = wanted[-1]
    k = -1
    try:
        with av.open(str(fo.path)) as container:
            container.streams.video[0].thread_type = "AUTO"
            for k, frame in enumerate(container.decode(video=0)):
                if k in want:
                    if size is not None:
                        frame = frame.reformat(width=size[0], height=size[1])
                    yield k, frame.to_ndarray(format="rgb24")
                if k >= last:
                    break
    except av.error.FFmpegError as e:
        raise FormatError(
            f"{fo.path}: video unreadable at frame {k + 1} ({_first_line(e)})"
        ) from None
    if k < last:
        raise FormatError(f"{fo.path}: the video ends at frame {k}, frame {last} asked for")


def write_video(
    path: str | os.PathLike[str],
    frames: np.ndarray | Sequence[np.ndarray],
    *,
    fps: float = 30.0,
    quality: int = 23,
) -> None:
    """Encode frames as a video file (H.264 for ``.mp4``/``.mov``/``.mkv``, MPEG-4 part 2
    for ``.avi``), written to a temporary file and renamed, so never left half-written.

    Parameters
    ----------
    path : str or path-like
    frames : (n, height, width, 3) uint8 or a sequence of such images, RGB; even sizes
    fps : float, frames per second
    quality : int
        H.264 constant rate factor (0 lossless, 23 FFmpeg's default, 51 worst); for
        MPEG-4, the quantiser ``1 + quality // 4``.
    """
    av = _av()
    p = Path(path)
    suffix = p.suffix.lower()
    if suffix not in (".mp4", ".mov", ".mkv", ".avi"):
        raise InputError(f"write_video: {path}: expected a .mp4, .mov, .mkv or .avi file")
    images = list(frames)
    if not images:
        raise InputError("write_video: no frames")
    H, W = images[0].shape[:2]
    if H % 2 or W % 2 or any(im.shape != (H, W, 3) for im in images):
        raise InputError(
            f"write_video: frames must all be (height, width, 3) with even sizes, found "
            f"{images[0].shape}"
        )
    tmp = p.with_name(f".{p.stem}.part{p.suffix}")
    try:
        with av.open(str(tmp), "w") as container:
            codec = "mpeg4" if suffix == ".avi" else "libx264"
            options = (
                {"qscale": str(1 + quality // 4)} if codec == "mpeg4" else {"crf": str(quality)}
            )
            stream = container.add_stream(codec, rate=round(fps), options=options)
            stream.width, stream.height, stream.pix_fmt = W, H, "yuv420p"
            for im in images:
                frame = av.VideoFrame.from_ndarray(np.ascontiguousarray(im, np.uint8), "rgb24")
                container.mux(stream.encode(frame))
            container.mux(stream.encode(None))
        os.replace(tmp, p)
    finally:
        tmp.unlink(missing_ok=True)


def find_footage(folder: str | os.PathLike[str], names: Sequence[str]) -> dict[str, Path]:
    """Match camera names to footage in ``folder``: ``<name>.<video suffix>`` or ``<name>/``.

    Raises
    ------
    MeshmocapFileNotFoundError
        ``folder`` is absent, or a camera has no footage (one line naming the camera and
        what was looked for).
    InputError
        A camera matches two entries.
    """
    root = Path(folder)
    if not root.is_dir():
        raise MeshmocapFileNotFoundError(f"{folder}: no such folder of videos")
    entries: dict[str, list[Path]] = {}
    for p in sorted(root.iterdir()):
        if (p.is_dir() or p.suffix.lower() in VIDEO_SUFFIXES) and not p.name.startswith("."):
            entries.setdefault((p.stem if p.is_file() else p.name).lower(), []).append(p)
    found = {}
    for name in names:
        hits = entries.get(name.lower(), [])
        if not hits:
            have = sorted(p.name for ps in entries.values() for p in ps if p.is_file())
            have = ", ".join(have[:8]) + (", ..." if len(have) > 8 else "")
            raise MeshmocapFileNotFoundError(
                f"{root}: the calibration's camera {name!r} has no video ({name}.mp4, .avi, "
                f".mov, ...) or folder of images {name}/; videos there: {have or 'none'}"
            )
        if len(hits) > 1:
            raise InputError(f"{root}: camera {name!r} matches {[p.name for p in hits]}; keep one")
        found[name] = hits[0]
    return found


# ----------------------------------------------------------------------------- helpers
def _av():
    try:
        import av
    except ImportError:  # pragma: no cover - a dependency
        raise InputError("reading videos needs PyAV (pip install av)") from None
    return av


def _natural(p: Path) -> list:
    return [int(s) if s.isdigit() else s.lower() for s in re.split(r"(\d+)", p.name)]


def _images(folder: Path) -> list[Path]:
    files = sorted(
        (p for p in folder.iterdir() if p.suffix.lower() in IMAGE_SUFFIXES and p.is_file()),
        key=_natural,
    )
    if not files:
        raise MeshmocapFileNotFoundError(
            f"{folder}: a folder without images ({', '.join(IMAGE_SUFFIXES)})"
        )
    return files


def _read_image(path: Path) -> np.ndarray:
    try:
        with Image.open(path) as img:
            return np.asarray(img.convert("RGB"))
    except (UnidentifiedImageError, OSError, SyntaxError, ValueError) as e:
        raise FormatError(f"{path}: not a readable image ({_first_line(e)})") from None


def _first_line(e: Exception) -> str:
    s = str(e).strip()
    return s.splitlines()[0] if s else type(e).__name__
