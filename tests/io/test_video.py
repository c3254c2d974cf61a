"""Camera footage: videos through PyAV, folders of images, matching cameras to files."""

import numpy as np
import pytest
from PIL import Image

from meshmocap.errors import FormatError, InputError, MeshmocapFileNotFoundError
from meshmocap.io.video import find_footage, open_footage, read_frames, write_video


def _frames(n=6, H=48, W=64):
    """Flat colours that change frame by frame (codec-friendly), a frame index in green."""
    out = np.zeros((n, H, W, 3), np.uint8)
    for k in range(n):
        out[k, :, :] = (200, 20 + 20 * k, 60)
        out[k, 10:30, 20:40] = (20, 20, 220)
    return out


@pytest.mark.parametrize("suffix", [".mp4", ".avi"])
def test_video_round_trip(tmp_path, suffix):
    path = tmp_path / f"cam01{suffix}"
    frames = _frames()
    write_video(path, frames, fps=25, quality=10)
    fo = open_footage(path)
    assert (fo.n_frames, fo.width, fo.height) == (6, 64, 48) and fo.fps == pytest.approx(25)
    got = dict(read_frames(fo, [4, 1]))
    assert sorted(got) == [1, 4]
    for k in (1, 4):  # lossy codecs: close, and each frame where it belongs
        assert np.abs(got[k].astype(int) - frames[k]).mean() < 6
    small = next(read_frames(path, [0], size=(32, 24)))[1]
    assert small.shape == (24, 32, 3)
    with pytest.raises(InputError, match="frame 6 asked for, the footage has 6"):
        list(read_frames(fo, [6]))
    assert [p.name for p in tmp_path.iterdir()] == [path.name]  # no temporary file left


def test_folder_of_images_in_natural_order(tmp_path):
    folder = tmp_path / "cam02"
    folder.mkdir()
    frames = _frames(n=11)
    for k, im in enumerate(frames):
        Image.fromarray(im).save(folder / f"img{k}.png")
    fo = open_footage(folder)
    assert (fo.n_frames, fo.width, fo.height, fo.fps) == (11, 64, 48, None)
    k, im = next(read_frames(fo, [10]))
    np.testing.assert_array_equal(im, frames[10])  # img10 is the 11th, not the 3rd


def test_find_footage_and_errors(tmp_path):
    write_video(tmp_path / "CAM01.mp4", _frames())
    (tmp_path / "cam02").mkdir()
    found = find_footage(tmp_path, ["cam01", "cam02"])
    assert found == {"cam01": tmp_path / "CAM01.mp4", "cam02": tmp_path / "cam02"}
    with pytest.raises(MeshmocapFileNotFoundError, match=r"camera 'cam03' has no video.*CAM01"):
        find_footage(tmp_path, ["cam01", "cam03"])
    (tmp_path / "bad.mp4").write_bytes(b"not a video at all" * 10)
    with pytest.raises(FormatError, match=r"bad.mp4: not a readable video"):
        open_footage(tmp_path / "bad.mp4")
    with pytest.raises(MeshmocapFileNotFoundError, match="folder without images"):
        open_footage(tmp_path / "cam02")
    with pytest.raises(InputError, match="even sizes"):
        write_video(tmp_path / "odd.mp4", np.zeros((2, 5, 5, 3), np.uint8))
