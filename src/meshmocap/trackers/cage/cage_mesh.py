"""The procedural cage of the Oriented Quads Rigging: topology, enclosure, checks.

cage-manifold-tracking §3: *the cage is built procedurally from the vertices defined by
the quads; its topology is computed once by defining relations between quads*. Consecutive
quads of a chain are joined by *tubes* (8 triangles: two per side of the quads), chain
ends are *capped*, and the two torso branchings are closed by fixed *junction* patches
(:func:`oqr_faces`). :class:`QuadRect` is a quad being fitted, which
:mod:`meshmocap.trackers.cage.growth` shrinks until the cage has no self-intersection, then
grows until it encloses the template; :func:`cage_problems` names the checks a cage fails (closed
2-manifold, consistent outward orientation, no self-intersection, enclosure of a point
set).

Conventions: ``V`` (nv, 3) float64 cage vertices, metres, world frame (Z up); ``F`` (nf, 3)
int64 triangles, counter-clockwise seen from outside. A *ring* is the 4 corner indices
``4 q … 4 q + 3`` of quad ``q``, counter-clockwise about the quad normal ``n`` (corners
``(+u, +v), (−u, +v), (−u, −v), (+u, −v)`` in the quad frame ``[u | v | n]``).

References
----------
- E. Duveau, S. Courtemanche, L. Reveret, E. Boyer, *Cage-based motion recovery
  using manifold learning*, International Conference on 3D Imaging, Modeling,
  Processing, Visualization and Transmission (3DIMPVT), 2012.
- A. van Oosterom, J. Strackee, *The solid angle of a plane triangle*, IEEE
  Transactions on Biomedical Engineering 30(2):125–126, 1983.
  https://doi.org/10.1109/TBME.1983.325207
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from meshmocap._tolerances import RELATIVE_DEGENERATE, UNDERFLOW_FLOOR, WINDING_SLACK
from meshmocap.errors import BodyPartError
from meshmocap.geometry.mesh import mesh_problems, signed_volume
from meshmocap.geometry.proximity import closest_points_on_triangles

#: Corner ``k`` of a quad in units of its half-sizes: counter-clockwise about ``n``.
CORNER_SIGNS = np.array([[1.0, 1.0], [-1.0, 1.0], [-1.0, -1.0], [1.0, -1.0]])
#: Chains of quads joined by tubes (indices into meshmocap.trackers.cage.oqr.QUAD_NAMES).
OQR_TUBES = (
    (0, 1),
    (1, 2),
    (3, 4),  # pelvis → abdomen → chest; neck → head top
    (5, 6),
    (6, 7),
    (7, 8),
    (9, 10),
    (10, 11),
    (11, 12),  # shoulder → elbow → wrist → hand
    (13, 14),
    (14, 15),
    (15, 16),
    (17, 18),
    (18, 19),
    (19, 20),  # hip → knee → ankle → toe
)
#: Chain ends closed by a flat cap (hand and toe tips); the head top gets a pyramid.
OQR_CAPS = (8, 12, 16, 20)
OQR_HEAD = 4
#: Index of the apex vertex (above the head quad, bound to it).
OQR_APEX = 84
_TIE = 1e-12  # metres: distances this close tie (surface_distances)


# ------------------------------------------------------------------------------ topology
def tube_faces(ring_a: np.ndarray, ring_b: np.ndarray) -> np.ndarray:
    """Return the 8 side triangles (8, 3) joining quad ring ``a`` to quad ring ``b``.

    Both rings are counter-clockwise about the tube direction (from ``a`` towards ``b``);
    side ``k`` joins corners ``k, k+1`` of both rings by two outward triangles.
    """
    a = np.asarray(ring_a, dtype=np.int64)
    b = np.asarray(ring_b, dtype=np.int64)
    a1, b1 = np.roll(a, -1), np.roll(b, -1)
    return np.concatenate([np.stack([a, a1, b1], 1), np.stack([a, b1, b], 1)])


def cap_faces(ring: np.ndarray, apex: int | None = None) -> np.ndarray:
    """Return the triangles closing a chain end whose ring faces outward (along ``+n``).

    Two triangles (a flat cap) or, with an ``apex`` vertex index, four (a pyramid).
    """
    r = np.asarray(ring, dtype=np.int64)
    if apex is None:
        return np.array([[r[0], r[1], r[2]], [r[0], r[2], r[3]]], dtype=np.int64)
    return np.stack([r, np.roll(r, -1), np.full(4, apex)], axis=1)


_L, _F, _U = np.eye(3)[0], -np.eye(3)[1], np.eye(3)[2]  # subject's left, front, up


#: The quads of the two junctions (cage vertex // 4), named as parts of the body.
_JUNCTION_QUADS = {
    0: "pelvis",
    13: "left hip",
    17: "right hip",
    2: "chest",
    3: "neck",
    5: "left shoulder",
    9: "right shoulder",
}
#: What usually makes a junction quad's corners ambiguous: its bone near the direction
#: the corners are told apart by (up for the shoulders, front or side for the hips).
_JUNCTION_CAUSE = {
    "chest": "an upper arm hanging straight down or raised, or the head bowed",
    "pelvis": "a thigh raised to the front or side",
}


def oqr_faces(C: np.ndarray) -> np.ndarray:
    """Triangles (166, 3) of the OQR cage on the 84 quad corners plus the head apex (84).

    Parameters
    ----------
    C : (21, 4, 3) float64
        World corners of the rest quads (corner ``k`` of quad ``q`` is cage vertex
        ``4 q + k``; rings counter-clockwise about each quad's normal, which points up the
        spine and down the limbs). Only used to tell which corner of a junction quad is
        front/back/left/right/top/bottom (subject facing −Y, left +X, Z up: the canonical
        frame, in which :func:`meshmocap.trackers.cage.oqr.build_oqr` places any template).

    Returns
    -------
    (166, 3) int64
        Outward triangles: 15 tubes × 8, 4 flat caps × 2, the head pyramid (4), the pants
        (pelvis ↔ hips, 14) and the shoulder girdle (chest ↔ shoulders ↔ neck, 20).

    Raises
    ------
    BodyPartError
        The corners of a junction quad cannot be told apart (the message names its part).

    Notes
    -----
    Pants: the pelvis ring (4 corners) over the two hip rings (8) is a sphere with three
    holes, closed without extra vertices by ``V − E + F = −1`` → 14 triangles: front and
    back hexagons (pelvis front edge, outer-front hip corners, the inner hip corners)
    of 4 triangles each, the two hip sides (2 each) and the crotch quad between the
    thighs' inner edges (2). Shoulder girdle: the chest ring below, the neck ring above
    and the shoulder rings on the sides (16 corners, a sphere with four holes → 20
    triangles): front and back octagons of 6 triangles (chest edge, armpit and top
    corners of each shoulder, neck edge), the two armpit panels (chest side to shoulder
    bottom, 2 each) and the two shoulder tops (neck side to shoulder top, 2 each).
    """
    ring = lambda q: 4 * q + np.arange(4)  # noqa: E731
    parts = [tube_faces(ring(a), ring(b)) for a, b in OQR_TUBES]
    parts += [cap_faces(ring(q)) for q in OQR_CAPS]
    parts.append(cap_faces(ring(OQR_HEAD), apex=OQR_APEX))

    def k(q: int, *dirs: np.ndarray) -> int:  # corner of quad q furthest along sum(dirs)
        c = C[q] - C[q].mean(axis=0)
        return 4 * q + int(np.argmax(c @ np.sum(dirs, axis=0)))

    B, R = -_F, -_L
    # pelvis 0, left hip 13, right hip 17 (f/b: front/back, o/i: outer/inner)
    pFL, pFR, pBR, pBL = k(0, _F, _L), k(0, _F, R), k(0, B, R), k(0, B, _L)
    lfo, lfi, lbi, lbo = k(13, _F, _L), k(13, _F, R), k(13, B, R), k(13, B, _L)
    rfo, rfi, rbi, rbo = k(17, _F, R), k(17, _F, _L), k(17, B, _L), k(17, B, R)
    pants = [
        (pFL, lfi, lfo),
        (pFR, rfo, rfi),
        (pFL, rfi, lfi),
        (pFL, pFR, rfi),  # front
        (pBL, lbo, lbi),
        (pBR, rbi, rbo),
        (pBL, lbi, rbi),
        (pBL, rbi, pBR),  # back
        (pFL, lbo, pBL),
        (pFL, lfo, lbo),
        (pFR, rbo, rfo),
        (pFR, pBR, rbo),  # hip sides
        (lfi, rbi, lbi),
        (lfi, rfi, rbi),  # crotch
    ]
    # chest 2, neck 3, left shoulder 5, right shoulder 9 (t/b: top/bottom, f/b: front/back)
    cFL, cFR, cBR, cBL = k(2, _F, _L), k(2, _F, R), k(2, B, R), k(2, B, _L)
    nFL, nFR, nBR, nBL = k(3, _F, _L), k(3, _F, R), k(3, B, R), k(3, B, _L)
    ltf, ltb, lbf, lbb = k(5, _U, _F), k(5, _U, B), k(5, -_U, _F), k(5, -_U, B)
    rtf, rtb, rbf, rbb = k(9, _U, _F), k(9, _U, B), k(9, -_U, _F), k(9, -_U, B)
    girdle = [
        (cFL, lbf, ltf),
        (cFL, ltf, nFL),
        (cFR, rtf, rbf),
        (cFR, nFR, rtf),  # front
        (cFL, nFL, nFR),
        (cFL, nFR, cFR),
        (cBL, ltb, lbb),
        (cBL, nBL, ltb),
        (cBR, rbb, rtb),
        (cBR, rtb, nBR),  # back
        (cBL, nBR, nBL),
        (cBL, cBR, nBR),
        (cFL, cBL, lbb),
        (cFL, lbb, lbf),
        (cFR, rbf, rbb),
        (cFR, rbb, cBR),  # armpits
        (nFL, ltf, ltb),
        (nFL, ltb, nBL),
        (nFR, nBR, rtb),
        (nFR, rtb, rtf),  # tops
    ]
    for name, faces in (("pelvis", pants), ("chest", girdle)):
        used = np.unique(np.asarray(faces))
        quads, n_used = np.unique(used // 4, return_counts=True)
        if np.any(n_used != 4):
            part = " and ".join(_JUNCTION_QUADS[int(q)] for q in quads[n_used != 4])
            reason = (
                f"the corners of its quad cannot be told apart at the {name} junction "
                f"({_JUNCTION_CAUSE[name]})"
            )
            raise BodyPartError(f"oqr_faces: the {part}: {reason}", part=part, reason=reason)
        parts.append(np.asarray(faces, dtype=np.int64))
    return np.concatenate(parts)


# ------------------------------------------------------------------------------ enclosure
@dataclass
class QuadRect:
    """A quad being fitted (mutable; :mod:`~meshmocap.trackers.cage.growth` grows it).

    Parameters
    ----------
    anchor : (3,) float64
        A point of the quad's plane (on the skeleton), metres, world frame.
    R : (3, 3) float64
        Quad frame, columns ``u, v, n``.
    lo, hi : (2,) float64
        In-plane bounds along ``u`` and ``v`` relative to ``anchor``, metres; the centre
        is ``anchor + R[:, :2] @ (lo + hi) / 2``, the half-sizes ``(hi − lo) / 2``.
    keep_out : ((3,) float64, float), optional
        ``(m, b)``: every corner must satisfy ``m·x ≥ b`` (the hip quads stay off the
        mid-sagittal plane); enforced on the ``u`` bounds by :meth:`clamp`.
    """

    anchor: np.ndarray
    R: np.ndarray
    lo: np.ndarray
    hi: np.ndarray
    keep_out: tuple[np.ndarray, float] | None = None

    def corners(self) -> np.ndarray:
        """(4, 3) world corners, :data:`CORNER_SIGNS` order."""
        mid, half = (self.lo + self.hi) / 2, (self.hi - self.lo) / 2
        return self.anchor + (mid + CORNER_SIGNS * half) @ self.R[:, :2].T

    def grow(self, axis: int, sign: int, step: float) -> bool:
        """Move the ``sign`` side along ``axis`` (0: u, 1: v) outward by ``step`` (inward if
        negative), or with ``axis`` 2 slide the whole quad by ``sign · step`` along ``n``;
        return whether it moved (the keep-out half-space may stop it)."""
        if axis == 2:
            self.anchor = self.anchor + sign * step * self.R[:, 2]
            self.clamp()
            return True
        old = (self.lo[axis], self.hi[axis])
        if sign > 0:
            self.hi[axis] += step
        else:
            self.lo[axis] -= step
        self.clamp()
        return (self.lo[axis], self.hi[axis]) != old

    def clamp(self) -> None:
        """Pull the ``u`` bound facing ``keep_out`` back so every corner satisfies it."""
        if self.keep_out is None:
            return
        m, b = self.keep_out
        mu, mv = m @ self.R[:, 0], abs(m @ self.R[:, 1])
        bound = (b - m @ self.anchor + mv * max(abs(self.lo[1]), abs(self.hi[1]))) / mu
        if mu > 0:
            self.lo[0] = max(self.lo[0], bound)
        else:
            self.hi[0] = min(self.hi[0], bound)


def rect_cage(rects: list[QuadRect], apex_height: float) -> np.ndarray:
    """(85, 3) cage vertices: the 84 corners, then the apex ``apex_height`` metres above
    the centre of the head quad along its normal."""
    head = rects[OQR_HEAD]
    apex = head.anchor + head.R @ np.r_[(head.lo + head.hi) / 2, apex_height]
    return np.vstack([np.concatenate([r.corners() for r in rects]), apex])


# ------------------------------------------------------------------------------ checks
def winding_numbers(P: np.ndarray, V: np.ndarray, F: np.ndarray) -> np.ndarray:
    """Winding numbers (n,) of points ``P`` (n, 3) with respect to a closed mesh.

    Sum of the signed solid angles of the faces (van Oosterom & Strackee) over 4π:
    1 inside an outward-oriented closed cage, 0 outside. One vectorised pass per face
    (cages have a few hundred faces; use chunks of points for large meshes).
    """
    P = np.asarray(P, dtype=np.float64).reshape(-1, 3)
    T = np.asarray(V, dtype=np.float64)[np.asarray(F, dtype=np.int64)]
    Px, Py, Pz = P.T
    total = np.zeros(len(P))
    for tri in T:
        (ax, ay, az), (bx, by, bz), (cx, cy, cz) = ((v[0] - Px, v[1] - Py, v[2] - Pz) for v in tri)
        la = np.sqrt(ax * ax + ay * ay + az * az)
        lb = np.sqrt(bx * bx + by * by + bz * bz)
        lc = np.sqrt(cx * cx + cy * cy + cz * cz)
        num = ax * (by * cz - bz * cy) + ay * (bz * cx - bx * cz) + az * (bx * cy - by * cx)
        den = (
            la * lb * lc
            + (ax * bx + ay * by + az * bz) * lc
            + (bx * cx + by * cy + bz * cz) * la
            + (cx * ax + cy * ay + cz * az) * lb
        )
        total += np.arctan2(num, den)
    return total / (2.0 * np.pi)


def surface_distances(P: np.ndarray, V: np.ndarray, F: np.ndarray) -> tuple[np.ndarray, ...]:
    """Exact distance from each point to a small triangle mesh (brute force over faces).

    Returns ``dist`` (n,) float64 metres and ``face`` (n,) int64, the nearest triangle.
    Meant for cages (a few hundred faces): one vectorised pass per face, skipping the
    points whose lower bound for the face (distance to its plane or to its bounding ball)
    exceeds their best so far (initially the distance to the face of least lower bound).
    Faces within 1e-12 m of the nearest (a point nearest to an edge or a vertex) tie: the
    lowest index wins, so the choice does not depend on rounding (e.g. of a rotation).
    """
    P = np.asarray(P, dtype=np.float64).reshape(-1, 3)
    V = np.asarray(V, dtype=np.float64)
    F = np.asarray(F, dtype=np.int64)
    T = V[F]
    N = np.cross(T[:, 1] - T[:, 0], T[:, 2] - T[:, 0])
    N /= np.maximum(np.linalg.norm(N, axis=1, keepdims=True), UNDERFLOW_FLOOR)
    centre = T.mean(axis=1)
    radius = np.linalg.norm(T - centre[:, None], axis=2).max(axis=1)
    sq = (P * P).sum(1)[:, None]
    ball = np.sqrt(np.maximum(sq - 2.0 * P @ centre.T + (centre * centre).sum(1), 0.0)) - radius
    plane = np.maximum(np.abs(P @ N.T - np.einsum("ij,ij->i", N, T[:, 0])), ball)  # (n, m)
    face = np.argmin(plane, axis=1)  # start from the most promising face: a tight bound
    t = T[face]
    dist = np.linalg.norm(P - closest_points_on_triangles(P, t[:, 0], t[:, 1], t[:, 2]), axis=1)
    for f in range(len(T)):
        rows = np.flatnonzero(plane[:, f] <= dist + _TIE)
        if not len(rows):
            continue
        p = P[rows]
        A, B, C = (np.broadcast_to(v, p.shape) for v in T[f])
        d = np.linalg.norm(p - closest_points_on_triangles(p, A, B, C), axis=1)
        tie = np.abs(d - dist[rows]) <= _TIE
        closer = np.where(tie, f < face[rows], d < dist[rows])
        face[rows[closer]] = f
        dist[rows] = np.minimum(dist[rows], d)
    return dist, face


def _orient3d(a: np.ndarray, b: np.ndarray, c: np.ndarray, d: np.ndarray) -> np.ndarray:
    """Six times the signed volume of tetrahedra ``(a, b, c, d)``, rows of (k, 3) arrays."""
    (ux, uy, uz), (vx, vy, vz), (wx, wy, wz) = (b - a).T, (c - a).T, (d - a).T
    return wx * (uy * vz - uz * vy) + wy * (uz * vx - ux * vz) + wz * (ux * vy - uy * vx)


def _segments_cross_triangles(
    p: np.ndarray, q: np.ndarray, a: np.ndarray, b: np.ndarray, c: np.ndarray, eps: float
) -> np.ndarray:
    """Whether segment ``p q`` properly crosses triangle ``a b c`` (row-wise, (k,) bool).

    Proper crossing: the end points lie strictly on opposite sides of the triangle's plane
    and the segment's line passes strictly inside the triangle (all signed volumes beyond
    ``eps``, an absolute volume tolerance, so touching configurations do not count).
    """
    s1, s2 = _orient3d(a, b, c, p), _orient3d(a, b, c, q)
    o1, o2, o3 = _orient3d(p, q, a, b), _orient3d(p, q, b, c), _orient3d(p, q, c, a)
    sides = ((s1 > eps) & (s2 < -eps)) | ((s1 < -eps) & (s2 > eps))
    inside = ((o1 > eps) & (o2 > eps) & (o3 > eps)) | ((o1 < -eps) & (o2 < -eps) & (o3 < -eps))
    return sides & inside


def self_intersections(
    V: np.ndarray, F: np.ndarray, *, faces: np.ndarray | None = None, fold_cos: float = -0.999
) -> np.ndarray:
    """Pairs of cage triangles that intersect each other (k, 2) int64, ``i < j``.

    Every pair of triangles is tested (vectorised; ``m (m − 1) / 2`` pairs), or, with
    ``faces`` (indices), every pair involving one of them:

    * no shared vertex: any of the 6 edges properly crossing the other triangle;
    * one shared vertex: the edge opposite the shared vertex of either triangle crossing
      the other (generically their intersection, if more than the vertex, ends there);
    * a shared edge: a fold-over, the two normals nearly opposite (``n_i·n_j < fold_cos``).

    Coplanar overlaps of non-adjacent triangles are not detected (measure zero for a
    procedurally built cage). Volumes below ``1e-12 × diameter³`` count as touching.
    """
    V = np.asarray(V, dtype=np.float64)
    F = np.asarray(F, dtype=np.int64)
    m = len(F)
    i, j = np.triu_indices(m, k=1)
    if faces is not None:
        keep = np.zeros(m, dtype=bool)
        keep[np.asarray(faces, dtype=np.int64)] = True
        i, j = i[keep[i] | keep[j]], j[keep[i] | keep[j]]
    Fi, Fj = F[i], F[j]
    shared = (Fi[:, :, None] == Fj[:, None, :]).sum(axis=(1, 2))
    eps = RELATIVE_DEGENERATE * float(np.ptp(V, axis=0).max()) ** 3
    hits = np.zeros(len(i), dtype=bool)
    sel = np.flatnonzero(shared == 0)
    for A, B in ((Fi[sel], Fj[sel]), (Fj[sel], Fi[sel])):
        ta = V[B]
        for e in range(3):
            hits[sel] |= _segments_cross_triangles(
                V[A[:, e]], V[A[:, (e + 1) % 3]], ta[:, 0], ta[:, 1], ta[:, 2], eps
            )
    sel = np.flatnonzero(shared == 1)
    for A, B in ((Fi[sel], Fj[sel]), (Fj[sel], Fi[sel])):
        own = (A[:, :, None] != B[:, None, :]).all(axis=2)  # corners of A not in B (two)
        k = np.argsort(~own, axis=1, kind="stable")[:, :2]
        r = np.arange(len(A))
        p, q = V[A[r, k[:, 0]]], V[A[r, k[:, 1]]]
        tb = V[B]
        hits[sel] |= _segments_cross_triangles(p, q, tb[:, 0], tb[:, 1], tb[:, 2], eps)
    sel = np.flatnonzero(shared == 2)
    N = np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]])
    N /= np.maximum(np.linalg.norm(N, axis=1, keepdims=True), UNDERFLOW_FLOOR)
    hits[sel] |= np.einsum("ij,ij->i", N[i[sel]], N[j[sel]]) < fold_cos
    return np.stack([i[hits], j[hits]], axis=1)


def cage_problems(
    V: np.ndarray, F: np.ndarray, points: np.ndarray | None = None, *, clearance: float = 0.0
) -> list[str]:
    """Return the checks a cage fails, each message starting with the check's name.

    Checks (in order): ``manifold`` (finite, closed 2-manifold:
    :func:`~meshmocap.geometry.mesh.mesh_problems`), ``orientation`` (every directed edge used
    once), ``outward`` (signed volume > 0), ``self-intersection``
    (:func:`self_intersections`) and, when ``points`` (n, 3) are given, ``enclosure``: every
    point strictly inside (winding number within 1e-6 of 1) and at least ``clearance`` metres
    from the cage surface.
    """
    V = np.asarray(V, dtype=np.float64)
    F = np.asarray(F, dtype=np.int64)
    problems = [f"manifold: {p}" for p in mesh_problems(V, F)]
    if problems:
        return problems
    directed = np.concatenate([F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]])
    if len(np.unique(directed, axis=0)) != len(directed):
        problems.append("orientation: faces are not consistently oriented")
    vol = signed_volume(V, F)
    if not vol > 0:
        problems.append(f"outward: signed volume must be positive, found {vol:.4g} m³")
    pairs = self_intersections(V, F)
    if len(pairs):
        problems.append(
            f"self-intersection: {len(pairs)} pairs of faces intersect "
            f"(first: faces {pairs[0, 0]} and {pairs[0, 1]})"
        )
    if points is not None:
        P = np.asarray(points, dtype=np.float64).reshape(-1, 3)
        w = winding_numbers(P, V, F)
        out = np.abs(w - 1.0) > WINDING_SLACK
        if out.any():
            problems.append(
                f"enclosure: {int(out.sum())} of {len(P)} points are outside the cage "
                f"(first: point {int(np.flatnonzero(out)[0])})"
            )
        elif clearance > 0:
            d, _ = surface_distances(P, V, F)
            if d.min() < clearance:
                problems.append(
                    f"enclosure: {int((d < clearance).sum())} points are closer than "
                    f"{clearance:g} m to the cage (closest {d.min():.3g} m)"
                )
    return problems
