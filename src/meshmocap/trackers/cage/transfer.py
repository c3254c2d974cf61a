"""Motion transfer (cage-manifold-tracking §6.3): another mesh replays a cage track.

"Once we have captured our parameterized performance, we can put any model we want in the
cage to obtain a new animation (motion transfer) ... fully automatic as the computation of
the Green Coordinates is automatic." The new mesh is placed in the rest cage of the
tracking template's Oriented Quads Rigging, its vertices get Green coordinates with
respect to that rest cage (:class:`~meshmocap.geometry.green.GreenDeformer`), and every
tracked frame's cage deforms it (Eq. 1). Transferring the tracking template itself gives
back the tracked vertices.

A cage track (:func:`read_cage_track`) is a track folder written by the cage tracker
(:mod:`meshmocap.io.results`): each frame's state holds its cage vertices (``cage``; older
tracks are rebuilt from the quads, ``local``, ``pelvis_R``, ``pelvis_c``). The rest cage
and faces come from the template's OQR, rebuilt from the template named in
``track.json`` (or given); the stored cages are checked against that rigging.

Vertices outside the rest cage follow the analytic continuation of the nearest cage face
(:func:`~meshmocap.geometry.green.green_coordinates`, ``exterior="extend"``), which is
smooth only close to the cage: a body of another size should first be placed in the cage
(:func:`place_in_cage`, ``fit="scale"`` or ``"stretch"``), and vertices farther outside
than a tolerance are reported (warning, error or nothing).

Units: metres, world frame Z up (subject facing −Y at rest), like every mesh here.

References
----------
- E. Duveau, S. Courtemanche, L. Reveret, E. Boyer, *Cage-based motion recovery
  using manifold learning*, International Conference on 3D Imaging, Modeling,
  Processing, Visualization and Transmission (3DIMPVT), 2012.
- Y. Lipman, D. Levin, D. Cohen-Or, *Green coordinates*, ACM Transactions on Graphics
  27(3) (SIGGRAPH 2008). https://doi.org/10.1145/1360612.1360677
"""

from __future__ import annotations

import hashlib
import json
import os
import warnings
from dataclasses import dataclass
from pathlib import Path
from typing import Literal, get_args

import numpy as np

from meshmocap._atomic import write_text_atomic
from meshmocap._tolerances import SAME_POSITION
from meshmocap._validate import check_choice
from meshmocap.body.template import Template
from meshmocap.errors import (
    FormatError,
    InputError,
    MeshmocapFileNotFoundError,
    MeshmocapWarning,
)
from meshmocap.geometry.green import GreenDeformer
from meshmocap.geometry.proximity import closest_points_on_triangles
from meshmocap.io.gltf import morph_gltf, write_gltf
from meshmocap.io.results import done_frames, read_state, tracked_template
from meshmocap.trackers.cage.oqr import OQR, build_oqr, cage_vertices, configuration_from_vector

__all__ = [
    "FLOAT32_VERTICES",
    "MAX_TRANSFER_VERTICES",
    "CageTrack",
    "Placement",
    "TransferResult",
    "outside_distances",
    "place_in_cage",
    "read_cage_track",
    "transfer_motion",
    "write_transfer",
]

Fit = Literal["none", "scale", "stretch"]
Outside = Literal["warn", "raise", "ignore"]
TRANSFER_FORMAT = "meshmocap-transfer-1"
_CHUNK = 64  # frames deformed per batch
#: Vertices at most that a transfer binds to the cage. Each bound vertex stores one Green
#: coordinate per cage vertex and face (float32 above :data:`FLOAT32_VERTICES`), so memory
#: is bounded by design: ``4 × (nv + nf)`` bytes a vertex, about 0.5 GB at the cap for the
#: 86-vertex, 166-face cage. A larger mesh is refused in one line (decimate it first).
MAX_TRANSFER_VERTICES = 500_000
#: Meshes with more vertices than this store their coordinates in float32 (half the
#: memory, ~2 µm on a human-sized cage); smaller ones in float64 (the tracker's own numbers).
FLOAT32_VERTICES = 100_000


@dataclass(frozen=True, eq=False)
class CageTrack:
    """The per-frame cages of a cage track and the rest cage they deform.

    Attributes
    ----------
    path : Path
        The track folder.
    template : Template
        The tracking template (its rest vertices are what :func:`place_in_cage` aligns to).
    frames : (T,) int64
        Frame numbers.
    cages : (T, 85, 3) float64
        Each frame's cage vertices, metres, world frame (Z up).
    rest_cage : (85, 3) float64
        The template's rest cage.
    faces : (166, 3) int64
        Cage triangles, outward.
    """

    path: Path
    template: Template
    frames: np.ndarray
    cages: np.ndarray
    rest_cage: np.ndarray
    faces: np.ndarray


def read_cage_track(
    path: str | os.PathLike, *, template: Template | None = None, oqr: OQR | None = None
) -> CageTrack:
    """Read the cages of a track folder written by the cage tracker.

    Parameters
    ----------
    path : path
        Track folder (``meshmocap track --method cage``).
    template : Template, optional
        The tracking template (default: the bundled template named in ``track.json``).
    oqr : OQR, optional
        Its rigging (built when omitted, about a second).

    Raises
    ------
    MeshmocapFileNotFoundError
        No track, no frames, or a non-bundled template that was not given.
    InputError
        Not a cage track, another template, or cages that its rigging does not rebuild.
    FormatError
        Frame states without cage or quads.
    """
    path = Path(path)
    meta_path = path / "track.json"
    if not meta_path.is_file():
        raise MeshmocapFileNotFoundError(f"track: {path} has no track.json")
    meta = json.loads(meta_path.read_text())
    if meta.get("method") != "cage":
        raise InputError(
            f"{path}: motion transfer needs a cage track, found method {meta.get('method')!r}"
        )
    name = str(meta.get("template"))
    if template is None:
        template = tracked_template(path, meta)
    elif template.name != name:
        raise InputError(f"{path}: tracked with template {name!r}, found {template.name!r}")
    frames = done_frames(path)
    if not frames:
        raise MeshmocapFileNotFoundError(f"track: {path / 'frames'} holds no frame results")
    oqr = oqr or build_oqr(template)
    cages = []
    for i in frames:
        s = read_state(path, i)
        rebuilt = None
        if {"local", "pelvis_R", "pelvis_c"} <= s.keys():
            c, Q = configuration_from_vector(s["local"], s["pelvis_c"], s["pelvis_R"])
            rebuilt = cage_vertices(oqr, c, Q)
        if "cage" in s:
            cage = np.asarray(s["cage"], dtype=np.float64)
            if cage.shape != oqr.rest_vertices.shape:
                raise FormatError(
                    f"{path}: frame {i} cage has shape {cage.shape}, expected "
                    f"{oqr.rest_vertices.shape}"
                )
            if rebuilt is not None and np.abs(rebuilt - cage).max() > SAME_POSITION:
                raise InputError(
                    f"{path}: frame {i} cage does not follow the quad rigging of "
                    f"template {name!r} (tracked with another rigging?)"
                )
        elif rebuilt is not None:
            cage = rebuilt
        else:
            raise FormatError(f"{path}: frame {i} stores neither its cage nor its quads")
        cages.append(cage)
    return CageTrack(
        path,
        template,
        np.array(frames, dtype=np.int64),
        np.stack(cages),
        np.array(oqr.rest_vertices),
        np.array(oqr.faces),
    )


@dataclass(frozen=True, eq=False)
class Placement:
    """An axis-aligned scale and offset placing a mesh in the rest cage: ``X' = X s + t``.

    Attributes
    ----------
    scale : (3,) float64
        Per-axis scale (all equal for ``fit="scale"``).
    offset : (3,) float64
        Translation, metres.
    """

    scale: np.ndarray
    offset: np.ndarray

    def apply(self, X: np.ndarray) -> np.ndarray:
        """Placed points (..., 3) of points ``X`` (..., 3) in the mesh's frame."""
        return np.asarray(X, dtype=np.float64) * self.scale + self.offset


def place_in_cage(V: np.ndarray, reference: np.ndarray, *, fit: Fit = "scale") -> Placement:
    """How to place a body ``V`` where the tracking template ``reference`` stands.

    Both are in the rest frame of the library (Z up, facing −Y). Their bounding boxes are
    aligned: centres in x and y, soles (lowest z) on each other; ``fit="scale"`` scales
    uniformly to the reference's height, ``"stretch"`` each axis to its extent (a wider
    body is slimmed to fit), ``"none"`` leaves the body as it is.

    Parameters
    ----------
    V : (n, 3) float64
        The body's vertices, metres.
    reference : (m, 3) float64
        The tracking template's rest vertices.
    fit : {"none", "scale", "stretch"}

    Returns
    -------
    Placement
    """
    check_choice("place_in_cage", "fit", fit, get_args(Fit))
    V, ref = _points("place_in_cage", "V", V), _points("place_in_cage", "reference", reference)
    if fit == "none":
        return Placement(np.ones(3), np.zeros(3))
    lo, hi, rlo, rhi = V.min(0), V.max(0), ref.min(0), ref.max(0)
    ext, rext = hi - lo, rhi - rlo
    if fit == "scale":
        if not ext[2] > 0:
            raise InputError("place_in_cage: V has no height to scale")
        s = np.full(3, rext[2] / ext[2])
    else:
        if not np.all(ext > 0):
            raise InputError(f"place_in_cage: V is flat (extent {ext}), cannot stretch it")
        s = rext / ext
    anchor = np.array([(lo[0] + hi[0]) / 2, (lo[1] + hi[1]) / 2, lo[2]])
    target = np.array([(rlo[0] + rhi[0]) / 2, (rlo[1] + rhi[1]) / 2, rlo[2]])
    return Placement(s, target - anchor * s)


def _points(func: str, name: str, X) -> np.ndarray:
    X = np.asarray(X, dtype=np.float64)
    if X.ndim != 2 or X.shape[1] != 3 or len(X) == 0:
        raise InputError(f"{func}: {name} must have shape (n, 3) with n > 0, found {X.shape}")
    if not np.all(np.isfinite(X)):
        raise InputError(f"{func}: {name} contains NaN or infinite values")
    return X


def outside_distances(
    points: np.ndarray, cage_V: np.ndarray, cage_F: np.ndarray, outside: np.ndarray
) -> np.ndarray:
    """Distance, metres, of each point flagged ``outside`` (n,) bool to the cage surface
    (0 for the others); exact, brute force over the cage faces."""
    d = np.zeros(len(points))
    idx = np.flatnonzero(outside)
    A, B, C = (np.asarray(cage_V)[np.asarray(cage_F)[:, k]] for k in range(3))
    nf = len(A)
    for start in range(0, len(idx), 2048):
        p = points[idx[start : start + 2048]]
        pp = np.repeat(p, nf, axis=0)
        Q = closest_points_on_triangles(
            pp, np.tile(A, (len(p), 1)), np.tile(B, (len(p), 1)), np.tile(C, (len(p), 1))
        )
        d[idx[start : start + 2048]] = np.linalg.norm(pp - Q, axis=1).reshape(-1, nf).min(1)
    return d


def _encode(track: CageTrack, points, fit, outside: Outside, tolerance: float, func: str):
    check_choice(func, "outside", outside, get_args(Outside))
    if not (np.isfinite(tolerance) and tolerance >= 0):
        raise InputError(f"{func}: tolerance must be a number ≥ 0, found {tolerance!r}")
    P = _points(func, "points", points)
    if len(P) > MAX_TRANSFER_VERTICES:
        per = 4 * (len(track.rest_cage) + len(track.faces))
        raise InputError(
            f"{func}: the mesh has {len(P):,} vertices, more than the {MAX_TRANSFER_VERTICES:,} "
            f"a transfer binds (their Green coordinates take {per} bytes a vertex: "
            f"{len(P) * per / 1e9:.1f} GB); decimate it first (e.g. to {MAX_TRANSFER_VERTICES:,} "
            "vertices)"
        )
    placement = fit if isinstance(fit, Placement) else place_in_cage(P, track.template.V, fit=fit)
    P = placement.apply(P)
    dtype = np.float32 if len(P) > FLOAT32_VERTICES else np.float64
    deformer = GreenDeformer(track.rest_cage, track.faces, P, dtype=dtype)
    d = outside_distances(P, track.rest_cage, track.faces, deformer.outside_)
    far = d > tolerance
    if far.any() and outside != "ignore":
        hint = (
            "place the body with fit='scale' or 'stretch'"
            if fit == "none"
            else "they may deform less smoothly"
        )
        msg = (
            f"{func}: {int(far.sum())} of {len(P)} vertices lie outside the rest cage by more "
            f"than {tolerance * 1000:g} mm (up to {d.max() * 1000:.0f} mm) and follow the "
            f"nearest cage face's extension; {hint}"
        )
        if outside == "raise":
            raise InputError(msg)
        warnings.warn(msg, MeshmocapWarning, stacklevel=3)
    return deformer, placement, d


def transfer_motion(
    track: CageTrack,
    points: np.ndarray,
    *,
    fit: Fit | Placement = "none",
    outside: Outside = "warn",
    tolerance: float = 0.005,
) -> np.ndarray:
    """Replay a cage track with another body (or any points) placed in its rest cage.

    Parameters
    ----------
    track : CageTrack
        :func:`read_cage_track`.
    points : (n, 3) float64
        The body's rest vertices (or joints, markers), metres, world frame Z up, facing −Y.
    fit : {"none", "scale", "stretch"} or Placement
        How to place the body where the tracking template stands (:func:`place_in_cage`);
        a :class:`Placement` is applied as given (e.g. the one of a mesh, to its joints).
    outside : {"warn", "raise", "ignore"}
        What to do when placed points lie outside the rest cage by more than
        ``tolerance``: :class:`MeshmocapWarning`, :class:`InputError` or nothing.
    tolerance : float
        Metres.

    Returns
    -------
    (T, n, 3) float64
        The points in every frame of the track, metres, world frame. For the tracking
        template's own vertices this is the tracker's computation itself: the track's
        vertices up to their float32 storage (< 2e-7 m).
    """
    deformer, _, _ = _encode(track, points, fit, outside, tolerance, "transfer_motion")
    return np.concatenate(
        [deformer.deform(track.cages[k : k + _CHUNK]) for k in range(0, len(track.cages), _CHUNK)]
    )


@dataclass(frozen=True, eq=False)
class TransferResult:
    """What :func:`write_transfer` did.

    Attributes
    ----------
    out : Path
        The output folder.
    files : tuple of Path
        One mesh per track frame, in frame order (or the one animated glTF file).
    written, skipped : int
        Frames written now, and frames already there (a resumed run).
    placement : Placement
        How the body was placed in the rest cage.
    n_outside : int
        Vertices outside the rest cage (any distance).
    max_outside : float
        Largest distance of a vertex outside the rest cage, metres (0 when none).
    """

    out: Path
    files: tuple[Path, ...]
    written: int
    skipped: int
    placement: Placement
    n_outside: int
    max_outside: float


def write_transfer(
    track: CageTrack,
    V: np.ndarray,
    F: np.ndarray,
    out: str | os.PathLike,
    *,
    fit: Fit | Placement = "none",
    outside: Outside = "warn",
    tolerance: float = 0.005,
    ext: str = ".obj",
    resume: bool = True,
    name: str = "mesh",
    fps: float = 30.0,
) -> TransferResult:
    """Write ``V`` (n, 3) and ``F`` (m, 3) replaying the motion of ``track``
    (:func:`transfer_motion`; same options): one mesh per frame
    (``out/frame_NNNNN.obj``, ``.ply``, ``.off``, ``.stl``), or, for ``ext`` ``.glb`` or
    ``.gltf``, one animated glTF file ``out/transfer.glb`` (Y up as glTF's specification
    says; every frame a morph target, timed at ``fps`` from the track's first frame;
    :func:`meshmocap.io.gltf.morph_gltf`).

    Files are written atomically; ``out/transfer.json`` records the settings, and a
    resumed run (``resume``, same settings) skips the frames already written. Other
    settings in a resumed folder raise :class:`FormatError`; ``resume=False`` starts over.
    ``name`` is recorded in ``transfer.json`` (the mesh's file or template name).
    """
    from meshmocap.io.meshes import write_mesh

    func = "write_transfer"
    exts = (".obj", ".ply", ".off", ".stl", ".glb", ".gltf")
    if ext not in exts:
        raise InputError(f"{func}: ext must be one of {', '.join(exts)}, found {ext!r}")
    if not (np.isfinite(fps) and fps > 0):
        raise InputError(f"{func}: fps must be a positive number, found {fps!r}")
    animated = ext in (".glb", ".gltf")
    Fa = np.asarray(F)
    if Fa.ndim != 2 or Fa.shape[1] != 3 or Fa.dtype.kind not in "iu":
        raise InputError(f"{func}: F must be (m, 3) integers, found {Fa.shape} {Fa.dtype}")
    V = _points(func, "V", V)
    placement = fit if isinstance(fit, Placement) else place_in_cage(V, track.template.V, fit=fit)
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    h = hashlib.sha256(np.ascontiguousarray(V, dtype=np.float64).tobytes())
    h.update(np.ascontiguousarray(Fa, dtype=np.int64).tobytes())
    settings = {
        "format": TRANSFER_FORMAT,
        "track": str(track.path.resolve()),
        "mesh": name,
        "mesh_digest": h.hexdigest()[:16],
        "fit": fit
        if isinstance(fit, str)
        else {"scale": placement.scale.tolist(), "offset": placement.offset.tolist()},
        "ext": ext,
        "frames": track.frames.tolist(),
    }
    if animated:
        settings["fps"] = float(fps)
    meta = out / "transfer.json"
    files = (
        [out / f"transfer{ext}"]
        if animated
        else [out / f"frame_{i:05d}{ext}" for i in track.frames]
    )
    if meta.is_file() and resume:
        if json.loads(meta.read_text()) != json.loads(json.dumps(settings)):
            raise FormatError(
                f"{meta}: holds a transfer made with other settings; use another "
                "folder or start over"
            )
    else:
        for p in out.glob(f"transfer{ext}" if animated else f"frame_*{ext}"):
            p.unlink()
    deformer, _, d = _encode(track, V, fit, outside, tolerance, func)
    write_text_atomic(meta, json.dumps(settings, indent=2) + "\n")
    if animated:
        T = len(track.frames)
        if files[0].is_file():
            written, skipped = 0, T
        else:
            X = transfer_motion(track, V, fit=placement, outside="ignore")
            times = (track.frames - track.frames[0]) / fps
            write_gltf(files[0], morph_gltf(X, Fa, times, name=Path(name).stem or "mesh"))
            written, skipped = T, 0
        return TransferResult(
            out,
            tuple(files),
            written,
            skipped,
            placement,
            int(deformer.outside_.sum()),
            float(d.max()),
        )
    todo = [k for k, p in enumerate(files) if not p.is_file()]
    for start in range(0, len(todo), _CHUNK):
        ks = todo[start : start + _CHUNK]
        for k, X in zip(ks, deformer.deform(track.cages[ks]), strict=True):
            write_mesh(files[k], X, Fa)
    return TransferResult(
        out,
        tuple(files),
        len(todo),
        len(files) - len(todo),
        placement,
        int(deformer.outside_.sum()),
        float(d.max()),
    )
