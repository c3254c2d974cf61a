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
  a private name).

A module is as long as its one concept needs: there is no line limit.

Usage: ``python tools/check_architecture.py [SRC [TESTS]]`` (default: the project's ``src``
and ``tests``); exit status 1 when anything is found.
The test suite runs the same check (``tests/tools/test_check_architecture.py``).
"""

from __future__ import annotations

import ast
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
        "_progress",
        "_threads",
        "_timing",
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


@dataclass(frozen=True)
class Report:
    """What :func:`check` found; each entry is one human-readable line."""

    upward: list[str]
    file_cycles: list[list[str]]
    package_cycles: list[list[str]]
    sibling_methods: list[str]
    private_imports: list[str]

    @property
    def ok(self) -> bool:
        return not (
            self.upward
            or self.file_cycles
            or self.package_cycles
            or self.sibling_methods
            or self.private_imports
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
    return Report(upward, cycles(graph), cycles(dict(packages)), sibling, sorted(private))


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
    if report.ok:
        print(
            f"ok: {len(LAYERS)} layers, imports point down, no cycle, methods apart, "
            "no private name imported across modules" + (" or by a test" if tests else "")
        )
    return 0 if report.ok else 1


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
