"""Shared fixtures: the real third-party data in ../shared/data (skipped where absent, and
counted in one line at the end of the run: :func:`pytest_terminal_summary`), a posed body
made in code, and the synthetic captures the tests track.

The captures are one family, made once per session (per worker under pytest-xdist, ``-n``)
and shared by every file (:func:`synth_capture`): :func:`walk` (the neutral_5k walk at
60 fps, 1 cm hulls), :func:`small_walk` (at 30 fps, 2 cm hulls: the cheapest capture a
command can track),
:func:`walk_full` (the 12k-vertex ``neutral`` template's walk), :func:`jump` (jumping jacks)
and :func:`mesh_folder` (a walk's true surfaces as PLY files, a clean 4D capture). They are
read-only: a test that changes a capture copies it first.

The automatic first-pose search is the slow step of every track that does not start from
the truth (seconds per capture). Its answer depends only on the observations, the template
and the options, so within a test run (all its xdist workers) a search on the same inputs
is answered once (:func:`_first_pose_searched_once`), as the capture cache answers a
user's second track of a capture. The search itself is tested in ``tests/estimate/pose/``.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import os
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[1]
#: The data set's folder: ../shared/data beside the project (``MESHMOCAP_SHARED_DATA``
#: names another).
SHARED_DATA = Path(os.environ.get("MESHMOCAP_SHARED_DATA") or ROOT.parent / "shared" / "data")


#: Where a reader of a fresh clone learns what the data set is and where it comes from.
DATA_DOC = "docs/reference.rst, 'Test data'"


@pytest.fixture(scope="session")
def shared_data() -> Path:
    """Path to ../shared/data; skips the test when that folder is absent."""
    if not SHARED_DATA.is_dir():
        pytest.skip(f"real data not available: {SHARED_DATA} is absent")
    return SHARED_DATA


def pytest_terminal_summary(terminalreporter, exitstatus, config) -> None:
    """One line saying how many tests skipped because the third-party data set they read is
    absent, and where it comes from (each skip's own reason names the file it needed)."""
    skipped = terminalreporter.stats.get("skipped", [])
    data = [r for r in skipped if str(SHARED_DATA) in _skip_reason(r)]
    if data:
        terminalreporter.write_line(
            f"meshmocap: {len(data)} tests skipped: they read real third-party data (CMU "
            f"motion capture, the MIT crane sequence) from {SHARED_DATA}, which is absent "
            f"here and not shipped with the project (licences); see {DATA_DOC}",
            yellow=True,
        )


def _skip_reason(report) -> str:
    """The reason of a skipped test's report (``(file, line, reason)``), or ''."""
    longrepr = getattr(report, "longrepr", None)
    return str(longrepr[2]) if isinstance(longrepr, tuple) and len(longrepr) == 3 else ""


@pytest.fixture(scope="session")
def cmu(shared_data: Path) -> Path:
    """Path to the CMU motion-capture clips in ../shared/data/mocap/cmu."""
    path = shared_data / "mocap" / "cmu"
    if not path.is_dir():
        pytest.skip(f"CMU clips not available: {path} is absent")
    return path


@pytest.fixture(autouse=True, scope="session")
def _manifold_cache(tmp_path_factory):
    """Default pose manifolds learned by tests are cached in a session folder, not in the
    user's cache (``MESHMOCAP_CACHE``)."""
    mp = pytest.MonkeyPatch()
    mp.setenv("MESHMOCAP_CACHE", str(tmp_path_factory.mktemp("manifold_cache")))
    yield
    mp.undo()


_COMPILING = pytest.StashKey[object]()
_THREADS = pytest.StashKey[object]()
#: The threading variables the BLAS and OpenMP libraries read when they load.
THREAD_VARS = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "BLIS_NUM_THREADS")


def pytest_configure(config) -> None:
    """One BLAS and OpenMP thread in every test process (``MESHMOCAP_THREADS`` sets
    another count) and in the processes the tests start, as meshmocap's commands and
    tracking run (:mod:`meshmocap._threads`): a test that calls numpy, scipy or pykdtree
    outside them otherwise runs a pool thread per core, which spins beside the other
    pytest-xdist worker on a small machine (a two-frame shape fit's test took 17 CPU s so,
    6 on one thread). The pools loaded already are capped, those loaded later read the
    variables (set where the caller has not)."""
    from threadpoolctl import threadpool_limits

    from meshmocap._threads import thread_count

    n = thread_count()
    for var in THREAD_VARS:
        os.environ.setdefault(var, str(n))
    config.stash[_THREADS] = threadpool_limits(n)


def pytest_sessionstart(session) -> None:
    """On a fresh clone numba compiles each kernel at its first call (about a minute of CPU
    in all, ``benchmarks/bench_compile.py``); here a background process compiles them all
    from the start of the run, beside the tests, as ``meshmocap track`` does
    (:func:`~meshmocap.apps.kernels.start_compiling`; nothing to do once they are
    cached). A test that meets a kernel first compiles it itself, as before. Under
    pytest-xdist (``-n``) only the controlling process starts it: one compilation for the
    run, not one per worker."""
    if hasattr(session.config, "workerinput"):
        return
    from meshmocap.apps.kernels import start_compiling

    session.config.stash[_COMPILING] = start_compiling()


def pytest_sessionfinish(session) -> None:
    """End the background compilation if it still runs (:func:`pytest_sessionstart`)."""
    proc = session.config.stash.get(_COMPILING, None)
    if proc is not None:
        from meshmocap.apps.kernels import stop_compiling

        stop_compiling(proc)


@pytest.fixture(scope="session")
def walker():
    """neutral_5k walking (procedural walk, frame 10 at 30 fps) with its arms in a T-pose,
    turned 2.3 rad about Z and moved by (0.7, −0.4, 0) m: ``(template, R (J, 3, 3), root
    (3,), the posed template)``."""
    from meshmocap.body.procedural import procedural_motion
    from meshmocap.body.template import load_template
    from meshmocap.estimate.pose.library import seed_pose
    from meshmocap.geometry.rotations import so3_exp

    turn, shift = 2.3, np.array([0.7, -0.4, 0.0])
    t = load_template("neutral_5k")
    m = procedural_motion("walk", t, duration=1.0, fps=30.0)
    R, root = m.rotations[10].copy(), m.root_positions[10].copy()
    arms = [t.skeleton.index(n) for n in ("LeftArm", "RightArm", "LeftForeArm", "RightForeArm")]
    R[arms] = seed_pose(t, "t_pose")[arms]
    R[0] = so3_exp(np.array([0.0, 0.0, turn])) @ R[0]
    root = so3_exp(np.array([0.0, 0.0, turn])) @ root + shift
    return t, R, root, t.pose(R, root)


def _fingerprint(h, value) -> bool:
    """Feed ``value`` (an argument of the first-pose search) into the hash ``h``; False
    when it is of a kind not known to be a pure value (the call is then not shared)."""
    from meshmocap.body.template import Template
    from meshmocap.estimate.performer.capture_cache import template_key
    from meshmocap.geometry.distance_field import DistanceGrid, LazyDistanceGrid

    if value is None or isinstance(value, (bool, int, float, str)):
        h.update(repr(value).encode())
    elif isinstance(value, np.ndarray):
        h.update(f"{value.dtype}{value.shape}".encode())
        h.update(np.ascontiguousarray(value).tobytes())
    elif isinstance(value, (tuple, list)):
        h.update(f"{type(value).__name__}{len(value)}".encode())
        return all(_fingerprint(h, v) for v in value)
    elif isinstance(value, Template):
        h.update(template_key(value).encode())
    elif isinstance(value, LazyDistanceGrid):  # its values are filled in as looked up
        h.update(b"lazy")
        return all(_fingerprint(h, getattr(value, a)) for a in ("_occ", "_pad", "_stride", "_h"))
    elif type(value) is DistanceGrid:
        return all(_fingerprint(h, getattr(value, a)) for a in ("values", "origin", "spacing"))
    elif (
        dataclasses.is_dataclass(value)
        and dataclasses.fields(value)
        and value.__dataclass_params__.frozen
    ):
        h.update(type(value).__qualname__.encode())
        fields = [f.name for f in dataclasses.fields(value) if f.init]  # not caches
        return all(_fingerprint(h, getattr(value, name)) for name in fields)
    else:
        return False
    return True


def _run_folder(tmp_path_factory) -> Path:
    """A folder shared by every process of this test run: the session's base temporary
    folder, or under pytest-xdist (``-n``) the one its workers' folders are made in."""
    base = tmp_path_factory.getbasetemp()
    return base.parent if os.environ.get("PYTEST_XDIST_WORKER") else base


@pytest.fixture(autouse=True, scope="session")
def _first_pose_searched_once(tmp_path_factory):
    """Within the test run, :func:`~meshmocap.estimate.pose.first_pose.initial_pose` on the
    same template, observations and options runs once; later calls get a copy of its
    answer (the module docstring says why). The answers are kept in a folder of the run
    (:func:`_run_folder`), so that pytest-xdist's workers share them too (their captures are
    made alike, bit for bit): a worker that needs an answer another is computing waits for
    it (a lock per call). A call with an argument that is not a plain value (a pose library
    object, a callable) is always made."""
    import fcntl
    import pickle

    from meshmocap.estimate.pose import first_pose

    search = first_pose.initial_pose
    folder = _run_folder(tmp_path_factory) / "first_poses"
    folder.mkdir(exist_ok=True)

    def initial_pose(*args, **kwargs):
        h = hashlib.sha256()
        if not (_fingerprint(h, args) and _fingerprint(h, sorted(kwargs.items()))):
            return search(*args, **kwargs)
        answer = folder / f"{h.hexdigest()}.pkl"
        with open(answer.with_suffix(".lock"), "w") as lock:
            fcntl.flock(lock, fcntl.LOCK_EX)  # released when the file closes
            if not answer.is_file():
                data = pickle.dumps(search(*args, **kwargs))
                part = answer.with_suffix(f".{os.getpid()}.part")
                part.write_bytes(data)
                part.replace(answer)
            return pickle.loads(answer.read_bytes())

    initial_pose.__wrapped__ = search
    mp = pytest.MonkeyPatch()
    mp.setattr(first_pose, "initial_pose", initial_pose)
    yield folder
    mp.undo()


@pytest.fixture(scope="session")
def synth_capture(tmp_path_factory):
    """``synth_capture(motion="walk", *, template="neutral_5k", stop=4, **spec)``: the
    synthetic capture of that :class:`~meshmocap.studio.synth.SynthSpec`, written once per
    session and shared (read-only: copy it before changing a file)."""
    from meshmocap.studio.synth import SynthSpec, synthesize

    made: dict[str, object] = {}

    def make(motion: str = "walk", *, template: str = "neutral_5k", stop: int = 4, **spec):
        s = SynthSpec(motion=motion, template=template, stop=stop, **spec)
        key = json.dumps(s.as_dict(), sort_keys=True)
        if key not in made:
            out = tmp_path_factory.mktemp(f"{motion}_{template}") / "cap"
            made[key] = synthesize(out, s, show_progress=False)
        return made[key]

    return make


#: Frames of the shared captures: enough for a tracker to move and resume.
WALK_FRAMES = 8


@pytest.fixture(scope="session")
def walk(synth_capture):
    """The neutral_5k walk, :data:`WALK_FRAMES` frames at 60 fps, 4 cameras, 1 cm hulls
    (:class:`~meshmocap.io.capture.Capture`, with truth)."""
    return synth_capture("walk", stop=WALK_FRAMES)


@pytest.fixture(scope="session")
def small_walk(synth_capture):
    """The neutral_5k walk at 30 fps with 2 cm hulls, 5 frames: the cheapest capture a
    command can track (every other frame of :func:`walk`'s motion)."""
    return synth_capture("walk", stop=5, fps=30.0, voxel_size=0.02)


@pytest.fixture(scope="session")
def walk_full(synth_capture):
    """The walk of the full ``neutral`` template (12k vertices), 5 frames at 60 fps."""
    return synth_capture("walk", template="neutral", stop=5)


@pytest.fixture(scope="session")
def jump(synth_capture):
    """neutral_5k jumping jacks, 5 frames at 30 fps, 2 cm hulls."""
    return synth_capture("jumping_jacks", stop=5, fps=30.0, voxel_size=0.02)


@pytest.fixture(scope="session")
def mesh_folder(small_walk, tmp_path_factory) -> Path:
    """:func:`small_walk`'s true surfaces as ``00000.ply`` … (metres, Z up, neutral_5k's
    connectivity): a clean 4D capture with no cameras."""
    from meshmocap.io.meshes import write_mesh

    out = tmp_path_factory.mktemp("mesh_folder") / "meshes"
    out.mkdir()
    for f in small_walk:
        write_mesh(out / f"{f.index:05d}.ply", f.truth.vertices, small_walk.truth_faces)
    return out
