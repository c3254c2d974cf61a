"""The ``meshmocap`` command: a thin shell over the library.

Every subcommand parses its arguments, calls library functions and prints a short summary.
Each module of this package holds a few commands and a ``register(sub)`` that adds their
parsers; a new command is a new module listed in :data:`COMMANDS`. Errors the user can fix
(a missing file, a malformed BVH, a bad option) are printed as one line
``meshmocap: error: ...`` with exit status 2, never a traceback.
"""

from __future__ import annotations

import argparse
import os
import sys
import warnings
from collections.abc import Sequence
from typing import NoReturn

from meshmocap import __version__
from meshmocap._threads import blas_threads
from meshmocap.cli import (
    batch,
    capture,
    demo,
    evaluation,
    export,
    gait,
    motion,
    subject,
    track,
)
from meshmocap.errors import MeshmocapError, MeshmocapWarning

#: Command modules, in the order ``meshmocap --help`` lists their commands.
COMMANDS = (demo, motion, capture, subject, track, evaluation, batch, export, gait)


class _Parser(argparse.ArgumentParser):
    """Parse errors in one line, ``meshmocap: error: COMMAND: ...`` (status 2), like every
    other user mistake, instead of argparse's usage block."""

    def error(self, message: str) -> NoReturn:
        command = self.prog.split(" ", 1)[1] + ": " if " " in self.prog else ""
        print(f"meshmocap: error: {command}{message} (see {self.prog} --help)", file=sys.stderr)
        raise SystemExit(2)


def build_parser() -> argparse.ArgumentParser:
    """Return the argument parser of the ``meshmocap`` command."""
    p = _Parser(
        prog="meshmocap", description="Markerless human performance capture from 3D mesh sequences."
    )
    p.add_argument("--version", action="version", version=f"meshmocap {__version__}")
    sub = p.add_subparsers(dest="command", required=True, metavar="COMMAND")
    for module in COMMANDS:
        module.register(sub)
    return p


def main(argv: Sequence[str] | None = None) -> int:
    """Run the ``meshmocap`` command; return its exit status."""
    try:
        args = build_parser().parse_args(argv)
    except SystemExit as exc:  # --help, --version, or a parse error already printed
        return exc.code if isinstance(exc.code, int) else 2
    try:
        # one BLAS thread while the command runs (MESHMOCAP_THREADS), and warnings in one line
        with blas_threads(), warnings.catch_warnings():
            warnings.simplefilter("default", MeshmocapWarning)
            warnings.showwarning = _show_warning
            return int(args.func(args))
    except MeshmocapError as exc:
        print(f"meshmocap: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("meshmocap: interrupted", file=sys.stderr)
        return 130
    except BrokenPipeError:  # `meshmocap eval ... | head`: the reader left, not an error
        # keep the interpreter's final flush from raising again on the closed pipe
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 0


def _show_warning(message, category, filename, lineno, file=None, line=None) -> None:
    print(f"meshmocap: warning: {message}", file=sys.stderr)
