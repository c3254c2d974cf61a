"""Gauss–Newton normal equations of the patch tracker's energy (patch-skeleton-tracking.txt)

    E(Θ, J) = λr Er(Θ) + λd Edata(Θ) + λb Ebone(Θ, J)                              # Eq. (1)

over every patch's rotation and centre and every joint position together. A patch ``k``
predicts ``x_k(v) = R_k d_k(v) + c_k`` with ``d_k(v) = v0 − c0_k``; a step rotates it by
``exp(ω_k)`` (left) and moves its centre by ``δc_k``, so to first order
``δx = A(q) [ω_k; δc_k]`` with ``q = R_k d`` and ``A(q) = [−[q]×, I]``. Each term is a
weighted sum of squared 3-D residuals; the normal equations ``H δ = −g`` are assembled
block by block (6 unknowns per patch, then 3 per joint) on a sparsity :class:`Pattern`
computed once per patch model.

The rigidity term is assembled from per-pair moments of the rest offsets (precomputed
once), so its cost grows with the number of neighbouring pairs, not with vertices:
with ``Q_ab = Σ w q_a q_bᵀ = R_a M_ab R_bᵀ`` and ``s_a = Σ w q_a = R_a m_a``,
``Σ w A(q_a)ᵀ A(q_b) = [[tr(Q_ab) I − Q_ba, [s_a]×], [−[s_b]×, W I]]`` (from
``[a]×[b]× = b aᵀ − (a·b) I``).

References
----------
- C.-H. Huang, E. Boyer, S. Ilic, *Robust human body shape and pose tracking*,
  International Conference on 3D Vision (3DV), 2013.
- C. Cagniart, E. Boyer, S. Ilic, *Free-form mesh tracking: a patch-based
  approach*, IEEE Conference on Computer Vision and Pattern Recognition (CVPR), 2010.
- M. Straka, S. Hauswiesner, M. Rüther, H. Bischof, *Simultaneous shape and pose
  adaption of articulated models using linear optimization*, European Conference on
  Computer Vision (ECCV), 2012.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from meshmocap._tolerances import NORM_FLOOR
from meshmocap.geometry.levenberg_marquardt import (
    DAMPING,
    damped_diagonal,
    damped_solve,
    solve_damped,
)
from meshmocap.geometry.rotations import skew
from meshmocap.trackers.patch.kernels import (
    add_bone_joint_blocks,
    add_length_blocks,
    add_moment_blocks,
    add_pair_blocks,
    add_plane_blocks,
    block_cholesky,
    block_cholesky_solve,
    factor_values,
    point_moments,
    rigidity_blocks,
    vertex_moments,
)
from meshmocap.trackers.patch.model import PatchModel

#: ε of the damped solves, relative to the median diagonal entry
#: (:data:`~meshmocap.geometry.levenberg_marquardt.DAMPING` ``"patch"``).
FLOOR = DAMPING["patch"].floor


@dataclass(frozen=True, eq=False)
class RigidityMoments:
    """Per neighbouring pair (k, l), moments of the rest offsets ``d_k(v) = v0 − c0_k`` over
    the Eq. (2) terms: ``W = Σ w``, ``m_k = Σ w d_k``, ``M_ab = Σ w d_a d_bᵀ``."""

    W: np.ndarray  # (E,)
    m: np.ndarray  # (E, 2, 3): m_k, m_l
    M: np.ndarray  # (E, 2, 2, 3, 3): M_kk, M_kl, M_lk, M_ll


def rigidity_moments(model: PatchModel) -> RigidityMoments:
    """Precompute :class:`RigidityMoments` of a patch model."""
    E = len(model.pairs)
    pair = np.repeat(np.arange(E), np.bincount(_pair_index(model), minlength=E))
    order = np.argsort(_pair_index(model), kind="stable")
    v, k, l, w = (a[order] for a in (model.rig_v, model.rig_k, model.rig_l, model.rig_w))
    d = np.stack([model.V0[v] - model.centres0[k], model.V0[v] - model.centres0[l]], 1)  # (T, 2, 3)
    W = np.bincount(pair, w, minlength=E)
    m = np.zeros((E, 2, 3))
    np.add.at(m, pair, w[:, None, None] * d)
    outer = w[:, None, None, None, None] * d[:, :, None, :, None] * d[:, None, :, None, :]
    M = np.zeros((E, 2, 2, 3, 3))
    np.add.at(M, pair, outer)
    return RigidityMoments(W, m, M)


def _pair_index(model: PatchModel) -> np.ndarray:
    """Index into ``model.pairs`` of every rigidity term."""
    P = model.P
    key = model.pairs[:, 0] * P + model.pairs[:, 1]
    return np.searchsorted(key, model.rig_k * P + model.rig_l)


@dataclass(frozen=True, eq=False)
class BlockFactor:
    """Where the Cholesky factor of a :class:`Pattern`'s ``H`` has its 3×3 blocks (every
    unknown comes in threes: a patch's rotation, its centre, a joint), on a fill-reducing
    order of the blocks; :func:`~meshmocap.trackers.patch.kernels.block_cholesky` fills
    them in.

    Attributes
    ----------
    colptr, rowidx : compressed-column structure of the factor's blocks (block positions in
        the order; each column's diagonal block first, rows increasing)
    row_ptr, row_col, row_entry : its row structure: the blocks of row ``j`` are the entries
        ``row_entry[row_ptr[j]:row_ptr[j + 1]]`` in columns ``row_col[...]``
    src : (9 nnz,) int, index of each factor entry into the concatenated block arrays of a
        :class:`System` (−1: a fill entry, zero in ``H``)
    scalar : (n,) int, the unknown at each position of the ordered system
    diag : (n,) int, the flat factor entry of each unknown's diagonal
    """

    colptr: np.ndarray
    rowidx: np.ndarray
    row_ptr: np.ndarray
    row_col: np.ndarray
    row_entry: np.ndarray
    src: np.ndarray
    scalar: np.ndarray
    diag: np.ndarray


def block_factor(rows: np.ndarray, cols: np.ndarray, n: int) -> BlockFactor:
    """The :class:`BlockFactor` of a symmetric ``n × n`` matrix whose entries lie at
    ``rows``, ``cols`` (m,) int (both triangles, each entry once, in 3×3 blocks; ``n`` a
    multiple of 3): a minimum-degree order of the blocks (SuperLU's, on the block graph),
    then the factor's structure column by column (each column: the matrix's own below the
    diagonal and its children's in the elimination tree)."""
    nb = n // 3
    br, bc = rows // 3, cols // 3
    B = sp.csc_matrix((np.ones(len(br)), (br, bc)), shape=(nb, nb))
    B.sum_duplicates()
    B.data[:] = 1.0
    B = (B + sp.identity(nb, format="csc") * float(nb)).tocsc()
    lu = spla.splu(
        B, permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.0, options={"SymmetricMode": True}
    )
    pos = lu.perm_c  # block → position
    order = np.argsort(pos)  # position → block
    Bc = B.tocoo()
    pi, pj = pos[Bc.row], pos[Bc.col]
    low = pi > pj
    lower = sp.csc_matrix((np.ones(int(low.sum())), (pi[low], pj[low])), shape=(nb, nb))
    children: list[list[int]] = [[] for _ in range(nb)]
    struct: list[np.ndarray] = []
    for j in range(nb):  # symbolic factorisation along the elimination tree
        own = lower.indices[lower.indptr[j] : lower.indptr[j + 1]]
        s = np.union1d(
            np.concatenate([[j], own]),
            np.concatenate([struct[c][1:] for c in children[j]] or [np.zeros(0, np.int64)]).astype(
                np.int64
            ),
        )
        struct.append(s)
        if len(s) > 1:
            children[int(s[1])].append(j)
    counts = np.array([len(s) for s in struct])
    colptr = np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)
    rowidx = np.concatenate(struct).astype(np.int64)
    col = np.repeat(np.arange(nb), counts)
    off = np.flatnonzero(rowidx != col)
    by_row = off[np.argsort(rowidx[off], kind="stable")]
    row_ptr = np.concatenate([[0], np.cumsum(np.bincount(rowidx[off], minlength=nb))])
    # each factor entry's source among the matrix's entries (1-based; 0: fill)
    where = sp.csr_matrix((np.arange(1, len(rows) + 1), (rows, cols)), shape=(n, n))
    e3 = np.arange(3)
    r = (3 * order[rowidx])[:, None, None] + e3[None, :, None]
    c = (3 * order[col])[:, None, None] + e3[None, None, :]
    r, c = np.broadcast_arrays(r, c)
    src = np.asarray(where[r.ravel(), c.ravel()]).ravel().astype(np.int64) - 1
    scalar = (3 * order[:, None] + e3).ravel()
    u = np.arange(n)
    diag = 9 * colptr[pos[u // 3]] + 4 * (u % 3)
    return BlockFactor(
        colptr,
        rowidx,
        row_ptr.astype(np.int64),
        col[by_row].astype(np.int64),
        by_row.astype(np.int64),
        src,
        scalar.astype(np.int64),
        diag.astype(np.int64),
    )


@dataclass(frozen=True, eq=False)
class Pattern:
    """Sparsity of the normal equations of one patch model, fixed while tracking.

    ``H`` holds a dense 6×6 block per patch, one per neighbouring pair (and its transpose),
    a 6×3 block between each patch and each of its bone's two joints (and the transposes),
    and a dense joint–joint part (3K × 3K). Built once, it maps the block arrays of a
    :class:`System` straight onto the compressed-column entries of ``H`` in a fill-reducing
    order, so an iteration neither sorts coordinates nor recomputes the ordering.

    Attributes
    ----------
    n_patches, n_joints : int
    pairs : (E, 2) int, neighbouring patches (the model's rigidity pairs)
    order : (n,) int, the fill-reducing order (position in the ordered system → unknown)
    indptr, indices : compressed-column structure of the ordered ``H``
    gather : (nnz,) int, index of each stored entry into the concatenated block arrays of a
        :class:`System` (``D``, ``O``, ``Oᵀ``, ``PJ``, ``PJᵀ``, ``JJ``; no entry repeats: the
        pairs are distinct and a bone joins two different joints)
    diag : (n,) int, stored positions of the ordered diagonal
    factor : BlockFactor, the structure of ``H``'s Cholesky factor (:meth:`System.solve`)
    """

    n_patches: int
    n_joints: int
    pairs: np.ndarray
    order: np.ndarray
    indptr: np.ndarray
    indices: np.ndarray
    gather: np.ndarray
    diag: np.ndarray
    factor: BlockFactor

    @property
    def n(self) -> int:
        """Number of unknowns: 6 per patch, then 3 per joint."""
        return 6 * self.n_patches + 3 * self.n_joints


def _block_coords(r0: np.ndarray, c0: np.ndarray, a: int, b: int):
    """Row and column (m·a·b,) of every entry of ``m`` a×b blocks at offsets ``r0``, ``c0``,
    in C order of an (m, a, b) array."""
    rows = np.broadcast_to(r0[:, None, None] + np.arange(a)[None, :, None], (len(r0), a, b))
    cols = np.broadcast_to(c0[:, None, None] + np.arange(b)[None, None, :], (len(c0), a, b))
    return rows.ravel(), cols.ravel()


def normal_pattern(model: PatchModel, n_joints: int) -> Pattern:
    """The :class:`Pattern` of ``model``'s normal equations with ``n_joints`` joints."""
    P, K = model.P, n_joints
    k, l = model.pairs[:, 0], model.pairs[:, 1]
    bone = np.stack([model.bone_j, model.bone_child], 1)
    p6, base = 6 * np.arange(P), 6 * P
    blocks = [  # the storage order of System._damped
        _block_coords(p6, p6, 6, 6),
        _block_coords(6 * k, 6 * l, 6, 6),
        _block_coords(6 * l, 6 * k, 6, 6),
        _block_coords(np.repeat(p6, 2), base + 3 * bone.ravel(), 6, 3),
        _block_coords(base + 3 * bone.ravel(), np.repeat(p6, 2), 3, 6),
    ]
    # joint–joint: a dense (3K, 3K) array, row-major
    n = base + 3 * K
    jj = np.arange(base, n)
    blocks.append((np.repeat(jj, 3 * K), np.tile(jj, 3 * K)))
    rows = np.concatenate([b[0] for b in blocks])
    cols = np.concatenate([b[1] for b in blocks])
    # fill-reducing order: SuperLU's minimum degree on the structure (values only need to
    # keep the diagonal pivots safe); lu.perm_c sends unknown i to position perm_c[i]
    S = sp.csc_matrix((np.where(rows == cols, float(n), 1.0), (rows, cols)), shape=(n, n))
    lu = spla.splu(
        S, permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.0, options={"SymmetricMode": True}
    )
    order = np.argsort(lu.perm_c)
    inv = lu.perm_c
    r, c = inv[rows], inv[cols]
    gather = np.lexsort((r, c))  # column-major
    indptr = np.concatenate([[0], np.cumsum(np.bincount(c, minlength=n))])
    indices = r[gather]
    diag = np.flatnonzero(indices == c[gather])
    factor = block_factor(rows, cols, n)
    return Pattern(P, K, model.pairs, order, indptr, indices, gather, diag, factor)


@dataclass
class System:
    """The normal equations ``H δ = −g`` of one Gauss–Newton step, accumulated block by
    block on a :class:`Pattern` (the block arrays below, ``H`` being symmetric: each pair
    and patch–joint block is stored once)."""

    pattern: Pattern
    D: np.ndarray  # (P, 6, 6) patch diagonal blocks
    O: np.ndarray  # (E, 6, 6) pair blocks, rows of patch k, columns of patch l
    PJ: np.ndarray  # (P, 2, 6, 3) patch rows, columns of its bone's start / end joint
    JJ: np.ndarray  # (3K, 3K) joint rows and columns
    g: np.ndarray  # (n,)

    @classmethod
    def empty(cls, pattern: Pattern) -> System:
        """An all-zero system on ``pattern``."""
        P, K = pattern.n_patches, pattern.n_joints
        E = len(pattern.pairs)
        zeros = np.zeros
        return cls(
            pattern,
            zeros((P, 6, 6)),
            zeros((E, 6, 6)),
            zeros((P, 2, 6, 3)),
            zeros((3 * K, 3 * K)),
            zeros(pattern.n),
        )

    @property
    def n(self) -> int:
        """Number of unknowns."""
        return self.pattern.n

    def add_patches(self, k: np.ndarray, B: np.ndarray, *, unique: bool = False) -> None:
        """Add 6×6 blocks ``B`` (m, 6, 6) to the diagonal blocks of patches ``k`` (m,)
        (``unique``: no patch repeats, a faster path)."""
        if unique:
            self.D[k] += B
        else:
            np.add.at(self.D, k, B)

    def add_g(self, ru: np.ndarray, G: np.ndarray) -> None:
        """Add gradient pieces ``G`` (m, a) at offsets ``ru``."""
        idx = ru[:, None] + np.arange(G.shape[1])
        self.g += np.bincount(idx.ravel(), G.ravel(), minlength=self.n)

    def _blocks(self) -> np.ndarray:
        """The block arrays concatenated (the pattern's storage order, before ``gather``)."""
        return np.concatenate(
            [
                self.D.ravel(),
                self.O.ravel(),
                np.swapaxes(self.O, 1, 2).ravel(),
                self.PJ.ravel(),
                np.swapaxes(self.PJ, 2, 3).ravel(),
                self.JJ.ravel(),
            ]
        )

    def _values(self) -> np.ndarray:
        """Stored entries of ``H`` in the pattern's order."""
        return self._blocks()[self.pattern.gather]

    def matrix(self, damping: float | None = None) -> sp.csc_matrix:
        """``H`` (n, n), damped as in :meth:`solve` with λ = ``damping`` (None: undamped),
        unknowns in their own order."""
        pt = self.pattern
        data = self._values()
        if damping is not None:
            data[pt.diag] += damped_diagonal(data[pt.diag], damping, FLOOR)
        H = sp.csc_matrix((data, pt.indices, pt.indptr), shape=(self.n, self.n))
        inv = np.argsort(pt.order)
        return H[inv][:, inv].tocsc()

    def solve(self, damping: float) -> np.ndarray:
        """Solve ``(H + μ diag(H) + ε I) δ = −g`` (Levenberg–Marquardt, the rule of
        :mod:`meshmocap.geometry.levenberg_marquardt`: μ = ``damping``, ε a thousandth of
        the median diagonal entry, :data:`FLOOR`, which keeps weakly observed unknowns,
        the spin of a small patch about its own centre, from taking huge steps).

        Raises
        ------
        FitError
            Singular normal equations (after the rule's retries with more damping).
        """
        f = self.pattern.factor
        fresh = [factor_values(self.D, self.O, self.PJ, self.JJ, f.src)]  # _blocks()[f.src]
        d = fresh[0][f.diag]  # H's diagonal, unknowns in their own order
        rhs = np.ascontiguousarray(-self.g[f.scalar].reshape(-1, 3))

        def factor_and_solve(add: np.ndarray) -> np.ndarray:
            # H is symmetric positive definite and sparse (each patch couples with its ~6
            # neighbours and its bone's joints): a Cholesky factor in 3×3 blocks on the
            # pattern's fill-reducing order, its structure computed once (BlockFactor);
            # factored in place in H's entries (read again for a retry, which is rare)
            L = fresh.pop() if fresh else factor_values(self.D, self.O, self.PJ, self.JJ, f.src)
            L[f.diag] += add
            L = L.reshape(-1, 3, 3)
            if not block_cholesky(L, f.colptr, f.rowidx, f.row_ptr, f.row_col, f.row_entry):
                raise np.linalg.LinAlgError("not positive definite")
            delta = np.empty(self.n)
            delta[f.scalar] = block_cholesky_solve(L, f.colptr, f.rowidx, rhs).ravel()
            return delta

        return solve_damped(factor_and_solve, d, lam=damping, floor=FLOOR)

    def solve_grouped(self, damping: float, S: sp.spmatrix) -> np.ndarray:
        """Solve the damped normal equations restricted to steps ``δ = S δ_r`` (``S``
        (n, r), e.g. :func:`group_basis`): ``(SᵀHS + μ diag + ε I) δ_r = −Sᵀg``, dense
        (r is small), by the same rule as :meth:`solve`. Returns δ (n,)."""
        H = self.matrix()
        Hr = np.asarray((S.T @ H @ S).todense())
        dr = damped_solve(
            Hr, S.T @ self.g, lam=damping, floor=FLOOR, what="grouped normal equations"
        )
        return S @ dr


def group_basis(groups: np.ndarray, c: np.ndarray, n_joints: int) -> sp.csr_matrix:
    """Steps of patches that move rigidly in groups: (6P + 3K, 6G + 3K) sparse ``S`` with
    ``δ = S δ_r``. Group ``g`` turns by ``ω_g`` about the mean ``p_g`` of its patch centres
    and moves by ``t_g``, so each of its patches ``k`` (centre ``c_k``) gets ``ω_k = ω_g``
    and ``δc_k = t_g + ω_g × (c_k − p_g)`` (first order); joints stay free.

    Parameters: ``groups`` (P,) int in ``0 .. G-1``, ``c`` (P, 3) patch centres, metres.
    """
    P, G = len(groups), int(groups.max()) + 1
    cnt = np.bincount(groups, minlength=G)
    piv = np.stack([np.bincount(groups, c[:, a], minlength=G) for a in range(3)], 1)
    piv /= np.maximum(cnt, 1)[:, None]
    a = c - piv[groups]  # lever arms
    k6, g6 = 6 * np.arange(P), 6 * groups
    e3 = np.arange(3)
    rows = [k6[:, None] + e3, k6[:, None] + 3 + e3]  # ω_k = ω_g, δc_k ∋ t_g
    cols = [g6[:, None] + e3, g6[:, None] + 3 + e3]
    vals = [np.ones((P, 3)), np.ones((P, 3))]
    M = -skew(a)  # δc_k ∋ −[a]× ω_g
    rows.append(np.repeat(k6[:, None] + 3 + e3, 3, axis=1))
    cols.append(np.tile(g6[:, None] + e3, 3))
    vals.append(M.reshape(P, 9))
    n, r = 6 * P + 3 * n_joints, 6 * G + 3 * n_joints
    j = np.arange(3 * n_joints)
    rows.append(6 * P + j), cols.append(6 * G + j), vals.append(np.ones(3 * n_joints))
    return sp.csr_matrix(
        (
            np.concatenate([v.ravel() for v in vals]),
            (np.concatenate([x.ravel() for x in rows]), np.concatenate([x.ravel() for x in cols])),
        ),
        shape=(n, r),
    )


def add_rigidity(
    sys: System,
    model: PatchModel,
    mom: RigidityMoments,
    R: np.ndarray,
    c: np.ndarray,
    weight: float,
) -> float:
    """Add ``weight · Er`` (Eq. 2) and return its value (before ``weight``).

    With ``s_a = R_a m_a`` and ``Q_ab = R_a M_ab R_bᵀ`` (the pair's rest moments turned),
    the energy ``Σ w |q_k − q_l + Δc|²`` is ``tr Q_kk + tr Q_ll − 2 tr Q_kl + 2 Δc·(s_k −
    s_l) + W |Δc|²``; the Jacobians are ``+A(q_k)`` on patch k and ``−A(q_l)`` on patch l,
    so the blocks are ``Σ w A(q_a)ᵀ A(q_b)`` (module docstring) and the gradient pieces
    ``±[axial(Q_0a − Q_a0) − axial(Q_1a − Q_a1) + s_a × Δc; s_k − s_l + W Δc]`` (``Σ w q_a
    × q_b = axial(Q_ba − Q_ab)``), all computed in one pass
    (:func:`~meshmocap.trackers.patch.kernels.rigidity_blocks`).
    """
    k, l = model.pairs[:, 0], model.pairs[:, 1]
    H2, Hkl, G, value = rigidity_blocks(
        R, np.ascontiguousarray(c), k, l, mom.W, np.ascontiguousarray(mom.m), mom.M
    )
    add_pair_blocks(sys.D, sys.O, sys.g, H2, Hkl, G, k, l, float(weight))
    return float(value)


def add_point_terms(
    sys: System, patch: np.ndarray, q: np.ndarray, r: np.ndarray, w: np.ndarray, weight: float
) -> float:
    """Add ``weight · Σ w |r|²`` for residuals ``r = q + c_patch − target`` moved by one patch each.

    Parameters: ``patch`` (m,), ``q = R_k d`` (m, 3), residuals ``r`` (m, 3), weights ``w`` (m,).
    Returns the weighted sum before ``weight``.
    """
    # Per-patch moments W = Σ w, s = Σ w q, Q = Σ w q qᵀ give Σ w A(q)ᵀ A(q) (module
    # docstring): 10 sums per patch instead of 36, and no (m, 6, 6) array; one pass.
    n_p = int(patch.max()) + 1 if len(patch) else 0
    W, s, Q, G, value = point_moments(
        np.ascontiguousarray(patch, dtype=np.int64),
        np.ascontiguousarray(q, dtype=np.float64),
        np.ascontiguousarray(r, dtype=np.float64),
        np.ascontiguousarray(w, dtype=np.float64),
        n_p,
    )
    add_moment_blocks(sys.D, sys.g, W, s, Q, G, float(weight))
    return float(value)


def _vertex_rows(patch, vertex, V, c, Y) -> tuple[np.ndarray, ...]:
    """The arrays the vertex-row kernels read, contiguous: ``patch``, ``vertex`` int64,
    ``V``, ``c``, ``Y`` float64 (:func:`add_vertex_terms`)."""
    return (
        np.ascontiguousarray(patch, dtype=np.int64),
        np.ascontiguousarray(vertex, dtype=np.int64),
        np.ascontiguousarray(V, dtype=np.float64),
        np.ascontiguousarray(c, dtype=np.float64),
        np.ascontiguousarray(Y, dtype=np.float64),
    )


def add_vertex_terms(
    sys: System,
    patch: np.ndarray,
    vertex: np.ndarray,
    V: np.ndarray,
    c: np.ndarray,
    Y: np.ndarray,
    w: np.ndarray,
    weight: float,
) -> float:
    """:func:`add_point_terms` for vertices moved by their own patch: row ``t`` pulls
    vertex ``vertex[t]`` of patch ``patch[t]`` (m,) int, placed at ``V`` (n, 3) (each
    vertex as its own patch predicts it; ``c`` (P, 3) the patch centres), to ``Y[t]``
    (m, 3), weight ``w[t]`` (m,): ``q = V[vertex] − c[patch]``, ``r = V[vertex] − Y``,
    formed in the one pass. Returns the weighted sum before ``weight``."""
    n_p = int(patch.max()) + 1 if len(patch) else 0
    W, s, Q, G, value = vertex_moments(
        *_vertex_rows(patch, vertex, V, c, Y), np.ascontiguousarray(w, dtype=np.float64), n_p
    )
    add_moment_blocks(sys.D, sys.g, W, s, Q, G, float(weight))
    return float(value)


def add_bone(
    sys: System,
    model: PatchModel,
    R: np.ndarray,
    c: np.ndarray,
    X: np.ndarray,
    weight: float,
    *,
    joints: np.ndarray | None = None,
) -> float:
    """Add ``weight · Ebone`` (Eq. 11): ``Σ w_k |T_k(Δ0_k) − (γ x_j + (1 − γ) x_child)|²``.

    ``joints``: the term's joint–joint blocks before ``weight`` (3K, 3K), which depend on
    the bone binding only (:func:`bone_joint_blocks`; default: computed here)."""
    P = model.P
    k = np.arange(P)
    q = np.einsum("kij,kj->ki", R, model.delta0 - model.centres0)
    g = model.gamma
    r = q + c - (g[:, None] * X[model.bone_j] + (1 - g)[:, None] * X[model.bone_child])
    w = model.bone_w
    value = add_point_terms(sys, k, q, r, w, weight)
    # joint columns: ∂r/∂x_j = −γ I, ∂r/∂x_child = −(1 − γ) I, A(q)ᵀ = [[q]×; I]
    add_bone_joint_blocks(
        sys.PJ,
        sys.g,
        np.ascontiguousarray(q),
        np.ascontiguousarray(r),
        np.stack([-(w * g), -(w * (1 - g))]),
        np.stack([model.bone_j, model.bone_child]).astype(np.int64),
        6 * P,
        float(weight),
    )
    if joints is None:
        joints = bone_joint_blocks(model, sys.pattern.n_joints)
    sys.JJ += weight * joints
    return value


def bone_joint_blocks(model: PatchModel, n_joints: int) -> np.ndarray:
    """The bone term's joint–joint blocks before its weight, (3K, 3K) for ``K =
    n_joints``: multiples of I, ``Σ_k w_k c_a c_b`` at (joint a, joint b) with ``c`` the
    coefficients γ, 1 − γ of a patch's bone ends, one sum."""
    K, g, w = n_joints, model.gamma, model.bone_w
    ends = ((model.bone_j, g), (model.bone_child, 1 - g))
    at = np.concatenate([j1 * K + j2 for j1, _ in ends for j2, _ in ends])
    coef = np.concatenate([w * c1 * c2 for _, c1 in ends for _, c2 in ends])
    C = np.bincount(at, coef, minlength=K * K).reshape(K, K)
    return np.kron(C, np.eye(3))


def add_plane_terms(
    sys: System,
    patch: np.ndarray,
    q: np.ndarray,
    n: np.ndarray,
    s: np.ndarray,
    w: np.ndarray,
    weight: float,
) -> float:
    """Add ``weight · Σ w s²`` for point-to-plane residuals ``s = n · (q + c_patch − y)``.

    Parameters: ``patch`` (m,), ``q = R_k d`` (m, 3), unit normals ``n`` (m, 3) of the
    observed points, residuals ``s`` (m,), weights ``w`` (m,). The Jacobian row of a
    residual is ``nᵀ A(q) = [(q × n)ᵀ, nᵀ]``. Returns the weighted sum before ``weight``.
    """
    Jr = np.concatenate([np.cross(q, n), n], axis=1)  # (m, 6)
    n_p = int(patch.max()) + 1 if len(patch) else 0
    WJ = w[:, None] * Jr
    blocks = np.stack(
        [
            np.bincount(patch, WJ[:, i] * Jr[:, j], minlength=n_p)
            for i in range(6)
            for j in range(6)
        ],
        1,
    )
    used = np.flatnonzero(np.bincount(patch, minlength=n_p))
    sys.add_patches(used, weight * blocks[used].reshape(-1, 6, 6), unique=True)
    sys.add_g(6 * patch, weight * WJ * s[:, None])
    return float(np.sum(w * s * s))


def add_plane_vertex_terms(
    sys: System,
    patch: np.ndarray,
    vertex: np.ndarray,
    V: np.ndarray,
    c: np.ndarray,
    Y: np.ndarray,
    n: np.ndarray,
    w: np.ndarray,
    weight: float,
) -> float:
    """:func:`add_plane_terms` for vertices moved by their own patch, compiled: row ``t``
    measures vertex ``vertex[t]`` of patch ``patch[t]`` (m,) int, placed at ``V`` (n, 3)
    (``c`` (P, 3) the patch centres), from ``Y[t]`` (m, 3) along the unit normal ``n[t]``
    (m, 3), weight ``w[t]`` (m,): ``q = V[vertex] − c[patch]``, ``s = n · (V[vertex] −
    Y)``, formed in the one pass. Returns the weighted sum ``Σ w s²`` before ``weight``."""
    return float(
        add_plane_blocks(
            sys.D,
            sys.g,
            *_vertex_rows(patch, vertex, V, c, Y),
            np.ascontiguousarray(n, dtype=np.float64),
            np.ascontiguousarray(w, dtype=np.float64),
            float(weight),
        )
    )


def length_residuals(
    X: np.ndarray, pairs: np.ndarray, lengths: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Unit directions ``u`` (m, 3) of ``x_a − x_b`` over ``pairs`` (m, 2) of ``X`` (K, 3)
    and the length errors ``r = |x_a − x_b| − L`` (m,), metres: ``∂r/∂x_a = uᵀ = −∂r/∂x_b``."""
    d = X[pairs[:, 0]] - X[pairs[:, 1]]
    n = np.maximum(np.linalg.norm(d, axis=1), NORM_FLOOR)
    return d / n[:, None], n - lengths


def add_bone_lengths(
    sys: System,
    X: np.ndarray,
    pairs: np.ndarray,
    lengths: np.ndarray,
    weight: float,
) -> float:
    """Add ``weight · Σ_(a,b) (|x_a − x_b| − L_ab)²`` over pairs of joints.

    Not in the paper, which leaves bone lengths free (§IV-A, Fig. 6): an optional prior
    that keeps each bone (and each rigid pair across the pelvis or shoulders) at the length
    it had where tracking started. Gauss–Newton with the unit direction ``u`` of
    ``x_a − x_b``: ``∂r/∂x_a = uᵀ``, ``∂r/∂x_b = −uᵀ``.

    Parameters
    ----------
    X : (K, 3) joint positions, metres
    pairs : (m, 2) int, joints whose distance is held (a bone: child, parent)
    lengths : (m,) distance to hold for each pair, metres

    Returns
    -------
    float, the sum of squared length errors (before ``weight``)
    """
    u, r = length_residuals(X, pairs, lengths)
    pairs = np.asarray(pairs, dtype=np.int64)
    add_length_blocks(  # the blocks weight · u uᵀ (±) and the gradient ± weight · r u
        sys.JJ,
        sys.g,
        np.ascontiguousarray(u),
        np.ascontiguousarray(r),
        np.ascontiguousarray(pairs[:, 0]),
        np.ascontiguousarray(pairs[:, 1]),
        6 * sys.pattern.n_patches,
        float(weight),
    )
    return float(np.sum(r * r))
