"""The ``meshmocap`` command: a thin shell over the library.

Every subcommand parses its arguments, calls library functions and prints a short
summary. Errors the user can fix (a missing file, a malformed BVH, a bad option) are
printed as one line ``meshmocap: error: ...`` with exit status 2, never a traceback.
"""

from __future__ import annotations

import argparse
import os
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
    from meshmocap.body.template import load_template
    from meshmocap.io.bvh import write_bvh
    from meshmocap.io.clips import clip_on

    template = load_template(args.template)
    motion = clip_on(template, args.clip, fps=args.fps)
    path = write_bvh(args.out, motion)
    print(f"wrote {path}: {motion.n_frames} frames at {motion.fps:g} fps on {template.name!r}")
    return 0


def _cmd_render(args: argparse.Namespace) -> int:
    from meshmocap.apps.render import render_motion
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


def _cmd_demo(args: argparse.Namespace) -> int:
    from meshmocap.apps.demo import run_demo

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
    from meshmocap.analysis.evaluate import evaluate, summary
    from meshmocap.apps.evaluation_files import write_evaluation
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


def _cmd_report(args: argparse.Namespace) -> int:
    from meshmocap.apps.report import build_report

    t0 = time.perf_counter()
    path = build_report(
        args.out, args.capture, args.tracks, eval_dirs=args.eval_dir, max_frames=args.max_frames,
        silhouettes=not args.no_silhouettes, surface_frames=args.surface_frames,
    )  # fmt: skip
    size = path.stat().st_size / 1e6
    print(f"wrote {path} ({size:.1f} MB, {time.perf_counter() - t0:.1f} s); open it in a browser")
    return 0


def _cmd_track(args: argparse.Namespace) -> int:
    from meshmocap.body.template import load_template
    from meshmocap.io.capture import open_capture
    from meshmocap.trackers.driver import track_sequence
    from meshmocap.trackers.registry import MANIFOLD_METHODS, make_tracker

    options = {}
    for name in ("n_patches", "classifier", "keep_fraction", "outlier_sigmas", "max_iter",
                 "fast_iter_scale", "joint_readout"):  # fmt: skip
        value = getattr(args, name)
        if value is not None:
            options[name] = value
    template = load_template(args.template)
    if args.method in MANIFOLD_METHODS and args.manifold is None:
        print(f"{args.method}: no --manifold given: learning a 2-D pose manifold from the "
              f"procedural walk and jog on {template.name!r}")  # fmt: skip
    tracker = make_tracker(args.method, manifold=args.manifold, template=template, **options)
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


def _cmd_learn(args: argparse.Namespace) -> int:
    from pathlib import Path

    import numpy as np

    from meshmocap.apps.latent_plot import plot_latent_space
    from meshmocap.body.oqr import build_oqr
    from meshmocap.body.template import load_template
    from meshmocap.errors import InputError, MeshmocapFileNotFoundError
    from meshmocap.io.pose_data import load_pose_sources
    from meshmocap.trackers.manifold import fit_pose_manifold

    out = Path(args.out)
    if out.suffix != ".npz" or not out.parent.is_dir():  # fail before the work
        bad = MeshmocapFileNotFoundError if out.suffix == ".npz" else InputError
        raise bad(f"learn: --out must be a .npz file in an existing folder, found {out}")
    template = load_template(args.template)
    t0 = time.perf_counter()
    oqr = build_oqr(template)
    poses = load_pose_sources(args.sources, template, oqr=oqr, asf=args.asf)
    print(f"read {len(poses)} poses of {template.name!r} from {len(args.sources)} source(s) "
          f"in {time.perf_counter() - t0:.1f} s")  # fmt: skip
    pm = fit_pose_manifold(poses, template, oqr=oqr, n_components=args.latent_dim,
                           n_samples=args.samples, random_state=args.seed)  # fmt: skip
    gp = pm.gp
    names, counts = np.unique(pm.groups, return_counts=True)
    err = gp.predict(gp.X_) - gp.Y_mean_ - gp.Y_scale_ * gp.Y_
    centres = np.linalg.norm(err.reshape(len(err), -1, 3, 3)[:, :, 0], axis=2).mean() * 1000
    print(f"learned a {pm.n_components}-D manifold from {pm.n_samples} poses "
          f"({', '.join(f'{n} {g}' for g, n in zip(names, counts, strict=True))}) in "
          f"{pm.fit_seconds:.1f} s: final log-likelihood {gp.log_likelihood_:.1f} after "
          f"{gp.n_iter_} L-BFGS-B iterations{'' if gp.converged_ else ' (not converged)'}; "
          f"training quads reproduced to {centres:.1f} mm")  # fmt: skip
    print(f"wrote {pm.save(args.out)}")
    if args.plot:
        labels = pm.groups if len(names) <= 10 else None
        title = f"{template.name}: {pm.n_components}-D pose manifold, {pm.n_samples} poses"
        print(f"wrote {plot_latent_space(gp, args.plot, labels=labels, title=title)}")
    return 0


def _cmd_transfer(args: argparse.Namespace) -> int:
    import warnings

    from meshmocap.body.template import bundled_templates, load_template
    from meshmocap.io.meshes import read_mesh
    from meshmocap.trackers.transfer import read_cage_track, write_transfer

    template = load_template(args.template) if args.template else None
    track = read_cage_track(args.track, template=template)
    if args.mesh in bundled_templates():
        body = load_template(args.mesh)
        V, F = body.V, body.F
    else:
        V, F = read_mesh(args.mesh, up=args.up)
    t0 = time.perf_counter()
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        res = write_transfer(track, V, F, args.out, fit=args.fit, outside=args.outside,
                             tolerance=args.tolerance, ext=f".{args.format}",
                             resume=not args.restart, name=args.mesh)  # fmt: skip
    for w in caught:
        print(f"meshmocap: warning: {w.message}", file=sys.stderr)
    s = res.placement.scale
    print(f"transferred {len(res.files)} frames of {args.track} to {args.mesh!r} ({len(V)} "
          f"vertices, fit {args.fit}: scale {'/'.join(f'{v:.3f}' for v in s)}) in "
          f"{time.perf_counter() - t0:.1f} s: {res.written} written, {res.skipped} already "
          f"there; {res.n_outside} vertices outside the rest cage (up to "
          f"{res.max_outside * 1000:.0f} mm); meshes in {res.out}")  # fmt: skip
    return 0


def _cmd_bench(args: argparse.Namespace) -> int:
    from meshmocap.apps.bench import run_bench
    from meshmocap.apps.bench_report import markdown_table, tradeoff_table
    from meshmocap.errors import InputError

    def items(values: list[str] | None) -> list[str] | None:  # "a,b c" → [a, b, c]
        return None if values is None else [n for v in values for n in v.split(",") if n]

    fractions = items(args.keep_fractions)
    try:
        keep = (None if fractions is None else  # None: the set's sweep
                [] if fractions == ["none"] else [float(f) for f in fractions])  # fmt: skip
    except ValueError:
        msg = f"bench: --keep-fractions must be numbers or none, found {fractions}"
        raise InputError(msg) from None
    res = run_bench(
        args.out, captures=items(args.captures) or args.set, methods=items(args.methods),
        data=args.data, work=args.work, max_frames=args.max_frames, keep_fractions=keep,
        template=args.template, log=lambda line: print(line, flush=True),
    )  # fmt: skip
    print(f"\n{markdown_table(res.rows)}")
    if res.tradeoff:
        print(f"\nkept fraction of the patch classifier on {res.tradeoff_capture} (Fig. 8):")
        print(tradeoff_table(res.tradeoff))
    for name, why in res.skipped:
        print(f"left out {name}: {why}")
    n = len(res.rows) + len(res.tradeoff)
    print(f"\nwrote {len(res.files)} files to {args.out} in {res.seconds:.0f} s "
          f"({n} results, {len(res.tracked)} tracked by this run)")  # fmt: skip
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
    d.add_argument("--track-frames", type=int, default=120, help="frames tracked (0: skip)")
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
    k.add_argument("--method", default="patch", help="patch, patch_svc, patch_noclf, "
                   "articulated_icp, cage, cage_quads, cage_noreg, cage_nolocal")  # fmt: skip
    k.add_argument("--template", default="neutral_5k", help="tracking template (name or .npz)")
    k.add_argument("--out", required=True, help="track folder (frame-by-frame results)")
    k.add_argument("--frames", type=_frame_range, help="frame range START:STOP[:STEP]")
    k.add_argument("--n-patches", type=int, help="patch tracker: number of patches")
    k.add_argument("--classifier", help="patch tracker: logistic, svc or none")
    k.add_argument("--keep-fraction", type=float, help="patch tracker: on-bone points kept")
    k.add_argument("--outlier-sigmas", type=float, help="patch tracker: a point this many σ "
                   "from the model is as likely an outlier (default 3; 2 rejects more of a "
                   "few-camera hull's phantom volumes, but also true points where the subject's "
                   "surface differs from the template's)")  # fmt: skip
    k.add_argument("--max-iter", type=int, help="iterations per frame")
    k.add_argument("--fast-iter-scale", type=float, help="patch tracker: iterations of a frame "
                   "after a fast one (a joint moved > 5 cm), as a multiple of the usual "
                   "(default 2; 1 keeps every frame's cost the same)")  # fmt: skip
    k.add_argument("--joint-readout", help="patch tracker: joints reported: blend (default: "
                   "pelvis and thorax read off the surface, limbs mostly from the skeleton), "
                   "skeleton (the paper's) or surface")  # fmt: skip
    k.add_argument("--manifold", help="cage methods: pose manifold from 'meshmocap learn' "
                   "(default: learn one from the procedural walk and jog)")  # fmt: skip
    k.add_argument("--restart", action="store_true", help="start over instead of resuming")
    k.set_defaults(func=_cmd_track)

    m = sub.add_parser("learn", help="learn the cage tracker's pose manifold (GPLVM) from poses")
    m.add_argument("sources", nargs="+", metavar="SOURCE", help="walk, jog (procedural), "
                   ".bvh/.amc/.mat mocap or a hand-labelled .npz pose file")  # fmt: skip
    m.add_argument("--template", default="neutral_5k", help="tracking template (name or .npz)")
    m.add_argument("--out", required=True, help="manifold file to write (.npz)")
    m.add_argument("--latent-dim", type=int, default=2, help="latent dimension q")
    m.add_argument("--samples", type=int, default=120, help="training poses (default: 120)")
    m.add_argument("--asf", help="ASF skeleton of .amc/.mat sources (default: found beside)")
    m.add_argument("--plot", help="also draw the latent space (.png, .pdf or .svg)")
    m.add_argument("--seed", type=int, default=0, help="random seed")
    m.set_defaults(func=_cmd_learn)

    x = sub.add_parser("transfer", help="replay a cage track with another mesh (motion transfer)")
    x.add_argument("track", help="track folder written by 'meshmocap track --method cage'")
    x.add_argument("mesh", help="a bundled template name or a mesh file (.obj, .ply, ...)")
    x.add_argument("--out", required=True, help="folder for one mesh per frame")
    x.add_argument("--template", help="tracking template, if not the bundled one in track.json")
    x.add_argument(
        "--fit",
        default="none",
        choices=["none", "scale", "stretch"],
        help="place the mesh where the template stands (default: as it is)",
    )
    x.add_argument("--up", default="z", choices=["z", "y"], help="the mesh file's up axis")
    x.add_argument("--format", default="obj", choices=["obj", "ply", "off", "stl", "glb"])
    x.add_argument(
        "--outside",
        default="warn",
        choices=["warn", "raise", "ignore"],
        help="vertices outside the rest cage: warn, fail or ignore",
    )
    x.add_argument("--tolerance", type=float, default=0.005, help="outside tolerance, metres")
    x.add_argument("--restart", action="store_true", help="start over instead of resuming")
    x.set_defaults(func=_cmd_transfer)

    e = sub.add_parser("eval", help="score a track against its capture's ground truth")
    e.add_argument("capture", help="capture folder")
    e.add_argument("track", help="track folder written by 'meshmocap track'")
    e.add_argument("--out", help="folder for CSV tables and PNG plots")
    e.add_argument("--no-silhouettes", action="store_true", help="skip the silhouette error")
    e.add_argument("--surface-frames", type=int, default=8, help="frames for surface distances")
    e.set_defaults(func=_cmd_eval)

    o = sub.add_parser("report", help="write an HTML report: scores, plots and a 3D player")
    o.add_argument("capture", help="capture folder")
    o.add_argument("tracks", nargs="+", metavar="track", help="track folders to compare")
    o.add_argument("--out", required=True, help="HTML file to write (one self-contained file)")
    o.add_argument("--eval-dir", action="append", help="keep each track's CSV/PNG evaluation "
                   "here (repeat once per track, in order)")  # fmt: skip
    o.add_argument("--max-frames", type=int, default=120, help="frames in the 3D player")
    o.add_argument("--no-silhouettes", action="store_true", help="skip the silhouette error")
    o.add_argument("--surface-frames", type=int, default=8, help="frames for surface distances")
    o.set_defaults(func=_cmd_report)

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
    b.add_argument("--max-frames", type=int, help="at most N frames per capture")
    b.add_argument("--keep-fractions", nargs="+", help="Fig. 8 sweep of the patch tracker")
    b.add_argument("--template", default="neutral_5k", help="tracking template")
    b.set_defaults(func=_cmd_bench)
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
    except BrokenPipeError:  # `meshmocap eval ... | head`: the reader left, not an error
        # keep the interpreter's final flush from raising again on the closed pipe
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 0


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
