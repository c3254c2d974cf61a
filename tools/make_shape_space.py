"""Generate the body-shape space bundled with meshmocap from the ``anny`` body model.

Run from the repository root::

    python tools/make_shape_space.py [--out FILE] [--cache DIR] [--bodies N] [--components K]

It writes ``src/meshmocap/body/data/shape/shape_space.npz`` (format
``meshmocap-shape-space-1``, see ``meshmocap.body.shape_space``): the mean and the first
``K`` principal components of ``N`` anny bodies of random sex, age (teenage to old), muscle,
weight, height and proportions, each in the bundled templates' topology and world frame
(``tools/make_template.py``: cavities closed, feet on z = 0, hips at x = y = 0, the MakeHuman
A-pose). A component moves the rest vertices **and** the rig with them: each body's 31 bone
heads and tails and its evaluation head centre are stacked with its vertices before the
decomposition, so every component carries a linear joint regressor of its own. Skinning
weights, body parts and the bone binding of the evaluation joints are anny's, the same for
every body, taken from the mean body.

It needs the ``template`` extra (install ``torch==2.13.0`` first so that no CUDA build is
pulled). Time on 2 CPU cores: about 3 minutes to build anny's rig data the first time (cached
under ``--cache``), then about 0.4 s per body. The output is deterministic for a seed.
It prints the variance explained and how well the space reproduces the bundled bodies
(which are not among the samples).
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import make_template as mt
from meshmocap.models.shape_space import ShapeSpace

FORMAT = "meshmocap-shape-space-1"

#: Range of each anny phenotype sampled (uniformly). anny's age 0.6 is about 16 years,
#: 0.78 about 25, 1.0 about 90 (anny's calibration); the others span anny's whole range.
PHENOTYPE_RANGES = {
    "gender": (0.0, 1.0),
    "age": (0.6, 1.0),
    "muscle": (0.0, 1.0),
    "weight": (0.0, 1.0),
    "height": (0.0, 1.0),
    "proportions": (0.0, 1.0),
}


def sample_phenotypes(n: int, seed: int) -> list[dict]:
    """``n`` phenotypes drawn uniformly in :data:`PHENOTYPE_RANGES`."""
    rng = np.random.default_rng(seed)
    lo = np.array([r[0] for r in PHENOTYPE_RANGES.values()])
    hi = np.array([r[1] for r in PHENOTYPE_RANGES.values()])
    X = lo + (hi - lo) * rng.random((n, len(lo)))
    return [dict(zip(PHENOTYPE_RANGES, map(float, x), strict=True)) for x in X]


def body_vector(body: dict) -> np.ndarray:
    """Stack one body's rest vertices (n, 3), bone heads and tails (31, 3) and evaluation
    head centre (3,) into one vector (3n + 189,), metres."""
    W = mt.sparse_weights(body["W"])
    pos, _ = mt.eval_joints(body["V"], W, body["heads"])
    head = pos[mt.EVAL_NAMES.index("head")]
    return np.concatenate([body["V"].ravel(), body["heads"].ravel(), body["tails"].ravel(), head])


def main(argv: list[str] | None = None) -> None:
    """Generate the shape space; print what it explains."""
    root = Path(__file__).resolve().parents[1]
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    default_out = root / "src/meshmocap/body/data/shape/shape_space.npz"
    ap.add_argument("--out", type=Path, default=default_out)
    ap.add_argument("--cache", type=Path, default=Path("/tmp/anny_cache"))
    ap.add_argument("--bodies", type=int, default=600)
    ap.add_argument("--components", type=int, default=16)
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args(argv)
    args.out.parent.mkdir(parents=True, exist_ok=True)

    t0 = time.perf_counter()
    model = mt.load_anny(args.cache)
    cavities = mt.cavity_faces(model)
    phenotypes = sample_phenotypes(args.bodies, args.seed)
    bodies = [mt.body_in_world(mt.rest_body(model, p), cavities) for p in phenotypes]
    X = np.stack([body_vector(b) for b in bodies])
    n = len(bodies[0]["V"])
    F, W = bodies[0]["F"], bodies[0]["W"]
    assert all(np.array_equal(b["F"], F) and np.allclose(b["W"], W) for b in bodies)
    pca = ShapeSpace(n_components=args.components).fit(X)
    mean, comps, std, ratio = pca.mean_, pca.components_, pca.std_, pca.explained_variance_ratio_
    explained = ", ".join(f"{ratio[:k].sum():.4f}" for k in (1, 2, 4, 8, args.components))
    print(
        f"{args.bodies} bodies in {time.perf_counter() - t0:.0f} s; variance explained by "
        f"1, 2, 4, 8, {args.components} components: {explained}"
    )

    mean_body = dict(bodies[0], V=mean[: 3 * n].reshape(n, 3))
    mean_body["heads"] = mean[3 * n : 3 * n + 93].reshape(31, 3)
    mean_body["tails"] = mean[3 * n + 93 : 3 * n + 186].reshape(31, 3)
    arrays = mt.make_template(
        "shape_space_mean",
        **{k: mean_body[k] for k in ("V", "F")},
        heads=mean_body["heads"],
        tails=mean_body["tails"],
        W_dense=W,
    )
    arrays.update(
        format=np.str_(FORMAT),
        name=np.str_("anny_shape_space"),
        components=comps.astype(np.float32),
        mean=mean.astype(np.float64),
        std=std.astype(np.float64),
        explained_variance_ratio=ratio.astype(np.float64),
        n_samples=np.int64(args.bodies),
        phenotype_names=np.array(list(PHENOTYPE_RANGES)),
        phenotype_ranges=np.array(list(PHENOTYPE_RANGES.values())),
    )
    del arrays["V"], arrays["joint_positions"], arrays["end_positions"]
    del arrays["eval_rest_positions"]
    arrays["mean"] = arrays["mean"].astype(np.float32)
    with open(args.out, "wb") as f:
        np.savez_compressed(f, **arrays)
    print(
        f"{args.out}: {args.components} components of {X.shape[1]} values, "
        f"{args.out.stat().st_size / 1e6:.2f} MB"
    )

    for name, p in mt.SHAPES.items():  # held out: not among the random samples
        x = body_vector(mt.body_in_world(mt.rest_body(model, p), cavities))
        for k in sorted({4, 8, 12, 16, args.components}):
            if k > args.components:
                continue
            rec = mean + comps[:k].T @ (comps[:k] @ (x - mean))
            dv = np.linalg.norm((rec - x)[: 3 * n].reshape(n, 3), axis=1)
            dj = np.linalg.norm((rec - x)[3 * n : 3 * n + 93].reshape(31, 3), axis=1)
            print(
                f"  {name}, {k} components: vertices reproduced to "
                f"{dv.mean() * 1000:.2f} mm mean, {dv.max() * 1000:.2f} max; "
                f"joints {dj.mean() * 1000:.2f} mm mean"
            )
    print(f"done in {time.perf_counter() - t0:.0f} s")


if __name__ == "__main__":
    main()
