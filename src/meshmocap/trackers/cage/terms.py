"""The cage tracker's energy as data: a list of weighted terms (cage-manifold-tracking §5).

Each term has a name and a weight, adds its value to the energy and its rows to the
Gauss–Newton system of the problems it takes part in (:mod:`~meshmocap.trackers.cage.tracker`:
the pose step Eq. (11), the latent shape step Eq. (5)–(6), the local adjustment Eq. (12)).
Two kinds:

* **point terms**, functions of the sampled model points ``P`` (n, 3): ``residuals(P)``
  returns residuals ``r`` and their gradients ``g`` (one row per point, ``½ Σ r²`` the
  term's energy, weight included); every problem chains them through its own Jacobian of
  the points. :class:`DistanceTerm` (Eq. 4, the paper's), :class:`CoverageTerm` (hull or
  silhouette coverage, ours);
* **configuration terms**, functions of the problem's own parameters:
  :class:`VarianceTerm` (Eq. 5, the paper's, in the latent step), :class:`AnchorTerm`
  and :class:`ArticulationTerm` (the local adjustment's pull towards the manifold and
  soft joints, ours).

A tracker variant is a term list plus options (:data:`PAPER_TERMS`, :data:`ALL_TERMS`,
``CageOptions.terms``). Frames and units: world frame (Z up), metres; energies in m².
"""

from __future__ import annotations

from typing import Literal

import numpy as np

from meshmocap.geometry.rotations import skew
from meshmocap.trackers.cage.energy import Articulation

__all__ = [
    "ALL_TERMS",
    "PAPER_TERMS",
    "AnchorTerm",
    "ArticulationTerm",
    "CoverageTerm",
    "DistanceTerm",
    "TermName",
    "VarianceTerm",
]

TermName = Literal["distance", "variance", "coverage", "silhouette", "anchor", "articulation"]
#: The paper's energy: the distance-field sum (Eq. 4) and the variance regulariser (Eq. 5).
PAPER_TERMS: tuple[TermName, ...] = ("distance", "variance")
#: Every term (the default tracker).
ALL_TERMS: tuple[TermName, ...] = (
    "distance",
    "variance",
    "coverage",
    "silhouette",
    "anchor",
    "articulation",
)


class DistanceTerm:
    """Eq. (4): ``½ Σ_i w_i d_DF(P_i)²`` over the sampled points (squared, signed; points
    inside the hull weighted by ``inside_weight``, outside ones from ``outside_margin`` on
    and up to ``outside_cap``: the tracker's module notes). ``point_weights`` (n,) are
    ``√(w_i / kept)``, 0 for points left out."""

    name = "distance"
    weight = 1.0

    def __init__(self, field, point_weights, *, inside_weight, outside_margin, outside_cap):
        self.field, self.w = field, point_weights
        self.inside = np.sqrt(inside_weight)
        self.margin, self.cap = outside_margin, outside_cap

    @classmethod
    def from_options(cls, field, point_weights, opts) -> DistanceTerm:
        """The term with a :class:`~meshmocap.trackers.cage.options.CageOptions`' settings."""
        return cls(
            field,
            point_weights,
            inside_weight=opts.inside_weight,
            outside_margin=opts.outside_margin,
            outside_cap=opts.outside_cap,
        )

    def residuals(self, P: np.ndarray, sub=slice(None)) -> tuple[np.ndarray, np.ndarray]:
        """Residuals (n,) and point gradients (n, 3) at ``P``, the sampled points ``sub``."""
        r, g = self.field.value_and_gradient(P)
        if self.margin:  # outside: only beyond the margin
            r = np.where(r > 0, np.maximum(r - self.margin, 0.0), r)
        if self.cap:  # farther outside: the hull lost that part (a carved hole): no pull
            far = r > self.cap
            r, g = np.where(far, 0.0, r), np.where(far[:, None], 0.0, g)
        w = np.where(r < 0, self.inside, 1.0) * self.w[sub]
        return r * w, g * w[:, None]


class CoverageTerm:
    """The share of each model point in a coverage term (``HullCoverage`` or
    ``SilhouetteCoverage`` of :mod:`~meshmocap.trackers.cage.energy`), weighted:
    ``weight / m · ½ Σ_m ρ_m²`` over its ``m`` samples. ``local``: also in the local
    adjustment (silhouettes; the hull's phantom volumes would drag free quads)."""

    def __init__(self, coverage, weight: float, *, name: str, local: bool) -> None:
        self.coverage, self.weight, self.name, self.local = coverage, float(weight), name, local
        self._s = np.sqrt(self.weight / len(coverage))

    def residuals(self, P: np.ndarray, sub=slice(None)) -> tuple[np.ndarray, np.ndarray]:
        r, a = self.coverage.residuals(P)
        return self._s * r, self._s * a

    def mean_squared(self, P: np.ndarray) -> float:
        """Mean ρ² over the samples at ``P``, m² (the frame's reported value)."""
        return float(np.sum(self.coverage.residuals(P)[0] ** 2)) / len(self.coverage)


class VarianceTerm:
    """Eq. (5): ``λσ log σ²(x)`` of the latent point (sign and noise floor: the tracker's
    module notes), σ² the GPLVM's predictive variance plus its noise variance."""

    name = "variance"

    def __init__(self, weight: float, noise: float) -> None:
        self.weight, self.noise = float(weight), float(noise)

    def variance(self, var: float) -> float:
        return max(var, 0.0) + self.noise

    def value(self, var: float) -> float:
        """The term at predictive variance ``var`` (before the noise floor)."""
        return self.weight * np.log(self.variance(var))

    def rows(self, var: float, dvar: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Gradient (q,) and Gauss–Newton Hessian (q, q) at σ² ``var`` (floored), ``dvar``
        Eq. (10): ``d log σ² = dσ² / σ²``."""
        return self.weight * dvar / var, self.weight * np.outer(dvar, dvar) / var**2


class AnchorTerm:
    """``½ w Σ (ỹ − anchor)²``: the local adjustment's pull towards the manifold's
    configuration (metres and unit axis vectors), along each quad's ``(dc, ω)``."""

    name = "anchor"

    def __init__(self, weight: float) -> None:
        self.weight = float(weight)

    def value(self, y: np.ndarray, anchor: np.ndarray) -> float:
        e = y - anchor
        return 0.5 * self.weight * float(np.sum(e * e))

    def add_rows(self, grad, H, y: np.ndarray, anchor: np.ndarray) -> None:
        """Add to the local adjustment's ``grad`` and ``H`` (quads first, 6 per quad):
        ``dỹ/d(dc, ω) = [I; −[u]×; −[v]×]`` per quad."""
        w = self.weight
        Y, E = y.reshape(-1, 3, 3), (y - anchor).reshape(-1, 3, 3)
        nq = len(Y)
        Hq = np.zeros((nq, 6, 6))
        Hq[:, :3, :3] = np.eye(3)
        Hq[:, 3:, 3:] = sum(skew(Y[:, i]).transpose(0, 2, 1) @ skew(Y[:, i]) for i in (1, 2))
        gq = np.concatenate([E[:, 0], sum(np.cross(Y[:, i], E[:, i]) for i in (1, 2))], axis=1)
        idx = np.arange(6 * nq).reshape(nq, 6)
        H[idx[:, :, None], idx[:, None, :]] += w * Hq
        grad[: 6 * nq] += w * gq.ravel()


class ArticulationTerm:
    """``½ w Σ a²``: soft joints between consecutive quads (:class:`Articulation`)."""

    name = "articulation"

    def __init__(self, articulation: Articulation, weight: float) -> None:
        self.articulation, self.weight = articulation, float(weight)

    def value(self, c: np.ndarray, R: np.ndarray) -> float:
        a = self.articulation.residuals(c, R)
        return 0.5 * self.weight * float(a @ a)

    def add_rows(self, grad, H, c: np.ndarray, R: np.ndarray) -> None:
        """Add ``w JᵀJ`` and ``w Jᵀa`` to the quads' block (6 per quad 1…20)."""
        a, Ja = self.articulation.residuals(c, R, jacobian=True)
        k = Ja.shape[1]
        H[:k, :k] += self.weight * Ja.T @ Ja
        grad[:k] += self.weight * Ja.T @ a
