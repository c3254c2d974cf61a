"""The cage tracker's pose manifold: ``meshmocap learn``."""

from __future__ import annotations

import argparse
import time

from meshmocap.cli._args import number


def _cmd_learn(args: argparse.Namespace) -> int:
    from pathlib import Path

    import numpy as np

    from meshmocap.apps.figures.latent import plot_latent_space
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


def register(sub: argparse._SubParsersAction) -> None:
    """Add the parser of ``meshmocap learn`` to ``sub``."""
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
