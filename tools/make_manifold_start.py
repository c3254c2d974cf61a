"""Make the bundled start of the cage's default pose manifold (``manifold_start.npz``).

The default manifold (:func:`~meshmocap.trackers.cage.manifold.default_manifold`) is learned
on the fly for every tracking body, from the same poses of the bundled pose library
(:data:`~meshmocap.trackers.cage.manifold.DEFAULT_SOURCES`) retargeted to that body. From
the PCA start its L-BFGS-B fit needs thousands of iterations (and tens of CPU seconds) and
stops at optima that differ widely between bodies; started from the latent points and
kernel of one long fit on a reference body, a few hundred iterations reach a higher
likelihood (``docs/measurements.rst``). This tool makes that start: the default manifold's
GPLVM fitted on the reference body (``neutral``'s light tracking body, the cage's body of
it) with ``--iterations`` L-BFGS-B iterations from the PCA start, one BLAS thread.

Written (``.npz``): ``X`` (N, q) latent points, ``hyper`` (3,) α, γ, β, ``trials`` (N,)
the training poses' trials (a body whose poses differ is started from PCA),
``log_likelihood``, ``iterations``, ``template``, ``library`` (the pose library's digest).

Run: ``python tools/make_manifold_start.py [--template neutral] [--iterations 3000]
[--out src/meshmocap/trackers/cage/data/manifold_start.npz]``.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from meshmocap.body.light import tracking_body
from meshmocap.body.pose_library import load_pose_library
from meshmocap.body.template import load_template
from meshmocap.trackers.cage.body import cage_body
from meshmocap.trackers.cage.manifold import (
    DEFAULT_COMPONENTS,
    DEFAULT_POSES,
    DEFAULT_SOURCES,
    learn_pose_manifold,
)
from meshmocap.trackers.cage.options import CageOptions


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--template", default="neutral")
    ap.add_argument("--iterations", type=int, default=3000)
    ap.add_argument("--out", default="src/meshmocap/trackers/cage/data/manifold_start.npz")
    args = ap.parse_args()
    light = tracking_body(load_template(args.template)).light
    body, oqr = cage_body(light, body=CageOptions().body)
    t0 = time.process_time()
    pm = learn_pose_manifold(
        body,
        DEFAULT_SOURCES,
        n_components=DEFAULT_COMPONENTS,
        n_samples=DEFAULT_POSES,
        oqr=oqr,
        max_iter=args.iterations,
    )
    gp = pm.gp
    np.savez(
        args.out,
        X=gp.X_,
        hyper=np.array([gp.alpha_, gp.gamma_, gp.beta_]),
        trials=np.asarray(pm.trials, dtype=str),
        log_likelihood=np.array(gp.log_likelihood_),
        iterations=np.array(gp.n_iter_),
        template=np.str_(args.template),
        library=np.str_(load_pose_library().digest),
    )
    print(
        f"{args.out}: {args.template} ({body.name}), {gp.n_iter_} iterations, log-likelihood "
        f"{gp.log_likelihood_:.1f}, {time.process_time() - t0:.1f} CPU s"
    )


if __name__ == "__main__":
    main()
