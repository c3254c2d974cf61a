"""An evaluation written to a folder: ``summary.txt``, CSV tables and PNG plots."""

from __future__ import annotations

import os
from pathlib import Path

from meshmocap._atomic import write_text_atomic
from meshmocap.analysis.evaluate import Evaluation, summary
from meshmocap.analysis.tables import write_csv
from meshmocap.apps.figures.evaluation import (
    plot_bone_lengths,
    plot_frame_errors,
    plot_joint_errors,
    plot_silhouette_errors,
)

__all__ = ["write_evaluation"]


def write_evaluation(ev: Evaluation, out: str | os.PathLike) -> list[Path]:
    """Write ``summary.txt``, CSV tables and PNG plots of ``ev`` into the folder ``out``."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    written = []
    write_text_atomic(out / "summary.txt", summary(ev) + "\n")
    written.append(out / "summary.txt")
    if ev.joints is not None:
        written += [
            write_csv(out / "joint_errors.csv", ev.joints),
            write_csv(out / "joint_errors_per_frame.csv", ev.joints, per_frame=True),
            plot_frame_errors(ev.joints, out / "joint_error_per_frame.png"),
            plot_joint_errors(ev.joints, out / "joint_error_per_joint.png"),
        ]
    if ev.bones is not None:
        written += [
            write_csv(out / "bone_lengths.csv", ev.bones),
            plot_bone_lengths(ev.bones, out / "bone_lengths.png"),
        ]
    if ev.silhouettes is not None:
        written += [
            write_csv(out / "silhouette_errors.csv", ev.silhouettes),
            plot_silhouette_errors(ev.silhouettes, out / "silhouette_errors.png"),
        ]
    if ev.correspondence is not None:
        written += [
            write_csv(out / "vertex_errors.csv", ev.correspondence),
            write_csv(out / "vertex_errors_per_frame.csv", ev.correspondence, per_frame=True),
            plot_frame_errors(ev.correspondence, out / "vertex_error_per_frame.png"),
        ]
    return written
