"""Software rendering of posed meshes and skeletons to images, for people to look at.

Flat-shaded z-buffer rendering (:func:`meshmocap.geometry.raster.rasterize`) with faces
coloured by body part, an optional skeleton overlay and a floor grid; contact sheets tile
frames into one picture. Pure numpy + Pillow: no OpenGL, works headless.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from PIL import Image, ImageDraw, ImageFont

from meshmocap._atomic import atomic_open
from meshmocap._progress import progress
from meshmocap._tolerances import ROUNDING_SLACK
from meshmocap.body.motion import Motion
from meshmocap.body.template import Template
from meshmocap.errors import InputError
from meshmocap.geometry.camera import intrinsics, look_at, project
from meshmocap.geometry.mesh import face_normals
from meshmocap.geometry.raster import rasterize

#: 15 distinct colours (RGB 0–255), one per evaluation body part; left parts warm, right cool.
PART_COLORS = np.array(
    [
        [200, 200, 200],
        [170, 150, 120],
        [235, 205, 175],
        [230, 120, 60],
        [240, 160, 60],
        [250, 210, 80],
        [60, 120, 220],
        [60, 170, 230],
        [90, 210, 210],
        [210, 60, 80],
        [230, 90, 130],
        [240, 140, 180],
        [80, 90, 200],
        [120, 100, 220],
        [170, 140, 240],
    ],
    dtype=np.uint8,
)


@dataclass(frozen=True)
class View:
    """A pinhole camera for rendering: intrinsics ``K`` (3, 3), extrinsics ``R`` (3, 3), ``t`` (3,),
    image ``size`` (width, height) in pixels."""

    K: np.ndarray
    R: np.ndarray
    t: np.ndarray
    size: tuple[int, int]


def framing_view(
    points: np.ndarray,
    *,
    size: tuple[int, int] = (480, 640),
    azimuth: float = 30.0,
    elevation: float = 10.0,
    fov: float = 35.0,
    margin: float = 1.1,
) -> View:
    """Return a view that frames all ``points`` (..., 3) (metres, Z up).

    The camera looks at the points' bounding-box centre from ``azimuth`` degrees around Z
    (0 = from the front, i.e. from −Y) and ``elevation`` degrees above the horizon, far
    enough for the bounding sphere to fit the narrower field of view.
    """
    P = np.asarray(points, dtype=float).reshape(-1, 3)
    lo, hi = P.min(axis=0), P.max(axis=0)
    centre = 0.5 * (lo + hi)
    radius = 0.5 * np.linalg.norm(hi - lo) * margin
    w, h = size
    K = intrinsics(w, h, fov)
    half = np.arctan(min(w, h) / 2 / K[0, 0])
    dist = radius / np.sin(half)
    az, el = np.deg2rad(azimuth), np.deg2rad(elevation)
    eye = centre + dist * np.array([np.sin(az) * np.cos(el), -np.cos(az) * np.cos(el), np.sin(el)])
    R, t = look_at(eye, centre)
    return View(K, R, t, (w, h))


def render_mesh(
    V: np.ndarray,
    F: np.ndarray,
    view: View,
    *,
    face_colors: np.ndarray | None = None,
    joints: np.ndarray | None = None,
    parents: np.ndarray | None = None,
    floor: bool = True,
    background: tuple[int, int, int] = (250, 250, 250),
) -> np.ndarray:
    """Return an (height, width, 3) uint8 picture of a mesh, flat-shaded.

    Parameters
    ----------
    V : (n, 3) float64, metres, world frame (Z up); F : (m, 3) int
    view : View
    face_colors : (m, 3) uint8, optional; default light grey.
    joints : (K, 3) float64, optional
        Skeleton joints drawn on top (with ``parents`` (K,) int, −1 for the root).
    floor : bool
        Draw a 0.5 m grid on the floor z = 0.
    """
    w, h = view.size
    img = Image.new("RGB", (w, h), background)
    draw = ImageDraw.Draw(img)
    if floor:
        _draw_floor(draw, V, view)
    base = np.asarray(img).copy()
    uv, depth = project(V, view.K, view.R, view.t)
    face, _ = rasterize(uv, depth, F, (h, w))
    N = face_normals(V, F)
    cam_centre = -view.R.T @ view.t
    to_cam = cam_centre - V[F].mean(axis=1)
    to_cam /= np.linalg.norm(to_cam, axis=1, keepdims=True)
    light = np.array([0.3, -0.5, 0.8]) / np.linalg.norm([0.3, -0.5, 0.8])
    shade = 0.35 + 0.45 * np.abs(np.sum(N * to_cam, axis=1)) + 0.2 * np.clip(N @ light, 0, None)
    colors = np.full((len(F), 3), 190, np.uint8) if face_colors is None else face_colors
    lit = np.clip(colors * shade[:, None], 0, 255).astype(np.uint8)
    hit = face >= 0
    base[hit] = lit[face[hit]]
    img = Image.fromarray(base)
    if joints is not None and parents is not None:
        juv, jd = project(joints, view.K, view.R, view.t)
        draw = ImageDraw.Draw(img)
        for j, p in enumerate(parents):
            if p >= 0 and jd[j] > 0 and jd[p] > 0:
                draw.line([tuple(juv[p]), tuple(juv[j])], fill=(20, 20, 20), width=max(1, w // 250))
        r = max(1.5, w / 250)
        for x, y in juv[jd > 0]:
            draw.ellipse([x - r, y - r, x + r, y + r], fill=(220, 30, 30))
    return np.asarray(img)


def _draw_floor(draw: ImageDraw.ImageDraw, V: np.ndarray, view: View) -> None:
    lo, hi = V[:, :2].min(axis=0) - 1.0, V[:, :2].max(axis=0) + 1.0
    lo, hi = np.floor(lo * 2) / 2, np.ceil(hi * 2) / 2
    for axis in (0, 1):
        for c in np.arange(lo[axis], hi[axis] + ROUNDING_SLACK, 0.5):
            a = np.array([c, lo[1 - axis], 0.0]) if axis == 0 else np.array([lo[0], c, 0.0])
            b = np.array([c, hi[1 - axis], 0.0]) if axis == 0 else np.array([hi[0], c, 0.0])
            ts = np.linspace(0, 1, 20)[:, None]
            seg = a + ts * (b - a)
            uv, d = project(seg, view.K, view.R, view.t)
            pts = [tuple(p) for p, z in zip(uv, d, strict=True) if z > 0.05]
            if len(pts) > 1:
                draw.line(pts, fill=(200, 200, 205), width=1)


def caption_font(size: int) -> ImageFont.FreeTypeFont | ImageFont.ImageFont:
    """A scalable sans-serif font of ``size`` pixels (Pillow's bundled one; matplotlib's
    DejaVu Sans with Pillow < 10.1)."""
    try:
        return ImageFont.load_default(size=size)
    except TypeError:  # Pillow < 10.1: load_default() takes no size
        from matplotlib import font_manager

        return ImageFont.truetype(font_manager.findfont("DejaVu Sans"), size)


def contact_sheet(
    images: list[np.ndarray], *, columns: int = 6, labels: list[str] | None = None
) -> np.ndarray:
    """Tile equally sized (h, w, 3) uint8 images into one picture, ``columns`` wide.

    Without ``labels`` the sheet is (rows·h, columns·w, 3). With them, each tile gets a
    caption band under it, in dark text of a fifteenth of the tile's width (at least 14
    px), so that captions stay legible when the sheet is shown shrunk (e.g. in a report):
    the sheet is then (rows·(h + band), columns·w, 3).
    """
    if not images:
        raise InputError("contact_sheet: expected at least one image, found none")
    if labels is not None and len(labels) != len(images):
        raise InputError(
            f"contact_sheet: expected {len(images)} labels (one per image), found {len(labels)}"
        )
    h, w = images[0].shape[:2]
    cols = min(columns, len(images))
    rows = -(-len(images) // cols)
    size = max(14, round(w / 15))
    band = 0 if labels is None else round(1.7 * size)
    sheet = Image.new("RGB", (cols * w, rows * (h + band)), (255, 255, 255))
    draw = ImageDraw.Draw(sheet)
    font = caption_font(size) if labels is not None else None
    for k, im in enumerate(images):
        x, y = (k % cols) * w, (k // cols) * (h + band)
        sheet.paste(Image.fromarray(im), (x, y))
        if labels is not None:
            draw.text(
                (x + w / 2, y + h + band / 2), labels[k], fill=(25, 25, 25), font=font, anchor="mm"
            )
    return np.asarray(sheet)


def save_png(path: str | os.PathLike, image: np.ndarray) -> Path:
    """Write an (h, w) or (h, w, 3) uint8 image to ``path`` atomically; return the path."""
    with atomic_open(path) as f:
        Image.fromarray(image).save(f, format="PNG")
    return Path(path)


@dataclass(frozen=True)
class RenderResult:
    """Files written by :func:`render_motion`: the frame PNGs and the contact sheet."""

    frames: tuple[Path, ...]
    sheet: Path | None


def render_motion(
    template: Template,
    motion: Motion,
    out_dir: str | os.PathLike,
    *,
    step: int = 1,
    size: tuple[int, int] = (320, 400),
    azimuth: float = 30.0,
    frames: bool = True,
    sheet: bool = True,
    columns: int = 6,
    sheet_frames: int = 12,
    show_progress: bool | None = None,
) -> RenderResult:
    """Render ``motion`` played by ``template`` to PNG frames and a contact sheet.

    Parameters
    ----------
    template : Template
        Mesh and rig; ``motion`` must be on its skeleton (see
        :func:`~meshmocap.body.retarget.retarget`).
    motion : Motion
    out_dir : path
        Folder to write ``frame_NNNNN.png`` and ``contact_sheet.png`` into (created).
    step : int
        Render every ``step``-th frame.
    size : (width, height)
        Pixels per frame.
    azimuth : float
        Camera direction in degrees around Z (0 = from the front); the camera frames the
        whole clip and does not move.
    frames, sheet : bool
        Write the individual frames / the contact sheet (``sheet_frames`` evenly spaced
        frames in ``columns`` columns).
    """
    if (
        motion.skeleton is not template.skeleton
        and motion.skeleton.names != template.skeleton.names
    ):
        raise InputError("render: the motion is not on the template's skeleton; retarget it first")
    if step < 1:
        raise InputError(f"render: step must be ≥ 1, found {step}")
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    index = np.arange(0, motion.n_frames, step)
    picks = np.linspace(0, len(index) - 1, min(sheet_frames, len(index))).round().astype(int)
    posed = template.pose(motion.rotations[index], motion.root_positions[index])
    # The camera follows the subject horizontally at a fixed distance that frames the
    # largest per-frame extent, so the body stays large and the floor grid shows motion.
    centred = (
        posed.V[:, ::7]
        - np.concatenate([motion.root_positions[index, :2], np.zeros((len(index), 1))], axis=1)[
            :, None
        ]
    )
    base_view = framing_view(centred, size=size, azimuth=azimuth)
    colors = PART_COLORS[template.part_labels[template.F[:, 0]]]
    written: list[Path] = []
    tiles: list[np.ndarray] = []
    labels: list[str] = []
    parents = template.eval_skeleton.parents
    todo = range(len(index)) if frames else picks  # a sheet alone needs only its tiles
    for k in progress(todo, label="render", enabled=show_progress):
        shift = np.array([*motion.root_positions[index[k], :2], 0.0])
        view = View(base_view.K, base_view.R, base_view.t - base_view.R @ shift, base_view.size)
        img = render_mesh(
            posed.V[k],
            template.F,
            view,
            face_colors=colors,
            joints=posed.eval_joints[k],
            parents=parents,
        )
        if frames:
            written.append(save_png(out / f"frame_{index[k]:05d}.png", img))
        if k in picks:
            tiles.append(img)
            labels.append(f"{index[k] / motion.fps:.2f} s · frame {index[k]}")
    sheet_path = (
        save_png(out / "contact_sheet.png", contact_sheet(tiles, columns=columns, labels=labels))
        if sheet
        else None
    )
    return RenderResult(tuple(written), sheet_path)
