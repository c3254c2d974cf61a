"""Evaluation metrics, tables and plots (meshmocap.analysis.metrics / tables / plots)."""

import csv

import numpy as np
import pytest
import trimesh

from meshmocap.analysis.metrics import (
    Stats,
    bone_length_stats,
    bone_lengths,
    correspondence_error,
    joint_errors,
    mesh_silhouette,
    mesh_silhouette_errors,
    silhouette_errors,
    silhouette_overlap_error,
    surface_distance,
)
from meshmocap.analysis.tables import format_table, table, write_csv
from meshmocap.apps.figures.evaluation import (
    plot_bone_lengths,
    plot_frame_errors,
    plot_joint_errors,
    plot_silhouette_errors,
)
from meshmocap.body.template import EVAL_NAMES, EVAL_PARENTS
from meshmocap.errors import InputError
from meshmocap.geometry.camera import Camera, intrinsics, look_at
from meshmocap.geometry.proximity import (
    closest_points_on_triangles,
    point_to_surface,
    sample_surface,
)

RNG = np.random.default_rng(3)


def _joints(T: int = 12) -> np.ndarray:
    return RNG.normal(scale=0.5, size=(T, 15, 3)) + [0.0, 0.0, 1.0]


# ---------------------------------------------------------------- joints


def test_a_known_offset_gives_exactly_its_length():
    true = _joints()
    pred = true + [0.003, 0.004, 0.0]  # 3-4-5 mm
    e = joint_errors(pred, true)
    # Rounding: |true| ≤ 3 m, so each coordinate of pred − true is off by ≤ 4e-16 m = 4e-13 mm.
    assert np.abs(e.errors - 5.0).max() < 1e-9
    assert e.names == EVAL_NAMES and e.errors.shape == (12, 15)
    assert abs(e.overall.mean - 5.0) < 1e-9 and abs(e.overall.std) < 1e-9
    assert all(abs(s.max - 5.0) < 1e-9 for s in e.per_joint)


def test_statistics_match_numpy_and_failures_are_reported_not_propagated():
    true = _joints()
    pred = true + RNG.normal(scale=0.03, size=true.shape)
    pred[4, 7] = np.nan  # a tracker failure
    true[9] = np.nan  # corrupt ground truth
    e = joint_errors(pred, true)
    assert list(e.failed) == [4] and list(e.skipped) == [9]
    keep = [t for t in range(12) if t not in (4, 9)]
    ref = np.linalg.norm(pred[keep] - true[keep], axis=-1) * 1000
    assert np.array_equal(e.frames, keep) and np.allclose(e.errors, ref, rtol=1e-12)
    assert np.isfinite(e.errors).all() and np.isfinite(e.per_frame).all()
    o = e.overall
    assert np.allclose(
        [o.mean, o.median, o.std, o.max],
        [ref.mean(), np.median(ref), ref.std(), ref.max()],
        rtol=1e-12,
    )
    assert np.isclose(e.per_joint[3].median, np.median(ref[:, 3]), rtol=1e-12)
    assert np.allclose(e.per_frame, ref.mean(axis=1), rtol=1e-12)


def test_fourteen_joint_variant_without_pelvis():
    true = _joints()
    pred = true + RNG.normal(scale=0.03, size=true.shape)
    e14 = joint_errors(pred, true, exclude=("pelvis",))
    assert len(e14.names) == 14 and "pelvis" not in e14.names
    ref = np.linalg.norm(pred[:, 1:] - true[:, 1:], axis=-1) * 1000
    assert np.isclose(e14.overall.mean, ref.mean(), rtol=1e-12)
    assert np.array_equal(joint_errors(pred, true).excluding("pelvis").errors, e14.errors)
    with pytest.raises(InputError, match="unknown joints"):
        e14.excluding("tail")
    with pytest.raises(InputError, match=r"\(T, K, 3\)"):
        joint_errors(pred, true[:, :14])
    with pytest.raises(InputError, match="3 distinct joint names"):
        joint_errors(pred[:, :3], true[:, :3], names=["a", "a", "b"])


def test_every_frame_failed():
    true = _joints(3)
    e = joint_errors(np.full_like(true, np.nan), true)
    assert list(e.failed) == [0, 1, 2] and e.errors.shape == (0, 15)
    assert np.isnan(e.overall.mean)  # no data: NaN by definition, not a propagated failure


# ---------------------------------------------------------------- vertices, bones


def test_correspondence_error_of_a_known_displacement():
    V = RNG.normal(size=(5, 200, 3))
    tracked = V + [0.001, 0.002, 0.002]  # |(1, 2, 2)| = 3 mm
    tracked[2, 17] = np.inf
    c = correspondence_error(tracked, V)
    assert list(c.failed) == [2] and list(c.frames) == [0, 1, 3, 4]
    assert np.abs(c.errors - 3.0).max() < 1e-9  # rounding as in the joint test
    assert np.allclose(c.per_frame, 3.0, atol=1e-9) and np.allclose(c.per_vertex, 3.0, atol=1e-9)
    s = c.overall
    assert abs(s.mean - 3) < 1e-9 and abs(s.median - 3) < 1e-9 and abs(s.max - 3) < 1e-9


def test_bone_lengths_of_a_known_skeleton():
    chain = np.array([[0.0, 0.0, 0.0], [0.0, 0.0, 0.3], [0.0, 0.4, 0.3]])
    assert np.allclose(bone_lengths(chain, [-1, 0, 1]), [0.3, 0.4], atol=1e-15)
    # Rigid motions keep lengths: std 0 (to rounding); one stretched frame: 300 and 330 mm.
    c, s = np.cos(0.7), np.sin(0.7)
    R = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    frames = np.stack([chain, chain @ R.T + [1.0, 2.0, 0.5], chain * [1.0, 1.0, 1.1]])
    b = bone_length_stats(frames[:2], [-1, 0, 1], names=["root", "mid", "tip"])
    assert b.names == ("root-mid", "mid-tip")
    assert np.allclose(b.mean, [300.0, 400.0], atol=1e-9) and np.allclose(b.std, 0.0, atol=1e-9)
    b3 = bone_length_stats(frames, [-1, 0, 1])
    # Population std (ddof 0) of {300, 300, 330}: sqrt(200) mm.
    assert np.allclose(b3.mean[0], 310.0) and np.allclose(b3.std[0], np.sqrt(200.0))
    e = bone_length_stats(_joints(4), EVAL_PARENTS)
    assert e.lengths.shape == (4, 14) and e.names[0] == "pelvis-thorax"
    with pytest.raises(InputError, match="parents"):
        bone_lengths(chain, [-1, 0, 5])


# ---------------------------------------------------------------- silhouettes


def test_xor_error_of_two_known_masks():
    true = np.zeros((30, 40), bool)
    true[10:20, 10:20] = True  # 100 pixels
    pred = np.zeros_like(true)
    pred[10:20, 12:22] = True  # shifted 2 columns: 20 pixels missed, 20 extra
    assert silhouette_overlap_error(pred, true) == pytest.approx(0.4, abs=0)
    assert silhouette_overlap_error(true, true) == 0.0
    with pytest.raises(InputError, match="empty"):
        silhouette_overlap_error(true, np.zeros_like(true))
    # aggregate over 2 frames × 2 cameras: per camera, mean of ratios, pooled pixel ratio
    big = np.zeros((30, 40), bool)
    big[:, :10] = True  # 300 pixels, missed entirely by an empty prediction: ratio 1
    s = silhouette_errors(
        [[pred, true], [true, np.zeros_like(big)]],
        [[true, true], [true, big]],
        cameras=["c0", "c1"],
    )
    assert np.array_equal(s.errors, [[0.4, 0.0], [0.0, 1.0]])
    assert np.allclose(s.per_camera, [0.2, 0.5]) and s.overall == pytest.approx(0.35)
    assert s.pooled == pytest.approx((40 + 300) / (100 + 100 + 100 + 300))  # pixel-weighted


def test_reprojected_sphere_silhouettes():
    K = intrinsics(320, 240, 40.0)
    R, t = look_at([0.0, -4.0, 1.0], [0.0, 0.0, 1.0])
    cam = Camera(K, R, t, 320, 240, None, "front")
    s1 = trimesh.creation.icosphere(subdivisions=4, radius=0.5)
    V1 = np.asarray(s1.vertices) + [0, 0, 1.0]
    V2 = np.asarray(s1.vertices) * 1.1 + [0, 0, 1.0]
    true = [[mesh_silhouette(V1, s1.faces, cam)]]  # one frame, one camera
    same = mesh_silhouette_errors([(V1, s1.faces)], true, [cam])
    assert same.cameras == ("front",) and same.overall == 0.0
    bigger = mesh_silhouette_errors([(V2, s1.faces)], true, [cam])
    # A sphere of radius r at distance d images as a disc of radius f·r/√(d² − r²) pixels:
    # the error is the ratio of the disc areas minus 1 (0.214 here). Tolerance: pixelisation
    # of the outlines (~2πR ≈ 350 boundary pixels on R ≈ 55 px discs of ~9600 pixels: a few
    # 1e-3) and the polygonal outline of the icosphere (sagitta 6e-4 of the radius).
    R1, R2 = (r / np.sqrt(16 - r * r) for r in (0.5, 0.55))
    assert bigger.overall == pytest.approx(R2**2 / R1**2 - 1, abs=0.005)


# ---------------------------------------------------------------- surfaces


def test_closest_points_match_trimesh_including_degenerate_triangles():
    n = 4000
    A, B, C, P = (RNG.normal(size=(n, 3)) for _ in range(4))
    B[:20] = A[:20]  # two corners coincide
    C[20:40] = A[20:40] + 2 * (B[20:40] - A[20:40])  # collinear
    Q = closest_points_on_triangles(P, A, B, C)
    Qt = trimesh.triangles.closest_point(np.stack([A, B, C], axis=1), P)
    d, dt = np.linalg.norm(P - Q, axis=1), np.linalg.norm(P - Qt, axis=1)
    assert np.abs(d - dt).max() < 1e-12


def test_point_to_surface_against_brute_force():
    m = trimesh.creation.icosphere(subdivisions=2)
    V = np.asarray(m.vertices) * [1.0, 0.7, 1.3] + RNG.normal(scale=0.02, size=m.vertices.shape)
    F = np.asarray(m.faces)
    P = RNG.normal(scale=0.8, size=(400, 3))
    d, bound = point_to_surface(P, V, F)
    T = np.repeat(V[F][None], len(P), axis=0).reshape(-1, 3, 3)  # every point × triangle
    pp = np.repeat(P, len(F), axis=0)
    exact = np.linalg.norm(pp - closest_points_on_triangles(pp, *T.transpose(1, 0, 2)), axis=1)
    exact = exact.reshape(len(P), -1).min(axis=1)
    assert (d >= exact - 1e-12).all() and (d <= exact + bound + 1e-12).all()  # the guarantee
    assert np.mean(np.abs(d - exact) < 1e-12) > 0.95  # and in practice mostly exact


def test_samples_are_uniform_by_area_and_reproducible():
    V = np.array([[0, 0, 0], [1, 0, 0], [0, 2, 0], [3, 0, 0], [4, 0, 0], [3, 6, 0]], float)
    F = np.array([[0, 1, 2], [3, 4, 5]])  # areas 1 and 3
    p, face = sample_surface(V, F, 20_000, seed=7)
    assert np.array_equal(p, sample_surface(V, F, 20_000, seed=7)[0])
    # Binomial: fraction on face 0 is 0.25 ± 4σ, σ = √(0.25·0.75/20000) = 0.0031.
    assert abs(np.mean(face == 0) - 0.25) < 4 * 0.0031
    d, _ = point_to_surface(p, V, F)
    assert d.max() < 1e-12  # every sample lies on the mesh


def test_concentric_spheres_are_the_radius_difference_apart():
    a = trimesh.creation.icosphere(subdivisions=3, radius=1.0)
    b = trimesh.creation.icosphere(subdivisions=3, radius=1.1)
    r = surface_distance(a.vertices, a.faces, b.vertices, b.faces, n_samples=5000, seed=1)

    # Tessellation bounds: a convex polyhedron inscribed in a sphere of radius r contains
    # the ball of radius ρ (its nearest face plane), so every exact distance between the two
    # surfaces lies in [ρ_b − r_a, r_b − ρ_a] = [0.0950, 0.1045] m here (642-vertex spheres).
    def rho(m):
        return np.abs(np.einsum("ij,ij->i", m.face_normals, m.vertices[m.faces[:, 0]])).min()

    lo, hi = rho(b) - 1.0, 1.1 - rho(a)
    for s in (r.a_to_b, r.b_to_a):
        # guaranteed: lo ≤ each ≤ hi + bound; checked tighter (≤ hi): the results are exact
        assert lo - 1e-12 <= s.mean and s.max <= hi + 1e-12 and s.p95 <= s.max and s.n == 5000
        assert s.rms >= s.mean
    # The mean is the radius difference minus the average gap between the inner polyhedron
    # and its sphere (faces sag ≤ 1 − ρ_a/r_a = 0.005 inward): 0.1 within 0.002.
    assert abs(r.mean - 0.1) < 0.002 and r.hausdorff <= hi + 1e-12
    same = surface_distance(a.vertices, a.faces, a.vertices, a.faces, n_samples=1000)
    assert same.hausdorff < 1e-12
    with pytest.raises(InputError, match="F_b"):
        surface_distance(a.vertices, a.faces, b.vertices, b.faces + 10_000)


# ---------------------------------------------------------------- tables and plots


def _results():
    true = _joints(10)
    pred = true + RNG.normal(scale=0.02, size=true.shape)
    pred[3] = np.nan
    masks_t = RNG.random((4, 2, 12, 16)) > 0.4
    masks_p = masks_t ^ (RNG.random((4, 2, 12, 16)) > 0.9)
    return (
        joint_errors(pred, true),
        correspondence_error(pred, true),
        bone_length_stats(pred, EVAL_PARENTS),
        silhouette_errors(masks_p, masks_t),
    )


def test_tables_and_csv(tmp_path):
    je, ce, bl, se = _results()
    text = table(je)
    assert "right_ankle" in text and "1 failed" in text and f"{je.overall.mean:.1f}" in text
    assert "%" in table(se) and "pelvis-thorax" in table(bl) and "vertices" in table(ce)
    t = format_table(["name", "x"], [["a", 1.0], ["bb", float("nan")]], digits=2)
    assert t.splitlines() == ["name     x", "----  ----", "a     1.00", "bb     n/a"]
    with open(write_csv(tmp_path / "j.csv", je)) as f:
        rows = list(csv.reader(f))
    assert rows[0] == ["joint", "mean_mm", "median_mm", "std_mm", "max_mm"]
    assert float(rows[-1][1]) == je.overall.mean  # unrounded
    with open(write_csv(tmp_path / "f.csv", je, per_frame=True)) as f:
        frames = list(csv.reader(f))
    assert len(frames) == 11 and frames[4][1] == "failed" and frames[4][2:] == [""] * 16
    assert float(frames[1][-1]) == pytest.approx(je.per_frame[0], rel=1e-15)
    for r in (ce, bl, se):
        write_csv(tmp_path / "x.csv", r, per_frame=True)
    assert "nan" not in (tmp_path / "x.csv").read_text().lower()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["f.csv", "j.csv", "x.csv"]
    with pytest.raises(InputError, match="expected one of"):
        table(Stats(1.0, 1.0, 0.0, 1.0))


def test_plots_write_png_files(tmp_path):
    je, ce, bl, se = _results()
    written = [
        plot_frame_errors(je, tmp_path / "frames_j.png"),
        plot_frame_errors(ce, tmp_path / "frames_c.png"),
        plot_frame_errors(se, tmp_path / "frames_s.png"),
        plot_joint_errors(je, tmp_path / "joints.png"),
        plot_bone_lengths(bl, tmp_path / "bones.png", reference=bl),
        plot_silhouette_errors(se, tmp_path / "cams.png"),
    ]
    for path in written:
        data = path.read_bytes()
        assert data[:8] == b"\x89PNG\r\n\x1a\n" and len(data) > 5000
    with pytest.raises(InputError, match=r"\.png"):
        plot_joint_errors(je, tmp_path / "joints.pdf")
    with pytest.raises(InputError, match="expected JointErrors"):
        plot_joint_errors(bl, tmp_path / "x.png")
