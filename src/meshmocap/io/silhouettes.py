"""Binary silhouette masks as PNG images (through Pillow).

Masks are (height, width) bool arrays, row 0 at the top of the image (the pixel grid of
:mod:`meshmocap.geometry.camera`). :func:`write_mask` writes 1-bit (smallest) or 8-bit
(0/255, what most tools expect) greyscale PNGs; :func:`read_mask` reads any PNG (or other
image Pillow opens) and thresholds it at 50 % of full scale, with a :class:`GreyMaskWarning`
when the image is not binary (a mask stored as 0 and 1 rather than 0 and 255 is binary):

* greyscale (1, 2, 4, 8 or 16 bits): the grey value;
* RGB or palette: the luma (ITU-R 601, Pillow's ``convert("L")``);
* with transparency: the grey value or luma times the alpha (composited on black), so a
  white-on-transparent cut-out and a white-on-black mask read the same.
"""

from __future__ import annotations

import os
import warnings
from pathlib import Path
from typing import Literal

import numpy as np
from PIL import Image, UnidentifiedImageError

from meshmocap._atomic import atomic_open
from meshmocap.errors import FormatError, GreyMaskWarning, InputError, MeshmocapFileNotFoundError

#: Bit depths :func:`write_mask` writes.
MaskBits = Literal[1, 8]


def read_mask(path: str | os.PathLike[str], *, shape: tuple[int, int] | None = None) -> np.ndarray:
    """Read a silhouette mask.

    Parameters
    ----------
    path : str or path-like
        An image file, usually a PNG.
    shape : (height, width), optional
        Expected size; a different one raises :class:`FormatError`.

    Returns
    -------
    mask : (height, width) bool
        True where the image is brighter than 50 % of full scale (see the module docstring).

    Raises
    ------
    MeshmocapFileNotFoundError
        No such file.
    FormatError
        Not a readable image, or not of ``shape``.
    """
    p = Path(path)
    if not p.is_file():
        what = "is a folder, not a file" if p.is_dir() else "no such file"
        raise MeshmocapFileNotFoundError(f"{path}: {what}")
    from meshmocap.io._kernels import grey8  # compiled: imported on first use

    try:
        # the usual mask (8-bit grey PNG) decoded at once; any other image by Pillow
        fast = grey8(p.read_bytes(), Image.MAX_IMAGE_PIXELS)
        if fast is not None:
            grey, top, binary = fast
            mask, binary = (grey > 0, True) if top <= 1 else (grey > 127, binary)  # _threshold's
        else:
            with warnings.catch_warnings():
                warnings.simplefilter("error", Image.DecompressionBombWarning)
                with Image.open(p) as img:
                    img.load()
                    mask, binary = _threshold(img)
    except (UnidentifiedImageError, Image.DecompressionBombWarning, Image.DecompressionBombError):
        raise FormatError(f"{path}: not a readable image, expected a PNG mask") from None
    except (OSError, SyntaxError, ValueError, TypeError, MemoryError) as e:  # corrupt data
        msg = str(e).splitlines()[0] if str(e) else type(e).__name__
        raise FormatError(f"{path}: corrupt image, expected a PNG mask ({msg})") from None
    if not binary:
        warnings.warn(
            f"{path}: mask is not binary (grey levels); thresholded at 50 % of full scale",
            GreyMaskWarning,
            stacklevel=2,
        )
    if shape is not None and mask.shape != tuple(shape):
        raise FormatError(
            f"{path}: mask of {mask.shape[1]}×{mask.shape[0]} pixels, expected "
            f"{shape[1]}×{shape[0]} (width×height)"
        )
    return mask


def _threshold(img: Image.Image) -> tuple[np.ndarray, bool]:
    """The mask and whether the image was binary (0 and full scale, or 0 and 1 only)."""
    mode = img.mode
    if mode == "1":
        return np.asarray(img, dtype=bool).copy(), True
    if mode.startswith("I") or mode == "F":  # 16-bit PNG greyscale (I;16 or I)
        full = 65535.0 if mode != "F" else 1.0
        grey = np.asarray(img, dtype=np.float64)
    else:
        if mode == "P":
            img = img.convert("RGBA")
            mode = "RGBA"
        alpha = None
        if mode in ("LA", "RGBA", "PA", "La", "RGBa"):
            alpha = np.asarray(img.getchannel("A"), dtype=np.float64) / 255.0
        # 8-bit grey stays uint8: its comparisons with the thresholds below are exact
        grey = np.asarray(img.convert("L") if mode != "L" else img)
        if alpha is not None:
            grey = grey * alpha
        full = 255.0
    if grey.ndim != 2:
        raise ValueError(f"expected one channel, found shape {grey.shape}")
    if grey.dtype == np.uint8 and grey.size:  # the usual mask: the same answers, one pass
        if grey.max() <= 1:  # 0 and 1 only: binary, thresholded at 0.5
            return grey > 0, True
        # > 127.5 is ≥ 128; 0 and 255 are the values that wrap to ≤ 1 when 1 is added
        return grey > 127, bool((grey + np.uint8(1)).max() <= 1)
    if grey.size and grey.max() == 1.0 and _only(grey, 1.0):
        full = 1.0  # a mask stored as 0 and 1 rather than 0 and full scale
    return grey > 0.5 * full, _only(grey, full)


def _only(grey: np.ndarray, full: float) -> bool:
    """Whether every value of ``grey`` is 0 or ``full`` (``np.isin``, 15× cheaper)."""
    return bool(((grey == 0) | (grey == full)).all())


def write_mask(path: str | os.PathLike[str], mask: np.ndarray, *, bits: MaskBits = 8) -> None:
    """Write ``mask`` as a greyscale PNG, atomically (temporary file, then :func:`os.replace`).

    Parameters
    ----------
    path : str or path-like
        Destination (conventionally ``.png``); its folder must exist.
    mask : (height, width) bool
        The silhouette (any array of 0/1 or bools is accepted).
    bits : {1, 8}
        1-bit PNG (smallest files) or 8-bit with values 0 and 255.
    """
    if bits not in (1, 8) or isinstance(bits, bool):
        raise InputError(f"write_mask: bits must be one of [1, 8], found {bits!r}")
    m = np.asarray(mask)
    if m.ndim != 2 or m.size == 0:
        raise InputError(f"write_mask: mask must be a (height, width) array, found shape {m.shape}")
    if m.dtype != bool:
        if not np.isin(m, (0, 1)).all():
            raise InputError(f"write_mask: mask must hold booleans or 0/1, found dtype {m.dtype}")
        m = m.astype(bool)
    img = Image.fromarray(m) if bits == 1 else Image.fromarray(m.astype(np.uint8) * 255, "L")
    with atomic_open(path) as f:
        img.save(f, format="PNG", optimize=False)
