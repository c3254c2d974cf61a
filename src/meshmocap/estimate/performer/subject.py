"""The performer's body, estimated from the capture itself (no ground truth).

Two kinds of capture (:func:`subject_kind` tells which, ``kind=`` forces one):

``"hull"`` — cameras and silhouettes (a studio capture; the frames' meshes are visual hulls,
    supersets of the body). The body is a point of the bundled shape space
    (:mod:`meshmocap.body.shape_space`), fitted jointly with a pose per frame to the
    silhouettes of a few frames spread over the capture in different poses
    (:func:`choose_frames`, :func:`~meshmocap.estimate.performer.shape_fit.fit_shape`). Each frame's
    starting pose is a simple internal one: the mean body fitted with its size to the hull
    mesh from 8 headings (:func:`~meshmocap.body.autorig.fit_skeleton`), the best kept.
    The result is a template in the bundled topology and A-pose rest, so poses, motions
    and manifolds made for the bundled templates apply to it.
``"mesh"`` — clean meshes (a scanner, a 4D capture): the first frame's mesh is the body; it
    is rigged as it stands (:func:`~meshmocap.body.autorig.rig_mesh`), so the template's
    rest pose is that frame's pose.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Literal, get_args

import numpy as np
from scipy import ndimage

from meshmocap._parallel import Workers, parallel_map
from meshmocap._progress import phase
from meshmocap._validate import check_choice
from meshmocap.body.autorig import fit_skeleton, mesh_samples, rig_mesh
from meshmocap.body.shape_space import BodyShapeSpace, load_shape_space
from meshmocap.body.template import Template
from meshmocap.errors import InputError, MeshError
from meshmocap.estimate.performer.shape_fit import fit_shape, silhouette_view
from meshmocap.geometry.rotations import so3_exp

__all__ = [
    "KINDS",
    "Kind",
    "SubjectEstimate",
    "choose_frames",
    "estimate_subject",
    "initial_body_pose",
    "subject_kind",
    "whole_in_view",
]

Kind = Literal["auto", "hull", "mesh"]
KINDS: tuple[str, ...] = get_args(Kind)


@dataclass(frozen=True, eq=False)
class SubjectEstimate:
    """The estimated performer.

    Attributes
    ----------
    template : Template, the performer's rigged body
    kind : ``"hull"`` or ``"mesh"``, how it was estimated
    frames : tuple of int, the capture frames (indices) it was fitted to
    z : (K,) float64 or None, shape-space coefficients (hull kind)
    R : (f, J, 3, 3) float64, the fitted local rotations per frame; ``root`` (f, 3), metres
        (mesh kind: the identity at the rest root, the template's own pose)
    rms : float, the fit's residual (hull: silhouette residuals, metres; mesh: 0)
    seconds : float
    notes : dict, diagnostics (hull: the first guesses' size and RMS distance to the hulls,
        each frame's silhouette objective and the frames that informed the shape,
        :func:`~meshmocap.estimate.performer.shape_fit.fit_shape`)
    """

    template: Template
    kind: str
    frames: tuple[int, ...]
    z: np.ndarray | None
    R: np.ndarray
    root: np.ndarray
    rms: float
    seconds: float
    notes: dict = field(default_factory=dict)

    @property
    def height(self) -> float:
        """Height of the template's rest mesh (its vertical extent), metres."""
        return float(np.ptp(self.template.V[:, 2]))


def subject_kind(capture) -> str:
    """``"hull"`` for a capture with cameras and silhouettes, else ``"mesh"``."""
    if not capture.cameras:
        return "mesh"
    try:
        masks = capture[0].silhouettes
    except FileNotFoundError:
        return "mesh"
    return "hull" if masks else "mesh"


def whole_in_view(frame) -> bool:
    """Whether the performer is whole in every camera of a frame: every silhouette holds it
    and none touches its image border (a body cut by the border carves a cut hull). True
    without silhouettes."""
    try:
        masks = frame.silhouettes or []
    except (OSError, ValueError):  # a missing or unreadable mask: not a frame to fit
        return False
    return not any(
        m[0].any() or m[-1].any() or m[:, 0].any() or m[:, -1].any() or not m.any() for m in masks
    )


def choose_frames(capture, n: int, *, candidates: int = 30) -> list[int]:
    """Positions of up to ``n`` frames spread over the capture in different poses.

    Among ``candidates`` evenly spaced frames where the performer is whole in every view
    (:func:`whole_in_view`), the first one and then, greedily, the frame farthest from those
    chosen, in a pose descriptor of the frame's mesh: the square roots of the covariance
    eigenvalues of its vertices (metres) and its height. Returns sorted positions (not
    indices); empty when no candidate is in view. The candidates are read side by side
    (:mod:`meshmocap._parallel`): the same frames.
    """
    total = len(capture)
    pos = np.unique(np.linspace(0, total - 1, min(candidates, total)).round().astype(int))
    looks = parallel_map(lambda k: _look(capture[int(k)]), pos)
    looks = [(int(k), d) for k, (seen, d) in zip(pos, looks, strict=True) if seen]
    if len(looks) <= n:
        return [k for k, _ in looks]
    pos = [k for k, d in looks if d is not None]  # a frame without a hull (dropped): skipped
    D = np.asarray([d for _, d in looks if d is not None])
    chosen = [0]
    dist = np.linalg.norm(D - D[0], axis=1)
    while len(chosen) < min(n, len(pos)):
        k = int(np.argmax(dist))
        chosen.append(k)
        dist = np.minimum(dist, np.linalg.norm(D - D[k], axis=1))
    return sorted(pos[k] for k in chosen)


def _look(frame) -> tuple[bool, list[float] | None]:
    """Whether the performer is whole in every view of ``frame`` (:func:`whole_in_view`) and,
    if so, :func:`choose_frames`' pose descriptor of its hull mesh (None where it has none)."""
    if not whole_in_view(frame):
        return False, None
    try:
        V = frame.hull_mesh[0]
    except (OSError, ValueError):
        return True, None
    ev = np.sqrt(np.maximum(np.linalg.eigvalsh(np.cov((V - V.mean(0)).T)), 0.0))
    return True, [*ev, np.ptp(V[:, 2])]


def _hull_surface(frame) -> tuple[np.ndarray, np.ndarray]:
    """A closed 2-manifold surface of a frame's hull: marching cubes of its voxel occupancy
    smoothed by a Gaussian of 0.8 voxel (a binary occupancy leaves a few non-manifold edges
    where voxels touch along an edge), or the frame's own mesh without voxels."""
    from skimage.measure import marching_cubes

    try:
        hull = frame.hull
    except (AttributeError, FileNotFoundError):
        return frame.hull_mesh
    occ = ndimage.gaussian_filter(np.pad(hull.occupancy, 2).astype(np.float32), 0.8)
    V, F, _, _ = marching_cubes(occ, 0.5, allow_degenerate=False)
    return hull.origin + (V.astype(np.float64) - 2) * hull.voxel_size, F[:, ::-1].astype(np.int64)


def initial_body_pose(template: Template, V: np.ndarray, F: np.ndarray, *, seed: int):
    """A simple first guess of the pose and size of ``template`` in a hull mesh: fitted from
    8 headings (about Z, through the centroid), the two best refined, the best kept. (Only
    a start for the silhouette fit; the first-pose search of automatic initialisation is
    another part of :mod:`meshmocap.estimate`.)"""
    sk = template.skeleton
    s0 = float(np.ptp(V[:, 2]) / np.ptp(template.V[:, 2]))
    centre = V.mean(axis=0)
    c_t = template.V.mean(axis=0)
    coarse = mesh_samples(V, F, 1500, seed=seed)  # shared by the headings' fits
    fits = []
    for yaw in 2 * np.pi * np.arange(8) / 8:
        R = np.tile(np.eye(3), (sk.n_joints, 1, 1))
        R[0] = so3_exp(np.array([0.0, 0.0, yaw]))
        root = centre - s0 * R[0] @ (c_t - sk.rest_positions[0])
        fits.append(
            fit_skeleton(
                template,
                V,
                F,
                R=R,
                root=root,
                scale=s0,
                fit_scale=True,
                iterations=10,
                max_distance=(0.3, 0.1),
                n_model_points=600,
                seed=seed,
                samples=coarse,
            )
        )
    best = sorted(fits, key=lambda f: f.rms)[:2]
    fine = mesh_samples(V, F, seed=seed)  # fit_skeleton's default n_data_points
    final = [
        fit_skeleton(
            template,
            V,
            F,
            R=f.R,
            root=f.root,
            scale=f.scale,
            fit_scale=True,
            iterations=25,
            max_distance=(0.1, 0.03),
            seed=seed,
            samples=fine,
        )
        for f in best
    ]
    return min(final, key=lambda f: f.rms)


def estimate_subject(
    capture,
    *,
    kind: Kind = "auto",
    n_frames: int = 5,
    iterations: int = 40,
    space: BodyShapeSpace | None = None,
    name: str = "subject",
    decimate: int | None = None,
    seed: int = 0,
) -> SubjectEstimate:
    """Estimate the performer's rigged body from a capture (module docstring).

    Parameters
    ----------
    capture : Capture or SequenceCapture (:func:`meshmocap.io.capture.open_capture`)
    kind : {"auto", "hull", "mesh"}
        ``"auto"``: :func:`subject_kind`.
    n_frames : int
        Hull kind: frames fitted together (the first frame always among them).
    iterations : int
        Hull kind: Gauss–Newton iterations of the joint shape and pose fit.
    space : BodyShapeSpace, optional
        Hull kind: the shape space (default: the bundled one).
    name : str
        Name of the template.
    decimate : int, optional
        Mesh kind: vertices of the rigged template (default: the mesh's own).
    seed : int
        Seed of the point samples.

    Raises
    ------
    InputError
        Bad options, or a hull capture without silhouettes.
    MeshError
        Mesh kind: the first frame is not a closed mesh (e.g. a point cloud).
    """
    func = "estimate_subject"
    check_choice(func, "kind", kind, KINDS)
    if not (isinstance(n_frames, int | np.integer) and n_frames >= 1):
        raise InputError(f"{func}: n_frames must be an integer ≥ 1, found {n_frames!r}")
    t0 = time.perf_counter()
    kind = subject_kind(capture) if kind == "auto" else kind
    if kind == "mesh":
        first = capture[0]
        V, F = first.hull_mesh
        if F is None:
            raise MeshError(
                f"{func}: frame {first.index} is a point cloud; the mesh kind needs closed "
                "meshes (give a template instead)"
            )
        t = rig_mesh(V, F, name=name, decimate=decimate, seed=seed)
        J = t.skeleton.n_joints
        return SubjectEstimate(
            t,
            "mesh",
            (first.index,),
            None,
            np.eye(3)[None, None].repeat(J, 1),
            t.skeleton.rest_positions[:1].copy(),
            0.0,
            time.perf_counter() - t0,
        )
    if not capture.cameras:
        raise InputError(
            f"{func}: the hull kind needs cameras and silhouettes; {capture.path} has no cameras"
        )
    space = load_shape_space() if space is None else space
    with phase(f"choosing {int(n_frames)} frames in different poses"):
        positions = choose_frames(capture, int(n_frames))
    if not positions:
        raise InputError(
            f"{func}: the performer is cut by an image border in every frame "
            f"sampled from {capture.path}; give a template instead"
        )
    frames = [capture[k] for k in positions]
    mean = space.template(np.zeros(space.n_components))
    names = ", ".join(str(fr.index) for fr in frames)
    views = []

    def read_views():  # a second or less, while the workers make their first guesses
        for fr in frames:
            masks = fr.silhouettes
            if not masks:
                raise InputError(f"{func}: frame {fr.index} has no silhouettes")
            views.append(
                [silhouette_view(m, c, seed=seed) for m, c in zip(masks, fr.cameras, strict=True)]
            )

    with (
        phase(f"a first guess of the body in frames {names}"),
        Workers(
            lambda fr: initial_body_pose(mean, *_hull_surface(fr), seed=seed), len(frames)
        ) as w,
    ):  # side by side
        inits = w.map([(fr,) for fr in frames], meanwhile=read_views)
    scale = float(np.median([f.scale for f in inits]))
    z0 = space.model.transform(scale * space.model.mean_[None])[0]
    fit = fit_shape(
        space,
        views,
        np.stack([f.R for f in inits]),
        np.stack([f.root for f in inits]),
        z0=z0,
        iterations=iterations,
        seed=seed,
    )
    t = space.template(fit.z, name=name)
    notes = {
        "initial_scale": scale,
        "initial_rms": [float(f.rms) for f in inits],
        "frame_cost": [float(c) for c in fit.frame_cost],
        "shape_frames": [fr.index for fr, u in zip(frames, fit.shape_frames, strict=True) if u],
    }
    return SubjectEstimate(
        t,
        "hull",
        tuple(fr.index for fr in frames),
        fit.z,
        fit.R,
        fit.root,
        fit.rms,
        time.perf_counter() - t0,
        notes,
    )
