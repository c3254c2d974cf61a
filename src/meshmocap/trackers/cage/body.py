"""The body the cage is built on (cage-manifold-tracking §3, §6.3).

The Oriented Quads Rigging encloses a *body*: a closed, well-formed human surface whose
limbs the quads' cross-sections can box. A performer's own surface is not always one: a
dress flaring far beyond the legs, a loose sleeve, a scan with arms pressed into a jacket
give a cage that folds over itself or leaves the clothing outside. The paper's motion
transfer (§6.3) shows the way out: any surface placed in a cage follows it through Green
coordinates. So the cage is built on a body that is always well formed, and the
performer's real surface is bound to that cage:

* ``body="template"`` (the paper): the cage is built on the tracking template itself
  (:func:`~meshmocap.trackers.cage.oqr.build_oqr` with its relaxed rounds for clothing);
* ``body="reference"``: on the bundled reference body (``neutral``) posed and scaled onto
  the template's rest skeleton (:func:`posed_reference`): the same joints at the same
  places, a body's surface around them;
* ``body="auto"`` (default): the template where its cage builds without relaxing (bundled
  bodies, a clean scan), else the reference body.

Where the body is not the template, the tracker binds the template's vertices to the
body's rest cage (:class:`~meshmocap.trackers.cage.surface.GreenSurface`, or the
template's own skinning from the quads: the two skeletons coincide), so a dress or loose
sleeve rides along with the cage.

Frames and units: world frame (Z up), metres.

References
----------
- E. Duveau, S. Courtemanche, L. Reveret, E. Boyer, *Cage-based motion recovery
  using manifold learning*, International Conference on 3D Imaging, Modeling,
  Processing, Visualization and Transmission (3DIMPVT), 2012.
- Y. Lipman, D. Levin, D. Cohen-Or, *Green coordinates*, ACM Transactions on Graphics
  27(3) (SIGGRAPH 2008). https://doi.org/10.1145/1360612.1360677
"""

from __future__ import annotations

import numpy as np

from meshmocap._tolerances import ANTIPARALLEL, DEGENERATE_AXIS
from meshmocap.body.autorig import rest_in_pose
from meshmocap.body.template import Template, load_template
from meshmocap.errors import BodyPartError, InputError, MeshError, MeshmocapError, SkeletonError
from meshmocap.trackers.cage.options import Body
from meshmocap.trackers.cage.oqr import OQR, build_oqr

__all__ = ["Body", "cage_body", "posed_reference"]


def _turn(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Smallest rotation (3, 3) turning direction ``a`` onto ``b`` (Rodrigues)."""
    a, b = a / np.linalg.norm(a), b / np.linalg.norm(b)
    v, c = np.cross(a, b), float(a @ b)
    if c < -1 + ANTIPARALLEL:  # antiparallel: π about an axis orthogonal to a
        o = np.cross(a, [1.0, 0.0, 0.0])
        o = o if np.linalg.norm(o) > DEGENERATE_AXIS else np.cross(a, [0.0, 1.0, 0.0])
        o /= np.linalg.norm(o)
        return 2 * np.outer(o, o) - np.eye(3)
    K = np.array([[0, -v[2], v[1]], [v[2], 0, -v[0]], [-v[1], v[0], 0]])
    return np.eye(3) + K + K @ K / (1.0 + c)


def posed_reference(template: Template, *, reference: str | Template = "neutral") -> Template:
    """The reference body posed and scaled onto ``template``'s rest skeleton, as a template
    whose rest pose is that pose (:func:`~meshmocap.body.autorig.rest_in_pose`).

    One scale (the ratio of the skeletons' summed bone lengths) and, joint by joint from
    the root, the rotation that carries the reference's bones onto the template's: the
    smallest turn for a joint with one child, a Procrustes fit for several, the parent's
    for an end joint. A template rigged with the reference's skeleton
    (:func:`~meshmocap.body.autorig.rig_mesh`) gets its joints back to rounding.

    Raises
    ------
    SkeletonError
        The skeletons do not have the same joints.
    """
    ref = reference if isinstance(reference, Template) else load_template(reference)
    sk, rk = template.skeleton, ref.skeleton
    if tuple(sk.names) != tuple(rk.names) or not np.array_equal(sk.parents, rk.parents):
        raise SkeletonError(
            f"cage body: template {template.name!r} does not have the reference "
            f"{ref.name!r}'s joints; give body='template'"
        )
    P, Q, par = sk.rest_positions, rk.rest_positions, np.asarray(sk.parents)
    bones = par >= 0
    s = (
        np.linalg.norm(P[bones] - P[par[bones]], axis=1).sum()
        / np.linalg.norm(Q[bones] - Q[par[bones]], axis=1).sum()
    )
    J = len(P)
    G = np.tile(np.eye(3), (J, 1, 1))
    for level in sk.levels:
        for j in level:
            kids = np.flatnonzero(par == j)
            Gp = G[par[j]] if par[j] >= 0 else np.eye(3)
            if len(kids) == 1:
                a = Gp @ (s * (Q[kids[0]] - Q[j]))
                G[j] = _turn(a, P[kids[0]] - P[j]) @ Gp
            elif len(kids) > 1:
                H = (s * (Q[kids] - Q[j])).T @ (P[kids] - P[j])
                U, _, Vt = np.linalg.svd(H)
                D = np.diag([1.0, 1.0, np.sign(np.linalg.det(Vt.T @ U.T))])
                G[j] = Vt.T @ D @ U.T
            else:
                G[j] = Gp
    R = np.stack([G[j] if par[j] < 0 else G[par[j]].T @ G[j] for j in range(J)])
    return rest_in_pose(ref, R, P[0], scale=float(s), name=f"{template.name}_body")


def cage_body(template: Template, *, body: Body = "auto") -> tuple[Template, OQR]:
    """The body the cage is built on and its rigging (module docstring).

    Raises
    ------
    MeshError
        No cage could be built: one line naming the part of the body where it failed
        (a :class:`~meshmocap.errors.BodyPartError` where the rigging names one), why,
        and the alternative.
    """
    if body not in ("auto", "template", "reference"):
        raise InputError(f"cage: body must be one of auto, template, reference, found {body!r}")
    why: MeshmocapError | None = None
    if body in ("auto", "template"):
        try:
            return template, build_oqr(template, relaxed=body == "template")
        except (MeshError, SkeletonError) as exc:
            if body == "template":
                raise MeshError(
                    f"cage: no cage encloses template {template.name!r}: {_where(exc)}; build "
                    "it on the reference body (body='reference') or track with --method patch"
                ) from None
            why = exc
    try:  # a body: its cage builds without the relaxed rounds, or not at all (fast)
        posed = posed_reference(template)
        return posed, build_oqr(posed, relaxed=False)
    except (MeshError, SkeletonError) as exc:
        said = _where(exc)
        if why is None:
            where = f"on the reference body, {said}"
        elif _where(why) == said:
            where = f"{said} (on the reference body too)"
        else:
            where = f"{_where(why)} (on the reference body: {said})"
        raise MeshError(
            f"cage: no cage could be built for template {template.name!r}: {where}; "
            "track with --method patch instead"
        ) from None


def _where(exc: MeshmocapError) -> str:
    """Where and why a rigging failed, in words: ``the <part>: <reason>`` for a
    :class:`~meshmocap.errors.BodyPartError`, else its message."""
    if isinstance(exc, BodyPartError):
        return f"the {exc.part}: {exc.reason}"
    return str(exc)
