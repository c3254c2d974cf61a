"""``meshmocap track --follow --view``: each frame tracked goes to a rerun recording
(headless: ``OUT/live.rrd``), read back with rerun's own command line."""

import re
import subprocess
import sys
from pathlib import Path

from external import require_module
from meshmocap.cli import main


def _rows(rrd: Path) -> dict[str, int]:
    """Rows logged per entity and component, from ``rerun rrd print``."""
    rerun = Path(sys.executable).parent / "rerun"
    res = subprocess.run(
        [str(rerun), "rrd", "print", str(rrd)], capture_output=True, text=True, timeout=120
    )
    assert res.returncode == 0, res.stderr[-2000:]
    rows: dict[str, int] = {}
    for n, entity, columns in re.findall(
        r"with (\d+) rows .* - (\S+) - data columns: \[(.*)\]", res.stdout
    ):
        for column in columns.split():
            key = f"{entity}:{column.split(':')[-1]}"
            rows[key] = rows.get(key, 0) + int(n)
    return rows


def test_follow_view_records_every_frame(small_walk, tmp_path, monkeypatch, capsys):
    require_module("rerun", "rerun")
    monkeypatch.delenv("DISPLAY", raising=False)  # headless: the recording is written
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    monkeypatch.setenv("RERUN_ANALYTICS", "false")
    # the session's cheapest capture (5 frames), from its true first pose (the search is
    # tested in tests/estimate/pose/)
    n = len(small_walk)
    out = tmp_path / "track"
    args = ["track", str(small_walk.path), "--follow", "--idle", "1", "--view", "--init", "truth"]
    assert main([*args, "--method", "articulated_icp", "--out", str(out)]) == 0
    said = capsys.readouterr().out
    assert f"live view: {n} frames recorded in {out / 'live.rrd'}" in said
    rows = _rows(out / "live.rrd")
    assert rows["/track/body:vertex_positions"] == n  # one body per frame
    assert rows["/track/body:triangle_indices"] == 1  # its triangles once
    assert rows["/track/joints:positions"] == n and rows["/track/skeleton:strips"] == n


def test_view_goes_with_follow(tmp_path, capsys):
    cap = tmp_path / "capture"
    cap.mkdir()
    assert main(["track", str(cap), "--view", "--out", str(tmp_path / "t")]) == 2
    assert "track: --view goes with --follow" in capsys.readouterr().err
