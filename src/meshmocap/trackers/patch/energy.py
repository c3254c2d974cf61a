"""The patch tracker's energy, assembled from its terms (patch-skeleton-tracking.txt §III)

    E(Θ, J) = λr Er(Θ) + λd Edata(Θ) + λb Ebone(Θ, J)                              # Eq. (1)

and, beyond the paper, any of the extension terms of :mod:`~meshmocap.trackers.patch.terms`.
The energy is a list of term objects (:func:`energy_terms`, from a tracker's
:class:`~meshmocap.trackers.patch.options.PatchOptions`): a term is on when it is in the
list. A step adds every term of the list to one Gauss–Newton system (:func:`assemble`) and
solves it; the frame's total energy is the sum over the same list of each term's
coefficient × value (:func:`total_energy`).

References
----------
- C.-H. Huang, E. Boyer, S. Ilic, *Robust human body shape and pose tracking*,
  International Conference on 3D Vision (3DV), 2013.
- C. Cagniart, E. Boyer, S. Ilic, *Free-form mesh tracking: a patch-based
  approach*, IEEE Conference on Computer Vision and Pattern Recognition (CVPR), 2010.
- C. Cagniart, E. Boyer, S. Ilic, *Probabilistic deformable surface tracking from
  multiple videos*, European Conference on Computer Vision (ECCV), 2010.
- M. Straka, S. Hauswiesner, M. Rüther, H. Bischof, *Simultaneous shape and pose
  adaption of articulated models using linear optimization*, European Conference on
  Computer Vision (ECCV), 2012.
"""

from __future__ import annotations

from meshmocap.trackers.patch.options import PatchOptions
from meshmocap.trackers.patch.solver import System
from meshmocap.trackers.patch.terms import (
    BoneTerm,
    DataTerm,
    Iterate,
    LengthTerm,
    ReverseTerm,
    RigidityTerm,
    SilhouetteTerm,
    TemporalTerm,
    Term,
)

__all__ = ["assemble", "energy_terms", "paper_terms", "total_energy"]


def paper_terms(o: PatchOptions) -> tuple[Term, ...]:
    """The terms of Eq. (1) with ``o``'s weights: data (Eq. 7), rigidity (Eq. 2) and bone
    binding (Eq. 11), the last two times ``o.rigidity_scale`` and ``o.bone_scale`` (1 in the
    paper's row, :data:`~meshmocap.trackers.patch.options.PAPER`)."""
    return (
        DataTerm(o.lambda_data, o.residual),
        RigidityTerm(o.lambda_rigid, o.rigidity_scale),
        BoneTerm(o.lambda_bone, o.bone_scale),
    )


def energy_terms(o: PatchOptions) -> tuple[Term, ...]:
    """The terms a tracker with options ``o`` minimises: Eq. (1)'s (:func:`paper_terms`),
    then each extension whose weight is above zero (a zero weight leaves it out of the
    list)."""
    extensions: tuple[Term, ...] = (
        ReverseTerm(o.lambda_reverse, o.reverse_cap, o.reverse_scale),
        LengthTerm(o.lambda_length),
        SilhouetteTerm(o.lambda_silhouette, o.silhouette_scale),
        TemporalTerm(o.lambda_temporal),
    )
    return (*paper_terms(o), *(t for t in extensions if t.weight > 0))


def assemble(terms: tuple[Term, ...], sys: System, it: Iterate) -> dict[str, float]:
    """Add every term of ``terms`` at ``it`` to ``sys``; returns each term's value by name."""
    return {t.name: t.add(sys, it) for t in terms}


def total_energy(terms: tuple[Term, ...], values: dict[str, float]) -> float:
    """The energy: the sum over ``terms`` of coefficient × value (``values`` by name)."""
    return float(sum(t.coefficient * values[t.name] for t in terms))
