"""Gait analysis (events, cycles, parameters, flexion curves) on procedural walks and jogs of
known cadence, on jittered joints, on clips without walking, and through ``meshmocap gait``."""

import csv

import numpy as np
import pytest

from meshmocap.analysis.gait import (
    CYCLE_SAMPLES,
    capture_gait,
    compare_gaits,
    gait_analysis,
    track_gait,
)
from meshmocap.analysis.gait_signals import flexion_angles
from meshmocap.apps.files.gait import write_gait
from meshmocap.body.procedural import jog, squat, walk
from meshmocap.body.template import EVAL_NAMES, EVAL_PARENTS, load_template
from meshmocap.cli import main
from meshmocap.errors import InputError
from meshmocap.io.capture import Capture, Truth, write_meta, write_truth
from meshmocap.io.results import FrameResult, read_track, start_track, write_frame

FPS = 60.0


@pytest.fixture(scope="module")
def template():
    return load_template("neutral_5k")


def _joints(template, motion):
    return template.pose(motion.rotations, motion.root_positions).eval_joints


@pytest.fixture(scope="module")
def walking(template):
    """6 s of the procedural walk at 110 steps/min: (joints, mean pelvis speed m/s)."""
    m = walk(template, duration=6.0, fps=FPS, cadence=110.0)
    speed = np.linalg.norm(m.root_positions[-1, :2] - m.root_positions[0, :2]) / (6.0 - 1 / FPS)
    return _joints(template, m), speed


@pytest.mark.parametrize(("motion", "cadence"), [(walk, 110.0), (jog, 160.0), (walk, 90.0)])
def test_cadence_cycles_and_stride_of_known_gaits(template, motion, cadence):
    m = motion(template, duration=6.0, fps=FPS, cadence=cadence)
    g = gait_analysis(_joints(template, m), FPS, EVAL_NAMES)
    assert g.found and g.message == ""
    s = g.summary()
    # subframe event timing: the cadence the motion was made with, to 0.5 %
    assert s.cadence_steps_per_min == pytest.approx(cadence, rel=0.005)
    # 6 s at cadence/2 cycles per minute, less the cycles cut by the clip's ends
    assert s.n_cycles >= 2 * (6.0 * cadence / 120 - 2)
    # the feet alternate: one strike of the other foot inside each cycle, a step each
    for c in g.cycles:
        other = g.strikes[1 - ("left", "right").index(c.side)]
        assert ((other > c.strike) & (other < c.end)).sum() == 1
        assert c.strike < c.foot_off < c.end
    # stride length = the distance the body travels in a stride
    travel = np.linalg.norm(m.root_positions[-1, :2] - m.root_positions[0, :2]) / (6.0 - 1 / FPS)
    assert s.stride_length_m == pytest.approx(travel * s.stride_time_s, rel=0.02)
    assert s.step_length_m == pytest.approx(s.stride_length_m / 2, rel=0.02)
    assert s.speed_m_per_s == pytest.approx(travel, rel=0.02)
    # a walk stands about 60 % of the cycle (ankle events time it within a few %); the
    # procedural jog is a bouncy walk, no flight phase, a slightly shorter stance
    assert (56 < s.stance_pct < 66) if motion is walk else (52 < s.stance_pct < 64)
    assert s.swing_pct == pytest.approx(100 - s.stance_pct)
    for side in ("left", "right"):
        assert g.summary(side).n_cycles >= 2


def test_jittered_ankles_give_the_same_events(walking):
    """1 cm of noise per coordinate on every joint (several cm peak to peak at stance):
    no spurious contact, every event within one frame, cadence within 1 %."""
    J, _ = walking
    clean = gait_analysis(J, FPS, EVAL_NAMES)
    rng = np.random.default_rng(7)
    noisy = gait_analysis(J + rng.normal(0.0, 0.01, J.shape), FPS, EVAL_NAMES)
    c = compare_gaits(noisy, clean)
    assert c.reference_events >= 18
    assert c.matched == c.reference_events and c.spurious == 0
    assert c.max_offset <= 1.0
    assert abs(c.cadence_error_pct) < 1.0 and abs(c.stride_length_error_pct) < 1.0
    # offsets are in frame numbers: the same joints numbered one frame later are +1 frame
    later = compare_gaits(gait_analysis(J, FPS, EVAL_NAMES, frames=np.arange(len(J)) + 1), clean)
    assert later.matched == later.reference_events
    np.testing.assert_allclose(later.offsets, 1.0, atol=1e-9)


def test_flexion_sign_conventions():
    """Handmade legs facing −Y: thigh 30° forward of the trunk line, shank 50° behind the
    thigh (flexion), the other leg straight and 10° behind (hip extension)."""
    fwd = np.array([[0.0, -1.0, 0.0]])

    def leg(x, hip_deg, knee_deg):
        h = np.array([x, 0.0, 1.0])
        a, b = np.radians(hip_deg), np.radians(hip_deg - knee_deg)
        k = h + 0.45 * np.array([0.0, -np.sin(a), -np.cos(a)])
        return h, k, k + 0.45 * np.array([0.0, -np.sin(b), -np.cos(b)])

    J = np.zeros((1, 15, 3))
    idx = {n: i for i, n in enumerate(EVAL_NAMES)}
    J[0, idx["pelvis"]], J[0, idx["thorax"]] = [0, 0, 1.0], [0, 0, 1.5]
    for side, x, hip, knee in (("left", 0.1, 30.0, 50.0), ("right", -0.1, -10.0, 0.0)):
        for part, p in zip(("hip", "knee", "ankle"), leg(x, hip, knee), strict=True):
            J[0, idx[f"{side}_{part}"]] = p
    hip, knee = flexion_angles(J, EVAL_NAMES, fwd)
    np.testing.assert_allclose(hip[0], [30.0, -10.0], atol=1e-9)
    np.testing.assert_allclose(knee[0], [50.0, 0.0], atol=1e-9)


def test_flexion_curves_per_cycle(walking):
    g = gait_analysis(walking[0], FPS, EVAL_NAMES)
    for c in g.cycles:
        assert c.hip.shape == c.knee.shape == (CYCLE_SAMPLES,)
        # the walk's knee flexes most in swing (60° bump after foot off), least near strike
        peak = np.argmax(c.knee)
        assert peak > c.stance_pct and c.knee.max() > 55.0 and c.knee.min() < 15.0
        # the hip flexes at strike and extends in late stance
        assert c.hip[0] > 15.0 and c.hip.min() < -5.0


def test_no_walking_says_why(template):
    m = squat(template, duration=3.0, fps=FPS)
    g = gait_analysis(_joints(template, m), FPS, EVAL_NAMES)
    assert not g.found and "walk or a run" in g.message
    assert g.cycles == () and len(g.steps) == 0 and np.isnan(g.cadence)
    with pytest.raises(InputError, match="no walking"):
        write_gait(g, "unused")


def test_unusable_frames_drop_their_events_and_cycles(walking):
    J, _ = walking
    clean = gait_analysis(J, FPS, EVAL_NAMES)
    valid = np.ones(len(J), bool)
    valid[150:160] = False
    bad = J.copy()
    bad[150:160] = np.nan  # anything may be there
    g = gait_analysis(bad, FPS, EVAL_NAMES, valid=valid)
    assert all(not (148 <= p <= 161) for ev in (*g.strikes, *g.foot_offs) for p in ev)
    assert all(c.end < 150 or c.strike > 159 for c in g.cycles)
    assert len(g.cycles) < len(clean.cycles)
    assert compare_gaits(g, clean).spurious == 0
    assert np.isfinite(g.cadence)


def test_bad_input(walking):
    J, _ = walking
    with pytest.raises(InputError, match="missing"):
        gait_analysis(J[:, :3], FPS, EVAL_NAMES[:3])
    bad = J.copy()
    bad[4, 0, 0] = np.nan
    with pytest.raises(InputError, match="NaN"):
        gait_analysis(bad, FPS, EVAL_NAMES)
    with pytest.raises(InputError, match="fps"):
        gait_analysis(J, 0.0, EVAL_NAMES)
    with pytest.raises(InputError, match="side"):
        gait_analysis(J, FPS, EVAL_NAMES).summary("middle")


# --------------------------------------------------------------------------- folders, CLI


def _capture(folder, J):
    """A capture folder with ground-truth joints only (no images): enough for gait."""
    (folder / "truth").mkdir(parents=True)
    write_meta(
        folder / "capture.json",
        {"fps": FPS, "frames": list(range(len(J))), "eval_names": list(EVAL_NAMES)},
    )
    for i, j in enumerate(J):
        write_truth(folder / "truth" / f"{i:05d}.npz", Truth(j, j))
    return Capture(folder)


def _track(folder, capture, J, *, lost=()):
    meta = {
        "method": "jittered",
        "template": "neutral_5k",
        "capture": str(capture.path),
        "eval_names": list(EVAL_NAMES),
        "eval_parents": EVAL_PARENTS.tolist(),
    }
    start_track(folder, meta, np.zeros((1, 3), np.int64), resume=False)
    for i, j in enumerate(J):
        flags = ("lost",) if i in lost else ()
        write_frame(folder, FrameResult(i, j, j, flags=flags))
    return folder


@pytest.fixture(scope="module")
def folders(walking, template, tmp_path_factory):
    """(capture of the walk's truth, track of it jittered, capture of a squat)."""
    root = tmp_path_factory.mktemp("gait")
    J = walking[0][:240]
    cap = _capture(root / "cap", J)
    noisy = J + np.random.default_rng(3).normal(0.0, 0.008, J.shape)
    track = _track(root / "track", cap, noisy, lost=range(100, 104))
    sq = _capture(root / "squat", _joints(template, squat(template, duration=2.0, fps=FPS)))
    return cap, track, sq


def test_track_gait_reads_flags_and_the_capture_truth(folders):
    cap, track, _ = folders
    g = track_gait(read_track(track), FPS)
    assert not g.valid[100:104].any() and g.valid[:100].all()
    truth = capture_gait(cap)
    c = compare_gaits(g, truth)
    assert c.spurious == 0 and c.max_offset <= 1.0
    assert c.matched >= c.reference_events - 2  # events beside the lost frames are dropped


def test_gait_command_writes_tables_and_plots(folders, tmp_path, capsys):
    cap, track, _ = folders
    out = tmp_path / "g"
    assert main(["gait", str(track), "--out", str(out)]) == 0
    text = capsys.readouterr().out
    assert "against the ground truth" in text and "events matched" in text
    rows = list(csv.DictReader((out / "gait.csv").read_text().splitlines()))
    cycles = [r for r in rows if r["cycle"] != "all"]
    both = next(r for r in rows if r["side"] == "both" and r["cycle"] == "all")
    assert len(cycles) >= 2 and all(r["stride_length_m"] for r in cycles)
    assert float(both["cadence_steps_per_min"]) == pytest.approx(110.0, rel=0.02)
    events = list(csv.DictReader((out / "gait_events.csv").read_text().splitlines()))
    assert {e["event"] for e in events} == {"foot_strike", "foot_off"}
    curves = list(csv.DictReader((out / "gait_curves.csv").read_text().splitlines()))
    assert len(curves) == CYCLE_SAMPLES * len(cycles)
    frames = list(csv.DictReader((out / "gait_frames.csv").read_text().splitlines()))
    assert (
        len(frames) == 240
        and frames[101]["valid"] == "0"
        and frames[101]["left_hip_flexion_deg"] == ""
    )
    for png in ("gait.png", "gait_flexion.png"):
        assert (out / png).stat().st_size > 20_000
    # the capture's own truth, and a clip without walking: one line, status 2
    assert main(["gait", str(cap.path), "--out", str(tmp_path / "t")]) == 0
    assert "ground truth of cap" in capsys.readouterr().out
    assert main(["gait", str(folders[2].path), "--out", str(tmp_path / "s")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "no walking" in err[0] and "0.00 m/s" in err[0]
    assert not (tmp_path / "s").exists()
    assert main(["gait", str(tmp_path / "nowhere"), "--out", str(tmp_path / "n")]) == 2


def test_report_gait_section(folders):
    """The report's gait section: truth and track rows, the comparison, notes and plots; a
    clip without walking says why instead of numbers."""
    from meshmocap.apps.report.page import gait_section, table_html

    cap, track, squat_cap = folders
    s = gait_section(cap, [read_track(track)], ["jittered"])
    (t,) = s.tables
    truth, tracked = t.rows
    assert truth[0] == "ground truth" and truth[3] == pytest.approx(110.0, rel=0.01)
    matched, events = map(int, tracked[8].split("/"))  # no "+n": no spurious event
    assert tracked[0] == "jittered" and events - 2 <= matched <= events
    assert abs(tracked[11]) < 2.0 and tracked[10] <= 1.0  # cadence error %, max offset
    assert any("ankle joints" in n for n in t.notes) and len(s.images) == 2
    html = table_html(t)
    assert "<tfoot>" in html and "events matched" in html
    # no walking: a note, no row, no plot
    sq = _track(
        squat_cap.path.parent / "squat_track",
        squat_cap,
        np.stack([f.truth.joints for f in squat_cap]),
    )
    s = gait_section(squat_cap, [read_track(sq)], ["squat"])
    assert s.tables[0].rows == () and s.images == ()
    assert any(n.startswith("squat: no gait: the pelvis travels") for n in s.tables[0].notes)
