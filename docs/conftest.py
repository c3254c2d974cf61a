"""Run the documentation's examples so that the pages cannot rot (``pytest -q docs``).

* Every ``.. code-block:: console`` of a page is a shell session: its ``$ `` lines (with
  ``\\`` continuations) run in order with bash, in one fresh folder per page, and each must
  exit with status 0. The lines a command shows below it are its expected output: each must
  appear in the command's standard output, in order, with every number allowed to differ
  (timings, paths of temporary folders), ``...`` alone standing for any lines and a line
  ending in ``...`` for any line that starts so. Blocks written
  as ``.. code-block:: text`` are shown, not run (a cluster, a camera, data the build
  machine does not have).
* ``>>>`` examples run as doctests (``--doctest-glob``), also in a fresh folder.

``MESHMOCAP_DOCS_PAGES=guide/track.rst,...`` runs only the named pages' shell sessions.
"""

from __future__ import annotations

import atexit
import os
import re
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

import pytest

DOCS = Path(__file__).resolve().parent
SKIP_DIRS = {"_build", "generated", "auto_examples", "_templates"}
# Built pages, not sources: never collected.
collect_ignore = ["_build", "auto_examples", "api/generated", "examples", "conf.py"]
NUMBER = re.compile(r"[-+−]?\d[\d,]*(?:\.\d+)?(?:e[-+]?\d+)?")


def pytest_collect_file(parent, file_path):
    if file_path.suffix != ".rst" or SKIP_DIRS & set(file_path.relative_to(DOCS).parts[:-1]):
        return None
    only = os.environ.get("MESHMOCAP_DOCS_PAGES")
    rel = file_path.relative_to(DOCS).as_posix()
    if only and rel not in only.split(","):
        return None
    if sessions(file_path.read_text()):
        return ConsolePage.from_parent(parent, path=file_path)
    return None


@pytest.fixture(autouse=True)
def _in_fresh_folder(tmp_path, monkeypatch):
    """Doctests and sessions run in an empty folder of their own."""
    monkeypatch.chdir(tmp_path)


def sessions(text: str) -> list[list[tuple[str, list[str], int]]]:
    """Return each console block's commands as (command, expected lines, line number)."""
    lines = text.splitlines()
    blocks = []
    i = 0
    while i < len(lines):
        if re.match(r"\s*\.\. code-block:: console\s*$", lines[i]):
            indent = None
            body = []
            j = i + 1
            while j < len(lines):
                line = lines[j]
                if line.strip():
                    ind = len(line) - len(line.lstrip())
                    if indent is None:
                        if ind == 0 or line.lstrip().startswith(":"):
                            j += 1
                            continue
                        indent = ind
                    if ind < indent:
                        break
                    body.append((j + 1, line[indent:]))
                else:
                    body.append((j + 1, ""))
                j += 1
            blocks.append(_commands(body))
            i = j
        else:
            i += 1
    return [b for b in blocks if b]


def _commands(body):
    commands = []
    k = 0
    while k < len(body):
        lineno, line = body[k]
        if line.startswith("$ "):
            cmd = line[2:]
            while cmd.endswith("\\") and k + 1 < len(body):
                k += 1
                cmd = cmd[:-1] + " " + body[k][1].strip()
            commands.append((cmd, [], lineno))
        elif commands and line.strip():
            commands[-1][1].append(line)
        k += 1
    return commands


def _pattern(expected: str) -> re.Pattern:
    text = expected.rstrip()
    prefix = text.endswith("...") and text.strip() != "..."  # a line's start only
    parts = NUMBER.split(text[:-3].rstrip() if prefix else text)
    body = r"[-+−]?\d[\d,]*(?:\.\d+)?(?:e[-+]?\d+)?".join(re.escape(p) for p in parts)
    end = "" if prefix else r"\s*$"
    return re.compile(r"\s*" + re.sub(r"(\\ )+", r"\\s+", body) + end)


def check_output(expected: list[str], stdout: str) -> str | None:
    """Return why ``stdout`` does not show the ``expected`` lines in order, or None."""
    out = stdout.splitlines()
    pos = 0
    for line in expected:
        if line.strip() == "...":
            continue
        pat = _pattern(line)
        while pos < len(out) and not pat.match(out[pos]):
            pos += 1
        if pos == len(out):
            return f"expected line not found in order: {line!r}"
        pos += 1
    return None


_ROOT: list[Path] = []


def _session_root() -> Path:
    """This run's folder for the pages' sessions: each page runs in ``page/`` in it, emptied
    before the page, and the commands share one cache, ``cache/`` (``MESHMOCAP_CACHE``,
    unless set), removed at exit. Many pages make the same capture under the same name
    (``walk-cap``): at the same path, its cache (the first pose, the estimated body: keyed
    by the capture's path and content) answers every page after the first, as it answers a
    user who makes it again."""
    if not _ROOT:
        _ROOT.append(Path(tempfile.mkdtemp(prefix="meshmocap-docs-")))
        atexit.register(shutil.rmtree, _ROOT[0], True)
    return _ROOT[0]


class ConsolePage(pytest.File):
    def collect(self):
        yield ConsoleSession.from_parent(self, name="console")


class ConsoleSession(pytest.Item):
    def runtest(self):
        env = dict(os.environ)
        env["PATH"] = str(Path(sys.executable).parent) + os.pathsep + env.get("PATH", "")
        env.setdefault("MESHMOCAP_PROGRESS_SECONDS", "3600")
        env.pop("COLUMNS", None)
        root = _session_root()
        env.setdefault("MESHMOCAP_CACHE", str(root / "cache"))
        folder = root / "page"
        shutil.rmtree(folder, ignore_errors=True)
        folder.mkdir()
        try:
            for block in sessions(self.path.read_text()):
                for cmd, expected, lineno in block:
                    self._run(cmd, expected, lineno, folder, env)
        finally:
            shutil.rmtree(folder, ignore_errors=True)

    def _run(self, cmd, expected, lineno, folder, env):
        r = subprocess.run(
            ["bash", "-c", cmd],
            cwd=folder,
            env=env,
            capture_output=True,
            text=True,
            check=False,
        )
        where = f"{self.path.name}:{lineno}: $ {cmd}"
        if r.returncode != 0:
            raise AssertionError(
                f"{where}\nexit status {r.returncode}\n{r.stdout[-3000:]}{r.stderr[-3000:]}"
            )
        problem = check_output(expected, r.stdout)
        if problem:
            raise AssertionError(f"{where}\n{problem}\nstdout:\n{r.stdout[-3000:]}")

    def reportinfo(self):
        return self.path, 0, f"console sessions of {self.path.name}"
