"""Oriented Quads Rigging (OQR): 21 rigid quads at the main joints and the cage they span.

cage-manifold-tracking §3 (Fig. 1): *oriented 3D quads located at main joints*, each with
6 degrees of freedom and a constant size; *the cage is then built procedurally from the
vertices defined by the quads*, its topology computed once, its geometry updated from the
quads' positions and orientations; every cage vertex is *connected rigidly to one and
only one oriented quad* (§5.2). §6.2 generates training data from mocap by *rigidly
mapping the quads of the OQR to the skeleton* (:func:`quads_from_pose`); §4 aligns the
configurations *with respect to the position and orientation of the quad at the pelvis*
(:func:`configuration_vector`).

Quads (``QUAD_NAMES``, the rig joint each follows in ``QUAD_JOINTS``). A quad's frame
``R = [u | v | n]`` has ``n`` along the spine (up) or the limb (away from the trunk), so
the quad is a cross-section of the body; ``u`` follows the subject's left on the trunk
and legs and up (+Z) on the arms, ``v = n × u``. Placement, from the rest mesh, skeleton
and skinning weights (:func:`build_oqr`), is done in the *canonical frame*: the template
turned about Z to face −Y with its left along +X (:func:`heading`, from its hips and
shoulders); the rig is turned back, so an upright template (Z up) with any heading gets
its canonical rig turned with it:

* pelvis (Hips) at the hip joint centre; chest (Spine) on the Hips→Neck axis half a
  shoulder quad below the shoulder quads' lowest corners (just under the armpits);
  abdomen (LowerBack) halfway; the three are parallel, normal along the trunk axis;
* neck (Neck) at the neck joint and head top (Head) just above the crown, normal along
  the head bone: they box the head (both cover the head projected along that axis);
* shoulder (Arm): the first cross-section of the upper arm, scanning out from the
  shoulder joint, whose rectangle holds no trunk vertex (the armpit section);
  elbow (ForeArm) and wrist (Hand) at their joints, normal bisecting the two bones (a
  mitre); hand tip (Hand) past the finger tips; wrist and hand tip box the hand;
* hip (UpLeg): the thigh section ``2 pad`` below the crotch (the lowest point of the
  surface on the mid-sagittal plane), kept ``pad`` off that plane; knee (Leg) and ankle
  (Foot) mitred at their joints (the ankle quad cuts from the front of the ankle to
  behind the heel); toe tip (ToeBase) past the toes; ankle and toe box the foot along
  its principal axis.

Each rectangle is the bounding box, in the quad frame, of the body part's vertices within
``slab`` of the quad plane (and of the boxed part projected along the box axis), its
half-sizes times ``margin`` plus ``pad``; :func:`~meshmocap.trackers.cage.growth.untangle`
shrinks quads whose cage faces intersect and :func:`~meshmocap.trackers.cage.growth.enclose`
then grows them until every template vertex lies ``clearance`` inside the cage. Where
that fails, a second placement also boxes each upper arm (shoulder and elbow quads cover
the upper arm's vertices between them projected along the bone: arms hanging against the
trunk, whose inner side bulges out of a tube fitted to two cross-sections).

The cage (:func:`meshmocap.trackers.cage.cage_mesh.oqr_faces`): the 84 quad corners plus
an apex above
the head top (bound to the head quad): **85 vertices, 166 triangles**, a closed genus-0
2-manifold (the paper's "86 vertices and 166 faces" cannot both hold for a closed triangle
mesh of genus 0, which has ``F = 2V − 4``). Tubes of 8 triangles join consecutive quads
(15 tubes: 120), flat caps close the hand and toe tips (4 × 2), a 4-triangle pyramid the
head; the pelvis–hips "pants" take 14 triangles and the chest–shoulders–neck girdle 20.

Frames and units: world frame (Z up, any heading), metres. A
*configuration* is ``centres`` (…, 21, 3) and ``rotations`` (…, 21, 3, 3) (columns
``u, v, n`` in world coordinates).

References
----------
- E. Duveau, S. Courtemanche, L. Reveret, E. Boyer, *Cage-based motion recovery
  using manifold learning*, International Conference on 3D Imaging, Modeling,
  Processing, Visualization and Transmission (3DIMPVT), 2012.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from meshmocap._tolerances import WINDING_SLACK
from meshmocap.body.names import canonical_name_map
from meshmocap.body.skeleton import forward_kinematics
from meshmocap.body.template import Template
from meshmocap.errors import BodyPartError, InputError
from meshmocap.trackers.cage.cage_mesh import (
    CORNER_SIGNS,
    OQR_APEX,
    OQR_HEAD,
    QuadRect,
    cage_problems,
    oqr_faces,
    rect_cage,
    self_intersections,
    surface_distances,
    winding_numbers,
)
from meshmocap.trackers.cage.growth import enclose, untangle
from meshmocap.trackers.cage.oqr_placement import Placer, heading

#: The 21 quads, in this order everywhere (index ``q``; corners ``4 q … 4 q + 3``).
QUAD_NAMES = (
    "pelvis",
    "abdomen",
    "chest",
    "neck",
    "head",
    "left_shoulder",
    "left_elbow",
    "left_wrist",
    "left_hand",
    "right_shoulder",
    "right_elbow",
    "right_wrist",
    "right_hand",
    "left_hip",
    "left_knee",
    "left_ankle",
    "left_toe",
    "right_hip",
    "right_knee",
    "right_ankle",
    "right_toe",
)
#: The rig joint (CMU MotionBuilder name) each quad follows rigidly.
QUAD_JOINTS = (
    "Hips",
    "LowerBack",
    "Spine",
    "Neck",
    "Head",
    "LeftArm",
    "LeftForeArm",
    "LeftHand",
    "LeftHand",
    "RightArm",
    "RightForeArm",
    "RightHand",
    "RightHand",
    "LeftUpLeg",
    "LeftLeg",
    "LeftFoot",
    "LeftToeBase",
    "RightUpLeg",
    "RightLeg",
    "RightFoot",
    "RightToeBase",
)
N_QUADS = len(QUAD_NAMES)
PELVIS = 0


#: build_oqr's numeric options: name, (lower bound, inclusive), upper bound, unit.
_RANGES = (
    ("margin", (1.0, True), 3.0, ""),
    ("pad", (0.0, False), 0.1, " metres"),
    ("clearance", (0.0, True), 0.05, " metres"),
    ("slab", (0.0, False), 0.2, " metres"),
    ("grow_step", (0.0, False), 0.05, " metres"),
)


# ------------------------------------------------------------------------------ structures
@dataclass(frozen=True, eq=False)
class OrientedQuads:
    """The 21 rest quads of an OQR (§3): constant size, 6 degrees of freedom each.

    Parameters
    ----------
    names : tuple of str, length 21
        ``QUAD_NAMES``.
    joints : tuple of str, length 21
        Name, in the template's skeleton, of the rig joint each quad follows rigidly.
    joint_indices : (21,) int64
        Index of that joint in the template's skeleton.
    centres : (21, 3) float64
        Rest centres, metres, world frame (Z up).
    rotations : (21, 3, 3) float64
        Rest orientations; columns ``u, v, n = u × v`` in world coordinates, ``n`` along
        the limb or spine (pointing away from the pelvis), so each quad is a body
        cross-section.
    half_sizes : (21, 2) float64
        In-plane half-extents along ``u`` and ``v``, metres.
    corners : (21, 4, 3) float64
        Corners in each quad's own frame: ``(±h_u, ±h_v, 0)``, counter-clockwise about
        ``n`` (``CORNER_SIGNS`` order); world corners are ``R @ corner + centre``.
    """

    names: tuple[str, ...]
    joints: tuple[str, ...]
    joint_indices: np.ndarray
    centres: np.ndarray
    rotations: np.ndarray
    half_sizes: np.ndarray
    corners: np.ndarray

    def world_corners(self) -> np.ndarray:
        """(21, 4, 3) float64: rest corners in world coordinates, metres."""
        return np.einsum("qij,qkj->qki", self.rotations, self.corners) + self.centres[:, None]


@dataclass(frozen=True, eq=False)
class OQR:
    """An Oriented Quads Rigging and its procedural cage (precomputed by :func:`build_oqr`).

    Parameters
    ----------
    quads : OrientedQuads
        The 21 rest quads.
    faces : (166, 3) int64
        Cage triangles, counter-clockwise seen from outside (topology fixed once).
    vertex_quad : (85,) int64
        The one quad each cage vertex is rigidly bound to (corner ``k`` of quad ``q`` is
        vertex ``4 q + k``; vertex 84, the head apex, is bound to the head quad).
    vertex_local : (85, 3) float64
        Each cage vertex in its quad's frame, metres: ``v = R_q @ local + c_q``.
    rest_vertices : (85, 3) float64
        The rest cage, metres, world frame.
    template_name : str
        Name of the template it was built on.
    """

    quads: OrientedQuads
    faces: np.ndarray
    vertex_quad: np.ndarray
    vertex_local: np.ndarray
    rest_vertices: np.ndarray
    template_name: str

    @property
    def n_vertices(self) -> int:
        """Number of cage vertices (85)."""
        return len(self.vertex_quad)

    @property
    def n_faces(self) -> int:
        """Number of cage triangles (166)."""
        return len(self.faces)


def build_oqr(
    template: Template,
    *,
    margin: float = 1.15,
    pad: float = 0.005,
    clearance: float = 0.004,
    slab: float = 0.02,
    grow_step: float = 0.004,
    max_grow: int = 40,
    relaxed: bool = True,
) -> OQR:
    """Place the 21 quads on a template and build the cage they span (§3, Fig. 1).

    Placement as in the module docstring, in the template's canonical frame
    (:func:`heading`); the cage topology from
    :func:`meshmocap.trackers.cage.cage_mesh.oqr_faces`; quads
    whose cage faces intersect shrink (:func:`~meshmocap.trackers.cage.growth.untangle`: e.g.
    a trunk quad fitted with its margin into an arm that hangs against the trunk; where
    faces still intersect after it, that placement fails at once: the growth adds no
    intersection, and on a jump pose took minutes to the same verdict); then quads grow
    (:func:`~meshmocap.trackers.cage.growth.enclose`: sides in their planes, then
    where that is not enough whole quads slide along their normals; steps of ``grow_step`` to
    ``4 grow_step``, never into a new self-intersection) until every template vertex is
    inside the cage and at least ``clearance`` from it; the rig is turned back to the
    template's heading. Where the cage still fails a check, the quads are placed again
    with the upper arms boxed (module docstring) and the same steps follow; where that
    fails too (loose clothing: a long dress flaring 25 cm beyond the legs), twice more,
    relaxed: cross-sections 15 % and then 30 % wider, three times the growth iterations,
    half and then a quarter of the clearance (``relaxed``). A bundled template takes one
    placement and seconds; a clothed scan more (``docs/guide/cage.rst``).

    Parameters
    ----------
    template : Template
        Rigged template in its rest pose, CMU MotionBuilder joint names (or a flavour
        :func:`~meshmocap.body.names.canonical_name_map` maps onto them).
    margin : float, in [1, 3]
        Scale of the cross-section half-extents.
    pad, clearance, slab, grow_step : float, metres
        Padding of every quad, in (0, 0.1]; minimum distance of every template vertex to
        the cage, in [0, 0.05]; half-thickness of the cross-section slabs, in (0, 0.2];
        corner growth per iteration, in (0, 0.05].
    max_grow : int, ≥ 0
        Maximum number of growth iterations (of each of the two passes of
        :func:`~meshmocap.trackers.cage.growth.enclose`, and of
        :func:`~meshmocap.trackers.cage.growth.untangle`).
    relaxed : bool
        Also try the two relaxed rounds for loose clothing (False: fail after the first
        two placements, which a body passes in seconds).

    Returns
    -------
    OQR

    Raises
    ------
    InputError
        An option out of its range (the message names it, the range and the value).
    SkeletonError
        The skeleton lacks a joint the quads need, or its hips and shoulders give no
        horizontal left-right axis (not upright, Z up).
    BodyPartError
        A quad cannot be placed (a cross-section holds no vertex, a junction quad's corners
        cannot be told apart: a performer far from a standing pose), or every placement's
        cage fails a check (``manifold``, ``orientation``, ``outward``,
        ``self-intersection``, ``enclosure``): one line naming the body part where the
        first placement failed, and why (its ``part`` and ``reason``).
    """
    func = "build_oqr"
    if not isinstance(template, Template):
        raise InputError(f"{func}: template must be a Template, found {type(template).__name__}")
    given = dict(margin=margin, pad=pad, clearance=clearance, slab=slab, grow_step=grow_step)
    for name, low, high, unit in _RANGES:
        v = given[name]
        if (
            isinstance(v, bool)
            or not isinstance(v, int | float | np.number)
            or not (low[0] < v or (low[1] and low[0] == v))
            or not v <= high
        ):
            interval = f"{'[' if low[1] else '('}{low[0]:g}, {high:g}]"
            raise InputError(f"{func}: {name} must be a number in {interval}{unit}, found {v!r}")
    if isinstance(max_grow, bool) or not (isinstance(max_grow, int | np.integer) and max_grow >= 0):
        raise InputError(f"{func}: max_grow must be a non-negative integer, found {max_grow!r}")
    C = heading(template)  # canonical frame → world: the rig is built facing −Y
    # the second placement boxes the upper arms; the later ones relax the cage for loose
    # clothing (a long dress): wider cross-sections, three times the growth, half and then
    # a quarter of the clearance
    rounds = [
        (False, margin, clearance, max_grow),
        (True, margin, clearance, max_grow),
        (True, min(margin * 1.15, 3.0), clearance / 2, 3 * max_grow),
        (True, min(margin * 1.3, 3.0), clearance / 4, 3 * max_grow),
    ][: 4 if relaxed else 2]
    failed: list[BodyPartError] = []
    for box_limbs, margin, clearance, max_grow in rounds:
        placer = Placer(template, C, QUAD_JOINTS, float(margin), float(pad), float(slab))
        placer.box_limbs = box_limbs
        placed = placer.place()  # a part no quad can box fails every round: raised at once
        rects = [placed[name] for name in QUAD_NAMES]
        try:
            F = oqr_faces(np.stack([r.corners() for r in rects]))
        except BodyPartError as exc:
            failed.append(exc)
            continue
        head = rects[OQR_HEAD]
        apex = 0.25 * float(np.mean(head.hi - head.lo)) / 2  # a low roof over the crown
        used = untangle(rects, F, apex_height=apex, step=grow_step, max_iter=int(max_grow))
        if used == int(max_grow):  # faces may still intersect: the growth (which adds no
            # intersection) would take minutes to the same verdict (a jump pose): said now
            V = rect_cage(rects, apex)
            left = self_intersections(V, F)
            if len(left):
                problem = f"self-intersection: {len(left)} pairs of faces intersect"
                part = problem_part(V, F, template.V @ C, problem)
                failed.append(BodyPartError(problem, part=part, reason=problem))
                continue
        enclose(
            rects,
            F,
            template.V @ C,
            apex_height=apex,
            clearance=clearance,
            step=grow_step,
            max_iter=int(max_grow),
        )
        for r in rects:  # back to the world frame (lo, hi are in the quad's own frame)
            r.anchor, r.R = C @ r.anchor, C @ r.R
            if r.keep_out is not None:
                r.keep_out = (C @ r.keep_out[0], r.keep_out[1])
        V = rect_cage(rects, apex)
        problems = cage_problems(V, F, template.V, clearance=clearance)
        if not problems:
            return _assemble(template, rects, F, V)
        part = problem_part(V, F, template.V, problems[0])
        failed.append(BodyPartError(problems[0], part=part, reason=problems[0]))
    raise _refusal(func, template.name, failed)


def _refusal(func: str, name: str, failed: list[BodyPartError]) -> BodyPartError:
    """One error for the rounds of :func:`build_oqr` that failed: the first round's part
    and reason, and the other rounds' parts where they differ."""
    first = failed[0]
    others = sorted({e.part for e in failed[1:]} - {first.part})
    also = f"; other placements fail at the {', '.join(others)}" if others else ""
    return BodyPartError(
        f"{func}: template {name!r}: the {first.part}: {first.reason}{also}",
        part=first.part,
        reason=first.reason,
    )


def problem_part(V: np.ndarray, F: np.ndarray, points: np.ndarray, problem: str) -> str:
    """The body part in words where a cage (``V`` (85, 3), ``F`` (166, 3)) fails the check
    ``problem`` (a :func:`~meshmocap.trackers.cage.cage_mesh.cage_problems` message) on the
    template's vertices ``points`` (n, 3): the quads of the first pair of intersecting
    faces, or of the face nearest the first point outside the cage or too close to it;
    ``"cage"`` for a check of the whole mesh (manifold, orientation, outward)."""
    check = problem.split(":")[0]
    if check == "self-intersection":
        faces = self_intersections(V, F)[:1].ravel()
    elif check == "enclosure":
        P = np.asarray(points, dtype=np.float64)
        d, face = surface_distances(P, V, F)
        out = np.abs(winding_numbers(P, V, F) - 1.0) > WINDING_SLACK
        first = int(np.flatnonzero(out)[0]) if out.any() else int(np.argmin(d))
        faces = face[first : first + 1]
    else:
        return "cage"
    corners = F[faces].ravel()
    quads = np.unique(np.where(corners == OQR_APEX, 4 * OQR_HEAD, corners) // 4)
    return " and ".join(QUAD_NAMES[int(q)].replace("_", " ") for q in quads[:3])


def _assemble(template: Template, rects: list[QuadRect], F: np.ndarray, V: np.ndarray) -> OQR:
    R = np.stack([r.R for r in rects])
    mid = np.stack([(r.lo + r.hi) / 2 for r in rects])
    half = np.stack([(r.hi - r.lo) / 2 for r in rects])
    centres = np.stack([r.anchor for r in rects]) + np.einsum("qij,qj->qi", R[:, :, :2], mid)
    local = np.concatenate([CORNER_SIGNS[None] * half[:, None], np.zeros((N_QUADS, 4, 1))], 2)
    sk = template.skeleton
    canon = canonical_name_map(sk.names)
    joints = tuple(canon[j] for j in QUAD_JOINTS)
    oq = OrientedQuads(
        names=QUAD_NAMES,
        joints=joints,
        joint_indices=np.array([sk.index(j) for j in joints], dtype=np.int64),
        centres=centres,
        rotations=R,
        half_sizes=half,
        corners=local,
    )
    vertex_quad = np.r_[np.repeat(np.arange(N_QUADS), 4), OQR_HEAD]
    apex_local = R[OQR_HEAD].T @ (V[OQR_APEX] - centres[OQR_HEAD])
    vertex_local = np.vstack([local.reshape(-1, 3), apex_local])
    rest = _apply(vertex_quad, vertex_local, centres, R)
    for a in (oq.joint_indices, centres, R, half, local, F, vertex_quad, vertex_local, rest):
        a.setflags(write=False)
    return OQR(oq, F, vertex_quad, vertex_local, rest, template.name)


# ------------------------------------------------------------------------------ configurations
def _apply(vq: np.ndarray, local: np.ndarray, c: np.ndarray, R: np.ndarray) -> np.ndarray:
    return np.einsum("...vij,vj->...vi", R[..., vq, :, :], local) + c[..., vq, :]


def _check_config(func: str, centres, rotations) -> tuple[np.ndarray, np.ndarray]:
    c = np.asarray(centres, dtype=np.float64)
    R = np.asarray(rotations, dtype=np.float64)
    if c.ndim < 2 or c.shape[-2:] != (N_QUADS, 3):
        raise InputError(f"{func}: centres must have shape (..., {N_QUADS}, 3), found {c.shape}")
    if R.shape != (*c.shape[:-2], N_QUADS, 3, 3):
        raise InputError(
            f"{func}: rotations must have shape {(*c.shape[:-2], N_QUADS, 3, 3)}, found {R.shape}"
        )
    if not (np.all(np.isfinite(c)) and np.all(np.isfinite(R))):
        raise InputError(f"{func}: centres or rotations contain NaN or infinite values")
    return c, R


def cage_vertices(oqr: OQR, centres: np.ndarray, rotations: np.ndarray) -> np.ndarray:
    """Cage of a quad configuration: every vertex follows its quad rigidly.

    Parameters
    ----------
    oqr : OQR
    centres : (..., 21, 3) float64
        Quad centres, metres, world frame.
    rotations : (..., 21, 3, 3) float64
        Quad orientations (columns ``u, v, n`` in world).

    Returns
    -------
    (..., 85, 3) float64
        Cage vertices ``v_i = R_{q(i)} @ local_i + c_{q(i)}``, metres. At the rest
        configuration (``oqr.quads.centres``, ``oqr.quads.rotations``) this is
        ``oqr.rest_vertices``.
    """
    c, R = _check_config("cage_vertices", centres, rotations)
    return _apply(oqr.vertex_quad, oqr.vertex_local, c, R)


def configuration_vector(
    centres: np.ndarray, rotations: np.ndarray, *, relative_to_pelvis: bool = True
) -> np.ndarray:
    """Flatten quad configurations into the data vectors the pose manifold learns (§4).

    Each quad contributes 9 numbers: its centre (3) and the first two columns of its
    rotation, ``u`` then ``v`` (the continuous 6-D rotation representation: linear
    blends of valid vectors stay near valid rotations and are restored exactly by
    Gram–Schmidt in :func:`configuration_from_vector`; axis-angle would jump at π and
    quaternions carry a sign ambiguity). Positions are in metres, rotation entries in
    [−1, 1]: comparable scales for a human-sized body.

    Parameters
    ----------
    centres : (..., 21, 3) float64
        Quad centres, metres, world frame.
    rotations : (..., 21, 3, 3) float64
        Quad orientations.
    relative_to_pelvis : bool
        If True (default), express quads 1…20 in the pelvis quad's frame
        (``c' = R_0ᵀ (c − c_0)``, ``R' = R_0ᵀ R``) and drop the pelvis quad, whose relative
        configuration is constant: "we align all the shapes with respect to the position
        and orientation of the quad at the pelvis". If False, keep all 21 quads in world.

    Returns
    -------
    (..., D) float64
        ``D = 180`` (relative) or ``189`` (absolute); quad ``k`` of the kept quads
        occupies ``y[..., 9k : 9k + 9] = (c, u, v)``.
    """
    c, R = _check_config("configuration_vector", centres, rotations)
    if relative_to_pelvis:
        R0T = np.swapaxes(R[..., PELVIS, :, :], -1, -2)
        c = np.einsum("...ij,...qj->...qi", R0T, c[..., 1:, :] - c[..., PELVIS : PELVIS + 1, :])
        R = R0T[..., None, :, :] @ R[..., 1:, :, :]
    cols = np.swapaxes(R[..., :, :2], -1, -2)  # (..., q, 2, 3): rows u, v
    y = np.concatenate([c[..., None, :], cols], axis=-2)  # (..., q, 3, 3)
    return y.reshape(*y.shape[:-3], -1)


def configuration_from_vector(
    y: np.ndarray,
    pelvis_centre: np.ndarray | None = None,
    pelvis_rotation: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Inverse of :func:`configuration_vector` (rotations re-orthonormalised).

    Parameters
    ----------
    y : (..., 180) or (..., 189) float64
        Configuration vectors (relative to the pelvis quad, or absolute).
    pelvis_centre : (..., 3) float64, optional
        World centre of the pelvis quad for relative vectors (default the origin: the
        configuration in the pelvis frame). Must be omitted for absolute vectors.
    pelvis_rotation : (..., 3, 3) float64, optional
        World orientation of the pelvis quad for relative vectors (default identity).

    Returns
    -------
    centres : (..., 21, 3) float64
    rotations : (..., 21, 3, 3) float64
        Proper rotations: ``u = a/|a|``, ``v`` = the second column made orthogonal to
        ``u`` and normalised (Gram–Schmidt), ``n = u × v``.
    """
    func = "configuration_from_vector"
    y = np.asarray(y, dtype=np.float64)
    if y.ndim < 1 or y.shape[-1] not in (9 * (N_QUADS - 1), 9 * N_QUADS):
        raise InputError(
            f"{func}: y must have shape (..., {9 * (N_QUADS - 1)}) or (..., {9 * N_QUADS}), "
            f"found {y.shape}"
        )
    if not np.all(np.isfinite(y)):
        raise InputError(f"{func}: y contains NaN or infinite values")
    relative = y.shape[-1] == 9 * (N_QUADS - 1)
    if not relative and (pelvis_centre is not None or pelvis_rotation is not None):
        raise InputError(f"{func}: absolute vectors (length 189) take no pelvis pose")
    Y = y.reshape(*y.shape[:-1], -1, 3, 3)
    a, b = Y[..., 1, :], Y[..., 2, :]
    u = a / np.linalg.norm(a, axis=-1, keepdims=True)
    v = b - np.sum(u * b, axis=-1, keepdims=True) * u
    v /= np.linalg.norm(v, axis=-1, keepdims=True)
    R = np.stack([u, v, np.cross(u, v)], axis=-1)
    c = Y[..., 0, :]
    if not relative:
        return c, R
    batch = y.shape[:-1]
    c0 = np.zeros(3) if pelvis_centre is None else np.asarray(pelvis_centre, dtype=np.float64)
    R0 = np.eye(3) if pelvis_rotation is None else np.asarray(pelvis_rotation, dtype=np.float64)
    if c0.shape[-1:] != (3,) or R0.shape[-2:] != (3, 3):
        raise InputError(
            f"{func}: pelvis_centre must be (..., 3) and pelvis_rotation (..., 3, 3), "
            f"found {c0.shape} and {R0.shape}"
        )
    c0 = np.broadcast_to(c0, (*batch, 3))
    R0 = np.broadcast_to(R0, (*batch, 3, 3))
    centres = np.concatenate(
        [c0[..., None, :], np.einsum("...ij,...qj->...qi", R0, c) + c0[..., None, :]], axis=-2
    )
    rotations = np.concatenate([R0[..., None, :, :], R0[..., None, :, :] @ R], axis=-3)
    return centres, rotations


def quads_from_pose(
    oqr: OQR, template: Template, R_local: np.ndarray, root: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Rigidly map the quads to a posed skeleton (§6.2): the training configurations.

    Each quad keeps its rest pose relative to its rig joint ``j`` (world-aligned rest
    frames, so the rest global rotation is the identity)::

        R_q = G_j R_q⁰,    c_q = P_j + G_j (c_q⁰ − P_j⁰)

    Parameters
    ----------
    oqr : OQR
        Built on ``template`` (or a template with the same skeleton).
    template : Template
        Supplies the skeleton.
    R_local : (..., J, 3, 3) float64
        Local joint rotations relative to the rest frames (e.g. ``Motion.rotations``).
    root : (..., 3) float64
        World position of the root joint, metres.

    Returns
    -------
    centres : (..., 21, 3) float64, metres, world frame
    rotations : (..., 21, 3, 3) float64
    """
    func = "quads_from_pose"
    sk = template.skeleton
    J = sk.n_joints
    R_local = np.asarray(R_local, dtype=np.float64)
    root = np.asarray(root, dtype=np.float64)
    if R_local.ndim < 3 or R_local.shape[-3:] != (J, 3, 3):
        raise InputError(f"{func}: R_local must have shape (..., {J}, 3, 3), found {R_local.shape}")
    if root.shape != (*R_local.shape[:-3], 3):
        raise InputError(
            f"{func}: root must have shape {(*R_local.shape[:-3], 3)}, found {root.shape}"
        )
    j = oqr.quads.joint_indices
    if j.max() >= J or tuple(sk.names[i] for i in j) != oqr.quads.joints:
        raise InputError(f"{func}: template {template.name!r} does not have the OQR's rig joints")
    G, P = forward_kinematics(sk, R_local, root)
    Gj = G[..., j, :, :]
    offset = oqr.quads.centres - sk.rest_positions[j]
    centres = P[..., j, :] + np.einsum("...qij,qj->...qi", Gj, offset)
    return centres, Gj @ oqr.quads.rotations
