"""Rigid surface patches (patch tracker §III): partition, adjacency, centres, joint labels."""

import numpy as np
import pytest
import scipy.sparse as sp
import trimesh
from scipy.sparse.csgraph import connected_components

from meshmocap.body.template import EVAL_NAMES, EVAL_PARENTS, load_template
from meshmocap.errors import InputError
from meshmocap.geometry.mesh import edges_unique
from meshmocap.geometry.patches import (
    bone_labels,
    connected_patches,
    first_per_group,
    majority_labels,
    patch_adjacency,
    patch_centres,
    surface_patches,
    vertex_areas,
)

CASES = [(name, P) for name in ("neutral_5k", "neutral") for P in (150, 200, 250)]


@pytest.fixture(scope="module")
def templates():
    return {name: load_template(name) for name in ("neutral_5k", "neutral")}


@pytest.fixture(scope="module")
def partitions(templates):
    """Default-option partitions of both templates (6 runs, ~0.1–0.35 s each)."""
    return {
        (name, P): surface_patches(templates[name].V, templates[name].F, n_patches=P)
        for name, P in CASES
    }


def _n_components_per_patch(F, labels):
    """Connected components of the graph keeping only mesh edges inside one patch."""
    E, _ = edges_unique(F)
    same = labels[E[:, 0]] == labels[E[:, 1]]
    n = len(labels)
    A = sp.coo_matrix((np.ones(same.sum()), (E[same, 0], E[same, 1])), shape=(n, n))
    return connected_components(A, directed=False)[0]


def _grid(nx, ny):
    """A flat (nx × ny)-vertex grid of unit squares split into triangles, z = 0."""
    x, y = np.meshgrid(np.arange(nx, dtype=float), np.arange(ny, dtype=float), indexing="ij")
    V = np.stack([x.ravel(), y.ravel(), np.zeros(x.size)], axis=1)
    idx = np.arange(nx * ny).reshape(nx, ny)
    a, b = idx[:-1, :-1].ravel(), idx[1:, :-1].ravel()
    c, d = idx[1:, 1:].ravel(), idx[:-1, 1:].ravel()
    F = np.concatenate([np.stack([a, b, c], 1), np.stack([a, c, d], 1)])
    return V, F


def _sphere():
    m = trimesh.creation.icosphere(subdivisions=4)  # 2562 near-uniform vertices
    return np.asarray(m.vertices, dtype=float), np.asarray(m.faces, dtype=np.int64)


# ----------------------------------------------------------------------------- partition


@pytest.mark.parametrize(("name", "P"), CASES)
def test_template_patches_exact_count_connected_and_uniform_in_area(templates, partitions, name, P):
    t, labels = templates[name], partitions[name, P]
    assert labels.shape == (t.n_vertices,) and labels.dtype == np.int64
    assert np.array_equal(np.unique(labels), np.arange(P))  # exactly P non-empty patches
    assert _n_components_per_patch(t.F, labels) == P  # one component per patch
    area = np.bincount(labels, vertex_areas(t.V, t.F))
    # Achieved max/min: 2.8–3.0 on the 5k template (its largest vertex area is 29 cm², a
    # third of a 71–119 cm² patch, so areas are coarsely quantised), 1.9–2.5 on the 12k.
    # The brief's bound of 4 leaves room for seeds; without balancing it is 5–10.
    assert area.max() / area.min() < 4.0
    # ... while vertex counts are not uniform at all (dense hands and face): patches are
    # uniform by area, not by vertex count, as graph distances in metres make them.
    counts = np.bincount(labels)
    assert counts.max() / counts.min() > 10


@pytest.mark.parametrize(("name", "P"), CASES)
def test_template_patch_adjacency_unique_and_every_patch_has_two_neighbours(
    templates, partitions, name, P
):
    adj = patch_adjacency(templates[name].F, partitions[name, P])
    assert adj.dtype == np.int64 and adj.ndim == 2 and adj.shape[1] == 2
    assert (adj[:, 0] < adj[:, 1]).all()  # k < l, so no self-pairs, no (l, k) duplicates
    assert len(np.unique(adj, axis=0)) == len(adj)
    assert np.array_equal(adj, adj[np.lexsort((adj[:, 1], adj[:, 0]))])  # sorted
    M = sp.coo_matrix((np.ones(len(adj)), (adj[:, 0], adj[:, 1])), shape=(P, P))
    sym = (M + M.T).toarray()
    assert np.array_equal(sym, sym.T)
    degree = sym.sum(axis=1)
    # A fingertip patch could touch a single patch; area balancing makes finger patches
    # big enough to reach the palm's neighbours, and none is left with fewer than 2.
    assert degree.min() >= 2
    assert 5 <= np.median(degree) <= 7  # ~6 neighbours, as for a tiling of the plane
    assert connected_components(M, directed=False)[0] == 1  # the body is one surface


def test_area_balancing_beats_plain_centroidal_voronoi(templates, partitions):
    t = templates["neutral"]
    area = vertex_areas(t.V, t.F)
    plain = surface_patches(t.V, t.F, n_patches=200, n_balance=0)
    ratio = [np.ptp(np.log(np.bincount(lab, area))) for lab in (plain, partitions["neutral", 200])]
    assert np.exp(ratio[1]) < 0.5 * np.exp(ratio[0])  # 2.5 vs 6.6 with seed 0


def test_sphere_patches_are_nearly_equal_in_area():
    V, F = _sphere()
    labels = surface_patches(V, F, n_patches=100)
    area = np.bincount(labels, vertex_areas(V, F))
    # A near-uniform sphere has no thin parts: achieved 1.31 (2.23 without balancing);
    # 1.5 allows for the vertex-level quantisation (a vertex is ~4 % of a patch).
    assert area.max() / area.min() < 1.5
    assert _n_components_per_patch(F, labels) == 100


def test_deterministic_per_seed_and_different_across_seeds(templates, partitions):
    t = templates["neutral_5k"]
    again = surface_patches(t.V, t.F, n_patches=150, seed=0)
    other = surface_patches(t.V, t.F, n_patches=150, seed=1)
    assert np.array_equal(again, partitions["neutral_5k", 150])
    assert not np.array_equal(other, again)
    assert len(np.unique(other)) == 150


def test_extreme_patch_counts_and_disconnected_meshes():
    V, F = _sphere()
    assert np.array_equal(surface_patches(V, F, n_patches=1), np.zeros(len(V), np.int64))
    one_each = surface_patches(V, F, n_patches=len(V), n_balance=2)
    assert np.array_equal(np.sort(one_each), np.arange(len(V)))
    # two separate spheres: farthest-point sampling seeds each component first
    V2, F2 = np.concatenate([V, V + [3.0, 0, 0]]), np.concatenate([F, F + len(V)])
    labels = surface_patches(V2, F2, n_patches=2)
    assert len(np.unique(labels[: len(V)])) == 1 and len(np.unique(labels[len(V) :])) == 1
    assert labels[0] != labels[-1]
    with pytest.raises(InputError, match="connected components of the mesh \\(2"):
        surface_patches(V2, F2, n_patches=1)


def test_fix_split_patches_keeps_largest_piece_and_reconnects():
    V, F = _grid(6, 6)
    E, _ = edges_unique(F)
    L = np.linalg.norm(V[E[:, 0]] - V[E[:, 1]], axis=1)
    labels = np.where(V[:, 0] < 3, 0, 1)  # left half 0, right half 1 ...
    labels[(V[:, 0] == 5) & (V[:, 1] == 5)] = 0  # ... plus a stray corner vertex in patch 0
    assert _n_components_per_patch(F, labels) == 3
    fixed = connected_patches(labels, E, L, np.ones(len(V)), 2)
    assert _n_components_per_patch(F, fixed) == 2
    expected = np.where(V[:, 0] < 3, 0, 1)  # the corner joins its only neighbour, patch 1
    assert np.array_equal(fixed, expected)
    assert connected_patches(expected, E, L, np.ones(len(V)), 2) is expected  # no-op


def test_first_per_group_matches_lexsort_including_ties():
    rng = np.random.default_rng(5)
    groups = rng.permutation(np.r_[np.arange(40), rng.integers(0, 40, 500)])
    keys = rng.integers(0, 6, len(groups)).astype(float)  # many ties
    order = np.lexsort((keys, groups))
    expected = order[np.searchsorted(groups[order], np.arange(40))]
    assert np.array_equal(first_per_group(groups, keys, 40), expected)


# ----------------------------------------------------------------------------- adjacency, centres


def test_patch_adjacency_on_a_grid():
    _, F = _grid(4, 3)
    labels = np.array([0, 0, 1, 0, 0, 1, 2, 2, 1, 2, 2, 3])  # column-major (x then y)
    adj = patch_adjacency(F, labels)
    assert adj.tolist() == [[0, 1], [0, 2], [1, 2], [1, 3], [2, 3]]
    assert patch_adjacency(F, np.zeros(12, int)).shape == (0, 2)


def test_patch_centres_uniform_and_weighted():
    V = np.array([[0.0, 0, 0], [2, 0, 0], [10, 0, 0], [10, 4, 0]])
    labels = np.array([0, 0, 1, 1])
    assert np.allclose(patch_centres(V, labels), [[1, 0, 0], [10, 2, 0]], atol=1e-15)
    w = np.array([3.0, 1.0, 0.0, 2.0])
    assert np.allclose(patch_centres(V, labels, weights=w), [[0.5, 0, 0], [10, 4, 0]])
    with pytest.raises(InputError, match="patch 1 has 0"):
        patch_centres(V, labels, weights=[1.0, 1.0, 0.0, 0.0])


def test_patch_centres_area_weighted_on_template(templates, partitions):
    t, labels = templates["neutral"], partitions["neutral", 200]
    a = vertex_areas(t.V, t.F)
    c = patch_centres(t.V, labels, weights=a)
    k = 17
    m = labels == k
    assert np.allclose(c[k], (a[m, None] * t.V[m]).sum(0) / a[m].sum(), atol=1e-12)
    # centres lie within a patch's extent: < 10 cm from the nearest of its vertices
    d = np.linalg.norm(t.V - c[labels], axis=1)
    nearest = np.minimum.reduceat(
        d[np.argsort(labels)], np.searchsorted(np.sort(labels), range(200))
    )
    assert nearest.max() < 0.10


# ----------------------------------------------------------------------------- joint labels


def test_majority_vote_with_ties_going_to_the_smallest_label():
    labels = np.array([0, 0, 0, 1, 1, 1, 1, 2, 2, 3])
    vertex = np.array([4, 4, 1, 2, 3, 3, 2, 0, 4, 1])
    # patch 0: 4 ×2 beats 1; patch 1: 2 and 3 tie ×2 → 2; patch 2: 0 and 4 tie → 0; patch 3: 1
    out = majority_labels(labels, vertex, 5)
    assert out.dtype == np.int64 and out.tolist() == [4, 2, 0, 1]


def test_bone_labels_map_leaves_to_their_parent_bone():
    names = list(EVAL_NAMES)
    labels, classes = bone_labels(np.arange(15), EVAL_PARENTS)
    got = {names[i]: names[j] for i, j in enumerate(labels)}
    expected = {n: n for n in names}
    expected.update(
        head="thorax",
        left_wrist="left_elbow",
        right_wrist="right_elbow",
        left_ankle="left_knee",
        right_ankle="right_knee",
    )
    assert got == expected
    non_leaf = [
        "pelvis",
        "thorax",
        "left_shoulder",
        "left_elbow",
        "right_shoulder",
        "right_elbow",
        "left_hip",
        "left_knee",
        "right_hip",
        "right_knee",
    ]
    assert classes.dtype == np.int64 and classes.tolist() == sorted(map(names.index, non_leaf))
    same, all_classes = bone_labels(np.arange(15), EVAL_PARENTS, leaf_to_parent=False)
    assert np.array_equal(same, np.arange(15)) and np.array_equal(all_classes, np.arange(15))
    assert bone_labels([0, 0], [-1])[0].tolist() == [0, 0]  # a lone root keeps its label


def test_template_patches_get_non_leaf_joints(templates, partitions):
    t, labels = templates["neutral"], partitions["neutral", 200]
    vlab, classes = bone_labels(t.part_labels, t.eval_skeleton.parents)
    assert np.isin(vlab, classes).all()
    plab = majority_labels(labels, vlab, len(t.eval_skeleton.names))
    # every bone carries patches (the fewest: 9 on the left upper arm at 200 patches)
    assert set(np.unique(plab)) == set(classes.tolist())
    # patches are small against body parts: ≥ 85 % of the vertices agree with their patch
    # (achieved 96.5–97.8 % on both templates at 150–250 patches; the rest lie on patches
    # straddling a joint)
    assert (plab[labels] == vlab).mean() > 0.85


# ----------------------------------------------------------------------------- input errors


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"n_patches": 0}, "n_patches must be \\[1, 2562\\], found 0"),
        ({"n_patches": 2563}, "n_patches must be \\[1, 2562\\], found 2563"),
        ({"n_patches": 10.0}, "n_patches must be an integer"),
        ({"n_patches": True}, "n_patches must be an integer"),
        ({"n_iter": -1}, "n_iter must be >= 0"),
        ({"n_balance": -1}, "n_balance must be >= 0"),
        ({"seed": -1}, "seed must be >= 0"),
    ],
)
def test_surface_patches_rejects_bad_options(kwargs, match):
    V, F = _sphere()
    with pytest.raises(InputError, match=match) as exc:
        surface_patches(V, F, **kwargs)
    assert "\n" not in str(exc.value)


def test_bad_shapes_and_values_raise_one_line_input_errors():
    V, F = _grid(3, 3)
    bad_V = V.copy()
    bad_V[2, 1] = np.nan
    calls = [
        (lambda: surface_patches(V[:, :2], F, n_patches=2), "V must have shape \\(n, 3\\)"),
        (lambda: surface_patches(bad_V, F, n_patches=2), "V must be finite"),
        (lambda: surface_patches(V, F[:, :2], n_patches=2), "F must have shape \\(m, 3\\)"),
        (lambda: surface_patches(V, F + 1, n_patches=2), "F indices must lie in \\[0, 8\\]"),
        (lambda: surface_patches(V, F * 1.0, n_patches=2), "F must hold integer"),
        (lambda: patch_adjacency(F, np.zeros(5, int)), "F indices must lie in \\[0, 4\\]"),
        (lambda: patch_adjacency(F, np.zeros(9)), "labels must hold integers"),
        (lambda: patch_centres(V, np.zeros(8, int)), "labels must have shape \\(9,\\)"),
        (lambda: patch_centres(V, np.r_[np.zeros(8, int), 2]), "found 1 empty \\(first: 1\\)"),
        (lambda: patch_centres(V, np.zeros(9, int), weights=-np.ones(9)), "non-negative"),
        (lambda: patch_centres(V, np.zeros(9, int), weights=np.ones(3)), "weights must have"),
        (lambda: majority_labels([0, 1], [0, 5], 5), "vertex_labels must lie in \\[0, 4\\]"),
        (lambda: majority_labels([0, 1], [0, 1, 1], 5), "vertex_labels must have shape"),
        (lambda: majority_labels([0, -1], [0, 1], 5), "labels must be >= 0"),
        (lambda: majority_labels([0, 1], [0, 1], 0), "n_classes must be >= 1"),
        (lambda: bone_labels([0, 15], EVAL_PARENTS), "part_labels must lie in \\[0, 14\\]"),
        (lambda: bone_labels([0], [[-1, 0]]), "eval_parents must be a \\(K,\\) integer"),
        (lambda: bone_labels([0], [-1, 1]), "not self-refer"),
    ]
    for call, match in calls:
        with pytest.raises(InputError, match=match) as exc:
            call()
        assert "\n" not in str(exc.value)
