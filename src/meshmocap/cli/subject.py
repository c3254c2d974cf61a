"""The performer's body: ``meshmocap subject``."""

from __future__ import annotations

import argparse
import sys


def _cmd_subject(args: argparse.Namespace) -> int:
    from pathlib import Path

    from meshmocap.body.template import save_template
    from meshmocap.errors import InputError, MeshmocapFileNotFoundError
    from meshmocap.estimate.performer.subject import estimate_subject
    from meshmocap.io.capture import open_capture
    from meshmocap.io.plausibility import body_warnings, check_observations

    out = Path(args.out)
    if out.suffix != ".npz" or not out.parent.is_dir():  # fail before the work
        bad = MeshmocapFileNotFoundError if out.suffix == ".npz" else InputError
        raise bad(f"subject: --out must be a .npz file in an existing folder, found {out}")
    capture = open_capture(args.capture, up=args.up) if args.up else open_capture(args.capture)
    # one person? dense (slow, as for track)? a sphere is no performer: said first
    for line in [*check_observations(capture, command="subject"), *body_warnings(capture)]:
        print(f"meshmocap: warning: {line}", file=sys.stderr)
    est = estimate_subject(
        capture,
        kind=args.kind,
        n_frames=args.n_frames,
        iterations=args.iterations,
        name=args.name or out.stem,
        decimate=args.decimate,
    )
    save_template(out, est.template)
    how = (
        "shape space fitted to the silhouettes"
        if est.kind == "hull"
        else "the mesh rigged as it stands"
    )
    rms = f", silhouette residual {est.rms * 1000:.1f} mm" if est.kind == "hull" else ""
    print(
        f"estimated the performer from frame(s) {', '.join(map(str, est.frames))} "
        f"({est.kind}: {how}{rms}) in {est.seconds:.1f} s: height {est.height:.3f} m, "
        f"{est.template.n_vertices} vertices; wrote {out}"
    )
    return 0


def register(sub: argparse._SubParsersAction) -> None:
    """Add the parser of ``meshmocap subject`` to ``sub``."""
    s = sub.add_parser("subject", help="estimate the performer's body (a template) from a capture")
    s.add_argument("capture", help="capture folder (cameras + silhouettes) or meshes")
    s.add_argument("--out", required=True, help="template file to write (.npz)")
    s.add_argument(
        "--kind",
        default="auto",
        choices=["auto", "hull", "mesh"],
        help="hull: fit the body-shape space to the silhouettes; mesh: rig the first "
        "mesh as it stands (default: hull when the capture has cameras and "
        "silhouettes)",
    )
    s.add_argument("--n-frames", type=int, default=5, help="hull: frames fitted together")
    s.add_argument("--iterations", type=int, default=40, help="hull: Gauss-Newton iterations")
    s.add_argument("--decimate", type=int, help="mesh: vertices of the rigged template")
    s.add_argument("--up", choices=["z", "y"], help="mesh files' up axis (default z)")
    s.add_argument("--name", help="template name (default: the file's stem)")
    s.set_defaults(func=_cmd_subject)
