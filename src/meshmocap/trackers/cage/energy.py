"""The cage tracker's energy, assembled from its terms (cage-manifold-tracking §5)

    E(x, Γ) = ½ Σ_i w_i d_DF(M_i(x, Γ))² / n  +  λσ · log σ²(x)                    # Eq. (4)–(5)

and, beyond the paper, the coverage terms and the local adjustment's anchor and soft joints
(:mod:`~meshmocap.trackers.cage.terms`). The energy is a list of term objects
(:func:`energy_terms`, from ``CageOptions.terms``): a term is on when it is in the list.
Each problem of the tracker takes the terms of the list that take part in it
(:func:`stage_terms`), adds them to one system (:func:`assemble`), and its energy is the
sum over the same terms of coefficient × value (:func:`total_energy`).

References
----------
- E. Duveau, S. Courtemanche, L. Reveret, E. Boyer, *Cage-based motion recovery
  using manifold learning*, International Conference on 3D Imaging, Modeling,
  Processing, Visualization and Transmission (3DIMPVT), 2012.
"""

from __future__ import annotations

from meshmocap.trackers.cage.options import CageOptions
from meshmocap.trackers.cage.terms import (
    AnchorTerm,
    ArticulationTerm,
    CoverageTerm,
    DistanceTerm,
    Iterate,
    SilhouetteTerm,
    Stage,
    System,
    Term,
    VarianceTerm,
)

__all__ = ["assemble", "energy_terms", "stage_terms", "total_energy"]


def energy_terms(o: CageOptions) -> tuple[Term, ...]:
    """The terms of ``o.terms``, in that order, with ``o``'s weights and settings: the
    paper's distance field sum (Eq. 4) and variance regulariser (Eq. 5); the hull and
    silhouette coverage terms, the local adjustment's anchor and soft joints (ours)."""
    make = {
        "distance": lambda: DistanceTerm(o.inside_weight, o.outside_margin, o.outside_cap),
        "variance": lambda: VarianceTerm(o.variance_weight),
        "coverage": lambda: CoverageTerm(o.coverage_weight),
        "silhouette": lambda: SilhouetteTerm(o.silhouette_weight),
        "anchor": lambda: AnchorTerm(o.anchor_weight),
        "articulation": lambda: ArticulationTerm(o.articulation),
    }
    return tuple(make[name]() for name in o.terms)


def stage_terms(terms: tuple[Term, ...], stage: Stage) -> tuple[Term, ...]:
    """The terms of ``terms`` that take part in the problem ``stage``, in list order."""
    return tuple(t for t in terms if stage in t.stages)


def assemble(terms: tuple[Term, ...], sys: System, it: Iterate) -> dict[str, float]:
    """Add every term of ``terms`` at ``it`` to ``sys``; returns each term's value by name."""
    return {t.name: t.add(sys, it) for t in terms}


def total_energy(terms: tuple[Term, ...], values: dict[str, float]) -> float:
    """The energy: the sum over ``terms`` of coefficient × value (``values`` by name)."""
    return float(sum(t.coefficient * values[t.name] for t in terms))
