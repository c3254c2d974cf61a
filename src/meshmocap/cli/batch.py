"""Many captures at once: ``meshmocap batch`` (Dask when installed, else one by one)."""

from __future__ import annotations

import argparse


def _cmd_batch(args: argparse.Namespace) -> int:
    from meshmocap.apps.batch.items import batch_items
    from meshmocap.apps.batch.run import run_batch

    items = batch_items(
        args.captures, method=args.method, template=args.template, frames=args.frames or ""
    )
    res = run_batch(
        items,
        args.out,
        workers=args.workers,
        scheduler=args.scheduler,
        serial=args.serial,
        dashboard=not args.no_dashboard,
        log=lambda line: print(line, flush=True),
    )
    ok = sum(s.status == "ok" for s in res.summaries)
    how = "on Dask" if res.mode == "dask" else "one after another"
    print(
        f"batch: {ok} of {len(res.summaries)} captures tracked {how} in {res.seconds:.1f} s; "
        f"summary in {res.files[1]}"
    )
    return 0 if ok == len(res.summaries) else 1


def register(sub: argparse._SubParsersAction) -> None:
    """Add the parser of ``batch`` to ``sub``."""
    b = sub.add_parser(
        "batch",
        help="track many captures at once (Dask: local cores or a cluster)",
        description="Carve missing hulls, track and evaluate many captures as Dask tasks; "
        "write one folder per capture and summary.csv / summary.md. Rerunning redoes only "
        "what is missing. Without dask (pip install -e '.[cluster]') the captures run "
        "one after another.",
    )
    b.add_argument(
        "captures",
        nargs="+",
        metavar="CAPTURE",
        help="capture folders, globs, a "
        ".txt list (one per line) or a .csv manifest (columns capture, method, "
        "template, frames)",
    )
    b.add_argument(
        "--method",
        default="patch",
        help="tracker for captures whose manifest row names none (default: %(default)s)",
    )
    b.add_argument(
        "--template",
        help="tracking template (name or .npz, or auto; default: as "
        "track chooses, the one capture.json names, else the performer's body "
        "estimated from each capture)",
    )
    b.add_argument("--frames", help="frame range START:STOP[:STEP] of every capture")
    b.add_argument("--out", required=True, help="batch folder")
    b.add_argument("--workers", type=int, help="local worker processes (default: the cores)")
    b.add_argument(
        "--scheduler",
        help="address of a running Dask scheduler, e.g. "
        "tcp://host:8786 (default: start a local cluster)",
    )
    b.add_argument("--serial", action="store_true", help="run in this process, no Dask")
    b.add_argument("--no-dashboard", action="store_true", help="no Dask dashboard")
    b.set_defaults(func=_cmd_batch)
