"""The patch tracker's normal equations: gradients against float64 finite differences."""

import numpy as np
import pytest

from meshmocap.body.template import load_template
from meshmocap.geometry.rotations import so3_exp
from meshmocap.trackers.patch.model import build_patch_model
from meshmocap.trackers.patch.solver import (
    System,
    add_bone,
    add_bone_lengths,
    add_point_terms,
    add_rigidity,
    normal_pattern,
)

RNG = np.random.default_rng(0)


@pytest.fixture(scope="module")
def setup(patch_problem):
    return patch_problem


def _energies(m, R, c, X, obs):
    """Each term summed directly over its residuals (the definitions, no moments)."""
    patch, v, y, w = obs
    x = lambda k, vv: np.einsum("nij,nj->ni", R[k], m.V0[vv] - m.centres0[k]) + c[k]  # noqa: E731
    e_data = np.sum(w * np.sum((x(patch, v) - y) ** 2, axis=1))
    r = x(m.rig_k, m.rig_v) - x(m.rig_l, m.rig_v)
    e_rig = np.sum(m.rig_w * np.sum(r * r, axis=1))  # Eq. (2)
    T = np.einsum("kij,kj->ki", R, m.delta0 - m.centres0) + c
    D = m.gamma[:, None] * X[m.bone_j] + (1 - m.gamma)[:, None] * X[m.bone_child]
    e_bone = np.sum(m.bone_w * np.sum((T - D) ** 2, axis=1))  # Eq. (11)
    return e_data, e_rig, e_bone


def _system(m, mom, R, c, X, obs):
    patch, v, y, w = obs
    sys = System.empty(normal_pattern(m, 15))
    q = np.einsum("nij,nj->ni", R[patch], m.V0[v] - m.centres0[patch])
    e = (
        add_point_terms(sys, patch, q, q + c[patch] - y, w, 1.0),
        add_rigidity(sys, m, mom, R, c, 1.0),
        add_bone(sys, m, R, c, X, 1.0),
    )
    return sys, e


def _perturbed(m, R, c, X, delta):
    d = delta[: 6 * m.P].reshape(m.P, 6)
    return so3_exp(d[:, :3]) @ R, c + d[:, 3:], X + delta[6 * m.P :].reshape(-1, 3)


def test_energy_values_match_their_definitions(setup):
    m, mom, R, c, X, obs = setup
    _, e = _system(m, mom, R, c, X, obs)
    assert np.allclose(e, _energies(m, R, c, X, obs), rtol=1e-10)


@pytest.mark.parametrize("term", [0, 1, 2])
def test_gradients_match_finite_differences(setup, term):
    m, mom, R, c, X, obs = setup
    # gradient of one term alone
    only = System.empty(normal_pattern(m, 15))
    patch, v, y, w = obs
    if term == 0:
        q = np.einsum("nij,nj->ni", R[patch], m.V0[v] - m.centres0[patch])
        add_point_terms(only, patch, q, q + c[patch] - y, w, 1.0)
    elif term == 1:
        add_rigidity(only, m, mom, R, c, 1.0)
    else:
        add_bone(only, m, R, c, X, 1.0)
    n = 6 * m.P + 45
    idx = RNG.choice(n, 40, replace=False)
    h = 1e-6
    for i in idx:
        d = np.zeros(n)
        d[i] = h
        ep = _energies(m, *_perturbed(m, R, c, X, d), obs)[term]
        em = _energies(m, *_perturbed(m, R, c, X, -d), obs)[term]
        fd = (ep - em) / (2 * h)
        # ∇(Σ w|r|²) = 2 Jᵀ W r = 2 g; central differences are accurate to ~h² · E''' ≈ 1e-9
        assert fd == pytest.approx(2 * only.g[i], rel=1e-5, abs=1e-7), i


def test_a_gauss_newton_step_lowers_the_energy(setup):
    m, mom, R, c, X, obs = setup
    sys, e = _system(m, mom, R, c, X, obs)
    delta = sys.solve(1e-6)
    e2 = _energies(m, *_perturbed(m, R, c, X, delta), obs)
    assert sum(e2) < 0.5 * sum(e)


def test_point_to_plane_gradient(setup):
    from meshmocap.trackers.patch.solver import add_plane_terms

    m, _, R, c, X, (patch, v, y, w) = setup
    n = RNG.normal(size=(len(y), 3))
    n /= np.linalg.norm(n, axis=1, keepdims=True)

    def energy(R, c):
        x = np.einsum("nij,nj->ni", R[patch], m.V0[v] - m.centres0[patch]) + c[patch]
        return np.sum(w * np.sum(n * (x - y), axis=1) ** 2)

    sys = System.empty(normal_pattern(m, 15))
    q = np.einsum("nij,nj->ni", R[patch], m.V0[v] - m.centres0[patch])
    s = np.sum(n * (q + c[patch] - y), axis=1)
    assert add_plane_terms(sys, patch, q, n, s, w, 1.0) == pytest.approx(energy(R, c), rel=1e-12)
    h = 1e-6
    for i in RNG.choice(6 * m.P, 30, replace=False):
        d = np.zeros(6 * m.P + 45)
        d[i] = h
        Rp, cp, _ = _perturbed(m, R, c, X, d)
        Rm, cm, _ = _perturbed(m, R, c, X, -d)
        fd = (energy(Rp, cp) - energy(Rm, cm)) / (2 * h)
        assert fd == pytest.approx(2 * sys.g[i], rel=1e-5, abs=1e-7)


def test_compiled_plane_rows_equal_the_numpy_ones(setup):
    """The point-to-plane rows of vertices moved by their own patch, formed and summed in
    one compiled pass (add_plane_vertex_terms, as the data term adds them): the blocks,
    gradient and value of add_plane_terms on the same rows, to rounding, and symmetric
    blocks (the gradient of these rows is checked against finite differences above)."""
    from meshmocap.trackers.patch.solver import add_plane_terms, add_plane_vertex_terms

    m, _, R, c, _, (patch, v, y, w) = setup
    n = RNG.normal(size=(len(y), 3))
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    V = np.einsum("nij,nj->ni", R[m.labels], m.V0 - m.centres0[m.labels]) + c[m.labels]
    ref, new = System.empty(normal_pattern(m, 15)), System.empty(normal_pattern(m, 15))
    q = V[v] - c[patch]
    e_ref = add_plane_terms(ref, patch, q, n, np.sum(n * (V[v] - y), axis=1), w, 0.7)
    e_new = add_plane_vertex_terms(new, patch, v, V, c, y, n, w, 0.7)
    assert e_new == pytest.approx(e_ref, rel=1e-12)
    assert np.allclose(new.D, ref.D, rtol=1e-10, atol=1e-14 * np.abs(ref.D).max())
    assert np.allclose(new.g, ref.g, rtol=1e-10, atol=1e-14 * np.abs(ref.g).max())
    assert np.array_equal(new.D, np.swapaxes(new.D, 1, 2))


def test_the_solve_agrees_with_a_direct_solve_on_the_coordinates(setup):
    """The pattern's precomputed order and compressed columns give the step of a direct
    sparse solve of the same equations assembled from coordinates (block by block, with
    scipy summing duplicates), to rounding (1e-9 of the step: both are exact solvers)."""
    import scipy.sparse as sp
    import scipy.sparse.linalg as spla

    m, mom, R, c, X, obs = setup
    sys, _ = _system(m, mom, R, c, X, obs)
    step = sys.solve(1e-4)
    n, base, K = sys.n, 6 * m.P, 15
    rows, cols, vals = [], [], []

    def put(r0, c0, B):
        a, b = B.shape[1:]
        rr = np.broadcast_to(r0[:, None, None] + np.arange(a)[:, None], B.shape)
        cc = np.broadcast_to(c0[:, None, None] + np.arange(b), B.shape)
        rows.append(rr.ravel()), cols.append(cc.ravel()), vals.append(B.ravel())

    k, l = m.pairs.T
    put(6 * np.arange(m.P), 6 * np.arange(m.P), sys.D)
    put(6 * k, 6 * l, sys.O)
    put(6 * l, 6 * k, np.swapaxes(sys.O, 1, 2))
    for end, j in enumerate((m.bone_j, m.bone_child)):
        put(6 * np.arange(m.P), base + 3 * j, sys.PJ[:, end])
        put(base + 3 * j, 6 * np.arange(m.P), np.swapaxes(sys.PJ[:, end], 1, 2))
    put(np.array([base]), np.array([base]), sys.JJ.reshape(1, 3 * K, 3 * K))
    H = sp.csc_matrix(
        (np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))), shape=(n, n)
    )
    d = H.diagonal()
    H = H + sp.diags(1e-4 * d + 1e-3 * np.median(d[d > 0]))
    assert abs(sys.matrix(1e-4) - H).max() <= 1e-12 * abs(H).max()
    direct = spla.spsolve(H.tocsc(), -sys.g)
    assert np.abs(step - direct).max() <= 1e-9 * np.abs(direct).max()


def test_patches_bind_to_the_nearest_bone_at_their_joint():
    """A belly or mid-chest patch well below the thorax joint follows the spine
    (pelvis → thorax), not a thorax → shoulder bone 25 cm above it; every patch's bone
    touches the joint of its body part."""
    t = load_template("neutral_5k")
    m = build_patch_model(t, n_patches=120, seed=0)
    ev = t.eval_skeleton
    thorax, pelvis = ev.names.index("thorax"), ev.names.index("pelvis")
    X = ev.rest_positions
    part = m.classes[m.bone_of_patch]
    assert np.all((m.bone_j == part) | (m.bone_child == part))
    c = m.centres0
    low_chest = (part == thorax) & (c[:, 2] < X[thorax, 2] - 0.15) & (np.abs(c[:, 0]) < 0.1)
    assert low_chest.sum() >= 3
    assert np.all(m.bone_j[low_chest] == pelvis) and np.all(m.bone_child[low_chest] == thorax)


def test_bone_length_prior_gradient_and_hessian(setup):
    """The optional bone-length prior (bones and a hip-to-hip pair): gradient against
    central differences (float64, h = 1e-6, accurate to ~1e-9), and a step of its
    Gauss–Newton Hessian restores the lengths."""
    m, _, _, _, X, _ = setup
    t = load_template("neutral_5k")
    parents = t.eval_skeleton.parents
    b = np.flatnonzero(parents >= 0)
    ev = t.eval_skeleton.names
    pairs = np.vstack(
        [np.stack([b, parents[b]], 1), [[ev.index("left_hip"), ev.index("right_hip")]]]
    )
    P0 = t.eval_skeleton.rest_positions
    L = np.linalg.norm(P0[pairs[:, 0]] - P0[pairs[:, 1]], axis=1)

    def energy(Xv):
        d = np.linalg.norm(Xv[pairs[:, 0]] - Xv[pairs[:, 1]], axis=1)
        return np.sum((d - L) ** 2)

    sys = System.empty(normal_pattern(m, 15))
    value = add_bone_lengths(sys, X, pairs, L, 1.0)
    assert value == pytest.approx(energy(X), rel=1e-12)
    g = sys.g[6 * m.P :]
    h = 1e-6
    for i in range(45):
        d = np.zeros(45)
        d[i] = h
        fd = (energy(X + d.reshape(15, 3)) - energy(X - d.reshape(15, 3))) / (2 * h)
        assert fd == pytest.approx(2 * g[i], rel=1e-5, abs=1e-8), i
    # a step of the prior alone restores every bone length to first order
    step = sys.solve(1e-9)[6 * m.P :].reshape(15, 3)
    assert energy(X + step) < 0.05 * energy(X)


def test_bone_length_blocks_are_the_numpy_expressions_they_replaced(setup):
    """The prior's compiled pass adds, bit for bit, what its numpy expressions added:
    ``weight · u uᵀ`` with ``np.add.at`` at (b, b), (p, p), −(b, p), −(p, b), and the
    gradient pieces ``± weight · r u`` through ``np.bincount``, to a system already holding
    other terms (repeated joints accumulate in pair order)."""
    from meshmocap.trackers.patch.solver import length_residuals

    m, mom, R, c, X, obs = setup
    pairs = np.array([[1, 0], [2, 1], [3, 1], [4, 3], [3, 4], [5, 0]])
    L = RNG.uniform(0.1, 0.4, size=len(pairs))
    sys, _ = _system(m, mom, R, c, X, obs)
    JJ, g = sys.JJ.copy(), sys.g.copy()
    add_bone_lengths(sys, X, pairs, L, 7.3)
    K, w = 15, 7.3
    b, p = pairs[:, 0], pairs[:, 1]
    u, r = length_residuals(X, pairs, L)
    uu = w * u[:, :, None] * u[:, None, :]
    a_, b_ = np.concatenate([b, p, b, p]), np.concatenate([b, p, p, b])
    blocks = np.concatenate([uu, uu, -uu, -uu])
    np.add.at(JJ.reshape(K, 3, K, 3), (a_, slice(None), b_, slice(None)), blocks)
    for rows, G in ((6 * m.P + 3 * b, w * r[:, None] * u), (6 * m.P + 3 * p, -w * r[:, None] * u)):
        idx = rows[:, None] + np.arange(3)
        g += np.bincount(idx.ravel(), G.ravel(), minlength=len(g))
    assert np.array_equal(sys.JJ, JJ)
    assert np.array_equal(sys.g, g)


def _block_sparse_spd(nb: int, seed: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A symmetric positive definite (3 nb, 3 nb) matrix on a random sparse pattern of
    3×3 blocks (a ring of blocks plus random pairs), with its entries' rows and columns."""
    rng = np.random.default_rng(seed)
    pairs = {(i, (i + 1) % nb) for i in range(nb)}
    pairs |= {tuple(p) for p in rng.integers(0, nb, size=(nb, 2)) if p[0] != p[1]}
    n = 3 * nb
    A = np.zeros((n, n))
    for i, j in pairs:
        B = rng.normal(size=(3, 3))
        A[3 * i : 3 * i + 3, 3 * j : 3 * j + 3] += B
        A[3 * j : 3 * j + 3, 3 * i : 3 * i + 3] += B.T
    for i in range(nb):
        A[3 * i : 3 * i + 3, 3 * i : 3 * i + 3] = np.eye(3)
    A += np.eye(n) * (np.abs(A).sum(axis=1).max() + 1.0)  # diagonally dominant
    rows, cols = np.nonzero(A)
    return A, rows, cols


def test_block_cholesky_solves_a_sparse_definite_system():
    """The 3×3-block Cholesky factor on its precomputed structure (a minimum-degree order
    and the fill) solves a random block-sparse definite system to 1e-12 of a dense solve,
    and reports an indefinite one (a negative pivot) instead of returning a step."""
    from meshmocap.trackers.patch.kernels import block_cholesky, block_cholesky_solve
    from meshmocap.trackers.patch.solver import block_factor

    A, rows, cols = _block_sparse_spd(40, seed=1)
    f = block_factor(rows, cols, len(A))
    assert np.all(f.src[f.src >= 0] < len(rows))
    b = RNG.normal(size=len(A))

    def factor(M):
        L = np.where(f.src >= 0, M[rows, cols][f.src], 0.0).reshape(-1, 3, 3)
        return L, block_cholesky(L, f.colptr, f.rowidx, f.row_ptr, f.row_col, f.row_entry)

    L, ok = factor(A)
    assert ok
    x = np.empty(len(A))
    rhs = np.ascontiguousarray(b[f.scalar].reshape(-1, 3))
    x[f.scalar] = block_cholesky_solve(L, f.colptr, f.rowidx, rhs).ravel()
    direct = np.linalg.solve(A, b)
    assert np.abs(x - direct).max() <= 1e-12 * np.abs(direct).max()
    bad = A.copy()
    bad[5, 5] = -1.0
    assert not factor(bad)[1]


def test_the_factor_reads_the_blocks_where_they_lie(setup):
    """The factor's entries, read from the block arrays (transposes included), are the
    concatenated blocks' to the bit, and 0 at its fill."""
    from meshmocap.trackers.patch.kernels import factor_values

    m = setup[0]
    sys = System.empty(normal_pattern(m, 15))
    for a in (sys.D, sys.O, sys.PJ, sys.JJ):
        a[...] = RNG.normal(size=a.shape)
    f = sys.pattern.factor
    want = sys._blocks()[f.src]
    want[f.src < 0] = 0.0
    assert (f.src < 0).any()
    assert np.array_equal(factor_values(sys.D, sys.O, sys.PJ, sys.JJ, f.src), want)
