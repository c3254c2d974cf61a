"""Skeletons and forward kinematics.

A :class:`Skeleton` is a tree of ``J`` joints. Joint frames are *world-aligned at rest*:
the rest pose has identity orientation everywhere, so a skeleton is fully described by
each joint's rest offset from its parent (the BVH convention). A pose is a local rotation
per joint, relative to that rest orientation, plus the root's world position.

Canonical names: ``J`` joints, ``R`` rotations ``(..., J, 3, 3)``, ``t`` translations.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import cached_property

import numpy as np

from meshmocap._tolerances import ZERO_EXTENT
from meshmocap.errors import SkeletonError


@dataclass(frozen=True, eq=False)
class Skeleton:
    """A joint tree with world-aligned rest frames.

    Parameters
    ----------
    names : sequence of str, length J
        Unique joint names.
    parents : (J,) int
        Parent index of each joint, ``-1`` for the root (exactly one root, joint 0); every
        parent comes before its children.
    offsets : (J, 3) float64
        Rest position of each joint relative to its parent, in the parent's (world-aligned)
        rest frame; for the root, its rest position. Metres, Z up (unless stated otherwise
        by a reader before conversion).
    end_offsets : (J, 3) float64, optional
        Rest position of each bone's tail relative to its joint. Defines the bone direction
        of leaf joints (toes, head, fingers); zeros where unknown.
    """

    names: tuple[str, ...]
    parents: np.ndarray
    offsets: np.ndarray
    end_offsets: np.ndarray = field(default=None)  # type: ignore[assignment]

    def __post_init__(self) -> None:
        names = tuple(str(n) for n in self.names)
        parents = np.asarray(self.parents, dtype=np.int64).reshape(-1)
        offsets = np.asarray(self.offsets, dtype=np.float64)
        J = len(names)
        if J == 0:
            raise SkeletonError("skeleton: expected at least one joint, found none")
        if len(set(names)) != J:
            dup = sorted({n for n in names if names.count(n) > 1})
            raise SkeletonError(f"skeleton: joint names must be unique, found duplicates {dup}")
        if parents.shape != (J,):
            raise SkeletonError(f"skeleton: expected {J} parents, found {parents.shape[0]}")
        if offsets.shape != (J, 3):
            raise SkeletonError(
                f"skeleton: offsets must have shape ({J}, 3), found {offsets.shape}"
            )
        if parents[0] != -1 or np.any(parents[1:] < 0) or np.any(parents[1:] >= np.arange(1, J)):
            raise SkeletonError(
                "skeleton: joint 0 must be the only root and every parent must precede its child"
            )
        if not np.all(np.isfinite(offsets)):
            raise SkeletonError("skeleton: offsets contain NaN or infinite values")
        end = self.end_offsets
        end = np.zeros((J, 3)) if end is None else np.asarray(end, dtype=np.float64)
        if end.shape != (J, 3) or not np.all(np.isfinite(end)):
            raise SkeletonError(f"skeleton: end_offsets must be finite with shape ({J}, 3)")
        object.__setattr__(self, "names", names)
        object.__setattr__(self, "parents", parents)
        object.__setattr__(self, "offsets", offsets)
        object.__setattr__(self, "end_offsets", end)
        for a in (parents, offsets, end):
            a.setflags(write=False)

    @property
    def n_joints(self) -> int:
        """Number of joints ``J``."""
        return len(self.names)

    def index(self, name: str) -> int:
        """Return the index of joint ``name``; raise :class:`SkeletonError` if unknown."""
        try:
            return self._index[name]
        except KeyError:
            raise SkeletonError(
                f"skeleton: no joint named {name!r}; joints are {list(self.names)}"
            ) from None

    @cached_property
    def _index(self) -> dict[str, int]:
        return {n: i for i, n in enumerate(self.names)}

    @cached_property
    def children(self) -> tuple[tuple[int, ...], ...]:
        """Children indices of each joint."""
        kids: list[list[int]] = [[] for _ in self.names]
        for j, p in enumerate(self.parents[1:], start=1):
            kids[p].append(j)
        return tuple(tuple(k) for k in kids)

    @cached_property
    def levels(self) -> tuple[np.ndarray, ...]:
        """Joint indices grouped by depth (root first), for level-by-level kinematics."""
        depth = np.zeros(self.n_joints, dtype=np.int64)
        for j in range(1, self.n_joints):
            depth[j] = depth[self.parents[j]] + 1
        return tuple(np.flatnonzero(depth == d) for d in range(depth.max() + 1))

    @cached_property
    def rest_positions(self) -> np.ndarray:
        """(J, 3) float64: world rest position of every joint (root at its offset)."""
        P = np.zeros((self.n_joints, 3))
        for level in self.levels:
            p = self.parents[level]
            P[level] = np.where((p >= 0)[:, None], P[np.maximum(p, 0)], 0.0) + self.offsets[level]
        P.setflags(write=False)
        return P

    @cached_property
    def bone_directions(self) -> np.ndarray:
        """(J, 3) float64: rest direction of each joint's bone (unit, or zero if unknown).

        The direction points to the mean of the joint's children; when every child sits on
        the joint (a zero-length bone, as converters produce), it is the mean of the
        children's own directions; for leaves it follows ``end_offsets``.
        """
        P = self.rest_positions
        D = np.zeros((self.n_joints, 3))
        for j in range(self.n_joints - 1, -1, -1):  # children before parents
            kids = list(self.children[j])
            d = P[kids].mean(axis=0) - P[j] if kids else self.end_offsets[j]
            if kids and np.linalg.norm(d) < ZERO_EXTENT:
                d = D[kids].mean(axis=0)
            n = np.linalg.norm(d)
            D[j] = d / n if n > ZERO_EXTENT else 0.0
        D.setflags(write=False)
        return D

    def scaled(self, factor: float) -> Skeleton:
        """Return this skeleton with offsets scaled by ``factor`` (e.g. a unit change)."""
        return Skeleton(self.names, self.parents, self.offsets * factor, self.end_offsets * factor)

    def transformed(self, C: np.ndarray) -> Skeleton:
        """Return this skeleton with rest offsets rotated by ``C`` (3, 3), e.g. Y-up → Z-up."""
        return Skeleton(self.names, self.parents, self.offsets @ C.T, self.end_offsets @ C.T)


def forward_kinematics(
    skeleton: Skeleton, R: np.ndarray, root_position: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Return global joint rotations and world joint positions of posed skeletons.

    Parameters
    ----------
    skeleton : Skeleton
        ``J`` joints.
    R : (..., J, 3, 3) float64
        Local rotation of every joint relative to its world-aligned rest frame.
    root_position : (..., 3) float64
        World position of the root joint, metres.

    Returns
    -------
    G : (..., J, 3, 3) float64
        Global rotation of every joint (``G[j] = G[parent] @ R[j]``).
    P : (..., J, 3) float64
        World position of every joint (``P[j] = P[parent] + G[parent] @ offset[j]``).
    """
    R = np.asarray(R, dtype=float)
    G = np.empty_like(R)
    P = np.empty((*R.shape[:-2], 3))
    root = skeleton.levels[0]
    G[..., root, :, :] = R[..., root, :, :]
    P[..., root, :] = np.asarray(root_position, dtype=float)[..., None, :]
    for level in skeleton.levels[1:]:
        p = skeleton.parents[level]
        Gp = G[..., p, :, :]
        G[..., level, :, :] = Gp @ R[..., level, :, :]
        P[..., level, :] = P[..., p, :] + np.einsum("...ij,...j->...i", Gp, skeleton.offsets[level])
    return G, P


def local_rotations(skeleton: Skeleton, G: np.ndarray) -> np.ndarray:
    """Inverse of the rotation part of :func:`forward_kinematics`.

    Parameters
    ----------
    G : (..., J, 3, 3) float64
        Global joint rotations.

    Returns
    -------
    (..., J, 3, 3) float64
        Local rotations ``R[j] = G[parent]^T @ G[j]`` (``R[root] = G[root]``).
    """
    G = np.asarray(G, dtype=float)
    R = G.copy()
    child = np.arange(1, skeleton.n_joints)
    R[..., child, :, :] = (
        np.swapaxes(G[..., skeleton.parents[child], :, :], -1, -2) @ G[..., child, :, :]
    )
    return R
