"""Calibration of the ``lost`` flag on tracks of motions it never saw.

Protocol. Tracks of ``bench_limbs`` captures (synthetic CMU motions performed by
heavy_male and small_female, headings and offsets drawn per trial; ``--tracks``: folders
``<capture>/<method>-<path>/`` as ``bench_limbs`` writes them, the capture found in
``--captures`` by name), every tracker, default options. For every tracked frame the
evidence of :mod:`meshmocap.estimate.recovery.evidence` is replayed exactly as the driver
computes it (:class:`~meshmocap.estimate.recovery.reinit.Recovery` over the track's frames in
order, on the tracked body), and each limb's worst joint error (15 evaluation joints, mm)
is taken against the truth. A frame is **bad** when a joint is more than 150 mm off.

A track of the two-way pass (``<method>-two-way``) also has, per frame it chose, the other
tracks' disagreement (``track.json``'s ``two_way.disagreement``,
:data:`~meshmocap.estimate.recovery.evidence.DISAGREEMENT`): a frame is flagged where it
passes the rule's disagreement thresholds, fixed at the bad-frame criterion
(:data:`~meshmocap.estimate.recovery.evidence.DISAGREE`), and those flags count against
the evidence's budget.

Leave one category out: for each motion category (``bench_limbs.TRIALS``), the rule's
thresholds are fitted (:func:`~meshmocap.estimate.recovery.evidence.fit_rule`) on the frames
of the other categories only, the budget of good frames flagged (``--good-rate``) held in
each of them (``fit_rule``'s ``groups``: a margin for the category left out), and scored
on that category's frames; the table gives, per
left-out category and over all, the share of bad frames flagged (recall), the share of
good frames flagged, and the thresholds fitted. The rule is held over ``--frames`` frames in
a row (default: the shipped rule's, :attr:`~meshmocap.estimate.recovery.evidence.LostRule.frames`):
its thresholds are fitted to the evidence held so. Targets: ≥ 90 % of bad frames
flagged, ≤ 5 % of good frames flagged. The rule shipped
(``meshmocap/estimate/recovery/data/lost_rule.json``) is fitted on all the frames
(``--write``), after the left-out scores are reported.

Run: ``python benchmarks/bench_lost.py --tracks WORK/tracks --captures WORK/captures
[--subjects DIR] [--paths default two-way] [--good-rate 0.04] [--write]``
(``WORK``: a ``bench_limbs.py --work`` folder). Per-track evidence is read from
``bench_limbs``'s replay beside each track where there is one, else computed and cached in
``--work`` (``evidence-<capture>-<track>.npz``).
"""

from __future__ import annotations

import argparse
import json
import os
from pathlib import Path

import numpy as np

from bench_limbs import TRIALS
from meshmocap._threads import blas_threads
from meshmocap.body.light import tracking_body
from meshmocap.body.template import load_template
from meshmocap.estimate.recovery.evidence import (
    DISAGREEMENT,
    RULE_FILE,
    LostRule,
    fit_rule,
    shipped_rule,
)
from meshmocap.estimate.recovery.observe import observed
from meshmocap.estimate.recovery.quality import LIMB_PARTS
from meshmocap.estimate.recovery.reinit import Recovery
from meshmocap.io.capture import Capture
from meshmocap.io.results import read_track
from meshmocap.trackers.frame_step import read_track_frame

BAD_MM = 150.0
#: The share of good frames a fitted rule may flag (``--good-rate``).
GOOD_RATE = 0.04
#: Frames in a row the fitted rule holds a measure over (``--frames``): the shipped rule's.
FRAMES = shipped_rule().frames


def track_template(track_dir: Path, capture_name: str, subjects: list[Path]):
    """The template a track was made with: the performer's own body (``init`` truth,
    protocol) or the body estimated for it (``subjects/<capture>/subject.npz``)."""
    meta = json.loads((track_dir / "track.json").read_text())
    if meta.get("template_source") == "estimated":
        for s in subjects:
            f = s / capture_name / meta.get("template_file", "subject.npz")
            if f.is_file():
                return load_template(f)
        raise SystemExit(f"--subjects: no estimated body for {capture_name} in {subjects}")
    return load_template(capture_name.split("-")[1])


def track_evidence(track_dir: Path, cap: Capture, template) -> dict:
    """Per frame (from the second): the evidence (T, L, E) as the driver computes it, each
    limb's worst joint error (T, L) mm, the frame's ``lost`` flag as tracked (T,)."""
    body = tracking_body(template).light
    track = read_track(track_dir, vertices=False)
    frames = [int(i) for i in track.frames]
    r0 = read_track_frame(track_dir, frames[0])
    rec = Recovery(body, r0.state["pose_R"], r0.state["pose_root"])
    names = template.eval_skeleton.names
    limb_of = np.array(
        [next(k for k, (n, v) in enumerate(LIMB_PARTS.items()) if m in v) for m in names]
    )
    ev, err, lost = [], [], []
    with blas_threads():
        for i in frames[1:]:
            r = read_track_frame(track_dir, i)
            frame = observed(cap[cap.indices.index(i)])
            ev.append(rec.assess(frame, r.vertices, start=_start(rec, r)).evidence)
            truth = frame.truth.joints
            d = 1000 * np.linalg.norm(r.joints - truth, axis=1)
            err.append([d[limb_of == k].max(initial=0.0) for k in range(len(LIMB_PARTS))])
            lost.append("lost" in r.flags)
    return dict(evidence=np.array(ev), error=np.array(err), lost=np.array(lost))


def track_disagreement(track_dir: Path, n: int) -> np.ndarray:
    """(n, D) metres: the disagreement the two-way pass recorded for the track's frames from
    the second (``track.json``'s ``two_way.disagreement``; zeros on a frame without one, on
    every frame of a forward track)."""
    meta = json.loads((Path(track_dir) / "track.json").read_text())
    rec = {int(d["frame"]): d for d in (meta.get("two_way") or {}).get("disagreement", ())}
    frames = sorted(int(p.stem) for p in (Path(track_dir) / "frames").glob("*.npz"))
    out = np.zeros((n, len(DISAGREEMENT)))
    for t, i in enumerate(frames[1 : 1 + n]):
        if i in rec:
            out[t] = [rec[i].get(m, 0) / 1000 for m in DISAGREEMENT]
    return out


def _start(rec, r):
    R, root = r.state.get("R"), r.state.get("root")
    if R is None or root is None or np.shape(R) != rec.R.shape:
        return None
    return np.asarray(R, np.float64), np.asarray(root, np.float64)


def gather(args) -> list[dict]:
    """Evidence of every track found, cached per track."""
    work = Path(args.work)
    work.mkdir(parents=True, exist_ok=True)
    caps = {p.name: p for c in args.captures for p in Path(c).iterdir() if p.is_dir()}
    rows = []
    for root in args.tracks:
        for tdir in sorted(Path(root).glob("*/*-*")):
            if not (tdir / "track.json").is_file():
                continue
            name, method_path = tdir.parent.name, tdir.name
            trial = name.split("-")[0]
            method, path = method_path.split("-", 1)
            if name not in caps or trial not in TRIALS or path not in args.paths:
                continue
            cache = work / f"evidence-{name}-{method_path}-{Path(root).parent.name}.npz"
            beside = tdir.with_name(f"{tdir.name}.evidence.npz")  # bench_limbs's replay
            if beside.is_file():
                cache = beside
            if not cache.is_file():
                tpl = track_template(tdir, name, [Path(s) for s in args.subjects])
                d = track_evidence(tdir, Capture(caps[name]), tpl)
                np.savez(cache, **d)
                print(f"  evidence of {name} {method_path}: {len(d['lost'])} frames", flush=True)
            z = np.load(cache)
            rows.append(
                dict(
                    name=name,
                    trial=trial,
                    category=TRIALS[trial][1],
                    method=method,
                    path=path,
                    evidence=z["evidence"],
                    error=z["error"],
                    lost=z["lost"],
                    disagreement=track_disagreement(tdir, len(z["lost"])),
                )
            )
    return rows


def score(rule: LostRule, rows: list[dict]) -> dict:
    """Bad frames flagged / bad frames, good frames flagged / good frames: flagged by the
    rule's evidence or, where a row has ``disagreement`` (T, D), by its disagreement (a
    row's ``also`` (T,) bool, where given: frames flagged besides the rule's)."""
    bad = flagged = good = false = 0
    for r in rows:
        f = rule.flags(r["evidence"]) | r.get("also", False)
        if r.get("disagreement") is not None:
            f = f | rule.disagrees(r["disagreement"])
        b = (r["error"] > BAD_MM).any(axis=1)
        bad += int(b.sum())
        flagged += int((f & b).sum())
        good += int((~b).sum())
        false += int((f & ~b).sum())
    return dict(bad=bad, bad_flagged=flagged, good=good, good_flagged=false)


def _pct(a: int, b: int) -> str:
    return f"{100 * a / b:.1f} %" if b else "–"


def _row(label: str, n: int, s: dict, o: dict, rule: str) -> str:
    """A markdown row: the rule's counts ``s`` and, as tracked, the flags' ``o``."""
    return (
        f"| {label} | {n} | {s['bad']} | {s['bad_flagged']} ({_pct(s['bad_flagged'], s['bad'])})"
        f" | {s['good']} | {s['good_flagged']} ({_pct(s['good_flagged'], s['good'])})"
        f" | {_pct(o['bad_flagged'], o['bad'])} / {_pct(o['good_flagged'], o['good'])} | {rule} |"
    )


def as_tracked(rows: list[dict]) -> dict:
    """The counts of the ``lost`` flags the tracks carry (the rule they were made with)."""
    b = [(r["error"] > BAD_MM).any(axis=1) for r in rows]
    return dict(
        bad=sum(int(x.sum()) for x in b),
        bad_flagged=sum(int((r["lost"] & x).sum()) for r, x in zip(rows, b, strict=True)),
        good=sum(int((~x).sum()) for x in b),
        good_flagged=sum(int((r["lost"] & ~x).sum()) for r, x in zip(rows, b, strict=True)),
    )


def rule_of(rows: list[dict], good_rate: float, frames: int = FRAMES) -> LostRule:
    """The rule fitted on ``rows`` (their evidence, the budget held in each of their
    categories; their disagreement flagged at the fixed thresholds,
    :func:`~meshmocap.estimate.recovery.evidence.fit_rule`)."""
    return fit_rule(
        [r["evidence"] for r in rows],
        [(r["error"] > BAD_MM).any(axis=1) for r in rows],
        good_rate=good_rate,
        frames=frames,
        groups=[r["category"] for r in rows],
        disagreement=[
            r["disagreement"]
            if r.get("disagreement") is not None
            else np.zeros((len(r["evidence"]), len(DISAGREEMENT)))
            for r in rows
        ],
    )


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--tracks", nargs="+", required=True)
    ap.add_argument("--captures", nargs="+", required=True)
    ap.add_argument("--subjects", nargs="*", default=[])
    ap.add_argument("--work", default="/tmp/meshmocap-lost")
    ap.add_argument(
        "--paths",
        nargs="+",
        default=["default", "two-way"],
        help="the tracks used (<method>-<path>): default path forward, two-way, protocol",
    )
    ap.add_argument(
        "--good-rate", type=float, default=GOOD_RATE, help="budget of good frames flagged"
    )
    ap.add_argument(
        "--frames", type=int, default=FRAMES, help="frames in a row the rule holds a measure"
    )
    ap.add_argument("--write", action="store_true", help="ship the rule fitted on all frames")
    args = ap.parse_args()
    args.subjects = args.subjects or [str(Path(t).parent / "subjects") for t in args.tracks]
    rows = gather(args)
    cats = sorted({r["category"] for r in rows})
    n_frames = sum(len(r["lost"]) for r in rows)
    print(f"\n{len(rows)} tracks, {n_frames} frames; budget {args.good_rate}; {os.getloadavg()}")
    print(
        "\n| left out | tracks | bad frames | flagged (recall) | good frames | flagged "
        "| as tracked: recall / good flagged | thresholds fitted without it |"
    )
    print("|---|---:|---:|---:|---:|---:|---:|---|")
    keys = ("bad", "bad_flagged", "good", "good_flagged")
    tot, old = dict.fromkeys(keys, 0), dict.fromkeys(keys, 0)
    for c in cats:
        test = [r for r in rows if r["category"] == c]
        rule = rule_of([r for r in rows if r["category"] != c], args.good_rate, args.frames)
        s, o = score(rule, test), as_tracked(test)
        for k in keys:
            tot[k] += s[k]
            old[k] += o[k]
        print(_row(c, len(test), s, o, rule.describe()))
    print(_row("**all, each left out**", len(rows), tot, old, ""))
    by_method = {}
    for r in rows:
        by_method.setdefault(r["method"], []).append(r)
    full = rule_of(rows, args.good_rate, args.frames)
    print(f"\nfitted on all frames: {full.describe()}; in-sample per tracker:")
    for m, rs in sorted(by_method.items()):
        s = score(full, rs)
        print(
            f"  {m}: recall {_pct(s['bad_flagged'], s['bad'])} of {s['bad']}, good flagged "
            f"{_pct(s['good_flagged'], s['good'])} of {s['good']}"
        )
    if args.write:
        note = (
            f"fitted by benchmarks/bench_lost.py (budget {args.good_rate} of good frames, "
            f"{args.frames} frames in a row) on "
            f"{len(rows)} tracks ({', '.join(sorted(by_method))}; {', '.join(args.paths)}), "
            f"{n_frames} frames, categories {', '.join(cats)}"
        )
        full.write(RULE_FILE, note=note)
        print(f"wrote {RULE_FILE}")


if __name__ == "__main__":
    main()
