"""Marker exports in OpenSim (``pip install -e ".[opensim]"``): the documentation's
OpenSim script reads a gait track's TRC and C3D and runs inverse kinematics; its hip and
knee flexion agree with ``meshmocap gait``'s. Skips without ``opensim`` unless
``MESHMOCAP_REQUIRE`` names it (CI)."""

import csv
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from external import SCRIPTS, included_script, require_module, walk_track
from meshmocap.apps.files.export import export_track
from meshmocap.cli import main

SCRIPT = SCRIPTS / "opensim_ik.py"
T, FPS = 90, 30.0


def test_the_docs_page_is_the_script():
    assert included_script("guide/opensim.rst") == SCRIPT


@pytest.fixture(scope="module")
def track_dir(tmp_path_factory):
    """Three seconds of a procedural walk (110 steps/min) on neutral_5k at 30 fps as a
    track: the posed template, its evaluation joints off by 2 mm of noise (seeded)."""
    out = tmp_path_factory.mktemp("opensim") / "walk"
    walk_track(out, T, FPS, noise=0.002)
    return out


def inverse_kinematics(markers: Path, tmp_path: Path) -> dict[str, np.ndarray]:
    """Run the docs' script on ``markers``; return its .mot's columns."""
    mot = tmp_path / f"{markers.stem}_{markers.suffix[1:]}.mot"
    cmd = [sys.executable, str(SCRIPT), str(markers), "--out", str(mot)]
    cmd += ["--model", str(tmp_path / "model.osim")]
    res = subprocess.run(cmd, capture_output=True, text=True, timeout=300, cwd=tmp_path)
    assert res.returncode == 0, res.stdout[-3000:] + res.stderr[-3000:]
    assert f"{markers.name}: {T} frames, 15 markers" in res.stdout
    error_mm = float(res.stdout.split("RMS marker error ")[1].split()[0])
    assert error_mm < 5.0, res.stdout  # the model's segments fit the joints
    header, *rows = mot.read_text().split("endheader\n", 1)[1].splitlines()
    values = np.array([[float(x) for x in r.split("\t")] for r in rows])
    return dict(zip(header.split("\t"), values.T, strict=True))


def test_inverse_kinematics_agrees_with_gait(track_dir, tmp_path):
    require_module("opensim", "opensim")
    trc = export_track(track_dir, tmp_path / "walk.trc").path
    c3d = export_track(track_dir, tmp_path / "walk.c3d").path
    from_trc = inverse_kinematics(trc, tmp_path)
    from_c3d = inverse_kinematics(c3d, tmp_path)
    assert len(from_trc["time"]) == T
    np.testing.assert_allclose(from_trc["time"], np.arange(T) / FPS, atol=1e-5)
    for name, values in from_trc.items():  # the two files hold the same markers
        np.testing.assert_allclose(from_c3d[name], values, atol=0.05, err_msg=name)
    gait_dir = tmp_path / "gait"
    assert main(["gait", str(track_dir), "--out", str(gait_dir), "--fps", "30"]) == 0
    rows = list(csv.DictReader((gait_dir / "gait_frames.csv").read_text().splitlines()))
    assert len(rows) == T
    for side, s in (("left", "l"), ("right", "r")):
        for joint in ("hip", "knee"):
            gait = np.array([float(r[f"{side}_{joint}_flexion_deg"]) for r in rows])
            ik = from_trc[f"{joint}_flexion_{s}"]
            rms = np.sqrt(np.mean((ik - gait) ** 2))
            assert rms < 3.0, (side, joint, rms)  # the acceptance
            assert np.ptp(gait) > 40  # a walk's swing, not two flat lines
