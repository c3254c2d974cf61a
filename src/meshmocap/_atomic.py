"""Atomic file writes: a result is either complete or absent, never half-written."""

from __future__ import annotations

import os
import tempfile
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import IO, Literal

from meshmocap.errors import FolderBusyError, MeshmocapFileNotFoundError


@contextmanager
def atomic_open(path: str | os.PathLike, mode: Literal["w", "wb"] = "wb") -> Iterator[IO]:
    """Open a temporary file beside ``path`` for writing; on success it replaces ``path``.

    On any exception the temporary file is removed and ``path`` is left untouched. Text mode
    writes UTF-8 with ``\\n`` line endings. An existing file keeps its permissions.

    Raises
    ------
    MeshmocapFileNotFoundError
        The destination folder does not exist.
    """
    path = Path(path)
    if not path.parent.is_dir():
        raise MeshmocapFileNotFoundError(f"{path}: folder {path.parent} does not exist")
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    try:
        kwargs = {"encoding": "utf-8", "newline": "\n"} if mode == "w" else {}
        with os.fdopen(fd, mode, **kwargs) as f:
            yield f
        os.chmod(tmp, path.stat().st_mode & 0o777 if path.exists() else 0o644)
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def write_text_atomic(path: str | os.PathLike, text: str) -> None:
    """Write ``text`` to ``path`` atomically (see :func:`atomic_open`)."""
    with atomic_open(path, "w") as f:
        f.write(text)


def write_bytes_atomic(path: str | os.PathLike, data: bytes) -> Path:
    """Write ``data`` to ``path`` atomically (see :func:`atomic_open`); return the path."""
    with atomic_open(path, "wb") as f:
        f.write(data)
    return Path(path)


#: The lock file :func:`folder_lock` holds in the folder it guards.
LOCK_NAME = ".meshmocap.lock"


@contextmanager
def folder_lock(folder: str | os.PathLike, what: str) -> Iterator[None]:
    """Hold an exclusive lock on ``folder`` while writing into it.

    The lock is ``fcntl.flock`` on ``folder/.meshmocap.lock``, holding the writer's
    process id. The kernel releases it when the process ends, however it ends (``kill -9``
    included), so a crashed run never leaves a stuck lock (only the file, which the next
    run takes over); when the ``with`` block ends, the file is removed while still locked,
    so a folder left by a finished run holds no lock file. A process that opened the file
    before it was removed finds, once it holds the lock, that the name now points to
    another file (or none) and tries again. Where ``fcntl`` is not available (Windows)
    nothing is locked.

    Raises
    ------
    FolderBusyError
        Another process holds the lock (the message names its process id).
    """
    try:
        import fcntl
    except ImportError:  # pragma: no cover (Windows)
        yield
        return
    path = Path(folder) / LOCK_NAME
    while True:
        fd = os.open(path, os.O_RDWR | os.O_CREAT, 0o644)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            pid = os.pread(fd, 32, 0).decode("ascii", "replace").strip() or "?"
            os.close(fd)
            raise FolderBusyError(
                f"{what}: {folder} is being written by another meshmocap process (pid {pid}); "
                "wait for it to finish or write to another folder"
            ) from None
        if _same_file(fd, path):
            break
        os.close(fd)  # the holder removed it as we opened it: lock the new one
    try:
        os.ftruncate(fd, 0)
        os.pwrite(fd, f"{os.getpid()}\n".encode(), 0)
        yield
    finally:
        try:
            if _same_file(fd, path):
                path.unlink()  # still locked: nobody else holds this file
        finally:
            os.close(fd)  # releases the lock


def _same_file(fd: int, path: Path) -> bool:
    """Whether ``path`` still names the open file ``fd``."""
    try:
        st = path.stat()
    except FileNotFoundError:
        return False
    own = os.fstat(fd)
    return (st.st_dev, st.st_ino) == (own.st_dev, own.st_ino)
