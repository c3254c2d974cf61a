"""The main job on the bundled defaults: ``meshmocap demo``."""

from __future__ import annotations

import argparse

from meshmocap.cli._args import frame_range, number


def _cmd_demo(args: argparse.Namespace) -> int:
    from meshmocap._progress import phase

    with phase("loading meshmocap's modules"):  # scipy, matplotlib, scikit-learn...: seconds
        from meshmocap.apps.demo import run_demo

    frames = args.frames
    if args.track_frames is not None:  # the old spelling: a count from frame 0, 0 skips
        frames = slice(0, args.track_frames) if args.track_frames > 0 else None
    res = run_demo(
        args.out,
        seconds=args.seconds,
        frames=frames,
        clip=args.clip,
        subject=args.subject,
        template=args.template,
    )
    print(f"meshmocap demo: wrote {args.out}/ in {res.seconds:.1f} s")
    for note in res.notes:
        print(f"  {note}")
    for what, path in res.files:
        print(f"  {what:<56} {path}")
    if res.scores:
        print(f"\n{'tracker':<18} {'mean joint error':>17} {'worst frame':>12} {'s/frame':>8}")
        for s in res.scores:
            print(f"{s.method:<18} {s.mean_mm:>14.1f} mm {s.max_mm:>9.1f} mm {s.seconds:>8.2f}")
        print("worst frame: the frame with the largest mean error over the 15 joints")
    return 0


def register(sub: argparse._SubParsersAction) -> None:
    """Add the parsers of this module's commands to ``sub``."""
    d = sub.add_parser("demo", help="run the main job on the bundled defaults")
    d.add_argument("--out", default="meshmocap-demo", help="output folder (default: %(default)s)")
    d.add_argument(
        "--seconds", type=number(0.1, 600, "seconds"), default=4.0, help="length of the demo walk"
    )
    d.add_argument("--clip", help="also retarget and render this BVH/AMC clip")
    d.add_argument(
        "--frames",
        type=frame_range,
        default=slice(0, 120),
        help="frame numbers START:STOP[:STEP] of the synthetic capture (60 fps) that the "
        "trackers follow (default: 0:120)",
    )
    d.add_argument("--no-track", dest="frames", action="store_const", const=None, help="no capture")
    d.add_argument("--track-frames", type=number(0, 100_000, integer=True), help=argparse.SUPPRESS)
    d.add_argument(
        "--subject",
        default="heavy_male",
        help="bundled body that performs in the capture, as in `meshmocap synth --subject` "
        "(default: %(default)s)",
    )
    d.add_argument("--performer", dest="subject", help=argparse.SUPPRESS)
    d.add_argument(
        "--template",
        default="auto",
        help="tracking template: auto estimates "
        "the performer's body from the hulls (default), or a name or .npz",
    )
    d.set_defaults(func=_cmd_demo)
