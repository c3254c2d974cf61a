"""The captures of a batch (``meshmocap batch``): folders, globs, lists and CSV manifests."""

from __future__ import annotations

import csv
import glob
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

from meshmocap._validate import frame_slice
from meshmocap.errors import InputError, MeshmocapFileNotFoundError

__all__ = ["DEFAULT_TEMPLATE", "BatchItem", "batch_items"]

#: Template of a capture when neither the command nor the manifest names one: as
#: ``meshmocap track`` chooses (the one capture.json names, else the performer's body
#: estimated from the capture;
#: :func:`~meshmocap.estimate.performer.tracking_template.tracking_template`).
DEFAULT_TEMPLATE = ""


@dataclass(frozen=True)
class BatchItem:
    """One capture of a batch.

    Attributes
    ----------
    name : str, unique folder name of its results inside the batch folder
    capture : str, capture folder, mesh folder, glob or archive (as ``meshmocap track`` takes)
    method : str, tracker name (:data:`meshmocap.trackers.registry.METHODS`)
    template : str, template name or ``.npz`` path, ``"auto"`` to estimate the performer's
        body, or empty for ``meshmocap track``'s default (:data:`DEFAULT_TEMPLATE`)
    frames : str, ``START:STOP[:STEP]`` or empty for every frame
    """

    name: str
    capture: str
    method: str
    template: str = DEFAULT_TEMPLATE
    frames: str = ""


def _expand(source: str, base: Path | None = None) -> list[str]:
    """Captures named by one source: a glob, a ``.txt`` list, or a path."""
    text = source.strip()
    path = Path(text) if base is None or Path(text).is_absolute() else base / text
    if any(c in text for c in "*?["):
        found = sorted(glob.glob(str(path)))
        if not found:
            raise MeshmocapFileNotFoundError(f"batch: {source!r} matches no capture")
        return found
    if path.suffix == ".txt" and path.is_file():
        lines = [ln.strip() for ln in path.read_text().splitlines()]
        return [
            c for ln in lines if ln and not ln.startswith("#") for c in _expand(ln, path.parent)
        ]
    if not path.exists():
        raise MeshmocapFileNotFoundError(f"batch: {source}: no such capture")
    return [str(path)]


def _manifest(path: Path, *, method: str, template: str, frames: str) -> list[dict[str, str]]:
    """Rows of a CSV manifest: a ``capture`` column; ``method``, ``template``, ``frames``
    optional."""
    with path.open(newline="") as f:
        reader = csv.DictReader(f)
        if reader.fieldnames is None or "capture" not in reader.fieldnames:
            raise InputError(
                f"batch: {path}: a manifest needs a 'capture' column (and optionally method, "
                f"template, frames), found columns {reader.fieldnames}"
            )
        rows = []
        for line, row in enumerate(reader, start=2):
            if None in row:  # DictReader files cells beyond the header under None
                raise InputError(
                    f"batch: {path}:{line}: expected {len(reader.fieldnames)} cells "
                    f"({', '.join(reader.fieldnames)}), found "
                    f"{len(reader.fieldnames) + len(row[None])}"
                )
            if not (row.get("capture") or "").strip():
                raise InputError(f"batch: {path}:{line}: empty capture")
            for cap in _expand(row["capture"], path.parent):
                rows.append(
                    {
                        "capture": cap,
                        "method": (row.get("method") or "").strip() or method,
                        "template": (row.get("template") or "").strip() or template,
                        "frames": (row.get("frames") or "").strip() or frames,
                    }
                )
    return rows


def batch_items(
    sources: Sequence[str],
    *,
    method: str = "patch",
    template: str | None = None,
    frames: str = "",
) -> list[BatchItem]:
    """The captures named by ``sources``, each with its method, template and frames.

    Parameters
    ----------
    sources : sequence of str
        Capture folders (or mesh folders, archives), globs (``captures/*``), ``.txt`` files
        listing one source per line (relative to the file; ``#`` comments), and ``.csv``
        manifests with a ``capture`` column and optional ``method``, ``template``,
        ``frames`` columns (empty cells take the defaults below).
    method, template, frames : str
        Defaults for every capture (``frames``: ``START:STOP[:STEP]``, empty for all).

    Returns
    -------
    list of BatchItem
        In the order given; a capture named twice with the same settings once. Result
        folder names are the captures' folder names, made unique with ``-2``, ``-3``, ….
    """
    from meshmocap.trackers.registry import METHODS

    if isinstance(sources, str) or not sources:
        raise InputError(f"batch: expected one or more captures, found {sources!r}")
    template = template or DEFAULT_TEMPLATE
    rows: list[dict[str, str]] = []
    for source in sources:
        if source.endswith(".csv") and Path(source).is_file():
            rows += _manifest(Path(source), method=method, template=template, frames=frames)
        else:
            rows += [
                {"capture": c, "method": method, "template": template, "frames": frames}
                for c in _expand(source)
            ]
    items: list[BatchItem] = []
    seen: set[tuple[str, ...]] = set()
    names: set[str] = set()
    for row in rows:
        if row["method"] not in METHODS:
            raise InputError(
                f"batch: method must be one of {sorted(METHODS)}, found {row['method']!r} "
                f"for {row['capture']}"
            )
        if row["frames"]:
            frame_slice(row["frames"], what=f"batch: frames of {row['capture']}")
        key = (str(Path(row["capture"]).resolve()), row["method"], row["template"], row["frames"])
        if key in seen:
            continue
        seen.add(key)
        stem = Path(row["capture"].rstrip("/")).name
        for suffix in (".tar.gz", ".tgz", ".tar", ".zip"):
            stem = stem.removesuffix(suffix)
        name, k = stem or "capture", 1
        while name in names:
            k += 1
            name = f"{stem}-{k}"
        names.add(name)
        items.append(BatchItem(name, row["capture"], row["method"], row["template"], row["frames"]))
    return items
