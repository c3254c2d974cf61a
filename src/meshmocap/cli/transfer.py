"""Motion transfer: ``meshmocap transfer`` (a cage track replayed with another mesh)."""

from __future__ import annotations

import argparse
import sys
import time

from meshmocap.cli._args import add_restart, check_track_folders, number


def _cmd_transfer(args: argparse.Namespace) -> int:
    import json
    import warnings
    from pathlib import Path

    from meshmocap.apps.files.export import capture_fps
    from meshmocap.body.template import bundled_templates, load_template
    from meshmocap.io.meshes import read_mesh
    from meshmocap.trackers.cage.transfer import read_cage_track, write_transfer

    check_track_folders("transfer", [args.track])
    template = load_template(args.template) if args.template else None
    track = read_cage_track(args.track, template=template)
    if args.mesh in bundled_templates():
        body = load_template(args.mesh)
        V, F = body.V, body.F
    else:
        V, F = read_mesh(args.mesh, up=args.up)
    fps, _ = capture_fps(json.loads((Path(args.track) / "track.json").read_text()))
    t0 = time.perf_counter()
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        res = write_transfer(
            track,
            V,
            F,
            args.out,
            fit=args.fit,
            outside=args.outside,
            tolerance=args.tolerance,
            ext=f".{args.format}",
            resume=not args.restart,
            name=args.mesh,
            fps=fps,
        )
    for w in caught:
        print(f"meshmocap: warning: {w.message}", file=sys.stderr)
    s = res.placement.scale
    animated = args.format in ("glb", "gltf")
    where = f"animation in {res.files[0]}" if animated else f"meshes in {res.out}"
    print(
        f"transferred {res.written + res.skipped} frames of {args.track} to {args.mesh!r} "
        f"({len(V)} "
        f"vertices, fit {args.fit}: scale {'/'.join(f'{v:.3f}' for v in s)}) in "
        f"{time.perf_counter() - t0:.1f} s: {res.written} written, {res.skipped} already "
        f"there; {res.n_outside} vertices outside the rest cage (up to "
        f"{res.max_outside * 1000:.0f} mm); {where}"
    )
    return 0


def register(sub: argparse._SubParsersAction) -> None:
    """Add the parser of ``meshmocap transfer`` to ``sub``."""
    x = sub.add_parser("transfer", help="replay a cage track with another mesh (motion transfer)")
    x.add_argument("track", help="track folder written by 'meshmocap track --method cage'")
    x.add_argument("mesh", help="a bundled template name or a mesh file (.obj, .ply, ...)")
    x.add_argument(
        "--out",
        required=True,
        help="folder for one mesh per frame, or for one "
        "animated glTF (--format glb/gltf: transfer.glb, Y up)",
    )
    x.add_argument("--template", help="tracking template, if not the bundled one in track.json")
    x.add_argument(
        "--fit",
        default="none",
        choices=["none", "scale", "stretch"],
        help="place the mesh where the template stands (default: as it is)",
    )
    x.add_argument("--up", default="z", choices=["z", "y"], help="the mesh file's up axis")
    x.add_argument(
        "--format",
        default="obj",
        choices=["obj", "ply", "off", "stl", "glb", "gltf"],
        help="obj, ply, off, stl: one mesh per frame; glb, gltf: one animation",
    )
    x.add_argument(
        "--outside",
        default="warn",
        choices=["warn", "raise", "ignore"],
        help="vertices outside the rest cage: warn, fail or ignore",
    )
    x.add_argument(
        "--tolerance", type=number(0, 1, "metres"), default=0.005, help="outside tolerance, metres"
    )
    add_restart(x, "transfer again instead of resuming")
    x.set_defaults(func=_cmd_transfer)
