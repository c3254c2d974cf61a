"""Compiled loops (numba) behind :mod:`meshmocap.body.articulated_system`.

Each loop runs once per Gauss–Newton iteration over a few thousand small terms (3×3
products per nonzero skinning weight, per pair of weights, per correspondence): as numpy
array expressions the normal equations alone cost 3–6 ms an iteration, compiled 0.2 ms.
Compiled on first use and cached beside this file (``cache=True``); the arithmetic is the
numpy functions' own, in the same order (``tests/trackers/test_articulated_icp.py`` compares).
"""

from __future__ import annotations

import numpy as np

from meshmocap._numba import njit
from meshmocap._tolerances import NORM_FLOOR


@njit(cache=True, nogil=True)
def pair_moments_kernel(v, i, y, ny, s, plane):  # pragma: no cover - compiled
    """S (m, 3, 3), b (m, 3), r² (p,) of :func:`~.articulated_system.pair_moments`."""
    m, p = v.shape[0], i.shape[0]
    S = np.zeros((m, 3, 3))
    b = np.zeros((m, 3))
    r2 = np.empty(p)
    for t in range(p):
        k = i[t]
        d0, d1, d2 = v[k, 0] - y[t, 0], v[k, 1] - y[t, 1], v[k, 2] - y[t, 2]
        if plane:
            n0, n1, n2 = ny[t, 0], ny[t, 1], ny[t, 2]
            r = n0 * d0 + n1 * d1 + n2 * d2
            r2[t] = r * r
            sr = s[t] * r
            b[k, 0] += sr * n0
            b[k, 1] += sr * n1
            b[k, 2] += sr * n2
            for a in range(3):
                sa = s[t] * ny[t, a]
                for c in range(3):
                    S[k, a, c] += sa * ny[t, c]
        else:
            r2[t] = d0 * d0 + d1 * d1 + d2 * d2
            b[k, 0] += s[t] * d0
            b[k, 1] += s[t] * d1
            b[k, 2] += s[t] * d2
            for a in range(3):
                S[k, a, a] += s[t]
    return S, b, r2


@njit(cache=True, nogil=True)
def weight_moments_kernel(indptr, cols, w, q, S, b, J):  # pragma: no cover - compiled
    """The per-joint moments of :func:`~.articulated_system.normal_equations`.

    Returns ``M`` (J, J, 3, 3, 3): for the ordered pairs (e, e') of nonzero weights of the
    same point binned by their joints (k, k'), ``Σ [q_e]× S_i [q_e']×`` (minus the A of the
    module docstring), ``B = Σ w_e S_i [q_e']×ᵀ`` and ``D = Σ w_e w_e' S_i``; ``EF`` (J, 2,
    3, 3): ``E_k = Σ S_i [q_e]×ᵀ`` and ``F_k = Σ w_e S_i`` over the weights on joint k;
    ``gk`` (J, 6): ``Σ q_e × b_i`` and ``Σ w_e b_i`` over the same.
    """
    nnz = cols.shape[0]
    X = np.empty((nnz, 3, 3))  # [q_e]× S_i, column c = q_e × S_i[:, c]
    M = np.zeros((J, J, 3, 3, 3))
    EF = np.zeros((J, 2, 3, 3))
    gk = np.zeros((J, 6))
    for i in range(indptr.shape[0] - 1):
        lo, hi = indptr[i], indptr[i + 1]
        for e in range(lo, hi):
            qx, qy, qz = q[e, 0], q[e, 1], q[e, 2]
            for c in range(3):
                s0, s1, s2 = S[i, 0, c], S[i, 1, c], S[i, 2, c]
                X[e, 0, c] = qy * s2 - qz * s1
                X[e, 1, c] = qz * s0 - qx * s2
                X[e, 2, c] = qx * s1 - qy * s0
        b0, b1, b2 = b[i, 0], b[i, 1], b[i, 2]
        for e in range(lo, hi):
            k, we = cols[e], w[e]
            qx, qy, qz = q[e, 0], q[e, 1], q[e, 2]
            for a in range(3):
                for c in range(3):
                    EF[k, 0, a, c] += X[e, c, a]
                    EF[k, 1, a, c] += we * S[i, a, c]
            gk[k, 0] += qy * b2 - qz * b1
            gk[k, 1] += qz * b0 - qx * b2
            gk[k, 2] += qx * b1 - qy * b0
            gk[k, 3] += we * b0
            gk[k, 4] += we * b1
            gk[k, 5] += we * b2
            for f in range(lo, hi):
                k2, wf = cols[f], w[f]
                ux, uy, uz = q[f, 0], q[f, 1], q[f, 2]
                for a in range(3):  # row a of X_e [q_f]× is X_e[a] × q_f
                    xa0, xa1, xa2 = X[e, a, 0], X[e, a, 1], X[e, a, 2]
                    M[k, k2, 0, a, 0] += xa1 * uz - xa2 * uy
                    M[k, k2, 0, a, 1] += xa2 * ux - xa0 * uz
                    M[k, k2, 0, a, 2] += xa0 * uy - xa1 * ux
                    for c in range(3):
                        M[k, k2, 1, a, c] += we * X[f, c, a]
                        M[k, k2, 2, a, c] += we * wf * S[i, a, c]
    return M, EF, gk


@njit(cache=True, nogil=True)
def _skew_mul(p, X, out, left):  # pragma: no cover - compiled
    """``out`` ← [p]× X (left) or X [p]× for a 3×3 X."""
    for c in range(3):
        if left:  # column c of [p]× X is p × X[:, c]
            x0, x1, x2 = X[0, c], X[1, c], X[2, c]
            out[0, c] = p[1] * x2 - p[2] * x1
            out[1, c] = p[2] * x0 - p[0] * x2
            out[2, c] = p[0] * x1 - p[1] * x0
        else:  # row c of X [p]× is X[c] × p
            x0, x1, x2 = X[c, 0], X[c, 1], X[c, 2]
            out[c, 0] = x1 * p[2] - x2 * p[1]
            out[c, 1] = x2 * p[0] - x0 * p[2]
            out[c, 2] = x0 * p[1] - x1 * p[0]


@njit(cache=True, nogil=True)
def normal_equations_kernel(indptr, cols, w, q, S, b, P, parents):  # pragma: no cover
    """H (3 + 3J, 3 + 3J) and g (3 + 3J,) of :func:`~.articulated_system.normal_equations`
    (``parents`` (J,) with every parent before its children, −1 at the root)."""
    J = P.shape[0]
    M, EF, gk = weight_moments_kernel(indptr, cols, w, q, S, b, J)
    Mf = M.reshape(J, J, 27)
    for k in range(J - 1, 0, -1):  # subtree sums: children come after their parents
        pk = parents[k]
        for a in range(3):
            for c in range(3):
                EF[pk, 0, a, c] += EF[k, 0, a, c]
                EF[pk, 1, a, c] += EF[k, 1, a, c]
        for a in range(6):
            gk[pk, a] += gk[k, a]
        for l in range(J):
            for a in range(27):
                Mf[pk, l, a] += Mf[k, l, a]
    for k in range(J - 1, 0, -1):
        pk = parents[k]
        for j in range(J):
            for a in range(27):
                Mf[j, pk, a] += Mf[j, k, a]
    n = 3 + 3 * J
    H = np.zeros((n, n))
    g = np.zeros(n)
    for i in range(S.shape[0]):
        for a in range(3):
            g[a] += b[i, a]
            for c in range(3):
                H[a, c] += S[i, a, c]
    T1, T2, U, PDP = np.empty((3, 3)), np.empty((3, 3)), np.empty((3, 3)), np.empty((3, 3))
    for j in range(J):
        o = 3 + 3 * j
        pj = P[j]
        _skew_mul(pj, EF[j, 1], T1, False)  # H_tj = Ē_j + F̄_j [p_j]×
        for a in range(3):
            for c in range(3):
                H[a, o + c] = H[o + c, a] = EF[j, 0, a, c] + T1[a, c]
        gj = gk[j]
        g[o] = gj[0] - (pj[1] * gj[5] - pj[2] * gj[4])
        g[o + 1] = gj[1] - (pj[2] * gj[3] - pj[0] * gj[5])
        g[o + 2] = gj[2] - (pj[0] * gj[4] - pj[1] * gj[3])
        for l in range(j, J):  # H is symmetric
            u = 3 + 3 * l
            _skew_mul(pj, M[j, l, 1], T1, True)  # [p_j]× B̄_jl
            _skew_mul(P[l], M[l, j, 1], T2, True)  # [p_l]× B̄_lj
            _skew_mul(pj, M[j, l, 2], U, True)
            _skew_mul(P[l], U, PDP, False)  # [p_j]× D̄_jl [p_l]×
            for a in range(3):
                for c in range(3):
                    h = -M[j, l, 0, a, c] - T1[a, c] - T2[c, a] - PDP[a, c]
                    H[o + a, u + c] = H[u + c, o + a] = h
    return H, g


@njit(cache=True, nogil=True, inline="always")
def _row_dot(M, a, x0, x1, x2):  # pragma: no cover - compiled
    """Row ``a`` of the 3×3 ``M`` times (x0, x1, x2), summed left to right."""
    return (M[a, 0] * x0 + M[a, 1] * x1) + M[a, 2] * x2


@njit(cache=True, nogil=True)
def posed_kernel(R, root, parents, offsets, rest, indptr, cols, w, Xe, N0):  # pragma: no cover
    """G (J, 3, 3), P (J, 3), q (nnz, 3), v (m, 3), n (m, 3) of
    :func:`~.articulated_system.posed_model`: forward kinematics
    (:func:`~meshmocap.body.skeleton.forward_kinematics`) and linear-blend skinning of the
    model points, ``q_e = w_e (G_k X_i + P_k − G_k P0_k)``, ``v_i = Σ_e q_e``, ``n_i`` the
    unit ``(Σ_e w_e G_k) N0_i``."""
    J = R.shape[0]
    G = np.empty((J, 3, 3))
    P = np.empty((J, 3))
    T = np.empty((J, 3))  # translations of the skinning transforms
    for j in range(J):
        p = parents[j]
        if p < 0:  # element by element: a slice assignment would compile numba's shape
            for a in range(3):  # mismatch message, the longest part of this kernel's compile
                P[j, a] = root[a]
                for c in range(3):
                    G[j, a, c] = R[j, a, c]
        else:
            o = offsets[j]
            for a in range(3):
                P[j, a] = P[p, a] + _row_dot(G[p], a, o[0], o[1], o[2])
                for c in range(3):
                    G[j, a, c] = _row_dot(G[p], a, R[j, 0, c], R[j, 1, c], R[j, 2, c])
        for a in range(3):
            T[j, a] = P[j, a] - _row_dot(G[j], a, rest[j, 0], rest[j, 1], rest[j, 2])
    m = indptr.shape[0] - 1
    q = np.empty((cols.shape[0], 3))
    v = np.zeros((m, 3))
    n = np.zeros((m, 3))
    B = np.empty((3, 3))
    for i in range(m):
        B[:] = 0.0
        for e in range(indptr[i], indptr[i + 1]):
            k, we = cols[e], w[e]
            for a in range(3):
                q[e, a] = we * (_row_dot(G[k], a, Xe[e, 0], Xe[e, 1], Xe[e, 2]) + T[k, a])
                v[i, a] += q[e, a]
                for c in range(3):
                    B[a, c] += we * G[k, a, c]
        for a in range(3):
            n[i, a] = _row_dot(B, a, N0[i, 0], N0[i, 1], N0[i, 2])
        norm = max(np.sqrt((n[i, 0] * n[i, 0] + n[i, 1] * n[i, 1]) + n[i, 2] * n[i, 2]), NORM_FLOOR)
        for a in range(3):
            n[i, a] /= norm
    return G, P, q, v, n


@njit(cache=True, nogil=True)
def point_motion_kernel(delta, P, q, indptr, cols, w, parents):  # pragma: no cover
    """(m, 3): ``t + Σ_e (Ω_k × q_e − w_e Π_k)`` of :func:`~.articulated_system.point_motion`,
    with Ω_k, Π_k the sums of ω_j and ω_j × p_j over the ancestors-or-self j of joint k."""
    J = P.shape[0]
    OP = np.empty((J, 6))
    for j in range(J):
        o0, o1, o2 = delta[3 + 3 * j], delta[4 + 3 * j], delta[5 + 3 * j]
        x = np.array(
            [
                o0,
                o1,
                o2,
                o1 * P[j, 2] - o2 * P[j, 1],
                o2 * P[j, 0] - o0 * P[j, 2],
                o0 * P[j, 1] - o1 * P[j, 0],
            ]
        )
        p = parents[j]
        for a in range(6):
            OP[j, a] = x[a] + (OP[p, a] if p >= 0 else 0.0)
    m = indptr.shape[0] - 1
    out = np.empty((m, 3))
    for i in range(m):
        d0, d1, d2 = delta[0], delta[1], delta[2]
        for e in range(indptr[i], indptr[i + 1]):
            k, we = cols[e], w[e]
            d0 += OP[k, 1] * q[e, 2] - OP[k, 2] * q[e, 1] - we * OP[k, 3]
            d1 += OP[k, 2] * q[e, 0] - OP[k, 0] * q[e, 2] - we * OP[k, 4]
            d2 += OP[k, 0] * q[e, 1] - OP[k, 1] * q[e, 0] - we * OP[k, 5]
        out[i, 0], out[i, 1], out[i, 2] = d0, d1, d2
    return out


@njit(cache=True, nogil=True)
def rotation_error_kernel(R, R_ref, G, parents):  # pragma: no cover - compiled
    """(J, 3): ``G_parent log(R_j R̂_jᵀ)``, each joint's rotation away from ``R_ref`` as a
    world-frame rotation vector (radians; ``G_parent = I`` at the root). The log goes
    through the unit quaternion (largest-component branch), exact near 0 and π."""
    J = R.shape[0]
    out = np.empty((J, 3))
    M = np.empty((3, 3))
    for j in range(J):
        for a in range(3):
            for c in range(3):
                M[a, c] = (R[j, a, 0] * R_ref[j, c, 0] + R[j, a, 1] * R_ref[j, c, 1]) + R[
                    j, a, 2
                ] * R_ref[j, c, 2]
        tr = M[0, 0] + M[1, 1] + M[2, 2]
        k = 3
        big = tr
        for a in range(3):
            if M[a, a] > big:
                big, k = M[a, a], a
        if k == 3:
            w = np.sqrt(1.0 + tr) / 2.0
            x, y, z = (
                (M[2, 1] - M[1, 2]) / (4 * w),
                (M[0, 2] - M[2, 0]) / (4 * w),
                (M[1, 0] - M[0, 1]) / (4 * w),
            )
        else:
            a1, a2 = (k + 1) % 3, (k + 2) % 3
            s = np.sqrt(1.0 + 2.0 * M[k, k] - tr) / 2.0  # |quaternion component k|
            v = np.empty(3)
            v[k] = s
            v[a1] = (M[a1, k] + M[k, a1]) / (4 * s)
            v[a2] = (M[a2, k] + M[k, a2]) / (4 * s)
            w = (M[a2, a1] - M[a1, a2]) / (4 * s)
            x, y, z = v[0], v[1], v[2]
        if w < 0:
            w, x, y, z = -w, -x, -y, -z
        norm = np.sqrt(x * x + y * y + z * z)
        angle = 2.0 * np.arctan2(norm, w)
        scale = angle / norm if norm > NORM_FLOOR else 2.0 / w  # Taylor: θ/sin(θ/2) → 2
        e0, e1, e2 = scale * x, scale * y, scale * z
        p = parents[j]
        if p < 0:
            out[j, 0], out[j, 1], out[j, 2] = e0, e1, e2
        else:
            for a in range(3):
                out[j, a] = (G[p, a, 0] * e0 + G[p, a, 1] * e1) + G[p, a, 2] * e2
    return out


@njit(cache=True, nogil=True)
def compatible_kernel(idx, n_tree, n_q, normal_cos, n):  # pragma: no cover - compiled
    """For the nearest tree point ``idx`` (q,) of each query (``n``: none within range):
    ``partner`` (q,) int64, that point when its normal agrees (``n_tree · n_q >
    normal_cos``), else −1; and the queries whose nearest point disagrees (to search
    further), in order."""
    q = idx.shape[0]
    partner = np.empty(q, dtype=np.int64)
    retry = np.empty(q, dtype=np.int64)
    r = 0
    for t in range(q):
        j = idx[t]
        partner[t] = -1
        if j >= n:
            continue
        c = (n_tree[j, 0] * n_q[t, 0] + n_tree[j, 1] * n_q[t, 1]) + n_tree[j, 2] * n_q[t, 2]
        if c > normal_cos:
            partner[t] = j
        else:
            retry[r] = t
            r += 1
    return partner, retry[:r]


@njit(cache=True, nogil=True)
def first_compatible_kernel(idx, n_tree, n_q, rows, normal_cos, n, partner):  # pragma: no cover
    """``partner[rows[t]]`` ← the first of the k nearest tree points ``idx[t]`` (k,) (by
    distance; ``n``: none) whose normal agrees with the query's ``n_q[rows[t]]``."""
    for t in range(rows.shape[0]):
        u = rows[t]
        for c in range(idx.shape[1]):
            j = idx[t, c]
            if j >= n:
                break
            d = (n_tree[j, 0] * n_q[u, 0] + n_tree[j, 1] * n_q[u, 1]) + n_tree[j, 2] * n_q[u, 2]
            if d > normal_cos:
                partner[u] = j
                break
