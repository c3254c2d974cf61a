"""Compiled loops (numba) of the patch tracker's inner work.

* :func:`assign_kernel`: the E-step
  (:meth:`~meshmocap.trackers.patch.tracker.PatchTracker.correspondences`). After the k-d
  query it keeps for every observed point its nearest compatible vertex per patch and
  weighs those by their Gaussian posterior against an outlier class, in one pass over the
  candidates: the pairs and order of the numpy expressions it replaced (a gather of the
  candidates' normals, a sort of point × patch keys, a bincount), weights to rounding
  (``tests/trackers/patch/test_assign.py``).
* :func:`point_moments`: the per-patch sums of the point terms, one pass.
* :func:`rigidity_blocks`: the rigidity term's blocks, gradient and energy from the pairs'
  rest moments (:func:`rotated_moments`), one pass.
* :func:`nearest_among`, :func:`vertex_moves`, :func:`stale_rows`: the candidate vertices
  re-used across a frame's iterations (:mod:`~meshmocap.trackers.patch.nearest`).
* :func:`block_cholesky`, :func:`block_cholesky_solve`: the normal equations' sparse
  Cholesky factor in 3×3 blocks on a structure computed once
  (:class:`~meshmocap.trackers.patch.solver.BlockFactor`), and its solve.

References
----------
- C.-H. Huang, E. Boyer, S. Ilic, *Robust human body shape and pose tracking*,
  International Conference on 3D Vision (3DV), 2013.
- C. Cagniart, E. Boyer, S. Ilic, *Probabilistic deformable surface tracking from
  multiple videos*, European Conference on Computer Vision (ECCV), 2010.
"""

from __future__ import annotations

import numpy as np

from meshmocap._numba import njit
from meshmocap._tolerances import ZERO_EXTENT

#: A squared distance above the k-th candidate's squared reach by more than this relative
#: margin is beyond it whatever the rounding of the square root (the re-query test).
REACH_ROUNDING = 1e-9


@njit(cache=True, nogil=True)
def assign_kernel(d, idx, Nc, Y, NY, cls, labels, bone_of_patch, normal_cos, s2, p_out):
    """Pairs of the E-step: rows, patches, vertices, posterior weights, and each pair's
    observed point ``Y[t]`` (m, 3) and its normal ``NY[t]`` (m, 3), gathered in the pass.

    For each point t (in order) and each patch (ascending) whose nearest compatible
    candidate among ``idx[t]`` (k,) (by increasing distance ``d[t]``) is candidate c: the
    row t, the patch, the vertex ``idx[t, c]`` and the posterior weight
    ``p / (Σ_t p + p_out)`` with ``p = exp(−d²/2 / s2)``. Compatible: normals agree
    (``Nc[v] · NY[t] > normal_cos``) and, where ``cls[t] ≥ 0``, the patch lies on bone
    ``cls[t]`` (``cls`` of length 0: no classes)."""
    n, k = idx.shape
    rows = np.empty(n * k, dtype=np.int64)
    patch = np.empty(n * k, dtype=np.int64)
    vert = np.empty(n * k, dtype=np.int64)
    w = np.empty(n * k)
    pts = np.empty((n * k, 3))
    nrm = np.empty((n * k, 3))
    m = 0
    for t in range(n):
        start = m
        for c in range(k):
            v = idx[t, c]
            dot = (Nc[v, 0] * NY[t, 0] + Nc[v, 1] * NY[t, 1]) + Nc[v, 2] * NY[t, 2]
            if not dot > normal_cos:
                continue
            q = labels[v]
            if cls.shape[0] and cls[t] >= 0 and bone_of_patch[q] != cls[t]:
                continue
            seen = False
            for u in range(start, m):
                if patch[u] == q:
                    seen = True
                    break
            if seen:
                continue
            # insert in ascending patch order (a few entries per point)
            u = m
            while u > start and patch[u - 1] > q:
                patch[u], vert[u], w[u] = patch[u - 1], vert[u - 1], w[u - 1]
                u -= 1
            patch[u], vert[u], w[u] = q, v, d[t, c]
            m += 1
        total = 0.0
        for u in range(start, m):
            p = np.exp(-0.5 * (w[u] * w[u]) / s2)
            w[u] = p
            total += p
        for u in range(start, m):
            rows[u] = t
            w[u] = w[u] / (total + p_out)
            for a in range(3):
                pts[u, a] = Y[t, a]
                nrm[u, a] = NY[t, a]
    return rows[:m], patch[:m], vert[:m], w[:m], pts[:m], nrm[:m]


@njit(cache=True, nogil=True)
def _moment_arrays(n_p):
    """Zeroed ``W`` (n_p,), ``s`` (n_p, 3), ``Q`` (n_p, 3, 3), ``G`` (n_p, 6)."""
    return np.zeros(n_p), np.zeros((n_p, 3)), np.zeros((n_p, 3, 3)), np.zeros((n_p, 6))


@njit(cache=True, nogil=True)
def _add_moment(W, s, Q, G, k, wt, q0, q1, q2, r0, r1, r2):
    """Add one weighted residual ``r`` moved by patch ``k`` at offset ``q`` to the moments
    (upper triangle of ``Q``); returns ``wt · |r|²``."""
    W[k] += wt
    s[k, 0] += wt * q0
    s[k, 1] += wt * q1
    s[k, 2] += wt * q2
    Q[k, 0, 0] += wt * q0 * q0
    Q[k, 0, 1] += wt * q0 * q1
    Q[k, 0, 2] += wt * q0 * q2
    Q[k, 1, 1] += wt * q1 * q1
    Q[k, 1, 2] += wt * q1 * q2
    Q[k, 2, 2] += wt * q2 * q2
    G[k, 0] += wt * (q1 * r2 - q2 * r1)
    G[k, 1] += wt * (q2 * r0 - q0 * r2)
    G[k, 2] += wt * (q0 * r1 - q1 * r0)
    G[k, 3] += wt * r0
    G[k, 4] += wt * r1
    G[k, 5] += wt * r2
    return wt * (r0 * r0 + r1 * r1 + r2 * r2)


@njit(cache=True, nogil=True)
def _add_vertex_moment(W, s, Q, G, k, wt, V, i, c, Y, y):
    """:func:`_add_moment` for vertex ``V[i]`` of patch ``k`` pulled to ``Y[y]``: ``q =
    V[i] − c[k]``, ``r = V[i] − Y[y]``."""
    return _add_moment(
        W,
        s,
        Q,
        G,
        k,
        wt,
        V[i, 0] - c[k, 0],
        V[i, 1] - c[k, 1],
        V[i, 2] - c[k, 2],
        V[i, 0] - Y[y, 0],
        V[i, 1] - Y[y, 1],
        V[i, 2] - Y[y, 2],
    )


@njit(cache=True, nogil=True)
def _symmetric(Q):
    """Copy the upper triangles of ``Q`` (n, 3, 3) to the lower ones."""
    for k in range(Q.shape[0]):
        Q[k, 1, 0] = Q[k, 0, 1]
        Q[k, 2, 0] = Q[k, 0, 2]
        Q[k, 2, 1] = Q[k, 1, 2]


@njit(cache=True, nogil=True)
def point_moments(patch, q, r, w, n_p):
    """Per-patch moments of weighted residuals, in one pass.

    Sums over weighted 3-D residuals ``r`` (m, 3) moved by one patch each
    (``patch`` (m,) in ``0 .. n_p-1``, offsets ``q = R_k d`` (m, 3), weights ``w`` (m,)),
    in one pass: ``W = Σ w``, ``s = Σ w q``, ``Q = Σ w q qᵀ`` (P, 3, 3), the gradient
    ``G = Σ w [q × r, r]`` (P, 6) and the value ``Σ w |r|²``
    (:func:`~meshmocap.trackers.patch.solver.add_point_terms`)."""
    W, s, Q, G = _moment_arrays(n_p)
    value = 0.0
    for t in range(patch.shape[0]):
        value += _add_moment(
            W, s, Q, G, patch[t], w[t], q[t, 0], q[t, 1], q[t, 2], r[t, 0], r[t, 1], r[t, 2]
        )
    _symmetric(Q)
    return W, s, Q, G, value


@njit(cache=True, nogil=True)
def vertex_moments(patch, vert, V, c, Y, w, n_p):
    """:func:`point_moments` of the residuals of vertices moved by their own patch:
    row ``t`` has ``q = V[vert[t]] − c[patch[t]]`` and ``r = V[vert[t]] − Y[t]``
    (``V`` (n, 3) each vertex as its own patch places it, ``c`` (P, 3) the patch centres,
    ``Y`` (m, 3) the targets), computed as it goes instead of gathered first (the same
    subtractions)."""
    W, s, Q, G = _moment_arrays(n_p)
    value = 0.0
    for t in range(patch.shape[0]):
        value += _add_vertex_moment(W, s, Q, G, patch[t], w[t], V, vert[t], c, Y, t)
    _symmetric(Q)
    return W, s, Q, G, value


@njit(cache=True, nogil=True)
def reverse_moments(ok, vert, near, d, labels, V, c, Y, scale, n_p):
    """:func:`vertex_moments` of the reverse term's pairs: each row ``t`` with ``ok[t]``
    pulls vertex ``vert[t]`` (its patch ``labels[vert[t]]``, placed at ``V`` (n, 3); ``c``
    (P, 3) the patch centres) to ``Y[near[t]]``, ``d[t]`` away, with the Cauchy weight
    ``1 / (1 + (d / scale)²)``. Returns the moments over ``n_p`` patches and the value."""
    W, s, Q, G = _moment_arrays(n_p)
    value = 0.0
    for t in range(ok.shape[0]):
        if not ok[t]:
            continue
        x = d[t] / scale
        k = labels[vert[t]]
        value += _add_vertex_moment(W, s, Q, G, k, 1.0 / (1.0 + x * x), V, vert[t], c, Y, near[t])
    _symmetric(Q)
    return W, s, Q, G, value


@njit(cache=True, nogil=True)
def add_plane_blocks(D, g, patch, vert, V, c, Y, NY, w, weight):
    """In place, the point-to-plane rows of vertices moved by their own patch
    (:func:`~meshmocap.trackers.patch.solver.add_plane_vertex_terms`): row ``t`` has
    ``q = V[vert[t]] − c[k]`` (``k = patch[t]``), the residual ``s = n · (V[vert[t]] −
    Y[t])`` along ``n = NY[t]`` and the Jacobian row ``J = [q × n, n]``; ``D[k] += weight ·
    w J Jᵀ`` (D (P, 6, 6)) and ``g[6k:6k + 6] += weight · w s J`` (g (n,)), in one pass
    without an (m, 6) array. Returns ``Σ w s²`` (before ``weight``)."""
    value = 0.0
    J = np.empty(6)
    B = np.zeros(D.shape)  # the upper triangles of Σ w J Jᵀ
    for t in range(patch.shape[0]):
        k = patch[t]
        v = vert[t]
        q0, q1, q2 = V[v, 0] - c[k, 0], V[v, 1] - c[k, 1], V[v, 2] - c[k, 2]
        n0, n1, n2 = NY[t, 0], NY[t, 1], NY[t, 2]
        st = (n0 * (V[v, 0] - Y[t, 0]) + n1 * (V[v, 1] - Y[t, 1])) + n2 * (V[v, 2] - Y[t, 2])
        J[0] = q1 * n2 - q2 * n1
        J[1] = q2 * n0 - q0 * n2
        J[2] = q0 * n1 - q1 * n0
        J[3], J[4], J[5] = n0, n1, n2
        wt = w[t]
        value += wt * st * st
        for i in range(6):
            wj = weight * wt * J[i]
            g[6 * k + i] += wj * st
            for j in range(i, 6):
                B[k, i, j] += wj * J[j]
    for k in range(D.shape[0]):
        for i in range(6):
            D[k, i, i] += B[k, i, i]
            for j in range(i + 1, 6):
                D[k, i, j] += B[k, i, j]
                D[k, j, i] += B[k, i, j]
    return value


@njit(cache=True, nogil=True)
def add_moment_blocks(D, g, W, s, Q, G, weight):
    """In place: ``D[k] += weight · Σ w A(q)ᵀ A(q)`` (D (P, 6, 6)) for every patch ``k``
    with ``W[k] > 0``, from its moments ``W`` (n_p,), ``s`` (n_p, 3), ``Q`` (n_p, 3, 3)
    (:func:`~meshmocap.trackers.patch.solver.add_point_terms` states the blocks), and
    ``g[6k:6k + 6] += weight · G[k]`` (g (n,), G (n_p, 6)) for every ``k < n_p``; the
    operations of the numpy expressions it replaced, in their order."""
    for k in range(W.shape[0]):
        if W[k] > 0:
            tr = (Q[k, 0, 0] + Q[k, 1, 1]) + Q[k, 2, 2]
            s0, s1, s2 = s[k, 0], s[k, 1], s[k, 2]
            for i in range(3):
                for j in range(3):
                    e = tr * 1.0 if i == j else tr * 0.0  # tr I − Q
                    D[k, i, j] += weight * (e - Q[k, i, j])
                    e = W[k] * 1.0 if i == j else W[k] * 0.0  # W I
                    D[k, 3 + i, 3 + j] += weight * e
            # [s]× top right, −[s]× bottom left (their zero diagonals add nothing)
            D[k, 0, 4] += weight * -s2
            D[k, 0, 5] += weight * s1
            D[k, 1, 3] += weight * s2
            D[k, 1, 5] += weight * -s0
            D[k, 2, 3] += weight * -s1
            D[k, 2, 4] += weight * s0
            D[k, 3, 1] += weight * s2
            D[k, 3, 2] += weight * -s1
            D[k, 4, 0] += weight * -s2
            D[k, 4, 2] += weight * s0
            D[k, 5, 0] += weight * s1
            D[k, 5, 1] += weight * -s0
        for i in range(6):
            g[6 * k + i] += weight * G[k, i]


@njit(cache=True, nogil=True)
def add_pair_blocks(D, O, g, H2, Hkl, G, k, l, weight):
    """In place, the rigidity term's pieces (:func:`rigidity_blocks`) times ``weight``
    added to a system's blocks: ``H2`` (2E, 6, 6) to the diagonal blocks ``D`` (P, 6, 6)
    of each pair's first patches ``k`` (E,) then second ones ``l`` (E,), ``Hkl`` (E, 6, 6)
    to the pair blocks ``O``, and the gradient pieces ``G`` (E, 2, 6) to ``g`` at the
    rows of patch k then of patch l. Each sum is taken in the order of the numpy
    expressions it replaced: per patch over its pair ends in order, then added."""
    E = k.shape[0]
    acc = np.zeros(D.shape)
    for e in range(2 * E):
        p = k[e] if e < E else l[e - E]
        for i in range(6):
            for j in range(6):
                acc[p, i, j] += weight * H2[e, i, j]
    for p in range(D.shape[0]):
        for i in range(6):
            for j in range(6):
                D[p, i, j] += acc[p, i, j]
    for e in range(E):
        for i in range(6):
            for j in range(6):
                O[e, i, j] += weight * Hkl[e, i, j]
    for end in range(2):
        sums = np.zeros(g.shape[0])
        for e in range(E):
            p = k[e] if end == 0 else l[e]
            for i in range(6):
                sums[6 * p + i] += weight * G[e, end, i]
        for i in range(g.shape[0]):
            g[i] += sums[i]


@njit(cache=True, nogil=True)
def add_bone_joint_blocks(PJ, g, q, r, cw, ends, base, weight):
    """In place, the bone term's patch–joint blocks and joint gradient: for each end
    (0: the bone's start joint, 1: its end) and patch ``k``, ``PJ[k, end] += weight ·
    cw[end, k] · A(q_k)ᵀ`` (``A(q)ᵀ = [[q]×; I]`` (6, 3), ``q`` (P, 3)) and ``weight ·
    cw[end, k] · r_k`` (``r`` (P, 3)) summed into ``g`` at joint ``ends[end, k]``'s rows
    (``base + 3 j``) over the patches in order, then added; ``cw`` (2, P) the residuals'
    coefficients on the joints (:func:`~meshmocap.trackers.patch.solver.add_bone`)."""
    P = q.shape[0]
    A = np.zeros((6, 3))
    for end in range(2):
        sums = np.zeros(g.shape[0])
        for k in range(P):
            a = weight * cw[end, k]
            q0, q1, q2 = q[k, 0], q[k, 1], q[k, 2]
            A[0, 0], A[0, 1], A[0, 2] = 0.0, -q2, q1
            A[1, 0], A[1, 1], A[1, 2] = q2, 0.0, -q0
            A[2, 0], A[2, 1], A[2, 2] = -q1, q0, 0.0
            A[3, 0], A[3, 1], A[3, 2] = 1.0, 0.0, 0.0
            A[4, 0], A[4, 1], A[4, 2] = 0.0, 1.0, 0.0
            A[5, 0], A[5, 1], A[5, 2] = 0.0, 0.0, 1.0
            for i in range(6):
                for j in range(3):
                    PJ[k, end, i, j] += a * A[i, j]
            row = base + 3 * ends[end, k]
            for i in range(3):
                sums[row + i] += a * r[k, i]
        for i in range(g.shape[0]):
            g[i] += sums[i]


@njit(cache=True, nogil=True)
def add_length_blocks(JJ, g, u, r, b, p, base, weight):
    """In place, the bone-length prior's joint blocks and gradient
    (:func:`~meshmocap.trackers.patch.solver.add_bone_lengths`): for each pair ``t``
    (joints ``b[t]``, ``p[t]``, unit direction ``u`` (m, 3), length error ``r`` (m,)),
    ``weight · u uᵀ`` added to ``JJ`` (3K, 3K) at (b, b) and (p, p) and subtracted at
    (b, p) and (p, b), in that order over the pairs, then ``± weight · r u`` summed into
    ``g`` at the rows ``base + 3 b`` (+) and ``base + 3 p`` (−), each sum over the pairs
    in order, then added: the operations of the numpy expressions it replaced."""
    m = u.shape[0]
    for blk in range(4):  # (b, b), (p, p), (b, p), (p, b)
        for t in range(m):
            ja = b[t] if blk == 0 or blk == 2 else p[t]
            jb = b[t] if blk == 0 or blk == 3 else p[t]
            for i in range(3):
                wu = weight * u[t, i]
                for j in range(3):
                    v = wu * u[t, j]
                    JJ[3 * ja + i, 3 * jb + j] += v if blk < 2 else -v
    for end in range(2):
        sums = np.zeros(g.shape[0])
        w = weight if end == 0 else -weight
        for t in range(m):
            row = base + 3 * (b[t] if end == 0 else p[t])
            wr = w * r[t]
            for i in range(3):
                sums[row + i] += wr * u[t, i]
        for i in range(g.shape[0]):
            g[i] += sums[i]


@njit(cache=True, nogil=True)
def nearest_among(Y, V, cand, k):
    """For each point ``Y[t]`` (m, 3), its ``k`` nearest vertices of ``V`` (n, 3) among the
    candidates ``cand[t]`` (m, K) int64, by increasing distance (ties in candidate order):
    distances (m, k) float64 and vertex indices (m, k) int64."""
    m, K = cand.shape
    d = np.empty((m, k))
    idx = np.empty((m, k), dtype=np.int64)
    for t in range(m):
        y0, y1, y2 = Y[t, 0], Y[t, 1], Y[t, 2]
        n = 0  # the n nearest so far, sorted, in d[t, :n] (at most k: a candidate not
        for c in range(K):  # nearer than the k-th so far cannot enter)
            v = cand[t, c]
            x = V[v, 0] - y0
            y = V[v, 1] - y1
            z = V[v, 2] - y2
            dd = np.sqrt(x * x + y * y + z * z)
            if n < k:
                u = n
                n += 1
            elif d[t, k - 1] > dd:
                u = k - 1
            else:
                continue
            while u > 0 and d[t, u - 1] > dd:  # insert after any equal one: candidate order
                d[t, u], idx[t, u] = d[t, u - 1], idx[t, u - 1]
                u -= 1
            d[t, u], idx[t, u] = dd, v
    return d, idx


@njit(cache=True, nogil=True)
def vertex_moves(Vm, snaps, start, cstart):
    """How far each vertex moved since each snapshot: ``Vm`` (n, 3) the vertices now and
    ``snaps`` (S, n, 3) at each snapshot, both in patch order (patch ``p``'s vertices in
    rows ``start[p]:start[p + 1]``), each patch's rows cut into chunks (chunk ``c``: rows
    ``cstart[c]:cstart[c + 1]``, no chunk across two patches). Returns the distances
    (S, n), their largest per patch (S, P) and per chunk (S, C), metres, and each patch's
    and each chunk's bounding box now, (P, 6) and (C, 6): lowest x, y, z, then highest."""
    S, n = snaps.shape[0], Vm.shape[0]
    P = start.shape[0] - 1
    C = cstart.shape[0] - 1
    dv = np.empty((S, n))
    moved = np.zeros((S, P))
    cmoved = np.zeros((S, C))
    box = np.empty((P, 6))
    cbox = np.empty((C, 6))
    c = 0
    for p in range(P):
        for a in range(3):
            box[p, a] = np.inf
            box[p, 3 + a] = -np.inf
        while c < C and cstart[c] < start[p + 1]:
            for a in range(3):
                cbox[c, a] = np.inf
                cbox[c, 3 + a] = -np.inf
            for s in range(cstart[c], cstart[c + 1]):
                for a in range(3):
                    cbox[c, a] = min(cbox[c, a], Vm[s, a])
                    cbox[c, 3 + a] = max(cbox[c, 3 + a], Vm[s, a])
            for a in range(3):
                box[p, a] = min(box[p, a], cbox[c, a])
                box[p, 3 + a] = max(box[p, 3 + a], cbox[c, 3 + a])
            c += 1
    for e in range(S):
        for c in range(C):
            top = 0.0
            for s in range(cstart[c], cstart[c + 1]):
                x = Vm[s, 0] - snaps[e, s, 0]
                y = Vm[s, 1] - snaps[e, s, 1]
                z = Vm[s, 2] - snaps[e, s, 2]
                d = np.sqrt(x * x + y * y + z * z)
                dv[e, s] = d
                if d > top:
                    top = d
            cmoved[e, c] = top
        c = 0
        for p in range(P):
            top = 0.0
            while c < C and cstart[c] < start[p + 1]:
                top = max(top, cmoved[e, c])
                c += 1
            moved[e, p] = top
    return dv, moved, box, cmoved, cbox


@njit(cache=True, nogil=True)
def stale_rows(
    Y,
    kth,
    far,
    epoch,
    moved,
    dv,
    box,
    Vm,
    cand,
    start,
    members,
    gstart,
    gmembers,
    pchunk,
    cstart,
    cmoved,
    cbox,
):
    """Points whose ``k`` nearest candidates may miss a nearer vertex
    (:mod:`~meshmocap.trackers.patch.nearest`): point t (``Y[t]``, k-th candidate at
    ``kth[t]``, every other vertex at least ``far[t]`` away at snapshot ``epoch[t]``) is
    stale if a vertex outside its candidates ``cand[t]`` (m, K) now lies within ``kth[t]``
    (ties included). Only a vertex that moved at least ``far[t] − kth[t]`` since that
    snapshot (``dv[epoch[t]]`` (S, n), in patch order: patch ``p``'s vertices are
    ``members[start[p]:start[p + 1]]``, at ``Vm`` (n, 3) now, in that order) can, and only
    in a patch that moved that much (``moved`` (S, P), the most of its vertices) and whose
    bounding box now (``box`` (P, 6), :func:`vertex_moves`) reaches within ``kth[t]``,
    and there in the chunks of the patch (patch ``p``'s chunks ``pchunk[p]:pchunk[p + 1]``,
    chunk ``c`` its rows ``cstart[c]:cstart[c + 1]``) that moved that much (``cmoved``
    (S, C)) and whose box (``cbox`` (C, 6)) reaches; each distance counts a nanometre more
    movement for rounding. The patches come in
    groups (group ``g``: patches ``gmembers[gstart[g]:gstart[g + 1]]``, e.g. a bone's),
    and a point looks into a group only where the group moved that much and its box (all
    its patches') reaches. Returns (m,) bool."""
    m = Y.shape[0]
    S = moved.shape[0]
    n_g = gstart.shape[0] - 1
    K = cand.shape[1]
    gmoved = np.zeros((S, n_g))  # per snapshot, the most a group's patches moved
    gbox = np.empty((n_g, 6))  # each group's box: its patches' boxes together
    for g in range(n_g):
        for a in range(3):
            gbox[g, a] = np.inf
            gbox[g, 3 + a] = -np.inf
        for u in range(gstart[g], gstart[g + 1]):
            p = gmembers[u]
            for a in range(3):
                gbox[g, a] = min(gbox[g, a], box[p, a])
                gbox[g, 3 + a] = max(gbox[g, 3 + a], box[p, 3 + a])
            for e in range(S):
                gmoved[e, g] = max(gmoved[e, g], moved[e, p])
    out = np.zeros(m, dtype=np.bool_)
    for t in range(m):
        slack = far[t] - kth[t] - ZERO_EXTENT
        if not slack > 0:
            out[t] = True
            continue
        e = epoch[t]
        y0, y1, y2 = Y[t, 0], Y[t, 1], Y[t, 2]
        reach = kth[t] * kth[t] + ZERO_EXTENT
        for g in range(n_g):
            if gmoved[e, g] < slack:
                continue
            x = max(gbox[g, 0] - y0, y0 - gbox[g, 3], 0.0)
            y = max(gbox[g, 1] - y1, y1 - gbox[g, 4], 0.0)
            z = max(gbox[g, 2] - y2, y2 - gbox[g, 5], 0.0)
            if not x * x + y * y + z * z <= reach:  # no patch of the group reaches
                continue
            for u in range(gstart[g], gstart[g + 1]):
                p = gmembers[u]
                if moved[e, p] < slack:
                    continue
                x = max(box[p, 0] - y0, y0 - box[p, 3], 0.0)
                y = max(box[p, 1] - y1, y1 - box[p, 4], 0.0)
                z = max(box[p, 2] - y2, y2 - box[p, 5], 0.0)
                if not x * x + y * y + z * z <= reach:
                    continue
                for h in range(pchunk[p], pchunk[p + 1]):  # the patch reaches: its chunks
                    if cmoved[e, h] < slack:
                        continue
                    x = max(cbox[h, 0] - y0, y0 - cbox[h, 3], 0.0)
                    y = max(cbox[h, 1] - y1, y1 - cbox[h, 4], 0.0)
                    z = max(cbox[h, 2] - y2, y2 - cbox[h, 5], 0.0)
                    if not x * x + y * y + z * z <= reach:
                        continue
                    for s in range(cstart[h], cstart[h + 1]):  # the chunk reaches: its vertices
                        if dv[e, s] < slack:
                            continue
                        x = Vm[s, 0] - y0
                        y = Vm[s, 1] - y1
                        z = Vm[s, 2] - y2
                        d2 = x * x + y * y + z * z
                        if d2 > reach * (1.0 + REACH_ROUNDING):  # surely beyond kth[t]
                            continue
                        if not np.sqrt(d2) <= kth[t]:
                            continue
                        i = members[s]
                        known = False
                        for c in range(K):
                            if cand[t, c] == i:
                                known = True
                                break
                        if not known:  # a vertex within kth[t] that is not a candidate
                            out[t] = True
                            break
                    if out[t]:
                        break
                if out[t]:
                    break
            if out[t]:
                break
    return out


@njit(cache=True, nogil=True)
def patch_points(R, c, labels, D, N0):
    """Each vertex as its own patch places it, and its normal: ``R_k d + c_k`` and
    ``R_k n0`` with ``k = labels[i]``, for rest offsets ``D`` (n, 3) from the patch centres
    and rest normals ``N0`` (n, 3); patch rotations ``R`` (P, 3, 3), centres ``c`` (P, 3).
    Returns (n, 3), (n, 3) float64."""
    n = labels.shape[0]
    V = np.empty((n, 3))
    N = np.empty((n, 3))
    for i in range(n):
        k = labels[i]
        for a in range(3):
            V[i, a] = (R[k, a, 0] * D[i, 0] + R[k, a, 1] * D[i, 1]) + R[k, a, 2] * D[i, 2] + c[k, a]
            N[i, a] = (R[k, a, 0] * N0[i, 0] + R[k, a, 1] * N0[i, 1]) + R[k, a, 2] * N0[i, 2]
    return V, N


@njit(cache=True, nogil=True)
def rotated_moments(R, k, l, M):
    """``Q_ab = R_a M_ab R_bᵀ`` (E, 2, 2, 3, 3) for every neighbouring pair ``(k[e], l[e])``
    (``R_0 = R[k[e]]``, ``R_1 = R[l[e]]``) and rest moments ``M`` (E, 2, 2, 3, 3)
    (:func:`~meshmocap.trackers.patch.solver.add_rigidity`)."""
    E = k.shape[0]
    Q = np.empty((E, 2, 2, 3, 3))
    T = np.empty((3, 3))
    for e in range(E):
        for a in range(2):
            Ra = R[k[e]] if a == 0 else R[l[e]]
            for b in range(2):
                Rb = R[k[e]] if b == 0 else R[l[e]]
                for i in range(3):  # T = R_a M_ab
                    for j in range(3):
                        T[i, j] = (Ra[i, 0] * M[e, a, b, 0, j] + Ra[i, 1] * M[e, a, b, 1, j]) + Ra[
                            i, 2
                        ] * M[e, a, b, 2, j]
                for i in range(3):  # Q = T R_bᵀ
                    for j in range(3):
                        Q[e, a, b, i, j] = (T[i, 0] * Rb[j, 0] + T[i, 1] * Rb[j, 1]) + T[i, 2] * Rb[
                            j, 2
                        ]
    return Q


@njit(cache=True, nogil=True)
def factor_values(D, O, PJ, JJ, src):
    """The entries ``src`` (m,) int64 of a system's blocks concatenated as
    :class:`~meshmocap.trackers.patch.solver.System` orders them (``D`` (P, 6, 6), ``O``
    (E, 6, 6), ``O`` transposed, ``PJ`` (P, 2, 6, 3), ``PJ`` transposed, ``JJ`` (3K, 3K),
    each flattened), 0 where ``src`` is negative: (m,) float64, read where they lie
    instead of from a concatenated copy."""
    n0, n1, n3 = D.size, O.size, PJ.size
    Df, Of, Pf, Jf = D.ravel(), O.ravel(), PJ.ravel(), JJ.ravel()
    out = np.empty(src.shape[0])
    for i in range(src.shape[0]):
        j = src[i]
        if j < 0:
            out[i] = 0.0
        elif j < n0:
            out[i] = Df[j]
        elif j < n0 + n1:
            out[i] = Of[j - n0]
        elif j < n0 + 2 * n1:  # Oᵀ: (e, r, c) is O[e, c, r]
            j -= n0 + n1
            out[i] = O[j // 36, j % 6, (j // 6) % 6]
        elif j < n0 + 2 * n1 + n3:
            out[i] = Pf[j - n0 - 2 * n1]
        elif j < n0 + 2 * n1 + 2 * n3:  # PJᵀ: (p, end, r, c) is PJ[p, end, c, r]
            j -= n0 + 2 * n1 + n3
            out[i] = PJ[j // 36, (j // 18) % 2, j % 6, (j // 6) % 3]
        else:
            out[i] = Jf[j - n0 - 2 * n1 - 2 * n3]
    return out


@njit(cache=True, nogil=True)
def block_cholesky(L, colptr, rowidx, row_ptr, row_col, row_entry):
    """In place, the Cholesky factor of a symmetric positive definite matrix stored as the
    lower 3×3 blocks ``L`` (nnz, 3, 3) of its factor's pattern (compressed columns
    ``colptr`` (nb + 1,), block rows ``rowidx`` (nnz,), each column's diagonal block first
    and its rows increasing; fill blocks zero). Left-looking, column by column: column
    ``j`` is updated by every column ``k = row_col[t]`` whose block in row ``j`` is the
    entry ``row_entry[t]`` of ``L``, ``t`` in ``row_ptr[j]:row_ptr[j + 1]`` (the factor's
    row structure). Returns False (``L`` spoiled) where a pivot is not positive: the
    matrix is not positive definite to rounding."""
    nb = colptr.shape[0] - 1
    pos = np.zeros(nb, dtype=np.int64)
    for j in range(nb):
        for e in range(colptr[j], colptr[j + 1]):
            pos[rowidx[e]] = e
        for t in range(row_ptr[j], row_ptr[j + 1]):
            ejk = row_entry[t]  # L[j, k]: the rows of column k from j on follow it
            # L[j, k] in scalars (column k < j: no block of it is written here)
            b00, b01, b02 = L[ejk, 0, 0], L[ejk, 0, 1], L[ejk, 0, 2]
            b10, b11, b12 = L[ejk, 1, 0], L[ejk, 1, 1], L[ejk, 1, 2]
            b20, b21, b22 = L[ejk, 2, 0], L[ejk, 2, 1], L[ejk, 2, 2]
            for e in range(ejk, colptr[row_col[t] + 1]):  # L[i, j] −= L[i, k] L[j, k]ᵀ
                dst = pos[rowidx[e]]
                for a in range(3):
                    a0, a1, a2 = L[e, a, 0], L[e, a, 1], L[e, a, 2]
                    L[dst, a, 0] -= (a0 * b00 + a1 * b01) + a2 * b02
                    L[dst, a, 1] -= (a0 * b10 + a1 * b11) + a2 * b12
                    L[dst, a, 2] -= (a0 * b20 + a1 * b21) + a2 * b22
        d = colptr[j]  # the diagonal block: its 3×3 Cholesky factor
        for a in range(3):
            s = L[d, a, a]
            for c in range(a):
                s -= L[d, a, c] * L[d, a, c]
            if not s > 0.0:
                return False
            L[d, a, a] = np.sqrt(s)
            for b in range(a + 1, 3):
                s = L[d, b, a]
                for c in range(a):
                    s -= L[d, b, c] * L[d, a, c]
                L[d, b, a] = s / L[d, a, a]
            for b in range(a + 1, 3):
                L[d, a, b] = 0.0
        for e in range(d + 1, colptr[j + 1]):  # L[i, j] = A[i, j] L[j, j]⁻ᵀ
            for r in range(3):
                for a in range(3):
                    s = L[e, r, a]
                    for c in range(a):
                        s -= L[e, r, c] * L[d, a, c]
                    L[e, r, a] = s / L[d, a, a]
    return True


@njit(cache=True, nogil=True)
def block_cholesky_solve(L, colptr, rowidx, b):
    """``x`` (nb, 3) of ``L Lᵀ x = b`` (nb, 3) for the factor ``L`` of
    :func:`block_cholesky` (same storage): forward, then backward substitution."""
    nb = colptr.shape[0] - 1
    x = b.copy()
    for j in range(nb):  # L y = b
        d = colptr[j]
        for a in range(3):
            s = x[j, a]
            for c in range(a):
                s -= L[d, a, c] * x[j, c]
            x[j, a] = s / L[d, a, a]
        for e in range(d + 1, colptr[j + 1]):
            i = rowidx[e]
            for a in range(3):
                x[i, a] -= (L[e, a, 0] * x[j, 0] + L[e, a, 1] * x[j, 1]) + L[e, a, 2] * x[j, 2]
    for j in range(nb - 1, -1, -1):  # Lᵀ x = y
        d = colptr[j]
        for e in range(d + 1, colptr[j + 1]):
            i = rowidx[e]
            for a in range(3):
                x[j, a] -= (L[e, 0, a] * x[i, 0] + L[e, 1, a] * x[i, 1]) + L[e, 2, a] * x[i, 2]
        for a in range(2, -1, -1):
            s = x[j, a]
            for c in range(a + 1, 3):
                s -= L[d, c, a] * x[j, c]
            x[j, a] = s / L[d, a, a]
    return x


@njit(cache=True, nogil=True)
def rigidity_blocks(R, c, k, l, W, m, M):
    """The rigidity term (Eq. 2) from the pairs' rest moments, one pass
    (:func:`~meshmocap.trackers.patch.solver.add_rigidity`, which states the algebra): per
    neighbouring pair ``(k[e], l[e])`` with moments ``W`` (E,), ``m`` (E, 2, 3), ``M``
    (E, 2, 2, 3, 3), the 6×6 blocks ``H_kk``, ``H_ll`` (in ``H2[:E]``, ``H2[E:]``) and
    ``H_kl`` (E, 6, 6), the gradient pieces of patch k and patch l (E, 2, 6), and the
    energy; patch rotations ``R`` (P, 3, 3), centres ``c`` (P, 3)."""
    E = k.shape[0]
    Q = rotated_moments(R, k, l, M)
    H2 = np.zeros((2 * E, 6, 6))
    Hkl = np.zeros((E, 6, 6))
    G = np.zeros((E, 2, 6))
    s = np.empty((2, 3))
    dc = np.empty(3)
    value = 0.0
    for e in range(E):
        w = W[e]
        for a in range(2):
            Ra = R[k[e]] if a == 0 else R[l[e]]
            for i in range(3):
                s[a, i] = (Ra[i, 0] * m[e, a, 0] + Ra[i, 1] * m[e, a, 1]) + Ra[i, 2] * m[e, a, 2]
        for i in range(3):
            dc[i] = c[k[e], i] - c[l[e], i]
        t00 = Q[e, 0, 0, 0, 0] + Q[e, 0, 0, 1, 1] + Q[e, 0, 0, 2, 2]
        t11 = Q[e, 1, 1, 0, 0] + Q[e, 1, 1, 1, 1] + Q[e, 1, 1, 2, 2]
        t01 = Q[e, 0, 1, 0, 0] + Q[e, 0, 1, 1, 1] + Q[e, 0, 1, 2, 2]
        value += t00 + t11 - 2.0 * t01
        for i in range(3):
            value += 2.0 * dc[i] * (s[0, i] - s[1, i]) + w * dc[i] * dc[i]
        # Σ w A(q_a)ᵀ A(q_b) = [[tr(Q_ab) I − Q_ba, [s_a]×], [−[s_b]×, W I]]
        for blk in range(3):  # H_kk, H_ll, −H_kl
            a, b = (0, 0) if blk == 0 else ((1, 1) if blk == 1 else (0, 1))
            tr = t00 if blk == 0 else (t11 if blk == 1 else t01)
            sign = -1.0 if blk == 2 else 1.0
            for i in range(3):
                for j in range(3):
                    v = -Q[e, b, a, i, j]
                    if i == j:
                        v += tr
                    if blk == 0:
                        H2[e, i, j] = v
                    elif blk == 1:
                        H2[E + e, i, j] = v
                    else:
                        Hkl[e, i, j] = -v
            sa0, sa1, sa2 = s[a, 0], s[a, 1], s[a, 2]
            sb0, sb1, sb2 = s[b, 0], s[b, 1], s[b, 2]
            X = H2[e] if blk == 0 else (H2[E + e] if blk == 1 else Hkl[e])
            # [s_a]× top right, −[s_b]× bottom left, W I bottom right
            X[0, 4], X[0, 5] = -sa2 * sign, sa1 * sign
            X[1, 3], X[1, 5] = sa2 * sign, -sa0 * sign
            X[2, 3], X[2, 4] = -sa1 * sign, sa0 * sign
            X[4, 0], X[5, 0] = -sb2 * sign, sb1 * sign
            X[3, 1], X[5, 1] = sb2 * sign, -sb0 * sign
            X[3, 2], X[4, 2] = -sb1 * sign, sb0 * sign
            X[3, 3] = w * sign
            X[4, 4] = w * sign
            X[5, 5] = w * sign
        # gradient: Σ w A(q_a)ᵀ r, r = q_k − q_l + Δc; Σ w q_a × q_b = axial(Q_ba − Q_ab)
        for a in range(2):
            sign = 1.0 if a == 0 else -1.0
            for i in range(3):
                i1, i2 = (i + 1) % 3, (i + 2) % 3
                # axial(S)_i = (S[i2, i1] − S[i1, i2]) / 2 for S = Q_0a − Q_a0 − Q_1a + Q_a1
                ax = 0.5 * (
                    (Q[e, 0, a, i2, i1] - Q[e, a, 0, i2, i1])
                    - (Q[e, 0, a, i1, i2] - Q[e, a, 0, i1, i2])
                    - (Q[e, 1, a, i2, i1] - Q[e, a, 1, i2, i1])
                    + (Q[e, 1, a, i1, i2] - Q[e, a, 1, i1, i2])
                )
                cross = s[a, i1] * dc[i2] - s[a, i2] * dc[i1]
                G[e, a, i] = sign * (ax + cross)
                G[e, a, 3 + i] = sign * (s[0, i] - s[1, i] + w * dc[i])
    return H2, Hkl, G, value
