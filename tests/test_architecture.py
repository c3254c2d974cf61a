"""The package's layers: imports point down, no import cycle, no module over 600 lines.

The check itself is ``tools/check_architecture.py`` (an ``ast`` walk, nothing imported); the
second test shows it catches each kind of fault on a small package written here.
"""

import importlib.util
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def _checker():
    spec = importlib.util.spec_from_file_location(
        "check_architecture", ROOT / "tools" / "check_architecture.py"
    )
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module  # dataclasses look their module up
    spec.loader.exec_module(module)
    return module


def test_meshmocap_imports_only_point_down():
    report = _checker().check(ROOT / "src")
    assert report.upward == []
    assert report.file_cycles == []
    assert report.package_cycles == []
    assert report.long_modules == []


def test_checker_finds_upward_imports_cycles_and_long_modules(tmp_path):
    pkg = tmp_path / "meshmocap"
    for sub in ("body", "io", "trackers", "apps"):
        (pkg / sub).mkdir(parents=True)
        (pkg / sub / "__init__.py").write_text("")
    (pkg / "__init__.py").write_text("")
    (pkg / "errors.py").write_text("")
    # body reaches up into trackers (upward), io and body import each other (a package
    # cycle through an upward edge), two apps modules import each other (a file cycle,
    # one edge hidden under TYPE_CHECKING), and one module is too long
    (pkg / "body" / "autorig.py").write_text("from meshmocap.trackers.icp import fit\n")
    (pkg / "body" / "clips.py").write_text("from meshmocap.io import bvh\n")
    (pkg / "io" / "bvh.py").write_text("from meshmocap.body.skeleton import Skeleton\n")
    (pkg / "body" / "skeleton.py").write_text("import meshmocap.errors\n")
    (pkg / "trackers" / "icp.py").write_text("from ..body import skeleton\n")
    (pkg / "apps" / "a.py").write_text("from meshmocap.apps.b import x\n")
    (pkg / "apps" / "b.py").write_text(
        "from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n    from meshmocap.apps import a\n"
    )
    (pkg / "apps" / "long.py").write_text("x = 1\n" * 601)
    report = _checker().check(tmp_path)
    assert report.upward == [
        "meshmocap.body.autorig imports meshmocap.trackers.icp (layer trackers is above body)",
        "meshmocap.body.clips imports meshmocap.io (layer io is above body)",
        "meshmocap.body.clips imports meshmocap.io.bvh (layer io is above body)",
    ]
    assert report.file_cycles == [["meshmocap.apps.a", "meshmocap.apps.b"]]
    assert report.package_cycles == [["body", "io", "trackers"]]
    assert report.long_modules == ["meshmocap.apps.long: 601 lines (at most 600)"]
    assert not report.ok
