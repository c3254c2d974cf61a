"""The report's camera views: outline and skeleton land where the camera sees them, video
frames as backdrop when the capture records its footage, silhouettes otherwise."""

import json

import numpy as np
import pytest

from meshmocap.apps.report.cameras import (
    BONE_COLOR,
    JOINT_COLOR,
    OUTLINE_COLOR,
    backdrops,
    camera_views,
    overlay,
)
from meshmocap.body.template import EVAL_PARENTS
from meshmocap.errors import InputError
from meshmocap.geometry.camera import Camera, intrinsics, look_at
from meshmocap.io.capture import Capture
from meshmocap.io.results import FrameResult, read_track, start_track, write_frame
from meshmocap.io.video import write_video


def _camera(w=80, h=60):
    R, t = look_at([3.0, 0.0, 1.0], [0.0, 0.0, 1.0])
    return Camera(intrinsics(w, h, 50.0), R, t, w, h, None, "c")


def test_overlay_draws_the_outline_and_the_projected_joints():
    cam = _camera()
    image = np.zeros((120, 160, 3), np.uint8)  # twice the camera's size
    mask = np.zeros((120, 160), bool)
    mask[30:90, 40:120] = True
    J = np.array([[0.0, 0.0, 1.0], [0.0, 0.3, 1.3]])
    out = overlay(image, cam, mask=mask, joints=J, parents=[-1, 0])
    assert out.shape == image.shape and out.dtype == np.uint8
    assert (out[30, 60] == OUTLINE_COLOR).all() and (out[60, 60] == 0).all()
    uv, _ = cam.project(J)
    u, v = np.round((uv + 0.5) * 2 - 0.5).astype(int).T
    near = out[v[0] - 1 : v[0] + 2, u[0] - 1 : u[0] + 2]
    assert (near == JOINT_COLOR).all(axis=2).any()  # the joint lands at its projection
    m = np.round(((uv[0] + uv[1]) / 2 + 0.5) * 2 - 0.5).astype(int)
    assert (out[m[1] - 1 : m[1] + 2, m[0] - 1 : m[0] + 2] == BONE_COLOR).all(axis=2).any()
    behind = overlay(image, cam, joints=np.array([[5.0, 0.0, 1.0]]), parents=[-1])
    assert not behind.any()  # a joint behind the camera is not drawn
    with pytest.raises(InputError, match="mask must be"):
        overlay(image, cam, mask=mask[:10])


def _truth_track(capture, folder):
    meta = {"method": "truth", "template": "subject_body", "eval_parents": EVAL_PARENTS.tolist()}
    start_track(folder, meta, capture.truth_faces, resume=False)
    for f in capture:
        t = f.truth
        write_frame(folder, FrameResult(f.index, t.joints, t.vertices, seconds=0.01))
    return read_track(folder)


def test_camera_views_of_a_capture_with_and_without_its_video(synth_capture, tmp_path):
    cap = synth_capture("walk", stop=3)
    track = _truth_track(cap, tmp_path / "track")
    pictures, note = camera_views(cap, track, EVAL_PARENTS, frames=2, height=48)
    assert [c.split(" (")[0] for c, _ in pictures] == ["frame 0", "frame 2"]
    assert all(p[:3] == b"\xff\xd8\xff" for _, p in pictures)  # JPEG
    assert "not made from video" in note
    # the same capture as if made from video: each camera's backdrop is its video frame
    meta = json.loads((cap.path / "capture.json").read_text())
    videos = {}
    for j, cam in enumerate(cap.cameras):
        frames = np.full((3, cam.height, cam.width, 3), 40 * j + 20, np.uint8)
        videos[cam.name] = str(tmp_path / f"{cam.name}.mp4")
        write_video(videos[cam.name], frames, fps=30, quality=10)
    copy = tmp_path / "cap"
    copy.mkdir()
    for name in ("cameras.json",):
        (copy / name).write_bytes((cap.path / name).read_bytes())
    meta |= {"videos": videos, "offsets": {n: 0 for n in videos}}
    (copy / "capture.json").write_text(json.dumps(meta))
    images, note = backdrops(Capture(copy), [1], 24)
    assert note == ""
    assert all(abs(int(im[0][12, 2, 0]) - (40 * j + 20)) <= 4 for j, im in enumerate(images))
    gone = meta | {"videos": {n: str(tmp_path / "gone.mp4") for n in videos}}
    (copy / "capture.json").write_text(json.dumps(gone))
    images, note = backdrops(Capture(copy), [1], 24)
    assert "cannot be read" in note and images[0][0].shape[0] == 24
