"""Reading ``.npz`` archives safely: one-line errors and a size cap, never unpacked to disk.

``numpy.load`` lets through ``zipfile.BadZipFile``, ``zlib.error``, ``EOFError``, a pickle
complaint for a file that is not a zip at all, and happily inflates a small archive into
gigabytes. :func:`read_npz` reads every array of an archive in memory, refuses archives
whose arrays would unpack past :data:`MAX_NPZ_BYTES` (read from the zip directory before
anything is inflated), and turns every failure into one line naming the file, what it was
expected to be and what went wrong.
"""

from __future__ import annotations

import os
import zipfile
import zlib
from pathlib import Path
from tokenize import TokenError

import numpy as np

from meshmocap.errors import FormatError, MeshmocapError, MeshmocapFileNotFoundError

#: What ``numpy.load`` raises on a damaged ``.npy`` (its header is parsed as Python syntax).
NPY_ERRORS = (ValueError, OSError, EOFError, SyntaxError, TokenError, UnicodeDecodeError,
              TypeError, MemoryError, OverflowError)  # fmt: skip

#: Largest total of uncompressed array bytes one ``.npz`` may hold (4 GiB; a 2.6-million-
#: vertex hull's occupancy and mesh take about 100 MB). ``MESHMOCAP_MAX_NPZ_MB`` changes it.
MAX_NPZ_BYTES = 4 << 30


def max_npz_bytes() -> int:
    """The cap in force: ``MESHMOCAP_MAX_NPZ_MB`` megabytes if set, else :data:`MAX_NPZ_BYTES`."""
    env = os.environ.get("MESHMOCAP_MAX_NPZ_MB", "")
    return int(float(env) * 1e6) if env.replace(".", "", 1).isdigit() else MAX_NPZ_BYTES


def read_npz(
    path: str | os.PathLike,
    what: str,
    *,
    keys: tuple[str, ...] = (),
    error: type[MeshmocapError] = FormatError,
) -> dict[str, np.ndarray]:
    """Every array of the ``.npz`` file ``path`` (no pickles), as a dict.

    Parameters
    ----------
    path : path, the file
    what : str, what the file should be, for messages (``"template"``, ``"pose manifold"``)
    keys : tuple of str, arrays the file must hold (a missing one raises ``error``)
    error : the error class raised for an unreadable file (a :class:`MeshmocapError`)

    Raises
    ------
    MeshmocapFileNotFoundError
        No such file.
    error
        Not a zip archive, a corrupt or truncated one, an array that is not a readable
        ``.npy`` (or holds Python objects), arrays above the size cap, or a missing key.
    """
    path = Path(path)
    if not path.is_file():
        what_is = "is a folder, not a file" if path.is_dir() else "no such file"
        raise MeshmocapFileNotFoundError(f"{path}: {what_is}")
    cap = max_npz_bytes()
    try:
        with zipfile.ZipFile(path) as zf:
            total = sum(i.file_size for i in zf.infolist())
            if total > cap:
                raise error(
                    f"{path}: {what} arrays unpack to {total / 1e6:.0f} MB, above the "
                    f"{cap / 1e6:.0f} MB limit (MESHMOCAP_MAX_NPZ_MB)"
                )
        with open(path, "rb") as fh, np.load(fh, allow_pickle=False) as z:
            d = {k: z[k] for k in z.files}
    except MeshmocapError:
        raise
    except (zipfile.BadZipFile, zlib.error, KeyError, NotImplementedError, RuntimeError,
            *NPY_ERRORS) as exc:  # fmt: skip
        text = str(exc).strip().splitlines()
        why = f"{type(exc).__name__}: {text[0] if text else ''}".rstrip(": ")
        raise error(f"{path}: not a readable .npz {what} ({why[:160]})") from None
    missing = [k for k in keys if k not in d]
    if missing:
        raise error(f"{path}: not a {what}: missing {', '.join(map(repr, missing))}")
    return d
