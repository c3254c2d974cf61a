"""A small patch model in a perturbed pose with random correspondences, shared by the
tests of the normal equations, of the energy's terms and of the registry's coefficients."""

import numpy as np
import pytest

from meshmocap.body.template import load_template
from meshmocap.geometry.rotations import so3_exp
from meshmocap.trackers.patch.model import build_patch_model
from meshmocap.trackers.patch.solver import rigidity_moments


@pytest.fixture(scope="module")
def patch_problem():
    """``(model, moments, R, c, X, (patch, v, y, w))``: 60 patches of ``neutral_5k`` turned
    by 0.2 rad and moved by 2 cm at random, joints 2 cm off their rest, and 300 observed
    points 3 cm from a random vertex of their patch with weights in [0.2, 1]."""
    rng = np.random.default_rng(0)
    t = load_template("neutral_5k")
    m = build_patch_model(t, n_patches=60, seed=1)
    R = so3_exp(rng.normal(scale=0.2, size=(m.P, 3)))
    c = m.centres0 + rng.normal(scale=0.02, size=(m.P, 3))
    X = t.eval_skeleton.rest_positions + rng.normal(scale=0.02, size=(15, 3))
    n_obs = 300
    patch = rng.integers(0, m.P, n_obs)
    v = np.array([rng.choice(np.flatnonzero(m.labels == k)) for k in patch])
    y = m.V0[v] + rng.normal(scale=0.03, size=(n_obs, 3))
    w = rng.uniform(0.2, 1.0, n_obs)
    return m, rigidity_moments(m), R, c, X, (patch, v, y, w)
