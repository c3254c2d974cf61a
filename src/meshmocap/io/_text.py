"""Shared helpers of the text-format readers and writers (BVH, ASF/AMC): fast tokenising,
number parsing with line-accurate errors, frame selections and atomic writes."""

from __future__ import annotations

import math
import os
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from meshmocap.errors import FormatError, InputError, MeshmocapFileNotFoundError, where

#: A frame selection: all frames (None), a slice, or frame indices.
FrameSelection = slice | Sequence[int] | np.ndarray | None

_WS = np.zeros(256, dtype=bool)
_WS[[9, 10, 11, 12, 13, 32]] = True  # the bytes bytes.split() splits on


def read_bytes(path: str | os.PathLike[str]) -> bytes:
    """Return the bytes of the file ``path``; :class:`MeshmocapFileNotFoundError` if absent."""
    p = Path(path)
    if not p.is_file():
        what = "is a folder, not a file" if p.is_dir() else "no such file"
        raise MeshmocapFileNotFoundError(f"{path}: {what}")
    data = p.read_bytes()
    if b"\n" not in data:  # old Mac line endings: CR only
        data = data.replace(b"\r", b"\n")
    return data


def scan_tokens(data: bytes) -> tuple[np.ndarray, np.ndarray]:
    """Return the byte offset and 0-based line index (int64) of every token of ``data.split()``.

    Vectorised over the bytes; lines end at ``\\n``.
    """
    b = np.frombuffer(data, dtype=np.uint8)
    if b.size == 0:
        return np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64)
    ws = _WS[b]
    starts = np.flatnonzero(~ws & np.concatenate(([True], ws[:-1])))
    return starts, np.searchsorted(np.flatnonzero(b == 10), starts)


def parse_floats(tokens: list[bytes], lines: np.ndarray, path: object) -> np.ndarray:
    """Return ``tokens`` as float64, or raise :class:`FormatError` naming the bad token's line.

    ``lines`` holds each token's 1-based line number (only read on the error path).
    """
    try:
        values = np.array(tokens, dtype=np.float64)
    except (ValueError, OverflowError):
        values = None
    if values is not None and np.all(np.isfinite(values)):
        return values
    for k, tok in enumerate(tokens):  # error path only: find the culprit
        text = tok.decode("utf-8", errors="replace")
        try:
            x = float(tok)
        except ValueError:
            raise FormatError(
                f"{where(path, int(lines[k]))}: expected a number, found {text!r}"
            ) from None
        if not math.isfinite(x):
            raise FormatError(f"{where(path, int(lines[k]))}: non-finite value {text!r}")
    raise FormatError(f"{path}: could not read the numbers")  # pragma: no cover


def frame_index(n: int, frames: FrameSelection, func: str) -> tuple[np.ndarray, int]:
    """Return (indices, step) of a frame selection of ``n`` frames; step divides the frame rate.

    Raises :class:`InputError` for an empty selection, out-of-range indices or a non-positive
    slice step.
    """
    if frames is None:
        return np.arange(n), 1
    if isinstance(frames, slice):
        if frames.step is not None and frames.step <= 0:
            raise InputError(f"{func}: frames slice step must be positive, found {frames.step}")
        r = range(n)[frames]
        idx, step = np.arange(r.start, r.stop, r.step), r.step
    else:
        idx, step = np.asarray(frames), 1
        if idx.ndim != 1 or not np.issubdtype(idx.dtype, np.integer):
            raise InputError(f"{func}: frames must be a slice or 1-D integers, found {idx!r}")
        if np.any((idx < -n) | (idx >= n)):
            raise InputError(f"{func}: frames must lie in [-{n}, {n}), found {idx.max()}")
        idx = idx % n if n else idx
    if idx.size == 0:
        raise InputError(f"{func}: frame selection {frames!r} selects no frame of {n}")
    return idx, step
