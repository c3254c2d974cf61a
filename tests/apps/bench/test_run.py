"""meshmocap bench: both papers' methods side by side on tiny captures, resumable."""

from __future__ import annotations

import csv
import math
import shutil

import numpy as np
import pytest

from meshmocap.apps.bench.captures import CAPTURE_SETS, parse_capture
from meshmocap.apps.bench.report import COLUMNS
from meshmocap.apps.bench.run import run_bench
from meshmocap.cli import main
from meshmocap.errors import InputError, MeshmocapFileNotFoundError

FRAMES = 4
PATCH = {"n_patches": 60, "max_iter": 3}


def _bench(out, work, **kw):
    kw = {
        "captures": ["walk"],
        "methods": ["articulated_icp", "patch"],
        "max_frames": FRAMES,
        "keep_fractions": (0.25, 1.0),
        "method_options": {"patch": PATCH},
        **kw,
    }
    return run_bench(out, work=work, show_progress=False, **kw)


@pytest.fixture(scope="module")
def bench(tmp_path_factory):
    root = tmp_path_factory.mktemp("bench")
    return _bench(root / "out", root / "work"), root


def _csv(path):
    with open(path, newline="") as f:
        return list(csv.DictReader(f))


@pytest.mark.slow
def test_writes_table_markdown_and_plots(bench):
    res, root = bench
    out = root / "out"
    rows = _csv(out / "results.csv")
    assert list(rows[0]) == [h for h, _ in COLUMNS]
    assert [(r["capture"], r["method"]) for r in rows] == [
        ("walk", "articulated_icp"),
        ("walk", "patch"),
    ]
    numeric = [
        "mean_mm",
        "median_mm",
        "std_mm",
        "worst_frame_mm",
        "silhouette_error_ratio",
        "bone_std_max_mm",
        "seconds_per_frame_s",
    ]
    for r in rows:
        assert r["status"] == "ok" and r["metric"] == "joints" and int(r["frames"]) == FRAMES
        assert all(math.isfinite(float(r[k])) and float(r[k]) >= 0 for k in numeric)
        assert float(r["mean_mm"]) < 60 and int(r["flagged"]) == 0
    md = (out / "results.md").read_text()
    assert f"| walk | articulated_icp | {FRAMES} |" in md and f"| walk | patch | {FRAMES} |" in md
    assert "## Fig. 8" in md
    sweep = _csv(out / "keep_fraction.csv")
    assert [float(r["keep_fraction"]) for r in sweep] == [0.25, 1.0]
    assert all(math.isfinite(float(r["mean_mm"])) for r in sweep)
    assert len(_csv(out / "frame_errors.csv")) == 2 * FRAMES
    assert len(_csv(out / "bone_lengths.csv")) == 2 * 14  # 14 bones of the 15 joints
    for name in ("mean_error", "bone_std_walk", "frame_errors_walk", "keep_fraction"):
        png = out / f"{name}.png"
        assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and f"]({name}.png)" in md
    assert set(res.files) >= {out / "results.csv", out / "results.md"}
    assert res.tradeoff_capture == "walk" and len(res.tradeoff) == 2


def test_settings_beside_the_results_say_how_to_reproduce_them(bench):
    import json

    res, root = bench
    settings = json.loads((root / "out" / "settings.json").read_text())
    assert [c["name"] for c in settings["captures"]] == ["walk"]
    assert settings["captures"][0]["stop"] == FRAMES
    assert settings["methods"] == ["articulated_icp", "patch"]
    assert settings["method_options"] == {"patch": PATCH}
    assert settings["template"] == "neutral_5k" and len(settings["template_digest"]) == 16
    assert set(settings["tracks"]) == {
        "walk/articulated_icp",
        "walk/patch",
        "walk/patch[keep=0.25]",
        "walk/patch[keep=1]",
    }
    assert all(str(root / "work" / "tracks") in t for t in settings["tracks"].values())
    assert settings["versions"]["numpy"] == np.__version__
    assert settings["machine"]["cores"] >= 1 and len(settings["code_digest"]) == 8
    assert root / "out" / "settings.json" in res.files


def test_rerun_reuses_captures_tracks_and_scores(bench):
    res, root = bench
    work = root / "work"
    frames = sorted(work.glob("tracks/*/*/frames/*.npz")) + sorted(
        work.glob("captures/*/truth/*.npz")
    )
    before = {p: p.stat().st_mtime_ns for p in frames}
    again = _bench(root / "out2", work)
    assert again.tracked == () and again.evaluated == ()
    assert res.tracked and res.evaluated  # the first run did the work
    assert {p: p.stat().st_mtime_ns for p in frames} == before
    for a, b in zip(res.rows, again.rows, strict=True):
        assert (a.capture, a.method, a.frames) == (b.capture, b.method, b.frames)
        assert a.mean_mm == b.mean_mm and a.seconds_per_frame == b.seconds_per_frame
        assert np.array_equal(a.per_frame_mm, b.per_frame_mm)


@pytest.mark.slow
def test_changed_tracking_code_tracks_afresh(bench, tmp_path, monkeypatch):
    """Tracks are keyed by the tracking code too: after an edit to the package a re-run
    tracks again instead of resuming the old code's frames."""
    import meshmocap.apps.bench.run as bench_module

    _, root = bench
    work = tmp_path / "work"
    shutil.copytree(root / "work", work)
    digest = bench_module.code_digest()
    assert len(digest) == 8 and digest == bench_module.code_digest()  # stable
    monkeypatch.setattr(bench_module, "code_digest", lambda: "0" * 8)
    # one method is enough to show it (the cheapest: the patch tracks cost ~4/5 of a run)
    again = _bench(tmp_path / "out", work, methods=["articulated_icp"], keep_fractions=())
    (tracked,) = again.tracked  # tracked afresh
    assert "articulated_icp" in tracked
    assert len(list(work.glob("tracks/*/*/"))) == 1 + len(list((root / "work").glob("tracks/*/*/")))


def test_cli_prints_the_table_and_reuses_the_work_folder(bench, tmp_path, capsys):
    _, root = bench
    argv = [
        "bench",
        "--captures",
        "walk",
        "--methods",
        "articulated_icp",
        "--max-frames",
        str(FRAMES),
        "--keep-fractions",
        "none",
        "--work",
        str(root / "work"),
        "--out",
        str(tmp_path),
    ]
    assert main(argv) == 0
    text = capsys.readouterr().out
    assert f"| walk | articulated_icp | {FRAMES} |" in text and "0 tracked by this run" in text
    assert (tmp_path / "results.csv").is_file() and not (tmp_path / "keep_fraction.csv").exists()


@pytest.mark.parametrize(
    ("kw", "match"),
    [
        ({"methods": ["nope"]}, r"method must be one of \[.*'articulated_icp'.*'patch'"),
        ({"captures": "huge"}, r"set must be one of \['quick', 'standard', 'full'\]"),
        ({"captures": ["walk+fisheye"]}, r"variant must be one of \['humaneva4', 'ring8', 'deg"),
        ({"captures": ["moonwalk"]}, r"capture must be one of \[.*'walk'.*'crane'\]"),
        ({"captures": ["05_01"]}, r"needs the data folder"),
        ({"keep_fractions": (0.0,)}, r"keep fractions must lie in \(0, 1\]"),
    ],
)
def test_bad_choices_are_rejected_in_one_line(tmp_path, kw, match):
    with pytest.raises(InputError, match=match) as exc:
        _bench(tmp_path / "out", tmp_path / "work", **kw)
    assert "\n" not in str(exc.value)
    assert not (tmp_path / "work").exists()  # rejected before any work


def test_cli_rejects_an_unknown_set_in_one_line(tmp_path, capsys):
    assert main(["bench", "--set", "huge", "--out", str(tmp_path)]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "'quick', 'standard', 'full'" in err


def test_capture_names_resolve_against_the_data_folder(tmp_path):
    cmu = tmp_path / "mocap" / "cmu"
    cmu.mkdir(parents=True)
    for f in ("05_01.amc", "09_01.bvh", "01_01.amc"):
        (cmu / f).touch()
    run = parse_capture("09_01+ring8+heavy_male", data=tmp_path, frames=100)
    assert (run.start, run.stop, run.rig, run.subject) == (4, 104, "ring8", "heavy_male")
    assert run.folder == "09_01+ring8+heavy_male-100f" and run.source.endswith("09_01.bvh")
    assert parse_capture("01_01", data=tmp_path).stop == 600  # first 600 frames at 60 fps
    assert parse_capture("walk+degraded", frames=60).degraded
    with pytest.raises(MeshmocapFileNotFoundError, match="crane_mesh"):
        parse_capture("crane", data=tmp_path)
    with pytest.raises(InputError, match="two rig variants"):
        parse_capture("walk+ring8+humaneva4")
    assert CAPTURE_SETS["quick"].captures == ("walk", "jog")
