"""Check the package's architecture: imports point down the layers, no import cycle, a
method package never imports another, no private name crosses a module boundary.

Walks ``src/meshmocap`` with :mod:`ast` (nothing is imported) and reports:

* every import of a module from a higher layer than its own (``LAYERS`` below);
* import cycles between files and between packages (strongly connected components of the
  import graph, with ``TYPE_CHECKING`` and function-level imports counted: a cycle hidden
  in a function is still a knot);
* imports between method packages (the sub-packages of ``trackers``: ``trackers/patch/``,
  ``trackers/cage/``): each method is whole in its folder, and shares only what lies in
  the layers below;
* a private name (``_name``) imported from another module: what a module shares, it names
  publicly. The tests are held to it too (``tests/``, when given): a test reaches a module
  through what it shares, or the name is made public (a module itself, ``_atomic``, is not
  a private name);
* a module without its mirrored test file (``meshmocap/a/b.py`` ↔ ``tests/a/test_b.py``; a
  top-level module's is ``tests/test_b.py`` or, for the base layer, ``tests/base/test_b.py``;
  a leading underscore is dropped) and not listed in :data:`UNTESTED` with the reason; a
  listed module that has its file now, or no longer exists, is reported too, so the list
  stays true. Packages' ``__init__`` files are not modules here.

A module is as long as its one concept needs: there is no line limit.

Usage: ``python tools/check_architecture.py [SRC [TESTS]]`` (default: the project's ``src``
and ``tests``); exit status 1 when anything is found.
The test suite runs the same check (``tests/tools/test_check_architecture.py``).
"""

from __future__ import annotations

import ast
import dataclasses
import re
import sys
from collections import defaultdict
from dataclasses import dataclass
from pathlib import Path

#: Layers from the bottom up. A module may import its own layer and the layers below.
#: Top-level modules and packages of ``meshmocap``; ``meshmocap/__init__.py`` is base.
LAYERS: tuple[tuple[str, ...], ...] = (
    (
        "__init__",
        "errors",
        "_atomic",
        "_npz",
        "_numba",
        "_validate",
        "_parallel",
        "_progress",
        "_threads",
        "_timing",
        "_tolerances",
        "_version",
    ),  # base
    ("geometry",),
    ("models",),
    ("body",),
    ("io",),
    ("estimate",),
    ("trackers",),
    ("studio",),
    ("analysis",),
    ("apps",),
    ("api",),
    ("cli",),
)
#: Imports allowed up the layers: the package's ``__init__`` re-exports the Python API
#: lazily (a module ``__getattr__`` loads ``meshmocap.api`` on first use, never at import).
LAZY_EXPORTS = {("meshmocap", "meshmocap.api")}
#: The package whose sub-packages are methods (one folder each, never importing a sibling).
METHODS_PACKAGE = "meshmocap.trackers"

#: Modules without a mirrored test file, each with the reason: where its behaviour is
#: tested instead, or why it needs no test of its own. A path named in a reason must exist.
UNTESTED: dict[str, str] = {
    "meshmocap._atomic": (
        "atomic writes and the folder lock: tests/io/test_faults.py (one writer per folder, a"
        " killed run's lock) and every writer's tests"
    ),
    "meshmocap._validate": (
        "the option-constraint table: tests/trackers/test_registry.py feeds every registered "
        "method an invalid value for every option"
    ),
    "meshmocap._version": "the version string, nothing to test",
    "meshmocap.errors": (
        "the error classes; each is raised and matched by the tests of the module that raises it"
    ),
    "meshmocap.analysis.gait_signals": "the gait signals: tests/analysis/test_gait.py",
    "meshmocap.analysis.tables": (
        "the score tables: tests/analysis/test_metrics.py and tests/analysis/test_evaluate.py"
    ),
    "meshmocap.apps.batch.items": "batch items: tests/apps/batch/test_run.py",
    "meshmocap.apps.batch.report": (
        "batch's report: tests/apps/batch/test_run.py (the batch command in process)"
    ),
    "meshmocap.apps.batch.summary": "batch's summary: tests/apps/batch/test_run.py",
    "meshmocap.apps.bench.captures": "bench's captures: tests/apps/bench/test_run.py",
    "meshmocap.apps.bench.plots": (
        "bench's plots: tests/apps/bench/test_run.py (table, markdown and plots written)"
    ),
    "meshmocap.apps.bench.rows": (
        "bench's rows: tests/apps/bench/test_run.py and tests/trackers/patch/test_residuals.py"
    ),
    "meshmocap.apps.files.evaluation": "eval's files: tests/analysis/test_evaluate.py",
    "meshmocap.apps.files.gait": "gait's files: tests/analysis/test_gait.py",
    "meshmocap.apps.figures.latent": "the latent-space plot: tests/models/test_gplvm.py",
    "meshmocap.apps.figures.evaluation": "the evaluation plots: tests/analysis/test_metrics.py",
    "meshmocap.apps.figures.render": (
        "contact sheets: tests/geometry/test_raster.py and the render command in "
        "tests/cli/test_commands.py"
    ),
    "meshmocap.body._articulated_kernels": (
        "numba loops of body/articulated_system: tests/body/test_articulated_system.py "
        "(against NumPy and finite differences), signatures in tests/apps/test_kernels.py"
    ),
    "meshmocap.body.contact": (
        "foot contact: tests/body/test_procedural.py and tests/body/test_retarget.py"
    ),
    "meshmocap.body.markers": (
        "virtual markers: tests/apps/files/test_export.py and tests/io/test_exports.py"
    ),
    "meshmocap.body.motion": (
        "the Motion record: tests/body/test_retarget.py and tests/body/test_skeleton.py"
    ),
    "meshmocap.body.names": (
        "joint-name tables (data): used by tests/toys.py and every skeleton test"
    ),
    "meshmocap.body.shape_space": "the body shape space: tests/models/test_shape_space.py",
    "meshmocap.body.skinning": "linear blend skinning: tests/body/test_template.py",
    "meshmocap.cli._args": "argument types: the one-line refusals of tests/cli/test_bad_input.py",
    "meshmocap.cli.batch": "the batch command in process: tests/apps/batch/test_run.py",
    "meshmocap.cli.capture": (
        "synth and hull in process: tests/io/test_faults.py, tests/studio/test_synth.py, "
        "tests/cli/test_bad_input.py"
    ),
    "meshmocap.cli.demo": "the demo command in process: tests/cli/test_commands.py",
    "meshmocap.cli.evaluation": (
        "eval, report and bench in process: tests/analysis/test_evaluate.py, "
        "tests/apps/report/test_page.py, tests/apps/bench/test_run.py"
    ),
    "meshmocap.cli.export": "the export command in process: tests/apps/files/test_export.py",
    "meshmocap.cli.gait": "the gait command in process: tests/analysis/test_gait.py",
    "meshmocap.cli.motion": "templates, retarget and render in process: tests/cli/test_commands.py",
    "meshmocap.cli.subject": (
        "the subject command in process: tests/estimate/performer/test_subject.py"
    ),
    "meshmocap.estimate.performer.tracking_template": (
        "the template a track uses: tests/estimate/performer/test_capture_cache.py and "
        "tests/estimate/performer/test_point_subject.py"
    ),
    "meshmocap.estimate.pose._kernels": (
        "numba loops of the pose search: tests/estimate/pose/test_pose_search.py (against "
        "NumPy), signatures in tests/apps/test_kernels.py"
    ),
    "meshmocap.geometry._mesh_kernels": (
        "numba loops of geometry/mesh: tests/apps/test_kernels.py and the normals of "
        "tests/geometry/test_raster.py"
    ),
    "meshmocap.geometry.camera": (
        "the pinhole camera: tests/geometry/test_carving.py, tests/geometry/test_raster.py, "
        "tests/io/test_cameras.py"
    ),
    "meshmocap.geometry.coverage": "camera coverage: tests/trackers/patch/test_residuals.py",
    "meshmocap.geometry.mesh": (
        "mesh helpers: tests/body/test_template.py and tests/estimate/pose/test_first_pose.py"
    ),
    "meshmocap.geometry.proximity": "nearest points on meshes: tests/analysis/test_metrics.py",
    "meshmocap.io._labelled": "checks shared by the C3D and TRC writers: tests/io/test_exports.py",
    "meshmocap.io._text": (
        "tokenising for BVH and ASF/AMC: tests/io/test_bvh.py, tests/io/test_asf_amc.py, "
        "tests/io/test_fuzz_loaders.py"
    ),
    "meshmocap.io._kernels": (
        "the masks' PNG decoding: tests/geometry/test_silhouette.py (against Pillow), "
        "signatures in tests/apps/test_kernels.py"
    ),
    "meshmocap.io.archives": "mesh archives: tests/io/test_meshes.py",
    "meshmocap.io.c3d": "the C3D writer: tests/io/test_exports.py",
    "meshmocap.io.clips": "motion clips: tests/body/test_pose_library.py",
    "meshmocap.io.gltf": (
        "the glTF writer: tests/io/test_exports.py and tests/apps/files/test_export.py (the Khronos"
        " validator)"
    ),
    "meshmocap.io.guards": "output and track-folder checks: tests/cli/test_bad_input.py",
    "meshmocap.io.joints_csv": "the joints CSV writer: tests/io/test_exports.py",
    "meshmocap.io.live": "the growing capture: tests/trackers/test_follow.py",
    "meshmocap.io.plausibility": "input plausibility: tests/io/test_faults.py",
    "meshmocap.io.silhouettes": (
        "mask files: tests/geometry/test_silhouette.py and tests/io/test_faults.py"
    ),
    "meshmocap.io.trc": "the TRC writer: tests/io/test_exports.py",
    "meshmocap.models._kernels": (
        "numba loops of models/gplvm: tests/models/test_gplvm.py (gradients by finite differences)"
    ),
    "meshmocap.models._softmax": (
        "numba passes of models/bodyparts' logistic fit: tests/models/test_bodyparts.py "
        "(derivatives by finite differences, the fit against scikit-learn's)"
    ),
    "meshmocap.studio.hulls": (
        "hulls of silhouettes: tests/studio/test_synth.py and tests/io/test_faults.py"
    ),
    "meshmocap.studio.rigs": (
        "camera rigs: tests/io/test_cameras.py and tests/geometry/test_silhouette.py"
    ),
    "meshmocap.trackers.base": (
        "the tracker protocol: every tracker's tests and tests/trackers/test_registry.py"
    ),
    "meshmocap.trackers.cage.cage_mesh": "the cage mesh: tests/trackers/cage/test_oqr.py",
    "meshmocap.trackers.cage.energy": "the cage energy: tests/trackers/cage/test_terms.py",
    "meshmocap.trackers.cage.growth": (
        "quad growth: tests/trackers/cage/test_oqr.py (cages enclose, tangles undone)"
    ),
    "meshmocap.trackers.cage.options": (
        "the cage options: tests/trackers/cage/test_terms.py and tests/trackers/test_registry.py"
    ),
    "meshmocap.trackers.cage.oqr_placement": (
        "quad placement: tests/trackers/cage/test_oqr.py (turned templates, closed cages)"
    ),
    "meshmocap.trackers.cage.oqr_skinning": (
        "the rig's skinning: tests/trackers/cage/test_kernels.py"
    ),
    "meshmocap.trackers.cage.quad_frames": "quad frames: tests/trackers/cage/test_derivatives.py",
    "meshmocap.trackers.cage.surface": "the cage surfaces: tests/trackers/cage/test_derivatives.py",
    "meshmocap.trackers.patch.energy": "the patch energy: tests/trackers/patch/test_terms.py",
    "meshmocap.trackers.patch.kernels": (
        "numba loops of the patch tracker: tests/trackers/patch/test_assign.py (against the "
        "NumPy E-step) and tests/trackers/patch/test_nearest.py"
    ),
    "meshmocap.trackers.patch.model": (
        "the patch model: tests/trackers/patch/test_residuals.py and "
        "tests/trackers/patch/test_nearest.py"
    ),
    "meshmocap.trackers.patch.options": (
        "the patch options: tests/trackers/patch/test_terms.py and tests/trackers/test_registry.py"
    ),
}


@dataclass(frozen=True)
class Report:
    """What :func:`check` found; each entry is one human-readable line."""

    upward: list[str]
    file_cycles: list[list[str]]
    package_cycles: list[list[str]]
    sibling_methods: list[str]
    private_imports: list[str]
    untested: list[str] = dataclasses.field(default_factory=list)

    @property
    def ok(self) -> bool:
        return not (
            self.upward
            or self.file_cycles
            or self.package_cycles
            or self.sibling_methods
            or self.private_imports
            or self.untested
        )


def module_name(path: Path, src: Path) -> str:
    """Dotted module name of ``path`` (a ``.py`` file under ``src``)."""
    parts = list(path.relative_to(src).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts = parts[:-1]
    return ".".join(parts)


def imports(path: Path, name: str, known: set[str]) -> set[str]:
    """The modules of ``known`` that the file at ``path`` (module ``name``) imports."""
    tree = ast.parse(path.read_text(encoding="utf-8"), filename=str(path))
    is_package = path.name == "__init__.py"
    found: set[str] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            targets = [alias.name for alias in node.names]
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = name.split(".")
                keep = len(base) - node.level + (1 if is_package else 0)
                module = ".".join(base[:keep] + ([node.module] if node.module else []))
            else:
                module = node.module or ""
            targets = [module] + [f"{module}.{alias.name}" for alias in node.names]
        else:
            continue
        for target in targets:
            # ``import a.b.c`` also runs a and a.b: the deepest known module is the edge
            while target and target not in known:
                target = target.rpartition(".")[0]
            if target and target != name and target.count(".") >= 1:
                found.add(target)
    return found


def private_imports(path: Path, name: str, known: set[str]) -> list[str]:
    """``from M import _x`` in the file at ``path`` (module ``name``, or a test file's path),
    ``M`` another module of ``known`` and ``M._x`` not itself a module: one line each."""
    tree = ast.parse(path.read_text(encoding="utf-8"), filename=str(path))
    is_package = path.name == "__init__.py"
    found = []
    for node in ast.walk(tree):
        if not isinstance(node, ast.ImportFrom):
            continue
        if node.level:
            base = name.split(".")
            keep = len(base) - node.level + (1 if is_package else 0)
            module = ".".join(base[:keep] + ([node.module] if node.module else []))
        else:
            module = node.module or ""
        if module not in known or module == name:
            continue
        for alias in node.names:
            private = alias.name.startswith("_") and not alias.name.startswith("__")
            if private and f"{module}.{alias.name}" not in known:
                found.append(f"{name} imports {alias.name} from {module}")
    return found


def method_package(module: str, packages: set[str]) -> str | None:
    """The method package (a sub-package of :data:`METHODS_PACKAGE`) that holds ``module``."""
    for pkg in packages:
        if module == pkg or module.startswith(pkg + "."):
            return pkg
    return None


def unit(module: str) -> str:
    """The top-level module or package of ``meshmocap.x.y`` (``x``); ``__init__`` for the root."""
    parts = module.split(".")
    return parts[1] if len(parts) > 1 else "__init__"


def cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """Strongly connected components with more than one node (Tarjan, iterative)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    found: list[list[str]] = []
    counter = 0
    for root in sorted(graph):
        if root in index:
            continue
        work = [(root, iter(sorted(graph[root])))]
        index[root] = low[root] = counter
        counter += 1
        stack.append(root)
        on_stack.add(root)
        while work:
            node, children = work[-1]
            for child in children:
                if child not in index:
                    index[child] = low[child] = counter
                    counter += 1
                    stack.append(child)
                    on_stack.add(child)
                    work.append((child, iter(sorted(graph.get(child, ())))))
                    break
                if child in on_stack:
                    low[node] = min(low[node], index[child])
            else:
                work.pop()
                if work:
                    parent = work[-1][0]
                    low[parent] = min(low[parent], low[node])
                if low[node] == index[node]:
                    component = []
                    while True:
                        member = stack.pop()
                        on_stack.discard(member)
                        component.append(member)
                        if member == node:
                            break
                    if len(component) > 1:
                        found.append(sorted(component))
    return sorted(found)


def mirrored_tests(module: str, tests: Path) -> list[Path]:
    """The test files that may mirror ``module`` (``meshmocap.a.b``): ``tests/a/test_b.py``;
    for a top-level module also ``tests/base/test_b.py`` (the base layer's tests)."""
    parts = module.split(".")[1:]
    name = "test_" + parts[-1].lstrip("_") + ".py"
    found = [tests.joinpath(*parts[:-1], name)]
    if len(parts) == 1:
        found.append(tests / "base" / name)
    return found


def untested_modules(
    files: dict[str, Path], tests: Path, listed: dict[str, str] | None = None
) -> list[str]:
    """One line per module with neither a mirrored test file (:func:`mirrored_tests`) nor a
    reason in ``listed`` (default :data:`UNTESTED`), per listed module that has its test
    file or no longer exists, and per reason naming a ``tests/…`` or ``benchmarks/…`` path
    that does not exist."""
    listed = UNTESTED if listed is None else listed
    root = tests.parent
    found = []
    for name, path in sorted(files.items()):
        if path.name in ("__init__.py", "__main__.py"):
            continue
        has = any(p.is_file() for p in mirrored_tests(name, tests))
        if not has and name not in listed:
            where = mirrored_tests(name, tests)[0].relative_to(root).as_posix()
            found.append(f"{name}: no {where} and no reason in UNTESTED")
        elif has and name in listed:
            found.append(f"{name}: has its test file; remove it from UNTESTED")
    for name, reason in sorted(listed.items()):
        if name not in files:
            found.append(f"{name}: listed in UNTESTED but no such module")
        for ref in re.findall(r"\b(?:tests|benchmarks)/[\w/]+\.py", reason):
            if not (root / ref).is_file():
                found.append(f"{name}: its reason names {ref}, which does not exist")
    return found


def check(src: Path, tests: Path | None = None) -> Report:
    """Check the package ``src/meshmocap`` (``src`` is the folder that holds it) and, given
    ``tests`` (the folder of the test suite), the tests' imports of private names."""
    files = {module_name(p, src): p for p in sorted((src / "meshmocap").rglob("*.py"))}
    known = set(files)
    layer = {u: k for k, names in enumerate(LAYERS) for u in names}
    graph = {name: imports(path, name, known) for name, path in files.items()}

    upward = []
    for name in sorted(graph):
        own = unit(name)
        if own not in layer:
            upward.append(f"{name}: '{own}' is in no layer of tools/check_architecture.py")
            continue
        for target in sorted(graph[name]):
            other = unit(target)
            if layer.get(other, len(LAYERS)) > layer[own] and (name, target) not in LAZY_EXPORTS:
                upward.append(f"{name} imports {target} (layer {other} is above {own})")

    packages: dict[str, set[str]] = defaultdict(set)
    for name, targets in graph.items():
        packages[unit(name)] |= {unit(t) for t in targets} - {unit(name)}

    methods = {
        name
        for name, path in files.items()
        if path.name == "__init__.py" and name.rpartition(".")[0] == METHODS_PACKAGE
    }
    sibling = []
    for name in sorted(graph):
        own = method_package(name, methods)
        for target in sorted(graph[name]):
            other = method_package(target, methods)
            if own and other and other != own:
                sibling.append(f"{name} imports {target} (method {other} from method {own})")

    private = [line for name, path in files.items() for line in private_imports(path, name, known)]
    if tests is not None:
        for path in sorted(tests.rglob("*.py")):
            where = path.relative_to(tests.parent).as_posix()
            private += private_imports(path, where, known)
    untested = untested_modules(files, tests) if tests is not None else []
    return Report(upward, cycles(graph), cycles(dict(packages)), sibling, sorted(private), untested)


def main(argv: list[str]) -> int:
    root = Path(__file__).resolve().parents[1]
    src = Path(argv[0]) if argv else root / "src"
    tests = Path(argv[1]) if len(argv) > 1 else (None if argv else root / "tests")
    report = check(src, tests)
    for line in report.upward:
        print("upward import:", line)
    for c in report.file_cycles:
        print("file cycle:", " <-> ".join(c))
    for c in report.package_cycles:
        print("package cycle:", " <-> ".join(c))
    for line in report.sibling_methods:
        print("method imports method:", line)
    for line in report.private_imports:
        print("private import:", line)
    for line in report.untested:
        print("untested:", line)
    if report.ok:
        print(
            f"ok: {len(LAYERS)} layers, imports point down, no cycle, methods apart, "
            "no private name imported across modules"
            + (" or by a test, every module tested or its reason listed" if tests else "")
        )
    return 0 if report.ok else 1


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
