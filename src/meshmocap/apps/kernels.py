"""The numba kernels, compiled ahead in a background process while a command does work it
must do anyway, so that a fresh install's first run does not wait for them.

numba compiles a kernel at its first call and caches the machine code (``cache=True``):
beside the source in ``__pycache__``, or, where the installed package is read-only, in the
user's cache folder (``~/.cache/numba``); ``NUMBA_CACHE_DIR`` overrides both. The cache is
keyed by the source file's time stamp, so a fresh install or clone starts without it, and
the first command that tracks compiles every kernel it meets (about a minute in all,
:data:`KERNELS`; ``benchmarks/bench_compile.py`` measures each). :func:`start_compiling`
compiles them in a child process instead, each with the argument types the library calls
it with, in the order a command meets them. Each kernel is compiled by one process only
(a lock file per kernel, ``meshmocap._numba``): a command or worker that reaches a
kernel the child is compiling waits for it and loads it from the cache, and one it
reaches first it compiles itself, the child then loading it. With a warm cache the child
only loads them (about a second of its own CPU). While the performer's body is estimated
and the first pose found, the child compiles only the kernels those meet
(:func:`compiling_only`), the trackers' after them: the body's processes have the cores.

``python -m meshmocap.apps.kernels`` compiles them in the foreground and prints the CPU
seconds each took.
"""

from __future__ import annotations

import atexit
import contextlib
import importlib
import os
import select
import subprocess
import sys
import time
from collections.abc import Callable, Iterator

#: Every kernel and the argument types it is called with (numba's signature notation:
#: ``float64[:, ::1]`` a C-contiguous 2D array, ``int64[:]`` any 1D layout; read-only
#: arrays spelled out), by module, in the order the demo first meets them.
#: ``tests/apps/test_kernels.py`` checks that tracking compiles nothing else.
KERNELS: dict[str, dict[str, tuple[str, ...]]] = {
    "meshmocap.io._kernels": {
        "mesh_extent_kernel": tuple(
            f"{dK}[:, ::1], int64[::1], int64[::1]" for dK in ("int16", "int32")
        ),
        "mesh_vertices_kernel": tuple(
            f"{dK}[:, ::1], float32[::1], float32[::1], float32[::1], int64[::1], float64[:, ::1]"
            for dK in ("int16", "int32")
        ),
        "mesh_faces_kernel": tuple(
            f"uint8[::1], {below}[:, ::1], int64[:, ::1]" for below in ("uint8", "uint16", "uint32")
        ),
        "inflate_kernel": ("Array(uint8, 1, 'C', readonly=True), uint8[::1]",),
        "unfilter_kernel": (
            "uint8[::1], uint8[:, ::1]",
            "Array(uint8, 1, 'C', readonly=True), uint8[:, ::1]",
        ),
    },
    "meshmocap.geometry._mesh_kernels": {
        "normals_at_kernel": ("float64[:, ::1], int64[:, ::1], int64[::1], int64",),
        "fill_kernel": (
            "float64[:, ::1], int64[:, ::1], boolean[::1], boolean, float64, boolean[:, ::1]",
        ),
        "boundary_distance_kernel": ("float64[:, ::1], boolean[:, :, ::1], int64, float64[::1]",),
        "boundary_side_kernel": (
            "float64[:, ::1], boolean[:, :, ::1], boolean[::1], float64, float64, float64, "
            "int64, int8[::1]",
        ),
        "occupied_kernel": (  # a capture's occupancy is read-only, one of your own may not be
            "float64[:, ::1], Array(boolean, 3, 'C', readonly=True), boolean[::1]",
            "float64[:, ::1], boolean[:, :, ::1], boolean[::1]",
        ),
        "in_image_kernel": ("float64[:, ::1], float64[::1], boolean[::1]",),
        "farther_kernel": (
            "float64[:, ::1], float64[:, ::1], float64, boolean, float64, boolean[::1]",
        ),
        "point_tree_kernel": ("float64[:, ::1], float64[:, ::1], int64",),
        "agreeing_kernel": (
            "float64[:, ::1], float64[:, ::1], int64[::1], int64[::1], int64[::1], int64[::1], "
            "int64[::1], float64[::1], int64[::1], int64, float64[:, ::1], float64[:, ::1], "
            "int64[::1], int64, float64, float64",
        ),
    },
    "meshmocap.body._articulated_kernels": {
        "posed_kernel": (
            "float64[:, :, ::1], float64[::1], int64[::1], "
            "Array(float64, 2, 'C', readonly=True), Array(float64, 2, 'C', readonly=True), "
            "int64[::1], int64[::1], float64[::1], float64[:, ::1], float64[:, ::1]",
        ),
        "pair_moments_kernel": (
            "float64[:, ::1], int64[::1], float64[:, ::1], float64[:, ::1], float64[::1], boolean",
        ),
        "weight_moments_kernel": (
            "int64[::1], int64[::1], float64[::1], float64[:, ::1], float64[:, :, ::1], "
            "float64[:, ::1], int64",
        ),
        "normal_equations_kernel": (
            "int64[::1], int64[::1], float64[::1], float64[:, ::1], float64[:, :, ::1], "
            "float64[:, ::1], float64[:, ::1], int64[::1]",
        ),
        "point_motion_kernel": (
            "float64[::1], float64[:, ::1], float64[:, ::1], int64[::1], int64[::1], "
            "float64[::1], int64[::1]",
        ),
        "rotation_error_kernel": (
            "float64[:, :, ::1], float64[:, :, ::1], float64[:, :, ::1], int64[::1]",
        ),
        "compatible_kernel": ("int64[::1], float64[:, ::1], float64[:, ::1], float64, int64",),
        "first_compatible_kernel": (
            "int64[:, ::1], float64[:, ::1], float64[:, ::1], int64[::1], float64, int64, "
            "int64[::1]",
        ),
    },
    "meshmocap.estimate.pose._kernels": {
        "nearest_d2_kernel": ("float32[:, :, ::1], float32[:, ::1]",),
        "nearest_kernel": ("float32[:, :, ::1], float32[:, ::1]",),
    },
    "meshmocap.models._softmax": {
        "softmax_probabilities": ("float64[:, ::1], float64[:, ::1], int64[::1]",),
        "pair_products": ("float64[:, ::1], float64[:, ::1]",),
    },
    "meshmocap.trackers.patch.kernels": {
        "nearest_among": ("float64[:, ::1], float64[:, ::1], int64[:, ::1], int64",),
        "vertex_moves": ("float64[:, ::1], float64[:, :, ::1], int64[::1], int64[::1]",),
        "stale_rows": (
            "float64[:, ::1], float64[:], float64[::1], int64[::1], float64[:, ::1], "
            "float64[:, ::1], float64[:, ::1], float64[:, ::1], int64[:, ::1], int64[::1], "
            "int64[::1], int64[::1], int64[::1], int64[::1], int64[::1], float64[:, ::1], "
            "float64[:, ::1]",
        ),
        "assign_kernel": (
            "float64[:, ::1], int64[:, ::1], float64[:, ::1], float64[:, ::1], float64[:, ::1], "
            "int64[::1], int64[::1], int64[::1], float64, float64, float64",
        ),
        "point_moments": ("int64[::1], float64[:, ::1], float64[:, ::1], float64[::1], int64",),
        "vertex_moments": (
            "int64[::1], int64[::1], float64[:, ::1], float64[:, ::1], float64[:, ::1], "
            "float64[::1], int64",
        ),
        "reverse_moments": (
            "boolean[::1], int64[::1], int64[::1], float64[::1], int64[::1], float64[:, ::1], "
            "float64[:, ::1], float64[:, ::1], float64, int64",
        ),
        "add_plane_blocks": (
            "float64[:, :, ::1], float64[::1], int64[::1], int64[::1], float64[:, ::1], "
            "float64[:, ::1], float64[:, ::1], float64[:, ::1], float64[::1], float64",
        ),
        "add_moment_blocks": (
            "float64[:, :, ::1], float64[::1], float64[::1], float64[:, ::1], "
            "float64[:, :, ::1], float64[:, ::1], float64",
        ),
        "rotated_moments": ("float64[:, :, ::1], int64[:], int64[:], float64[:, :, :, :, ::1]",),
        "rigidity_blocks": (
            "float64[:, :, ::1], float64[:, ::1], int64[:], int64[:], float64[::1], "
            "float64[:, :, ::1], float64[:, :, :, :, ::1]",
        ),
        "add_pair_blocks": (
            "float64[:, :, ::1], float64[:, :, ::1], float64[::1], float64[:, :, ::1], "
            "float64[:, :, ::1], float64[:, :, ::1], int64[:], int64[:], float64",
        ),
        "add_bone_joint_blocks": (
            "float64[:, :, :, ::1], float64[::1], float64[:, ::1], float64[:, ::1], "
            "float64[:, ::1], int64[:, ::1], int64, float64",
        ),
        "add_length_blocks": (
            "float64[:, ::1], float64[::1], float64[:, ::1], float64[::1], int64[::1], "
            "int64[::1], int64, float64",
        ),
        "patch_points": (
            "float64[:, :, ::1], float64[:, ::1], int64[::1], float64[:, ::1], float64[:, ::1]",
        ),
        "factor_values": (
            "float64[:, :, ::1], float64[:, :, ::1], float64[:, :, :, ::1], float64[:, ::1], "
            "int64[::1]",
        ),
        "block_cholesky": (
            "float64[:, :, ::1], int64[::1], int64[::1], int64[::1], int64[::1], int64[::1]",
        ),
        "block_cholesky_solve": ("float64[:, :, ::1], int64[::1], int64[::1], float64[:, ::1]",),
    },
    "meshmocap.trackers.cage.kernels": {
        "quad_skinning_transforms": (
            "float64[:, ::1], float64[:, :, ::1], Array(float64, 2, 'C', readonly=True), "
            "Array(int64, 1, 'C', readonly=True), int64[::1], int64[::1], float64[:, :, ::1], "
            "float64[:, ::1], int64[:, ::1], int64[::1]",
        ),
        "silhouette_residuals": (
            "float64[:, ::1], float64[:, :, ::1], float64[:, ::1], float64[:, :, ::1], "
            "float64[:, ::1], int64[::1], float64, float64",
        ),
        "skinned_directions": (
            "float64[:, ::1], float64[:, ::1], float64[:, ::1], float64[:, :, ::1], "
            "float64[:, :, :, ::1], float64[:, :, ::1], int64[::1], int64[::1], float64[::1], "
            "int64",
        ),
        "local_normal_equations": (
            "float64[:, :, ::1], float64[::1], float64[:, ::1], float64[::1], float64[:, ::1], "
            "int64[::1], int64[::1], float64[::1], float64[:, ::1], int64",
        ),
        "skinned_points": ("int32[::1], int32[::1], float64[::1], float64[:, :, ::1], int64",),
        "gram_schmidt_frames": ("float64[:, ::1], float64[:, ::1]",),
        "contour_pixels": ("boolean[:, ::1], float64, int64, int64",),
    },
    "meshmocap.trackers.cage.field": {
        "_boundary_buckets": ("Array(boolean, 3, 'C', readonly=True), int64",),
        "_nearest_cell": (
            "int64, int64, int64, int64, boolean[::1], int64[::1], int64[:, ::1], int64[::1], "
            "int64[::1], int64",
        ),
        "_evaluate_cell": (
            "int64, boolean[::1], float64[::1], boolean[::1], "
            "Array(boolean, 3, 'C', readonly=True), int64[:, ::1], int64[::1], int64[::1], "
            "int64, int64[::1], int64, int64, float64",
        ),
        "_lookup": (
            "float64[:, ::1], float64[::1], float64, int64[::1], float64[::1], boolean[::1], "
            "Array(boolean, 3, 'C', readonly=True), int64[:, ::1], int64[::1], int64[::1], "
            "int64, int64, int64, float64",
        ),
    },
}


def argument_types(signature: str) -> tuple:
    """The numba types (a tuple) of one of :data:`KERNELS`' signatures. A kernel is
    compiled for this tuple, as a call compiles it: numba's cache files a compilation
    under the signature object it was asked for, so one asked for by a string would never
    be found by a call."""
    from numba.core import sigutils

    return tuple(sigutils.normalize_signature(f"({signature},)")[0])


def compile_kernels(
    modules=None, *, before: Callable[[str], None] | None = None
) -> dict[str, float]:
    """Compile every kernel of :data:`KERNELS` (of ``modules``, default all) with its
    argument types, or load it from numba's cache; returns the CPU seconds each took
    (compiling is single-threaded: on a quiet machine its wall time),
    ``"module:function"`` → s, and ``"module"`` → s for importing each module. A
    signature the kernel has already costs nothing; a kernel another process is compiling
    (a worker that reached it first) is left for the end, the others compiled meanwhile.
    ``before``: called with the module's name before each module and kernel (the
    background child waits there while held back, :func:`compiling_only`)."""
    try:
        from meshmocap._numba import compiling_elsewhere
    except ImportError:  # an older tree (benchmarks/bench_compile.py runs this file on one)

        def compiling_elsewhere(kernel) -> bool:
            return False

    out = {}
    later = []  # kernels another process was compiling: loaded once the others are done
    for name in modules or KERNELS:
        if before is not None:
            before(name)
        t0 = time.process_time()
        module = importlib.import_module(name)
        out[name] = time.process_time() - t0
        for function in KERNELS[name]:
            if before is not None:
                before(name)
            if compiling_elsewhere(getattr(module, function)):
                later.append((name, module, function))
                continue
            out[f"{name}:{function}"] = _compiled(module, function)
    for name, module, function in later:
        out[f"{name}:{function}"] = _compiled(module, function)
    return out


def _compiled(module, function: str) -> float:
    """Compile (or load) ``module.function`` for each of its :data:`KERNELS` signatures;
    the CPU seconds it took."""
    t0 = time.process_time()
    for sig in KERNELS[module.__name__][function]:
        getattr(module, function).compile(argument_types(sig))
    return time.process_time() - t0


#: The kernel modules every tracking run meets (a capture's hull meshes and silhouettes
#: read; normals; the articulated body's fits: the first pose, the checks, the ICP
#: tracker; the first pose's search), and those of each method's folder.
SHARED = (
    "meshmocap.io._kernels",
    "meshmocap.geometry._mesh_kernels",
    "meshmocap.body._articulated_kernels",
    "meshmocap.estimate.pose._kernels",
)
METHOD_KERNELS = {
    "patch": ("meshmocap.models._softmax", "meshmocap.trackers.patch.kernels"),
    "cage": ("meshmocap.trackers.cage.kernels", "meshmocap.trackers.cage.field"),
}


def kernels_of(method: str) -> tuple[str, ...]:
    """The kernel modules (:data:`KERNELS`) that tracking with ``method`` (a registry name:
    ``patch``, ``cage_quads``, ``articulated_icp``...) meets."""
    return SHARED + METHOD_KERNELS.get(method.split("_")[0], ())


def uncached_kernels(modules=None) -> list[str]:
    """The kernels of :data:`KERNELS` (of ``modules``) that numba's cache holds fewer
    compiled signatures of than listed, ``"module:function"`` (imports the modules); a
    kernel numba cannot cache (:mod:`meshmocap._numba`) is not among them."""
    out = []
    for name in modules or KERNELS:
        module = importlib.import_module(name)
        for function, signatures in KERNELS[name].items():
            cache = getattr(getattr(module, function), "_cache", None)
            if not hasattr(cache, "_cache_file"):  # uncached (meshmocap._numba): none to fill
                continue
            try:  # numba's cache index of the kernel (its source's time stamp checked)
                n = len(cache._cache_file._load_index())
            except Exception:  # numba's internals changed: assume none
                n = 0
            if n < len(signatures):
                out.append(f"{name}:{function}")
    return out


#: One thread for every pool in the compiling child: it must not compete with the command.
_CHILD_ENV = {"NUMBA_NUM_THREADS": "1", "OMP_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1"}


#: The background compilations started by this process (ended when it exits).
_RUNNING: list[subprocess.Popen] = []


def start_compiling(modules=None) -> subprocess.Popen | None:
    """Start compiling the kernels of ``modules`` (default all of :data:`KERNELS`) that
    numba has not cached, in a background process (silent; at the command's own priority:
    it is work the command would otherwise do itself), and return it; None
    when every kernel is cached already, when one is compiling them already, or where it
    cannot start (the command then compiles as it goes). It runs on after this call
    returns, and ends with it, or when this process exits (:func:`stop_compiling`)."""
    modules = tuple(modules or KERNELS)
    if any(p.poll() is None for p in _RUNNING):
        return None
    missing = {k.split(":")[0] for k in uncached_kernels(modules)}
    if not missing:
        return None
    env = {**os.environ, **_CHILD_ENV}
    todo = [m for m in modules if m in missing]  # in the order a command meets them
    try:
        proc = subprocess.Popen(
            [sys.executable, "-m", "meshmocap.apps.kernels", "--quiet", "--listen", *todo],
            env=env,
            stdin=subprocess.PIPE,  # compiling_only's lines
            stdout=subprocess.DEVNULL,
            stderr=subprocess.DEVNULL,
        )
    except OSError:
        return None
    if not _RUNNING:
        atexit.register(_stop_all)
    _RUNNING.append(proc)
    return proc


def stop_compiling(proc: subprocess.Popen | None) -> None:
    """End the background compilation ``proc`` if it still runs (whatever it compiled is
    cached; numba writes each kernel's cache atomically)."""
    if proc is None:
        return
    if proc.poll() is None:
        proc.terminate()
    proc.wait()
    if proc.stdin is not None:
        with contextlib.suppress(OSError):
            proc.stdin.close()
    if proc in _RUNNING:
        _RUNNING.remove(proc)


def _stop_all() -> None:
    for proc in list(_RUNNING):
        stop_compiling(proc)


@contextlib.contextmanager
def compiling_only(modules: tuple[str, ...] = SHARED) -> Iterator[None]:
    """While the ``with`` block runs, the background compilations this process started
    (:func:`start_compiling`) compile the kernels of ``modules`` only (default
    :data:`SHARED`: those estimating the performer's body and finding the first pose
    meet) and wait before any other module's, so that the block's own processes have the
    cores; they go on when the block ends. A process of the block that reaches a kernel
    held back compiles it itself, as without the child."""
    _tell("only " + " ".join(modules))
    try:
        yield
    finally:
        _tell("all")


def _tell(line: str) -> None:
    """Send ``line`` to every running background compilation (:func:`_listen` reads it)."""
    for proc in _RUNNING:
        if proc.poll() is not None or proc.stdin is None:
            continue
        try:
            proc.stdin.write(f"{line}\n".encode())
            proc.stdin.flush()
        except OSError:  # it ended meanwhile: nothing to hold back
            pass


def _listen(fd: int) -> Callable[[str], None]:
    """The child's side of :func:`compiling_only`: the wait called before each module and
    kernel, which reads the ``only MODULE...`` and ``all`` lines sent to the file
    descriptor ``fd`` so far and returns at once for a module allowed, else when ``all``
    or the end of the input (the parent gone) comes."""
    only: list = [None]  # the modules allowed; None: every one
    rest = [b""]  # a line's start, its end not read yet

    def read(block: bool) -> None:
        while block or select.select([fd], [], [], 0)[0]:
            data = os.read(fd, 4096)
            if not data:  # the parent is gone: nothing is held back any more
                only[0] = None
                return
            *lines, rest[0] = (rest[0] + data).split(b"\n")
            for line in lines:
                words = line.decode().split()
                only[0] = set(words[1:]) if words[:1] == ["only"] else None
            block = False  # what else was sent, without waiting for more

    def wait(module: str) -> None:
        try:
            read(block=False)
            while only[0] is not None and module not in only[0]:
                read(block=True)
        except (OSError, ValueError):  # no select on this input (Windows): never held
            only[0] = None

    return wait


def main(argv: list[str] | None = None) -> int:
    """``python -m meshmocap.apps.kernels [--quiet] [--listen] [MODULE...]``: compile the
    kernels (of those modules of :data:`KERNELS`, default all), print the CPU seconds each
    took (nothing with ``--quiet``); ``--listen``: held back by lines on the standard
    input (:func:`compiling_only`)."""
    args = sys.argv[1:] if argv is None else argv
    quiet = "--quiet" in args
    modules = [a for a in args if a in KERNELS]
    before = _listen(sys.stdin.fileno()) if "--listen" in args else None
    t0 = time.process_time()
    seconds = compile_kernels(modules, before=before)
    if not quiet:
        for name, s in seconds.items():
            print(f"{s:7.2f} s  {'importing ' * (':' not in name)}{name}")
        print(f"{time.process_time() - t0:7.2f} s  in all (CPU)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
