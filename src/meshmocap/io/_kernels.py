"""Compiled loops (numba) of the io layer, imported on first use: a capture frame's hull
mesh unpacked (:func:`mesh_extent_kernel`, :func:`mesh_vertices_kernel`,
:func:`mesh_faces_kernel`, behind :func:`~meshmocap.io.capture.read_hull_mesh`), and the
usual silhouette mask file decoded without Pillow (:func:`grey8`).

The usual mask file is an 8-bit greyscale, non-interlaced PNG of one image stream
(``IHDR``, ``IDAT``…, ``IEND``), what :func:`~meshmocap.io.silhouettes.write_mask` and
most tools write. Its rows are inflated at once (``zlib``, the exact size asked for) and
unfiltered by one compiled pass (:func:`unfilter_kernel`), which also says whether the
image is binary. Any other file, or anything unexpected in this one, is left to Pillow
(:func:`grey8`: None), so every answer is Pillow's: the same grey values, the same
errors."""

from __future__ import annotations

import struct
import zlib

import numpy as np

from meshmocap._numba import njit

__all__ = [
    "grey8",
    "mesh_extent_kernel",
    "mesh_faces_kernel",
    "mesh_vertices_kernel",
    "unfilter_kernel",
]

#: The eight bytes every PNG file starts with.
SIGNATURE = b"\x89PNG\r\n\x1a\n"


def grey8(data: bytes, max_pixels: int | None) -> tuple[np.ndarray, int, bool] | None:
    """The grey values of the PNG file ``data`` when it is the usual mask (module
    docstring) of at most ``max_pixels`` pixels (None: no limit), with their largest value
    and whether each is 0 or 255: ``(grey (h, w) uint8, max, binary)``; None for any other
    file, a damaged one included (Pillow reads those)."""
    if data[:8] != SIGNATURE or len(data) < 8 + 25:
        return None
    pos, idat, header = 8, [], None
    while True:
        if pos + 12 > len(data):
            return None
        n, kind = struct.unpack_from(">I4s", data, pos)
        end = pos + 8 + n
        if end + 4 > len(data):
            return None
        if kind == b"IDAT" and header is not None:
            idat.append(data[pos + 8 : end])
        elif kind == b"IHDR" and pos == 8 and n == 13:
            crc = struct.unpack_from(">I", data, end)[0]
            if zlib.crc32(data[pos + 4 : end]) != crc:  # Pillow checks the header's
                return None
            header = struct.unpack_from(">IIBBBBB", data, pos + 8)
        elif kind == b"IEND" and idat:
            break
        else:  # any other chunk, or these out of order: Pillow's
            return None
        pos = end + 4
    w, h, depth, colour, method, filtering, interlace = header
    if (depth, colour, method, filtering, interlace) != (8, 0, 0, 0, 0) or not 0 < w < 1 << 24:
        return None
    if not 0 < h < 1 << 24 or (max_pixels is not None and w * h > max_pixels):
        return None
    size = h * (w + 1)  # each row: its filter byte, then its pixels
    z = zlib.decompressobj()
    try:
        raw = z.decompress(b"".join(idat), size + 1)
    except zlib.error:
        return None
    if len(raw) != size or not z.eof or z.unused_data or z.unconsumed_tail:
        return None
    grey = np.empty((h, w), dtype=np.uint8)
    top = unfilter_kernel(np.frombuffer(raw, dtype=np.uint8), grey)
    if top < 0:  # a filter type PNG does not have
        return None
    return grey, int(top & 255), bool(top >> 8)


@njit(cache=True, nogil=True)
def unfilter_kernel(raw, grey):  # pragma: no cover - compiled
    """Unfilter the inflated rows ``raw`` ((h (w + 1),) uint8: each row's filter type,
    then its bytes) into ``grey`` (h, w) uint8 (PNG's five filters for one byte a pixel:
    none, sub, up, average, Paeth). Returns the largest value, plus 256 where every value
    is 0 or 255; −1 for a filter type above 4."""
    h, w = grey.shape
    if h == 0 or w == 0:
        return 256
    top = 0
    odd = False  # values other than 0 and 255 seen
    for y in range(h):
        s = y * (w + 1)
        f = raw[s]
        s += 1
        if f > 4:
            return -1
        if y == 0 and f == 2:  # up from above the image: none
            f = 0
        if f == 0:
            for x in range(w):
                v = np.int64(raw[s + x])
                grey[y, x] = v
                top = max(top, v)
                odd |= (v != 0) & (v != 255)
        elif f == 1:
            v = np.int64(raw[s])
            grey[y, 0] = v
            top = max(top, v)
            odd |= (v != 0) & (v != 255)
            for x in range(1, w):
                v = (np.int64(raw[s + x]) + v) & 255
                grey[y, x] = v
                top = max(top, v)
                odd |= (v != 0) & (v != 255)
        elif f == 2:
            for x in range(w):
                v = (np.int64(raw[s + x]) + np.int64(grey[y - 1, x])) & 255
                grey[y, x] = v
                top = max(top, v)
                odd |= (v != 0) & (v != 255)
        else:
            a = 0
            for x in range(w):
                b = np.int64(grey[y - 1, x]) if y > 0 else 0
                r = np.int64(raw[s + x])
                if f == 3:
                    v = (r + (a + b) // 2) & 255
                else:
                    c = np.int64(grey[y - 1, x - 1]) if x > 0 and y > 0 else 0
                    p = a + b - c
                    pa, pb, pc = abs(p - a), abs(p - b), abs(p - c)
                    if pa <= pb and pa <= pc:
                        v = (r + a) & 255
                    elif pb <= pc:
                        v = (r + b) & 255
                    else:
                        v = (r + c) & 255
                grey[y, x] = v
                a = v
                top = max(top, v)
                odd |= (v != 0) & (v != 255)
    return top if odd else top + 256


@njit(cache=True, nogil=True)
def mesh_extent_kernel(dK, lo, hi):  # pragma: no cover - compiled
    """Into ``lo``, ``hi`` (3,) int64: the smallest and largest of each column of the
    running sums of ``dK`` (n, 3) int16 or int32 (a hull mesh's vertices as half-voxel
    steps, :func:`~meshmocap.io.capture.write_hull`)."""
    k0 = k1 = k2 = 0
    for c in range(3):
        lo[c] = hi[c] = dK[0, c]  # the first running sums
    for i in range(dK.shape[0]):
        k0 += dK[i, 0]
        k1 += dK[i, 1]
        k2 += dK[i, 2]
        lo[0], hi[0] = min(lo[0], k0), max(hi[0], k0)
        lo[1], hi[1] = min(lo[1], k1), max(hi[1], k1)
        lo[2], hi[2] = min(lo[2], k2), max(hi[2], k2)


@njit(cache=True, nogil=True)
def mesh_vertices_kernel(dK, t0, t1, t2, lo, V):  # pragma: no cover - compiled
    """Into ``V`` (n, 3) float64: each column's running sum of ``dK`` (as
    :func:`mesh_extent_kernel`'s) looked up in its table ``t0``, ``t1``, ``t2`` (float32,
    from the column's smallest sum ``lo[c]`` on)."""
    k0 = k1 = k2 = 0
    for i in range(dK.shape[0]):
        k0 += dK[i, 0]
        k1 += dK[i, 1]
        k2 += dK[i, 2]
        V[i, 0] = t0[k0 - lo[0]]
        V[i, 1] = t1[k1 - lo[1]]
        V[i, 2] = t2[k2 - lo[2]]


@njit(cache=True, nogil=True)
def mesh_faces_kernel(dtop, below, F):  # pragma: no cover - compiled
    """Into ``F`` (m, 3) int64: each triangle's corners, ``top − below`` with ``top`` the
    running sum of ``dtop`` (m,) and ``below`` (m, 3) (unsigned integers of at most 4
    bytes)."""
    top = 0
    for f in range(F.shape[0]):
        top += dtop[f]
        for j in range(3):
            F[f, j] = top - below[f, j]
