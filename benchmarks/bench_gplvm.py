"""Benchmark the GPLVM pose manifold: training time and the tracker's hot path.

Data: 120 × 126 — 60 walk and 60 jog frames of ../shared/data/mocap/cmu/cmu35WalkJog.mat
(59 AMC channels without the root translation, columns tiled to 126, the size of the cage
paper's 21 quads × 6), or, when the file is absent, 120 noisy samples of a smooth random
2-D manifold in 126-D.

Reported per configuration: fit time (wall and CPU seconds: the machines are shared, and
CPU time is less disturbed by other processes), L-BFGS-B iterations, convergence, final
Eq. (2) log-likelihood, and ``predict_with_gradient`` µs per call (best of 7 × 2000 calls,
wall and CPU, one BLAS thread). Reference (brief): GPy's back-constrained GPLVM takes 4 s
for q = 2 on this size and 30 s (unconverged) for q = 10. Target: ``predict_with_gradient`` ≤ 50 µs.

Run: ``python benchmarks/bench_gplvm.py``.
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from meshmocap._threads import limit_blas_threads
from meshmocap.models.gplvm import GPLVM

limit_blas_threads()

MAT = Path(__file__).resolve().parents[1].parent / "shared/data/mocap/cmu/cmu35WalkJog.mat"
TRIALS = [*range(1, 17), 17, *range(19, 27), 28, *range(30, 35)]  # columns of ``lbls``
JOGS = {17, *range(19, 27)}


def data(D: int = 126) -> tuple[np.ndarray, str]:
    """(120, D) training poses and a description of where they come from."""
    if MAT.is_file():
        from scipy.io import loadmat

        mat = loadmat(MAT)
        Y = mat["Y"][:, 3:]
        jog = np.isin(np.array(TRIALS)[np.argmax(mat["lbls"], 1)], list(JOGS))
        w, j = np.flatnonzero(~jog), np.flatnonzero(jog)
        rows = np.concatenate(
            [
                w[np.linspace(0, len(w) - 1, 60).astype(int)],
                j[np.linspace(0, len(j) - 1, 60).astype(int)],
            ]
        )
        Y = np.tile(Y[rows], (1, -(-D // Y.shape[1])))[:, :D]
        return Y, f"cmu35WalkJog.mat, 60 walk + 60 jog frames, 59 channels tiled to {D}"
    rng = np.random.default_rng(0)
    t = rng.uniform(0, 1, (120, 2))
    f, p = rng.uniform(0.3, 1.5, (2, D)), rng.uniform(0, 2 * np.pi, D)
    Y = np.sin(2 * np.pi * t @ f + p) + 0.02 * rng.standard_normal((120, D))
    return Y, f"synthetic 2-D manifold in {D}-D (cmu35WalkJog.mat absent)"


def per_call_us(model: GPLVM, repeat: int = 7, number: int = 2000) -> tuple[float, float]:
    """Best wall and CPU time of one ``predict_with_gradient`` call, in µs."""
    rng = np.random.default_rng(1)
    x = model.X_[rng.integers(len(model.X_))] + 0.1
    wall = cpu = np.inf
    for _ in range(repeat):
        t0, c0 = time.perf_counter(), time.process_time()
        for _ in range(number):
            model.predict_with_gradient(x)
        wall = min(wall, (time.perf_counter() - t0) / number)
        cpu = min(cpu, (time.process_time() - c0) / number)
    return wall * 1e6, cpu * 1e6


def main() -> None:
    Y, source = data()
    print(f"data: {Y.shape[0]} x {Y.shape[1]} ({source})")
    head = (
        "q",
        "bc",
        "fit s",
        "cpu s",
        "iters",
        "conv",
        "log-lik",
        "alpha",
        "gamma",
        "beta",
        "pwg us",
        "cpu us",
    )
    widths = (3, 5, 6, 6, 6, 5, 9, 6, 7, 6, 7, 7)
    print(" ".join(f"{h:>{w}}" for h, w in zip(head, widths, strict=True)))
    for q in (2, 10):
        for bc in ("rbf", "mlp", None):
            t0, c0 = time.perf_counter(), time.process_time()
            m = GPLVM(q, back_constraint=bc, random_state=0).fit(Y)
            fit_s, fit_cpu = time.perf_counter() - t0, time.process_time() - c0
            us, cpu_us = per_call_us(m)
            print(
                f"{q:>3} {bc!s:>5} {fit_s:>6.2f} {fit_cpu:>6.2f} {m.n_iter_:>6} "
                f"{m.converged_!s:>5} {m.log_likelihood_:>9.1f} {m.alpha_:>6.3g} "
                f"{m.gamma_:>7.3g} {m.beta_:>6.3g} {us:>7.1f} {cpu_us:>7.1f}"
            )
    print(
        "reference: GPy BC-GPLVM 4 s (q = 2), 30 s unconverged (q = 10); "
        "target predict_with_gradient <= 50 us"
    )


if __name__ == "__main__":
    main()
