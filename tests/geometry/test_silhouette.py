"""Silhouette rasterisation and PNG mask files."""

import re
import struct
import warnings
import zlib

import numpy as np
import pytest
import trimesh
from PIL import Image

from meshmocap.errors import FormatError, GreyMaskWarning, InputError, MeshmocapFileNotFoundError
from meshmocap.geometry.camera import Camera, intrinsics, look_at
from meshmocap.geometry.raster import coverage, rasterize
from meshmocap.geometry.silhouette import covered_pixels, fill_triangles, silhouette
from meshmocap.io.silhouettes import read_mask, write_mask
from meshmocap.studio.rigs import camera_rig


def _camera(eye, target=(0, 0, 0.9), *, dist=None, fov=50.0) -> Camera:
    R, t = look_at(eye, target)
    return Camera(intrinsics(640, 480, fov), R, t, 640, 480, dist)


def _lumpy_sphere(seed: int) -> tuple[np.ndarray, np.ndarray]:
    """A closed, consistently oriented random mesh: an icosphere with random radii."""
    m = trimesh.creation.icosphere(subdivisions=3, radius=1.0)
    r = np.random.default_rng(seed).uniform(0.25, 0.45, len(m.vertices))
    V = np.asarray(m.vertices) * r[:, None] * [1.0, 1.0, 2.2] + [0, 0, 0.9]
    return V, np.asarray(m.faces)


def test_sphere_silhouette_area_matches_the_analytic_disc():
    # A sphere of radius r at distance d on the optical axis images to a disc of radius
    # f·tan(asin(r/d)). Tolerance 1 %: counting pixel centres misses ~±perimeter/√N pixels
    # (≈0.1 % here), and the subdivision-5 icosphere is inscribed in the sphere
    # (its silhouette is ≤ 0.02 % smaller).
    m = trimesh.creation.icosphere(subdivisions=5, radius=0.5)
    cam = _camera([0, -4.0, 0.9])
    mask = silhouette(np.asarray(m.vertices) + [0, 0, 0.9], np.asarray(m.faces), cam)
    disc = np.pi * (cam.K[0, 0] * np.tan(np.arcsin(0.5 / 4.0))) ** 2
    assert mask.sum() == pytest.approx(disc, rel=0.01)
    rows, cols = np.nonzero(mask)  # centred on the principal point, to a tenth of a pixel
    np.testing.assert_allclose([cols.mean(), rows.mean()], cam.K[:2, 2], atol=0.1)


@pytest.mark.parametrize("seed", [0, 1])
def test_equals_coverage_of_raster_exactly(seed):
    # Same rule (pixel centre inside or on a triangle ⇒ set): the masks are identical,
    # except for centres within rounding (1e-12 px) of an edge, which random vertices avoid.
    V, F = _lumpy_sphere(seed)
    cams = [
        *camera_rig("humaneva4"),
        _camera([0, -2.0, 1.0], fov=40.0),  # close: the body leaves the image
        _camera([0.3, 0.2, 6.0], [0.1, 0.0, 0.9]),  # from above
    ]
    for cam in cams:
        uv, _ = cam.project(V)
        expect = coverage(uv, F, cam.shape)
        assert expect.any()
        assert np.array_equal(silhouette(V, F, cam), expect)
        # A closed mesh: its positive-area triangles alone cover the silhouette.
        assert np.array_equal(silhouette(V, F, cam, assume_closed=True), expect)
        assert np.array_equal(silhouette(V, F[:, ::-1], cam, assume_closed=True), expect)


@pytest.mark.parametrize("orientation", ["any", "positive"])
def test_covered_pixels_are_the_filled_image_at_those_pixels(orientation):
    """The pixels' rows only, cut into the same spans: exactly the image's pixels, for a
    closed mesh and for a soup of random triangles (some off the image, some behind the
    camera), and nothing for no pixels."""
    rng = np.random.default_rng(3)
    cam = _camera((2.5, -1.0, 1.2))
    soup = rng.uniform(-2.0, 2.0, size=(300, 3)) + [0, 0, 0.9]
    for V, F in (_lumpy_sphere(4), (soup, rng.integers(0, 300, size=(400, 3)))):
        uv, depth = cam.project(V)
        mask = fill_triangles(uv, F, cam.shape, valid=depth > 0, orientation=orientation)
        px = np.stack([rng.integers(0, 640, 2000), rng.integers(0, 480, 2000)], 1)
        px = np.concatenate([px, np.argwhere(mask)[::7, ::-1]])  # and pixels inside
        for some in (px[:300:7], px):  # few rows: cut into spans; many: the image filled
            got = covered_pixels(uv, F, some, cam.shape, valid=depth > 0, orientation=orientation)
            np.testing.assert_array_equal(got, mask[some[:, 1], some[:, 0]])
            assert got.any()
    assert covered_pixels(uv, F, np.zeros((0, 2), int), cam.shape).shape == (0,)


@pytest.mark.parametrize("grid", [0.0, 1.0, 0.5])
def test_the_compiled_fill_cuts_the_spans_covered_pixels_cuts(grid):
    """Every pixel of the image: the filled mask (compiled, a triangle at a time) and the
    spans :func:`covered_pixels` cuts row by row in NumPy agree exactly, for triangles of
    every size and orientation, some degenerate, off the image or with an invalid vertex;
    on a grid (``grid`` pixels) many pixel centres lie exactly on edges and vertices."""
    rng = np.random.default_rng(int(2 * grid) + 11)
    uv = rng.uniform(-60, 700, (300, 2)) + rng.normal(0, 30, (300, 2))
    if grid:
        uv = np.round(uv / grid) * grid
    F = rng.integers(0, 300, (500, 3))
    F[:20, 2] = F[:20, 1]  # degenerate
    valid = rng.random(300) > 0.05
    every = np.argwhere(np.ones((480, 640), dtype=bool))[:, ::-1]  # (column, row)
    for orientation in ("any", "positive"):
        mask = fill_triangles(uv, F, (480, 640), valid=valid, orientation=orientation)
        assert mask.any()
        for rows in np.array_split(np.arange(480), 8):  # few rows a call: cut into spans
            px = every[np.isin(every[:, 1], rows)]
            got = covered_pixels(uv, F, px, (480, 640), valid=valid, orientation=orientation)
            np.testing.assert_array_equal(got, mask[px[:, 1], px[:, 0]])


def test_triangle_soup_equals_coverage():
    # Random small and large triangles, either orientation, partly outside the image.
    rng = np.random.default_rng(3)
    centre = rng.uniform(-40, 680, (400, 1, 2))
    uv = (centre + rng.normal(0, 1, (400, 3, 2)) * rng.uniform(0.5, 40, (400, 1, 1))).reshape(-1, 2)
    F = np.arange(1200).reshape(400, 3)
    assert np.array_equal(fill_triangles(uv, F, (480, 640)), coverage(uv, F, (480, 640)))
    # Exact pixel centres on edges and vertices count as covered (closed triangles).
    uv = np.array([[2.0, 1.0], [6.0, 1.0], [2.0, 5.0]])
    mask = fill_triangles(uv, np.array([[0, 1, 2]]), (8, 8))
    rows, cols = np.nonzero(mask)
    assert ((cols >= 2) & (rows >= 1) & (cols - 2 + rows - 1 <= 4)).all() and mask.sum() == 15


def test_triangles_behind_the_camera_are_skipped():
    # The camera sits inside the lumpy sphere's bounding box: some triangles straddle the
    # camera plane; like rasterize(), silhouette skips any triangle with a vertex at depth ≤ 0.
    V, F = _lumpy_sphere(2)
    cam = _camera([0.0, -0.3, 0.9], [0.0, 1.0, 0.9], fov=90.0)
    uv, depth = cam.project(V)
    assert (depth <= 0).any() and (depth > 0).any()
    face, _ = rasterize(uv, depth, F, cam.shape)
    assert np.array_equal(silhouette(V, F, cam), face >= 0)


def test_distortion_moves_the_silhouette_like_its_centre():
    # A small sphere (≈11 px radius) near a corner under barrel distortion (a ≈15 px shift):
    # the mask's centroid moves by the displacement of the sphere's image centre. The
    # first-order change of the displacement across the blob (a −8 % scaling here) leaves
    # the centroid in place; the second-order one moves it by ~0.1 px. Tolerance 0.3 px.
    m = trimesh.creation.icosphere(subdivisions=4, radius=0.06)
    V = np.asarray(m.vertices) + [1.6, 0.0, 2.0]
    plain = _camera([0, -4.0, 0.9])
    bent = Camera(plain.K, plain.R, plain.t, 640, 480, [-0.2, 0.05, 0.001, -0.001, 0.0])
    a, b = silhouette(V, m.faces, plain), silhouette(V, m.faces, bent)
    shift = np.subtract(bent.project(V.mean(0))[0], plain.project(V.mean(0))[0])
    assert np.linalg.norm(shift) > 10  # the test is meaningful
    ca = np.array(np.nonzero(a)).mean(1)[::-1]
    cb = np.array(np.nonzero(b)).mean(1)[::-1]
    np.testing.assert_allclose(cb - ca, shift, atol=0.3)
    uv, _ = bent.project(V)
    assert np.array_equal(b, coverage(uv, m.faces, (480, 640)))  # straight-edged triangles


def test_vertices_at_the_camera_plane():
    V, F = _lumpy_sphere(0)
    # A vertex 1e-300 m in front of the camera plane projects to inf: its triangles are
    # skipped without warnings (pytest turns warnings into errors).
    cam = Camera(intrinsics(640, 480, 50.0), np.eye(3), np.zeros(3), 640, 480)
    V = V - [0, 0, 0.9] + [0, 0, 3.0]  # in front of the camera, on its axis
    whole = silhouette(V, F, cam)
    W = np.concatenate([V, [[1e300, 0.0, 1e-300]]])
    G = np.concatenate([F, [[len(V), 0, 1]]])
    assert whole.any() and np.array_equal(silhouette(W, G, cam), whole)


def test_empty_and_off_image_meshes():
    V, F = _lumpy_sphere(0)
    cam = _camera([0, -4.0, 0.9])
    assert not silhouette(V + [10.0, 0, 0], F, cam).any()  # beside the image
    assert not silhouette(V, F[:0], cam).any()  # no faces
    assert silhouette(V, F, cam).shape == (480, 640)


def test_bad_inputs_are_rejected():
    V, F = _lumpy_sphere(0)
    cam = _camera([0, -4.0, 0.9])
    with pytest.raises(InputError, match=r"V must be an \(n, 3\)"):
        silhouette(V[:, :2], F, cam)
    with pytest.raises(InputError, match="F must index V"):
        silhouette(V, F + len(V), cam)
    with pytest.raises(InputError, match="F must be an"):
        silhouette(V, F.astype(float), cam)
    with pytest.raises(InputError, match="finite"):
        silhouette(np.full_like(V, np.nan), F, cam)
    with pytest.raises(InputError, match="camera must be a Camera"):
        silhouette(V, F, "C1")


# ----------------------------------------------------------------------------- PNG files
@pytest.mark.parametrize("bits", [1, 8])
def test_mask_round_trip(tmp_path, bits):
    mask = np.random.default_rng(0).random((48, 64)) > 0.5
    path = tmp_path / "m.png"
    write_mask(path, mask, bits=bits)
    with Image.open(path) as img:
        assert img.mode == ("1" if bits == 1 else "L") and img.format == "PNG"
    back = read_mask(path, shape=(48, 64))
    assert back.dtype == bool and np.array_equal(back, mask)
    assert [p.name for p in tmp_path.iterdir()] == ["m.png"]  # atomic: no temporary left


def test_reads_any_png_at_half_scale(tmp_path):
    grey = np.array([[0, 127, 128, 255]], dtype=np.uint8)  # 50 % of 255 is 127.5
    expect = np.array([[False, False, True, True]])
    Image.fromarray(grey, "L").save(tmp_path / "l.png")
    Image.fromarray(np.repeat(grey[..., None], 3, axis=2), "RGB").save(tmp_path / "rgb.png")
    Image.fromarray(grey.astype(np.uint16) * 257).save(tmp_path / "i16.png")  # 16-bit
    Image.fromarray(grey, "L").convert("P").save(tmp_path / "p.png")
    rgba = np.zeros((1, 4, 4), np.uint8)
    rgba[..., :3], rgba[..., 3] = 255, grey  # white cut-out on transparency
    Image.fromarray(rgba, "RGBA").save(tmp_path / "rgba.png")
    for name in ("l", "rgb", "i16", "p", "rgba"):
        with pytest.warns(GreyMaskWarning, match=f"{name}.png: mask is not binary"):
            assert np.array_equal(read_mask(tmp_path / f"{name}.png"), expect), name


def test_binary_masks_read_without_warning_and_0_1_masks_are_binary(tmp_path):
    m = np.array([[0, 1, 1, 0]], dtype=np.uint8)
    Image.fromarray(m, "L").save(tmp_path / "01.png")  # 0/1, not 0/255
    Image.fromarray(m * 255, "L").save(tmp_path / "0255.png")
    rgba = np.zeros((1, 4, 4), np.uint8)
    rgba[..., :3], rgba[..., 3] = 255, m * 255
    Image.fromarray(rgba, "RGBA").save(tmp_path / "cut.png")
    for name in ("01", "0255", "cut"):  # filterwarnings = error: no warning is raised
        assert np.array_equal(read_mask(tmp_path / f"{name}.png"), m.astype(bool)), name


def test_8_bit_masks_read_as_the_general_rule_reads_them(tmp_path):
    # the 8-bit path (one pass) against the rule in floats: > 50 % of full scale, binary
    # (no warning) when only 0 and full scale (or 0 and 1, full scale then 1) occur
    for v in (0, 1, 2, 126, 127, 128, 129, 254, 255):
        for base in ((0, 255), (0, 1), (0,), (255,)):
            grey = np.array([[*base, v]], dtype=np.uint8)
            g = grey.astype(np.float64)
            full = 1.0 if g.max() == 1.0 else 255.0
            path = tmp_path / f"{v}-{len(base)}-{base[-1]}.png"
            Image.fromarray(grey, "L").save(path)
            with warnings.catch_warnings(record=True) as seen:
                warnings.simplefilter("always")
                mask = read_mask(path)
            assert np.array_equal(mask, g > 0.5 * full), (base, v)
            binary = bool(np.all((g == 0) | (g == full)))
            assert binary == (not any(w.category is GreyMaskWarning for w in seen)), (base, v)


def test_unreadable_masks_raise_one_line_errors(tmp_path):
    good = tmp_path / "good.png"
    write_mask(good, np.eye(8, dtype=bool), bits=8)
    cut = tmp_path / "cut.png"
    cut.write_bytes(good.read_bytes()[:50])
    text = tmp_path / "text.png"
    text.write_text("not an image")
    for path in (cut, text):
        with pytest.raises(FormatError, match=re.escape(str(path))) as info:
            read_mask(path)
        assert "\n" not in str(info.value)
    with pytest.raises(FormatError, match=r"8×8 pixels, expected 10×8"):
        read_mask(good, shape=(8, 10))
    with pytest.raises(MeshmocapFileNotFoundError, match="no such file"):
        read_mask(tmp_path / "absent.png")
    with pytest.raises(MeshmocapFileNotFoundError, match="does not exist"):
        write_mask(tmp_path / "nowhere" / "m.png", np.eye(4, dtype=bool))
    with pytest.raises(InputError, match=r"bits must be one of \[1, 8\]"):
        write_mask(good, np.eye(4, dtype=bool), bits=16)
    with pytest.raises(InputError, match="booleans or 0/1"):
        write_mask(good, np.full((4, 4), 0.5))


def _png(grey: np.ndarray, filters, *, extra: bytes = b"") -> bytes:
    """An 8-bit grey PNG of ``grey`` with row ``y`` filtered by ``filters[y % 5]`` (PNG's
    filters computed here, the spec's way), ``extra`` chunks before the image data."""

    def chunk(kind: bytes, body: bytes) -> bytes:
        return (
            struct.pack(">I", len(body)) + kind + body + struct.pack(">I", zlib.crc32(kind + body))
        )

    h, w = grey.shape
    g = grey.astype(np.int64)
    rows = []
    for y in range(h):
        f = filters[y % len(filters)]
        out = [f]
        for x in range(w):
            a = g[y, x - 1] if x else 0
            b = g[y - 1, x] if y else 0
            c = g[y - 1, x - 1] if x and y else 0
            p = a + b - c
            paeth = min((abs(p - a), 0, a), (abs(p - b), 1, b), (abs(p - c), 2, c))[2]
            pred = (0, a, b, (a + b) // 2, paeth)[f]
            out.append((g[y, x] - pred) % 256)
        rows.append(bytes(out))
    ihdr = struct.pack(">IIBBBBB", w, h, 8, 0, 0, 0, 0)
    body = chunk(b"IHDR", ihdr) + extra + chunk(b"IDAT", zlib.compress(b"".join(rows)))
    return b"\x89PNG\r\n\x1a\n" + body + chunk(b"IEND", b"")


def test_usual_masks_decode_as_pillow_decodes_them(tmp_path):
    """The compiled decoding of 8-bit grey PNGs (every filter, grey and binary images)
    gives Pillow's values, and leaves any other file to Pillow."""
    from meshmocap.io._kernels import grey8

    rng = np.random.default_rng(3)
    grey = rng.integers(0, 256, (11, 13)).astype(np.uint8)
    binary = np.where(rng.random((9, 6)) > 0.5, 255, 0).astype(np.uint8)
    for image in (grey, binary, binary // 255):
        for filters in ((0, 1, 2, 3, 4), (4, 3, 2, 1, 0), (2,), (3,), (4,)):
            data = _png(image, filters)
            path = tmp_path / "m.png"
            path.write_bytes(data)
            with Image.open(path) as img:
                expect = np.asarray(img)
            got, top, is_binary = grey8(data, None)
            assert np.array_equal(got, expect) and top == expect.max(), filters
            assert is_binary == bool(np.isin(expect, (0, 255)).all())
            if image is not grey:  # binary: no warning
                assert np.array_equal(read_mask(path), expect > (0 if top <= 1 else 127))
    data = _png(grey, (4,))
    text = struct.pack(">I", 2) + b"tEXt" + b"ab" + struct.pack(">I", zlib.crc32(b"tEXtab"))
    assert grey8(data, None) is not None and grey8(data, grey.size - 1) is None  # too large
    for other in (
        _png(grey, (4,), extra=text),  # another chunk
        data[:-20],  # cut
        data[:17] + bytes([data[17] ^ 1]) + data[18:],  # the header's checksum fails
        data[:45] + bytes([data[45] ^ 1]) + data[46:],  # the image data's fails
        data.replace(b"IHDR", b"IHDr"),
    ):
        assert grey8(other, None) is None
    path = tmp_path / "text.png"
    path.write_bytes(_png(binary, (1, 4), extra=text))
    with Image.open(path) as img:
        assert np.array_equal(read_mask(path), np.asarray(img) > 127)


def _zlib_inflated(stream: bytes, size: int) -> bytes | None:
    """What the mask reader asked of zlib: exactly ``size`` bytes, the stream's end, nothing
    after it (None otherwise)."""
    z = zlib.decompressobj()
    try:
        raw = z.decompress(stream, size + 1)
    except zlib.error:
        return None
    ok = len(raw) == size and z.eof and not z.unused_data and not z.unconsumed_tail
    return raw if ok else None


def test_the_compiled_inflate_answers_as_zlib():
    """Streams of every block kind (stored, fixed and dynamic codes; runs, rows, noise, as
    each of zlib's strategies writes them), asked for their size, one byte more or less,
    and damaged (a bit flipped, a byte replaced, cut, a byte after the end), and a stream
    with a preset dictionary: the kernel's bytes are zlib's where it answers, and it
    answers for every intact stream; the mask reader's (``inflated``, the kernel or zlib)
    the same bytes or the same refusal as zlib's."""
    from meshmocap.io._kernels import inflated, kernel_inflated

    rng = np.random.default_rng(11)
    mask = np.zeros((60, 81), dtype=np.uint8)
    mask[10:50, 20:45] = 255
    sources = [
        bytes(3000),
        rng.integers(0, 256, 2000, dtype=np.uint8).tobytes(),
        np.repeat(rng.integers(0, 3, 80, dtype=np.uint8) * 127, rng.integers(1, 300, 80)).tobytes(),
        np.c_[np.zeros(60, np.uint8), mask].tobytes(),  # a mask's rows, filter bytes first
        b"",
    ]
    strategies = (zlib.Z_DEFAULT_STRATEGY, zlib.Z_FILTERED, zlib.Z_HUFFMAN_ONLY, zlib.Z_RLE)
    for raw in sources:
        for level, strategy in [(0, 0), (1, 0), (6, 0), (9, 0), *((6, s) for s in strategies)]:
            for fixed in (False, True):
                c = zlib.compressobj(
                    level, zlib.DEFLATED, 15, 9, zlib.Z_FIXED if fixed else strategy
                )
                stream = c.compress(raw) + c.flush()
                got = kernel_inflated(stream, len(raw))
                assert got is not None and got.tobytes() == raw
                damaged = [stream, stream[:-1], stream + b"\0", stream[: len(stream) // 2]]
                for _ in range(6):
                    b = bytearray(stream)
                    i = int(rng.integers(2, len(b)))
                    b[i] = b[i] ^ (1 << int(rng.integers(0, 8))) if rng.random() < 0.5 else 0xFF
                    damaged.append(bytes(b))
                for s in damaged:
                    for size in {len(raw), len(raw) + 1, max(len(raw) - 1, 0)}:
                        expect = _zlib_inflated(s, size)
                        got = kernel_inflated(s, size)
                        assert got is None or got.tobytes() == expect
                        got = inflated(s, size)
                        assert (got is None) == (expect is None)
                        assert got is None or got.tobytes() == expect
    c = zlib.compressobj(6, zlib.DEFLATED, 15, 9, zlib.Z_DEFAULT_STRATEGY, zdict=b"\0" * 64)
    stream = c.compress(bytes(100)) + c.flush()
    assert kernel_inflated(stream, 100) is None and inflated(stream, 100) is None
    assert _zlib_inflated(stream, 100) is None
