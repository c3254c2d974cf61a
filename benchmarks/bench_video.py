"""Silhouettes from video, measured: rendered video with truth, and the real
Pose2Sim demonstration judged by multi-view consistency.

Rendered: a synthetic capture (``meshmocap synth``, the walk, HumanEva-like four cameras)
(every 4th frame: the subject crosses the volume) is rendered as colour video: a
Lambert-shaded body with a striped texture, a room (a tiled floor, textured walls), the
body's shadow on the floor, sensor noise (σ = 3 grey levels) and H.264 compression (CRF 23).
The plates are frames of each camera's video of the empty room. ``meshmocap silhouettes``
segments it with the empty-scene plates and without them (a background learned over the
video); the masks are scored by IoU against the capture's true silhouettes.

Real: ``meshmocap silhouettes`` then ``meshmocap hull`` on the Pose2Sim demo
(``../shared/data/video/pose2sim_demo``); each camera's mask against the reprojection of
the hull (:func:`meshmocap.studio.from_video.silhouette_agreement`).

Tracks (``--tracks patch,articulated_icp``): each tracker on the rendered capture's hulls
carved from its true silhouettes and from the silhouettes segmented from its video, from
the true first pose; the mean joint error of each against the truth, and their ratio.

Usage: ``python benchmarks/bench_video.py [--frames N] [--work DIR] [--skip-real]
[--real-frames START:STOP:STEP] [--tracks patch,articulated_icp]``.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np
from PIL import Image
from scipy import ndimage

from meshmocap.geometry.raster import rasterize
from meshmocap.geometry.silhouette import silhouette
from meshmocap.io.capture import Capture, read_truth
from meshmocap.io.silhouettes import read_mask
from meshmocap.io.video import read_frames, write_video
from meshmocap.studio.from_video import silhouette_agreement, silhouettes_from_video
from meshmocap.studio.hulls import compute_hulls
from meshmocap.studio.synth import SynthSpec, synthesize

LIGHT = np.array([0.35, 0.25, -1.0]) / np.linalg.norm([0.35, 0.25, -1.0])  # sun-like key


def room(cam, seed: int) -> np.ndarray:
    """(H, W, 3) float: a tiled floor (z = 0) and textured walls seen by ``cam``."""
    rng = np.random.default_rng(seed)
    v, u = np.mgrid[: cam.height, : cam.width]
    d = np.stack([u, v, np.ones_like(u)], -1).reshape(-1, 3) @ np.linalg.inv(cam.K).T @ cam.R
    c = cam.centre
    s = np.where(d[:, 2] < -1e-6, -c[2] / np.minimum(d[:, 2], -1e-6), 1e6)
    hit = c + s[:, None] * d
    floor = ((s < 1e6) & (np.hypot(hit[:, 0], hit[:, 1]) < 5.0)).reshape(cam.shape)
    tiles = ((np.floor(hit[:, 0] / 0.5) + np.floor(hit[:, 1] / 0.5)) % 2).reshape(cam.shape)
    img = np.empty((*cam.shape, 3))
    img[...] = np.array([150.0, 140.0, 120.0])  # walls
    tex = ndimage.gaussian_filter(rng.normal(0, 1, (*cam.shape, 3)), (6, 6, 0))
    img += 40 * tex / tex.std()
    img[floor] = np.where(tiles[floor, None] > 0, [170.0, 165.0, 160.0], [110.0, 105.0, 100.0])
    return np.clip(img, 0, 255)


def render(V, F, colour, cam, background, rng) -> np.ndarray:
    """One camera's frame: shadow on the floor, the shaded body, noise (uint8)."""
    img = background.copy()
    s = -V[:, 2] / LIGHT[2]  # along the light to z = 0
    shadow = silhouette(V + s[:, None] * LIGHT, F, cam)
    img[shadow] *= 0.55
    uv, depth = cam.project(V)
    face, _ = rasterize(uv, depth, F, cam.shape)
    body = face >= 0
    n = np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]])
    n /= np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-12)
    lambert = 0.35 + 0.65 * np.abs(n @ LIGHT)
    img[body] = colour[face[body]] * lambert[face[body], None]
    return np.clip(img + rng.normal(0, 3.0, img.shape), 0, 255).astype(np.uint8)


def rendered(work: Path, n_frames: int) -> dict[str, float]:
    cap_dir = work / "synth"
    spec = SynthSpec(motion="walk", stop=4 * n_frames, step=4)  # 15 fps: the walk crosses
    cap = synthesize(cap_dir, spec, show_progress=False)
    F = cap.truth_faces
    V0 = read_truth(cap_dir / "truth" / "00000.npz").vertices
    z = V0[:, 2]
    top = np.where(z[F].mean(axis=1) > np.percentile(z, 50), 1.0, 0.0)[:, None]
    stripes = 0.8 + 0.2 * np.sign(np.sin(V0[F].mean(axis=1)[:, 2] * 40))[:, None]
    colour = (top * [60.0, 90.0, 170.0] + (1 - top) * [70.0, 60.0, 50.0]) * stripes
    videos, plates = work / "videos", work / "plates"
    videos.mkdir(exist_ok=True)
    plates.mkdir(exist_ok=True)
    rng = np.random.default_rng(0)
    t0 = time.perf_counter()
    for j, cam in enumerate(cap.cameras):
        bg = room(cam, j)
        # the plate is a frame of the same camera's video of the empty room (compressed too)
        empty = [np.clip(bg + rng.normal(0, 3.0, bg.shape), 0, 255).astype(np.uint8)] * 2
        write_video(work / "plate.mp4", empty, fps=cap.fps, quality=23)
        Image.fromarray(next(read_frames(work / "plate.mp4", [0]))[1]).save(
            plates / f"{cam.name}.png"
        )
        frames = [
            render(read_truth(cap_dir / "truth" / f"{k:05d}.npz").vertices, F, colour, cam, bg, rng)
            for k in cap.indices
        ]
        write_video(videos / f"{cam.name}.mp4", frames, fps=cap.fps, quality=23)
    print(
        f"rendered {len(cap)} frames × {len(cap.cameras)} cameras: {time.perf_counter() - t0:.0f} s"
    )
    out = {}
    for label, kw in (("plates", {"plates": plates}), ("learned", {})):
        t0 = time.perf_counter()
        dest = work / f"seg_{label}"
        silhouettes_from_video(videos, cap_dir / "cameras.json", dest, show_progress=False, **kw)
        ious = []
        for cam in cap.cameras:
            for j, k in enumerate(cap.indices):  # video frame j is capture frame k
                t = read_mask(cap_dir / "silhouettes" / cam.name / f"{k:05d}.png")
                m = read_mask(dest / "silhouettes" / cam.name / f"{j:05d}.png")
                ious.append((t & m).sum() / max((t | m).sum(), 1))
        out[label] = float(np.mean(ious))
        print(
            f"  {label:8s} IoU vs truth: mean {np.mean(ious):.3f}, min {np.min(ious):.3f} "
            f"({time.perf_counter() - t0:.0f} s)"
        )
    return out


def tracks(work: Path, labels: list[str], methods: list[str]) -> None:
    """Track the rendered capture's hulls carved from its true silhouettes and from the
    silhouettes segmented from its video (``rendered`` first), each from the true first
    pose (the papers' protocol: what is measured is the silhouettes, not the start), and
    print each track's mean joint error against the truth."""
    import shutil

    from meshmocap.api import evaluate, track

    cap_dir = work / "synth"
    truth = Capture(cap_dir)
    sources = {"true silhouettes": cap_dir}
    for label in labels:  # video frame j is capture frame truth.indices[j]
        dest = work / f"seg_{label}"
        compute_hulls(dest, voxel_size=0.01, show_progress=False)
        (dest / "truth").mkdir(exist_ok=True)
        shutil.copy(cap_dir / "truth" / "faces.npy", dest / "truth" / "faces.npy")
        for j, k in enumerate(truth.indices):
            shutil.copy(cap_dir / "truth" / f"{k:05d}.npz", dest / "truth" / f"{j:05d}.npz")
        sources[f"video, {label}"] = dest
    base = {}
    for method in methods:
        for name, src in sources.items():
            t0 = time.perf_counter()
            out = work / f"track_{method}_{Path(src).name}"
            shutil.rmtree(out, ignore_errors=True)
            tr = track(
                src,
                method=method,
                out=out,
                template="neutral",
                init="truth",
                show_progress=False,
            )
            err = evaluate(src, tr, silhouettes=False, surface_frames=0).joints.overall.mean
            base.setdefault(method, err)
            print(
                f"  {method:16s} {name:20s} mean joint error {err:6.1f} mm "
                f"({err / base[method]:.2f}× the true silhouettes'; "
                f"{time.perf_counter() - t0:.0f} s)"
            )


def real(work: Path, data: Path, frames: slice | None = None) -> None:
    dest = work / "pose2sim"
    t0 = time.perf_counter()
    run = silhouettes_from_video(
        data, data / "Calib.qca.txt", dest, frames=frames, show_progress=False
    )
    for note in run.notes:
        print("  note:", note)
    t1 = time.perf_counter()
    compute_hulls(dest, voxel_size=0.01, show_progress=False)
    t2 = time.perf_counter()
    agree = silhouette_agreement(dest)
    names = [c.name for c in Capture(dest).cameras]
    took = f"silhouettes {t1 - t0:.0f} s, hulls {t2 - t1:.0f} s"
    print(f"Pose2Sim demo: {len(run.frames)} frames, {took}")
    for j, n in enumerate(names):
        print(f"  {n}: IoU mask vs hull reprojection mean {np.nanmean(agree[:, j]):.3f}")
    print(f"  all: {np.nanmean(agree):.3f}")


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--frames", type=int, default=30, help="rendered frames (default 30)")
    p.add_argument("--work", default="/tmp/bench_video", help="work folder")
    p.add_argument("--skip-real", action="store_true", help="only the rendered capture")
    p.add_argument("--skip-rendered", action="store_true", help="only the real demo")
    p.add_argument(
        "--real-frames",
        default="",
        help="the demo's frames as start:stop:step (default: all 100)",
    )
    p.add_argument(
        "--tracks",
        default="",
        help="trackers to run on the rendered capture, comma-separated (patch,articulated_icp): "
        "joint error from the segmented video against that from the true silhouettes",
    )
    a = p.parse_args()
    work = Path(a.work)
    work.mkdir(parents=True, exist_ok=True)
    if not a.skip_rendered:
        rendered(work, a.frames)
        if a.tracks:
            tracks(work, ["plates", "learned"], a.tracks.split(","))
    data = (
        Path(__file__).resolve().parents[1] / ".." / "shared" / "data" / "video" / "pose2sim_demo"
    )
    if not a.skip_real and data.is_dir():
        sel = slice(*(int(x) if x else None for x in a.real_frames.split(":")))
        real(work, data, sel if a.real_frames else None)


if __name__ == "__main__":
    main()
