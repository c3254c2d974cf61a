"""No bare epsilon in the source: every small number that guards a division, a comparison of
floats or a degenerate case is named (in :mod:`meshmocap._tolerances`, or in its module when
it belongs to one algorithm)."""

from __future__ import annotations

import ast
from pathlib import Path

import meshmocap
from meshmocap import _tolerances

SRC = Path(meshmocap.__file__).parent

#: Magnitudes at or below this are epsilons (larger literals are scales, weights, rates).
EPSILON = 1e-6


def _bare_epsilons(tree: ast.Module) -> list[int]:
    """Line numbers of small float literals outside a module-level constant, a parameter's
    default or a keyword argument (an option passed by name is named there)."""
    allowed: set[int] = set()
    for node in tree.body:  # module-level NAME = ... (constants, tables of them)
        if isinstance(node, ast.Assign | ast.AnnAssign):
            allowed.update(id(n) for n in ast.walk(node))
    for node in ast.walk(tree):
        if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef):
            for d in node.args.defaults + [d for d in node.args.kw_defaults if d is not None]:
                allowed.update(id(n) for n in ast.walk(d))
        elif isinstance(node, ast.keyword):
            allowed.update(id(n) for n in ast.walk(node.value))
    return [
        node.lineno
        for node in ast.walk(tree)
        if isinstance(node, ast.Constant)
        and isinstance(node.value, float)
        and 0.0 < abs(node.value) <= EPSILON
        and id(node) not in allowed
    ]


def test_no_bare_epsilon_in_the_source():
    found = [
        f"{path.relative_to(SRC)}:{line}"
        for path in sorted(SRC.rglob("*.py"))
        for line in _bare_epsilons(ast.parse(path.read_text(encoding="utf-8")))
    ]
    assert found == []


def test_the_finder_sees_a_bare_epsilon_and_spares_named_ones():
    code = "X = 1e-9\ndef f(a, tol=1e-7):\n    return g(a, rtol=1e-6) / max(a, 1e-12) + X\n"
    assert _bare_epsilons(ast.parse(code)) == [3]


def test_named_tolerances_are_small_positive_floats():
    for name in _tolerances.__all__:
        value = getattr(_tolerances, name)
        assert isinstance(value, float) and 0.0 < value <= EPSILON, name
