"""Residuals of the cage tracker's terms (the terms: :mod:`~meshmocap.trackers.cage.terms`):
where the energy looks (the sampled template vertices, the ones the cage cannot place), the
hull and silhouettes the model leaves unexplained, and the soft joints between quads
(cage-manifold-tracking §5.1).

Eq. (4) sums the distance field of the target over the model's vertices. The tracker
(:mod:`meshmocap.trackers.cage.tracker`) evaluates it on a sample of the template and adds a
second, opposite term; each choice was measured on synthetic ``humaneva4`` captures of CMU
05_01 (a walk by another subject than the manifold's):

* **Sample by area** (:func:`surface_sample`): vertices drawn with probability ∝ their
  area, so the sum approximates a surface integral whatever the tessellation. The bundled
  ``neutral_5k`` spends a quarter of its vertices on the head, a small part of its area.
* **Leave out what the cage cannot place** (:func:`placement_errors`): a template vertex
  follows the cage through Green coordinates, which reproduce skinning only where the
  skinned part moves with the quads around it. The head sits in the cage's neck–head tube
  and the fingers in the hand's, so when a retargeted CMU pose turns the neck and head
  (and the fingers) the true quads put them centimetres from their skinned places. With a
  uniform vertex sample those vertices held most of the energy at the true pose, and the
  fit traded the body's pose for them (every frame's fit had a lower energy than the
  truth). Vertices whose Green-coordinate position misses their skinned one by more than
  ``max_model_error`` in the first frame's known pose get no data term (the figures:
  ``docs/guide/cage.rst``).
* **Coverage** (:class:`HullCoverage`): Eq. (4) only asks the model to lie on the hull;
  nothing asks the hull to be explained. A swinging foot that falls behind lands on the
  stance foot's hull at no cost and stays there (on 05_01 a foot was lost for 40 frames
  at 0.6 m); the term ``½ λc mean_m max(0, d_m − margin)²`` over hull surface samples
  ``h_m``, ``d_m`` their distance to the nearest model point, makes the abandoned hull
  cost.

Frames and units: world frame (Z up), metres.

References
----------
- E. Duveau, S. Courtemanche, L. Reveret, E. Boyer, *Cage-based motion recovery
  using manifold learning*, International Conference on 3D Imaging, Modeling,
  Processing, Visualization and Transmission (3DIMPVT), 2012.
"""

from __future__ import annotations

import numpy as np
from pykdtree.kdtree import KDTree

from meshmocap._tolerances import NEAR_DEPTH, RELATIVE_DEGENERATE
from meshmocap.errors import InputError
from meshmocap.geometry.rotations import skew
from meshmocap.trackers.cage.kernels import contour_pixels, silhouette_residuals

#: Pixels between views in :class:`SilhouetteCoverage`'s k-d tree (no image is this wide).
_VIEW_GAP = 1e12

__all__ = [
    "Articulation",
    "HullCoverage",
    "SilhouetteCoverage",
    "placement_errors",
    "surface_sample",
]


def surface_sample(V: np.ndarray, F: np.ndarray, n: int, *, seed: int) -> np.ndarray:
    """``min(n, V)`` vertex indices (sorted) drawn without replacement with probability ∝
    vertex area (a third of the adjacent triangles' areas).

    Parameters
    ----------
    V : (N, 3) float64
        Vertices, metres.
    F : (M, 3) int
        Triangles.
    n : int
        Sample size.
    seed : int
        Seeds the draw.

    Returns
    -------
    (min(n, N),) int64
    """
    V, F = np.asarray(V, dtype=np.float64), np.asarray(F)
    if n < 1:
        raise InputError(f"surface_sample: n must be ≥ 1, found {n}")
    A = 0.5 * np.linalg.norm(np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]]), axis=1)
    area = np.bincount(F.ravel(), np.repeat(A, 3), minlength=len(V)) / 3.0
    p = area + RELATIVE_DEGENERATE * area.max()  # isolated vertices: possible, last
    pick = np.random.default_rng(seed).choice(len(V), min(n, len(V)), replace=False, p=p / p.sum())
    return np.sort(pick).astype(np.int64)


def placement_errors(model: np.ndarray, skinned: np.ndarray) -> np.ndarray:
    """Distances (n,) between the template points the cage places (Green coordinates of
    a pose's quads) and where skinning places them in that pose, metres."""
    return np.linalg.norm(np.asarray(model) - np.asarray(skinned), axis=-1)


class HullCoverage:
    """Hull-to-model term: every hull surface sample wants a model point within ``margin``.

    ``E_c = ½ Σ_m ρ_m²`` with ``ρ_m = max(0, d_m − margin)`` and ``d_m = min_i |h_m − P_i|``
    (the tracker scales it by ``λc / m``). ``margin`` absorbs the spacing of the model's
    sample points and the thin phantom layer of a visual hull.

    Parameters
    ----------
    points : (m, 3) float64
        Hull surface samples ``h_m``, metres, world frame.
    margin : float
        Metres, ≥ 0.
    """

    def __init__(self, points: np.ndarray, margin: float) -> None:
        H = np.ascontiguousarray(points, dtype=np.float64)
        if H.ndim != 2 or H.shape[1] != 3 or len(H) == 0:
            raise InputError(f"HullCoverage: points must have shape (m, 3), m ≥ 1, found {H.shape}")
        if not margin >= 0:
            raise InputError(f"HullCoverage: margin must be ≥ 0 metres, found {margin!r}")
        self.points, self.margin = H, float(margin)

    def __len__(self) -> int:
        return len(self.points)

    def residuals(self, P: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Each model point's share of the term, as one Gauss–Newton residual.

        Parameters
        ----------
        P : (n, 3) float64
            Model points, metres.

        Returns
        -------
        r : (n,) float64
            ``r_i = sqrt(Σ_{m → i} ρ_m²)`` over the samples whose nearest model point is
            ``i`` (0 for the others), so ``½ Σ_i r_i² = E_c``.
        a : (n, 3) float64
            Unit-free directions with ``r_i a_i = ∂E_c/∂P_i = Σ_{m → i} ρ_m (P_i − h_m) / d_m``
            (exact away from ties of the nearest point); Gauss–Newton then approximates
            ``Σ_m ∇ρ_m ∇ρ_mᵀ`` by the rank-one ``a_i a_iᵀ`` per point.
        """
        P = np.ascontiguousarray(P, dtype=np.float64)
        H = self.points
        d, i = KDTree(P).query(H, k=1)
        on = d > self.margin  # ρ_m > 0
        n = len(P)
        if not on.any():
            return np.zeros(n), np.zeros((n, 3))
        i, d = i[on].astype(np.intp), d[on]
        rho = d - self.margin
        u = (P[i] - H[on]) * (rho / d)[:, None]  # ρ_m ∂d_m/∂P_i
        r = np.sqrt(np.bincount(i, rho * rho, minlength=n))
        # the 3 coordinates in one bincount (bins 3 i + k): a third of the calls
        g = np.bincount((3 * i[:, None] + np.arange(3)).ravel(), u.ravel(), minlength=3 * n)
        g = g.reshape(n, 3)
        # r_i = 0 only where no sample maps to i, and g_i = 0 there: 0/∞ = 0 (a third of
        # the cost of np.divide with where=)
        a = g / np.where(r > 0, r, np.inf)[:, None]
        return r, a


class Articulation:
    """Soft joints between consecutive quads: the local adjustment's structure prior.

    Every quad ``q > 0`` follows a rig joint ``j_q`` rigidly (§3). Its parent ``p`` is the
    quad of the nearest ancestor joint that has one, or an earlier quad of the same joint
    (then the pair is rigid: the wrist and hand quads both follow the hand). At rest the
    joint ``j_q`` sits at fixed points ``l_p``, ``l_q`` of both quads' frames; whenever the
    skeleton bends only at joints with quads, both quads map it to the same place. The
    residuals are that gap, ``e_q = (R_p l_p + c_p) − (R_q l_q + c_q)`` (3 per quad,
    metres), and on rigid pairs also ``R_q [e1 e2] − R_p B_q [e1 e2]`` (6, unit vectors;
    ``B_q = R_p⁰ᵀ R_q⁰``). A joint without a quad between the two (the chest's Spine1
    before the neck and the shoulders, the clavicles, Neck1) opens the gap: 1–2.5 cm in
    retargeted CMU poses, more than the whole data term would allow the true pose.
    :meth:`calibrate` weighs each pair by how well poses hold it,
    ``σ / sqrt(σ² + g²)`` with ``g`` its RMS gap over them (the manifold's training poses).

    Configurations are pelvis-relative (:func:`~meshmocap.trackers.cage.oqr.configuration_vector`):
    the pelvis quad is the identity at the origin.

    Parameters
    ----------
    centres : (21, 3) float64
        Rest quad centres, metres.
    rotations : (21, 3, 3) float64
        Rest quad frames.
    joint_indices : (21,) int
        Rig joint of each quad.
    joint_positions : (J, 3) float64
        Rest joint positions, metres.
    parents : (J,) int
        Skeleton parents (−1 at the root).
    """

    def __init__(self, centres, rotations, joint_indices, joint_positions, parents) -> None:
        jq = [int(j) for j in joint_indices]
        parent = np.zeros(len(jq), dtype=np.int64)
        for q in range(1, len(jq)):
            same = [p for p in range(q) if jq[p] == jq[q]]
            a = jq[q]
            while not same:
                a = int(parents[a])
                if a < 0:
                    raise InputError(f"Articulation: quad {q} has no ancestor with a quad")
                same = [p for p in range(len(jq)) if jq[p] == a]
            parent[q] = same[0]
        q, p = np.arange(1, len(jq)), parent[1:]
        X = np.asarray(joint_positions)[np.array(jq)[q]]
        R0, c0 = np.asarray(rotations), np.asarray(centres)
        self.child, self.parent = q, p
        self.l_child = np.einsum("kji,kj->ki", R0[q], X - c0[q])
        self.l_parent = np.einsum("kji,kj->ki", R0[p], X - c0[p])
        self.rigid = np.array([jq[a] == jq[b] for a, b in zip(q, p, strict=True)])
        self.B = np.swapaxes(R0[p], 1, 2) @ R0[q]  # rest frame of the child in the parent's
        self.weights = np.ones(len(q))
        self._layout(len(jq))

    def calibrate(self, c: np.ndarray, R: np.ndarray, sigma: float) -> np.ndarray:
        """Weigh the pairs by the gaps of poses ``c`` (N, 21, 3), ``R`` (N, 21, 3, 3)
        (pelvis-relative, like :meth:`residuals`'): ``σ / sqrt(σ² + g²)``,
        ``g`` the RMS over the poses of a pair's joint gap, ``σ`` (metres) the gap taken
        for exact. Returns the RMS gaps (k,), metres."""
        self.weights = np.ones(len(self.child))
        gaps = np.stack(
            [self.residuals(a, b)[: 3 * len(self.child)] for a, b in zip(c, R, strict=True)]
        )
        g = np.sqrt(np.mean(gaps.reshape(len(c), -1, 3) ** 2, axis=(0, 2)) * 3)
        self.weights = sigma / np.sqrt(sigma**2 + g**2)
        return g

    def residuals(self, c: np.ndarray, R: np.ndarray, *, jacobian: bool = False):
        """Weighted residuals (k,) and, with ``jacobian``, their Jacobian (k, 6 · 20) along
        each quad's ``(dc, ω)`` (``c ← c + dc``, ``R ← exp(ω) R``, pelvis frame; quads
        1…20 in order).

        Parameters
        ----------
        c : (21, 3) float64
            Pelvis-relative quad centres (the pelvis's: 0), metres.
        R : (21, 3, 3) float64
            Pelvis-relative quad frames (the pelvis's: identity).
        """
        q, p, k = self.child, self.parent, len(self.child)
        a = np.einsum("kij,kj->ki", R[p], self.l_parent)
        b = np.einsum("kij,kj->ki", R[q], self.l_child)
        r = np.flatnonzero(self.rigid)
        u = R[q[r]][:, :, :2]  # rigid pairs: the child's u and v where the parent carries them
        v = R[p[r]] @ self.B[r][:, :, :2]
        e = np.concatenate([((a + c[p]) - (b + c[q])).ravel(), (u - v).transpose(0, 2, 1).ravel()])
        w = np.concatenate([np.repeat(self.weights, 3), np.repeat(self.weights[r], 6)])
        if not jacobian:
            return w * e
        # d(R l) = −[R l]× ω; the pelvis quad (index 0) does not move in its own frame: its
        # columns are left out (the 3 × 3 blocks written straight into the rows × 6 · 20
        # columns, at the flat places of :meth:`_layout`)
        on, ron = self.parent > 0, self.parent[r] > 0
        sk = [skew(x.transpose(0, 2, 1).reshape(-1, 3)).reshape(len(r), 2, 3, 3) for x in (u, v)]
        vals = [self._eye[0], skew(b), self._eye[1], -skew(a)[on], -sk[0], sk[1][ron]]
        J = np.zeros((3 * k + 6 * len(r), 6 * (len(c) - 1)))
        J.ravel()[self._flat] = np.concatenate([x.ravel() for x in vals])
        return w * e, w[:, None] * J

    def _layout(self, n_quads: int) -> None:
        """The flat places in the Jacobian (rows × 6 (n_quads − 1)) of its 3 × 3 blocks, in
        :meth:`residuals`' order (each block row-major): the children's ``dc`` (−I) and
        ``ω`` (``[b]×``), the parents' (I, −[a]×; not the pelvis's), then the rigid pairs'
        child ``ω`` and parent ``ω``; and the constant blocks (−I, I)."""
        k, q, p, r = len(self.child), self.child, self.parent, np.flatnonzero(self.rigid)
        on, ron = p > 0, p[r] > 0
        n = 6 * (n_quads - 1)
        rows = np.arange(3 * k).reshape(k, 3, 1)
        rigid = 3 * k + np.arange(6 * len(r)).reshape(len(r), 2, 3, 1)

        def at(rows, quads, first):  # rows (m, ..., 3, 1) of blocks at quads' columns
            cols = 6 * (quads - 1) + first
            return rows * n + cols.reshape(-1, *[1] * (rows.ndim - 1)) + np.arange(3)

        places = [
            at(rows, q, 0),
            at(rows, q, 3),
            at(rows[on], p[on], 0),
            at(rows[on], p[on], 3),
            at(rigid, q[r], 3),
            at(rigid[ron], p[r][ron], 3),
        ]
        self._flat = np.concatenate([x.ravel() for x in places])
        self._eye = (
            np.broadcast_to(-np.eye(3), (k, 3, 3)),
            np.broadcast_to(np.eye(3), (on.sum(), 3, 3)),
        )


class SilhouetteCoverage:
    """Silhouette-to-model term: every observed silhouette contour pixel wants a model point
    projecting within ``margin`` pixels (the image counterpart of :class:`HullCoverage`).

    A visual hull from few cameras holds phantom volume that no body explains, so asking the
    model to reach the hull's surface everywhere (:class:`HullCoverage`) drags it into the
    phantoms (from the true pose, the local adjustment moves the joints several times
    farther with it than without: ``docs/guide/cage.rst``). The silhouettes hold no
    phantom: each
    contour pixel is seen on the body's occluding contour. ``ρ_m = max(0, d_m − margin)``
    with ``d_m`` the image distance from contour sample ``q_m`` of camera ``c`` to the
    nearest projected model point ``π_c(P_i)``; residuals are ``ρ_m`` scaled to metres at
    the point's depth (``× z_i / f_c``). Pinhole projection: lens distortion is ignored
    (the studio's rigs have none).

    Parameters
    ----------
    cameras : list of Camera
        The capture's cameras (``K``, ``R``, ``t``).
    masks : list of (height, width) bool
        Their silhouettes, in the same order; an empty mask contributes nothing.
    n_per_camera : int
        Contour samples drawn per camera (all when fewer).
    margin : float
        Pixels.
    seed : int or sequence of int
        Seeds the draw.
    cap : float
        Pixels: contour samples farther than this from every projected model point are
        outliers (spurious blobs of a noisy silhouette) and cost nothing (0: no cap).
    min_component : float
        Connected pieces of a mask smaller than this fraction of its largest are dropped
        first (the usual cleaning of small spurious blobs; 0: none).
    """

    def __init__(
        self,
        cameras,
        masks,
        n_per_camera: int,
        margin: float,
        seed,
        cap: float = 0.0,
        min_component: float = 0.0,
    ) -> None:
        rng = np.random.default_rng(seed)
        qs, Ks, Rs, ts, cam = [], [], [], [], []
        for camera, mask in zip(cameras, masks, strict=True):
            full = np.asarray(mask, dtype=bool)
            rows_on, cols_on = np.flatnonzero(full.any(axis=1)), np.flatnonzero(full.any(axis=0))
            if not len(rows_on):
                continue
            # the mask's bounding box and one empty pixel around it where the image has one:
            # labelling and erosion there equal the whole image's (the same contour pixels,
            # in the same order) at a fraction of the pixels
            r0, c0 = max(rows_on[0] - 1, 0), max(cols_on[0] - 1, 0)
            m = np.array(full[r0 : rows_on[-1] + 2, c0 : cols_on[-1] + 2], order="C")
            # small pieces apart from the body (noise) dropped where min_component > 0, then
            # the contour: ndimage.label's pieces and m & ~binary_erosion(m)'s pixels in
            # np.nonzero's order, in the whole image's rows and columns (compiled)
            rows, cols = contour_pixels(m, float(min_component), r0, c0)
            if len(rows) > n_per_camera:
                pick = rng.choice(len(rows), n_per_camera, replace=False)
                rows, cols = rows[pick], cols[pick]
            # (x, y) = (column, row) in the whole image
            qs.append(np.stack([cols, rows], axis=1).astype(np.float64))
            Ks.append(np.asarray(camera.K, dtype=np.float64))
            Rs.append(np.asarray(camera.R, dtype=np.float64))
            ts.append(np.asarray(camera.t, dtype=np.float64))
            cam.append(np.full(len(rows), len(Ks) - 1))
        self.views = list(zip(qs, Ks, Rs, ts, strict=True))
        self.margin, self.cap = float(margin), float(cap)
        self.n = sum(len(q) for q in qs)
        # all views stacked: samples (m, 2) and their view (m,), per view K, R (C, 3, 3), t (C, 3)
        self._q = np.concatenate(qs) if qs else np.zeros((0, 2))
        self._cam = np.concatenate(cam) if cam else np.zeros(0, dtype=np.intp)
        self._K = np.array(Ks).reshape(-1, 3, 3)
        self._R = np.array(Rs).reshape(-1, 3, 3)
        self._t = np.array(ts).reshape(-1, 3)
        self._ptr = np.concatenate([[0], np.cumsum([len(q) for q in qs])]).astype(np.int64)
        # k-d tree coordinates of a sample: its pixel and its view far apart (_VIEW_GAP)
        self._query = np.concatenate([self._q, _VIEW_GAP * self._cam[:, None]], axis=1)

    def __len__(self) -> int:
        return self.n

    def residuals(self, P: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Each model point's share of the term as one Gauss–Newton residual, as
        :meth:`HullCoverage.residuals`: ``r`` (n,) metres and unit-free directions ``a``
        (n, 3) with ``r_i a_i`` the gradient of ``½ Σ_m ρ_m²`` (ρ in metres) at ``P_i``."""
        P = np.ascontiguousarray(P, dtype=np.float64)
        n = len(P)
        if not self.n:
            return np.zeros(n), np.zeros((n, 3))
        if self.cap > 0:  # a sample looks only within the cap: a grid of cells, compiled
            return silhouette_residuals(
                P, self._R, self._t, self._K, self._q, self._ptr, self.margin, self.cap
            )
        return self.residuals_reference(P)

    def residuals_reference(self, P: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`residuals` as array expressions and a k-d tree (any ``cap``, 0 included;
        the compiled version's reference in the tests)."""
        P = np.ascontiguousarray(P, dtype=np.float64)
        n, C = len(P), len(self._K)
        if not self.n:
            return np.zeros(n), np.zeros((n, 3))
        # every view at once: one k-d tree over the projections (C n points, the view as a
        # third coordinate _VIEW_GAP apart, so a sample only finds its own view's points)
        X = np.matmul(P, self._R.transpose(0, 2, 1)) + self._t[:, None]  # (C, n, 3) cameras
        z = np.maximum(X[:, :, 2], NEAR_DEPTH)
        K = self._K
        f = K[:, 0, 0]
        pts = np.empty((C, n, 3))
        pts[:, :, 0] = f[:, None] * X[:, :, 0] / z + K[:, 0, 2, None]
        pts[:, :, 1] = K[:, 1, 1, None] * X[:, :, 1] / z + K[:, 1, 2, None]
        pts[:, :, 2] = _VIEW_GAP * np.arange(C)[:, None]
        pts = pts.reshape(-1, 3)
        d, k = KDTree(pts).query(self._query, k=1)
        on = d > self.margin
        if self.cap:  # farther: a spurious blob, not the body (truncated, robust)
            on &= d <= self.cap
        if not on.any():
            return np.zeros(n), np.zeros((n, 3))
        k, d, c = k[on].astype(np.intp), d[on], self._cam[on]
        i = k % n  # the model point
        zk, fc = z.reshape(-1)[k], f[c]
        s = zk / fc  # metres per pixel at the point
        rho = (d - self.margin) * s
        e = (pts[k, :2] - self._q[on]) / d[:, None]  # image direction away from the sample
        # dρ/dX_cam = s (f / z) [e_x, e_y, −e·(x, y) / z] + (d − margin) / f [0, 0, 1]
        # (the scale s = z / f moves with depth too); s f / z = 1: unit-free
        xy = X.reshape(-1, 3)[k, :2] / zk[:, None]
        dz = (d - self.margin) / fc - np.sum(e * xy, axis=1)
        dX = np.concatenate([e, dz[:, None]], axis=1)
        u = np.einsum("ma,mab->mb", dX, self._R[c]) * rho[:, None]  # ρ ∂ρ/∂P, world frame
        rr = np.bincount(i, rho * rho, minlength=n)
        g = np.bincount(
            (3 * i[:, None] + np.arange(3)).ravel(), u.ravel(), minlength=3 * n
        ).reshape(n, 3)
        r = np.sqrt(rr)
        return r, g / np.where(r > 0, r, np.inf)[:, None]
