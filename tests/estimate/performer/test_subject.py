"""Subject estimation and the tracking-template defaults: a small performer's body found
from silhouettes, the capture kinds, capture.json's template honoured, an estimate cached
in the track folder, and the ``subject`` command."""

from __future__ import annotations

import json

import numpy as np
import pytest

from meshmocap import _progress
from meshmocap.body.template import load_template
from meshmocap.cli import main
from meshmocap.errors import InputError
from meshmocap.estimate.performer import tracking_template as tt
from meshmocap.estimate.performer.subject import SubjectEstimate, estimate_subject, subject_kind
from meshmocap.io.capture import open_capture
from meshmocap.io.meshes import write_mesh
from meshmocap.io.results import template_label


@pytest.fixture(scope="module")
def small(synth_capture):
    """Two frames of the procedural walk by small_female (1.55 m), made for neutral_5k."""
    return synth_capture("walk", subject="small_female", stop=2, voxel_size=0.02)


@pytest.fixture
def mesh_folder(tmp_path):
    t = load_template("neutral_5k")
    (tmp_path / "m").mkdir()
    for k in range(2):
        write_mesh(tmp_path / "m" / f"{k:05d}.ply", t.V, t.F)
    return open_capture(tmp_path / "m")


def stub_estimate(calls):
    def estimate(capture, *, kind="auto", **_):
        calls.append(kind)
        t = load_template("neutral_5k")
        R = np.tile(np.eye(3), (1, 31, 1, 1))
        return SubjectEstimate(t, "mesh", (0,), None, R, t.skeleton.rest_positions[:1], 0.0, 0.1)

    return estimate


def test_a_small_performer_is_found_from_one_frame_of_silhouettes(small, monkeypatch, capsys):
    """One frame, 8 iterations (a quick version of the default 5 frames, 40 iterations; the
    benchmark measures those): the mean body is 27 cm too tall, the estimate within 3 cm.
    About 10 s on 2 cores: the one end-to-end check of the hull fit. Every stage says what
    it does (all said at once with a phase threshold of 0)."""
    monkeypatch.setattr(_progress, "PHASE_SECONDS", 0.0)
    est = estimate_subject(small, n_frames=1, iterations=8)
    err = capsys.readouterr().err
    for stage in (
        "choosing 1 frames in different poses",
        "a first guess of the body in frames 0",
        "fitting the shape to the silhouettes (1 frames, iterations 1–8 of 8)",
    ):
        assert f"meshmocap: {stage} ...\n" in err and f"meshmocap: {stage}: done in" in err
    true = load_template("small_female")
    assert est.kind == "hull" and est.frames == (0,) and est.z.shape == (16,)
    assert abs(est.height - np.ptp(true.V[:, 2])) < 0.03
    assert est.template.n_vertices == 12411 and est.R.shape == (1, 31, 3, 3)
    assert est.rms < 0.02
    with pytest.raises(InputError, match="n_frames must be an integer ≥ 1"):
        estimate_subject(small, n_frames=0)
    with pytest.raises(InputError, match="kind must be one of"):
        estimate_subject(small, kind="hulls")  # type: ignore[arg-type]


def test_capture_kinds(small, mesh_folder):
    assert subject_kind(small) == "hull" and subject_kind(mesh_folder) == "mesh"


def test_the_template_capture_json_names_is_used_and_a_given_one_is_noted(small, tmp_path):
    c = tt.tracking_template(small, None, tmp_path / "t")
    assert c.template.name == "neutral_5k" and c.info == {"template_source": "capture"}
    assert "capture.json names" in c.note
    c = tt.tracking_template(small, "heavy_male", tmp_path / "t")
    assert c.template.name == "heavy_male" and c.info == {}
    assert "made for 'neutral_5k'" in c.note
    assert template_label({"template": "x"}) == "x (given)"
    assert template_label({"template": "s", **tt.tracking_template(small, None, ".").info}) == (
        "s (named by capture.json)"
    )


def test_an_estimate_is_cached_in_the_track_folder(mesh_folder, tmp_path, monkeypatch):
    calls = []
    monkeypatch.setattr(tt, "estimate_subject", stub_estimate(calls))
    out = tmp_path / "t"
    c = tt.tracking_template(mesh_folder, None, out)
    assert calls == ["auto"] and (out / tt.SUBJECT_FILE).is_file()
    assert c.info == {"template_source": "estimated", "template_file": "subject.npz"}
    again = tt.tracking_template(mesh_folder, "auto", out)
    assert calls == ["auto"] and "reused" in again.note
    # a resumed run tracks with the very template the first run did (a cage track's
    # settings digest its manifold, learned on the template's joints): bit for bit
    for a, b in (
        (again.template.V, c.template.V),
        (again.template.skeleton.end_offsets, c.template.skeleton.end_offsets),
        (again.template.weights.toarray(), c.template.weights.toarray()),
    ):
        np.testing.assert_array_equal(a, b)
    tt.tracking_template(mesh_folder, None, out, refresh=True)
    assert calls == ["auto", "auto"]


def test_track_records_how_the_template_was_chosen(mesh_folder, tmp_path, monkeypatch, capsys):
    monkeypatch.setattr(tt, "estimate_subject", stub_estimate([]))
    out = tmp_path / "t"
    args = [
        "track",
        str(mesh_folder.path),
        "--out",
        str(out),
        "--method",
        "articulated_icp",
        "--max-iter",
        "2",
    ]
    assert main(args) == 0
    assert "template estimated from the capture" in capsys.readouterr().out
    meta = json.loads((out / "track.json").read_text())
    assert meta["template_source"] == "estimated" and meta["template_file"] == "subject.npz"


def test_subject_command(mesh_folder, tmp_path, monkeypatch, capsys):
    import meshmocap.estimate.performer.subject as su

    monkeypatch.setattr(su, "estimate_subject", stub_estimate([]))
    out = tmp_path / "me.npz"
    assert main(["subject", str(mesh_folder.path), "--out", str(out)]) == 0
    text = capsys.readouterr().out
    assert "rigged as it stands" in text and f"wrote {out}" in text
    assert load_template(out).n_vertices == 5000
    assert main(["subject", str(mesh_folder.path), "--out", str(tmp_path / "x.ply")]) == 2
    err = capsys.readouterr().err
    assert err.startswith("meshmocap: error: subject: --out must be a .npz")
    assert "\n" not in err.strip()
