"""Growing the quads of an Oriented Quads Rigging until its cage encloses the template.

:func:`untangle` shrinks quads whose cage faces intersect; :func:`enclose` grows and slides
quads (:class:`~meshmocap.trackers.cage.cage_mesh.QuadRect`, in place) until every
template vertex lies
inside the cage, a clearance deep, never into a new self-intersection. Used by
:func:`meshmocap.trackers.cage.oqr.build_oqr`; conventions of
:mod:`meshmocap.trackers.cage.cage_mesh`.

References
----------
- E. Duveau, S. Courtemanche, L. Reveret, E. Boyer, *Cage-based motion recovery
  using manifold learning*, International Conference on 3D Imaging, Modeling,
  Processing, Visualization and Transmission (3DIMPVT), 2012.
"""

from __future__ import annotations

import numpy as np

from meshmocap._tolerances import UNDERFLOW_FLOOR, WINDING_SLACK
from meshmocap.geometry.proximity import closest_points_on_triangles
from meshmocap.trackers.cage.cage_mesh import (
    CORNER_SIGNS,
    QuadRect,
    rect_cage,
    self_intersections,
    surface_distances,
    winding_numbers,
)

__all__ = ["enclose", "untangle"]


def enclose(
    rects: list[QuadRect],
    F: np.ndarray,
    points: np.ndarray,
    *,
    apex_height: float,
    clearance: float,
    step: float,
    max_iter: int,
) -> int:
    """Grow quads in place until every point is inside the cage, ``clearance`` deep.

    Each iteration finds the points outside the cage (winding number ≠ 1) or closer than
    ``clearance`` to it, and their nearest cage faces; each quad with a corner in such a
    face moves towards the point along the axis of its frame closest to the push direction
    ``g`` (from the nearest cage point to an outside point, the face normal for an inside
    one), by the missing depth (``1.25 clearance`` − signed distance) over ``|g·axis|``,
    clipped to ``[step, 4 step]``. Moves are applied one by one; one that makes faces
    around its quad intersect faces they did not intersect before is undone, and that
    move is not tried again. Points deeper than 3 cm at the start of the first pass are not
    watched in it (the caller checks all of them at the end).

    A first pass (at most ``max_iter`` iterations) only moves sides: along ``u`` or ``v``
    the side holding that corner moves outward in the quad's plane. When points are left
    (no move left, or ``max_iter``), a second pass (as many iterations) also slides whole
    quads along their normal ``n``, only the quad of the face whose plane is nearest the
    point: by the push where it is mostly along ``n`` (a crotch between two thighs, a
    cap), and away from the trunk (``+n``) where the side that should move cannot (undone
    before), which deepens the crease of a junction (an armpit under a hanging arm, the
    crotch of legs held together); there a move that runs into other quads' faces may keep
    its place by shrinking those quads' facing sides as much, when that makes no new
    intersection and no point outside or too close. A third pass does the same with steps
    of ``step / 4``, every move allowed again (a finer move may fit where a coarse one
    intersected). Templates that the first pass encloses (the bundled ones) get exactly
    the cage they got before the later passes existed. Returns the iterations used.
    """
    frozen: set[tuple[int, int, int]] = set()
    used = 0
    for slide, size in ((False, step), (True, step), (True, step / 4)):
        if size < step:
            frozen = set()
        it, done = _grow_pass(
            rects, F, points, apex_height, clearance, size, max_iter, slide, frozen
        )
        used += it
        if done:
            break
    return used


def _grow_pass(rects, F, points, apex_height, clearance, step, max_iter, slide, frozen):
    """One pass of :func:`enclose` (``slide``: whether quads may slide; ``frozen``: the
    moves undone so far, updated): ``(iterations, whether every point is enclosed)``."""
    band = np.ones(len(points), dtype=bool)
    for it in range(max_iter + 1):
        V = rect_cage(rects, apex_height)
        outside = np.abs(winding_numbers(points, V, F) - 1.0) > WINDING_SLACK
        check = np.flatnonzero(band | outside)
        d, f = surface_distances(points[check], V, F)
        if it == 0 and not slide:  # a slide also moves faces inwards: watch every point
            band[check] = d < clearance + 0.03
        bad = outside[check] | (d < clearance)
        if not bad.any():
            return it, True
        if it == max_iter:
            break
        X, out, f, d = points[check[bad]], outside[check[bad]], f[bad], d[bad]
        T = V[F[f]]
        Q = closest_points_on_triangles(X, T[:, 0], T[:, 1], T[:, 2])
        g = np.where(out[:, None], X - Q, np.cross(T[:, 1] - T[:, 0], T[:, 2] - T[:, 0]))
        g /= np.maximum(np.linalg.norm(g, axis=1, keepdims=True), UNDERFLOW_FLOOR)
        need = 1.25 * clearance + np.where(out, d, -d)
        moves: dict[tuple[int, int, int], float] = {}
        corner = F[f] % 4
        if slide:  # slides only move the quad of the face whose plane is nearest the point
            qf = np.minimum(F[f] // 4, len(rects) - 1)  # the apex follows the head quad
            A = np.stack([r.anchor for r in rects])[qf]
            N = np.stack([r.R[:, 2] for r in rects])[qf]
            height = np.abs(np.einsum("pki,pki->pk", X[:, None] - A, N))
            nearest = qf[np.arange(len(qf)), np.argmin(height, axis=1)]
        for q, rect in enumerate(rects):  # loops over quads, vectorised over points
            rows, cols = np.nonzero(F[f] // 4 == q)
            if not len(rows):
                continue
            uvn = g[rows] @ rect.R
            axis = np.argmax(np.abs(uvn[:, : 3 if slide else 2]), axis=1)
            comp = uvn[np.arange(len(rows)), axis]
            sign = np.sign(comp).astype(int)
            ok = axis == 2  # a slide along n moves every corner
            ok[~ok] = CORNER_SIGNS[corner[rows, cols], np.minimum(axis, 1)][~ok] == sign[~ok]
            if slide:  # a side that cannot move: slide the quad away from the trunk
                held = [(q, a, s) in frozen for a, s in zip(axis, sign, strict=True)]
                stuck = ok & np.array(held, dtype=bool)
                axis[stuck], sign[stuck] = 2, 1
                comp[stuck] = uvn[stuck, 2]
                ok &= (axis != 2) | (nearest[rows] == q)
            amount = need[rows] / np.maximum(np.abs(comp), 0.5)
            for a in (0, 1, 2):
                for s in (-1, 1):
                    sel = ok & (axis == a) & (sign == s)
                    if sel.any():
                        moves[(q, a, s)] = float(amount[sel].max())
        moves = {key: m for key, m in moves.items() if key not in frozen}
        if not moves:
            break
        for (q, a, s), m in sorted(moves.items()):
            around = np.flatnonzero((q == F // 4).any(axis=1))
            V0 = rect_cage(rects, apex_height)
            before = _pair_set(V0, F, around)
            delta = min(max(m, step), 4 * step)
            if not rects[q].grow(a, s, delta):
                frozen.add((q, a, s))
                continue
            new = _pair_set(rect_cage(rects, apex_height), F, around) - before
            if new and not (
                slide
                and _make_way(rects, F, points[check], V0, q, new, delta, apex_height, clearance)
            ):
                rects[q].grow(a, s, -delta)
                frozen.add((q, a, s))
    return it, False


def _make_way(rects, F, P, V0, q, new, delta, apex_height, clearance) -> bool:
    """After quad ``q`` grew by ``delta`` into faces it now intersects (``new`` pairs),
    shrink by ``delta`` the sides of the other quads facing it (the corners of those
    faces on the side towards ``q``'s face): kept (True) if no face then intersects one
    it did not before and no point of ``P`` (the watched points, cage ``V0`` before the
    move) becomes outside or closer than ``clearance``; else undone (False)."""
    nq = len(rects)
    V = rect_cage(rects, apex_height)
    centre = V[F].mean(axis=1)
    mine = set(np.flatnonzero((q == F // 4).any(axis=1)).tolist())
    shrink: set[tuple[int, int, int]] = set()
    for i, j in new:
        own, other = (i, j) if i in mine else (j, i)
        for c in F[other][F[other] < 4 * nq]:
            b, k = divmod(int(c), 4)
            if b == q:
                continue
            uv = (centre[own] - centre[other]) @ rects[b].R[:, :2]
            ax = int(np.argmax(np.abs(uv)))
            sg = int(np.sign(uv[ax]))
            if CORNER_SIGNS[k, ax] == sg:
                shrink.add((b, ax, sg))
    if not shrink:
        return False
    quads = {q} | {b for b, _, _ in shrink}
    faces = np.flatnonzero(np.isin(F // 4, list(quads)).any(axis=1))
    before = _pair_set(V0, F, faces)
    done = []
    for b, ax, sg in sorted(shrink):
        if (rects[b].hi - rects[b].lo)[ax] > 2 * delta and rects[b].grow(ax, sg, -delta):
            done.append((b, ax, sg))
    V1 = rect_cage(rects, apex_height)
    ok = bool(done) and _pair_set(V1, F, faces) <= before
    if ok:
        was = _bad(P, V0, F, clearance)
        ok = not (_bad(P, V1, F, clearance) & ~was).any()
    if not ok:
        for b, ax, sg in done:
            rects[b].grow(ax, sg, delta)
    return ok


def _bad(P: np.ndarray, V: np.ndarray, F: np.ndarray, clearance: float) -> np.ndarray:
    """(n,) bool: points outside the cage or closer than ``clearance`` to it."""
    out = np.abs(winding_numbers(P, V, F) - 1.0) > WINDING_SLACK
    return out | (surface_distances(P, V, F)[0] < clearance)


def untangle(
    rects: list[QuadRect], F: np.ndarray, *, apex_height: float, step: float, max_iter: int
) -> int:
    """Shrink quads in place until the cage has no self-intersection.

    Each iteration takes every pair of intersecting faces; each corner of one face moves
    ``step`` inward along the axis (``u`` or ``v``) of its quad's frame closest to the
    direction from that face's centroid to the other's, if the corner lies on that side
    (the two faces retreat from each other: e.g. a trunk quad fitted with a margin into an
    arm hanging close to the trunk, and the arm's quads). No side shrinks by more than
    half its quad's initial extent. Returns the number of iterations used (``max_iter``
    when intersections remain; the caller's checks name them).
    """
    size0 = [r.hi - r.lo for r in rects]
    for it in range(max_iter):
        V = rect_cage(rects, apex_height)
        pairs = self_intersections(V, F)
        if not len(pairs):
            return it
        centre = V[F].mean(axis=1)
        moves: set[tuple[int, int, int]] = set()
        for i, j in np.concatenate([pairs, pairs[:, ::-1]]):
            for c in F[i][F[i] < 4 * len(rects)]:  # quad corners (not the apex)
                q, k = divmod(int(c), 4)
                uv = (centre[j] - centre[i]) @ rects[q].R[:, :2]
                a = int(np.argmax(np.abs(uv)))
                s = int(np.sign(uv[a]))
                if CORNER_SIGNS[k, a] == s:
                    moves.add((q, a, s))
        for q, a, s in sorted(moves):
            r = rects[q]
            if (r.hi - r.lo)[a] - step >= 0.5 * size0[q][a]:
                r.grow(a, s, -step)
    return max_iter


def _pair_set(V: np.ndarray, F: np.ndarray, faces: np.ndarray) -> set[tuple[int, int]]:
    return set(map(tuple, self_intersections(V, F, faces=faces).tolist()))
