"""Self-contained HTML reports: tables, embedded plots and a 3D player of tracked meshes.

A report is one ``.html`` file that works offline: PNG/JPEG images are embedded as
``data:`` URIs and the player (:mod:`meshmocap.apps.report.player`, three.js playing each track's
exported glTF) is inlined with its data; the page refers to no URL at all. Its size is
about the player's (0.7 MB of three.js, a few hundred kB per track, the per-frame data ≤
``max_megabytes``) plus the images'.

:func:`report_html` (pure) and :func:`write_report` assemble players, tables and images;
:func:`build_report` evaluates tracks on their capture and writes the whole report (the
``meshmocap report`` command).
"""

from __future__ import annotations

import base64
import html
import json
import math
import os
import tempfile
from collections.abc import Sequence
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from meshmocap._atomic import write_text_atomic
from meshmocap._version import __version__
from meshmocap.analysis.evaluate import Evaluation, evaluate
from meshmocap.analysis.tables import summary_table
from meshmocap.apps.files.evaluation import write_evaluation
from meshmocap.apps.files.gait import GAIT_HEADERS, gait_report
from meshmocap.apps.report.cameras import camera_views
from meshmocap.apps.report.notes import WORST_FRAME, bone_note, frame_rows, silhouette_note
from meshmocap.apps.report.player import (
    HULL_COLOR,
    MARKS,
    PALETTE,
    TRUTH_COLOR,
    Player,
    player_from_tracks,
    player_js,
    player_payload,
    track_templates,
)
from meshmocap.body.template import EVAL_PARENTS
from meshmocap.errors import InputError, MeshmocapFileNotFoundError
from meshmocap.io.capture import Capture, SequenceCapture
from meshmocap.io.results import Track, open_tracked_capture, read_track

ImageSource = str | os.PathLike | bytes


@dataclass(frozen=True)
class Table:
    """A table of a report: ``rows`` of cells under ``headers``; floats get ``digits``
    decimals (NaN prints as ``n/a``), numbers are right-aligned; ``notes`` (definitions,
    why a value is missing) are printed under it."""

    title: str
    headers: tuple[str, ...]
    rows: tuple[tuple[object, ...], ...]
    digits: int = 1
    notes: tuple[str, ...] = ()


@dataclass(frozen=True)
class Section:
    """A titled part of a report: tables, then ``(caption, image)`` pairs (a PNG/JPEG path
    or its bytes), then preformatted ``text``."""

    title: str
    tables: tuple[Table, ...] = ()
    images: tuple[tuple[str, ImageSource], ...] = ()
    text: str = ""


# --------------------------------------------------------------------------- tables


def table_of(result: object, *, digits: int = 1) -> Table:
    """A metrics result (joint, vertex, silhouette, bone or surface) as a report table, in
    the display units of :func:`meshmocap.analysis.tables.table` (mm or %)."""
    title, headers, rows, scale = summary_table(result)
    unit = "%" if scale == 100.0 else "mm"
    heads = []
    for h in headers:
        base = h.rsplit("_", 1)[0] if h.endswith(("_mm", "_m", "_ratio")) else h
        heads.append(f"{base} ({unit})" if base != h else h)
    shown = tuple(tuple(x * scale if isinstance(x, float) else x for x in r) for r in rows)
    return Table(title, tuple(heads), shown, digits)


def _seconds(ev: Evaluation) -> tuple[float, float]:
    return ev.seconds.mean, ev.seconds.median


def evaluation_tables(ev: Evaluation, *, track: Track | None = None) -> list[Table]:
    """The tables of :func:`meshmocap.analysis.evaluate.summary`, as report tables, with the
    frames not scored or flagged (``track``'s flags, when given) and why."""
    heads = (
        "method",
        "template",
        "init",
        "frames",
        "unhealthy",
        "lost (re-initialised)",
        "s/frame mean",
        "s/frame median",
    )
    row = (
        ev.method,
        ev.template,
        ev.init or "truth",
        ev.n_frames,
        ev.unhealthy,
        f"{ev.lost} ({ev.reinit})",
        *_seconds(ev),
    )
    out = [Table("Overview", heads, (row,), digits=3)]
    skipped = frame_rows(ev, track)
    if skipped:
        out.append(
            Table(
                "Frames not scored or flagged", ("what", "frames", "which", "why"), tuple(skipped)
            )
        )
    for r in (ev.joints, ev.joints14, ev.bones, ev.silhouettes):
        if r is not None:
            t = table_of(r)
            note = bone_note(ev) if r is ev.bones else ""
            out.append(replace(t, notes=(note,)) if note else t)
    if ev.surface is not None:
        s = ev.surface
        rows = [
            (int(f), float(m), float(h))
            for f, m, h in zip(s.frames, s.mean, s.hausdorff, strict=True)
        ]
        rows.append(("mean", float(s.mean.mean()), float(s.hausdorff.mean())))
        out.append(
            Table(
                f"Surface distance to the {s.against}, mm",
                ("frame", "mean (mm)", "hausdorff (mm)"),
                tuple(rows),
            )
        )
    if ev.correspondence is not None:
        out.append(table_of(ev.correspondence))
    return out


def comparison_table(
    evaluations: Sequence[Evaluation],
    *,
    names: Sequence[str] | None = None,
    no_silhouettes: str = "the report was made without silhouettes",
) -> Table:
    """One row per evaluation: frames, unhealthy frames, joint errors (mm; 14 joints without
    the pelvis), the worst frame, silhouette error (%) and seconds per frame; ``n/a`` where
    not measured, and notes that define the worst frame and say why silhouettes are missing
    (``no_silhouettes``: the reason)."""
    nan = math.nan
    rows = []
    for k, ev in enumerate(evaluations):
        j, j14 = ev.joints, ev.joints14
        worst = int(np.argmax(j.per_frame)) if j and len(j.per_frame) else None
        rows.append(
            (
                names[k] if names else ev.method,
                ev.n_frames,
                ev.unhealthy,
                j.overall.mean if j else nan,
                j.overall.median if j else nan,
                float(j.per_frame[worst]) if worst is not None else nan,
                int(j.frames[worst]) if worst is not None else "n/a",
                j14.overall.mean if j14 else nan,
                ev.silhouettes.overall * 100 if ev.silhouettes else nan,
                ev.seconds.mean,
            )
        )
    heads = (
        "method",
        "frames",
        "unhealthy",
        "joint mean (mm)",
        "joint median (mm)",
        "worst frame (mm)",
        "worst frame",
        "14 joints mean (mm)",
        "silhouette (%)",
        "s/frame",
    )
    notes = [WORST_FRAME, silhouette_note(evaluations, no_silhouettes)]
    return Table(
        "Trackers compared", heads, tuple(rows), digits=2, notes=tuple(n for n in notes if n)
    )


def evaluation_section(
    ev: Evaluation,
    *,
    images: Sequence[ImageSource] = (),
    title: str | None = None,
    track: Track | None = None,
) -> Section:
    """A report section of one evaluation: its tables (with ``track``'s flagged frames) and
    its plots (``.png`` paths or bytes, captioned by file name)."""
    pics = []
    for im in images:
        cap = "" if isinstance(im, bytes) else Path(im).stem.replace("_", " ")
        pics.append((cap, im))
    tables = tuple(evaluation_tables(ev, track=track))
    return Section(title or f"Evaluation: {ev.method}", tables, tuple(pics))


# --------------------------------------------------------------------------- HTML

_CSS = """
body{font:14px/1.45 system-ui,sans-serif;color:#222;margin:0 auto;padding:16px 24px;
 max-width:1200px}
h1{font-size:22px;margin:4px 0}h2{font-size:18px;margin:18px 0 8px}
.mm-meta{color:#666;margin:0 0 12px}
.mm-player{border:1px solid #d5dae0;border-radius:6px;padding:8px;margin:0 0 16px}
.mm-player h2{margin:0 0 6px;font-size:16px}
.mm-canvas{display:block;width:100%;height:560px;background:#f3f5f8;border-radius:4px;
 touch-action:none;cursor:grab;outline:none}
.mm-controls,.mm-layers{display:flex;gap:10px;align-items:center;flex-wrap:wrap;margin-top:6px}
.mm-slider{flex:1;min-width:200px}.mm-timeline{display:flex;gap:10px;align-items:center;margin-top:2px}
.mm-timeline span{min-width:9em;color:#444;font-size:12px}
.mm-timeline svg{flex:1;height:8px;background:#eef0f3}
.mm-label{font-variant-numeric:tabular-nums;color:#444}
.mm-swatch{display:inline-block;width:12px;height:12px;border-radius:2px;margin-right:4px;
 vertical-align:-1px}
.mm-table{border-collapse:collapse;margin:8px 24px 16px 0;font-size:13px;display:inline-table;
 vertical-align:top}
.mm-table caption{text-align:left;font-weight:600;padding:4px 0}
.mm-table th,.mm-table td{border-bottom:1px solid #e3e6ea;padding:3px 10px;text-align:left}
.mm-table td.num{text-align:right;font-variant-numeric:tabular-nums}
.mm-table th{background:#f3f5f8}
.mm-table td.mm-note{color:#555;font-size:12px;border:0;padding:2px 10px;max-width:60em}
figure{display:inline-block;margin:0 12px 12px 0;vertical-align:top}
figure img{max-width:100%;border:1px solid #e3e6ea}figcaption{color:#555;font-size:12px}
pre{background:#f6f8fa;padding:8px;overflow:auto;font-size:12px}
html.mm-shot body{margin:0;padding:0;max-width:none;overflow:hidden}
html.mm-shot body>:not(.mm-players),html.mm-shot .mm-player~.mm-player,
html.mm-shot .mm-player>:not(canvas){display:none}
html.mm-shot .mm-players,html.mm-shot .mm-player{margin:0;padding:0;border:0;width:800px}
html.mm-shot .mm-canvas{width:800px;height:600px;border-radius:0}
"""

#: The player's layer switches (all on at first): data-layer key, label.
_LAYERS = (
    ("mesh", "meshes"),
    ("skeleton", "skeletons"),
    ("truth", "truth joints"),
    ("hull", "hull points"),
    ("side", "side by side"),
    ("follow", "follow"),
)


def _esc(x: object) -> str:
    return html.escape(str(x), quote=True)


def _cell(x: object, digits: int) -> str:
    if isinstance(x, float | np.floating):
        text = "n/a" if math.isnan(x) else f"{x:.{digits}f}"
        return f'<td class="num">{text}</td>'
    if isinstance(x, int | np.integer):
        return f'<td class="num">{x}</td>'
    return f"<td>{_esc(x)}</td>"


def table_html(t: Table) -> str:
    """One ``<table>`` of a :class:`Table`."""
    head = "".join(f"<th>{_esc(h)}</th>" for h in t.headers)
    body = "".join("<tr>" + "".join(_cell(x, t.digits) for x in r) + "</tr>\n" for r in t.rows)
    foot = "".join(
        f'<tr><td class="mm-note" colspan="{len(t.headers)}">{_esc(n)}</td></tr>' for n in t.notes
    )
    return (
        f'<table class="mm-table"><caption>{_esc(t.title)}</caption>'
        f"<thead><tr>{head}</tr></thead>\n<tbody>\n{body}</tbody>"
        f"{f'<tfoot>{foot}</tfoot>' if foot else ''}</table>\n"
    )


def image_uri(image: ImageSource) -> str:
    """A ``data:`` URI of a PNG or JPEG (a path or its bytes)."""
    if isinstance(image, bytes):
        data, where = image, "image bytes"
    else:
        path = Path(image)
        if not path.is_file():
            raise MeshmocapFileNotFoundError(f"report image: {path} does not exist")
        data, where = path.read_bytes(), str(path)
    if data.startswith(b"\x89PNG\r\n\x1a\n"):
        mime = "image/png"
    elif data.startswith(b"\xff\xd8\xff"):
        mime = "image/jpeg"
    else:
        raise InputError(f"report image: {where}: expected a PNG or JPEG, found {data[:8]!r}")
    return f"data:{mime};base64,{base64.b64encode(data).decode('ascii')}"


#: The timeline's colours per mark (:data:`~meshmocap.apps.report.player.MARKS`): lost, changed by
#: the two-way pass, both (changed and still lost).
_MARK_COLORS = {1: "#d62728", 2: "#1f77b4", 3: "#9467bd"}


def _timeline(player: Player) -> str:
    """One strip per track under the slider: its frames flagged lost and those the two-way
    pass changed, as coloured ticks (an inline SVG, one unit per frame); empty when no
    track has a mark."""
    marked = [t for t in player.tracks if t.marks is not None and np.any(t.marks)]
    if not marked:
        return ""
    n = len(player.frames)
    rows = []
    for t in marked:
        ticks = "".join(
            f'<rect x="{i}" width="1" height="1" fill="{_MARK_COLORS[int(m)]}"/>'
            for i, m in enumerate(t.marks.tolist())
            if m
        )
        rows.append(
            f'<div class="mm-timeline"><span>{_esc(t.name)}</span>'
            f'<svg viewBox="0 0 {n} 1" preserveAspectRatio="none">{ticks}</svg></div>'
        )
    key = "".join(
        f'<span><span class="mm-swatch" style="background:{_MARK_COLORS[m]}"></span>{what}</span>'
        for m, what in ((*MARKS.items(), (3, "changed, still lost")))
    )
    return "".join(rows) + f'<div class="mm-layers">{key}</div>\n'


def _player_html(player: Player, k: int) -> str:
    payload = json.dumps(player_payload(player), separators=(",", ":")).replace("</", "<\\/")
    boxes = "".join(
        f'<label><input type="checkbox" data-layer="{key}" checked> {label}</label>'
        for key, label in _LAYERS
        if not (
            (key == "truth" and player.truth is None)
            or (key == "hull" and player.hull is None)
            or (key == "side" and len(player.tracks) < 2)
        )
    )
    legend = "".join(
        f'<span><span class="mm-swatch" style="background:rgb{PALETTE[i % len(PALETTE)]}">'
        f"</span>{_esc(t.name)}</span>"
        for i, t in enumerate(player.tracks)
    )
    for shown, rgb, what in (
        (player.truth, TRUTH_COLOR, "truth"),
        (player.hull, HULL_COLOR, "hull"),
    ):
        if shown is not None:
            legend += (
                f'<span><span class="mm-swatch" style="background:rgb{rgb}"></span>{what}</span>'
            )

    speeds = "".join(
        f'<option value="{s}"{" selected" if s == 1 else ""}>{s:g}×</option>'
        for s in (0.1, 0.25, 0.5, 1, 2)
    )
    title = player.title or "3D player"
    return (
        f'<div class="mm-player" id="mm-player-{k}">\n<h2>{_esc(title)}</h2>\n'
        f'<canvas class="mm-canvas" tabindex="0"></canvas>\n'
        f'<div class="mm-controls"><button type="button" class="mm-play">▶ Play</button>'
        f'<input type="range" class="mm-slider" min="0" max="{len(player.frames) - 1}" value="0">'
        f'<span class="mm-label"></span><select class="mm-speed">{speeds}</select></div>\n'
        f"{_timeline(player)}"
        f'<div class="mm-layers">{boxes}</div>\n<div class="mm-layers">{legend}</div>\n'
        f'<script type="application/json" class="mm-data">{payload}</script>\n</div>\n'
    )


def report_html(
    *,
    title: str,
    players: Sequence[Player] = (),
    sections: Sequence[Section] = (),
    tables: Sequence[Table] = (),
    images: Sequence[tuple[str, ImageSource]] = (),
    intro: str = "",
) -> str:
    """Return a self-contained HTML report: the players first, then ``tables`` and
    ``images`` (as one section "Results"), then ``sections``.

    ``images`` are ``(caption, PNG/JPEG path or bytes)`` pairs; ``intro`` is a line of text
    under the title.
    """
    out = [
        '<!DOCTYPE html>\n<html lang="en">\n<head>\n<meta charset="utf-8">\n',
        '<meta name="viewport" content="width=device-width, initial-scale=1">\n',
        f"<title>{_esc(title)}</title>\n<style>{_CSS}</style>\n</head>\n<body>\n",
        f'<header><h1>{_esc(title)}</h1><p class="mm-meta">{_esc(intro)}'
        f"{' · ' if intro else ''}written by meshmocap {__version__}</p></header>\n",
    ]
    if players:
        out.append('<section class="mm-players">\n')
        out += [_player_html(p, k) for k, p in enumerate(players)]
        out.append("</section>\n")
    parts = list(sections)
    if tables or images:
        parts.insert(0, Section("Results", tuple(tables), tuple(images)))
    for s in parts:
        out.append(f'<section class="mm-section">\n<h2>{_esc(s.title)}</h2>\n')
        out += [table_html(t) for t in s.tables]
        for caption, im in s.images:
            out.append(
                f'<figure><img src="{image_uri(im)}" alt="{_esc(caption)}">'
                f"<figcaption>{_esc(caption)}</figcaption></figure>\n"
            )
        if s.text:
            out.append(f"<pre>{_esc(s.text)}</pre>\n")
        out.append("</section>\n")
    if players:
        js = player_js()
        if "</script" in js.lower():
            raise InputError("report: player.js must not contain '</script'")
        out.append(f"<script>\n{js}</script>\n")
    out.append("</body>\n</html>\n")
    return "".join(out)


def write_report(path: str | os.PathLike, **content) -> Path:
    """Write :func:`report_html` (``**content``: its keyword arguments) to ``path`` (an
    ``.html`` file, folders created) atomically; return the path."""
    path = Path(path)
    if path.suffix.lower() not in (".html", ".htm"):
        raise InputError(f"report: the output must end in .html, found {path.name!r}")
    text = report_html(**content)
    path.parent.mkdir(parents=True, exist_ok=True)
    write_text_atomic(path, text)
    return path


def gait_section(
    capture: Capture | SequenceCapture, tracks: Sequence[Track], names: Sequence[str]
) -> Section:
    """The gait of each track (:mod:`meshmocap.analysis.gait`) against the capture's ground
    truth: a table, notes and each track's plots (Fig. 11, flexion over the cycle)."""
    with tempfile.TemporaryDirectory(prefix="meshmocap-gait-") as tmp:
        g = gait_report(capture, tracks, names, tmp)
    table = Table(
        "Gait from the tracked joints (and from the truth)",
        GAIT_HEADERS,
        g.rows,
        digits=2,
        notes=g.notes,
    )
    return Section("Gait", (table,), g.images)


def cameras_section(capture: Capture, track: Track, name: str, *, frames: int = 4) -> Section:
    """Each camera's frames with the track's skeleton and the silhouette's outline drawn
    over them (:func:`~meshmocap.apps.report.cameras.camera_views`)."""
    parents = np.asarray(track.meta.get("eval_parents", EVAL_PARENTS), np.int64)
    pictures, note = camera_views(capture, track, parents, frames=frames)
    text = (
        f"{name}'s skeleton (red, joints yellow) projected into each camera, over the "
        "silhouette's outline (green)" + (f"; {note}" if note else "")
    )
    return Section("Cameras", images=tuple(pictures), text=text)


def build_report(
    out: str | os.PathLike,
    capture: str | os.PathLike | Capture | SequenceCapture,
    tracks: Sequence[str | os.PathLike | Track],
    *,
    eval_dirs: Sequence[str | os.PathLike] | None = None,
    max_frames: int | None = None,
    silhouettes: bool = True,
    surface_frames: int = 8,
    camera_frames: int = 4,
    title: str | None = None,
) -> Path:
    """Evaluate ``tracks`` on ``capture`` and write a report to ``out`` (``.html``): a
    comparison table, a player of every track, and each evaluation's tables and plots.

    Parameters
    ----------
    capture : a capture folder (or glob of meshes) or an opened capture
    tracks : track folders (or read tracks), one or more
    eval_dirs : folders, one per track, optional
        Where each evaluation's CSV tables and PNG plots are written
        (:func:`~meshmocap.analysis.evaluate.write_evaluation`); default: a temporary
        folder, removed once the plots are embedded.
    max_frames : int, optional, at most this many frames in the player (default: every
        frame the size budget allows, :func:`~meshmocap.apps.report.player.player_from_tracks`)
    silhouettes, surface_frames : as in :func:`~meshmocap.analysis.evaluate.evaluate`
    camera_frames : int
        Frames of the section "Cameras" (each camera's video frame or silhouette with the
        first track's skeleton drawn over it, :mod:`meshmocap.apps.report.cameras`); 0 for
        none. A capture without cameras has no such section.
    """
    trs = [t if isinstance(t, Track) else read_track(t) for t in tracks]
    if not trs:
        raise InputError("report: expected at least one track, found none")
    cap = capture
    if not isinstance(capture, Capture | SequenceCapture):  # read as the track read it
        cap = open_tracked_capture(trs[0].meta, capture)
    if eval_dirs is not None and len(eval_dirs) != len(trs):
        raise InputError(
            f"eval_dirs: expected {len(trs)} folders (one per track), found {len(eval_dirs)}"
        )
    names = [str(t.meta.get("method", "?")) for t in trs]
    if len(set(names)) < len(names):
        names = [
            f"{n} ({Path(p).name if not isinstance(p, Track) else k})"
            for k, (n, p) in enumerate(zip(names, tracks, strict=True))
        ]
    why = (
        "the capture has no cameras" if silhouettes else "the report was made with --no-silhouettes"
    )
    evs, sections = [], []
    with tempfile.TemporaryDirectory(prefix="meshmocap-report-") as tmp:
        for k, (name, t) in enumerate(zip(names, trs, strict=True)):
            ev = evaluate(t, cap, silhouettes=silhouettes, surface_frames=surface_frames)
            folder = Path(eval_dirs[k]) if eval_dirs is not None else Path(tmp) / str(k)
            pngs = [p for p in write_evaluation(ev, folder) if p.suffix == ".png"]
            pics = tuple((p.stem.replace("_", " "), p.read_bytes()) for p in pngs)
            evs.append(ev)
            tables = tuple(evaluation_tables(ev, track=t))
            sections.append(Section(f"Evaluation: {name}", tables, pics))
    sections.append(gait_section(cap, trs, names))
    if camera_frames and isinstance(cap, Capture) and cap.cameras:
        sections.insert(0, cameras_section(cap, trs[0], names[0], frames=camera_frames))
    player = player_from_tracks(
        cap,
        trs,
        names=names,
        max_frames=max_frames,
        title=f"{', '.join(names)} on {Path(cap.path).name}",
        templates=[None if isinstance(p, Track) else track_templates([p])[0] for p in tracks],
    )
    return write_report(
        out,
        title=title or f"meshmocap report: {Path(cap.path).name}",
        players=[player],
        tables=[comparison_table(evs, names=names, no_silhouettes=why)],
        sections=sections,
        intro=f"capture {cap.path}, {len(cap)} frames; tracks: {', '.join(names)}",
    )
