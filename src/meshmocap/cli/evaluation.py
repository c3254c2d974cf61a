"""Scores: ``meshmocap eval``, ``report`` and ``bench``."""

from __future__ import annotations

import argparse
import sys
import time

from meshmocap.cli._args import check_track_folders, number


def _cmd_eval(args: argparse.Namespace) -> int:
    from meshmocap import api
    from meshmocap._progress import phase
    from meshmocap.apps.files.evaluation import write_evaluation
    from meshmocap.io.plausibility import partial_hulls
    from meshmocap.io.results import input_frame, open_tracked_capture, read_track

    check_track_folders("eval", [args.track])
    track = read_track(args.track)
    capture = open_tracked_capture(track.meta, args.capture)
    if "input" in track.meta:
        print(f"{args.capture}: read as tracked ({input_frame(track.meta).describe()})\n")
    note = partial_hulls(capture, track.frames.tolist(), command="eval")
    if note:  # scored on hulls from fewer cameras: say so
        print(f"meshmocap: warning: {note}", file=sys.stderr)
    with phase("scoring the track against the truth"):
        ev = api.evaluate(
            capture,
            args.track,
            silhouettes=not args.no_silhouettes,
            surface_frames=args.surface_frames,
            force=args.force,
        )
    print(api.summary(ev))
    if args.out:
        with phase(f"writing the tables and plots into {args.out}"):
            files = write_evaluation(ev, args.out)
        print(f"\nwrote {len(files)} files to {args.out}")
    return 0


def _cmd_report(args: argparse.Namespace) -> int:
    from meshmocap._progress import phase
    from meshmocap.apps.batch.report import build_batch_report, is_batch_folder
    from meshmocap.apps.report.page import build_report
    from meshmocap.errors import InputError

    t0 = time.perf_counter()
    if is_batch_folder(args.capture):  # a batch folder: its summary and evaluations
        if args.tracks:
            raise InputError(f"report: {args.capture} is a batch folder; give no track folders")
        path = build_batch_report(args.out, args.capture)
    else:
        _check_report_tracks(args)
        with phase("scoring the tracks and writing the report"):
            path = build_report(
                args.out,
                args.capture,
                args.tracks,
                eval_dirs=args.eval_dir,
                max_frames=args.max_frames,
                silhouettes=not args.no_silhouettes,
                surface_frames=args.surface_frames,
                camera_frames=args.camera_frames,
            )
    size = path.stat().st_size / 1e6
    print(f"wrote {path} ({size:.1f} MB, {time.perf_counter() - t0:.1f} s); open it in a browser")
    return 0


def _check_report_tracks(args: argparse.Namespace) -> None:
    """Refuse a track made from another capture (unless ``--force``), before the report."""
    import json
    from pathlib import Path

    from meshmocap.io.guards import check_track_capture
    from meshmocap.io.results import open_tracked_capture

    check_track_folders("report", args.tracks)
    for t in args.tracks:
        meta_path = Path(t) / "track.json"
        try:
            meta = json.loads(meta_path.read_text(encoding="utf-8"))
        except (OSError, ValueError):
            continue  # the report itself says what is wrong with the folder
        if isinstance(meta, dict):  # the capture read as this track read it
            capture = open_tracked_capture(meta, args.capture)
            check_track_capture(t, meta, capture, force=args.force, command="report")


def _cmd_bench(args: argparse.Namespace) -> int:
    from meshmocap.apps.bench.report import markdown_table, tradeoff_table
    from meshmocap.apps.bench.run import run_bench
    from meshmocap.errors import InputError

    def items(values: list[str] | None) -> list[str] | None:  # "a,b c" → [a, b, c]
        return None if values is None else [n for v in values for n in v.split(",") if n]

    fractions = items(args.keep_fractions)
    try:
        keep = (
            None
            if fractions is None
            # None: the set's sweep
            else []
            if fractions == ["none"]
            else [float(f) for f in fractions]
        )
    except ValueError:
        msg = f"bench: --keep-fractions must be numbers or none, found {fractions}"
        raise InputError(msg) from None
    res = run_bench(
        args.out,
        captures=items(args.captures) or args.set,
        methods=items(args.methods),
        data=args.data,
        work=args.work,
        max_frames=args.max_frames,
        keep_fractions=keep,
        template=args.template,
        init=args.init,
        log=lambda line: print(line, flush=True),
    )
    print(f"\n{markdown_table(res.rows)}")
    if res.tradeoff:
        print(f"\nkept fraction of the patch classifier on {res.tradeoff_capture} (Fig. 8):")
        print(tradeoff_table(res.tradeoff))
    for name, why in res.skipped:
        print(f"left out {name}: {why}")
    n = len(res.rows) + len(res.tradeoff)
    print(
        f"\nwrote {len(res.files)} files to {args.out} in {res.seconds:.0f} s "
        f"({n} results, {len(res.tracked)} tracked by this run)"
    )
    return 0


_FORCE = (
    "score a track against a capture other than the one its track.json names (refused otherwise)"
)


def register(sub: argparse._SubParsersAction) -> None:
    """Add the parsers of this module's commands to ``sub``."""
    e = sub.add_parser(
        "eval",
        help="score a track against its capture's ground truth (or, for a mesh sequence of "
        "fixed connectivity, against its files: the per-vertex error)",
    )
    e.add_argument(
        "capture",
        help="capture folder, or the mesh files tracked (read in the up axis, "
        "units and frame rate track.json records)",
    )
    e.add_argument("track", help="track folder written by 'meshmocap track'")
    e.add_argument("--out", help="folder for CSV tables and PNG plots")
    e.add_argument("--no-silhouettes", action="store_true", help="skip the silhouette error")
    e.add_argument("--force", action="store_true", help=_FORCE)
    e.add_argument(
        "--surface-frames",
        type=number(0, 10_000, integer=True),
        default=8,
        help="frames for surface distances",
    )
    e.set_defaults(func=_cmd_eval)
    o = sub.add_parser("report", help="write an HTML report: scores, plots and a 3D player")
    o.add_argument("capture", help="capture folder, or a batch folder (meshmocap batch)")
    o.add_argument("tracks", nargs="*", metavar="track", help="track folders to compare")
    o.add_argument("--out", required=True, help="HTML file to write (one self-contained file)")
    o.add_argument(
        "--eval-dir",
        action="append",
        help="keep each track's CSV/PNG evaluation here (repeat once per track, in order)",
    )
    o.add_argument(
        "--max-frames",
        type=number(1, 100_000, integer=True),
        help="at most N frames in the 3D player (default: every frame the size budget allows)",
    )
    o.add_argument("--no-silhouettes", action="store_true", help="skip the silhouette error")
    o.add_argument("--force", action="store_true", help=_FORCE)
    o.add_argument(
        "--surface-frames",
        type=number(0, 10_000, integer=True),
        default=8,
        help="frames for surface distances",
    )
    o.add_argument(
        "--camera-frames",
        type=number(0, 1000, integer=True),
        default=4,
        help="frames shown per camera with the skeleton drawn over them (0: none; "
        "default: %(default)s)",
    )
    o.set_defaults(func=_cmd_report)
    b = sub.add_parser(
        "bench",
        help="compare every tracker on a set of captures",
        description="Run every tracker on a set of captures; write results.csv, results.md "
        "and plots. Captures are BASE[+VARIANT...]: BASE a procedural motion (walk, jog, "
        "squat, ...), a CMU clip (05_01, 09_01, 01_01; needs --data) or crane (needs --data); "
        "VARIANT humaneva4|ring8, degraded, heavy_male|small_female. Re-runs reuse the work "
        "folder.",
    )
    b.add_argument("--set", default="quick", help="quick (minutes; run it first), standard, full")
    b.add_argument("--captures", nargs="+", help="captures instead of a set, e.g. walk,walk+ring8")
    b.add_argument("--methods", nargs="+", help="trackers (default: the set's, else all)")
    b.add_argument("--data", help="shared data folder (CMU clips, crane), e.g. ../shared/data")
    b.add_argument("--work", help="cache of captures and tracks (default: OUT/work); resumes")
    b.add_argument("--out", required=True, help="report folder")
    b.add_argument(
        "--max-frames", type=number(1, 1_000_000, integer=True), help="at most N frames per capture"
    )
    b.add_argument("--keep-fractions", nargs="+", help="Fig. 8 sweep of the patch tracker")
    b.add_argument("--template", default="neutral_5k", help="tracking template")
    b.add_argument(
        "--init",
        default="truth",
        choices=["truth", "auto"],
        help="first pose of "
        "the synthetic captures: from ground truth (the papers' protocol, default) "
        "or found from the capture (the crane always is)",
    )
    b.set_defaults(func=_cmd_bench)
