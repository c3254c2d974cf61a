"""The ``meshmocap`` command: a thin shell over the library.

Every subcommand parses its arguments, calls library functions and prints a short
summary. Errors the user can fix (a missing file, a malformed BVH, a bad option) are
printed as one line ``meshmocap: error: ...`` with exit status 2, never a traceback.
"""

from __future__ import annotations

import argparse
import sys
import time
from collections.abc import Sequence

from meshmocap import __version__
from meshmocap.errors import MeshmocapError


def _cmd_templates(args: argparse.Namespace) -> int:
    from meshmocap.body.template import bundled_templates, load_template

    print(f"{'name':<14} {'vertices':>8} {'faces':>7} {'joints':>6} {'height m':>8}")
    for name in bundled_templates():
        t = load_template(name)
        height = t.V[:, 2].max() - t.V[:, 2].min()
        print(f"{name:<14} {t.n_vertices:>8} {len(t.F):>7} {t.skeleton.n_joints:>6} {height:>8.3f}")
    return 0


def _cmd_retarget(args: argparse.Namespace) -> int:
    from meshmocap.body.clips import clip_on
    from meshmocap.body.template import load_template
    from meshmocap.io.bvh import write_bvh

    template = load_template(args.template)
    motion = clip_on(template, args.clip, fps=args.fps)
    path = write_bvh(args.out, motion)
    print(f"wrote {path}: {motion.n_frames} frames at {motion.fps:g} fps on {template.name!r}")
    return 0


def _cmd_render(args: argparse.Namespace) -> int:
    from meshmocap.body.clips import clip_on
    from meshmocap.body.template import load_template
    from meshmocap.evaluation.render import render_motion

    template = load_template(args.template)
    if args.clip is None:  # the rest pose
        import numpy as np

        from meshmocap.body.motion import Motion

        J = template.skeleton.n_joints
        motion = Motion(
            template.skeleton,
            np.tile(np.eye(3), (1, J, 1, 1)),
            template.skeleton.rest_positions[:1],
            1.0,
        )
    else:
        motion = clip_on(template, args.clip, fps=args.fps)
    if args.frames:
        motion = motion.frames(args.frames)
    res = render_motion(
        template,
        motion,
        args.out,
        step=args.step,
        size=(args.width, args.height),
        azimuth=args.azimuth,
        frames=not args.sheet_only,
    )
    frames = f"{len(res.frames)} frames and " if res.frames else ""
    print(f"wrote {frames}{res.sheet} ({motion.n_frames} frames at {motion.fps:g} fps)")
    return 0


def _cmd_demo(args: argparse.Namespace) -> int:
    from meshmocap.evaluation.demo import run_demo

    res = run_demo(args.out, seconds=args.seconds, track_frames=args.track_frames, clip=args.clip)
    print(f"meshmocap demo: wrote {args.out}/ in {res.seconds:.1f} s")
    for what, path in res.files:
        print(f"  {what:<56} {path}")
    if res.scores:
        print(f"\n{'tracker':<18} {'mean joint error':>17} {'worst frame':>12} {'s/frame':>8}")
        for s in res.scores:
            print(f"{s.method:<18} {s.mean_mm:>14.1f} mm {s.max_mm:>9.1f} mm {s.seconds:>8.2f}")
    return 0


def _cmd_synth(args: argparse.Namespace) -> int:
    from meshmocap.studio.degrade import Degradation
    from meshmocap.studio.synth import SynthSpec, synthesize

    rng = args.frames or slice(None)
    spec = SynthSpec(
        motion=args.motion, template=args.template, subject=args.subject, rig=args.rig,
        fps=args.fps, start=rng.start, stop=rng.stop, step=rng.step, seed=args.seed,
        voxel_size=args.voxel_size,
        degradation=Degradation(jitter=args.jitter, holes=args.holes, blobs=args.blobs,
                                missed_limb=args.missed_limb),
    )  # fmt: skip
    t0 = time.perf_counter()
    cap = synthesize(args.out, spec)
    dt = time.perf_counter() - t0
    print(f"wrote {cap.path}: {len(cap)} frames, {len(cap.cameras)} cameras, {dt:.1f} s")
    return 0


def _cmd_hull(args: argparse.Namespace) -> int:
    from meshmocap.studio.hulls import compute_hulls

    t0 = time.perf_counter()
    cap = compute_hulls(args.capture, voxel_size=args.voxel_size, overwrite=args.overwrite)
    print(f"hulls of {len(cap)} frames in {cap.path / 'hulls'} ({time.perf_counter() - t0:.1f} s)")
    return 0


def _cmd_eval(args: argparse.Namespace) -> int:
    from meshmocap.evaluation.evaluate import evaluate, summary, write_evaluation
    from meshmocap.io.capture import Capture
    from meshmocap.io.results import read_track

    track, capture = read_track(args.track), Capture(args.capture)
    ev = evaluate(
        track, capture, silhouettes=not args.no_silhouettes, surface_frames=args.surface_frames
    )
    print(summary(ev))
    if args.out:
        files = write_evaluation(ev, args.out)
        print(f"\nwrote {len(files)} files to {args.out}")
    return 0


def _cmd_track(args: argparse.Namespace) -> int:
    from meshmocap.body.template import load_template
    from meshmocap.io.capture import open_capture
    from meshmocap.trackers.driver import track_sequence
    from meshmocap.trackers.registry import make_tracker

    options = {}
    for name in ("n_patches", "classifier", "keep_fraction", "max_iter"):
        value = getattr(args, name)
        if value is not None:
            options[name] = value
    tracker = make_tracker(args.method, **options)
    template = load_template(args.template)
    capture = open_capture(args.capture)
    frames = range(len(capture))[args.frames] if args.frames else None
    t0 = time.perf_counter()
    track = track_sequence(
        tracker, template, capture, args.out, frames=frames, resume=not args.restart
    )
    dt = time.perf_counter() - t0
    bad = int((~track.healthy).sum())
    print(f"tracked {len(track.frames)} frames with {args.method} in {dt:.1f} s "
          f"({track.seconds[1:].mean() if len(track.seconds) > 1 else 0:.3f} s per frame); "
          f"{bad} flagged unhealthy; results in {args.out}")  # fmt: skip
    return 0


def _frame_range(text: str) -> slice:
    """Parse ``START:STOP[:STEP]`` (any part optional) into a slice."""
    parts = text.split(":")
    try:
        if len(parts) > 3:
            raise ValueError
        return (
            slice(*(int(p) if p else None for p in parts))
            if len(parts) > 1
            else slice(int(text), int(text) + 1)
        )
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"expected START:STOP[:STEP] with integers, found {text!r}"
        ) from None


def build_parser() -> argparse.ArgumentParser:
    """Return the argument parser of the ``meshmocap`` command."""
    p = argparse.ArgumentParser(
        prog="meshmocap", description="Markerless human performance capture from 3D mesh sequences."
    )
    p.add_argument("--version", action="version", version=f"meshmocap {__version__}")
    sub = p.add_subparsers(dest="command", required=True, metavar="COMMAND")

    d = sub.add_parser("demo", help="run the main job on the bundled defaults")
    d.add_argument("--out", default="meshmocap-demo", help="output folder (default: %(default)s)")
    d.add_argument("--seconds", type=float, default=4.0, help="length of the demo walk")
    d.add_argument("--clip", help="also retarget and render this BVH/AMC clip")
    d.add_argument("--track-frames", type=int, default=60, help="frames tracked (0: skip)")
    d.set_defaults(func=_cmd_demo)

    t = sub.add_parser("templates", help="list the bundled templates")
    t.set_defaults(func=_cmd_templates)

    r = sub.add_parser(
        "retarget", help="retarget a clip onto a template's skeleton and write a BVH"
    )
    r.add_argument(
        "clip", help="a .bvh or .amc file (its .asf beside it) or a procedural motion name"
    )
    r.add_argument("--template", default="neutral", help="bundled template name or .npz path")
    r.add_argument("--fps", type=float, help="resample to this frame rate")
    r.add_argument("--out", required=True, help="BVH file to write")
    r.set_defaults(func=_cmd_retarget)

    y = sub.add_parser("synth", help="make a synthetic capture with ground truth")
    y.add_argument("out", help="capture folder to write (resumes an interrupted run)")
    y.add_argument("--motion", default="walk", help="procedural motion name or .bvh/.amc file")
    y.add_argument("--template", default="neutral", help="tracking template (name or .npz)")
    y.add_argument("--subject", help="body that performs, if not the template (e.g. heavy_male)")
    y.add_argument("--rig", default="humaneva4", help="humaneva4, ring8 or a camera file")
    y.add_argument("--fps", type=float, default=60.0, help="frame rate (default: %(default)s)")
    y.add_argument("--frames", type=_frame_range, help="frame range START:STOP[:STEP]")
    y.add_argument("--voxel-size", type=float, default=0.01, help="hull voxel edge, metres")
    y.add_argument("--jitter", type=float, default=0.0, help="silhouette boundary jitter, pixels")
    y.add_argument("--holes", type=int, default=0, help="holes punched per silhouette")
    y.add_argument("--blobs", type=int, default=0, help="spurious blobs per silhouette")
    y.add_argument("--missed-limb", action="store_true", help="cut a limb from each silhouette")
    y.add_argument("--seed", type=int, default=0, help="seed of the degradations")
    y.set_defaults(func=_cmd_synth)

    h = sub.add_parser("hull", help="carve visual hulls from a capture's silhouettes")
    h.add_argument("capture", help="folder with cameras.json and silhouettes/<camera>/NNNNN.png")
    h.add_argument("--voxel-size", type=float, default=0.01, help="voxel edge, metres")
    h.add_argument("--overwrite", action="store_true", help="recompute existing hulls")
    h.set_defaults(func=_cmd_hull)

    k = sub.add_parser(
        "track", help="track a capture: skeleton joints and template shape per frame"
    )
    k.add_argument("capture", help="capture folder (meshmocap synth/hull) or folder/glob of meshes")
    k.add_argument("--method", default="patch", help="patch, patch_noclf, articulated_icp")
    k.add_argument("--template", default="neutral_5k", help="tracking template (name or .npz)")
    k.add_argument("--out", required=True, help="track folder (frame-by-frame results)")
    k.add_argument("--frames", type=_frame_range, help="frame range START:STOP[:STEP]")
    k.add_argument("--n-patches", type=int, help="patch tracker: number of patches")
    k.add_argument("--classifier", help="patch tracker: logistic, svc or none")
    k.add_argument("--keep-fraction", type=float, help="patch tracker: on-bone points kept")
    k.add_argument("--max-iter", type=int, help="iterations per frame")
    k.add_argument("--restart", action="store_true", help="start over instead of resuming")
    k.set_defaults(func=_cmd_track)

    e = sub.add_parser("eval", help="score a track against its capture's ground truth")
    e.add_argument("capture", help="capture folder")
    e.add_argument("track", help="track folder written by 'meshmocap track'")
    e.add_argument("--out", help="folder for CSV tables and PNG plots")
    e.add_argument("--no-silhouettes", action="store_true", help="skip the silhouette error")
    e.add_argument("--surface-frames", type=int, default=8, help="frames for surface distances")
    e.set_defaults(func=_cmd_eval)

    v = sub.add_parser(
        "render", help="render a posed template or a clip to PNG frames and a contact sheet"
    )
    v.add_argument(
        "clip", nargs="?", help="a .bvh/.amc file or a procedural motion name; none: the rest pose"
    )
    v.add_argument("--template", default="neutral", help="bundled template name or .npz path")
    v.add_argument("--out", required=True, help="output folder")
    v.add_argument("--fps", type=float, help="resample the clip to this frame rate first")
    v.add_argument(
        "--frames", type=_frame_range, help="frame range START:STOP[:STEP] (after resampling)"
    )
    v.add_argument("--step", type=int, default=1, help="render every STEP-th frame")
    v.add_argument("--width", type=int, default=320)
    v.add_argument("--height", type=int, default=400)
    v.add_argument(
        "--azimuth", type=float, default=30.0, help="camera angle around Z, degrees (0 = front)"
    )
    v.add_argument("--sheet-only", action="store_true", help="write only the contact sheet")
    v.set_defaults(func=_cmd_render)
    return p


def main(argv: Sequence[str] | None = None) -> int:
    """Run the ``meshmocap`` command; return its exit status."""
    args = build_parser().parse_args(argv)
    try:
        return int(args.func(args))
    except MeshmocapError as exc:
        print(f"meshmocap: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("meshmocap: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
