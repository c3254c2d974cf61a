"""Archives of frame files read in place, never unpacked to disk: ``.tar``, ``.tar.gz``.

A gzip stream is indexed once (decompressor checkpoints every few MiB), so a member
anywhere in the archive costs a few MiB of decompression, not a pass over the archive.
Members are held to the mesh file-size limit of :mod:`meshmocap.io.meshes`, and an archive
to :data:`MAX_ARCHIVE_MEMBERS` members.
"""

from __future__ import annotations

import bisect
import tarfile
import zlib
from collections.abc import Callable
from pathlib import Path

from meshmocap.errors import FormatError

#: Most members an archive may list.
MAX_ARCHIVE_MEMBERS = 1_000_000


def _one_line(exc: BaseException) -> str:
    text = str(exc).strip().splitlines()
    return f"{type(exc).__name__}: {text[0] if text else ''}".rstrip(": ")


class TarArchive:
    """Members of a ``.tar`` or ``.tar.gz`` file, read by offset without unpacking
    (``check_size(size, label)`` refuses a member too large to read)."""

    def __init__(self, path: Path, check_size: Callable[[int, str], None]) -> None:
        self.path, self.gz = path, not str(path).lower().endswith(".tar")
        self._check_size = check_size
        self._index = GzipIndex() if self.gz else None
        try:
            with open(path, "rb") as f, tarfile.open(fileobj=self._raw(f), mode="r:") as tf:
                members = [m for m in tf.getmembers() if m.isreg()]
        except (tarfile.TarError, zlib.error, EOFError, OSError) as exc:
            raise FormatError(f"{path}: not a readable tar archive ({_one_line(exc)})") from None
        if len(members) > MAX_ARCHIVE_MEMBERS:
            raise FormatError(
                f"{path}: {len(members)} members, above the "
                f"{MAX_ARCHIVE_MEMBERS} an archive may hold"
            )
        self.names = [m.name for m in members]
        self._where = {m.name: (m.offset_data, m.size) for m in members}

    def _raw(self, f):
        return GzipReader(f, self._index) if self.gz else f

    def read(self, name: str) -> bytes:
        """Return the bytes of member ``name``."""
        offset, size = self._where[name]
        self._check_size(size, f"{self.path}::{name}")
        try:
            with open(self.path, "rb") as f:
                (raw := self._raw(f)).seek(offset)
                data = raw.read(size)
        except (zlib.error, EOFError, OSError) as exc:
            raise FormatError(f"{self.path}::{name}: cannot read ({_one_line(exc)})") from None
        if len(data) != size:
            raise FormatError(f"{self.path}::{name}: truncated ({len(data)} of {size} bytes)")
        return data

    def __getstate__(self) -> dict:  # zlib states do not pickle: the index is rebuilt
        return {**self.__dict__, "_index": GzipIndex() if self.gz else None}


class GzipIndex:
    """Decompressor snapshots ``(uncompressed offset, compressed offset, zlib state)``.

    One is taken every ``spacing`` uncompressed bytes the first time the stream is
    decompressed that far; past ``max_points`` every other one is dropped and the spacing
    doubled (each holds ~40 KiB: zlib's 32 KiB window and state).

    ``cursor`` is where the last read stopped (a reader's whole state: its uncompressed
    bytes in hand too), so members read in order (a sequence tracked frame by frame)
    decompress each byte once instead of from the last snapshot each time.
    """

    def __init__(self, spacing: int = 1 << 20, max_points: int = 1024) -> None:
        self.spacing, self.max_points = spacing, max_points
        self.points: list[tuple[int, int, object]] = [(0, 0, None)]
        #: ``(u, c, zlib state, bytes in hand from u, at the end)`` after the last read
        self.cursor: tuple[int, int, object, bytes, bool] | None = None

    def add(self, u: int, c: int, d) -> None:
        """Keep a copy of decompressor ``d`` at uncompressed offset ``u`` and compressed
        offset ``c`` if it is ``spacing`` past the last snapshot."""
        if u - self.points[-1][0] >= self.spacing:
            self.points.append((u, c, d.copy()))
            if len(self.points) > self.max_points:
                self.points, self.spacing = self.points[::2], 2 * self.spacing

    def best(self, u: int) -> tuple[int, int, object]:
        """The last snapshot at or before uncompressed offset ``u``."""
        return self.points[bisect.bisect_right([p[0] for p in self.points], u) - 1]


class GzipReader:
    """A seekable, read-only file over a (multi-member) gzip file, through a :class:`GzipIndex`.

    ``_buf`` holds the uncompressed bytes ``[_u, _u + len(_buf))``; ``_c`` is the compressed
    offset of the next input byte; ``_d`` has consumed all input before ``_c``.
    """

    _CHUNK = 1 << 16

    def __init__(self, f, index: GzipIndex) -> None:
        self._f, self._index, self._pos = f, index, 0
        self._restore(index.points[0])

    def _restore(self, point) -> None:
        u, c, d = point
        self._d = d.copy() if d is not None else zlib.decompressobj(31)
        self._c, self._u, self._buf, self._end = c, u, b"", False

    def _step(self) -> None:
        self._u += len(self._buf)
        self._f.seek(self._c)
        chunk = self._f.read(self._CHUNK)
        self._c += len(chunk)
        if not chunk:
            if not self._d.eof:
                raise EOFError("gzip stream ends early (truncated archive)")
            self._buf, self._end = b"", True
            return
        out = [self._d.decompress(chunk)]
        while self._d.eof:  # end of a gzip member: another may follow
            rest = self._d.unused_data
            if len(rest) < 2:  # the next member's magic may straddle the chunk
                more = self._f.read(2 - len(rest))
                self._c, rest = self._c + len(more), rest + more
            if not rest.startswith(b"\x1f\x8b"):  # padding or nothing: the stream ends
                self._end = True
                break
            self._d = zlib.decompressobj(31)
            out.append(self._d.decompress(rest))
        self._buf = b"".join(out)
        if not self._end:
            self._index.add(self._u + len(self._buf), self._c, self._d)

    def tell(self) -> int:
        """The uncompressed read position."""
        return self._pos

    def seek(self, offset: int, whence: int = 0) -> int:
        """Move the uncompressed read position, as ``io.IOBase.seek`` does."""
        if whence == 2:
            while not self._end:
                self._step()
        base = {0: 0, 1: self._pos, 2: self._u + len(self._buf)}[whence]
        self._pos = max(0, base + offset)
        return self._pos

    def read(self, n: int = -1) -> bytes:
        """At most ``n`` uncompressed bytes from the read position (all of them: ``-1``),
        resumed from the nearest snapshot before it, or from where the last read stopped
        (the index's ``cursor``) where that is nearer."""
        point = self._index.best(self._pos)
        cur = self._index.cursor
        here = self._u if self._u <= self._pos else -1  # this reader's own state
        if cur is not None and max(here, point[0]) < cur[0] <= self._pos:
            u, c, d, buf, end = cur
            self._d, self._c, self._u, self._buf, self._end = d.copy(), c, u, buf, end
        elif self._pos < self._u or point[0] > self._u + len(self._buf):
            self._restore(point)
        end, parts = self._pos + n if n >= 0 else 1 << 62, []
        while self._pos < end:
            while self._pos >= self._u + len(self._buf) and not self._end:
                self._step()
            piece = self._buf[self._pos - self._u : end - self._u]
            if not piece:
                break
            parts.append(piece)
            self._pos += len(piece)
        self._index.cursor = (self._u, self._c, self._d.copy(), self._buf, self._end)
        return b"".join(parts)
