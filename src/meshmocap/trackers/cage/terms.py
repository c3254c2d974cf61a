"""The cage tracker's energy terms (cage-manifold-tracking §5): one small frozen dataclass per
term, all with one interface.

A term has a ``name`` and a ``weight`` (its :attr:`~Term.coefficient` in the energy);
:meth:`Term.add` adds its rows, times the coefficient, to one Levenberg–Marquardt
:class:`System` and returns its value (m², or the log of a variance). The energy is a list of
them (:mod:`~meshmocap.trackers.cage.energy`): a problem adds every term of the list that
takes part in it (``stages``) to one system, and its total is the sum over the same terms
of coefficient × value. The problems (:mod:`~meshmocap.trackers.cage.tracker`): the pelvis
transform (``"pose"``, Eq. 11), the latent point (``"shape"``, Eq. 5–6), the choice of the
local adjustment's start (``"start"``) and the local adjustment of the quads (``"local"``,
Eq. 12).

Two kinds of rows:

* **point rows** (:class:`DistanceTerm`, Eq. 4, the paper's; :class:`CoverageTerm` and
  :class:`SilhouetteTerm`, ours): one residual ``r_i`` and its gradient ``g_i`` with
  respect to the sampled model point ``P_i``; every problem chains them through its own
  Jacobian of the points;
* **parameter rows**, added straight to the problem's gradient and Gauss–Newton matrix:
  :class:`VarianceTerm` (Eq. 5, the paper's, over the latent point), :class:`AnchorTerm`
  and :class:`ArticulationTerm` (the local adjustment's pull towards the manifold and
  soft joints, ours, over the quads).

What the terms read: :class:`FrameData` (fixed over a frame) and :class:`Iterate` (one
problem's linearisation point). Frames and units: world frame (Z up), metres; energies in
m².

References
----------
- E. Duveau, S. Courtemanche, L. Reveret, E. Boyer, *Cage-based motion recovery
  using manifold learning*, International Conference on 3D Imaging, Modeling,
  Processing, Visualization and Transmission (3DIMPVT), 2012.
- D. W. Marquardt, *An algorithm for least-squares estimation of nonlinear
  parameters*, Journal of the Society for Industrial and Applied Mathematics
  11(2):431–441, 1963. https://doi.org/10.1137/0111030
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import ClassVar, Literal, Protocol

import numpy as np

from meshmocap.geometry.rotations import skew
from meshmocap.trackers.cage.residuals import Articulation, HullCoverage, SilhouetteCoverage

__all__ = [
    "ALL_TERMS",
    "PAPER_TERMS",
    "AnchorTerm",
    "ArticulationTerm",
    "CoverageTerm",
    "DistanceTerm",
    "FrameData",
    "Iterate",
    "SilhouetteTerm",
    "Stage",
    "System",
    "Term",
    "TermName",
    "VarianceTerm",
]

TermName = Literal["distance", "variance", "coverage", "silhouette", "anchor", "articulation"]
#: The paper's energy: the distance-field sum (Eq. 4) and the variance regulariser (Eq. 5).
PAPER_TERMS: tuple[TermName, ...] = ("distance", "variance")
#: Every term (the default tracker), in the order of the energy's list.
ALL_TERMS: tuple[TermName, ...] = (
    "distance",
    "variance",
    "coverage",
    "silhouette",
    "anchor",
    "articulation",
)
#: The problems a term may take part in (module docstring).
Stage = Literal["pose", "shape", "start", "local"]
#: Points closer than this (metres, every coordinate) are the same points
#: (:meth:`FrameData.point_rows`).
SAME_POINTS = 1e-12
#: Point rows kept per frame for reuse (:meth:`FrameData.point_rows`): the stages hand
#: over the same points (the last pose step's to the first shape step, and so on).
MEMO = 8


@dataclass(eq=False)
class FrameData:
    """What the terms read that stays fixed over one frame.

    Attributes
    ----------
    field : the frame's distance field (``value_and_gradient(P)``, signed, metres:
        :class:`~meshmocap.trackers.cage.field.HullDistanceField`)
    point_weights : (n,) float64, ``√(1 / kept)`` for the sampled vertices in the data term,
        0 for those left out
    noise : float, the manifold's noise variance (the floor of σ², Eq. 5)
    articulation : Articulation, the soft joints between consecutive quads
    hull : HullCoverage or None, this frame's hull surface samples (``"coverage"``)
    silhouettes : SilhouetteCoverage or None, this frame's contour samples (``"silhouette"``)
    """

    field: object
    point_weights: np.ndarray
    noise: float
    articulation: Articulation
    hull: HullCoverage | None = None
    silhouettes: SilhouetteCoverage | None = None
    _memo: list = field(default_factory=list, repr=False)

    def point_rows(
        self, name: str, P: np.ndarray, sub: slice, compute: Callable[[], tuple]
    ) -> tuple[np.ndarray, np.ndarray]:
        """``compute()`` (a term's residuals and gradients at the points ``P``, the sampled
        vertices ``sub``), or its result for the same term, subset and points (to
        :data:`SAME_POINTS`) if one of the last :data:`MEMO` calls of the frame had it."""
        key = (name, str(sub))
        for k, Q, out in self._memo:
            if (
                k == key
                and abs(Q[0, 0] - P[0, 0]) < SAME_POINTS
                and np.abs(Q - P).max() < SAME_POINTS
            ):
                return out
        out = compute()
        self._memo = [(key, P, out), *self._memo[: MEMO - 1]]
        return out


@dataclass(frozen=True, eq=False)
class Iterate:
    """One problem's linearisation point.

    Attributes
    ----------
    frame : FrameData
    P : (n, 3) float64, the sampled model points (the sampled vertices ``sub``), metres
    sub : slice, which sampled vertices ``P`` holds (all, or a subset ranking candidates)
    var : float or None, the latent point's predictive variance (Eq. 9), shape problem
    dvar : (q,) float64 or None, its gradient with respect to the latent point
    y : (9 · 20,) float64 or None, the quads' configuration (local adjustment)
    anchor : (9 · 20,) float64 or None, the manifold's configuration ``y`` is pulled to
    quads : tuple of (21, 3) centres and (21, 3, 3) rotations, pelvis-relative, or None:
        where the soft joints hold
    """

    frame: FrameData
    P: np.ndarray
    sub: slice = field(default_factory=lambda: slice(None))
    var: float | None = None
    dvar: np.ndarray | None = None
    y: np.ndarray | None = None
    anchor: np.ndarray | None = None
    quads: tuple[np.ndarray, np.ndarray] | None = None


@dataclass(eq=False)
class System:
    """The rows of one problem's Levenberg–Marquardt linearisation.

    Attributes
    ----------
    n : int
        The problem's parameters (the local adjustment: 6 per quad 1…20, then the
        pelvis's 6).
    r, g : lists of (m,) and (m, 3) float64
        Point rows, one block per point term (coefficients included): ``½ Σ r²`` is their
        energy, ``g`` the gradients with respect to the points.
    grad : (n,) float64 and H : (n, n) float64
        Gradient and Gauss–Newton matrix of the parameter rows (properties): the rows the
        terms handed over (:meth:`add_rows`) summed, in their order, when first read. A
        problem reads them only where it linearises; about half of its evaluations are
        steps it rejects or its last, whose rows were never used.
    """

    n: int
    r: list = field(default_factory=list)
    g: list = field(default_factory=list)
    _rows: list = field(default_factory=list, repr=False)
    _sums: tuple | None = field(default=None, repr=False)

    @classmethod
    def empty(cls, n: int) -> System:
        """No rows, over ``n`` parameters."""
        return cls(n)

    def add_rows(self, rows: Callable[[np.ndarray, np.ndarray], None]) -> None:
        """Hand over parameter rows: ``rows(grad, H)`` adds them in place, when
        ``grad`` or ``H`` is first read."""
        self._rows.append(rows)
        self._sums = None

    def _summed(self) -> tuple[np.ndarray, np.ndarray]:
        if self._sums is None:
            grad, H = np.zeros(self.n), np.zeros((self.n, self.n))
            for rows in self._rows:
                rows(grad, H)
            self._sums = grad, H
        return self._sums

    @property
    def grad(self) -> np.ndarray:
        return self._summed()[0]

    @property
    def H(self) -> np.ndarray:
        return self._summed()[1]

    def add_points(self, r: np.ndarray, g: np.ndarray) -> None:
        """Add a block of point rows ``r`` (m,) and gradients ``g`` (m, 3)."""
        self.r.append(r)
        self.g.append(g)

    def point_rows(self) -> tuple[np.ndarray, np.ndarray]:
        """Every point row, blocks in the order of the terms: ``r`` (k m,), ``g`` (k m, 3)."""
        if len(self.r) == 1:
            return self.r[0], self.g[0]
        return np.concatenate(self.r), np.concatenate(self.g)


class Term(Protocol):
    """One term of the energy.

    Attributes
    ----------
    name : str, its key in the term list (``CageOptions.terms``) and a frame's energies
    weight : float, its coefficient in the energy
    stages : tuple of Stage (class constant), the problems it takes part in
    """

    name: ClassVar[str]
    stages: ClassVar[tuple[Stage, ...]]
    weight: float

    @property
    def coefficient(self) -> float:
        """The factor on :meth:`add`'s value in the total energy (``weight``)."""
        ...

    def add(self, sys: System, it: Iterate) -> float:
        """Add ``coefficient · value``'s rows to ``sys`` and return the value at ``it``."""
        ...


class _Weighted:
    """Mixin: :attr:`Term.coefficient` is ``weight``."""

    weight: float

    @property
    def coefficient(self) -> float:
        return self.weight


# Eq. (4): E_d = ½ Σ_i w_i d_DF(M_i(x, Γ))² / kept over the sampled model points
@dataclass(frozen=True)
class DistanceTerm(_Weighted):
    """Eq. (4): the distance field of the hull at the sampled points, squared and signed
    (points inside the hull weighted by ``inside_weight``, outside ones counted from
    ``outside_margin`` on and up to ``outside_cap``: the tracker's module notes), over the
    points in the data term (:attr:`FrameData.point_weights`). Value: ``½ Σ w_i r_i²``, m²;
    its weight is the energy's unit (Eq. 4 has no λ)."""

    name: ClassVar[str] = "distance"
    stages: ClassVar[tuple[Stage, ...]] = ("pose", "shape", "start", "local")
    weight: ClassVar[float] = 1.0
    inside_weight: float = 0.05
    outside_margin: float = 0.0
    outside_cap: float = 0.0

    def residuals(self, it: Iterate) -> tuple[np.ndarray, np.ndarray]:
        """Residuals (n,) and point gradients (n, 3) at ``it.P``, point weights included."""
        r, g = it.frame.field.value_and_gradient(it.P)
        if self.outside_margin:  # outside: only beyond the margin
            r = np.where(r > 0, np.maximum(r - self.outside_margin, 0.0), r)
        if self.outside_cap:  # farther outside: the hull lost that part (a hole): no pull
            far = r > self.outside_cap
            r, g = np.where(far, 0.0, r), np.where(far[:, None], 0.0, g)
        w = np.where(r < 0, np.sqrt(self.inside_weight), 1.0) * it.frame.point_weights[it.sub]
        return r * w, g * w[:, None]

    def add(self, sys: System, it: Iterate) -> float:
        r, g = it.frame.point_rows(self.name, it.P, it.sub, lambda: self.residuals(it))
        sys.add_points(r, g)
        return 0.5 * float(r @ r)


class _Coverage(_Weighted):
    """Mixin of the coverage terms: ``½ Σ_m ρ_m² / m`` over the ``m`` samples of this
    frame's coverage (:meth:`coverage`), as point rows ``√(λ / m) r_i`` (the samples whose
    nearest model point is ``i``: :meth:`HullCoverage.residuals`); nothing where the frame
    has none."""

    name: ClassVar[str]

    def coverage(self, frame: FrameData) -> HullCoverage | SilhouetteCoverage | None:
        raise NotImplementedError

    def add(self, sys: System, it: Iterate) -> float:
        cov = self.coverage(it.frame)
        if cov is None or not len(cov):
            return 0.0
        r, a = it.frame.point_rows(self.name, it.P, it.sub, lambda: cov.residuals(it.P))
        s = np.sqrt(self.coefficient / len(cov))
        sys.add_points(s * r, s * a)
        return 0.5 * float(r @ r) / len(cov)


# ours: E_c = ½ Σ_m max(0, d_m − margin)² / m over hull surface samples h_m
@dataclass(frozen=True)
class CoverageTerm(_Coverage):
    """Hull coverage (:class:`~meshmocap.trackers.cage.residuals.HullCoverage`): every hull
    surface sample wants a model point within ``margin``. Not in the local adjustment: quads
    free of the manifold would follow it into the hull's phantom volumes."""

    name: ClassVar[str] = "coverage"
    stages: ClassVar[tuple[Stage, ...]] = ("pose", "shape", "start")
    weight: float = 0.3

    def coverage(self, frame: FrameData) -> HullCoverage | None:
        return frame.hull


# ours: E_s = ½ Σ_m (z/f · max(0, d_m − margin))² / m over silhouette contour samples
@dataclass(frozen=True)
class SilhouetteTerm(_Coverage):
    """Silhouette coverage (:class:`~meshmocap.trackers.cage.residuals.SilhouetteCoverage`):
    every contour pixel wants a model point projecting within ``margin`` pixels; in every
    problem (the silhouettes hold no phantom volume)."""

    name: ClassVar[str] = "silhouette"
    stages: ClassVar[tuple[Stage, ...]] = ("pose", "shape", "start", "local")
    weight: float = 0.3

    def coverage(self, frame: FrameData) -> SilhouetteCoverage | None:
        return frame.silhouettes


# Eq. (5): E_σ = λσ log σ²(x), σ² = Eq. (9) + the manifold's noise variance (sign: the
# tracker's module notes)
@dataclass(frozen=True)
class VarianceTerm(_Weighted):
    """Eq. (5): the log of the latent point's predictive variance. Value: ``log σ²``; rows
    (where ``it.dvar`` is given) by Eq. (10) in ``d log σ² = dσ² / σ²``, Gauss–Newton
    ``dσ² dσ²ᵀ / σ⁴``."""

    name: ClassVar[str] = "variance"
    stages: ClassVar[tuple[Stage, ...]] = ("shape",)
    weight: float = 1e-5

    def add(self, sys: System, it: Iterate) -> float:
        if it.var is None:
            return 0.0
        var = max(it.var, 0.0) + it.frame.noise
        if it.dvar is not None:
            c, dvar = self.coefficient, it.dvar

            def rows(grad, H):
                grad += c * dvar / var
                H += c * np.outer(dvar, dvar) / var**2

            sys.add_rows(rows)
        return float(np.log(var))


# ours: E_a = ½ Σ (ỹ − ȳ)² (ȳ: the manifold's configuration; metres and unit axis vectors)
@dataclass(frozen=True)
class AnchorTerm(_Weighted):
    """The local adjustment's pull towards the manifold's configuration ``it.anchor``,
    along each quad's ``(dc, ω)``: ``dỹ/d(dc, ω) = [I; −[u]×; −[v]×]`` per quad. Nothing
    where ``it.anchor`` is None (off the manifold, or no manifold)."""

    name: ClassVar[str] = "anchor"
    stages: ClassVar[tuple[Stage, ...]] = ("local",)
    weight: float = 3e-5

    def add(self, sys: System, it: Iterate) -> float:
        if it.anchor is None:
            return 0.0
        w = self.coefficient
        y = it.y
        Y, E = y.reshape(-1, 3, 3), (y - it.anchor).reshape(-1, 3, 3)

        def rows(grad, H):
            nq = len(Y)
            Hq = np.zeros((nq, 6, 6))
            Hq[:, :3, :3] = np.eye(3)
            Hq[:, 3:, 3:] = sum(skew(Y[:, i]).transpose(0, 2, 1) @ skew(Y[:, i]) for i in (1, 2))
            gq = np.concatenate([E[:, 0], sum(np.cross(Y[:, i], E[:, i]) for i in (1, 2))], axis=1)
            idx = np.arange(6 * nq).reshape(nq, 6)
            H[idx[:, :, None], idx[:, None, :]] += w * Hq
            grad[: 6 * nq] += w * gq.ravel()

        sys.add_rows(rows)
        return 0.5 * float(np.sum(E * E))


# ours: E_j = ½ Σ_q ‖e_q‖² soft joints between consecutive quads (Articulation)
@dataclass(frozen=True)
class ArticulationTerm(_Weighted):
    """Soft joints between consecutive quads
    (:class:`~meshmocap.trackers.cage.residuals.Articulation`) at ``it.quads``; rows over
    the quads' ``(dc, ω)`` (6 per quad 1…20). Nothing where ``it.quads`` is None."""

    name: ClassVar[str] = "articulation"
    stages: ClassVar[tuple[Stage, ...]] = ("local",)
    weight: float = 10.0

    def add(self, sys: System, it: Iterate) -> float:
        if it.quads is None:
            return 0.0
        art, quads, w = it.frame.articulation, it.quads, self.coefficient

        def rows(grad, H):
            a, Ja = art.residuals(*quads, jacobian=True)
            k = Ja.shape[1]
            H[:k, :k] += w * Ja.T @ Ja
            grad[:k] += w * Ja.T @ a

        sys.add_rows(rows)
        a = art.residuals(*quads)  # the residuals residuals(jacobian=True) returns
        return 0.5 * float(a @ a)
