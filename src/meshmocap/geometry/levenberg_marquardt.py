"""One damped Gauss–Newton (Levenberg–Marquardt) solve for every fit in meshmocap.

Every tracker and fit linearises its residuals ``r`` in its parameters, ``J = ∂r/∂θ``, and
solves the damped normal equations for the step ``δ``; all of them take it here, by one
rule (Marquardt 1963, "An algorithm for least-squares estimation of nonlinear
parameters", SIAM J. Appl. Math. 11(2); Nocedal & Wright, *Numerical Optimization*, 2nd
ed., 2006, §10.3)::

    (H + λ·diag(H) + ε·I) δ = −g,    H = JᵀJ,  g = Jᵀr,  ε = floor · median{H_ii > 0}

* **λ relative to the diagonal** (Marquardt's scaling: the damping of each unknown is its
  own curvature times λ, so it does not depend on the unknown's units: metres, radians,
  latent units). Small λ: a Gauss–Newton step; large λ: a short gradient step.
* **ε, a floor** relative to the median curvature (1 where no entry is positive): an
  unknown that nothing constrains (a zero row of ``H``, with a zero gradient) stays at
  zero instead of making the system singular, and a weakly observed one cannot take a
  huge step.
* **Bounded retries**: where the damped matrix is singular or the step not finite, λ is
  multiplied by 10 (at least :data:`LAMBDA_MIN`) and the solve retried, at most
  :data:`RETRIES` times; then :class:`~meshmocap.errors.FitError` (never a raw
  ``LinAlgError``): the tracking driver flags the frame and coasts across it.

Callers that keep a step only where it lowers their cost adapt λ across iterations with
:class:`AdaptiveDamping` (Marquardt's strategy, Nocedal & Wright §10.3): ÷ 10 after an
accepted step (never below :data:`LAMBDA_MIN`), × 10 after a rejected one, giving up past
:data:`LAMBDA_MAX`.

:data:`DAMPING` holds every caller's λ and floor: the only damping values in meshmocap.

References
----------
- D. W. Marquardt, *An algorithm for least-squares estimation of nonlinear
  parameters*, Journal of the Society for Industrial and Applied Mathematics
  11(2):431–441, 1963. https://doi.org/10.1137/0111030
- J. Nocedal, S. J. Wright, *Numerical Optimization*, 2nd ed., Springer, 2006.
  https://doi.org/10.1007/978-0-387-40065-5
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from meshmocap.errors import FitError

__all__ = [
    "DAMPING",
    "LAMBDA_MAX",
    "LAMBDA_MIN",
    "RETRIES",
    "AdaptiveDamping",
    "Damping",
    "damped_diagonal",
    "damped_solve",
    "solve_damped",
]

#: Retries of a singular solve, each with λ × 10, before :class:`FitError`.
RETRIES = 4
#: λ never falls below this after an accepted step (:class:`AdaptiveDamping`), and a retry
#: of a solve with λ = 0 starts here.
LAMBDA_MIN = 1e-9
#: :class:`AdaptiveDamping` gives up once λ exceeds this: the step is then a vanishing
#: gradient step, and no longer worth its cost.
LAMBDA_MAX = 1e8


@dataclass(frozen=True)
class Damping:
    """One caller's damping rule: ``lam`` (λ, or its start where the caller adapts it) and
    ``floor`` (ε relative to the median diagonal entry), see the module docstring."""

    lam: float
    floor: float


#: Every damped solve's λ and floor, by caller (the module docstring gives the rule).
DAMPING: dict[str, Damping] = {
    # articulated fits with closest-point pairs (trackers.articulated_icp's default is
    # "icp"; estimate.pose.fit's first-pose search, body.autorig, estimate.performer.shape_fit)
    "articulated": Damping(1e-2, 1e-9),
    "icp": Damping(1e-3, 1e-9),
    # known correspondences: a lighter λ (estimate.pose.fit.pose_of_vertices)
    "vertex": Damping(1e-3, 1e-9),
    # body.pose_fit: adaptive, from this λ
    "pose_fit": Damping(1e-6, 1e-9),
    # trackers.cage: adaptive per problem, from this λ
    "cage": Damping(1e-3, 1e-9),
    # trackers.patch: a floor a thousandth of the median curvature keeps the spin of a
    # small patch about its own centre (weakly observed) from taking huge steps
    "patch": Damping(1e-4, 1e-3),
    # no damping: a system positive definite by construction (I + μ JᵀJ)
    "none": Damping(0.0, 0.0),
}


def damped_diagonal(d: np.ndarray, lam: float, floor: float) -> np.ndarray:
    """What the rule adds to the diagonal ``d`` (n,) of ``H``: ``λ·d + ε`` with
    ``ε = floor · median{d_i > 0}`` (1 in place of the median where no entry is positive).

    Returns
    -------
    (n,) float64
    """
    d = np.asarray(d, dtype=np.float64)
    # the median of the positive entries as np.median takes it (the middle one, or the
    # mean of the two middle ones), without its ~20 µs of overhead a call: solves come
    # hundreds of times a frame (NaN never passes d > 0)
    pos = np.sort(d[d > 0])
    m = len(pos) // 2
    if not len(pos):
        scale = 1.0
    elif len(pos) % 2:
        scale = float(pos[m])
    else:
        scale = float((pos[m - 1] + pos[m]) / 2)
    return lam * d + floor * scale


def solve_damped(
    solve: Callable[[np.ndarray], np.ndarray],
    d: np.ndarray,
    *,
    lam: float,
    floor: float,
    what: str = "normal equations",
) -> np.ndarray:
    """The damped step ``δ`` by the rule of the module docstring, for a caller that factors
    its own ``H`` (sparse, structured): ``solve(add)`` returns ``δ`` of
    ``(H + diag(add)) δ = −g`` or raises ``numpy.linalg.LinAlgError`` where that matrix is
    singular. ``d`` (n,) is the diagonal of ``H``.

    Raises
    ------
    FitError
        Still singular, or the step not finite, after :data:`RETRIES` retries (λ × 10 each);
        the message names ``what``.
    """
    reason = "a non-finite step"
    for _ in range(RETRIES + 1):
        try:
            delta = solve(damped_diagonal(d, lam, floor))
        except np.linalg.LinAlgError as exc:
            reason = str(exc) or "singular"
        else:
            if np.all(np.isfinite(delta)):
                return delta
            reason = "a non-finite step"
        lam = max(10.0 * lam, LAMBDA_MIN)
    raise FitError(f"singular {what} ({reason}, after {RETRIES} retries with more damping)")


def damped_solve(
    H: np.ndarray, g: np.ndarray, *, lam: float, floor: float, what: str = "normal equations"
) -> np.ndarray:
    """The step ``δ`` of ``(H + λ·diag(H) + ε·I) δ = −g`` (module docstring), dense.

    Parameters
    ----------
    H : (n, n) float64
        Gauss–Newton matrix ``JᵀJ`` (plus any priors'), symmetric; not changed.
    g : (n,) float64
        Gradient ``Jᵀr``.
    lam, floor : float
        λ and the floor of ε (:data:`DAMPING`).
    what : str
        Names the system in the error.

    Returns
    -------
    (n,) float64

    Raises
    ------
    FitError
        ``H`` or ``g`` not finite, or the damped system singular after :data:`RETRIES`
        retries.
    """
    H = np.asarray(H, dtype=np.float64)
    g = np.asarray(g, dtype=np.float64)
    if not (np.all(np.isfinite(H)) and np.all(np.isfinite(g))):
        raise FitError(f"singular {what} (non-finite entries)")
    diag = np.diag_indices(len(H))

    def solve(add: np.ndarray) -> np.ndarray:
        A = H.copy()
        A[diag] += add
        return np.linalg.solve(A, -g)

    return solve_damped(solve, H[diag], lam=lam, floor=floor, what=what)


@dataclass
class AdaptiveDamping:
    """λ of a fit that keeps a step only where it lowers the cost (module docstring).

    Attributes
    ----------
    lam : float
        The current λ.
    """

    lam: float

    def accepted(self) -> None:
        """A step lowered the cost: λ ÷ 10, not below :data:`LAMBDA_MIN`."""
        self.lam = max(self.lam / 10.0, LAMBDA_MIN)

    def rejected(self) -> bool:
        """A step raised the cost: λ × 10. Returns False once λ exceeds :data:`LAMBDA_MAX`
        (give up: no step worth its cost is left)."""
        self.lam = max(10.0 * self.lam, LAMBDA_MIN)
        return self.lam <= LAMBDA_MAX
