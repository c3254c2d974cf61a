"""Benchmark 3D Green coordinates and the cage deformer at the cage tracker's sizes.

Sizes (cage-manifold-tracking §3): a closed cage of 85 vertices and 166 triangles (a
sphere triangulation perturbed into a non-convex, human-sized 0.35 × 0.25 × 0.9 m body)
carrying 12,411 points (template vertices + joints) strictly inside it.

Targets: coordinates once per template (no target; ~0.5 s), ``deform`` ≤ 1 ms for 12k
points. ``deform`` is one (3 × 251) @ (251 × n) product, i.e. reading the n × 251
coordinate matrix once: 25 MB in float64. The table also prints the time to merely read
that matrix (``G.sum()``), the machine's floor for any float64 implementation.

Run: ``python benchmarks/bench_green.py`` (one BLAS thread, the meshmocap default).
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import ConvexHull

from _timing import per_call
from meshmocap.geometry.green import GreenDeformer, green_coordinates

N_POINTS = 12_411
N_CAGE = 85  # a closed genus-0 triangle cage with 85 vertices has 2·85 − 4 = 166 faces


def cage(seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """(85, 3) vertices and (166, 3) outward faces of a bumpy, star-shaped body, metres."""
    u = np.random.default_rng(seed).normal(size=(N_CAGE, 3))
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    F = ConvexHull(u).simplices.copy()
    N = np.cross(u[F[:, 1]] - u[F[:, 0]], u[F[:, 2]] - u[F[:, 0]])
    flip = np.einsum("ij,ij->i", N, u[F].mean(axis=1)) < 0
    F[flip] = F[flip][:, ::-1]
    radius = 1.0 + 0.25 * np.sin(3 * u[:, 0]) * np.cos(2 * u[:, 1])
    V = u * radius[:, None] * np.array([0.35, 0.25, 0.9]) + np.array([0.0, 0.0, 1.0])
    return V, F


def inside(V: np.ndarray, F: np.ndarray, n: int, seed: int = 1) -> np.ndarray:
    """Points strictly inside the star-shaped cage: surface points shrunk towards its centre."""
    rng = np.random.default_rng(seed)
    centre = np.array([0.0, 0.0, 1.0])
    b = rng.dirichlet([1, 1, 1], n)
    surf = np.einsum("pk,pki->pi", b, V[F[rng.integers(0, len(F), n)]])
    return centre + rng.uniform(0.02, 0.98, (n, 1)) * (surf - centre)


def best(fn, repeat: int = 7, number: int = 20) -> tuple[float, float]:
    """(best, median) per-call seconds over ``repeat`` runs of ``number`` calls."""
    out = per_call(fn, repeat, number)
    return min(out), float(np.median(out))


def main() -> None:
    V, F = cage()
    P = inside(V, F, N_POINTS)
    rng = np.random.default_rng(2)
    Vn = V + 0.03 * rng.normal(size=V.shape)  # a deformed cage, 3 cm vertex noise
    rows: list[tuple[str, float, float]] = []

    rows.append(("green_coordinates (12,411 pts)", *best(lambda: green_coordinates(P, V, F), 3, 1)))
    d64 = GreenDeformer(V, F, P)
    d32 = GreenDeformer(V, F, P, dtype=np.float32)
    err = np.abs(d64.deform(V) - P).max()
    err32 = np.abs(d32.deform(Vn) - d64.deform(Vn)).max()
    G = np.ascontiguousarray(np.hstack([d64.phi_, d64.psi_]))
    rows.append(("  floor: read the float64 coordinates", *best(G.sum, 7, 50)))
    rows.append(("deform, float64", *best(lambda: d64.deform(Vn), 7, 50)))
    rows.append(("deform, float32 storage", *best(lambda: d32.deform(Vn), 7, 50)))
    batch = Vn + 0.01 * rng.normal(size=(8, *V.shape))
    t_b = best(lambda: d64.deform(batch), 5, 10)
    rows.append(("deform, float64, batch of 8 (per cage)", t_b[0] / 8, t_b[1] / 8))
    dV = rng.normal(size=V.shape)
    grad = rng.normal(size=P.shape)
    rows.append(("jvp (12,411 pts)", *best(lambda: d64.jvp(Vn, dV), 5, 10)))
    rows.append(("vjp (12,411 pts)", *best(lambda: d64.vjp(Vn, grad), 5, 10)))
    joints = GreenDeformer(V, F, P[:15])
    rows.append(("jacobian (15 joints)", *best(lambda: joints.jacobian(Vn), 5, 10)))

    print(f"cage: {len(V)} vertices, {len(F)} faces; {N_POINTS} points inside")
    print(f"{'operation':<40} {'best ms':>9} {'median ms':>10}")
    for name, b, m in rows:
        print(f"{name:<40} {b * 1e3:>9.3f} {m * 1e3:>10.3f}")
    print(f"rest-pose reproduction error: {err:.2e} m; float32 vs float64 deform: {err32:.2e} m")
    print(f"outside points: {int(d64.outside_.sum())}")
    print("target: deform <= 1 ms for 12k points")


if __name__ == "__main__":
    main()
