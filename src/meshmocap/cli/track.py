"""Tracking: ``meshmocap track``, and live mode (``track FOLDER --follow``)."""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

from meshmocap._validate import counted
from meshmocap.cli._args import add_frames, add_restart, flag, number

#: Tracking options the command line offers (each taken only by the methods that have it).
TRACK_OPTIONS = (
    "n_patches",
    "classifier",
    "keep_fraction",
    "outlier_sigmas",
    "max_iter",
    "fast_iter_scale",
    "joint_readout",
)

#: Defaults of the tracking options, as ``track --help`` states them (the tracker options'
#: own, :func:`meshmocap.trackers.registry.resolved_options`; a test keeps them equal):
#: written out so that ``--help`` does not import the trackers.
DEFAULTS = {
    "n_patches": 200,
    "classifier": "logistic",
    "keep_fraction": 1.0,
    "max_iter": 8,
    "icp_max_iter": 20,
}

#: Fewest patches ``--n-patches`` takes: about one per bone of the evaluation skeleton (the
#: paper uses 150–250). With one patch the rigidity energy has no pair and is NaN.
MIN_PATCHES = 16


def _tracker_options(args: argparse.Namespace) -> dict:
    from meshmocap.errors import InputError
    from meshmocap.trackers.registry import METHODS, method_options

    given = {n: getattr(args, n) for n in TRACK_OPTIONS if getattr(args, n) is not None}
    if args.method not in METHODS:  # the registry's one-line error
        method_options(args.method)
    takes = method_options(args.method)
    unused = [n for n in given if n not in takes]
    if unused:
        users = [m for m in METHODS if unused[0] in method_options(m)]
        offered = [flag(n) for n in TRACK_OPTIONS if n in takes]
        raise InputError(
            f"track: {flag(unused[0])} is not an option of --method {args.method} (it is of "
            f"{', '.join(users)}); {args.method} takes {', '.join(offered) or 'none of them'}"
        )
    return given


def _cmd_track(args: argparse.Namespace) -> int:
    from meshmocap._progress import phase

    with phase("loading meshmocap's modules"):  # scipy, matplotlib, scikit-learn...: seconds
        from meshmocap import api
    from meshmocap._timing import StageTimer
    from meshmocap._validate import frame_positions
    from meshmocap.errors import InputError
    from meshmocap.io.guards import check_resumable
    from meshmocap.io.plausibility import check_observations
    from meshmocap.io.results import done_frames
    from meshmocap.trackers.options import TrackOptions

    options = _tracker_options(args)
    live = args.follow
    if not live and (args.idle is not None or args.view or args.recording):
        given = "--idle" if args.idle is not None else "--view" if args.view else "--recording"
        raise InputError(f"track: {given} goes with --follow")
    if live and (len(args.capture) != 1 or args.frames):
        raise InputError("track --follow: give one folder (a capture or meshes) and no --frames")
    if live:
        idle = f"; stops after {args.idle:g} s without a new frame" if args.idle else ""
        print(f"following {args.capture[0]} with {args.method} (Ctrl-C stops){idle}", flush=True)
    before = set() if args.restart else set(done_frames(args.out))
    run = _Run(args)
    timer = StageTimer()
    try:
        capture, axes = api.capture_and_axes(
            args.capture, up=args.up, units=args.units, fps=args.fps, follow=live, idle=args.idle
        )
        if axes is not None:
            rate = f"{capture.fps:g} fps" + ("" if args.fps else " (assumed; --fps to set)")
            print(
                f"{args.capture[0]}: {axes.up.upper()} up, {axes.units}, a body "
                f"{axes.span:.2f} m long (--up, --units to set); {rate}"
            )
        gaps = getattr(capture, "gaps", [])
        if gaps:
            print(
                f"meshmocap: warning: {counted(len(gaps), 'frame number')} without a file "
                f"(first {gaps[0]}): tracked as missing frames, coasted across",
                file=sys.stderr,
            )
        frames = None
        if args.frames:
            numbers = [int(i) for i in capture.indices]
            frames = frame_positions(numbers, args.frames)  # --frames: frame numbers
            if not frames:
                raise InputError(
                    f"track: --frames {_text(args.frames)} selects none of the {len(numbers)} "
                    f"frames (numbers {numbers[0]}..{numbers[-1]}) of {args.capture[0]}"
                )
            if args.frames.stop is not None and args.frames.stop > numbers[-1] + 1:
                print(
                    f"meshmocap: warning: --frames {_text(args.frames)} asks for frames up to "
                    f"{args.frames.stop - 1}; the capture ends at frame {numbers[-1]}: "
                    f"tracking {len(frames)}",
                    file=sys.stderr,
                )
        if not args.restart:  # --out holds this capture's track, or none
            check_resumable(args.out, capture)
        for line in check_observations(capture, frames):  # one person? dense? partial hulls?
            print(f"meshmocap: warning: {line}", file=sys.stderr)
        run.capture = capture if live else None
        if args.view or args.recording:
            run.view = _live_view(args)
        how = TrackOptions(
            frames=args.frames or None,  # frame numbers, as meshmocap.track(frames=)
            init=args.init,
            resume=not args.restart,
            recover=not args.no_recover,
            refine=args.refine,
            passes=args.passes,
            vertices=False,
            show_progress=False if live else None,
        )
        result = api.track(
            capture,
            method=args.method,
            out=args.out,
            template=args.template,
            manifold=args.manifold,
            options=how,
            log=print,
            on_frame=run.frame if live else None,
            timer=None if live else timer,
            **options,
        )
    except KeyboardInterrupt:
        if not live:
            raise
        return run.stopped("Ctrl-C")
    if live:
        return run.stopped(f"no new frame for {args.idle:g} s" if args.idle else "stopped")
    _summary(args, result, before, timer)
    return 0


def _summary(args: argparse.Namespace, result, before: set[int], timer) -> None:
    """What ``track`` did: frames tracked and resumed, time, the start, the flags, and where
    a frame's time goes (``timer``: :class:`~meshmocap._timing.StageTimer`)."""
    from meshmocap.analysis.evaluate import track_init

    track, dt = result.data, result.seconds
    resumed = len(before & set(track.frames.tolist()))
    new = len(track.frames) - resumed
    bad = int((~track.healthy).sum())
    missing = sum("missing" in f for f in track.flags)
    fresh = [s for i, s in zip(track.frames, track.seconds, strict=True) if int(i) not in before]
    per = sum(fresh[1:]) / (len(fresh) - 1) if len(fresh) > 1 else 0.0
    done = f"tracked {counted(new, 'frame')}"
    done += f" ({resumed} resumed from an earlier run)" if resumed else ""
    flagged = f"{bad} flagged unhealthy" + (f" ({missing} missing)" if missing else "")
    print(
        f"{done} with {args.method} in {dt:.1f} s ({per:.3f} s per frame); "
        f"init {track_init(track)}; {flagged}{_lost(track)}; results in {args.out}"
    )
    if len(timer.frames) > 1:  # where a frame's time goes (frame 1 compiles and warms up)
        print(f"time {timer.summary()}")
    if missing:
        first = next(k for k, f in enumerate(track.flags) if "missing" in f)
        print(
            f"meshmocap: warning: {counted(missing, 'frame')} without a usable observation "
            f"(skipped, coasted across), first {int(track.frames[first])}: "
            f"{track.messages[first]}",
            file=sys.stderr,
        )


def _lost(track) -> str:
    """Frames with a limb lost (and re-initialised, where some were) and the first one's
    reason ('' if none)."""
    lost = [k for k, f in enumerate(track.flags) if "lost" in f]
    if not lost:
        return ""
    reinit = sum("reinit" in f for f in track.flags)
    again = f"{reinit} re-initialised; " if reinit else ""
    k = lost[0]
    return (
        f", {counted(len(lost), 'frame')} with a limb lost ({again}first: frame "
        f"{int(track.frames[k])}, {track.messages[k]})"
    )


class _Run:
    """Live mode's report: a line per frame as it is written (its time, its latency from
    the file's writing to its result on disk, its flags), the live view, and the closing
    line."""

    def __init__(self, args: argparse.Namespace):
        self.args = args
        self.seconds: list[float] = []
        self.flagged = 0
        self.view = None
        self.capture = None  # the LiveCapture, once open

    def frame(self, r) -> None:
        """Report the frame result ``r`` (just written)."""
        self.seconds.append(r.seconds)
        self.flagged += not r.healthy
        if self.view is not None:
            self.view.show(r.index)
        written = self.capture.written(r.index) if self.capture is not None else None
        latency = f", latency {1000 * (time.time() - written):.0f} ms" if written else ""
        flags = f"  {','.join(r.flags)}: {r.message}" if r.flags else ""
        print(f"frame {r.index}: {1000 * r.seconds:.0f} ms{latency}{flags}", flush=True)

    def stopped(self, how: str) -> int:
        """Print the closing line and return the exit status: 0, or (130 after Ctrl-C, else
        1) when the track folder holds no frame, with a line saying so."""
        from meshmocap.io.results import done_frames

        n = len(self.seconds)
        per = sorted(self.seconds)[n // 2] if n else 0.0
        have = len(done_frames(self.args.out))
        kept = f" ({have - n} from an earlier run)" if have > n else ""
        print(
            f"{how}: tracked {counted(n, 'frame')} (median {1000 * per:.0f} ms per frame, "
            f"{self.flagged} flagged){kept}; results in {self.args.out}"
        )
        if self.view is not None:
            self.view.close()
            if self.view.path is not None:
                print(
                    f"live view: {self.view.frames} frames recorded in {self.view.path} "
                    f"(rerun {self.view.path})"
                )
        if n:
            return 0
        print(
            f"meshmocap: warning: track --follow: this run tracked no frame of "
            f"{self.args.capture[0]} ({how})",
            file=sys.stderr,
        )
        return 0 if have else 130 if how == "Ctrl-C" else 1


def _live_view(args: argparse.Namespace):
    """``--view``: :class:`meshmocap.apps.live_view.LiveView` of the track folder."""
    from meshmocap.apps.live_view import LiveView
    from meshmocap.body.template import EVAL_PARENTS

    Path(args.out).mkdir(parents=True, exist_ok=True)
    return LiveView(args.out, parents=EVAL_PARENTS, recording=args.recording)


def _text(s: slice) -> str:
    return ":".join("" if v is None else str(v) for v in (s.start, s.stop, s.step)).rstrip(":")


def register(sub: argparse._SubParsersAction) -> None:
    """Add the parsers of this module's commands to ``sub``."""
    k = sub.add_parser(
        "track", help="track a capture: skeleton joints and template shape per frame"
    )
    k.add_argument(
        "capture",
        nargs="+",
        help="capture folder (meshmocap synth/hull), or mesh "
        "or point-cloud files, folders or a quoted glob or archive of them",
    )
    k.add_argument(
        "--method",
        default="patch",
        help="patch, patch_svc, patch_noclf, "
        "articulated_icp, cage, cage_quads, cage_noreg, cage_nolocal (default: %(default)s)",
    )
    k.add_argument(
        "--template",
        help="tracking template: a name or .npz, or auto to estimate "
        "the performer's body (default: the template capture.json names, else auto; "
        "an estimate is cached as subject.npz in --out)",
    )
    k.add_argument(
        "--out",
        required=True,
        help="track folder (frame-by-frame results); a new folder, or this capture's track "
        "to resume, never the input's own folder",
    )
    add_frames(k, "default: all")
    k.add_argument(
        "--n-patches",
        type=number(MIN_PATCHES, 10_000, integer=True),
        help=f"patch tracker: number of patches (default {DEFAULTS['n_patches']}; at least "
        f"{MIN_PATCHES}: fewer cannot follow the limbs, and one has no neighbour to be rigid "
        "with)",
    )
    k.add_argument(
        "--classifier",
        help=f"patch tracker: logistic, svc or none (default {DEFAULTS['classifier']})",
    )
    k.add_argument(
        "--keep-fraction",
        type=number(0, 1, open_lo=True),
        help=f"patch tracker: fraction of the on-bone points kept (default "
        f"{DEFAULTS['keep_fraction']:g}: all)",
    )
    k.add_argument(
        "--outlier-sigmas",
        type=number(0, 100, open_lo=True),
        help="patch tracker: a point this many σ "
        "from the model is as likely an outlier (default 3; 2 rejects more of a "
        "few-camera hull's phantom volumes, but also true points where the subject's "
        "surface differs from the template's)",
    )
    k.add_argument(
        "--max-iter",
        type=number(1, 10_000, integer=True),
        help=f"iterations per frame (default {DEFAULTS['max_iter']} for the patch tracker, "
        f"{DEFAULTS['icp_max_iter']} for articulated_icp; the cage methods have their own "
        "schedule)",
    )
    k.add_argument(
        "--fast-iter-scale",
        type=number(1, 100),
        help="patch tracker: iterations of a frame "
        "after a fast one (a joint moved > 5 cm), as a multiple of the usual "
        "(default 2.5; 1 keeps every frame's cost the same)",
    )
    k.add_argument(
        "--joint-readout",
        help="patch tracker: joints reported: blend (default: "
        "pelvis and thorax read off the surface, limbs mostly from the skeleton), "
        "skeleton (the paper's) or surface",
    )
    k.add_argument(
        "--manifold",
        help="cage methods: pose manifold from 'meshmocap learn' "
        "(default: learned from the bundled CMU pose library at first use, cached)",
    )
    k.add_argument(
        "--init",
        default="auto",
        choices=["auto", "truth"],
        help="first pose: "
        "found from the capture (auto, default) or copied from its ground truth "
        "(truth: the papers' protocol, synthetic captures only)",
    )
    k.add_argument(
        "--up",
        default="auto",
        choices=["auto", "z", "y"],
        help="mesh/point-cloud files: their up axis (default: detected)",
    )
    k.add_argument(
        "--units",
        default="auto",
        choices=["auto", "m", "cm", "mm"],
        help="mesh/point-cloud files: their length unit (default: detected)",
    )
    k.add_argument(
        "--refine",
        default="auto",
        choices=["auto", "on", "arap", "off"],
        help="refine each frame's output surface towards its observations: on: along its "
        "normals; arap: as rigidly as possible, its vertices keeping their place on the "
        "body from frame to frame (the joints are the skeleton's either way; default "
        "auto: arap for mesh and point-cloud files, off for a capture folder's visual "
        "hulls, which are larger than the body)",
    )
    k.add_argument(
        "--passes",
        default="two-way",
        choices=["two-way", "forward"],
        help="two-way (default): after the forward pass, track the runs of frames it "
        "flagged lost again from whole-body searches at keyframes, backward and forward, "
        "and keep per frame what the evidence prefers (track.json says which frames changed "
        "and from which keyframe); forward: the forward pass alone. Live mode (--follow) "
        "is forward only",
    )
    k.add_argument(
        "--no-recover",
        action="store_true",
        help="do not score frames or flag lost limbs",
    )
    k.add_argument(
        "--fps",
        type=number(0, 1e5, "frames per second", open_lo=True),
        help="mesh/point-cloud files: their frame rate (default: 30, recorded as unknown)",
    )
    add_restart(k, "track again instead of resuming")
    k.add_argument(
        "--follow",
        action="store_true",
        help="live: track each frame as it is "
        "written into the folder (complete files: write, then rename), print its "
        "latency; Ctrl-C stops, a rerun resumes",
    )
    k.add_argument(
        "--idle",
        type=number(0, 1e6, "seconds", open_lo=True),
        help="with --follow: stop after this many seconds without a new frame (default: "
        "never; Ctrl-C stops)",
    )
    k.add_argument(
        "--view",
        action="store_true",
        help="with --follow: show the body as it is tracked in the rerun viewer "
        '(pip install -e ".[view]"); headless, save the recording as OUT/live.rrd',
    )
    k.add_argument(
        "--recording", help="with --follow: --view, saved to this .rrd file (default: none)"
    )
    k.set_defaults(func=_cmd_track)
