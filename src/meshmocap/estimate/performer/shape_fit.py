"""Body shape and pose fitted jointly to the silhouettes of several frames.

The body is a point of the bundled shape space (:mod:`meshmocap.body.shape_space`,
standardised coefficients ``z``) posed in each frame ``f`` by its own pose (root
translation, one rotation per free joint; the parametrisation of
:mod:`meshmocap.body.articulated`). A visual hull is a superset of the body (phantom
volumes), so the fit does not pull the model onto the hull; it asks, in every camera ``c``,

* **inside** — every model point projects inside the silhouette:
  ``r = max(0, d_c(π_c(v)))`` where ``d_c`` is the silhouette's signed distance
  (pixels, > 0 outside); the one-sided hull term, at pixel rather than voxel resolution;
* **outline** — every point of the model's own outline (a vertex on the boundary of the
  model's rendered silhouette, seen edge-on) lies on the silhouette's contour:
  ``r = d_c(π_c(v))``, both signs;
* **coverage** — every contour pixel ``q`` of the silhouette is explained by the nearest
  point of the model's outline: ``r = n_q · (π_c(v) − q)`` with ``n_q`` the contour's
  outward normal; this is what keeps the body from shrinking inside the silhouettes;

each residual converted from pixels to metres at the point's depth (``r · z / f``), with
Huber-like weights beyond 2 cm, plus a Gaussian prior on the shape (``λ_z ‖z‖²``) and a
weak pull of every joint towards the rest pose. Damped Gauss–Newton on all frames' poses
and the shared shape together (the damping and step limit of
:func:`~meshmocap.body.articulated.articulated_step`); the outlines and the matches are
recomputed every iteration.

A frame whose pose settled in a wrong minimum (an arm fitted where the other one is, a
leg crossed) still explains its silhouettes partly, by stretching the shared body: a long
forearm, wide shoulders. Halfway through the iterations each frame's objective (its own
terms' Huber-weighted means, as :func:`fit_pose` reports) is compared with the best
frame's; a frame more than ``screen_ratio`` times the best stops informing the shape (its
pose is still fitted, the body held for it). ``docs/measurements.rst`` has the numbers
(section "The performer's body, its frames screened").

The frames' terms are computed side by side, one process a core (``MESHMOCAP_JOBS``), and
gathered in order: the same fit to the bit.

Derivatives (exact for the model; the projection's derivative ignores lens distortion):
a skinned point ``v_i = Σ_k w_ik (G_k (X_i − P_k) + p_k)`` moves with the shape through its
rest position ``X_i(z)`` and the rest joints ``P_k(z)`` (both linear in ``z``), and the
posed joints ``p_k = p_parent + G_parent (P_k − P_parent)``, ``p_root`` = the root
parameter, so

    ∂v_i/∂z = Σ_k w_ik [G_k (∂X_i − ∂P_k) + ∂p_k],   ∂p_k = ∂p_parent + G_parent (∂P_k − ∂P_parent)

(:func:`shape_jacobian`, checked against finite differences in the tests).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from pykdtree.kdtree import KDTree
from scipy import ndimage

from meshmocap._parallel import Workers
from meshmocap._progress import phase
from meshmocap._tolerances import DIVISOR_FLOOR, NEAR_DEPTH, NORM_FLOOR
from meshmocap.body.articulated import (
    DAMPING,
    FIXED_JOINTS,
    add_pose_pull,
    apply_increment,
    articulated_model,
    damped_solve,
    limit_step,
    model_subset,
    pose_points,
    rotation_error,
)
from meshmocap.body.shape_space import BodyShapeSpace
from meshmocap.body.skeleton import forward_kinematics
from meshmocap.body.template import Template
from meshmocap.errors import FitError, InputError
from meshmocap.geometry.camera import Camera
from meshmocap.geometry.rotations import cross
from meshmocap.geometry.silhouette import fill_triangles

__all__ = [
    "ShapeFit",
    "SilhouettePose",
    "SilhouetteView",
    "fit_pose",
    "fit_shape",
    "outlines",
    "shape_jacobian",
    "silhouette_view",
]

#: Residuals beyond this (metres) get Huber weights.
HUBER = 0.02
#: Largest change of any shape coefficient in one step (the joints' rotations are limited by
#: :func:`~meshmocap.body.articulated.limit_step`).
MAX_STEP_Z = 0.5
#: Gauss–Newton iterations of :func:`fit_shape` per progress line.
PROGRESS_EVERY = 10
#: A frame whose silhouette objective exceeds this many times the best frame's, halfway
#: through :func:`fit_shape`, stops informing the shape (module docstring).
SCREEN_RATIO = 2.0


@dataclass(frozen=True, eq=False)
class SilhouetteView:
    """One camera's silhouette of one frame, ready for the fit.

    Attributes
    ----------
    camera : Camera
    sdt : (H, W) float64, signed distance to the silhouette's boundary, pixels (> 0 outside)
    grad : (2, H, W) float64, its derivatives along u (columns) and v (rows)
    contour : (c, 2) float64, boundary pixels (u, v) of the silhouette (subsampled)
    normal : (c, 2) float64, their outward unit normals
    """

    camera: Camera
    sdt: np.ndarray
    grad: np.ndarray
    contour: np.ndarray
    normal: np.ndarray


def silhouette_view(
    mask: np.ndarray, camera: Camera, *, max_contour: int = 400, seed: int = 0
) -> SilhouetteView:
    """Precompute a :class:`SilhouetteView` of a (H, W) bool ``mask`` seen by ``camera``."""
    mask = np.asarray(mask, dtype=bool)
    # zero level on the pixels' edges: ±0.5 on the pixels either side of the boundary
    sdt = np.where(
        mask,
        0.5 - ndimage.distance_transform_edt(mask),
        ndimage.distance_transform_edt(~mask) - 0.5,
    )
    sdt = ndimage.gaussian_filter(sdt.astype(np.float64), 0.7)
    gv, gu = np.gradient(sdt)
    edge = mask & ~ndimage.binary_erosion(mask)
    rows, cols = np.nonzero(edge)
    if len(rows) > max_contour:
        pick = np.sort(np.random.default_rng(seed).choice(len(rows), max_contour, replace=False))
        rows, cols = rows[pick], cols[pick]
    n = np.stack([gu[rows, cols], gv[rows, cols]], axis=1)
    n /= np.maximum(np.linalg.norm(n, axis=1, keepdims=True), NORM_FLOOR)
    q = np.stack([cols, rows], 1) + 0.5 * n  # the pixel's outer edge: where sdt = 0
    return SilhouetteView(camera, sdt, np.stack([gu, gv]), q, n)


def _bilinear(img: np.ndarray, uv: np.ndarray) -> np.ndarray:
    """Bilinear samples of ``img`` (..., H, W) at pixel positions ``uv`` (p, 2), clamped."""
    H, W = img.shape[-2:]
    u = np.clip(uv[:, 0], 0, W - 1.001)
    v = np.clip(uv[:, 1], 0, H - 1.001)
    u0, v0 = u.astype(np.int64), v.astype(np.int64)
    a, b = u - u0, v - v0
    return (
        img[..., v0, u0] * (1 - a) * (1 - b)
        + img[..., v0, u0 + 1] * a * (1 - b)
        + img[..., v0 + 1, u0] * (1 - a) * b
        + img[..., v0 + 1, u0 + 1] * a * b
    )


def _projection(camera: Camera, X: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Pixels (p, 2), their derivatives ``∂uv/∂X`` (p, 2, 3) (pinhole, no distortion) and
    metres per pixel at each point's depth (p,)."""
    uv, _ = camera.project(X)
    Xc = X @ camera.R.T + camera.t
    z = np.maximum(Xc[:, 2], NEAR_DEPTH)
    K, R = camera.K, camera.R
    du = (K[0, 0] / z)[:, None] * (R[0] - (Xc[:, 0] / z)[:, None] * R[2])
    dv = (K[1, 1] / z)[:, None] * (R[1] - (Xc[:, 1] / z)[:, None] * R[2])
    return uv, np.stack([du, dv], axis=1), z / (0.5 * (K[0, 0] + K[1, 1]))


def shape_jacobian(
    space: BodyShapeSpace,
    template: Template,
    R: np.ndarray,
    root: np.ndarray,
    *,
    rows: np.ndarray | None = None,
    derivatives=None,
) -> np.ndarray:
    """``∂v/∂z`` (n, 3, K) float64 of every skinned vertex of ``template`` (the space's body
    at the current ``z``) posed by local rotations ``R`` (J, 3, 3) and ``root`` (3,)
    (module docstring); with ``rows`` (r,) int64, of those vertices only (r, 3, K), the
    same values. ``derivatives``: ``space.derivatives()`` where the caller has it."""
    sk = template.skeleton
    G, _ = forward_kinematics(sk, R, root)
    d = space.derivatives() if derivatives is None else derivatives  # leading axis K
    dP = np.moveaxis(d.heads, 0, -1)  # (J, 3, K)
    dp = np.zeros_like(dP)
    for k in range(1, sk.n_joints):  # parents precede children
        q = sk.parents[k]
        dp[k] = dp[q] + G[q] @ (dP[k] - dP[q])
    W = template.weights if rows is None else template.weights[rows]
    n, K = W.shape[0], space.n_components
    Gb = (W @ G.reshape(-1, 9)).reshape(n, 3, 3)
    dX = np.moveaxis(d.V if rows is None else d.V[:, rows], 0, -1)  # (n, 3, K)
    out = np.einsum("nab,nbk->nak", Gb, dX)
    out -= (W @ np.einsum("jab,jbk->jak", G, dP).reshape(-1, 3 * K)).reshape(n, 3, K)
    out += (W @ dp.reshape(-1, 3 * K)).reshape(n, 3, K)
    return out


@dataclass(frozen=True, eq=False)
class ShapeFit:
    """Shape and poses fitted by :func:`fit_shape`.

    Attributes
    ----------
    z : (K,) float64, standardised shape coefficients
    R : (f, J, 3, 3) float64, local rotations per frame; ``root`` (f, 3) float64, metres
    rms : float, RMS of the last iteration's silhouette residuals, metres
    n_iter : int
    shape_frames : (f,) bool, the frames that inform the shape (module docstring)
    frame_cost : (f,) float64, each frame's silhouette objective at the screening (m²;
        the last iteration's without screening)
    """

    z: np.ndarray
    R: np.ndarray
    root: np.ndarray
    rms: float
    n_iter: int
    shape_frames: np.ndarray
    frame_cost: np.ndarray


class FrameTerms:
    """Residual rows of one frame (:func:`frame_terms`), accumulated into the normal
    equations.

    Attributes
    ----------
    rows : list of (term name, residuals (p,) metres, pose Jacobian (p, n_pose), shape
        Jacobian (p, K))
    population : dict of str → int, the candidates each term is a mean over
    """

    def __init__(self, n_pose: int, K: int):
        self.rows: list[tuple[str, np.ndarray, np.ndarray, np.ndarray]] = []
        self.population: dict[str, int] = {}
        self.n_pose, self.K = n_pose, K

    def add(self, term, r, w3, a, S, population):
        """Residuals ``r`` (p,) metres with ``∂r/∂v`` = ``w3`` (p, 3), lever arms ``a``
        (p, J, 3) and shape Jacobians ``S`` (p, 3, K) of their points, out of
        ``population`` candidates (the term is a mean over those)."""
        self.population[term] = self.population.get(term, 0) + population
        if len(r) == 0:
            return
        Jp = np.concatenate([w3, cross(a, w3[:, None, :]).reshape(len(r), -1)], axis=1)
        Jz = np.einsum("pc,pck->pk", w3, S)
        self.rows.append((term, r, Jp, Jz))


def _outline(v, n, cam, F, *, ring: float = 2.0, rim_cos: float = 0.35) -> np.ndarray:
    """Indices of the vertices ``v`` (n, 3) on the outline of the model seen by ``cam``:
    for each boundary pixel of the model's rendered
    silhouette, the nearest vertex seen edge-on (``|n · view| < rim_cos``) projected within
    ``ring`` pixels of it.

    The silhouette is rendered and its boundary found in the box of the projected vertices
    (2 pixels of margin, within the image) only: the same pixels as in the whole image
    (pixel centres sit at integers, so the box's whole-pixel shift is exact)."""
    uv, depth = cam.project(v)
    ok = depth > 0
    H, W = cam.shape
    if ok.any():
        lo = np.floor(uv[ok].min(axis=0)).astype(np.int64) - 2
        hi = np.ceil(uv[ok].max(axis=0)).astype(np.int64) + 3
        c0, r0 = (max(0, int(x)) for x in lo)
        c1, r1 = min(W, int(hi[0])), min(H, int(hi[1]))
    else:
        c0 = r0 = c1 = r1 = 0
    if c1 <= c0 or r1 <= r0:
        return np.zeros(0, dtype=np.int64)
    mask = fill_triangles(
        uv - np.array([c0, r0], dtype=np.float64),
        F,
        (r1 - r0, c1 - c0),
        valid=ok,
        orientation="positive",  # a closed body (silhouette(..., assume_closed=True))
    )
    view = v - cam.centre
    view /= np.linalg.norm(view, axis=1, keepdims=True)
    cand = np.flatnonzero((np.abs(np.sum(view * n, axis=1)) < rim_cos) & ok)
    rows, cols = np.nonzero(mask & ~ndimage.binary_erosion(mask))
    if len(cand) == 0 or len(rows) == 0:
        return np.zeros(0, dtype=np.int64)
    dist, k = KDTree(np.ascontiguousarray(uv[cand])).query(
        np.stack([cols + c0, rows + r0], 1).astype(np.float64), k=1, distance_upper_bound=ring
    )
    return np.unique(cand[k[np.isfinite(dist) & (k < len(cand))].astype(np.int64)])


def outlines(views, v, n, F) -> list[np.ndarray]:
    """The outline vertices of the model ``v``, ``n`` (n, 3) with faces ``F`` in each of
    ``views`` (list of SilhouetteView): a list of (o,) int64 vertex indices per view."""
    return [_outline(v, n, view.camera, F) for view in views]


def frame_terms(views, v, n, a, S, F, sample, max_match, *, lines=None, rows=None):
    """The three silhouette terms of one frame (module docstring), as a :class:`FrameTerms`.

    ``a`` and ``S``: lever arms (r, J, 3) and shape Jacobians (r, 3, K) of the vertices
    ``rows`` (sorted, holding ``sample`` and every outline vertex; default all vertices);
    ``lines``: :func:`outlines` where the caller has them."""
    t = FrameTerms(a.shape[1] * 3 + 3, S.shape[2])
    lines = outlines(views, v, n, F) if lines is None else lines

    def at(i):  # rows of a and S of vertices i
        return i if rows is None else np.searchsorted(rows, i)

    for view, ol in zip(views, lines, strict=True):
        cam = view.camera
        # inside: sampled points outside the silhouette
        uv, D, s = _projection(cam, v[sample])
        d = _bilinear(view.sdt, uv)
        out = d > 0
        if out.any():
            g = _bilinear(view.grad, uv[out]).T  # (p, 2)
            w3 = s[out, None] * np.einsum("pc,pcx->px", g, D[out])
            i = at(sample[out])
            t.add("inside", s[out] * d[out], w3, a[i], S[i], len(sample))
        # outline on the contour, both signs
        if len(ol) == 0:
            continue
        uv, D, s = _projection(cam, v[ol])
        d = _bilinear(view.sdt, uv)
        g = _bilinear(view.grad, uv).T
        i = at(ol)
        t.add("outline", s * d, s[:, None] * np.einsum("pc,pcx->px", g, D), a[i], S[i], len(ol))
        # coverage: each contour pixel explained by the nearest outline point
        tree = KDTree(np.ascontiguousarray(uv))
        dist, k = tree.query(view.contour, k=1, distance_upper_bound=max_match)
        ok = np.isfinite(dist) & (k < len(ol))
        if ok.any():
            k, q, nq = k[ok].astype(np.int64), view.contour[ok], view.normal[ok]
            r = np.sum(nq * (uv[k] - q), axis=1) * s[k]
            w3 = s[k, None] * np.einsum("pc,pcx->px", nq, D[k])
            t.add("coverage", r, w3, a[i[k]], S[i[k]], len(view.contour))
    return t


def fit_shape(
    space: BodyShapeSpace,
    views: list[list[SilhouetteView]],
    R0: np.ndarray,
    root0: np.ndarray,
    *,
    z0: np.ndarray | None = None,
    iterations: int = 30,
    lambda_shape: float = 1e-7,
    lambda_pose: float = 1e-7,
    n_points: int = 1500,
    max_match: float = 25.0,
    fixed_joints: tuple[str, ...] = FIXED_JOINTS,
    screen_ratio: float | None = SCREEN_RATIO,
    seed: int = 0,
) -> ShapeFit:
    """Fit one body shape and a pose per frame to the frames' silhouettes (module docstring).

    Parameters
    ----------
    space : BodyShapeSpace
    views : list (frames) of list (cameras) of SilhouetteView
    R0 : (f, J, 3, 3) float64, starting local rotations per frame; ``root0`` (f, 3), metres
    z0 : (K,) float64, starting shape (default: the mean body)
    iterations : int, Gauss–Newton iterations
    lambda_shape : float, weight (m²) of ``‖z‖²``
    lambda_pose : float, weight (m²/rad²) of each joint's squared rotation from rest
    n_points : int, model points of the inside term (area-weighted sample, fixed)
    max_match : float, pixels: a contour pixel farther from every outline point is left out
    fixed_joints : joints kept at their starting rotation
    screen_ratio : float > 1 or None, halfway through, a frame whose objective exceeds this
        many times the best frame's stops informing the shape (module docstring); None
        keeps every frame
    seed : int, seed of the point sample

    Returns
    -------
    ShapeFit
    """
    if screen_ratio is not None and not (np.isfinite(screen_ratio) and screen_ratio > 1):
        raise InputError(f"fit_shape: screen_ratio must be > 1 or None, found {screen_ratio!r}")
    n_f, K = len(views), space.n_components
    R = np.array(R0, dtype=np.float64)
    root = np.array(root0, dtype=np.float64)
    z = np.zeros(K) if z0 is None else np.array(z0, dtype=np.float64)
    tmpl = space.template(z)
    sample = articulated_model(tmpl, n_points=n_points, seed=seed).sample
    free = [j for j, name in enumerate(space.joint_names) if name not in fixed_joints]
    act_pose = np.r_[0:3, (3 + 3 * np.array(free)[:, None] + np.arange(3)).ravel()]
    rms = np.inf
    use = np.ones(n_f, dtype=bool)
    cost = np.full(n_f, np.nan)
    screen = iterations // 2 if screen_ratio is not None and n_f > 1 else -1

    posed: dict = {}  # the body at the last z this process saw: posed once an iteration

    def terms(f, z, R_f, root_f):  # one frame's rows, in a worker (meshmocap._parallel)
        if posed.get("z") != z.tobytes():
            posed["z"], posed["body"] = z.tobytes(), _posable(space, z)
        return _frame_rows(space, views[f], posed["body"], R_f, root_f, sample, max_match)

    with Workers(terms, n_f) as workers:  # the frames side by side, the same rows
        for first in range(0, iterations, PROGRESS_EVERY):
            last = min(first + PROGRESS_EVERY, iterations)
            with phase(
                f"fitting the shape to the silhouettes ({n_f} frames, iterations {first + 1}–"
                f"{last} of {iterations})"
            ):
                for it in range(first, last):
                    z, rms, c = _shape_step(
                        space,
                        views,
                        R,
                        root,
                        z,
                        sample,
                        act_pose,
                        lambda_shape,
                        lambda_pose,
                        max_match,
                        use,
                        workers,
                    )
                    if it == screen:
                        use = c <= screen_ratio * c.min()
                    if screen < 0 or it <= screen:
                        cost = c
    return ShapeFit(z, R, root, rms, int(iterations), use, cost)


def _posable(space: BodyShapeSpace, z: np.ndarray):
    """The space's body at ``z``, its model of every vertex and the space's derivatives:
    what a frame's rows are computed from (:func:`_frame_rows`)."""
    tmpl = space.template(z)
    return tmpl, articulated_model(tmpl, n_points=tmpl.n_vertices), space.derivatives()


def _frame_rows(space, views, posable, R, root, sample, max_match) -> FrameTerms:
    """One frame's silhouette terms (:func:`frame_terms`) for the body ``posable``
    (:func:`_posable`) in pose ``R``, ``root``: every vertex posed (the outlines), the
    derivatives of those the terms use only."""
    tmpl, model, deriv = posable
    v, n, _ = pose_points(model, R, root, jacobian=False)
    lines = outlines(views, v, n, tmpl.F)
    rows = np.unique(np.concatenate([sample, *lines]))
    _, _, a = pose_points(model_subset(model, rows), R, root)
    S = shape_jacobian(space, tmpl, R, root, rows=rows, derivatives=deriv)
    return frame_terms(views, v, n, a, S, tmpl.F, sample, max_match, lines=lines, rows=rows)


def _shape_step(
    space, views, R, root, z, sample, act_pose, lambda_shape, lambda_pose, max_match, use, workers
):
    """One damped Gauss–Newton step of :func:`fit_shape`: returns the new ``z``, the
    residuals' RMS before the step and each frame's objective (f,) before it (m²); ``R``
    and ``root`` are updated in place. Frames where ``use`` (f,) bool is False do not
    inform the shape. ``workers``: the worker processes computing a frame's rows
    (:func:`_frame_rows`) from ``(f, z, R[f], root[f])``, or one (this process)."""
    n_f, K = len(views), space.n_components
    if workers.jobs > 1:
        frames = workers.map([(f, z, R[f], root[f]) for f in range(n_f)])
        tmpl = space.template(z)
    else:  # the body posed once for every frame
        posable = _posable(space, z)
        tmpl = posable[0]
        frames = [
            _frame_rows(space, views[f], posable, R[f], root[f], sample, max_match)
            for f in range(n_f)
        ]
    J = tmpl.skeleton.n_joints
    n_pose = 3 + 3 * J
    n_par = K + n_f * n_pose
    H = np.zeros((n_par, n_par))
    g = np.zeros(n_par)
    sq, cnt = 0.0, 0
    counts: dict[str, int] = {}
    for t in frames:
        for term, n_term in t.population.items():
            counts[term] = counts.get(term, 0) + n_term
    cost = np.zeros(n_f)
    for f, t in enumerate(frames):
        sl = slice(K + f * n_pose, K + (f + 1) * n_pose)
        for term, r, Jp, Jz in t.rows:
            huber = np.minimum(1.0, HUBER / np.maximum(np.abs(r), DIVISOR_FLOOR))
            cost[f] += float(huber @ (r * r)) / t.population[term]  # as fit_pose's
            w = huber / counts[term]
            H[sl, sl] += Jp.T @ (w[:, None] * Jp)
            g[sl] += Jp.T @ (w * r)
            sq, cnt = sq + float(r @ r), cnt + len(r)
            if not use[f]:  # its pose only, the body held for it
                continue
            B = Jp.T @ (w[:, None] * Jz)
            H[sl, :K] += B
            H[:K, sl] += B.T
            H[:K, :K] += Jz.T @ (w[:, None] * Jz)
            g[:K] += Jz.T @ (w * r)
        # weak pull of every non-root joint towards the rest pose (world-frame error)
        e = rotation_error(tmpl.skeleton, R[f], root[f])[1:]
        add_pose_pull(H, g, e, lambda_pose, start=sl.start + 6)
    H[:K, :K] += lambda_shape * np.eye(K)
    g[:K] += lambda_shape * z
    rms = float(np.sqrt(sq / max(cnt, 1)))
    act = np.concatenate([np.arange(K)] + [K + f * n_pose + act_pose for f in range(n_f)])
    delta = np.zeros(n_par)
    try:
        delta[act] = damped_solve(H[np.ix_(act, act)], g[act], damping=DAMPING)
    except FitError as exc:
        raise FitError(f"fit_shape: {exc}") from None
    z = z + np.clip(delta[:K], -MAX_STEP_Z, MAX_STEP_Z)
    for f in range(n_f):
        d = limit_step(delta[K + f * n_pose : K + (f + 1) * n_pose])
        R[f], root[f] = apply_increment(tmpl.skeleton, R[f], root[f], d)
    return z, rms, cost


@dataclass(frozen=True, eq=False)
class SilhouettePose:
    """A pose fitted to one frame's silhouettes with the body held (:func:`fit_pose`).

    Attributes
    ----------
    R : (J, 3, 3) float64, local rotations; ``root`` (3,) float64, metres
    cost : float, the fit's objective at the returned pose: the Huber-weighted mean squared
        silhouette residual of each term (inside, outline, coverage), summed, m²
    """

    R: np.ndarray
    root: np.ndarray
    cost: float


def fit_pose(
    template: Template,
    views: list[SilhouetteView],
    R0: np.ndarray,
    root0: np.ndarray,
    *,
    iterations: int = 10,
    lambda_pose: float = 1e-7,
    n_points: int = 1500,
    max_match: float = 25.0,
    fixed_joints: tuple[str, ...] = FIXED_JOINTS,
    seed: int = 0,
) -> SilhouettePose:
    """Fit ``template``'s pose to one frame's silhouettes, the body held as it is: the
    terms of :func:`fit_shape` (module docstring) without the shape's unknowns.

    Parameters
    ----------
    template : Template, the body (any rigged template)
    views : list (cameras) of SilhouetteView, the frame's silhouettes
    R0 : (J, 3, 3) float64, starting local rotations; ``root0`` (3,) float64, metres
    iterations : int, Gauss–Newton iterations
    lambda_pose, n_points, max_match, fixed_joints, seed : as :func:`fit_shape`

    Returns
    -------
    SilhouettePose, with the objective at the returned pose (comparable between fits of
    the same frame and body from different starts)
    """
    R = np.array(R0, dtype=np.float64)
    root = np.array(root0, dtype=np.float64)
    model = articulated_model(template, n_points=template.n_vertices)
    sample = articulated_model(template, n_points=n_points, seed=seed).sample
    names = template.skeleton.names
    free = [j for j, name in enumerate(names) if name not in fixed_joints]
    act = np.r_[0:3, (3 + 3 * np.array(free)[:, None] + np.arange(3)).ravel()]
    for _ in range(iterations):
        H, g, _ = _pose_system(template, model, views, R, root, sample, lambda_pose, max_match)
        delta = np.zeros(len(g))
        try:
            delta[act] = damped_solve(H[np.ix_(act, act)], g[act], damping=DAMPING)
        except FitError as exc:
            raise FitError(f"fit_pose: {exc}") from None
        R, root = apply_increment(template.skeleton, R, root, limit_step(delta))
    cost = _pose_system(template, model, views, R, root, sample, lambda_pose, max_match)[2]
    return SilhouettePose(R, root, cost)


def _pose_system(template, model, views, R, root, sample, lambda_pose, max_match):
    """The normal equations ``H`` (n, n), ``g`` (n,) of :func:`fit_pose`'s step at
    ``R``, ``root`` and its objective there (m²)."""
    v, n, _ = pose_points(model, R, root, jacobian=False)
    lines = outlines(views, v, n, template.F)
    rows = np.unique(np.concatenate([sample, *lines]))
    _, _, a = pose_points(model_subset(model, rows), R, root)
    S = np.zeros((len(rows), 3, 0))  # no shape unknowns
    t = frame_terms(views, v, n, a, S, template.F, sample, max_match, lines=lines, rows=rows)
    n_pose = 3 + 3 * template.skeleton.n_joints
    H, g, cost = np.zeros((n_pose, n_pose)), np.zeros(n_pose), 0.0
    for term, r, Jp, _ in t.rows:
        w = np.minimum(1.0, HUBER / np.maximum(np.abs(r), DIVISOR_FLOOR)) / t.population[term]
        H += Jp.T @ (w[:, None] * Jp)
        g += Jp.T @ (w * r)
        cost += float(w @ (r * r))
    e = rotation_error(template.skeleton, R, root)[1:]
    add_pose_pull(H, g, e, lambda_pose, start=6)
    return H, g, cost
