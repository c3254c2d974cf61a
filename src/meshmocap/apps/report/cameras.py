"""The report's camera views: each camera's frames with the silhouette's outline and the
tracked skeleton projected over them, so that a person judges a track at a glance.

The backdrop of a camera's view is its video frame when the capture was made from video
(``meshmocap silhouettes`` records each camera's footage and frame offset in
``capture.json``) and the footage is still where it was; otherwise the silhouette itself,
in grey. Over it: the silhouette's outline (green) and the track's 15 evaluation joints
projected through the camera, lens distortion included (bones in red, joints as dots).
"""

from __future__ import annotations

import io
import os
from collections.abc import Sequence
from pathlib import Path

import numpy as np
from PIL import Image, ImageDraw
from scipy import ndimage

from meshmocap._tolerances import NEAR_DEPTH
from meshmocap.errors import FormatError, InputError, MeshmocapFileNotFoundError
from meshmocap.geometry.camera import Camera
from meshmocap.io.capture import Capture, frame_name
from meshmocap.io.results import Track
from meshmocap.io.silhouettes import read_mask
from meshmocap.io.video import read_frames

#: Colours (RGB) of the silhouette's outline, the bones and the joints.
OUTLINE_COLOR = (60, 220, 90)
BONE_COLOR = (235, 40, 40)
JOINT_COLOR = (255, 230, 40)


def overlay(
    image: np.ndarray,
    camera: Camera,
    *,
    mask: np.ndarray | None = None,
    joints: np.ndarray | None = None,
    parents: Sequence[int] | np.ndarray | None = None,
) -> np.ndarray:
    """Draw a silhouette's outline and a skeleton over a camera's image.

    Parameters
    ----------
    image : (h, w, 3) uint8, RGB
        The backdrop, the camera's image at any size (the camera's pixels are scaled to it).
    camera : Camera
        The calibrated camera of the image (``camera.width × camera.height`` pixels).
    mask : (h, w) bool, optional
        The silhouette, at the image's size; its one-pixel outline is drawn.
    joints : (K, 3) float64, metres, world frame, optional
        Joints to project (those behind the camera are not drawn).
    parents : (K,) int, optional
        Each joint's parent (−1 for the root): a bone is drawn to it.

    Returns
    -------
    (h, w, 3) uint8
    """
    img = np.asarray(image)
    if img.ndim != 3 or img.shape[2] != 3 or img.dtype != np.uint8:
        raise InputError(f"overlay: image must be (h, w, 3) uint8, found {img.shape} {img.dtype}")
    h, w = img.shape[:2]
    out = img.copy()
    if mask is not None:
        m = np.asarray(mask, bool)
        if m.shape != (h, w):
            raise InputError(f"overlay: mask must be {(h, w)} like the image, found {m.shape}")
        edge = m & ~ndimage.binary_erosion(m, border_value=0)
        if h >= 900:  # thicker on large images (iterations=0 would dilate to the end)
            edge = ndimage.binary_dilation(edge, iterations=round(h / 600))
        out[edge] = OUTLINE_COLOR
    if joints is None:
        return out
    J = np.asarray(joints, np.float64)
    if J.ndim != 2 or J.shape[1] != 3:
        raise InputError(f"overlay: joints must be (K, 3), found {J.shape}")
    uv, depth = camera.project(J)
    sx, sy = w / camera.width, h / camera.height
    uv = np.stack([(uv[:, 0] + 0.5) * sx - 0.5, (uv[:, 1] + 0.5) * sy - 0.5], axis=1)
    seen = (depth > NEAR_DEPTH) & np.all(np.isfinite(uv), axis=1) & np.all(np.abs(uv) < 1e5, axis=1)
    pic = Image.fromarray(out)
    draw = ImageDraw.Draw(pic)
    width = max(1, round(max(h, w) / 180))
    if parents is not None:
        for j, p in enumerate(np.asarray(parents).tolist()):
            if p >= 0 and seen[j] and seen[p]:
                draw.line([tuple(uv[p]), tuple(uv[j])], fill=BONE_COLOR, width=width)
    r = 1.0 * width
    for x, y in uv[seen]:
        draw.ellipse([x - r, y - r, x + r, y + r], fill=JOINT_COLOR)
    return np.asarray(pic)


def backdrops(
    capture: Capture, indices: Sequence[int], height: int
) -> tuple[list[list[np.ndarray]], str]:
    """Each camera's images of frames ``indices``: its video frames when the capture records
    its footage (``capture.json``'s ``videos`` and ``offsets``) and the footage can be read,
    else the silhouettes in grey.

    Parameters
    ----------
    capture : Capture, with cameras and silhouettes
    indices : sequence of int, the capture's frame numbers
    height : int, pixels: every image is resampled to this height (aspect kept)

    Returns
    -------
    images : per camera, a list of (height, w, 3) uint8, one per frame
    note : str, empty, or why the silhouettes stand in for the video
    """
    videos = capture.meta.get("videos")
    videos = videos if isinstance(videos, dict) else {}
    offsets = capture.meta.get("offsets")
    offsets = offsets if isinstance(offsets, dict) else {}
    note = "" if videos else "the capture was not made from video: each camera shows its silhouette"
    out = []
    for cam in capture.cameras:
        wh = (max(1, round(cam.width * height / cam.height)), height)
        src = videos.get(cam.name)
        if src is not None:
            try:
                at = [k + int(offsets.get(cam.name, 0)) for k in indices]
                got = dict(read_frames(Path(os.fspath(src)), at, size=wh))
                out.append([got[k] for k in at])
                continue
            except (MeshmocapFileNotFoundError, FormatError, InputError, TypeError, ValueError):
                note = (
                    note or f"{cam.name}: its video {src} cannot be read: the silhouette is shown"
                )
        pics = []
        for k in indices:
            path = capture.path / "silhouettes" / cam.name / f"{frame_name(k)}.png"
            m = read_mask(path) if path.is_file() else np.zeros(cam.shape, bool)
            grey = Image.fromarray(np.where(m, np.uint8(150), np.uint8(235))).resize(wh)
            pics.append(np.repeat(np.asarray(grey)[..., None], 3, axis=2))
        out.append(pics)
    return out, note


def camera_views(
    capture: Capture,
    track: Track,
    parents: Sequence[int] | np.ndarray,
    *,
    frames: int = 4,
    height: int = 320,
) -> tuple[list[tuple[str, bytes]], str]:
    """Pictures of the track over the capture's cameras: per chosen frame, every camera's
    image side by side with the silhouette's outline and the projected skeleton.

    Parameters
    ----------
    capture : Capture with cameras
    track : Track of that capture
    parents : (K,) int, the evaluation skeleton's parents (−1 for the root)
    frames : int, how many frames, evenly spread over the track's (the first and the last
        included)
    height : int, pixels, each camera's image height in the pictures

    Returns
    -------
    pictures : list of (caption, JPEG bytes), one per chosen frame
    note : str, empty, or why a camera shows its silhouette instead of its video
    """
    if not capture.cameras:
        return [], ""
    if not (isinstance(frames, int) and frames >= 1):
        raise InputError(f"camera_views: frames must be a whole number ≥ 1, found {frames!r}")
    have = set(capture.indices)
    rows = [i for i, k in enumerate(track.frames.tolist()) if k in have]
    if not rows:
        return [], "the track has no frame of the capture"
    pick = sorted({rows[round(p)] for p in np.linspace(0, len(rows) - 1, frames)})
    indices = [int(track.frames[i]) for i in pick]
    images, note = backdrops(capture, indices, height)
    names = " · ".join(c.name for c in capture.cameras)
    gap = np.full((height, 4, 3), 255, np.uint8)
    pictures = []
    for f, (i, k) in enumerate(zip(pick, indices, strict=True)):
        tiles = []
        for cam, pics in zip(capture.cameras, images, strict=True):
            small = pics[f]
            path = capture.path / "silhouettes" / cam.name / f"{frame_name(k)}.png"
            mask = None
            if path.is_file():
                big = Image.fromarray(read_mask(path).astype(np.uint8) * 255)
                mask = np.asarray(big.resize(small.shape[1::-1], Image.BILINEAR)) > 127
            tiles.append(overlay(small, cam, mask=mask, joints=track.joints[i], parents=parents))
        strip = np.concatenate([t for tile in tiles for t in (tile, gap)][:-1], axis=1)
        buf = io.BytesIO()
        Image.fromarray(strip).save(buf, format="JPEG", quality=85)
        flags = ", ".join(track.flags[i]) if track.flags and track.flags[i] else ""
        caption = f"frame {k} ({names})" + (f": flagged {flags}" if flags else "")
        pictures.append((caption, buf.getvalue()))
    return pictures, note
