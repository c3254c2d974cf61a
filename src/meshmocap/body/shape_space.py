"""The body-shape space bundled with meshmocap: bodies of any build in the bundled
templates' topology, rig and rest pose, from a few standardised coefficients.

The space (``data/shape/shape_space.npz``, made by ``tools/make_shape_space.py`` from
hundreds of anny bodies of random sex, age, muscle, weight, height and proportions) is a
:class:`~meshmocap.models.shape_space.ShapeSpace` over body vectors that stack, in order,

* the rest vertices ``V`` (n, 3) (the MakeHuman A-pose, feet on z = 0, hips at x = y = 0,
  facing −Y), metres;
* the 31 bone heads and the 31 bone tails (31, 3) of the CMU MotionBuilder rig, metres;
* the evaluation head centre (3,), metres;

so each component moves the skeleton with the surface: a linear joint regressor per
component. Skinning weights, body-part labels and the evaluation joints' bone binding do not
depend on the shape (anny's are the same for every body). On-disk keys (format
``meshmocap-shape-space-1``): ``mean`` (d,), ``components`` (K, d), ``std`` (K,),
``explained_variance_ratio`` (K,), ``n_samples``, and the template keys that do not move
with shape (``F``, ``joint_names``, ``joint_parents``, ``weights_*``, ``part_labels``,
``eval_names``, ``eval_parents``, ``eval_weights``; see :mod:`meshmocap.body.template`).
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from importlib import resources
from pathlib import Path

import numpy as np
import scipy.sparse as sp

from meshmocap.body.skeleton import Skeleton
from meshmocap.body.template import EvalSkeleton, Template
from meshmocap.errors import InputError, MeshError
from meshmocap.models.shape_space import ShapeSpace

__all__ = ["FORMAT", "BodyShape", "BodyShapeSpace", "load_shape_space"]

FORMAT = "meshmocap-shape-space-1"


@dataclass(frozen=True, eq=False)
class BodyShape:
    """One body's rest geometry.

    Attributes
    ----------
    V : (n, 3) float64, rest vertices, metres, world frame (Z up, facing −Y)
    heads, tails : (J, 3) float64, rest bone heads (joint positions) and tails, metres
    eval_rest : (K, 3) float64, rest positions of the evaluation joints, metres
    """

    V: np.ndarray
    heads: np.ndarray
    tails: np.ndarray
    eval_rest: np.ndarray


@dataclass(frozen=True, eq=False)
class BodyShapeSpace:
    """A shape space with the rig that does not change with shape.

    Attributes
    ----------
    model : ShapeSpace, fitted; ``n_components`` coefficients ``z``
    F : (m, 3) int64, triangles
    joint_names : tuple of str (J); ``joint_parents`` (J,) int64
    weights : (n, J) scipy.sparse.csr_matrix, skinning weights (rows sum to 1)
    part_labels : (n,) int64, evaluation body part of each vertex
    eval_names : tuple of str (K); ``eval_parents`` (K,) int64
    eval_weights : (K, J) float64, one-hot: the rig bone whose head each evaluation joint is
    head_index : int, the evaluation joint placed by the space's own row (the head centre)
    """

    model: ShapeSpace
    F: np.ndarray
    joint_names: tuple[str, ...]
    joint_parents: np.ndarray
    weights: sp.csr_matrix
    part_labels: np.ndarray
    eval_names: tuple[str, ...]
    eval_parents: np.ndarray
    eval_weights: np.ndarray
    head_index: int

    @property
    def n_components(self) -> int:
        """Number of shape coefficients ``K``."""
        return len(self.model.std_)

    @property
    def n_vertices(self) -> int:
        """Number of vertices ``n``."""
        return self.weights.shape[0]

    def split(self, x: np.ndarray) -> BodyShape:
        """Cut body vectors ``x`` (..., d) into their parts (see the module docstring)."""
        n, J = self.n_vertices, len(self.joint_names)
        lead = x.shape[:-1]
        V = x[..., : 3 * n].reshape(*lead, n, 3)
        heads = x[..., 3 * n : 3 * n + 3 * J].reshape(*lead, J, 3)
        tails = x[..., 3 * n + 3 * J : 3 * n + 6 * J].reshape(*lead, J, 3)
        E = np.einsum("kj,...jc->...kc", self.eval_weights, heads)
        E[..., self.head_index, :] = x[..., 3 * n + 6 * J :]
        return BodyShape(V, heads, tails, E)

    def body(self, z: np.ndarray) -> BodyShape:
        """Rest geometry of standardised coefficients ``z`` (K,) float64."""
        z = np.asarray(z, dtype=np.float64)
        if z.shape != (self.n_components,) or not np.all(np.isfinite(z)):
            raise InputError(
                f"shape space: z must be {self.n_components} finite coefficients, "
                f"found shape {z.shape}"
            )
        return self.split(self.model.inverse_transform(z))

    def derivatives(self) -> BodyShape:
        """``∂/∂z`` of every part, each with a leading axis of length K (constant)."""
        basis = self.model.basis_
        d = self.split(basis)
        E = np.einsum("kj,...jc->...kc", self.eval_weights, d.heads)
        E[..., self.head_index, :] = basis[:, -3:]
        return BodyShape(d.V, d.heads, d.tails, E)

    def template(self, z: np.ndarray, *, name: str = "subject") -> Template:
        """The rigged :class:`Template` of coefficients ``z`` (K,) (rest pose: the A-pose,
        like the bundled templates, so their poses and motions apply to it)."""
        b = self.body(z)
        parents = self.joint_parents
        off = b.heads - np.where((parents >= 0)[:, None], b.heads[np.maximum(parents, 0)], 0.0)
        skel = Skeleton(self.joint_names, parents, off, b.tails - b.heads)
        ev = EvalSkeleton(
            self.eval_names, self.eval_parents.copy(), b.eval_rest, self.eval_weights.copy()
        )
        return Template(name, b.V, self.F, skel, self.weights, self.part_labels, ev)


def load_shape_space(path: str | os.PathLike | None = None) -> BodyShapeSpace:
    """Load the bundled body-shape space, or one written in its format at ``path``.

    Raises
    ------
    MeshError
        The file is not a readable shape space (the missing key or bad value is named).
    """
    if path is None:
        with resources.as_file(
            resources.files("meshmocap.body") / "data" / "shape" / "shape_space.npz"
        ) as p:
            return _read(Path(p))
    return _read(Path(path))


def _read(path: Path) -> BodyShapeSpace:
    try:
        with np.load(path, allow_pickle=False) as z:
            d = {k: z[k] for k in z.files}
    except (OSError, ValueError) as exc:
        raise MeshError(f"{path}: not a readable shape space ({exc})") from None
    if str(d.get("format", "")) != FORMAT:
        raise MeshError(f"{path}: expected format {FORMAT!r}, found {str(d.get('format'))!r}")
    try:
        m = ShapeSpace(n_components=len(d["std"]))
        m.mean_ = d["mean"].astype(np.float64)
        m.components_ = d["components"].astype(np.float64)
        m.std_ = d["std"].astype(np.float64)
        m.explained_variance_ratio_ = d["explained_variance_ratio"].astype(np.float64)
        m.n_samples_ = int(d["n_samples"])
        names = tuple(str(s) for s in d["joint_names"])
        n = (len(m.mean_) - 6 * len(names) - 3) // 3
        W = sp.csr_matrix(
            (d["weights_data"].astype(np.float64), d["weights_indices"], d["weights_indptr"]),
            shape=(n, len(names)),
        )
        W = sp.csr_matrix(sp.diags(1.0 / np.asarray(W.sum(axis=1)).ravel()) @ W)
        eval_names = tuple(str(s) for s in d["eval_names"])
        space = BodyShapeSpace(
            m,
            d["F"].astype(np.int64),
            names,
            d["joint_parents"].astype(np.int64),
            W,
            d["part_labels"].astype(np.int64),
            eval_names,
            d["eval_parents"].astype(np.int64),
            d["eval_weights"].astype(np.float64),
            eval_names.index("head"),
        )
    except KeyError as exc:
        raise MeshError(f"{path}: shape space is missing key {exc}") from None
    except ValueError as exc:
        raise MeshError(f"{path}: shape space arrays are inconsistent ({exc})") from None
    if m.components_.shape != (len(m.std_), len(m.mean_)):
        raise MeshError(f"{path}: components must have shape ({len(m.std_)}, {len(m.mean_)})")
    return space
