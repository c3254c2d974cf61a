"""Property-based fuzzing of every loader (see ``tests/fuzzing.py``): mutated files either
read into well-formed results or raise meshmocap's one-line errors, never anything else.

A few hundred examples here (seeded, reproducible); ``benchmarks/bench_fuzz.py`` runs
10,000 and more.
"""

from __future__ import annotations

from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings

from fuzzing import Loader, loaders, manifold_loader, run_one

#: Examples per loader in the test suite.
EXAMPLES = 15

NAMES = [
    "mesh_ply",
    "mesh_obj",
    "mesh_off",
    "mesh_stl",
    "mesh_glb",
    "mesh_gltf",
    "points_npy",
    "points_ply",
    "points_xyz",
    "points_pcd",
    "archive_tar_gz",
    "bvh",
    "asf",
    "amc",
    "cameras_json",
    "cameras_yaml",
    "silhouette_png",
    "template_npz",
    "track_frame_npz",
    "track_frame_bytes",
    "track_json",
    "capture_hull_npz",
    "capture_truth_npz",
    "capture_json",
    "manifold_npz",
]


@pytest.fixture(scope="module")
def fuzz(tmp_path_factory) -> tuple[dict[str, Loader], Path]:
    from meshmocap.body.template import load_template
    from meshmocap.trackers.cage.manifold import fit_pose_manifold
    from meshmocap.trackers.cage.oqr import build_oqr
    from meshmocap.trackers.cage.training_poses import load_pose_sources

    work = tmp_path_factory.mktemp("fuzz")
    found = {ld.name: ld for ld in loaders(work)}
    t = load_template("neutral_5k")
    oqr = build_oqr(t)
    poses = load_pose_sources(["walk"], t, oqr=oqr, duration=0.4, fps=15.0)
    pm = fit_pose_manifold(poses, t, oqr=oqr, n_samples=6, max_iter=20)
    found["manifold_npz"] = manifold_loader(pm.save(work / "manifold.npz"))
    return found, work


def test_every_loader_is_fuzzed(fuzz):
    assert sorted(fuzz[0]) == sorted(NAMES)


@pytest.mark.parametrize("name", NAMES)
def test_mutated_files_give_results_or_meshmocap_errors(fuzz, name):
    loader, work = fuzz[0][name], fuzz[1]
    outcomes = []

    @settings(
        max_examples=EXAMPLES,
        deadline=None,
        database=None,
        derandomize=True,
        suppress_health_check=list(HealthCheck),
    )
    @given(data=loader.strategy)
    def prop(data: bytes) -> None:
        outcomes.append(run_one(loader, data, work))

    prop()
    assert len(outcomes) >= EXAMPLES // 2  # hypothesis ran (it may dedupe a few)
