"""glTF 2.0 animations (``.glb`` binary or ``.gltf`` with the buffer embedded), through
pygltflib: a skinned mesh driven by a skeleton animation, or a mesh whose frames are
morph targets.

Conventions of the files written here (those of the glTF 2.0 specification):

* **Y up, metres**, right-handed, as the specification says: the library's Z-up world
  (subjects facing −Y) is turned by (x, y, z) → (x, z, −y) (:data:`Z_UP_TO_Y_UP`), so a
  subject faces +Z, the glTF "front", and stands on the y = 0 plane.
* **Skinned** (:func:`skinned_gltf`): one node per rig joint, named after it, whose
  translation is the joint's rest offset from its parent (the root's: its position) and
  whose rotation is the joint's local rotation (quaternions x, y, z, w); the skin's
  inverse bind matrices undo the world-aligned rest frames, so that glTF skinning is the
  library's linear-blend skinning (:mod:`meshmocap.body.skinning`) exactly. The animation
  ("motion") has one rotation channel per joint, quantised to normalised int16 (the
  specification allows it for rotations; ≤ 0.006° per joint), and the root's
  translation in float32, sampled at the frames' times with ``LINEAR`` interpolation
  (spherical for rotations). Up to 4 skinning weights per vertex go in ``JOINTS_0`` /
  ``WEIGHTS_0``, more in ``JOINTS_1`` / ``WEIGHTS_1`` and so on.
* **Morph** (:func:`morph_gltf`): the first frame is the mesh, every later frame a morph
  target (its displacement from the first, float32), and a ``weights`` animation steps
  from one target to the next (normalised uint8 weights, ``LINEAR``: the mesh moves
  linearly between frames). No normals are stored: viewers shade it from its faces.
  A frame costs 12 bytes per vertex.
* Triangles are indexed with uint16 below 65,536 vertices, uint32 otherwise; positions and
  normals are float32.

References
----------
- The Khronos Group, *glTF 2.0 specification*,
  https://registry.khronos.org/glTF/specs/2.0/glTF-2.0.html
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import scipy.sparse as sp

from meshmocap._atomic import write_bytes_atomic, write_text_atomic
from meshmocap._tolerances import NORM_FLOOR
from meshmocap.body.skeleton import Skeleton
from meshmocap.errors import InputError
from meshmocap.geometry.mesh import vertex_normals
from meshmocap.geometry.rotations import matrix_to_quat

__all__ = [
    "Z_UP_TO_Y_UP",
    "gltf_bytes",
    "morph_gltf",
    "skinned_gltf",
    "write_gltf",
]

#: Rotation from the library's Z-up world to glTF's Y-up: (x, y, z) → (x, z, −y).
Z_UP_TO_Y_UP = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, -1.0, 0.0]])

_FLOAT, _UBYTE, _SHORT, _USHORT, _UINT = 5126, 5121, 5122, 5123, 5125
_ARRAY, _ELEMENTS = 34962, 34963
_TYPES = {1: "SCALAR", 3: "VEC3", 4: "VEC4", 16: "MAT4"}
_DTYPES = {_FLOAT: "<f4", _UBYTE: "u1", _SHORT: "<i2", _USHORT: "<u2", _UINT: "<u4"}


@dataclass
class _Builder:
    """Accumulates one binary buffer and the accessors that read it."""

    blob: bytearray = field(default_factory=bytearray)
    views: list = field(default_factory=list)
    accessors: list = field(default_factory=list)

    def add(
        self,
        a: np.ndarray,
        component: int,
        *,
        target: int | None = None,
        normalized: bool = False,
        bounds: bool = False,
    ) -> int:
        """Append ``a`` (count, width) or (count,) as one accessor; return its index."""
        import pygltflib as g

        a = np.ascontiguousarray(a, dtype=_DTYPES[component])
        width = 1 if a.ndim == 1 else a.shape[1]
        data = a.tobytes()
        self.blob.extend(b"\0" * (-len(self.blob) % 4))
        view = g.BufferView(buffer=0, byteOffset=len(self.blob), byteLength=len(data))
        if target is not None:
            view.target = target
        self.blob.extend(data)
        self.views.append(view)
        acc = g.Accessor(
            bufferView=len(self.views) - 1,
            componentType=component,
            count=len(a),
            type=_TYPES[width],
            normalized=True if normalized else None,
        )
        if bounds:
            flat = a.reshape(len(a), width)
            acc.min = [float(x) for x in flat.min(axis=0)]
            acc.max = [float(x) for x in flat.max(axis=0)]
        self.accessors.append(acc)
        return len(self.accessors) - 1

    def gltf(self, **parts):
        import pygltflib as g

        self.blob.extend(b"\0" * (-len(self.blob) % 4))
        out = g.GLTF2(
            asset=g.Asset(version="2.0", generator="meshmocap"),
            buffers=[g.Buffer(byteLength=len(self.blob))],
            bufferViews=self.views,
            accessors=self.accessors,
            **parts,
        )
        out.set_binary_blob(bytes(self.blob))
        return out


def _check(func: str, name: str, a, shape: tuple) -> np.ndarray:
    a = np.asarray(a, dtype=np.float64)
    if a.ndim != len(shape) or any(
        s is not None and s != n for s, n in zip(shape, a.shape, strict=True)
    ):
        want = "(" + ", ".join("·" if s is None else str(s) for s in shape) + ")"
        raise InputError(f"{func}: {name} must have shape {want}, found {a.shape}")
    if not np.all(np.isfinite(a)):
        raise InputError(f"{func}: {name} contains NaN or infinite values")
    return a


def _times(func: str, times, T: int) -> np.ndarray:
    t = _check(func, "times", times, (T,))
    if T > 1 and not np.all(np.diff(t) > 0):
        raise InputError(f"{func}: times must increase strictly")
    return t


def _faces(func: str, F, n: int) -> np.ndarray:
    F = np.asarray(F)
    if F.ndim != 2 or F.shape[1] != 3 or F.dtype.kind not in "iu" or len(F) == 0:
        raise InputError(f"{func}: F must be (m, 3) integers, found {F.shape} {F.dtype}")
    if F.min() < 0 or F.max() >= n:
        raise InputError(f"{func}: F indexes vertices outside [0, {n - 1}]")
    return F


def _mesh_primitive(b: _Builder, V: np.ndarray, F: np.ndarray, *, normals: bool) -> dict:
    """Accessors of the Y-up mesh ``V`` (n, 3), ``F`` (m, 3): attributes and indices."""
    Vy = V @ Z_UP_TO_Y_UP.T
    attrs = {"POSITION": b.add(Vy, _FLOAT, target=_ARRAY, bounds=True)}
    if normals:
        N = vertex_normals(V, F) @ Z_UP_TO_Y_UP.T
        N /= np.maximum(np.linalg.norm(N, axis=1, keepdims=True), NORM_FLOOR)
        N[np.linalg.norm(N, axis=1) < 0.5] = (0.0, 1.0, 0.0)  # isolated vertices
        attrs["NORMAL"] = b.add(N, _FLOAT, target=_ARRAY)
    idx = _USHORT if len(V) < 65536 else _UINT
    return {"attrs": attrs, "indices": b.add(F.reshape(-1), idx, target=_ELEMENTS)}


def _material(name: str, color):
    import pygltflib as g

    rgb = [float(c) for c in color]
    return g.Material(
        name=name,
        doubleSided=False,
        pbrMetallicRoughness=g.PbrMetallicRoughness(
            baseColorFactor=[*rgb, 1.0], metallicFactor=0.0, roughnessFactor=0.8
        ),
    )


def skinned_gltf(
    V: np.ndarray,
    F: np.ndarray,
    skeleton: Skeleton,
    weights: sp.spmatrix,
    rotations: np.ndarray,
    root_positions: np.ndarray,
    times: np.ndarray,
    *,
    name: str = "body",
    color: tuple[float, float, float] = (0.7, 0.7, 0.7),
):
    """A skinned mesh and its skeleton animation as a ``pygltflib.GLTF2``.

    Parameters
    ----------
    V : (n, 3) float64
        Rest vertices, metres, world frame (Z up); the rest pose has identity rotations.
    F : (m, 3) int
        Triangles, counter-clockwise seen from outside.
    skeleton : Skeleton
        ``J`` joints with world-aligned rest frames (metres, Z up).
    weights : (n, J) scipy.sparse matrix
        Linear-blend skinning weights, rows summing to 1.
    rotations : (T, J, 3, 3) float64
        Local joint rotations per frame; ``root_positions`` (T, 3) float64, metres.
    times : (T,) float64
        Seconds of each frame, strictly increasing.
    name : str
        Name of the mesh and its node; ``color`` its material's linear RGB in [0, 1].

    Returns
    -------
    pygltflib.GLTF2
        Y up (see the module docstring); write it with :func:`write_gltf`.
    """
    import pygltflib as g

    func = "skinned_gltf"
    V = _check(func, "V", V, (None, 3))
    F = _faces(func, F, len(V))
    J = skeleton.n_joints
    R = _check(func, "rotations", rotations, (None, J, 3, 3))
    T = len(R)
    if T == 0:
        raise InputError(f"{func}: expected at least one frame, found none")
    root = _check(func, "root_positions", root_positions, (T, 3))
    t = _times(func, times, T)
    W = sp.csr_matrix(weights)
    if W.shape != (len(V), J):
        raise InputError(f"{func}: weights must have shape ({len(V)}, {J}), found {W.shape}")
    C = Z_UP_TO_Y_UP
    b = _Builder()
    prim = _mesh_primitive(b, V, F, normals=True)
    # skinning weights: the largest first, 4 per JOINTS_k/WEIGHTS_k set
    W.sort_indices()
    counts = np.diff(W.indptr)
    width = max(4, int(-(-counts.max() // 4) * 4))
    slot = np.arange(W.nnz) - np.repeat(W.indptr[:-1], counts)
    rows = np.repeat(np.arange(len(V)), counts)
    order = np.lexsort((-W.data, rows))
    ranks = np.empty(W.nnz, np.int64)
    ranks[order] = slot
    Jt = np.zeros((len(V), width), np.int64)
    Wt = np.zeros((len(V), width))
    Jt[rows, ranks], Wt[rows, ranks] = W.indices, W.data
    Wt /= Wt.sum(axis=1, keepdims=True)
    for k in range(width // 4):
        comp = _UBYTE if J < 256 else _USHORT
        prim["attrs"][f"JOINTS_{k}"] = b.add(Jt[:, 4 * k : 4 * k + 4], comp, target=_ARRAY)
        prim["attrs"][f"WEIGHTS_{k}"] = b.add(Wt[:, 4 * k : 4 * k + 4], _FLOAT, target=_ARRAY)
    # inverse bind matrices: world-aligned rest frames at the rest joint positions (Y up)
    P0 = skeleton.rest_positions @ C.T
    ibm = np.tile(np.eye(4), (J, 1, 1))
    ibm[:, :3, 3] = -P0
    ibm_acc = b.add(ibm.transpose(0, 2, 1).reshape(J, 16), _FLOAT)  # column-major
    # animation: quaternions of C R Cᵀ, kept in one hemisphere along time
    q = matrix_to_quat(C @ R @ C.T)  # (T, J, 4), x y z w
    flip = np.cumprod(np.where(np.sum(q[1:] * q[:-1], axis=-1) < 0, -1.0, 1.0), axis=0)
    q[1:] *= flip[..., None]
    qi = np.clip(np.rint(q * 32767.0), -32767, 32767)
    t_acc = b.add(t.astype(np.float32), _FLOAT, bounds=True)
    samplers, channels = [], []
    for j in range(J):
        out = b.add(qi[:, j], _SHORT, normalized=True)
        samplers.append(g.AnimationSampler(input=t_acc, output=out, interpolation="LINEAR"))
        channels.append(
            g.AnimationChannel(
                sampler=j, target=g.AnimationChannelTarget(node=j + 1, path="rotation")
            )
        )
    tr = b.add((root @ C.T).astype(np.float32), _FLOAT)
    samplers.append(g.AnimationSampler(input=t_acc, output=tr, interpolation="LINEAR"))
    channels.append(
        g.AnimationChannel(sampler=J, target=g.AnimationChannelTarget(node=1, path="translation"))
    )
    # nodes: 0 the mesh, 1 + j the joints
    offsets = skeleton.offsets @ C.T
    q0 = matrix_to_quat(C @ R[0] @ C.T)
    nodes = [g.Node(name=name, mesh=0, skin=0)]
    for j in range(J):
        nodes.append(
            g.Node(
                name=skeleton.names[j],
                children=[k + 1 for k in skeleton.children[j]],
                translation=[float(x) for x in (root[0] @ C.T if j == 0 else offsets[j])],
                rotation=[float(x) for x in q0[j]],
            )
        )
    primitive = g.Primitive(
        attributes=g.Attributes(**prim["attrs"]), indices=prim["indices"], material=0
    )
    mesh = g.Mesh(name=name, primitives=[primitive])
    skin = g.Skin(
        name="skeleton", joints=list(range(1, J + 1)), skeleton=1, inverseBindMatrices=ibm_acc
    )
    return b.gltf(
        scene=0,
        scenes=[g.Scene(nodes=[0, 1])],
        nodes=nodes,
        meshes=[mesh],
        skins=[skin],
        materials=[_material(name, color)],
        animations=[g.Animation(name="motion", samplers=samplers, channels=channels)],
    )


def morph_gltf(
    V: np.ndarray,
    F: np.ndarray,
    times: np.ndarray,
    *,
    name: str = "mesh",
    color: tuple[float, float, float] = (0.7, 0.7, 0.7),
):
    """A mesh sequence of fixed connectivity as morph targets and their animation.

    Parameters
    ----------
    V : (T, n, 3) float64
        Vertices of every frame, metres, world frame (Z up).
    F : (m, 3) int
        Triangles.
    times : (T,) float64
        Seconds of each frame, strictly increasing.

    Returns
    -------
    pygltflib.GLTF2
        Y up; the first frame is the mesh and frames 2..T its ``T − 1`` morph targets.
    """
    import pygltflib as g

    func = "morph_gltf"
    V = _check(func, "V", V, (None, None, 3))
    T, n = V.shape[:2]
    if T == 0 or n == 0:
        raise InputError(f"{func}: expected at least one frame and one vertex, found {V.shape}")
    F = _faces(func, F, n)
    t = _times(func, times, T)
    b = _Builder()
    prim = _mesh_primitive(b, V[0], F, normals=False)
    targets = [
        {"POSITION": b.add((V[k] - V[0]) @ Z_UP_TO_Y_UP.T, _FLOAT, target=_ARRAY, bounds=True)}
        for k in range(1, T)
    ]
    parts: dict = {}
    if T > 1:
        w = np.zeros((T, T - 1), np.uint8)
        w[np.arange(1, T), np.arange(T - 1)] = 255
        t_acc = b.add(t.astype(np.float32), _FLOAT, bounds=True)
        out = b.add(w.reshape(-1), _UBYTE, normalized=True)
        parts["animations"] = [
            g.Animation(
                name="motion",
                samplers=[g.AnimationSampler(input=t_acc, output=out, interpolation="LINEAR")],
                channels=[
                    g.AnimationChannel(
                        sampler=0, target=g.AnimationChannelTarget(node=0, path="weights")
                    )
                ],
            )
        ]
    prim_ = g.Primitive(
        attributes=g.Attributes(**prim["attrs"]),
        indices=prim["indices"],
        material=0,
        targets=[g.Attributes(**x) for x in targets] or None,
    )
    mesh = g.Mesh(name=name, primitives=[prim_], weights=[0.0] * (T - 1) if T > 1 else None)
    return b.gltf(
        scene=0,
        scenes=[g.Scene(nodes=[0])],
        nodes=[g.Node(name=name, mesh=0)],
        meshes=[mesh],
        materials=[_material(name, color)],
        **parts,
    )


def gltf_bytes(gltf) -> bytes:
    """The binary glTF (GLB) of a ``pygltflib.GLTF2``."""
    return b"".join(gltf.save_to_bytes())


def write_gltf(path: str | os.PathLike, gltf) -> Path:
    """Write a ``pygltflib.GLTF2`` atomically: ``.glb`` binary, or ``.gltf`` JSON with its
    buffer embedded as a base64 data URI (one self-contained file); return the path."""
    import pygltflib as g

    path = Path(path)
    ext = path.suffix.lower()
    if ext == ".glb":
        return write_bytes_atomic(path, gltf_bytes(gltf))
    if ext != ".gltf":
        raise InputError(f"write_gltf: the file must end in .glb or .gltf, found {path.name!r}")
    embedded = g.GLTF2.from_json(gltf.to_json())
    embedded.set_binary_blob(gltf.binary_blob())
    embedded.convert_buffers(g.BufferFormat.DATAURI)
    write_text_atomic(path, embedded.to_json(separators=(",", ":")))
    return path
