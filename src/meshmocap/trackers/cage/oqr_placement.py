"""Placement of the Oriented Quads Rigging's 21 quads on a rest template (internal).

:func:`heading` turns any upright template (Z up) to the canonical heading (facing −Y,
left +X); :class:`Placer` fits each quad as a cross-section of the body there, as
described in :mod:`meshmocap.trackers.cage.oqr` (which builds the cage from them). Metres.

References
----------
- E. Duveau, S. Courtemanche, L. Reveret, E. Boyer, *Cage-based motion recovery
  using manifold learning*, International Conference on 3D Imaging, Modeling,
  Processing, Visualization and Transmission (3DIMPVT), 2012.
"""

from __future__ import annotations

import numpy as np

from meshmocap.body.names import canonical_name_map
from meshmocap.body.template import Template
from meshmocap.errors import BodyPartError, SkeletonError
from meshmocap.trackers.cage.cage_mesh import QuadRect

_TORSO = (
    "Hips",
    "LHipJoint",
    "RHipJoint",
    "LowerBack",
    "Spine",
    "Spine1",
    "LeftShoulder",
    "RightShoulder",
)
_HEAD = ("Neck", "Neck1", "Head")
_SIDES = (("Left", "left", "LThumb"), ("Right", "right", "RThumb"))
_X, _Z = np.eye(3)[0], np.eye(3)[2]


def _unit(x: np.ndarray) -> np.ndarray:
    return x / np.linalg.norm(x, axis=-1, keepdims=True)


def _frame(n: np.ndarray, u_ref: np.ndarray) -> np.ndarray:
    """Rotation (3, 3): columns ``u`` (``u_ref`` projected on the plane ⟂ n), ``n × u``, ``n``."""
    n = _unit(n)
    u = _unit(u_ref - (u_ref @ n) * n)
    return np.stack([u, np.cross(n, u), n], axis=1)


def _principal_axis(X: np.ndarray, hint: np.ndarray) -> np.ndarray:
    """First principal direction of points ``X`` (k, 3), signed to agree with ``hint``."""
    _, _, Vt = np.linalg.svd(X - X.mean(axis=0), full_matrices=False)
    return Vt[0] if Vt[0] @ hint >= 0 else -Vt[0]


def heading(template: Template) -> np.ndarray:
    """Rotation (3, 3) about +Z from the canonical heading (facing −Y, left +X) to the
    template's, whose left is the horizontal part of its hips' plus its shoulders'
    left-minus-right rest positions (``LeftUpLeg − RightUpLeg + LeftArm − RightArm``).

    Exactly the identity for a template whose left points along +X (the bundled ones).

    Raises
    ------
    SkeletonError
        The skeleton lacks those joints, or they give no horizontal left direction (the
        subject is not upright, Z up).
    """
    sk = template.skeleton
    canon = canonical_name_map(sk.names)
    need = ("LeftUpLeg", "RightUpLeg", "LeftArm", "RightArm")
    missing = [n for n in need if n not in canon]
    if missing:
        raise SkeletonError(f"build_oqr: the template's skeleton lacks joints {missing}")
    P = sk.rest_positions
    lat = sum(
        P[sk.index(canon[f"Left{j}"])] - P[sk.index(canon[f"Right{j}"])] for j in ("UpLeg", "Arm")
    )
    h = float(np.hypot(lat[0], lat[1]))
    if not h > 0.1 * np.linalg.norm(lat):
        raise SkeletonError(
            f"build_oqr: template {template.name!r}: the left-right axis of its hips and "
            f"shoulders {np.round(lat, 3).tolist()} has no horizontal direction; the "
            "subject must stand upright (Z up)"
        )
    c, s = lat[0] / h, lat[1] / h
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


class Placer:
    """Places the 21 quads on a MotionBuilder-named template
    (:mod:`meshmocap.trackers.cage.oqr`), in the canonical frame: the template turned by ``C.T``
    about Z (``C`` from :func:`heading`), so that it faces −Y with its left along +X.
    ``joints`` are the rig joints the quads follow (all must exist);
    :meth:`Placer.place` returns the quads by name (``QUAD_NAMES``), in that frame. With
    ``box_limbs`` set (default False) the shoulder and elbow quads also cover the upper
    arm's vertices between them, projected along the shoulder→elbow bone."""

    def __init__(
        self,
        t: Template,
        C: np.ndarray,
        joints: tuple[str, ...],
        margin: float,
        pad: float,
        slab: float,
    ) -> None:
        sk = t.skeleton
        canon = canonical_name_map(sk.names)
        missing = sorted((set(joints) | set(_TORSO) | set(_HEAD)) - set(canon))
        if missing:
            raise SkeletonError(f"build_oqr: the template's skeleton lacks joints {missing}")
        self.idx = {name: sk.index(canon[name]) for name in canon}
        P, B = sk.rest_positions @ C, sk.bone_directions @ C  # row vectors: x' = Cᵀ x
        self.P = {name: P[i] for name, i in self.idx.items()}
        self.bone = {name: B[i] for name, i in self.idx.items()}
        self.t, self.V = t, t.V @ C
        self.owner = np.asarray(t.weights.argmax(axis=1)).ravel()  # rig joint of each vertex
        self.margin, self.pad, self.slab = margin, pad, slab
        self.box_limbs = False

    def part(self, *names: str) -> np.ndarray:
        """Return the (n,) bool mask of the vertices owned by the joints ``names``."""
        return np.isin(self.owner, [self.idx[n] for n in names if n in self.idx])

    def fit(self, name, anchor, n, u_ref, section, box=None, axis=None, keep_out=None) -> QuadRect:
        """Quad ``name`` through ``anchor`` ⟂ ``n`` covering the ``section`` vertices within
        the slab and the ``box`` vertices projected along ``axis``, scaled by the margin."""
        R = _frame(n, u_ref)
        rel = self.V - anchor
        pts = [rel[section & (np.abs(rel @ R[:, 2]) <= self.slab)]]
        if box is not None:
            r = rel[box]
            pts.append(r - ((r @ R[:, 2]) / (axis @ R[:, 2]))[:, None] * axis)
        uv = np.concatenate(pts) @ R[:, :2]
        if not len(uv):
            reason = f"its cross-section holds no vertex within {self.slab:g} m of its plane"
            raise self.refused(name, reason)
        lo, hi = uv.min(axis=0), uv.max(axis=0)
        mid, half = (lo + hi) / 2, (hi - lo) / 2 * self.margin + self.pad
        q = QuadRect(np.asarray(anchor, float), R, mid - half, mid + half, keep_out)
        q.clamp()
        return q

    def crotch(self, lateral: np.ndarray) -> np.ndarray:
        """(3,) the lowest point above the knees of the vertices within ``pad`` of the
        mid-sagittal plane (through the hip joint centre, normal ``lateral``) and of the
        points where mesh edges cross that plane (a coarse mesh may have no vertex near
        it)."""
        P, V = self.P, self.V
        s = (V - P["Hips"]) @ lateral
        E = self.t.F[:, [[0, 1], [1, 2], [2, 0]]].reshape(-1, 2)
        E = E[np.sign(s[E[:, 0]]) * np.sign(s[E[:, 1]]) < 0]
        w = (s[E[:, 0]] / (s[E[:, 0]] - s[E[:, 1]]))[:, None]
        X = np.concatenate([V[np.abs(s) < self.pad], (1 - w) * V[E[:, 0]] + w * V[E[:, 1]]])
        X = X[X[:, 2] > max(P["LeftLeg"][2], P["RightLeg"][2])]
        if not len(X):
            raise self.refused("crotch", "no surface between the legs above the knees")
        return X[np.argmin(X[:, 2])]

    def refused(self, name: str, reason: str) -> BodyPartError:
        """The error of a quad ``name`` (a ``QUAD_NAMES`` entry or a part's name)
        that cannot be placed, naming the body part."""
        part = name.replace("_", " ")
        return BodyPartError(
            f"build_oqr: template {self.t.name!r}: the {part}: {reason}", part=part, reason=reason
        )

    def clear(self, quads: list[QuadRect], other: np.ndarray) -> QuadRect:
        """The first quad whose rectangle (grown by ``pad``, within the slab) holds no
        ``other`` vertex: the first cross-section of a limb clear of the trunk."""
        X = self.V[other]
        for q in quads:
            rel = X - q.anchor
            uv = rel @ q.R[:, :2]
            inside = (np.abs(rel @ q.R[:, 2]) <= self.slab) & np.all(
                (uv >= q.lo - self.pad) & (uv <= q.hi + self.pad), axis=1
            )
            if not inside.any():
                return q
        return quads[-1]

    def place(self) -> list[QuadRect]:
        """Return the 21 quads, in the canonical frame (see the class docstring)."""
        P, bone, part = self.P, self.bone, self.part
        torso, head = part(*_TORSO), part(*_HEAD)
        out: dict[str, QuadRect] = {}
        steps = np.arange(0.0, 0.5, 0.005)  # fraction of a bone's length scanned
        lateral = _unit(P["LeftUpLeg"] - P["RightUpLeg"])
        crotch = self.crotch(lateral)
        for s, side, thumb in _SIDES:
            arm = part(
                f"{s}Arm", f"{s}ForeArm", f"{s}Hand", f"{s}FingerBase", f"{s}HandIndex1", thumb
            )
            hand = part(f"{s}Hand", f"{s}FingerBase", f"{s}HandIndex1", thumb)
            pa, pe, pw = P[f"{s}Arm"], P[f"{s}ForeArm"], P[f"{s}Hand"]
            d1, d2 = _unit(pe - pa), _unit(pw - pe)
            if not hand.any():
                raise self.refused(f"{side}_hand", "no vertex is skinned to the hand")
            d3 = _unit(self.V[hand].mean(axis=0) - pw)
            # shoulder: the first cross-section of the upper arm clear of the torso
            L = np.linalg.norm(pe - pa)
            cand = [self.fit(f"{side}_shoulder", pa + f * L * d1, d1, _Z, arm) for f in steps]
            sh = out[f"{side}_shoulder"] = self.clear(cand, torso)
            out[f"{side}_elbow"] = self.fit(f"{side}_elbow", pe, d1 + d2, _Z, arm)
            if self.box_limbs:  # both quads cover the upper arm projected along its bone
                h = (self.V - sh.anchor) @ d1
                upper = arm & (h >= 0) & (h <= (pe - sh.anchor) @ d1)
                boxed = ((f"{side}_shoulder", sh.anchor, d1), (f"{side}_elbow", pe, d1 + d2))
                for q, a, n in boxed:
                    out[q] = self.fit(q, a, n, _Z, arm, upper, d1)
            out[f"{side}_wrist"] = self.fit(f"{side}_wrist", pw, d2 + d3, _Z, arm, hand, d3)
            tip = pw + (((self.V[hand] - pw) @ d3).max() + self.pad) * d3
            out[f"{side}_hand"] = self.fit(f"{side}_hand", tip, d3, _Z, hand & False, hand, d3)
            # leg: the first cross-section of the thigh below the crotch, not crossing
            # the mid-sagittal plane; mitred knee and ankle; a foot box to the toe tips
            leg = part(f"{s}UpLeg", f"{s}Leg", f"{s}Foot", f"{s}ToeBase")
            foot = part(f"{s}Foot", f"{s}ToeBase")
            if not foot.any():
                raise self.refused(f"{side}_foot", "no vertex is skinned to the foot")
            ph, pk, pf = P[f"{s}UpLeg"], P[f"{s}Leg"], P[f"{s}Foot"]
            e1, e2 = _unit(pk - ph), _unit(pf - pk)
            e3 = _principal_axis(self.V[foot], bone[f"{s}Foot"])
            m = lateral if s == "Left" else -lateral
            keep = (m, m @ P["Hips"] + self.pad)
            below = (crotch - ph) @ e1 + 2 * self.pad
            hip = ph + below * e1
            out[f"{side}_hip"] = self.fit(f"{side}_hip", hip, e1, _X, leg, keep_out=keep)
            out[f"{side}_knee"] = self.fit(f"{side}_knee", pk, e1 + e2, _X, leg)
            out[f"{side}_ankle"] = self.fit(f"{side}_ankle", pf, e2 + e3, _X, leg, foot, e3)
            tip = pf + (((self.V[foot] - pf) @ e3).max() + self.pad) * e3
            out[f"{side}_toe"] = self.fit(f"{side}_toe", tip, e3, _X, foot & False, foot, e3)
        # torso: the chest section just below the armpits (the shoulder quads' lowest
        # corners), the pelvis at the hip joints, the abdomen halfway; parallel quads
        low = np.concatenate([out[f"{s}_shoulder"].corners() for s in ("left", "right")])
        base = P["Hips"]
        axis = _unit(P["Neck"] - base)
        drop = np.mean(
            [
                (out[f"{s}_shoulder"].hi[0] - out[f"{s}_shoulder"].lo[0]) / 4
                for s in ("left", "right")
            ]
        )
        chest = base + (((low - base) @ axis).min() - drop) * axis
        axis = _unit(chest - base)
        section = torso | part("LeftUpLeg", "RightUpLeg")
        out["pelvis"] = self.fit("pelvis", base, axis, _X, section)
        out["abdomen"] = self.fit("abdomen", (base + chest) / 2, axis, _X, torso)
        out["chest"] = self.fit("chest", chest, axis, _X, torso)
        # neck and head top: a box around the head along the head bone
        h = bone["Head"]
        if not head.any():
            raise self.refused("head", "no vertex is skinned to the head or neck")
        out["neck"] = self.fit("neck", P["Neck"], h, _X, head, head, h)
        top = P["Head"] + (((self.V[head] - P["Head"]) @ h).max() + self.pad) * h
        out["head"] = self.fit("head", top, h, _X, head & False, head, h)
        return out
