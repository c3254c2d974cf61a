"""Pose manifolds (saved with their template) and the cage methods of the tracker registry."""

from __future__ import annotations

import logging
import re
from dataclasses import replace

import numpy as np
import pytest

from meshmocap.body.template import load_template
from meshmocap.errors import FormatError, InputError
from meshmocap.models.gplvm import GPLVM
from meshmocap.trackers.cage import manifold as manifold_module
from meshmocap.trackers.cage.manifold import (
    LatentStart,
    PoseManifold,
    fit_pose_manifold,
    learn_pose_manifold,
    resolve_manifold,
    template_digest,
)
from meshmocap.trackers.cage.oqr import build_oqr
from meshmocap.trackers.cage.tracker import CageTracker
from meshmocap.trackers.cage.training_poses import load_pose_sources
from meshmocap.trackers.registry import (
    CAGE_ABLATIONS,
    MANIFOLD_METHODS,
    METHODS,
    make_tracker,
)


@pytest.fixture(scope="module")
def tiny():
    """A 2-D manifold of 20 walk/jog poses of neutral_5k (fits in well under a second)."""
    t = load_template("neutral_5k")
    oqr = build_oqr(t)
    poses = load_pose_sources(["walk", "jog"], t, oqr=oqr, duration=1.0, fps=15.0)
    return t, oqr, fit_pose_manifold(poses, t, oqr=oqr, n_samples=20, max_iter=200)


def test_fit_records_what_it_was_built_for(tiny):
    t, oqr, pm = tiny
    assert (pm.n_samples, pm.n_components, pm.n_poses) == (20, 2, 32)
    assert pm.template_name == "neutral_5k" and pm.template_digest == template_digest(t)
    assert template_digest(load_template("neutral_5k")) == pm.template_digest  # reloaded
    assert template_digest(load_template("neutral")) != pm.template_digest
    np.testing.assert_array_equal(pm.rest_cage, oqr.rest_vertices)
    assert set(pm.groups) == {"walk", "jog"} and pm.fit_seconds > 0
    pm.check(t, oqr)  # no error


def test_save_load_round_trip_and_plain_gplvm_reader(tiny, tmp_path):
    _, _, pm = tiny
    path = pm.save(tmp_path / "m.npz")
    back = PoseManifold.load(path)
    X = np.random.default_rng(3).normal(size=(5, 2))
    np.testing.assert_array_equal(back.gp.predict(X), pm.gp.predict(X))  # bit for bit
    for key in ("template_name", "template_digest", "sources", "n_poses", "fit_seconds"):
        assert getattr(back, key) == getattr(pm, key)
    np.testing.assert_array_equal(back.groups, pm.groups)
    np.testing.assert_array_equal(GPLVM.load(path).predict(X), pm.gp.predict(X))
    pm.gp.save(tmp_path / "bare.npz")
    with pytest.raises(FormatError, match="without the template it was built for"):
        PoseManifold.load(tmp_path / "bare.npz")
    with pytest.raises(InputError, match=r"must end in \.npz"):
        pm.save(tmp_path / "m.json")


def test_check_refuses_another_template_or_rigging_in_one_line(tiny):
    t, oqr, pm = tiny
    heavy = load_template("heavy_male")
    with pytest.raises(InputError, match="built for template 'neutral_5k'") as info:
        pm.check(heavy, source="m.npz")
    msg = str(info.value)
    assert msg.startswith("m.npz: manifold") and "'heavy_male'" in msg and "\n" not in msg
    assert resolve_manifold(pm, t, oqr) is pm and resolve_manifold(pm.gp, None) is pm.gp
    with pytest.raises(InputError, match="not the tracking template 'heavy_male'"):
        resolve_manifold(pm, heavy)
    moved = replace(pm, rest_cage=pm.rest_cage + 0.01)
    with pytest.raises(InputError, match=r"another quad rigging .* 0\.01 m"):
        moved.check(t, oqr)


def test_registry_cage_methods_and_their_ablations(tiny, tmp_path):
    t, _, pm = tiny
    every = ("distance", "variance", "coverage", "silhouette", "anchor", "articulation")
    fixed = {
        "cage": {},
        "cage_quads": {"space": "quads"},
        "cage_noreg": {"terms": tuple(x for x in every if x != "variance")},
        "cage_nolocal": {"local_iters": 0},
        "cage_nosil": {"terms": tuple(x for x in every if x != "silhouette")},
        "cage_nowiden": {"off_manifold": 0.0},
        "cage_green": {"surface": "green", "joints": "green"},
        "cage_paper": {
            "terms": ("distance", "variance"),
            "surface": "green",
            "joints": "green",
            "body": "template",
            "off_manifold": 0.0,
        },
    }
    assert set(MANIFOLD_METHODS) == set(fixed)
    assert set(MANIFOLD_METHODS) < set(METHODS)
    assert set(CAGE_ABLATIONS) < set(MANIFOLD_METHODS)
    path = pm.save(tmp_path / "m.npz")
    for method in MANIFOLD_METHODS:
        tr = make_tracker(method, manifold=pm.gp, n_sample=100)
        assert isinstance(tr, CageTracker) and tr.gp is pm.gp and tr.opts.n_sample == 100
        for key, value in fixed[method].items():
            assert getattr(tr.opts, key) == value
    # a saved manifold and the tracking template: checked, and the tracker set up for it
    tr = make_tracker("cage", manifold=str(path), template=t)
    assert tr.template is t and tr.gp.X_.shape == (20, 2)


def test_registry_errors(tiny, tmp_path):
    t, _, pm = tiny
    path = pm.save(tmp_path / "m.npz")
    heavy = load_template("heavy_male")
    with pytest.raises(InputError, match=re.escape(f"{path}: manifold was built for")):
        make_tracker("cage", manifold=path, template=heavy)
    with pytest.raises(InputError, match="only used by"):
        make_tracker("patch", manifold=path)
    with pytest.raises(InputError, match="template= is needed"):
        make_tracker("cage", manifold=path)
    with pytest.raises(InputError, match="must be a fitted GPLVM"):
        make_tracker("cage", manifold=GPLVM(2))
    with pytest.raises(InputError, match="must be a GPLVM, PoseManifold, path or None"):
        resolve_manifold(3, t)
    with pytest.raises(InputError, match="unexpected keyword"):
        make_tracker("cage", manifold=pm.gp, n_patches=3)


def test_a_latent_start_serves_only_the_poses_it_was_fitted_on(tiny, tmp_path):
    t, oqr, pm = tiny
    gp = pm.gp
    path = tmp_path / "start.npz"
    np.savez(path, X=gp.X_, hyper=[gp.alpha_, gp.gamma_, gp.beta_], trials=pm.trials)
    start = LatentStart.load(path)
    poses = load_pose_sources(["walk", "jog"], t, oqr=oqr, duration=1.0, fps=15.0)
    train = poses.subsample(20)
    assert start.fits(train, 2) and not start.fits(train, 3)
    assert not start.fits(poses.subsample(19), 2)
    # started there, the fit begins at the earlier fit's likelihood
    warm = fit_pose_manifold(poses, t, oqr=oqr, n_samples=20, max_iter=5, start=start)
    assert warm.gp.log_likelihood_history_[0] == pytest.approx(gp.log_likelihood_, rel=1e-3)
    np.savez(path, X=gp.X_)
    with pytest.raises(FormatError, match="not a manifold start"):
        LatentStart.load(path)


@pytest.mark.slow
def test_no_manifold_learns_one_from_the_pose_library_and_caches_it(
    tiny, monkeypatch, caplog, tmp_path
):
    t, _, _ = tiny
    monkeypatch.setattr(manifold_module, "ON_THE_FLY_MAX_ITER", 20)  # a quick fit suffices
    monkeypatch.setenv(manifold_module.CACHE_ENV, str(tmp_path / "cache"))
    with caplog.at_level(logging.INFO, logger="meshmocap.trackers.cage.manifold"):
        tr = make_tracker("cage_nolocal", template=t)
    assert tr.gp.X_.shape == (400, 5) and tr.gp.n_iter_ <= 20
    # started from the bundled fit (the PCA start's log-likelihood is about -5e5)
    start = manifold_module.default_start()
    assert start.X.shape == (400, 5)
    assert tr.gp.log_likelihood_history_[0] > -1e5
    assert "learned a 5-D one from library:400 on 'neutral_5k'" in caplog.text
    path = manifold_module.default_manifold_path(t)
    assert path.parent == tmp_path / "cache" and path.is_file()
    assert set(PoseManifold.load(path).groups) >= {"walk", "run", "salsa", "modern dance"}
    caplog.clear()
    with caplog.at_level(logging.INFO, logger="meshmocap.trackers.cage.manifold"):
        again = make_tracker("cage_nolocal", template=t)  # read from the cache
    assert "learned" not in caplog.text
    np.testing.assert_array_equal(again.gp.X_, tr.gp.X_)
    path.write_bytes(b"not a manifold")  # a broken cache file is learned again
    with caplog.at_level(logging.INFO, logger="meshmocap.trackers.cage.manifold"):
        make_tracker("cage_nolocal", template=t)
    assert "unusable" in caplog.text and "learned" in caplog.text
    monkeypatch.setattr(manifold_module, "ON_THE_FLY_MAX_ITER", 21)  # another setting
    assert manifold_module.default_manifold_path(t) != path
    monkeypatch.setenv(manifold_module.CACHE_ENV, "off")
    assert manifold_module.default_manifold_path(t) is None
    with pytest.raises(InputError, match="none given"):
        learn_pose_manifold(t, [])
