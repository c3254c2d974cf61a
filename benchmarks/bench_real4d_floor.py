"""The floor of a 4D track's per-vertex error in its own truth (issue 44).

The per-vertex error of ``bench_real4d`` compares each tracked template vertex with the
vertex of the same index in the input files. That is a fair measure only where the files'
own vertices stay on the same point of the body. The crane's files are themselves a track
(Vlasic et al. 2008 deformed one template to multi-view silhouettes), and a vertex that
slides along its surface there cannot be followed by any tracker that sees only the surface:
a tangential slide leaves the surface where it was.

This script measures that slide where a real body cannot deform: the parts a skeleton keeps
rigid, taken from the track's own rig (its template is the first frame's file, so its
vertices are the files' vertices). The parts:

- ``head``: the vertices whose largest weight is the head joint's, at least 0.9;
- ``pelvis``: the vertices whose weights on the hips' joints (the root and the two hip
  joints that sit on it) sum to at least 0.6 (a rig blends the pelvis's skin with the
  thighs' and the spine's: none reaches 0.9 on the crane);
- each long bone's middle third (thigh, shin, upper arm, forearm): the vertices whose
  largest weight is that bone's, projected onto the bone (joint to child joint, rest pose)
  between a third and two thirds of its length.

For each part and frame ``t``, the best rigid motion of the part's TRUE vertices from frame
0 to frame ``t`` and the residual of each vertex, split along the true surface's normal at
``t`` and along the surface (tangential): the nearest rigid motion (least squares, Kabsch:
``nearest``) and the one nearest along the surface (:func:`tangent_fit`: ``along``, what is
left once each vertex is moved along the normal onto the true surface). The residual is the
files' own non-rigid motion of a rigid part: vertices that move rigidly with the part
cannot be nearer the files (in root mean square, frame by frame), and its tangential part
is invisible in the surface. A tracker whose vertices do not move rigidly can be nearer
where the surface shows the motion (a fold of the clothes that moves).

Beside it, each track's own error on the same vertices, and the same for the whole body:

- the **piecewise-rigid oracle**: each vertex moved with the best rigid motion (from the
  truth, with known correspondences) of all the vertices of its rig part (largest weight;
  parts with fewer than 30 vertices join their parent's);
- the **skinning oracle** (``--lbs``, minutes): the rig posed on each true frame with known
  correspondences and its weights fitted to ALL the true frames in those poses, twice over
  (:func:`lbs_oracle`): the best a skeleton-driven tracker of that rig could do, fitted on
  the frames it is scored on; the same refined frame by frame towards the true meshes as a
  track of a clean 4D capture is (:func:`refined`); and each track measured against the
  skinning oracle.

Each row: the mean per-vertex error over the first and the last fifth of the frames and
their ratio (the target of issue 44: ≤ 1.5), the same for its tangential part (what is
left once the vertex is moved along the normal onto the true surface, as a perfect
refinement along the normals would), and the last fifth's normal part; with ``--settle
S``, also the mean over the first fifth's frames from ``S`` on (the crane's first 20
frames stay near the first frame's pose, where the template, the first file itself, is
right by construction) and the last fifth's ratio to it.

Run: ``python benchmarks/bench_real4d_floor.py TRACK [TRACK ...] [--cache FILE] [--lbs]
[--settle S] [--rig FILE]``, the tracks of one source (e.g. ``bench_real4d``'s
``crane175_patch_refine-arap`` and ``crane175_articulated_icp_refine-arap``); the rig is
the first track's template. ``--cache`` keeps the true vertices and the skinning oracle
(reading the crane's 175 files takes most of a minute, the oracle a few). ``--rig FILE``:
the parts from this template's weights instead (the same vertices: a synthetic capture's
own performer, whose rig is the truth's).
"""

from __future__ import annotations

import argparse
import itertools
from pathlib import Path

import numpy as np

from bench_real4d import table
from meshmocap.body.template import load_template
from meshmocap.geometry.mesh import vertex_normals
from meshmocap.io.results import open_tracked_capture, read_track, tracked_template

LONG_BONES = {
    "thighs": ("LeftUpLeg", "RightUpLeg"),
    "shins": ("LeftLeg", "RightLeg"),
    "upper arms": ("LeftArm", "RightArm"),
    "forearms": ("LeftForeArm", "RightForeArm"),
}
HIPS = ("Hips", "LHipJoint", "RHipJoint")
MIN_PART = 30


def rigid_parts(
    template, *, dominant: float = 0.9, pelvis: float = 0.6
) -> dict[str, list[np.ndarray]]:
    """The parts a real body keeps rigid (module docstring): name -> the (n,) bool masks
    of its pieces (a bone's left and right, each rigid on its own)."""
    sk = template.skeleton
    W = np.asarray(template.weights.todense())
    top = W.argmax(axis=1)
    parts = {"head": [(top == sk.index("Head")) & (W.max(axis=1) >= dominant)]}
    hips = [sk.index(n) for n in HIPS if n in sk.names]
    parts["pelvis"] = [W[:, hips].sum(axis=1) >= pelvis]
    P = sk.rest_positions
    for label, names in LONG_BONES.items():
        parts[label] = []
        for name in names:
            j = sk.index(name)
            a, b = P[j], P[sk.children[j][0]]
            s = (template.V - a) @ (b - a) / np.dot(b - a, b - a)
            parts[label].append((top == j) & (s >= 1 / 3) & (s <= 2 / 3))
    return parts


def rig_parts(template) -> np.ndarray:
    """(n,) int: each vertex's rig part (largest weight), parts under ``MIN_PART``
    vertices merged into their parent's, repeatedly."""
    sk = template.skeleton
    part = np.asarray(template.weights.todense()).argmax(axis=1)
    for j in range(sk.n_joints - 1, 0, -1):  # children before parents
        if 0 < (part == j).sum() < MIN_PART:
            part[part == j] = sk.parents[j]
    return part


def rigid_fit(X: np.ndarray, Y: np.ndarray) -> np.ndarray:
    """The least-squares rigid motion of ``X`` (k, 3) onto each ``Y`` (T, k, 3), applied
    to ``X``: (T, k, 3) (Kabsch, no scaling, no reflection)."""
    cx, cy = X.mean(axis=0), Y.mean(axis=1, keepdims=True)
    H = np.einsum("ka,tkb->tab", X - cx, Y - cy)
    U, _, Vt = np.linalg.svd(H)
    d = np.sign(np.linalg.det(np.einsum("tab,tbc->tac", U, Vt)))
    D = np.ones((len(Y), 3))
    D[:, 2] = d
    R = np.einsum("tba,tb,tcb->tac", Vt, D, U)  # R = V diag(1, 1, d) Uᵀ
    return np.einsum("tab,kb->tka", R, X - cx) + cy


def tangent_fit(X: np.ndarray, Y: np.ndarray, N: np.ndarray, iters: int = 20) -> np.ndarray:
    """The rigid motion of ``X`` (k, 3) that brings it nearest each ``Y`` (T, k, 3) ALONG
    the surface (least squares of the offsets' parts in the tangent planes of the unit
    normals ``N`` (T, k, 3); Gauss–Newton from :func:`rigid_fit`), applied to ``X``:
    (T, k, 3). Such vertices, then moved along the normals onto the true surface, are as
    near the truth as vertices moving rigidly with their part can be."""
    Z = rigid_fit(X, Y)
    P = np.eye(3) - N[..., :, None] * N[..., None, :]  # (T, k, 3, 3) tangent projectors
    for _ in range(iters):
        zc = Z.mean(axis=1, keepdims=True)
        d = Z - zc
        Dx = np.zeros(d.shape + (3,))  # [d]×
        Dx[..., 0, 1], Dx[..., 0, 2], Dx[..., 1, 2] = -d[..., 2], d[..., 1], -d[..., 0]
        Dx -= np.swapaxes(Dx, -1, -2)
        J = np.concatenate([-P @ Dx, P], axis=-1)  # (T, k, 3, 6): δz = ω × d + δc
        r = np.einsum("tkab,tkb->tka", P, Z - Y)
        H = np.einsum("tkai,tkaj->tij", J, J) + 1e-12 * np.eye(6)
        x = -np.linalg.solve(H, np.einsum("tkai,tka->ti", J, r)[..., None])[..., 0]
        w, c = x[:, :3], x[:, 3:]
        th = np.linalg.norm(w, axis=1)[:, None, None]
        K = np.zeros((len(w), 3, 3))
        K[:, 0, 1], K[:, 0, 2], K[:, 1, 2] = -w[:, 2], w[:, 1], -w[:, 0]
        K -= np.swapaxes(K, -1, -2)
        safe = np.maximum(th, 1e-12)
        R = np.eye(3) + np.sin(th) / safe * K + (1 - np.cos(th)) / safe**2 * (K @ K)
        Z = np.einsum("tab,tkb->tka", R, d) + zc + c[:, None]
    return Z


def lbs_oracle(template, V: np.ndarray, rounds: int = 2) -> np.ndarray:
    """The best linear-blend skinning of the template's rig to the truth ``V`` (T, n, 3)
    with known correspondences: each frame's pose fitted to the true vertices
    (:func:`~meshmocap.body.pose_fit.pose_from_surface`), then the weights fitted to ALL
    the true frames in those poses (:func:`~meshmocap.body.skinning.fit_weights`, over each
    vertex's :func:`~meshmocap.body.skinning.weight_candidates`), ``rounds`` times; the
    skinned vertices (T, n, 3). Fitted on the frames it is scored on, so no tracker of that
    rig reaches it."""
    from dataclasses import replace

    from meshmocap.body.pose_fit import pose_from_surface
    from meshmocap.body.skeleton import forward_kinematics
    from meshmocap.body.skinning import fit_weights, skinning_transforms, weight_candidates

    sk = template.skeleton
    C = weight_candidates(template.weights, template.F, sk.parents)
    for _ in range(rounds):
        fit = pose_from_surface(template, V, joint_weight=0.0)
        G, P = forward_kinematics(sk, fit.rotations, fit.root_positions)
        A = skinning_transforms(G, P, sk.rest_positions)
        W = fit_weights(template.V, A, V, template.weights, C)
        template = replace(template, weights=W)
    fit = pose_from_surface(template, V, joint_weight=0.0)
    return np.stack(
        [template.pose(R, r).V for R, r in zip(fit.rotations, fit.root_positions, strict=True)]
    )


def refined(template, S: np.ndarray, V: np.ndarray, N: np.ndarray) -> np.ndarray:
    """The surfaces ``S`` (T, n, 3) refined frame by frame towards the true vertices ``V``
    (T, n, 3) with their normals ``N`` as observed points, by the refinement a track of a
    clean 4D capture gets (:func:`~meshmocap.trackers.driver.output_refiner`: as rigidly
    as possible, anchored frame to frame), on the template's full mesh."""
    from meshmocap.trackers.driver import output_refiner

    refiner = output_refiner(template, refine="arap", four_d=True, clean=True)
    return np.stack([refiner.refine(S[t], V[t], N[t], key=t) for t in range(len(S))])


def split(E: np.ndarray, N: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per-vertex error vectors ``E`` (T, k, 3) and unit normals ``N`` (T, k, 3): the
    distances, their normal parts (absolute) and tangential parts, each (T, k) mm."""
    en = np.einsum("tka,tka->tk", E, N)
    tan = np.linalg.norm(E - en[..., None] * N, axis=-1)
    return np.linalg.norm(E, axis=-1) * 1e3, np.abs(en) * 1e3, tan * 1e3


def fifths(x: np.ndarray) -> np.ndarray:
    """(5,) means of ``x`` (T, ...) over the five fifths of its frames (the last one takes
    the remainder, as ``bench_real4d``'s first and last fifths: ``T // 5`` frames each)."""
    f = max(1, len(x) // 5)
    cuts = [0, f, 2 * f, 3 * f, len(x) - f, len(x)]
    return np.array([x[a:b].mean() for a, b in itertools.pairwise(cuts)])


def truth(track_dir: Path, cache: Path | None) -> tuple[np.ndarray, np.ndarray]:
    """The true vertices (T, n, 3) of the track's frames and their normals, metres."""
    t = read_track(track_dir, vertices=False)
    if cache is not None and cache.is_file():
        z = np.load(cache)
        return z["V"], z["N"]
    cap = open_tracked_capture(t.meta)
    pos = {int(f): k for k, f in enumerate(cap.indices)}
    meshes = [cap[pos[int(f)]].hull_mesh for f in t.frames]
    V = np.stack([m[0] for m in meshes])
    N = np.stack([vertex_normals(*m) for m in meshes])
    if cache is not None:
        np.savez(cache, V=V, N=N)
    return V, N


def row(label: str, k: int, E: np.ndarray, N: np.ndarray, settle: int = 0) -> list:
    """A table row of the error vectors ``E`` (T, k, 3) against the normals ``N``: per
    fifth, the mean distance and its tangential part (first, last, their ratio) and the
    last fifth's normal part, mm; with ``settle`` > 0, also the mean distance over the
    first fifth's frames from ``settle`` on and the last fifth's ratio to it."""
    d, n, g = split(E, N)
    f, t = fifths(d), fifths(g)
    out = [label, k, f[0], f[-1], f"{f[-1] / f[0]:.2f}", t[0], t[-1], f"{t[-1] / t[0]:.2f}"]
    out.append(float(fifths(n)[-1]))
    if settle:
        later = float(d[settle : max(1, len(d) // 5)].mean())
        out += [later, f"{f[-1] / later:.2f}"]
    return out


HEADS = ["part", "vertices", "first fifth", "last fifth", "last/first"]
HEADS += ["tangential first", "tangential last", "last/first", "normal last"]
SETTLED = ["first fifth from settle", "last/that"]


def cli() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("tracks", nargs="+", type=Path)
    ap.add_argument("--cache", type=Path, default=None, help="npz keeping the true vertices")
    ap.add_argument("--rig", type=Path, default=None, help="the parts from this template")
    ap.add_argument("--lbs", action="store_true", help="also the skinning oracle (minutes)")
    ap.add_argument("--settle", type=int, default=0, help="also the first fifth from this frame on")
    args = ap.parse_args()
    heads = HEADS + (SETTLED if args.settle else [])
    template = load_template(args.rig) if args.rig else tracked_template(args.tracks[0])
    V, N = truth(args.tracks[0], args.cache)
    tracks = {}
    for d in args.tracks:
        t = read_track(d)
        if t.vertices.shape != V.shape:
            raise SystemExit(f"{d}: {t.vertices.shape} vertices, the truth has {V.shape}")
        tracks[f"{t.meta['method']} ({d.name})"] = t.vertices
    rows = []
    for name, pieces in rigid_parts(template).items():
        pieces = [m for m in pieces if m.sum() >= 3]
        if not pieces:
            continue
        m = np.any(pieces, axis=0)
        kabsch, along = np.empty_like(V), np.empty_like(V)
        for p in pieces:
            kabsch[:, p] = rigid_fit(V[0, p], V[:, p])
            along[:, p] = tangent_fit(V[0, p], V[:, p], N[:, p])
        k = int(m.sum())
        rows.append(
            row(
                f"{name}: the truth's own (nearest)",
                k,
                kabsch[:, m] - V[:, m],
                N[:, m],
                args.settle,
            )
        )
        rows.append(
            row(f"{name}: the truth's own (along)", k, along[:, m] - V[:, m], N[:, m], args.settle)
        )
        for label, X in tracks.items():
            rows.append(row(f"{name}: {label}", k, X[:, m] - V[:, m], N[:, m], args.settle))
    print(
        f"\nRigid parts: each part's true vertices against their best rigid motion from "
        f"frame 0, the nearest (least squares) and the nearest along the surface (the "
        f"truth's own non-rigid motion), and each track's error on the same vertices; "
        f"per-vertex mean mm over the first and last fifths of {len(V)} frames\n"
    )
    print(table(heads, rows))
    part = rig_parts(template)
    O = np.empty_like(V)
    for j in np.unique(part):
        m = part == j
        O[:, m] = rigid_fit(V[0, m], V[:, m])
    n = len(part)
    rows = [row("piecewise-rigid oracle", n, O - V, N, args.settle)]
    if args.lbs:
        if args.cache is not None and "L" in np.load(args.cache):
            L = np.load(args.cache)["L"]
        else:
            L = lbs_oracle(template, V)
            if args.cache is not None:
                np.savez(args.cache, V=V, N=N, L=L)
        rows.append(row("skinning oracle", n, L - V, N, args.settle))
        if args.cache is not None and "LR" in np.load(args.cache):
            LR = np.load(args.cache)["LR"]
        else:
            LR = refined(template, L, V, N)
            if args.cache is not None:
                np.savez(args.cache, V=V, N=N, L=L, LR=LR)
        rows.append(row("skinning oracle, refined", n, LR - V, N, args.settle))
    rows += [row(label, n, X - V, N, args.settle) for label, X in tracks.items()]
    if args.lbs:
        rows += [
            row(f"{label} against the skinning oracle", n, X - L, N, args.settle)
            for label, X in tracks.items()
        ]
    print(
        f"\nWhole body: the piecewise-rigid oracle ({len(np.unique(part))} rig parts), the "
        "skinning oracle and each track, per-vertex mean mm\n"
    )
    print(table(heads, rows))


if __name__ == "__main__":
    cli()
