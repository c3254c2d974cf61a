"""Silhouettes from calibrated multi-view footage, end to end on a small scene made in code."""

import shutil

import numpy as np
import pytest
from PIL import Image

from meshmocap.cli import main
from meshmocap.errors import FormatError, InputError, MeshmocapFileNotFoundError
from meshmocap.geometry.camera import Camera, intrinsics, look_at
from meshmocap.geometry.foreground import others_silhouettes
from meshmocap.geometry.raster import rasterize
from meshmocap.io.calibration import write_calibration
from meshmocap.io.cameras import read_cameras
from meshmocap.io.capture import read_meta
from meshmocap.io.silhouettes import read_mask
from meshmocap.io.video import write_video
from meshmocap.studio.from_video import silhouette_agreement, silhouettes_from_video
from meshmocap.studio.hulls import compute_hulls

W, H, N = 64, 48, 10


def _rig():
    cams = []
    for k in range(4):
        a = 2 * np.pi * k / 4 + 0.3
        R, t = look_at([3 * np.cos(a), 3 * np.sin(a), 1.6], [0.0, 0.0, 1.0])
        cams.append(Camera(intrinsics(W, H, 50.0), R, t, W, H, None, f"cam{k}"))
    return cams


def _ball(cam, centre, radius=0.3):
    """Mask and shading of a ball seen by ``cam``."""
    v, u = np.mgrid[:H, :W]
    rays = np.stack([u, v, np.ones_like(u)], -1).reshape(-1, 3) @ np.linalg.inv(cam.K).T @ cam.R
    rays /= np.linalg.norm(rays, axis=1, keepdims=True)
    oc = np.asarray(centre) - cam.centre
    along = rays @ oc
    d2 = oc @ oc - along**2
    mask = (d2 < radius**2).reshape(H, W)
    shade = np.sqrt(np.clip(1 - d2 / radius**2, 0, 1)).reshape(H, W)
    return mask, shade


def _scene(tmp_path, *, mp4=True):
    """Four cameras' footage of a ball crossing a textured room, and the true masks."""
    rng = np.random.default_rng(1)
    cams = _rig()
    root = tmp_path / "videos"
    root.mkdir()
    plates = tmp_path / "plates"
    plates.mkdir()
    truth = {}
    for i, cam in enumerate(cams):
        y, x = np.mgrid[:H, :W]
        bg = np.stack(
            [90 + 40 * np.sin(x / 5 + i), 120 + 30 * np.cos(y / 4), 100 + 20 * (x % 7)], -1
        )
        bg = np.clip(bg + rng.normal(0, 4, bg.shape), 0, 255)
        Image.fromarray(bg.astype(np.uint8)).save(plates / f"{cam.name}.png")
        frames, masks = [], []
        for k in range(N):
            a = 2 * np.pi * k / N  # a circle: every camera sees it move across
            m, shade = _ball(cam, [0.8 * np.cos(a), 0.8 * np.sin(a), 1.0])
            im = bg.copy()
            im[m] = np.array([230.0, 60.0, 40.0]) * (0.5 + 0.5 * shade[m, None])
            frames.append(np.clip(im + rng.normal(0, 2, im.shape), 0, 255).astype(np.uint8))
            masks.append(m)
        truth[cam.name] = np.array(masks)
        if mp4 and i == 3:
            write_video(root / f"{cam.name}.mp4", frames, fps=30, quality=12)
        else:
            (root / cam.name).mkdir()
            for k, im in enumerate(frames):
                Image.fromarray(im).save(root / cam.name / f"frame_{k}.png")
    write_calibration(tmp_path / "Calib.toml", cams)
    return root, tmp_path / "Calib.toml", truth, plates


def _cli(videos, calib, out, *options):
    return main(
        ["silhouettes", str(videos), "--calibration", str(calib), "--out", str(out), *options]
    )


def _iou(out, truth):
    ious = []
    for name, masks in truth.items():
        for k, t in enumerate(masks):
            m = read_mask(out / "silhouettes" / name / f"{k:05d}.png")
            ious.append((m & t).sum() / max((m | t).sum(), 1))
    return float(np.mean(ious))


@pytest.mark.slow
def test_videos_to_a_capture_folder(tmp_path):
    videos, calib, truth, plates = _scene(tmp_path)
    out = tmp_path / "capture"
    run = silhouettes_from_video(videos, calib, out, scale=1.0, show_progress=False)
    assert run.frames == list(range(N)) and run.written == N and run.notes == []
    assert [c.name for c in read_cameras(out / "cameras.json")] == list(truth)
    assert read_meta(out)["fps"] == pytest.approx(30)
    assert _iou(out, truth) > 0.85  # learned background: the ball never stays
    # consistent at the end: each mask within the outline of the hull of the others (1 cm)
    for k in (0, 5):
        masks = [read_mask(out / "silhouettes" / c / f"{k:05d}.png") for c in truth]
        views = others_silhouettes(masks, _rig(), voxel_size=0.01)
        for m, v in zip(masks, views, strict=True):
            assert (m & ~v).sum() <= 0.01 * m.sum()
    again = silhouettes_from_video(videos, calib, out, scale=1.0, show_progress=False)
    assert again.written == 0  # resumes: every frame is there
    compute_hulls(out, voxel_size=0.02, show_progress=False)
    agree = silhouette_agreement(out)
    assert agree.shape == (N, 4) and np.nanmean(agree) > 0.8
    with_plates = tmp_path / "plated"
    silhouettes_from_video(videos, calib, with_plates, plates=plates, scale=1.0)
    assert _iou(with_plates, truth) > 0.9


@pytest.mark.slow
def test_offsets_frames_and_the_command_line(tmp_path, capsys):
    videos, calib, truth, _ = _scene(tmp_path, mp4=False)
    out = tmp_path / "capture"
    shifted = [a for k in range(4) for a in ("--offset", f"cam{k}=1")]  # all started early
    code = _cli(videos, calib, str(out), "--frames", "2:6", *shifted, "--scale", "1")
    assert code == 0
    assert "silhouettes of 4 frames × 4 cameras" in capsys.readouterr().out
    assert sorted(p.name for p in (out / "silhouettes" / "cam1").iterdir())[0] == "00002.png"
    # capture frame k is every video's frame k + 1: the ball one step further
    m = read_mask(out / "silhouettes" / "cam1" / "00003.png")
    t = truth["cam1"][4]
    assert (m & t).sum() / (m | t).sum() > 0.9


def test_user_errors_are_one_line(tmp_path, capsys):
    videos, calib, _, _ = _scene(tmp_path, mp4=False)
    cams = _rig()
    big = [Camera(c.K, c.R, c.t, 2 * W, 2 * H, None, c.name) for c in cams]
    write_calibration(tmp_path / "big.toml", big)
    with pytest.raises(FormatError, match=r"images of 64×48 pixels but the calibration's camera"):
        silhouettes_from_video(videos, tmp_path / "big.toml", tmp_path / "o")
    more = [*cams, Camera(cams[0].K, cams[0].R, cams[0].t, W, H, None, "cam9")]
    write_calibration(tmp_path / "more.toml", more)
    with pytest.raises(MeshmocapFileNotFoundError, match="camera 'cam9' has no video"):
        silhouettes_from_video(videos, tmp_path / "more.toml", tmp_path / "o")
    with pytest.raises(InputError, match=r"offsets for cameras \['camX'\]"):
        silhouettes_from_video(videos, calib, tmp_path / "o", offsets={"camX": 1})
    with pytest.raises(InputError, match="no frame in common"):
        silhouettes_from_video(videos, calib, tmp_path / "o", offsets={"cam0": 20})
    code = _cli(videos, calib, str(tmp_path / "o"), "--offset", "cam0")
    assert code == 2 and "expected CAMERA=FRAMES" in capsys.readouterr().err


def _render(V, F, cam, background, rng):
    """A camera's colour frame of a body: Lambert-shaded, two-toned, over ``background``,
    with sensor noise."""
    uv, depth = cam.project(V)
    face, _ = rasterize(uv, depth, F, cam.shape)
    n = np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]])
    n /= np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-12)
    upper = V[F].mean(axis=1)[:, 2] > np.median(V[:, 2])
    colour = np.where(upper[:, None], [200.0, 70.0, 50.0], [40.0, 60.0, 160.0])
    shade = 0.4 + 0.6 * np.abs(n @ np.array([0.3, 0.2, -0.93]))
    img = background.copy()
    body = face >= 0
    img[body] = colour[face[body]] * shade[face[body], None]
    return np.clip(img + rng.normal(0, 2, img.shape), 0, 255).astype(np.uint8)


@pytest.mark.slow
def test_rendered_video_silhouettes_hull_track_report(synth_capture, tmp_path, capsys):
    """The whole path from footage with default options: silhouettes → hull → track →
    report, whose section "Cameras" draws the track over each camera's video frames."""
    cap = synth_capture("walk", stop=3)
    rng = np.random.default_rng(2)
    videos, plates = tmp_path / "videos", tmp_path / "plates"
    videos.mkdir()
    plates.mkdir()
    for j, cam in enumerate(cap.cameras):
        y, x = np.mgrid[: cam.height, : cam.width]
        room = np.stack([120 + 40 * np.sin(x / 9 + j), 150 + 30 * np.cos(y / 7), 0 * x + 110], -1)
        Image.fromarray(room.astype(np.uint8)).save(plates / f"{cam.name}.png")
        frames = [_render(f.truth.vertices, cap.truth_faces, cam, room, rng) for f in cap]
        write_video(videos / f"{cam.name}.mp4", frames, fps=cap.fps, quality=12)
    out = tmp_path / "capture"
    assert _cli(videos, cap.path / "cameras.json", out, "--plates", str(plates)) == 0
    truth = {c.name: np.array([f.silhouettes[j] for f in cap]) for j, c in enumerate(cap.cameras)}
    assert _iou(out, truth) > 0.9
    assert main(["hull", str(out), "--voxel-size", "0.02"]) == 0
    shutil.copytree(cap.path / "truth", out / "truth")  # the start from the truth: no search
    track = ["track", str(out), "--out", str(tmp_path / "track"), "--method", "articulated_icp"]
    assert main([*track, "--template", "neutral_5k", "--init", "truth"]) == 0
    report = tmp_path / "report.html"
    args = ["report", str(out), str(tmp_path / "track"), "--out", str(report)]
    assert main([*args, "--surface-frames", "0", "--camera-frames", "2"]) == 0
    text = report.read_text()
    assert "<h2>Cameras</h2>" in text and text.count("data:image/jpeg;base64,") == 2
    assert 'alt="frame 0 (' in text and "cannot be read" not in text
