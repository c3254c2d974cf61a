"""The kernels compiled ahead: the list names every kernel with the argument types tracking
calls it with, a background process compiles what numba has not cached, and a cached
kernel is not compiled again."""

from __future__ import annotations

import functools
import importlib
import os
import subprocess
import sys

import pytest
from numba.core import sigutils

from meshmocap.apps.kernels import KERNELS, SHARED, compile_kernels, kernels_of, uncached_kernels

MESH = "meshmocap.geometry._mesh_kernels"


def _types(sig: str) -> tuple:
    return tuple(sigutils.normalize_signature(f"({sig},)")[0])


def test_every_listed_kernel_exists_and_its_types_parse():
    for name, kernels in KERNELS.items():
        module = importlib.import_module(name)
        for function, signatures in kernels.items():
            assert hasattr(getattr(module, function), "compile"), function  # a numba kernel
            for sig in signatures:
                assert len(_types(sig)) >= 2
    patch, cage = "meshmocap.trackers.patch.kernels", "meshmocap.trackers.cage.field"
    assert kernels_of("patch_svc") == (*SHARED, "meshmocap.models._softmax", patch)
    assert kernels_of("articulated_icp") == SHARED
    assert kernels_of("cage_quads")[-1] == cage and patch not in kernels_of("cage")
    assert set(KERNELS) == {*kernels_of("patch"), *kernels_of("cage")}


def _python(code: str, cache) -> str:
    env = {**os.environ, "NUMBA_CACHE_DIR": str(cache)}
    p = subprocess.run(
        [sys.executable, "-c", code], env=env, capture_output=True, text=True, timeout=600
    )
    assert p.returncode == 0, p.stderr[-2000:]
    return p.stdout.strip()


def test_a_compiled_kernel_is_cached_for_the_next_process(tmp_path):
    """A fresh cache (a fresh install) lacks the kernel; ``python -m meshmocap.apps.kernels``
    compiles it; the next process finds it cached, and a call of the kernel with the
    library's argument types loads it from there instead of compiling it."""
    check = (
        f"from meshmocap.apps.kernels import uncached_kernels; print(uncached_kernels([{MESH!r}]))"
    )
    kernels = [
        "normals_at_kernel",
        "fill_kernel",
        "boundary_distance_kernel",
        "boundary_side_kernel",
        "occupied_kernel",
        "in_image_kernel",
        "farther_kernel",
        "point_tree_kernel",
        "agreeing_kernel",
    ]
    assert _python(check, tmp_path) == str([f"{MESH}:{k}" for k in kernels])
    _python(f"from meshmocap.apps.kernels import main; main(['--quiet', {MESH!r}])", tmp_path)
    assert _python(check, tmp_path) == "[]"
    call = (
        "import numpy as np; from meshmocap.geometry._mesh_kernels import normals_at_kernel as k; "
        "V = np.eye(3); F = np.array([[0, 1, 2]]); "
        "print(k(V, F, np.arange(3), 3).shape, sum(k.stats.cache_hits.values()), "
        "sum(k.stats.cache_misses.values()))"
    )
    assert _python(call, tmp_path) == "(3, 3) 1 0"  # loaded by the call: one hit, no miss


def test_a_kernel_another_process_is_compiling_is_left_for_the_end(monkeypatch):
    """The compiler does not wait for a kernel a worker is compiling: it compiles the next
    ones meanwhile and loads that one last."""
    import meshmocap._numba

    pose = "meshmocap.estimate.pose._kernels"
    busy = "nearest_d2_kernel"
    monkeypatch.setattr(
        meshmocap._numba, "compiling_elsewhere", lambda k: k.py_func.__name__ == busy
    )
    seconds = compile_kernels([pose])
    assert list(seconds) == [pose, f"{pose}:nearest_kernel", f"{pose}:{busy}"]


def test_the_background_compiler_held_back_compiles_the_named_modules_first(tmp_path):
    """While :func:`compiling_only` names the first pose's kernels, the background child
    compiles those and holds the classifier's back (the body's processes have the cores);
    when the block ends it compiles them too."""
    pose, softmax = "meshmocap.estimate.pose._kernels", "meshmocap.models._softmax"
    code = (
        "import time; from meshmocap.apps import kernels as k\n"
        f"pose, softmax = {pose!r}, {softmax!r}\n"
        "p = k.start_compiling([pose, softmax])\n"
        "with k.compiling_only((pose,)):\n"
        "    end = time.monotonic() + 300\n"
        "    while k.uncached_kernels([pose]) and time.monotonic() < end:\n"
        "        time.sleep(0.1)\n"
        "    time.sleep(2.0)  # a child not held would compile the classifier's meanwhile\n"
        "    held = (k.uncached_kernels([pose]), len(k.uncached_kernels([softmax])))\n"
        "p.wait()\n"
        "print(held, k.uncached_kernels([pose, softmax]), p.returncode)"
    )
    assert _python(code, tmp_path) == "([], 2) [] 0"


@pytest.mark.slow
def test_tracking_compiles_only_the_listed_signatures(synth_capture, tmp_path):
    """Each tracker follows a short walk with the checks on: every signature its kernels
    were compiled or loaded with in this process is one :data:`KERNELS` lists (a kernel
    called with other types would compile at first use, in the foreground)."""
    from meshmocap.body.procedural import walk
    from meshmocap.body.template import load_template
    from meshmocap.trackers.cage.tracker import CageOptions, CageTracker, learn_manifold
    from meshmocap.trackers.driver import track_sequence
    from meshmocap.trackers.options import TrackOptions
    from meshmocap.trackers.registry import make_tracker

    t = load_template("neutral_5k")
    cap = synth_capture("walk", stop=3)
    gp = learn_manifold(t, [walk(t, duration=1.0, fps=30.0)], n_components=2, n_samples=30)
    opts = TrackOptions(show_progress=False, init="truth", light=None)
    run = functools.partial(track_sequence, options=opts)
    run(make_tracker("patch", template=t), t, cap, tmp_path / "patch")
    run(make_tracker("articulated_icp", template=t), t, cap, tmp_path / "icp")
    run(CageTracker(gp, CageOptions(local_iters=1, alternations=1)), t, cap, tmp_path / "cage")
    assert not uncached_kernels()  # every kernel met and cached
    for name, kernels in KERNELS.items():
        module = importlib.import_module(name)
        for function, signatures in kernels.items():
            listed = {_types(s) for s in signatures}
            used = set(getattr(module, function).signatures)
            # a kernel called only from another compiled kernel records no signature of its
            # own when its caller is loaded from the cache: none used is then no finding
            assert used <= listed, (function, used - listed)
