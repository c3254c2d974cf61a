"""Compiled loops (numba) of the io layer, imported on first use: a capture frame's hull
mesh unpacked (:func:`mesh_extent_kernel`, :func:`mesh_vertices_kernel`,
:func:`mesh_faces_kernel`, behind :func:`~meshmocap.io.capture.read_hull_mesh`), and the
usual silhouette mask file decoded without Pillow (:func:`grey8`).

The usual mask file is an 8-bit greyscale, non-interlaced PNG of one image stream
(``IHDR``, ``IDAT``…, ``IEND``), what :func:`~meshmocap.io.silhouettes.write_mask` and
most tools write. Its rows are inflated at once, the exact size asked for, and unfiltered
by one compiled pass (:func:`unfilter_kernel`), which also says whether the image is
binary. Any other file, or anything unexpected in this one, is left to Pillow
(:func:`grey8`: None), so every answer is Pillow's: the same grey values, the same
errors.

A mask's image data inflates to a few hundred times its size, almost all of it long
copies of the byte before or of the row above, which ``zlib`` writes a byte at a time
(~0.5 ms a 640 × 480 mask). :func:`inflate_kernel` decodes such a stream itself (RFC 1950
and 1951, the way ``zlib`` reads them: the same rules for the Huffman codes it accepts)
and writes each copy as one block; its output counts only with the stream's own Adler-32
checksum matching (:func:`kernel_inflated`), and anything it does not decode to the end, or
a stream mostly of literals, is inflated by ``zlib`` as before (:func:`inflated`)."""

from __future__ import annotations

import struct
import zlib

import numpy as np

from meshmocap._numba import njit

__all__ = [
    "grey8",
    "inflate_kernel",
    "inflated",
    "kernel_inflated",
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
    raw = inflated(b"".join(idat), size)
    if raw is None:
        return None
    grey = np.empty((h, w), dtype=np.uint8)
    top = unfilter_kernel(raw, grey)
    if top < 0:  # a filter type PNG does not have
        return None
    return grey, int(top & 255), bool(top >> 8)


#: Bytes out per byte in below which :func:`inflated` leaves a stream to ``zlib`` at once:
#: :func:`inflate_kernel` reads its codes a bit at a time, slower than ``zlib``'s tables
#: where most of the output is literals (a hull file's mesh, 3–15 to one: 2.5–7.5 times
#: slower), faster where it is long copies (a mask, 150–330 to one: 4 times faster).
KERNEL_RATIO = 64


def inflated(stream: bytes, size: int) -> np.ndarray | None:
    """(size,) uint8: the zlib ``stream`` (RFC 1950) inflated, when it holds exactly
    ``size`` bytes and nothing follows it; None otherwise (a damaged stream included).
    Decoded by :func:`kernel_inflated` where it can and the stream inflates
    :data:`KERNEL_RATIO`-fold or more; anything else by ``zlib``, as
    ``zlib.decompressobj`` answers (the same bytes, the same refusals)."""
    if size >= KERNEL_RATIO * len(stream):
        out = kernel_inflated(stream, size)
        if out is not None:
            return out
    z = zlib.decompressobj()
    try:
        raw = z.decompress(stream, size + 1)
    except zlib.error:
        return None
    if len(raw) != size or not z.eof or z.unused_data or z.unconsumed_tail:
        return None
    return np.frombuffer(raw, dtype=np.uint8)


def kernel_inflated(stream: bytes, size: int) -> np.ndarray | None:
    """(size,) uint8: the zlib ``stream`` inflated by :func:`inflate_kernel`, where it
    decodes the stream to its end, exactly ``size`` bytes, with nothing after its checksum
    and the checksum (Adler-32) that of the bytes; None where it cannot tell."""
    out = np.empty(size, dtype=np.uint8)
    end = inflate_kernel(np.frombuffer(stream, dtype=np.uint8), out)
    if end >= 0 and end + 4 == len(stream) and zlib.adler32(out) == _adler(stream, end):
        return out
    return None


def _adler(stream: bytes, end: int) -> int:
    """The Adler-32 checksum a zlib stream stores after its last block, at ``end``."""
    return struct.unpack_from(">I", stream, end)[0]


#: The order of the code length code's lengths in a dynamic block's header (RFC 1951 3.2.7).
CODE_LENGTH_ORDER = np.array(
    [16, 17, 18, 0, 8, 7, 9, 6, 10, 5, 11, 4, 12, 3, 13, 2, 14, 1, 15], dtype=np.int64
)
#: Each length code's (257…285) base length and extra bits (RFC 1951 3.2.5).
LENGTH_BASE = np.array(
    [3, 4, 5, 6, 7, 8, 9, 10, 11, 13, 15, 17, 19, 23, 27, 31, 35, 43, 51, 59, 67, 83, 99, 115]
    + [131, 163, 195, 227, 258],
    dtype=np.int64,
)
LENGTH_EXTRA = np.array([0] * 8 + [1] * 4 + [2] * 4 + [3] * 4 + [4] * 4 + [5] * 4 + [0])
#: Each distance code's (0…29) base distance and extra bits.
DISTANCE_BASE = np.array(
    [1, 2, 3, 4, 5, 7, 9, 13, 17, 25, 33, 49, 65, 97, 129, 193, 257, 385, 513, 769, 1025]
    + [1537, 2049, 3073, 4097, 6145, 8193, 12289, 16385, 24577],
    dtype=np.int64,
)
DISTANCE_EXTRA = np.array([0, 0] + [(k - 2) // 2 for k in range(2, 30)])


@njit(cache=True, nogil=True)
def _bits(data, state, need):  # pragma: no cover - compiled
    """The next ``need`` (0…16) bits of ``data``, least significant first, from the reader
    ``state`` (byte position, bit buffer, bits in it); −1 past the end."""
    pos, buf, have = state[0], state[1], state[2]
    while have < need:
        if pos >= data.shape[0]:
            return -1
        buf |= np.int64(data[pos]) << have
        pos += 1
        have += 8
    state[0], state[1], state[2] = pos, buf >> need, have - need
    return buf & ((np.int64(1) << need) - 1)


@njit(cache=True, nogil=True)
def _decode(data, state, count, symbol):  # pragma: no cover - compiled
    """The next symbol of the canonical Huffman code of ``count`` (16,) codes per length
    and ``symbol`` (its symbols by code), read a bit at a time; −1 for a code it does not
    have or past the end."""
    code = first = index = 0
    for length in range(1, 16):
        b = _bits(data, state, 1)
        if b < 0:
            return -1
        code |= b
        n = count[length]
        if code - n < first:
            return symbol[index + code - first]
        index += n
        first = (first + n) << 1
        code <<= 1
    return -1


@njit(cache=True, nogil=True)
def _code(lengths, count, symbol, table):  # pragma: no cover - compiled
    """Fill ``count`` and ``symbol`` with the canonical code of the code ``lengths``;
    whether zlib accepts it (``inflate_table``): never over-subscribed, and incomplete
    only with codes of one bit and not for the code lengths (``table``)."""
    count[:] = 0
    for v in lengths:
        count[v] += 1
    longest = 0
    for length in range(15, 0, -1):
        if count[length]:
            longest = length
            break
    if longest == 0:  # no codes: any symbol read is refused
        return True
    left = 1
    for length in range(1, 16):
        left = (left << 1) - count[length]
        if left < 0:
            return False
    if left > 0 and (table or longest != 1):
        return False
    offset = np.zeros(16, dtype=np.int64)
    for length in range(1, 15):
        offset[length + 1] = offset[length] + count[length]
    for s in range(lengths.shape[0]):
        if lengths[s]:
            symbol[offset[lengths[s]]] = s
            offset[lengths[s]] += 1
    return True


@njit(cache=True, nogil=True)
def inflate_kernel(data, out):  # pragma: no cover - compiled
    """Inflate the zlib stream ``data`` (n,) uint8 into ``out`` (size,) uint8: the byte
    position of its Adler-32 checksum (after the last block), where it fills ``out``
    exactly; −1 where it cannot tell (a preset dictionary, a code zlib refuses, a distance
    before the start, more or fewer bytes than ``out``, the data cut short). Each copy is
    written as one block: the byte before repeated, or the bytes ``distance`` back."""
    n = data.shape[0]
    if n < 2:
        return -1
    cmf, flg = np.int64(data[0]), np.int64(data[1])
    if (cmf & 15) != 8 or (cmf >> 4) > 7 or (cmf * 256 + flg) % 31 != 0 or flg & 32:
        return -1
    state = np.array([2, 0, 0], dtype=np.int64)
    size = out.shape[0]
    o = 0
    lengths = np.zeros(320, dtype=np.int64)
    lcount = np.zeros(16, dtype=np.int64)
    lsymbol = np.zeros(288, dtype=np.int64)
    dcount = np.zeros(16, dtype=np.int64)
    dsymbol = np.zeros(32, dtype=np.int64)
    last = 0
    while last == 0:
        last = _bits(data, state, 1)
        kind = _bits(data, state, 2)
        if last < 0 or kind < 0 or kind == 3:
            return -1
        if kind == 0:  # stored: from the next byte, its length and the length's complement
            pos = state[0]
            state[1], state[2] = 0, 0
            if pos + 4 > n:
                return -1
            k = np.int64(data[pos]) | np.int64(data[pos + 1]) << 8
            if k != 0xFFFF ^ (np.int64(data[pos + 2]) | np.int64(data[pos + 3]) << 8):
                return -1
            pos += 4
            if pos + k > n or o + k > size:
                return -1
            out[o : o + k] = data[pos : pos + k]
            o += k
            state[0] = pos + k
            continue
        if kind == 1:  # the fixed codes (distance codes 30 and 31 refused when read)
            nlen, ndist = 288, 32
            lengths[:144] = 8
            lengths[144:256] = 9
            lengths[256:280] = 7
            lengths[280:288] = 8
            lengths[288:320] = 5
        else:  # the codes' lengths, themselves coded
            nlen = _bits(data, state, 5) + 257
            ndist = _bits(data, state, 5) + 1
            ncode = _bits(data, state, 4) + 4
            if nlen < 257 or ndist < 1 or ncode < 4 or nlen > 286 or ndist > 30:
                return -1
            lengths[:19] = 0
            for i in range(ncode):
                v = _bits(data, state, 3)
                if v < 0:
                    return -1
                lengths[CODE_LENGTH_ORDER[i]] = v
            if not _code(lengths[:19], lcount, lsymbol, True):
                return -1
            i = 0
            while i < nlen + ndist:
                sym = _decode(data, state, lcount, lsymbol)
                if sym < 0:
                    return -1
                if sym < 16:
                    lengths[i] = sym
                    i += 1
                    continue
                v = lengths[i - 1] if sym == 16 else 0  # a repeat of the last, or zeros
                e = _bits(data, state, (2, 3, 7)[sym - 16])
                k = e + (3, 3, 11)[sym - 16]
                if (sym == 16 and i == 0) or e < 0 or i + k > nlen + ndist:
                    return -1
                lengths[i : i + k] = v
                i += k
            if lengths[256] == 0:  # no end of block
                return -1
        if not _code(lengths[:nlen], lcount, lsymbol, False):
            return -1
        if not _code(lengths[nlen : nlen + ndist], dcount, dsymbol, False):
            return -1
        while True:
            sym = _decode(data, state, lcount, lsymbol)
            if sym < 0:
                return -1
            if sym < 256:
                if o >= size:
                    return -1
                out[o] = sym
                o += 1
                continue
            if sym == 256:
                break
            sym -= 257
            if sym >= 29:
                return -1
            e = _bits(data, state, LENGTH_EXTRA[sym])
            d = _decode(data, state, dcount, dsymbol)
            if e < 0 or d < 0 or d >= 30:
                return -1
            k = LENGTH_BASE[sym] + e
            e = _bits(data, state, DISTANCE_EXTRA[d])
            if e < 0:
                return -1
            dist = DISTANCE_BASE[d] + e
            if dist > o or o + k > size:
                return -1
            if dist >= k:  # apart: one block
                out[o : o + k] = out[o - dist : o - dist + k]
            elif dist == 1:  # the byte before, repeated
                out[o : o + k] = out[o - 1]
            else:
                for j in range(k):
                    out[o + j] = out[o - dist + j]
            o += k
    return state[0] if o == size else -1


@njit(cache=True, nogil=True)
def unfilter_kernel(raw, grey):  # pragma: no cover - compiled
    """Unfilter the inflated rows ``raw`` ((h (w + 1),) uint8: each row's filter type,
    then its bytes) into ``grey`` (h, w) uint8 (PNG's five filters for one byte a pixel:
    none, sub, up, average, Paeth). Returns the largest value, plus 256 where every value
    is 0 or 255; −1 for a filter type above 4. The rows first (a mask's, none and up, are
    copies and sums that vectorise), then the values' largest and kinds in one pass."""
    h, w = grey.shape
    if h == 0 or w == 0:
        return 256
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
                grey[y, x] = raw[s + x]
        elif f == 1:
            v = np.int64(raw[s])
            grey[y, 0] = v
            for x in range(1, w):
                v = (np.int64(raw[s + x]) + v) & 255
                grey[y, x] = v
        elif f == 2:
            for x in range(w):
                grey[y, x] = (np.int64(raw[s + x]) + np.int64(grey[y - 1, x])) & 255
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
    top = np.uint8(0)
    odd = 0  # values other than 0 and 255: 1…254, which less one are below 254
    for y in range(h):
        for x in range(w):
            v = grey[y, x]
            top = max(top, v)
            odd += np.uint8(v - np.uint8(1)) < np.uint8(254)
    return np.int64(top) if odd else np.int64(top) + 256


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
