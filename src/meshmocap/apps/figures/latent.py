"""Picture of a GPLVM pose manifold, like Fig. 2 of the cage paper.

The predictive variance (Eq. (9)) is drawn as a grey level over the latent space (white:
low variance, i.e. poses the model is confident about; black: high variance), on a log
scale; the latent points of the training poses are blue crosses. Drawn with matplotlib's
object API on the Agg canvas (headless, no global state) and written atomically.

References
----------
- E. Duveau, S. Courtemanche, L. Reveret, E. Boyer, *Cage-based motion recovery
  using manifold learning*, International Conference on 3D Imaging, Modeling,
  Processing, Visualization and Transmission (3DIMPVT), 2012.
- N. D. Lawrence, *Probabilistic non-linear principal component analysis with
  Gaussian process latent variable models*, Journal of Machine Learning Research
  6:1783–1816, 2005.
"""

from __future__ import annotations

import io
import os
from pathlib import Path

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.colors import LogNorm
from matplotlib.figure import Figure

from meshmocap._atomic import atomic_open
from meshmocap._tolerances import UNDERFLOW_FLOOR, ZERO_EXTENT
from meshmocap.errors import InputError
from meshmocap.models.gplvm import GPLVM

_FORMATS = (".png", ".pdf", ".svg")


def _plane(X: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Centre (q,) and orthonormal axes (2, q) of the plane the latent points lie closest to.

    For q = 2 the latent axes themselves; for q > 2 the two principal axes of the latent
    points (through their mean).
    """
    centre = X.mean(0)
    if X.shape[1] == 2:
        return centre, np.eye(2)
    _, _, Vt = np.linalg.svd(X - centre, full_matrices=False)
    return centre, Vt[:2]


def plot_latent_space(
    model: GPLVM,
    path: str | os.PathLike,
    *,
    resolution: int = 200,
    labels: np.ndarray | None = None,
    margin: float = 0.15,
    title: str | None = None,
) -> Path:
    """Draw the predictive variance over the latent space with the training points on top.

    For ``n_components`` = 2 the latent plane itself; for q > 2 the plane through the mean
    of the latent points spanned by their two principal axes (the axes are labelled PC 1,
    PC 2; every grid point is mapped back to q dimensions before prediction, so the shading
    is the true variance on that slice); for q = 1 a curve of the variance along the line.

    Parameters
    ----------
    model : GPLVM
        A fitted model.
    path : str or os.PathLike
        Output file, ``.png``, ``.pdf`` or ``.svg`` (written atomically).
    resolution : int
        Grid cells per side (≥ 8).
    labels : (N,) array_like of int, optional
        Class of each training point: one marker colour per class instead of blue crosses.
    margin : float
        Extra space around the training points, as a fraction of their extent.
    title : str, optional
        Figure title.

    Returns
    -------
    Path
        ``path``.
    """
    if not isinstance(model, GPLVM) or not hasattr(model, "X_"):
        raise InputError("plot_latent_space: model must be a fitted GPLVM")
    path = Path(path)
    if path.suffix.lower() not in _FORMATS:
        raise InputError(
            f"plot_latent_space: path must end in one of {list(_FORMATS)}, found {path.name!r}"
        )
    if not isinstance(resolution, int | np.integer) or resolution < 8:
        raise InputError(f"plot_latent_space: resolution must be an int ≥ 8, found {resolution!r}")
    X = model.X_
    N, q = X.shape
    if labels is not None:
        labels = np.asarray(labels)
        if labels.shape != (N,):
            raise InputError(
                f"plot_latent_space: labels must have shape ({N},), found {labels.shape}"
            )

    fig = Figure(figsize=(6, 5) if q > 1 else (7, 3.5), dpi=100, layout="constrained")
    FigureCanvasAgg(fig)
    ax = fig.add_subplot()
    if q == 1:
        lo, hi = X[:, 0].min(), X[:, 0].max()
        pad = margin * (hi - lo) + ZERO_EXTENT
        t = np.linspace(lo - pad, hi + pad, resolution * 4)
        _, var = model.predict(t[:, None], return_var=True)  # Eq. (9)
        ax.semilogy(t, np.maximum(var, UNDERFLOW_FLOOR), color="0.2")
        ax.plot(X[:, 0], np.full(N, var.min()), "x", color="tab:blue", label="training poses")
        ax.set_xlabel("latent x")
        ax.set_ylabel("predictive variance")
    else:
        centre, axes = _plane(X)
        P = (X - centre) @ axes.T  # training points in plane coordinates (N, 2)
        lo, hi = P.min(0), P.max(0)
        pad = margin * (hi - lo).max() + ZERO_EXTENT
        u = np.linspace(lo[0] - pad, hi[0] + pad, resolution)
        v = np.linspace(lo[1] - pad, hi[1] + pad, resolution)
        U, V = np.meshgrid(u, v)
        grid = centre + np.column_stack([U.ravel(), V.ravel()]) @ axes
        _, var = model.predict(grid, return_var=True)  # Eq. (9)
        var = np.maximum(var, var[var > 0].min() if np.any(var > 0) else UNDERFLOW_FLOOR)
        img = ax.imshow(
            var.reshape(U.shape),
            origin="lower",
            cmap="gray_r",
            norm=LogNorm(),
            extent=(u[0], u[-1], v[0], v[-1]),
            interpolation="bilinear",
            aspect="auto",
        )
        fig.colorbar(img, ax=ax, label="predictive variance (log scale)")
        if labels is None:
            ax.plot(P[:, 0], P[:, 1], "x", color="tab:blue", markersize=5, label="training poses")
        else:
            for k in np.unique(labels):
                sel = labels == k
                ax.plot(P[sel, 0], P[sel, 1], "x", markersize=5, label=str(k))
            ax.legend(loc="best", fontsize="small")
        names = ("latent 1", "latent 2") if q == 2 else ("PC 1", "PC 2")
        ax.set_xlabel(names[0])
        ax.set_ylabel(names[1])
    ax.set_title(title if title is not None else f"GPLVM latent space (q = {q}, N = {N})")
    buf = io.BytesIO()
    fig.savefig(buf, format=path.suffix.lower()[1:])
    with atomic_open(path, "wb") as f:
        f.write(buf.getvalue())
    return path
