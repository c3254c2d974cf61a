"""Results out of the tool: ``meshmocap export`` (BVH, C3D, TRC, glTF/GLB, CSV)."""

from __future__ import annotations

import argparse
import math

from meshmocap.cli._args import add_frames, check_track_folders, number


def _cmd_export(args: argparse.Namespace) -> int:
    from meshmocap._progress import phase
    from meshmocap.apps.files.export import export_format, export_track, frame_ranges

    check_track_folders("export", [args.track])
    export_format(args.out, args.format, given_as="--format")  # before reading the track
    joints = [j for j in args.joints.split(",") if j] if args.joints else None
    with phase(f"exporting {args.out}"):
        res = export_track(
            args.track,
            args.out,
            format=args.format,
            frames=args.frames,
            joints=joints,
            markers=args.markers,
            long=args.long,
            fps=args.fps,
            template=args.template,
            bvh_unit=args.bvh_unit,
            joint_weight=args.joint_weight,
        )
    fit = ""
    if not math.isnan(res.vertex_error_mm):
        fit = (
            f"; the rig reproduces the tracked vertices to {res.vertex_error_mm:.1f} mm "
            f"and joints to {res.joint_error_mm:.1f} mm (mean)"
        )
    points = f", {len(res.points)} points" if res.points else ""
    size = res.size_bytes / 1e6
    print(
        f"wrote {res.path} ({res.format}, {res.n_frames} frames at {res.fps:g} fps from "
        f"{res.fps_source}{points}, {size:.2f} MB, {res.seconds:.1f} s){fit}"
    )
    if res.gaps:
        how = (
            "held at the last tracked pose (the format has no gaps)"
            if res.format in ("bvh", "gltf", "glb")
            else "written as gaps"
        )
        print(
            f"{len(res.gaps)} frames without a fit of their own (coasted or never tracked) "
            f"{how}: {frame_ranges(res.gaps)}"
        )
    return 0


def register(sub: argparse._SubParsersAction) -> None:
    """Add the parser of ``meshmocap export`` to ``sub``."""
    x = sub.add_parser(
        "export", help="write a track as BVH, C3D, TRC, glTF/GLB or CSV (format from --out)"
    )
    x.add_argument("track", help="track folder (meshmocap track)")
    x.add_argument("--out", required=True, help="file to write: .bvh .c3d .trc .gltf .glb .csv")
    x.add_argument(
        "--format",
        choices=["bvh", "c3d", "trc", "gltf", "glb", "csv"],
        help="format (default: from the extension of --out)",
    )
    add_frames(x)
    x.add_argument("--joints", help="evaluation joints to keep, comma-separated (c3d, trc, csv)")
    x.add_argument(
        "--markers",
        default="none",
        choices=["none", "lower_body"],
        help="add virtual markers on the template's surface (c3d, trc): "
        "lower_body is the conventional lower-body set (LASI ... RTOE)",
    )
    x.add_argument("--long", action="store_true", help="csv: one row per frame and joint")
    x.add_argument(
        "--fps",
        type=number(0, 1000, "frames per second", open_lo=True),
        help="frame rate (default: the capture's)",
    )
    x.add_argument("--template", help="tracking template, if not the bundled one in track.json")
    x.add_argument(
        "--bvh-unit",
        default="cm",
        choices=["m", "cm", "mm", "inch"],
        help="length unit of a BVH file (default cm)",
    )
    x.add_argument(
        "--joint-weight",
        type=number(0, 1000),
        default=2.0,
        help="bvh, gltf: weight of the tracked joints against the tracked surface "
        "in the pose fit (default 2; 0 fits the surface alone)",
    )
    x.set_defaults(func=_cmd_export)
