"""Bodies and motions: ``meshmocap templates``, ``retarget`` and ``render``."""

from __future__ import annotations

import argparse

from meshmocap.cli._args import frame_range, number


def _cmd_templates(args: argparse.Namespace) -> int:
    from meshmocap.body.template import bundled_templates, load_template

    print(f"{'name':<14} {'vertices':>8} {'faces':>7} {'joints':>6} {'height m':>8}")
    for name in bundled_templates():
        t = load_template(name)
        height = t.V[:, 2].max() - t.V[:, 2].min()
        print(f"{name:<14} {t.n_vertices:>8} {len(t.F):>7} {t.skeleton.n_joints:>6} {height:>8.3f}")
    return 0


def _cmd_retarget(args: argparse.Namespace) -> int:
    from meshmocap.body.template import load_template
    from meshmocap.io.bvh import write_bvh
    from meshmocap.io.clips import clip_on

    template = load_template(args.template)
    motion = clip_on(template, args.clip, fps=args.fps)
    path = write_bvh(args.out, motion)
    print(f"wrote {path}: {motion.n_frames} frames at {motion.fps:g} fps on {template.name!r}")
    return 0


def _cmd_render(args: argparse.Namespace) -> int:
    from meshmocap.apps.figures.render import render_motion
    from meshmocap.body.template import load_template
    from meshmocap.io.clips import clip_on

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


def register(sub: argparse._SubParsersAction) -> None:
    """Add the parsers of this module's commands to ``sub``."""
    t = sub.add_parser("templates", help="list the bundled templates")
    t.set_defaults(func=_cmd_templates)
    r = sub.add_parser(
        "retarget", help="retarget a clip onto a template's skeleton and write a BVH"
    )
    r.add_argument(
        "clip", help="a .bvh or .amc file (its .asf beside it) or a procedural motion name"
    )
    r.add_argument("--template", default="neutral", help="bundled template name or .npz path")
    r.add_argument(
        "--fps",
        type=number(0, 1000, "frames per second", open_lo=True),
        help="resample to this frame rate",
    )
    r.add_argument("--out", required=True, help="BVH file to write")
    r.set_defaults(func=_cmd_retarget)
    v = sub.add_parser(
        "render", help="render a posed template or a clip to PNG frames and a contact sheet"
    )
    v.add_argument(
        "clip", nargs="?", help="a .bvh/.amc file or a procedural motion name; none: the rest pose"
    )
    v.add_argument("--template", default="neutral", help="bundled template name or .npz path")
    v.add_argument("--out", required=True, help="output folder")
    v.add_argument(
        "--fps",
        type=number(0, 1000, "frames per second", open_lo=True),
        help="resample the clip to this frame rate first",
    )
    v.add_argument(
        "--frames", type=frame_range, help="frame range START:STOP[:STEP] (after resampling)"
    )
    v.add_argument(
        "--step",
        type=number(1, 100_000, integer=True),
        default=1,
        help="render every STEP-th frame",
    )
    v.add_argument("--width", type=number(16, 8192, "pixels", integer=True), default=320)
    v.add_argument("--height", type=number(16, 8192, "pixels", integer=True), default=400)
    v.add_argument(
        "--azimuth",
        type=number(-360, 360, "degrees"),
        default=30.0,
        help="camera angle around Z, degrees (0 = front)",
    )
    v.add_argument("--sheet-only", action="store_true", help="write only the contact sheet")
    v.set_defaults(func=_cmd_render)
