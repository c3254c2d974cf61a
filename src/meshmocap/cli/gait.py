"""Gait analysis: ``meshmocap gait``."""

from __future__ import annotations

import argparse


def _cmd_gait(args: argparse.Namespace) -> int:
    from meshmocap._progress import phase
    from meshmocap.analysis.tables import format_table
    from meshmocap.apps.files.gait import SUMMARY_HEADERS, gait_of, summary_rows, write_gait

    with phase(f"analysing the gait of {args.source}"):
        run = gait_of(args.source, fps=args.fps, truth=not args.no_truth)
        g = run.gait
        files = write_gait(g, args.out, reference=run.reference, title=run.what)  # no gait: raises
    print(
        f"gait of {run.what}: {len(g.steps)} step(s), {len(g.cycles)} full cycle(s) "
        f"(walking speed {g.progression_speed:.2f} m/s)"
    )
    print(format_table(SUMMARY_HEADERS, summary_rows(g), digits=2))
    if run.reference is not None:
        r, c = run.reference, run.comparison
        if c is None:
            print(f"ground truth: {r.message or 'not comparable'}")
        else:
            s = r.summary()
            print(
                f"against the ground truth ({s.cadence_steps_per_min:.1f} steps/min, stride "
                f"{s.stride_length_m:.3f} m): {c.matched}/{c.reference_events} events matched "
                f"({c.spurious} spurious), offset mean {c.mean_offset:.2f} frames, max "
                f"{c.max_offset:.2f}; cadence {c.cadence_error_pct:+.2f} %, stride length "
                f"{c.stride_length_error_pct:+.2f} %"
            )
    print(f"wrote {len(files)} files to {args.out}")
    return 0


def register(sub: argparse._SubParsersAction) -> None:
    """Add the parser of ``meshmocap gait`` to ``sub``."""
    g = sub.add_parser(
        "gait",
        help="gait events, cycles, cadence, stride, flexion curves of a track",
        description="Gait analysis of a track folder's joints (or of a capture folder's "
        "ground truth): foot strikes and foot offs, cycles, cadence, step and stride length "
        "and time, speed, stance and swing %%, hip and knee flexion per cycle; writes "
        "gait.csv, gait_events.csv, gait_curves.csv, gait_frames.csv, gait.png and "
        "gait_flexion.png. A track is compared with its capture's ground truth when it has one.",
    )
    g.add_argument("source", help="track folder (meshmocap track) or synthetic capture folder")
    g.add_argument("--out", required=True, help="folder for the CSV tables and PNG plots")
    g.add_argument("--fps", type=float, help="frame rate (default: the capture's)")
    g.add_argument("--no-truth", action="store_true", help="do not compare with the truth")
    g.set_defaults(func=_cmd_gait)
