"""HTML reports: offline, self-contained, data round-trips, the player draws in a browser."""

import base64
import json
import re
import shutil
import subprocess

import numpy as np
import pytest

from meshmocap.apps.report.page import Section, Table, report_html, write_report
from meshmocap.apps.report.player import (
    decode_array,
    encode_array,
    player_from_tracks,
    player_js,
    player_payload,
    surface_voxels,
)
from meshmocap.cli import main
from meshmocap.errors import InputError, MeshmocapFileNotFoundError
from meshmocap.io.results import FrameResult, read_track, start_track, write_frame

# the smallest valid PNG (1 x 1 grey pixel)
PNG = bytes.fromhex(
    "89504e470d0a1a0a0000000d4948445200000001000000010800000000"
    "3a7e9b550000000a4944415478da63680000008200816c8a35b30000000049454e44ae426082"
)


@pytest.fixture(scope="module")
def capture(synth_capture):
    return synth_capture("walk", stop=3)


@pytest.fixture(scope="module")
def tracked(capture, tmp_path_factory):
    """A real articulated-ICP track of the capture: (folder, Track)."""
    from meshmocap.body.template import load_template
    from meshmocap.trackers.driver import track_sequence
    from meshmocap.trackers.options import TrackOptions
    from meshmocap.trackers.registry import make_tracker

    out = tmp_path_factory.mktemp("icp")
    tr = track_sequence(
        make_tracker("articulated_icp"),
        load_template("neutral_5k"),
        capture,
        out,
        TrackOptions(show_progress=False, init="truth", recover=False),
    )
    return out, tr


@pytest.fixture(scope="module")
def shifted(capture, tmp_path_factory):
    """The truth moved 5 cm along x, frames 1 and 2 only: (folder, Track). Its template is
    not a bundled one: the player shows its meshes as they are (morph targets)."""
    from meshmocap.body.template import EVAL_NAMES, EVAL_PARENTS

    out = tmp_path_factory.mktemp("shift")
    meta = {
        "method": "truth+5cm",
        "template": "subject_body",
        "eval_names": list(EVAL_NAMES),
        "eval_parents": EVAL_PARENTS.tolist(),
    }
    start_track(out, meta, capture.truth_faces, resume=False)
    shift = np.array([0.05, 0.0, 0.0])
    for f in list(capture)[1:]:
        t = f.truth
        write_frame(out, FrameResult(f.index, t.joints + shift, t.vertices + shift, seconds=0.01))
    return out, read_track(out)


@pytest.fixture(scope="module")
def player(capture, tracked, shifted):
    return player_from_tracks(capture, [tracked[1], shifted[1]], title="two tracks <&>")


def _payloads(text: str) -> list[dict]:
    found = re.findall(
        r'<script type="application/json" class="mm-data">(.*?)</script>', text, re.S
    )
    return [json.loads(s) for s in found]


def test_player_data_round_trips(player, capture, tracked, shifted, tmp_path):
    import pygltflib

    from meshmocap.apps.files.export import export_track

    tr, sh = tracked[1], shifted[1]
    assert player.frames.tolist() == [0, 1, 2] and player.fps == capture.fps
    assert player.capture_fps == capture.fps
    assert player.tracks[1].rows.tolist() == [-1, 0, 1]  # the shifted track starts at frame 1
    assert player.tracks[1].first == 1 and player.tracks[0].first == 0
    d = player_payload(player)
    t0, t1 = d["tracks"]
    step = t0["joints"]["step"]
    assert 0 < step < 1e-4  # 0.1 mm or better for a ~2 m scene
    y_up = np.array([[1, 0, 0], [0, 0, 1], [0, -1, 0]])  # glTF's frame
    np.testing.assert_allclose(decode_array(t0["joints"]), tr.joints @ y_up.T, atol=step)
    np.testing.assert_allclose(decode_array(t1["joints"]), sh.joints @ y_up.T, atol=step)
    assert t0["parents"] == tr.meta["eval_parents"]
    assert decode_array(t1["rows"]).tolist() == [-1, 0, 1]
    truth = np.stack([f.truth.joints for f in capture]) @ y_up.T
    np.testing.assert_allclose(decode_array(d["truth"]["joints"]), truth, atol=step)
    offsets = decode_array(d["hull"]["offsets"])
    assert offsets[0] == 0 and len(offsets) == 4 and 0 < np.diff(offsets).min() <= 1500
    hull = decode_array(d["hull"]["points"])
    assert hull.shape == (offsets[-1], 3)
    # hull points lie around the true body of their frame
    assert np.abs(hull[: offsets[1]].mean(axis=0) - truth[0].mean(axis=0)).max() < 0.15
    # each track is what `meshmocap export` writes: the same animation, re-skinned to the
    # tracked surface within the export's 5 mm
    out = tmp_path / "icp.glb"
    export_track(tracked[0], out)
    shown = pygltflib.GLTF2.load_from_bytes(base64.b64decode(t0["glb"]))
    exported = pygltflib.GLTF2.load(str(out))
    for g in (shown, exported):
        assert len(g.animations[0].channels) == 32 and g.accessors[0].count == 5000

    def rotations(g):
        blob, acc = g.binary_blob(), g.accessors[g.animations[0].samplers[5].output]
        view = g.bufferViews[acc.bufferView]
        return blob[view.byteOffset : view.byteOffset + view.byteLength]

    assert rotations(shown) == rotations(exported)
    assert player.tracks[0].vertex_error_mm < 5
    # a track without its template: the tracked meshes as morph targets, exactly
    morph = pygltflib.GLTF2.load_from_bytes(base64.b64decode(t1["glb"]))
    prim = morph.meshes[0].primitives[0]
    assert len(prim.targets) == 1 and morph.skins == [] and player.tracks[1].vertex_error_mm == 0


def test_surface_voxels_match_an_erosion():
    from scipy.ndimage import binary_erosion

    occ = np.random.default_rng(0).random((12, 15, 9)) > 0.3
    assert np.array_equal(surface_voxels(occ), np.argwhere(occ & ~binary_erosion(occ)))
    assert surface_voxels(np.zeros((3, 3, 3), bool)).shape == (0, 3)


def test_encode_plain_arrays_little_endian():
    a = np.arange(6, dtype=">u4").reshape(2, 3)
    e = encode_array(a)
    assert e["dtype"] == "uint32" and e["shape"] == [2, 3]
    assert decode_array(e).tolist() == a.tolist()


def test_report_is_offline_and_self_contained(player, tmp_path):
    png = tmp_path / "plot.png"
    png.write_bytes(PNG)
    t = Table("errors <mm>", ("joint", "mean"), (("head", 1.25), ("all", float("nan"))))
    more = Section("more", images=(("bytes", PNG),), text="x < y")
    text = report_html(
        title="report & co", players=[player], tables=[t], images=[("a plot", png)], sections=[more]
    )
    urls = text.replace("http://www.w3.org/1999/xhtml", "")  # three.js: a namespace, not a URL
    assert "http://" not in urls and "https://" not in urls and "//cdn" not in urls
    assert all(s.startswith("data:") for s in re.findall(r'src="([^"]*)"', text))
    assert text.count("data:image/png;base64,") == 2
    assert "<caption>errors &lt;mm&gt;</caption>" in text and '<td class="num">1.2' in text
    assert ">n/a<" in text and "x &lt; y" in text and "two tracks &lt;&amp;&gt;" in text
    assert _payloads(text) == [json.loads(json.dumps(player_payload(player)))]
    js = player_js()
    assert js in text and "MMTHREE" in js and "Player.prototype.setFrame" in js
    assert "three.js r187" in text and "Permission is hereby granted" in text  # MIT notice
    assert text.count("<script>") == 1  # the player's code, once for all players
    # a page without players carries no script at all
    assert "<script" not in report_html(title="plain", tables=[t])


def test_player_js_syntax(tmp_path):
    node = shutil.which("node")
    if node is None:
        pytest.skip("node is not installed: cannot syntax-check player.js")
    js = tmp_path / "player.js"
    js.write_text(player_js())
    res = subprocess.run([node, "--check", str(js)], capture_output=True, text=True, timeout=60)
    assert res.returncode == 0, res.stderr


def test_frame_cap_and_size_budget(capture, tracked):
    tr = tracked[1]
    assert player_from_tracks(capture, [tr], max_frames=2).frames.tolist() == [0, 2]
    p = player_from_tracks(capture, [tr], max_frames=2, hull_points=0, truth=False)
    assert p.fps == capture.fps / 2 and p.hull is None and p.truth is None
    tiny = player_from_tracks(capture, [tr], max_megabytes=0.002)  # room for one frame
    assert tiny.frames.tolist() == [0]
    assert len(json.dumps(player_payload(tiny))) < 0.6e6  # the GLB and one frame


def test_mistakes_are_reported(capture, tracked, tmp_path):
    tr = tracked[1]
    with pytest.raises(InputError, match="expected at least one track"):
        player_from_tracks(capture, [])
    with pytest.raises(InputError, match="names: expected 1"):
        player_from_tracks(capture, [tr], names=["a", "b"])
    with pytest.raises(InputError, match="expected a PNG or JPEG"):
        report_html(title="x", images=[("bad", b"GIF89a....")])
    with pytest.raises(MeshmocapFileNotFoundError, match=r"nope\.png"):
        report_html(title="x", images=[("missing", tmp_path / "nope.png")])
    with pytest.raises(InputError, match=r"must end in \.html"):
        write_report(tmp_path / "r.txt", title="x")


def test_track_frames_missing_from_the_capture(capture, tracked, tmp_path):
    tr = tracked[1]
    start_track(tmp_path / "t", tr.meta, tr.faces, resume=False)
    write_frame(tmp_path / "t", FrameResult(99, tr.joints[0], tr.vertices[0]))
    with pytest.raises(InputError, match=r"\[99\] are not in the capture"):
        player_from_tracks(capture, [read_track(tmp_path / "t")])


def test_report_command(capture, tracked, shifted, tmp_path, capsys):
    out = tmp_path / "sub" / "report.html"
    args = [
        "report",
        str(capture.path),
        str(tracked[0]),
        str(shifted[0]),
        "--out",
        str(out),
        "--eval-dir",
        str(tmp_path / "e1"),
        "--eval-dir",
        str(tmp_path / "e2"),
        "--max-frames",
        "2",
        "--no-silhouettes",
        "--surface-frames",
        "1",
    ]
    assert main(args) == 0
    assert "wrote" in capsys.readouterr().out
    text = out.read_text()
    assert "Trackers compared" in text and "Evaluation: truth+5cm" in text
    assert "Surface distance to the truth" in text and "data:image/png;base64," in text
    assert (tmp_path / "e1" / "joint_errors.csv").is_file()
    assert (tmp_path / "e2" / "joint_error_per_frame.png").is_file()
    assert _payloads(text)[0]["frames"] == [0, 2]
    assert main([*args[:6], "--eval-dir", str(tmp_path / "e1")]) == 2
    assert "eval_dirs: expected 2 folders" in capsys.readouterr().err


def _browser() -> str | None:
    return next(
        (p for n in ("chromium", "chromium-browser", "google-chrome") if (p := shutil.which(n))),
        None,
    )


def _chromium(browser, tmp_path, page, *args):
    cmd = [
        browser,
        "--headless",
        "--no-sandbox",
        "--disable-gpu",
        "--disable-background-networking",
        "--disable-component-update",
        "--disable-default-apps",
        "--no-first-run",
        "--hide-scrollbars",
        f"--user-data-dir={tmp_path / 'profile'}",
        "--window-size=1200,900",
        "--virtual-time-budget=10000",
        *args,
        page,
    ]
    return subprocess.run(cmd, capture_output=True, text=True, timeout=180)


@pytest.mark.slow
def test_player_draws_in_headless_chromium(player, tmp_path):
    browser = _browser()
    if browser is None:
        pytest.skip("no chromium, chromium-browser or google-chrome on PATH")
    page = write_report(tmp_path / "report.html", title="shot", players=[player])
    url = f"{page.resolve().as_uri()}?screenshot&frame=1"
    dom = _chromium(browser, tmp_path, url, "--dump-dom").stdout
    assert 'data-mm-ready="1"' in dom, dom[-500:]  # the GLBs loaded and a frame was drawn
    assert "data-mm-errors" not in dom.split(">", 2)[1], dom[:300]  # no error on the page
    shot = tmp_path / "shot.png"
    res = _chromium(browser, tmp_path, url, f"--screenshot={shot}")
    assert shot.is_file(), f"no screenshot (exit {res.returncode}): {res.stderr[-500:]}"
    from PIL import Image

    im = np.asarray(Image.open(shot).convert("RGB")).astype(int)
    canvas, outside = im[:600, :800], im[:, 820:]
    r, g, b = canvas[..., 0], canvas[..., 1], canvas[..., 2]
    blue = (b > r + 40) & (b > g + 20)  # the first track's mesh (50, 100, 220)
    crimson = (r > g + 60) & (r > b + 20)  # the second track's mesh (210, 50, 110)
    assert blue.sum() > 3000, f"only {blue.sum()} mesh pixels in the canvas"
    assert crimson.sum() > 3000  # side by side
    assert (np.abs(canvas - [243, 245, 248]).sum(axis=2) < 6).mean() > 0.3  # background
    assert (outside > 250).all()  # in ?screenshot mode only the canvas shows
