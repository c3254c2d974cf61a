"""Tracking: ``meshmocap track``, ``learn`` (pose manifolds) and ``transfer``."""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

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


def _capture_source(
    sources: list[str], up: str = "auto", units: str = "auto", fps: float | None = None
):
    """One capture folder, or several mesh files/folders (the shell expands an unquoted
    glob into many arguments), in metres and Z up: :func:`meshmocap.api.capture_and_axes`
    (``fps``: the rate of mesh files). Returns the capture and the axes read (None for a
    capture folder)."""
    from meshmocap.api import capture_and_axes

    return capture_and_axes(sources, up=up, units=units, fps=fps)


def _cmd_track(args: argparse.Namespace) -> int:
    from meshmocap._progress import phase

    with phase("loading meshmocap's modules"):  # scipy, matplotlib, scikit-learn...: seconds
        from meshmocap import api
    from meshmocap._timing import StageTimer
    from meshmocap._validate import frame_positions
    from meshmocap.analysis.evaluate import track_init
    from meshmocap.errors import InputError
    from meshmocap.estimate.plausibility import check_observations
    from meshmocap.io.results import done_frames

    options = _tracker_options(args)
    if args.follow or args.idle is not None or args.view or args.recording:
        return _follow(args, options)
    capture, axes = _capture_source(args.capture, args.up, args.units, args.fps)
    if axes is not None:
        rate = f"{capture.fps:g} fps" + ("" if args.fps else " (assumed; --fps to set)")
        print(
            f"{args.capture[0]}: {axes.up.upper()} up, {axes.units}, a body "
            f"{axes.span:.2f} m long (--up, --units to set); {rate}"
        )
        gaps = getattr(capture, "gaps", [])
        if gaps:
            print(
                f"meshmocap: warning: {len(gaps)} frame numbers have no file (first "
                f"{gaps[0]}): tracked as missing frames, coasted across",
                file=sys.stderr,
            )
    frames = None
    if args.frames:
        numbers = [int(i) for i in capture.indices]
        frames = frame_positions(numbers, args.frames)  # frame numbers, not positions
        if not frames:
            raise InputError(
                f"track: --frames {_text(args.frames)} selects none of the {len(numbers)} "
                f"frames (numbers {numbers[0]}..{numbers[-1]}) of {args.capture[0]}"
            )
        if args.frames.stop is not None and args.frames.stop > numbers[-1] + 1:
            print(
                f"meshmocap: warning: --frames {_text(args.frames)} asks for frames up to "
                f"{args.frames.stop - 1}; the capture ends at frame {numbers[-1]}: tracking "
                f"{len(frames)}",
                file=sys.stderr,
            )
    for line in check_observations(capture, frames):  # one person? dense? partial hulls?
        print(f"meshmocap: warning: {line}", file=sys.stderr)
    before = set() if args.restart else set(done_frames(args.out))
    timer = StageTimer()
    result = api.track(
        capture,
        method=args.method,
        out=args.out,
        template=args.template,
        frames=frames,
        init=args.init,
        resume=not args.restart,
        recover=not args.no_recover,
        reseat=args.reseat,
        manifold=args.manifold,
        vertices=False,
        log=print,
        timer=timer,
        **options,
    )
    track, dt = result.data, result.seconds
    resumed = len(before & set(track.frames.tolist()))
    new = len(track.frames) - resumed
    bad = int((~track.healthy).sum())
    missing = sum("missing" in f for f in track.flags)
    fresh = [s for i, s in zip(track.frames, track.seconds, strict=True) if int(i) not in before]
    per = sum(fresh[1:]) / (len(fresh) - 1) if len(fresh) > 1 else 0.0
    done = f"tracked {new} frames"
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
            f"meshmocap: warning: {missing} frames had no observation and were coasted "
            f"across, first {int(track.frames[first])}: {track.messages[first]}",
            file=sys.stderr,
        )
    return 0


def _lost(track) -> str:
    """Frames with a limb lost, re-initialised, and the first one's reason ('' if none)."""
    lost = [k for k, f in enumerate(track.flags) if "lost" in f]
    if not lost:
        return ""
    reinit = sum("reinit" in f for f in track.flags)
    k = lost[0]
    return (
        f", {len(lost)} with a limb lost ({reinit} re-initialised; first: frame "
        f"{int(track.frames[k])}, {track.messages[k]})"
    )


def _follow(args: argparse.Namespace, options: dict) -> int:
    """``track FOLDER --follow``: frames tracked as they are written (trackers.follow)."""
    from meshmocap.body.light import LIGHT_VERTICES, tracking_body
    from meshmocap.errors import InputError
    from meshmocap.trackers.follow import follow_sequence
    from meshmocap.trackers.registry import make_tracker

    if not args.follow:
        given = "--idle" if args.idle is not None else "--view" if args.view else "--recording"
        raise InputError(f"track: {given} goes with --follow")
    if len(args.capture) != 1 or args.frames:
        raise InputError("track --follow: give one folder (a capture or meshes) and no --frames")
    choice = _follow_template(args)
    template = choice.template
    print(choice.note)
    light = None if args.manifold else LIGHT_VERTICES  # as in _cmd_track
    tracked = tracking_body(template, n_vertices=light).light
    tracker = make_tracker(args.method, manifold=args.manifold, template=tracked, **options)
    seen: list[float] = []
    view = _live_view(args, template) if args.view or args.recording else None

    def report(f) -> None:
        seen.append(f.seconds)
        if view is not None:
            view.show(f.index)
        flags = f"  {','.join(f.flags)}: {f.message}" if f.flags else ""
        print(
            f"frame {f.index}: {1000 * f.seconds:.0f} ms, latency {1000 * f.latency:.0f} ms{flags}",
            flush=True,
        )

    idle = f"; stops after {args.idle:g} s without a new frame" if args.idle else ""
    print(f"following {args.capture[0]} with {args.method} (Ctrl-C stops){idle}", flush=True)
    how = f"no new frame for {args.idle:g} s" if args.idle else "stopped"
    try:
        follow_sequence(
            tracker,
            template,
            args.capture[0],
            args.out,
            idle=args.idle,
            resume=not args.restart,
            report=report,
            template_info=choice.info,
            light=light,
        )
    except KeyboardInterrupt:
        how = "Ctrl-C"
    per = sorted(seen)[len(seen) // 2] if seen else 0.0
    print(
        f"{how}: tracked {len(seen)} frames (median {1000 * per:.0f} ms per frame); "
        f"results in {args.out}"
    )
    if view is not None:
        view.close()
        if view.path is not None:
            print(f"live view: {view.frames} frames recorded in {view.path} (rerun {view.path})")
    return 0


def _live_view(args: argparse.Namespace, template):
    """``--view``: :class:`meshmocap.apps.live_view.LiveView` of the track folder."""
    from meshmocap.apps.live_view import LiveView

    Path(args.out).mkdir(parents=True, exist_ok=True)
    return LiveView(args.out, parents=template.eval_skeleton.parents, recording=args.recording)


def _follow_template(args: argparse.Namespace):
    """The template of a folder being written: as ``track`` chooses it, except that a
    folder with no frames yet cannot have the performer's body estimated from it."""
    import json
    from types import SimpleNamespace

    from meshmocap.errors import InputError
    from meshmocap.estimate.tracking_template import SUBJECT_FILE, tracking_template

    meta_file = Path(args.capture[0]) / "capture.json"
    try:
        meta = json.loads(meta_file.read_text()) if meta_file.is_file() else {}
    except (OSError, ValueError):
        meta = {}
    named = isinstance(meta, dict) and (meta.get("spec") or {}).get("template")
    cached = (Path(args.out) / SUBJECT_FILE).is_file() and not args.restart
    if args.template in (None, "auto") and not (named and args.template is None) and not cached:
        raise InputError(
            "track --follow: give --template NAME|FILE (a folder being written "
            "has no frames yet to estimate the performer's body from)"
        )
    capture = SimpleNamespace(meta=meta if isinstance(meta, dict) else {})
    return tracking_template(capture, args.template, args.out, refresh=args.restart)


def _text(s: slice) -> str:
    return ":".join("" if v is None else str(v) for v in (s.start, s.stop, s.step)).rstrip(":")


def _cmd_learn(args: argparse.Namespace) -> int:
    from pathlib import Path

    import numpy as np

    from meshmocap.apps.latent_plot import plot_latent_space
    from meshmocap.body.template import load_template
    from meshmocap.errors import InputError, MeshmocapFileNotFoundError
    from meshmocap.trackers.cage.manifold import fit_pose_manifold
    from meshmocap.trackers.cage.oqr import build_oqr
    from meshmocap.trackers.cage.training_poses import load_pose_sources

    out = Path(args.out)
    if out.suffix != ".npz" or not out.parent.is_dir():  # fail before the work
        bad = MeshmocapFileNotFoundError if out.suffix == ".npz" else InputError
        raise bad(f"learn: --out must be a .npz file in an existing folder, found {out}")
    template = load_template(args.template)
    t0 = time.perf_counter()
    oqr = build_oqr(template)
    poses = load_pose_sources(args.sources, template, oqr=oqr, asf=args.asf)
    print(
        f"read {len(poses)} poses of {template.name!r} from {len(args.sources)} source(s) "
        f"in {time.perf_counter() - t0:.1f} s"
    )
    pm = fit_pose_manifold(
        poses,
        template,
        oqr=oqr,
        n_components=args.latent_dim,
        n_samples=args.samples,
        random_state=args.seed,
    )
    gp = pm.gp
    names, counts = np.unique(pm.groups, return_counts=True)
    err = gp.predict(gp.X_) - gp.Y_mean_ - gp.Y_scale_ * gp.Y_
    centres = np.linalg.norm(err.reshape(len(err), -1, 3, 3)[:, :, 0], axis=2).mean() * 1000
    print(
        f"learned a {pm.n_components}-D manifold from {pm.n_samples} poses "
        f"({', '.join(f'{n} {g}' for g, n in zip(names, counts, strict=True))}) in "
        f"{pm.fit_seconds:.1f} s: final log-likelihood {gp.log_likelihood_:.1f} after "
        f"{gp.n_iter_} L-BFGS-B iterations{'' if gp.converged_ else ' (not converged)'}; "
        f"training quads reproduced to {centres:.1f} mm"
    )
    print(f"wrote {pm.save(args.out)}")
    if args.plot:
        labels = pm.groups if len(names) <= 10 else None
        title = f"{template.name}: {pm.n_components}-D pose manifold, {pm.n_samples} poses"
        print(f"wrote {plot_latent_space(gp, args.plot, labels=labels, title=title)}")
    return 0


def _cmd_transfer(args: argparse.Namespace) -> int:
    import json
    import warnings
    from pathlib import Path

    from meshmocap.apps.export import capture_fps
    from meshmocap.body.template import bundled_templates, load_template
    from meshmocap.io.meshes import read_mesh
    from meshmocap.trackers.cage.transfer import read_cage_track, write_transfer

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
        "articulated_icp, cage, cage_quads, cage_noreg, cage_nolocal",
    )
    k.add_argument(
        "--template",
        help="tracking template: a name or .npz, or auto to estimate "
        "the performer's body (default: the template capture.json names, else auto; "
        "an estimate is cached as subject.npz in --out)",
    )
    k.add_argument("--out", required=True, help="track folder (frame-by-frame results)")
    add_frames(k)
    k.add_argument(
        "--n-patches",
        type=number(MIN_PATCHES, 10_000, integer=True),
        help=f"patch tracker: number of patches (at least {MIN_PATCHES}: fewer cannot follow "
        "the limbs, and one has no neighbour to be rigid with)",
    )
    k.add_argument("--classifier", help="patch tracker: logistic, svc or none")
    k.add_argument(
        "--keep-fraction",
        type=number(0, 1, open_lo=True),
        help="patch tracker: on-bone points kept",
    )
    k.add_argument(
        "--outlier-sigmas",
        type=number(0, 100, open_lo=True),
        help="patch tracker: a point this many σ "
        "from the model is as likely an outlier (default 3; 2 rejects more of a "
        "few-camera hull's phantom volumes, but also true points where the subject's "
        "surface differs from the template's)",
    )
    k.add_argument("--max-iter", type=number(1, 10_000, integer=True), help="iterations per frame")
    k.add_argument(
        "--fast-iter-scale",
        type=number(1, 100),
        help="patch tracker: iterations of a frame "
        "after a fast one (a joint moved > 5 cm), as a multiple of the usual "
        "(default 2; 1 keeps every frame's cost the same)",
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
        "--reseat",
        action="store_true",
        help="re-initialise a lost limb where a "
        "better pose is found and hold one the hulls miss as last seen (rescues a "
        "limb lost behind a hole; can mistake a fast limb for a lost one)",
    )
    k.add_argument(
        "--no-recover",
        action="store_true",
        help="do not score frames, flag lost limbs or re-initialise them",
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
        help="with --follow: stop after this many seconds without a new frame",
    )
    k.add_argument(
        "--view",
        action="store_true",
        help="with --follow: show the body as it is tracked in the rerun viewer "
        '(pip install "meshmocap[view]"); headless, save the recording as OUT/live.rrd',
    )
    k.add_argument("--recording", help="with --follow: --view, saved to this .rrd file")
    k.set_defaults(func=_cmd_track)
    m = sub.add_parser("learn", help="learn the cage tracker's pose manifold (GPLVM) from poses")
    m.add_argument(
        "sources",
        nargs="+",
        metavar="SOURCE",
        help="walk, jog (procedural), .bvh/.amc/.mat mocap or a hand-labelled .npz pose file",
    )
    m.add_argument("--template", default="neutral_5k", help="tracking template (name or .npz)")
    m.add_argument("--out", required=True, help="manifold file to write (.npz)")
    m.add_argument(
        "--latent-dim", type=number(1, 20, integer=True), default=2, help="latent dimension q"
    )
    m.add_argument(
        "--samples",
        type=number(3, 100_000, integer=True),
        default=120,
        help="training poses (default: 120)",
    )
    m.add_argument("--asf", help="ASF skeleton of .amc/.mat sources (default: found beside)")
    m.add_argument("--plot", help="also draw the latent space (.png, .pdf or .svg)")
    m.add_argument("--seed", type=number(0, 2**32 - 1, integer=True), default=0, help="random seed")
    m.set_defaults(func=_cmd_learn)
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
