"""The ``meshmocap`` command: a thin shell over the library.

Every subcommand parses its arguments, calls library functions and prints a short summary.
Each module of this package holds a few commands and a ``register(sub)`` that adds their
parsers; a new command is a new module listed in :data:`COMMANDS`. Errors the user can fix
(a missing file, a malformed BVH, a bad option, an ``--out`` that cannot be written) are
printed as one line ``meshmocap: error: ...`` with exit status 2, never a traceback. An
``OSError`` or ``MemoryError`` met while working (a disk that fills, a mesh too large for
memory) also ends in one line, naming the path or the inputs and the cause, with exit
status 1.

Before a command runs, every path it writes (``--out``, and ``learn --plot``, ``bench
--work``, ``track --recording``) is checked (:func:`meshmocap.io.guards.check_output_path`):
a file where a folder is expected or the reverse, a read-only or unwritable place, and any
path in a track folder (only ``track`` writes there) are refused.
"""

from __future__ import annotations

import argparse
import os
import sys
import warnings
from collections.abc import Sequence
from pathlib import Path
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
    learn,
    motion,
    subject,
    track,
    transfer,
)
from meshmocap.errors import MeshmocapError, MeshmocapWarning
from meshmocap.io.guards import OutputKind, check_apart_from_inputs, check_output_path

#: Command modules, in the order ``meshmocap --help`` lists their commands.
COMMANDS = (demo, motion, capture, subject, track, learn, transfer, evaluation, batch, export, gait)

#: What each writing command's ``out`` argument names: a file or a folder.
OUTPUTS: dict[str, OutputKind] = {
    "export": "file",
    "report": "file",
    "subject": "file",
    "learn": "file",
    "retarget": "file",
    "track": "folder",
    "synth": "folder",
    "silhouettes": "folder",
    "eval": "folder",
    "batch": "folder",
    "bench": "folder",
    "demo": "folder",
    "gait": "folder",
    "render": "folder",
    "transfer": "folder",
}


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
        check_outputs(args)
        # one BLAS thread while the command runs (MESHMOCAP_THREADS), and the library's
        # warnings in one line each, on stderr
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
    except OSError as exc:  # a disk that fills, a folder removed while writing, ...
        print(f"meshmocap: error: {args.command}: {os_error_line(exc)}", file=sys.stderr)
        return 1
    except MemoryError as exc:
        print(f"meshmocap: error: {args.command}: {memory_error_line(exc, args)}", file=sys.stderr)
        return 1


#: Other paths a command writes, besides its ``out``: (argument, flag, file or folder).
OTHER_OUTPUTS: dict[str, tuple[tuple[str, str, OutputKind], ...]] = {
    "learn": (("plot", "--plot", "file"),),
    "bench": (("work", "--work", "folder"),),
    "track": (("recording", "--recording", "file"),),
}


def check_outputs(args: argparse.Namespace) -> None:
    """Refuse a path the command would write but cannot, or one in a track folder: only
    ``track`` writes there (into its own ``--out``: a track folder it resumes, and the
    live view's ``--recording``). One check for every path every command writes."""
    out = getattr(args, "out", None)
    kind = OUTPUTS.get(args.command)
    paths = [] if kind is None or out is None else [("--out", out, kind)]
    if args.command == "synth":
        paths = [("OUT", out, kind)]
    for name, flag, what in OTHER_OUTPUTS.get(args.command, ()):
        if getattr(args, name, None) is not None:
            paths.append((flag, getattr(args, name), what))
    if args.command == "track" and out is not None:  # never among what it reads
        check_apart_from_inputs(out, args.capture, command="track")
    for flag, path, what in paths:
        own = args.command == "track" and flag != "--out" and _inside(path, out)
        if own:  # the live view's recording, in the track folder this run writes
            continue
        track_ok = args.command == "track"  # resumed, or refused there if made otherwise
        check_output_path(
            path, kind=what, command=args.command, flag=flag, track_folder_ok=track_ok
        )


def _inside(path: str, folder: str | None) -> bool:
    """Whether ``path`` lies in ``folder``."""
    if folder is None:
        return False
    return Path(os.path.abspath(folder)) in Path(os.path.abspath(path)).parents


def os_error_line(exc: OSError) -> str:
    """``PATH: cause`` of an ``OSError`` (both paths of a rename), in one line."""
    cause = exc.strerror or type(exc).__name__
    paths = [p for p in (exc.filename, exc.filename2) if p is not None]
    if not paths:
        return cause if exc.strerror else f"{cause}: {(str(exc) or 'no detail').splitlines()[0]}"
    return f"{' -> '.join(map(str, paths))}: {cause}"


def memory_error_line(exc: MemoryError, args: argparse.Namespace) -> str:
    """What ran out of memory, on which inputs, in one line."""
    inputs: list[str] = []
    for k in ("capture", "track", "mesh", "sources", "captures"):
        v = getattr(args, k, None)
        inputs += [] if v is None else [v] if isinstance(v, str) else [str(x) for x in v[:2]]
    detail = str(exc).splitlines()[0] if str(exc) else "no detail"
    on = f" on {', '.join(inputs)}" if inputs else ""
    return f"out of memory{on} ({detail}); try a smaller input or a machine with more memory"


def _show_warning(message, category, filename, lineno, file=None, line=None) -> None:
    print(f"meshmocap: warning: {message}", file=sys.stderr)
