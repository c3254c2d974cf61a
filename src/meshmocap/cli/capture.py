"""Captures: ``meshmocap synth`` (the synthetic studio), ``silhouettes`` (silhouettes of
calibrated multi-view video) and ``hull`` (visual hulls of real silhouettes)."""

from __future__ import annotations

import argparse
import time
from pathlib import Path

from meshmocap.cli._args import add_frames, add_restart, frame_range, number, xy_pair


def _cmd_synth(args: argparse.Namespace) -> int:
    from meshmocap.studio.degrade import Degradation
    from meshmocap.studio.synth import SynthSpec, synthesize

    rng = args.frames or slice(None)
    gap = args.missed_limb_frames
    gap = None if gap is None else (gap.start or 0, gap.stop)
    spec = SynthSpec(
        motion=args.motion,
        template=args.template,
        subject=args.subject,
        rig=args.rig,
        fps=args.fps,
        start=rng.start,
        stop=rng.stop,
        step=rng.step,
        seed=args.seed,
        voxel_size=args.voxel_size,
        heading=args.heading,
        offset=args.offset,
        degradation=Degradation(
            jitter=args.jitter,
            holes=args.holes,
            blobs=args.blobs,
            missed_limb=args.missed_limb or gap is not None or args.missed_limb_joint is not None,
            missed_limb_frames=gap,
            missed_limb_joint=args.missed_limb_joint,
        ),
    )
    t0 = time.perf_counter()
    cap = synthesize(args.out, spec)
    dt = time.perf_counter() - t0
    print(f"wrote {cap.path}: {len(cap)} frames, {len(cap.cameras)} cameras, {dt:.1f} s")
    return 0


def _offset(text: str) -> tuple[str, int]:
    """Parse ``CAMERA=N`` (a camera name and a whole number of frames)."""
    name, _, value = text.rpartition("=")
    try:
        if not name:
            raise ValueError
        return name, int(value)
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"expected CAMERA=FRAMES (e.g. cam02=3), found {text!r}"
        ) from None


def _cmd_silhouettes(args: argparse.Namespace) -> int:
    from meshmocap.studio.from_video import silhouettes_from_video

    t0 = time.perf_counter()
    run = silhouettes_from_video(
        args.videos,
        args.calibration,
        args.out,
        frames=args.frames,
        offsets=dict(args.offset or []),
        plates=args.plates,
        scale=args.scale,
        voxel_size=args.voxel_size,
        misses=args.misses,
        overwrite=args.restart,
    )
    for note in run.notes:
        print(f"note: {note}")
    print(
        f"silhouettes of {len(run.frames)} frames × {len(run.cameras)} cameras in "
        f"{run.path / 'silhouettes'} ({run.written} segmented by this run; "
        f"{time.perf_counter() - t0:.1f} s); next: meshmocap hull {run.path}"
    )
    return 0


def _cmd_hull(args: argparse.Namespace) -> int:
    from meshmocap._validate import counted, frame_positions
    from meshmocap.apps.files.export import frame_ranges
    from meshmocap.errors import InputError
    from meshmocap.io.cameras import read_cameras
    from meshmocap.studio.hulls import camera_file, compute_hulls, silhouette_frames

    t0 = time.perf_counter()
    frames = None
    path = Path(args.capture)
    if args.frames and path.is_dir():  # frame numbers: of the silhouettes, those in range
        numbers = silhouette_frames(path, [c.name for c in read_cameras(camera_file(path))])
        frames = [numbers[k] for k in frame_positions(numbers, args.frames)]
        if not frames:
            raise InputError(
                f"hull: --frames selects none of the {len(numbers)} frames "
                f"(numbers {numbers[0]}..{numbers[-1]}) of {args.capture}"
            )
    run = compute_hulls(
        args.capture, voxel_size=args.voxel_size, overwrite=args.restart, frames=frames
    )
    cap = run.capture
    made = cap.indices if frames is None else frames  # the frames asked for, not the folder's
    ranges = f" ({frame_ranges(made)})" if frames is not None else ""
    which = counted(len(made), "frame") + ranges
    print(
        f"hulls of {which} in {cap.path / 'hulls'} ({run.carved} carved by this run, "
        f"{len(run.partial)} from fewer cameras, {len(run.missing)} without hull; "
        f"{time.perf_counter() - t0:.1f} s)"
    )
    return 0


def register(sub: argparse._SubParsersAction) -> None:
    """Add the parsers of this module's commands to ``sub``."""
    y = sub.add_parser("synth", help="make a synthetic capture with ground truth")
    y.add_argument("out", help="capture folder to write (resumes an interrupted run)")
    y.add_argument("--motion", default="walk", help="procedural motion name or .bvh/.amc file")
    y.add_argument("--template", default="neutral", help="tracking template (name or .npz)")
    y.add_argument("--subject", help="body that performs, if not the template (e.g. heavy_male)")
    y.add_argument("--rig", default="humaneva4", help="humaneva4, ring8 or a camera file")
    y.add_argument(
        "--fps",
        type=number(0, 1000, "frames per second", open_lo=True),
        default=60.0,
        help="frame rate (default: %(default)s)",
    )
    add_frames(y, "of the motion")
    y.add_argument(
        "--voxel-size",
        type=number(0.002, 0.1, "metres"),
        default=0.01,
        help="hull voxel edge, metres",
    )
    y.add_argument(
        "--jitter",
        type=number(0, 20, "pixels"),
        default=0.0,
        help="silhouette boundary jitter, pixels",
    )
    y.add_argument(
        "--holes", type=number(0, 100, integer=True), default=0, help="holes punched per silhouette"
    )
    y.add_argument(
        "--blobs",
        type=number(0, 100, integer=True),
        default=0,
        help="spurious blobs per silhouette",
    )
    y.add_argument("--missed-limb", action="store_true", help="cut a limb from each silhouette")
    y.add_argument(
        "--missed-limb-frames",
        type=frame_range,
        metavar="START:STOP",
        help="miss the limb on these frames only (implies --missed-limb)",
    )
    y.add_argument(
        "--missed-limb-joint",
        metavar="JOINT",
        help="miss the body parts of this evaluation joint and below (e.g. left_elbow: the "
        "forearm and hand) in every camera, so the hull misses that limb (default: a random "
        "extremity cut from each camera's silhouette; implies --missed-limb)",
    )
    y.add_argument(
        "--heading",
        type=number(-3600, 3600, "degrees"),
        default=0.0,
        metavar="DEG",
        help="turn the whole motion about the vertical axis through the volume's centre (degrees)",
    )
    y.add_argument(
        "--offset",
        type=xy_pair,
        default=(0.0, 0.0),
        metavar="X,Y",
        help="shift the whole motion in the volume (metres)",
    )
    y.add_argument(
        "--seed",
        type=number(0, 2**32 - 1, integer=True),
        default=0,
        help="seed of the degradations",
    )
    y.set_defaults(func=_cmd_synth)
    v = sub.add_parser(
        "silhouettes", help="segment calibrated multi-view video into a capture's silhouettes"
    )
    v.add_argument(
        "videos", help="folder with a video (<camera>.mp4, .avi, .mov) or image folder per camera"
    )
    v.add_argument(
        "--calibration",
        required=True,
        help="Qualisys .qca.txt, Pose2Sim/anipose Calib.toml, OpenCV .yml or cameras.json",
    )
    v.add_argument("--out", required=True, help="capture folder to write (resumes)")
    add_frames(v, "capture frame numbers, default: every frame all cameras have")
    v.add_argument(
        "--offset",
        type=_offset,
        action="append",
        metavar="CAMERA=N",
        help="capture frame k is frame k+N of this camera's video (repeat per camera)",
    )
    v.add_argument("--plates", help="folder of empty-scene images, <camera>.png (or .jpg)")
    v.add_argument(
        "--scale",
        type=number(0.1, 1, "of the image size"),
        help="segmentation resolution relative to the images (default: about 1000 pixels "
        "on the longest side)",
    )
    v.add_argument(
        "--voxel-size",
        type=number(0.005, 0.2, "metres"),
        default=0.03,
        help="voxel edge of the multi-view consistency carving, metres (default: %(default)s)",
    )
    v.add_argument(
        "--misses",
        type=number(0, 10, integer=True),
        default=0,
        help="other cameras allowed to miss what a camera keeps (default: %(default)s: a "
        "pixel's ray must meet the volume carved from all the others)",
    )
    add_restart(v, "segment every frame again")
    v.set_defaults(func=_cmd_silhouettes)
    h = sub.add_parser("hull", help="carve visual hulls from a capture's silhouettes")
    h.add_argument("capture", help="folder with cameras.json and silhouettes/<camera>/NNNNN.png")
    h.add_argument(
        "--voxel-size", type=number(0.002, 0.1, "metres"), default=0.01, help="voxel edge, metres"
    )
    add_frames(h, "default: every frame with silhouettes")
    add_restart(h, "recompute existing hulls")
    h.set_defaults(func=_cmd_hull)
