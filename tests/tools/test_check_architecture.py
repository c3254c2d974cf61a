"""The package's architecture: imports point down, no import cycle, a method package never
imports another, no private name is imported across modules, by the package or its
tests, and every module has its mirrored test file or a listed reason.

The check itself is ``tools/check_architecture.py`` (an ``ast`` walk, nothing imported); the
second test shows it catches each kind of fault on a small package written here.
"""

import importlib.util
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


def _checker():
    spec = importlib.util.spec_from_file_location(
        "check_architecture", ROOT / "tools" / "check_architecture.py"
    )
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module  # dataclasses look their module up
    spec.loader.exec_module(module)
    return module


def test_meshmocap_imports_only_point_down():
    report = _checker().check(ROOT / "src", ROOT / "tests")
    assert report.upward == []
    assert report.file_cycles == []
    assert report.package_cycles == []
    assert report.sibling_methods == []
    assert report.private_imports == []
    assert report.untested == []


def test_checker_finds_upward_imports_cycles_sibling_methods_and_private_names(tmp_path):
    pkg = tmp_path / "meshmocap"
    for sub in ("body", "io", "trackers", "trackers/patch", "trackers/cage", "apps"):
        (pkg / sub).mkdir(parents=True)
        (pkg / sub / "__init__.py").write_text("")
    (pkg / "__init__.py").write_text("")
    (pkg / "errors.py").write_text("")
    # body reaches up into trackers (upward), io and body import each other (a package
    # cycle through an upward edge), two apps modules import each other (a file cycle,
    # one edge hidden under TYPE_CHECKING), one method reaches into another, and a private
    # name crosses a module boundary (a module's own and dunder names are fine)
    (pkg / "body" / "autorig.py").write_text("from meshmocap.trackers.icp import fit\n")
    (pkg / "body" / "clips.py").write_text("from meshmocap.io import bvh\n")
    (pkg / "io" / "bvh.py").write_text("from meshmocap.body.skeleton import Skeleton\n")
    (pkg / "body" / "skeleton.py").write_text("import meshmocap.errors\n")
    (pkg / "trackers" / "icp.py").write_text("from ..body import skeleton\n")
    (pkg / "apps" / "a.py").write_text("from meshmocap.apps.b import x\n")
    (pkg / "apps" / "b.py").write_text(
        "from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n    from meshmocap.apps import a\n"
    )
    (pkg / "trackers" / "patch" / "terms.py").write_text("_w = 1\n")
    (pkg / "trackers" / "patch" / "tracker.py").write_text(
        "from meshmocap.trackers.cage.energy import e\nfrom .terms import _w\n"
    )
    (pkg / "trackers" / "cage" / "energy.py").write_text(
        "from meshmocap.body.skeleton import __all__\n"
    )
    (pkg / "trackers" / "registry.py").write_text(
        "from meshmocap.trackers.patch.tracker import t\n"
    )
    # a test imports a private name of a module (a private module itself is no name)
    (tmp_path / "tests" / "io").mkdir(parents=True)
    (tmp_path / "tests" / "io" / "test_bvh.py").write_text(
        "from meshmocap.io.bvh import _read, read\nfrom meshmocap import _atomic\n"
    )
    (pkg / "_atomic.py").write_text("")
    (tmp_path / "tests" / "helpers.py").write_text("from toys import _small\n")  # not ours
    assert _checker().check(tmp_path).private_imports == [
        "meshmocap.trackers.patch.tracker imports _w from meshmocap.trackers.patch.terms"
    ]
    report = _checker().check(tmp_path, tmp_path / "tests")
    assert report.upward == [
        "meshmocap.body.autorig imports meshmocap.trackers.icp (layer trackers is above body)",
        "meshmocap.body.clips imports meshmocap.io (layer io is above body)",
        "meshmocap.body.clips imports meshmocap.io.bvh (layer io is above body)",
    ]
    assert report.file_cycles == [["meshmocap.apps.a", "meshmocap.apps.b"]]
    assert report.package_cycles == [["body", "io", "trackers"]]
    assert report.sibling_methods == [
        "meshmocap.trackers.patch.tracker imports meshmocap.trackers.cage.energy "
        "(method meshmocap.trackers.cage from method meshmocap.trackers.patch)"
    ]
    assert report.private_imports == [
        "meshmocap.trackers.patch.tracker imports _w from meshmocap.trackers.patch.terms",
        "tests/io/test_bvh.py imports _read from meshmocap.io.bvh",
    ]
    assert not report.ok


def test_every_module_has_its_test_file_or_a_true_reason(tmp_path):
    """A module without ``tests/<package>/test_<module>.py`` is reported unless listed with
    its reason; a top-level base module's file may live in ``tests/base/``; a listed module
    that has its file, no longer exists, or whose reason names a missing test is reported."""
    checker = _checker()
    pkg = tmp_path / "src" / "meshmocap"
    (pkg / "io").mkdir(parents=True)
    for name in ("__init__.py", "_npz.py", "errors.py", "io/__init__.py", "io/bvh.py"):
        (pkg / name).write_text("")
    (pkg / "io" / "c3d.py").write_text("")
    tests = tmp_path / "tests"
    (tests / "io").mkdir(parents=True)
    (tests / "base").mkdir()
    (tests / "io" / "test_bvh.py").write_text("")
    (tests / "base" / "test_npz.py").write_text("")  # meshmocap._npz's
    files = {checker.module_name(p, pkg.parent): p for p in sorted(pkg.rglob("*.py"))}
    assert checker.untested_modules(files, tests, {}) == [
        "meshmocap.errors: no tests/test_errors.py and no reason in UNTESTED",
        "meshmocap.io.c3d: no tests/io/test_c3d.py and no reason in UNTESTED",
    ]
    listed = {
        "meshmocap.errors": "raised and matched by every module's tests",
        "meshmocap.io.c3d": "the C3D writer: tests/io/test_exports.py",
        "meshmocap.io.bvh": "tested",
        "meshmocap.io.gone": "a module removed since",
    }
    assert checker.untested_modules(files, tests, listed) == [
        "meshmocap.io.bvh: has its test file; remove it from UNTESTED",
        "meshmocap.io.c3d: its reason names tests/io/test_exports.py, which does not exist",
        "meshmocap.io.gone: listed in UNTESTED but no such module",
    ]
