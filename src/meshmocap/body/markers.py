"""Virtual markers: named points of a template's surface that stand where a marker-based
system puts its reflective markers, so that a tracked surface yields marker trajectories
for biomechanics tools (C3D, TRC).

A marker is a template vertex, found on the rest mesh by a rule relative to the
evaluation joints: cast a ray from a point near a joint in an anatomical direction and
take the outermost vertex within ``radius`` of the ray among the vertices of the allowed
body parts (``part_labels``). Once chosen, it is tracked as that vertex.

The set :data:`LOWER_BODY` follows the conventional lower-body marker set (Vicon
Plug-in Gait; Davis et al., *A gait analysis data collection and reduction technique*,
Hum. Mov. Sci. 1991): anterior and posterior superior iliac spines (ASI, PSI), lateral
thigh (THI), lateral femoral epicondyle (KNE), lateral shank (TIB), lateral malleolus
(ANK), heel (HEE) and second metatarsal head (TOE), prefixed ``L``/``R``. The rules place
them on the template's skin at those landmarks' usual positions, not on bony landmarks
of the performer: they are virtual, for tools that expect these names.

Units: metres; the rest frame of templates (Z up, facing −Y, left towards +X).

References
----------
- R. B. Davis, S. Õunpuu, D. Tyburski, J. R. Gage, *A gait analysis data collection
  and reduction technique*, Human Movement Science 10(5):575–587, 1991.
  https://doi.org/10.1016/0167-9457(91)90046-Z
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from meshmocap.body.template import Template
from meshmocap.errors import InputError

__all__ = ["LOWER_BODY", "MARKER_SETS", "MarkerRule", "marker_vertices"]


@dataclass(frozen=True)
class MarkerRule:
    """Where one marker sits, for the left side (the right side mirrors x).

    Attributes
    ----------
    name : str, without its side prefix (``"ASI"``)
    anchor : tuple of (evaluation joint without side, weight) pairs; ``left_``/``right_`` is
        prefixed to names other than ``pelvis``
    offset : (3,) metres added to the weighted anchor (x mirrored on the right)
    direction : (3,) the ray's direction (x mirrored on the right)
    parts : evaluation joints (without side) whose body parts may carry the marker
    """

    name: str
    anchor: tuple[tuple[str, float], ...]
    offset: tuple[float, float, float]
    direction: tuple[float, float, float]
    parts: tuple[str, ...]


_LEG = ("pelvis", "hip", "knee", "ankle")
#: The conventional lower-body marker set (see the module docstring).
LOWER_BODY = (
    MarkerRule("ASI", (("hip", 1.0),), (0.03, 0.0, 0.07), (0.0, -1.0, 0.0), _LEG),
    MarkerRule("PSI", (("pelvis", 1.0),), (0.045, 0.0, 0.06), (0.0, 1.0, 0.0), _LEG),
    MarkerRule("THI", (("hip", 0.35), ("knee", 0.65)), (0.0, 0.0, 0.0), (1.0, 0.0, 0.0), _LEG),
    MarkerRule("KNE", (("knee", 1.0),), (0.0, 0.0, 0.0), (1.0, 0.0, 0.0), _LEG),
    MarkerRule("TIB", (("knee", 0.35), ("ankle", 0.65)), (0.0, 0.0, 0.0), (1.0, 0.0, 0.0), _LEG),
    MarkerRule("ANK", (("ankle", 1.0),), (0.0, 0.0, 0.0), (1.0, 0.0, 0.0), _LEG),
    MarkerRule("HEE", (("ankle", 1.0),), (0.0, 0.0, -0.04), (0.0, 1.0, 0.0), ("ankle",)),
    MarkerRule("TOE", (("ankle", 1.0),), (0.0, -0.12, -0.04), (0.0, 0.0, 1.0), ("ankle",)),
)
#: Marker sets by name.
MARKER_SETS = {"lower_body": LOWER_BODY}


def _joint(names: tuple[str, ...], base: str, side: str) -> int:
    name = base if base == "pelvis" else f"{side}_{base}"
    if name not in names:
        raise InputError(f"marker_vertices: the template has no evaluation joint {name!r}")
    return names.index(name)


def marker_vertices(
    template: Template, rules=LOWER_BODY, *, radius: float = 0.025
) -> tuple[tuple[str, ...], np.ndarray]:
    """Choose the template vertex of each marker of a set, both sides.

    Parameters
    ----------
    template : Template
        Its rest pose in the canonical heading (facing −Y, left towards +X) with the 15
        evaluation joints (``left_hip``, ``left_knee``, ... ``pelvis``).
    rules : sequence of MarkerRule or a name of :data:`MARKER_SETS`
    radius : float
        Metres: vertices within this distance of the ray compete (widened ×2, ×4 when none).

    Returns
    -------
    names : tuple of str, ``L``-prefixed markers then ``R``-prefixed ones
    vertices : (M,) int64, template vertex of each marker
    """
    if isinstance(rules, str):
        if rules not in MARKER_SETS:
            raise InputError(
                f"marker_vertices: marker set must be one of {list(MARKER_SETS)}, found {rules!r}"
            )
        rules = MARKER_SETS[rules]
    ev = template.eval_skeleton
    X0, V = ev.rest_positions, template.V
    names, chosen = [], []
    for side, s in (("left", 1.0), ("right", -1.0)):
        mirror = np.array([s, 1.0, 1.0])
        for rule in rules:
            anchor = sum(w * X0[_joint(ev.names, j, side)] for j, w in rule.anchor)
            origin = anchor + np.asarray(rule.offset) * mirror
            d = np.asarray(rule.direction, dtype=np.float64) * mirror
            d /= np.linalg.norm(d)
            parts = [_joint(ev.names, p, side) for p in rule.parts]
            ok = np.isin(template.part_labels, parts)
            rel = V - origin
            along = rel @ d
            perp = np.linalg.norm(rel - along[:, None] * d, axis=1)
            for r in (radius, 2 * radius, 4 * radius):
                cand = np.flatnonzero(ok & (along > 0) & (perp < r))
                if len(cand):
                    break
            else:
                raise InputError(
                    f"marker_vertices: no vertex of the template's {rule.parts} parts lies "
                    f"within {4 * radius:g} m of marker {rule.name}'s ray ({side} side)"
                )
            names.append(f"{side[0].upper()}{rule.name}")
            chosen.append(int(cand[np.argmax(along[cand])]))
    return tuple(names), np.array(chosen, dtype=np.int64)
