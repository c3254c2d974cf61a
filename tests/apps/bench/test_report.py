"""The bench report (meshmocap.apps.bench.report): how the first poses were found comes from
the rows' start records, never from their messages."""

import numpy as np
import pytest

from meshmocap.apps.bench.report import write_report
from meshmocap.apps.bench.rows import BenchRow


def _row(capture: str, start: str, init: str) -> BenchRow:
    return BenchRow(
        capture,
        "patch",
        frames=2,
        mean_mm=10.0,
        frame_numbers=np.arange(2),
        per_frame_mm=np.array([9.0, 11.0]),
        init=init,
        start=start,
    )


@pytest.mark.parametrize(
    ("starts", "says"),
    [
        ({"walk": "truth", "jog": "truth"}, "initialised from ground truth,"),
        ({"walk": "search", "jog": "subject-fit"}, "from the capture alone (automatic"),
        ({"walk": "truth", "jog": "search"}, "from ground truth (jog: from the capture alone)"),
    ],
)
def test_the_protocol_line_says_how_the_first_poses_were_found(tmp_path, starts, says):
    # the words of a truth start begin "truth:"; a parser of them would count it as automatic
    rows = [_row(c, s, f"{s}: the first pose, in words") for c, s in starts.items()]
    write_report(tmp_path, rows, [], None)
    assert says in (tmp_path / "results.md").read_text()


def test_a_row_round_trips_its_start_and_an_older_row_reads_without_one():
    row = _row("walk", "search", "auto: 02_02:2")
    assert BenchRow.from_json(row.to_json()).start == "search"
    old = row.to_json()
    del old["start"]
    assert BenchRow.from_json(old).start == ""
