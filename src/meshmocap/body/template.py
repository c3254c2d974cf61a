"""The tracking template: a watertight human mesh rigged to a skeleton.

A :class:`Template` bundles the rest mesh (``V``, ``F``), the rig :class:`Skeleton`, sparse
linear-blend skinning weights, per-vertex body-part labels and the 15-joint evaluation
skeleton whose joints are carried by the rig like skinned points.

On-disk format (``.npz``, ``format = "meshmocap-template-1"``), all in metres, world frame
Z up, subject facing −Y, its left side towards +X, feet on z = 0:

=============================  ============  ===============================================
key                            shape/dtype   meaning
=============================  ============  ===============================================
format                         str           ``"meshmocap-template-1"``
name                           str           template name
V                              (n, 3) f4/8   rest vertices
F                              (m, 3) int    triangles, counter-clockwise seen from outside
joint_names                    (J,) str      rig joint names (parents before children)
joint_parents                  (J,) int      parent index, −1 for the root
joint_positions                (J, 3) float  rest joint positions (world-aligned rest frames)
end_positions                  (J, 3) float  rest position of each bone's tail
weights_data/indices/indptr    CSR parts     (n, J) skinning weights, rows sum to 1
weights_exact                  bool          optional: the weights are read back as stored
part_labels                    (n,) int      evaluation-joint index (0..14) of each vertex
eval_names                     (K,) str      evaluation joints (15: pelvis ... right_ankle)
eval_parents                   (K,) int      evaluation skeleton tree
eval_rest_positions            (K, 3) float  rest positions of evaluation joints
eval_weights                   (K, J) float  rig weights carrying each evaluation joint
=============================  ============  ===============================================

A file without ``weights_exact`` (the bundled templates store float32 weights) has its rows
renormalised on reading, as every file was read before the key existed (so a kept
``subject.npz`` tracks as it did). :func:`save_template` writes the weights as the template
holds them with ``weights_exact``: a template saved and read back is the same template, to
the bit and in the same storage order, however often it goes round (an estimated body
cached for a capture and read back by the next track or the next run).
"""

from __future__ import annotations

import os
import warnings
from dataclasses import dataclass
from functools import cached_property
from importlib import resources
from pathlib import Path

import numpy as np
import scipy.sparse as sp

from meshmocap._atomic import atomic_open
from meshmocap._npz import read_npz
from meshmocap.body.skeleton import Skeleton, forward_kinematics
from meshmocap.body.skinning import apply_skinning, skinning_operator, skinning_transforms
from meshmocap.errors import InputError, MeshError, MeshmocapFileNotFoundError, SkeletonError
from meshmocap.geometry.mesh import mesh_problems

FORMAT = "meshmocap-template-1"

#: The 15 evaluation joints (HumanEva-style), root first.
EVAL_NAMES = (
    "pelvis",
    "thorax",
    "head",
    "left_shoulder",
    "left_elbow",
    "left_wrist",
    "right_shoulder",
    "right_elbow",
    "right_wrist",
    "left_hip",
    "left_knee",
    "left_ankle",
    "right_hip",
    "right_knee",
    "right_ankle",
)
EVAL_PARENTS = np.array([-1, 0, 1, 1, 3, 4, 1, 6, 7, 0, 9, 10, 0, 12, 13])


@dataclass(frozen=True, eq=False)
class EvalSkeleton:
    """Evaluation joints carried by a rig.

    Parameters
    ----------
    names : tuple of str, length K
    parents : (K,) int64, −1 for the root
    rest_positions : (K, 3) float64, metres, world frame (Z up)
    weights : (K, J) float64, rows summing to 1: the rig joints that carry each joint.
    """

    names: tuple[str, ...]
    parents: np.ndarray
    rest_positions: np.ndarray
    weights: np.ndarray


@dataclass(frozen=True, eq=False)
class PosedTemplate:
    """A template posed by skinning (one frame or ``T`` frames along a leading axis).

    Attributes
    ----------
    V : (..., n, 3) float64, posed vertices, metres, world frame (Z up)
    joints : (..., J, 3) float64, rig joint positions
    eval_joints : (..., K, 3) float64, evaluation joint positions
    """

    V: np.ndarray
    joints: np.ndarray
    eval_joints: np.ndarray


@dataclass(frozen=True, eq=False)
class Template:
    """A rigged, watertight human template.

    Parameters
    ----------
    name : str
    V : (n, 3) float64
        Rest vertices, metres, world frame (Z up, facing −Y).
    F : (m, 3) int64
        Triangles, counter-clockwise seen from outside.
    skeleton : Skeleton
        Rig with ``J`` joints.
    weights : (n, J) scipy.sparse.csr_matrix, float64
        Linear-blend skinning weights; rows sum to 1.
    part_labels : (n,) int64
        Index of each vertex's body part in ``eval_skeleton``.
    eval_skeleton : EvalSkeleton
        The evaluation joints (15 for the bundled templates).
    """

    name: str
    V: np.ndarray
    F: np.ndarray
    skeleton: Skeleton
    weights: sp.csr_matrix
    part_labels: np.ndarray
    eval_skeleton: EvalSkeleton

    @cached_property
    def _skinning(self) -> sp.csc_matrix:
        return skinning_operator(self.V, self.weights)

    @property
    def n_vertices(self) -> int:
        """Number of vertices ``n``."""
        return len(self.V)

    def pose(self, R: np.ndarray, root_position: np.ndarray) -> PosedTemplate:
        """Pose the template by linear-blend skinning.

        Parameters
        ----------
        R : (J, 3, 3) or (T, J, 3, 3) float64
            Local joint rotations relative to the rest frames.
        root_position : (3,) or (T, 3) float64
            World position of the root joint, metres.
        """
        G, P = forward_kinematics(self.skeleton, R, root_position)
        A = skinning_transforms(G, P, self.skeleton.rest_positions)
        V = apply_skinning(self._skinning, A)
        ev = self.eval_skeleton
        Ae = np.einsum("kj,...jab->...kab", ev.weights, A)
        E = np.einsum("...kab,kb->...ka", Ae[..., :3], ev.rest_positions) + Ae[..., 3]
        return PosedTemplate(V=V, joints=P, eval_joints=E)


def template_problems(t: Template) -> list[str]:
    """Return what is wrong with a template (empty when it is usable for tracking)."""
    problems = mesh_problems(t.V, t.F)
    n, J = t.n_vertices, t.skeleton.n_joints
    if t.weights.shape != (n, J):
        problems.append(f"weights must have shape ({n}, {J}), found {t.weights.shape}")
    else:
        w = t.weights
        if not np.all(np.isfinite(w.data)) or (w.data < 0).any():
            problems.append("skinning weights must be finite and non-negative")
        rows = np.asarray(w.sum(axis=1)).ravel()
        if np.abs(rows - 1).max() > 1e-4:
            problems.append(
                "skinning weights must sum to 1 per vertex, "
                f"found {rows.min():.4g}..{rows.max():.4g}"
            )
    K = len(t.eval_skeleton.names)
    if t.part_labels.shape != (n,) or t.part_labels.min() < 0 or t.part_labels.max() >= K:
        problems.append(f"part_labels must be {n} indices in [0, {K - 1}]")
    if t.eval_skeleton.weights.shape != (K, J):
        problems.append(
            f"eval_weights must have shape ({K}, {J}), found {t.eval_skeleton.weights.shape}"
        )
    return problems


def bundled_templates() -> list[str]:
    """Return the names of the templates shipped with meshmocap (e.g. ``"neutral"``)."""
    files = resources.files("meshmocap.body") / "data"
    return sorted(p.name[:-4] for p in files.iterdir() if p.name.endswith(".npz"))


def load_template(name_or_path: str | os.PathLike = "neutral") -> Template:
    """Load a bundled template by name, or a template ``.npz`` file by path.

    Parameters
    ----------
    name_or_path : str or path
        A name from :func:`bundled_templates` (``"neutral"``, ``"neutral_5k"``,
        ``"heavy_male"``, ``"small_female"``) or the path of a file in the format described
        in this module's docstring.

    Raises
    ------
    MeshmocapFileNotFoundError
        Neither a bundled name nor an existing file.
    MeshError
        The file is not a valid template (which key or check failed is named).
    """
    name = os.fspath(name_or_path)
    if name in bundled_templates():
        with resources.as_file(resources.files("meshmocap.body") / "data" / f"{name}.npz") as p:
            return _read(Path(p))
    path = Path(name)
    if not path.is_file():
        raise MeshmocapFileNotFoundError(
            f"template: {name!r} is neither a bundled template {bundled_templates()} nor a file"
        )
    return _read(path)


def _read(path: Path) -> Template:
    d = read_npz(path, "template", error=MeshError)
    if str(d.get("format", "")) != FORMAT:
        raise MeshError(
            f"{path}: expected format {FORMAT!r}, found {str(d.get('format', 'none'))!r}"
        )
    try:
        with np.errstate(invalid="raise", over="raise"), warnings.catch_warnings():
            warnings.simplefilter("error", np.exceptions.ComplexWarning)
            t = _from_arrays(d)
    except KeyError as exc:
        raise MeshError(f"{path}: template is missing key {exc}") from None
    except (
        ValueError,
        TypeError,
        IndexError,
        ArithmeticError,
        np.exceptions.ComplexWarning,
        InputError,
        SkeletonError,
    ) as exc:
        why = str(exc).splitlines()[0][:160] if str(exc) else type(exc).__name__
        raise MeshError(f"{path}: template arrays are inconsistent ({why})") from None
    problems = template_problems(t)
    if problems:
        raise MeshError(f"{path}: invalid template: {'; '.join(problems)}")
    return t


def _from_arrays(d: dict[str, np.ndarray]) -> Template:
    names = tuple(str(s) for s in d["joint_names"])
    parents = d["joint_parents"].astype(np.int64)
    P = d["joint_positions"].astype(np.float64)
    off = P - np.where((parents >= 0)[:, None], P[np.maximum(parents, 0)], 0.0)
    skel = Skeleton(names, parents, off, d["end_positions"].astype(np.float64) - P)
    V = d["V"].astype(np.float64)
    W = sp.csr_matrix(
        (d["weights_data"].astype(np.float64), d["weights_indices"], d["weights_indptr"]),
        shape=(len(V), len(names)),
    )
    if not bool(d.get("weights_exact", False)):
        # a partition of unity in float64 (files may store float32); the product reorders
        # each row's entries and rescales them by an ulp, so it is not repeated on files
        # that hold the exact weights (module docstring)
        rows = np.asarray(W.sum(axis=1)).ravel()
        if np.all(rows > 0):
            W = sp.csr_matrix(sp.diags(1.0 / rows) @ W)
    ev = EvalSkeleton(
        tuple(str(s) for s in d["eval_names"]),
        d["eval_parents"].astype(np.int64),
        d["eval_rest_positions"].astype(np.float64),
        d["eval_weights"].astype(np.float64),
    )
    t = Template(
        str(d["name"]), V, d["F"].astype(np.int64), skel, W, d["part_labels"].astype(np.int64), ev
    )
    return t


def save_template(path: str | os.PathLike, t: Template) -> Path:
    """Write ``t`` to ``path`` (``.npz``) atomically; return the path written.

    Raises :class:`MeshError` if the template fails :func:`template_problems`.
    """
    problems = template_problems(t)
    if problems:
        raise MeshError(f"template {t.name!r}: {'; '.join(problems)}")
    path = Path(path)
    if path.suffix != ".npz":
        raise InputError(f"save_template: path must end in .npz, found {path.name!r}")
    W = t.weights.tocsr()
    sk, ev = t.skeleton, t.eval_skeleton
    P = sk.rest_positions
    arrays = dict(
        format=np.str_(FORMAT),
        name=np.str_(t.name),
        V=t.V,
        F=t.F.astype(np.int32),
        joint_names=np.array(sk.names),
        joint_parents=sk.parents.astype(np.int32),
        joint_positions=P,
        end_positions=P + sk.end_offsets,
        weights_data=W.data.astype(np.float64),
        weights_indices=W.indices.astype(np.int32),
        weights_indptr=W.indptr.astype(np.int32),
        weights_exact=np.bool_(True),
        part_labels=t.part_labels.astype(np.int8),
        eval_names=np.array(ev.names),
        eval_parents=ev.parents.astype(np.int32),
        eval_rest_positions=ev.rest_positions,
        eval_weights=ev.weights,
    )
    with atomic_open(path) as f:
        np.savez_compressed(f, **arrays)
    return path
