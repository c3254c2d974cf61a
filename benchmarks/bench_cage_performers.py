"""The cage tracker on every performer: each bundled body, a body in a
loose skirt, and the MIT crane's clothed performer.

Protocol: synthetic ``humaneva4`` captures (4 cameras, 60 fps, hulls at 1 cm) of the
procedural walk, ``--frames`` frames, for each bundled template and for a **skirt**:
``neutral_5k`` whose lower torso and thighs are grown into a loose cone (:func:`skirt`: the
vertices between the knees and 5 cm above the hips pushed out to a cone 16 cm in radius at
the top flaring at ``--flare`` degrees; skinned as the legs they were, so the skirt swings
with them); the **crane** (``../shared/data``; ``ring8`` hulls of its 175 frames, the
tracking template its frame 0 rigged by :func:`~meshmocap.apps.bench.captures.mesh_template`)
when ``--crane``. Every capture is tracked by ``cage`` with default options (its manifold
the default one of the body it builds its cage on), first pose from the truth; the skirt
and the crane with the cage on the template where it builds (``body="auto"``) and on the
reference body (``"reference"``). Columns:
the body the cage was built on (``template`` or ``reference``: the bundled ``neutral``
posed on the template's skeleton, :mod:`meshmocap.trackers.cage.body`), seconds to build
the tracker (rigging and manifold, learned at first use and cached), the mean per-vertex
error of the template's own vertices against the truth and the mean joint error (mm),
seconds per frame of ``step``; the load average is printed.

Run: ``python benchmarks/bench_cage_performers.py [--frames 40] [--crane]
[--bodies neutral_5k ...] [--work /tmp/meshmocap-cage-performers]``.
"""

from __future__ import annotations

import argparse
import os
import time
from pathlib import Path

import numpy as np

from meshmocap.apps.bench.captures import make_capture, mesh_template, parse_capture
from meshmocap.body.template import Template, bundled_templates, load_template, save_template
from meshmocap.errors import MeshmocapError
from meshmocap.studio.synth import SynthSpec, synthesize
from meshmocap.trackers.registry import make_tracker

DATA = Path(__file__).resolve().parents[1].parent / "shared" / "data"


def skirt(template: Template, *, flare: float = 25.0, radius: float = 0.16) -> Template:
    """``template`` with its lower torso and thighs grown into a loose cone (module
    docstring): vertices between the knees and 5 cm above the hips, nearer the vertical
    axis through the root than the cone, pushed out onto it."""
    sk = template.skeleton
    P = sk.rest_positions
    top = P[sk.index("LeftUpLeg"), 2] + 0.05
    knee = P[sk.index("LeftLeg"), 2]
    V = template.V.copy()
    d = V[:, :2] - P[0, :2]
    r = np.linalg.norm(d, axis=1)
    cone = radius + np.clip(top - V[:, 2], 0.0, None) * np.tan(np.radians(flare))
    push = (V[:, 2] < top) & (V[:, 2] > knee) & (r < cone)
    V[push, :2] = P[0, :2] + d[push] / np.maximum(r[push], 1e-9)[:, None] * cone[push, None]
    return Template(
        f"{template.name}_skirt",
        V,
        template.F,
        sk,
        template.weights,
        template.part_labels,
        template.eval_skeleton,
    )


def track(template: Template, capture, frames: int, body: str = "auto") -> dict:
    """Cage track from the true first pose: body, setup seconds, errors, s/frame."""
    t0 = time.perf_counter()
    try:
        tracker = make_tracker("cage", template=template, body=body)
    except MeshmocapError as exc:
        return {"error": str(exc).splitlines()[0][:160], "setup": time.perf_counter() - t0}
    setup = time.perf_counter() - t0
    f0 = capture[0]
    R, root = f0.truth.rotations, f0.truth.root
    if R is None or np.ndim(R) != 3:  # a mesh sequence: the template is frame 0, at rest
        R = np.tile(np.eye(3), (template.skeleton.n_joints, 1, 1))
        root = template.skeleton.rest_positions[0]
    tracker.init(template, f0, R, root)
    verr, jerr, sec = [], [], []
    for k in range(1, min(frames, len(capture))):
        fr = capture[k]
        s0 = time.perf_counter()
        r = tracker.step(fr)
        sec.append(time.perf_counter() - s0)
        truth = fr.truth
        if truth.vertices is not None and len(truth.vertices) == len(r.vertices):
            verr.append(1000 * np.linalg.norm(r.vertices - truth.vertices, axis=1).mean())
        if truth.joints is not None and len(truth.joints) == len(r.joints):
            jerr.append(1000 * np.linalg.norm(r.joints - truth.joints, axis=1).mean())
    body = "template" if tracker.body is template else "reference"
    return {
        "body": body,
        "setup": setup,
        "vertex": float(np.mean(verr)) if verr else float("nan"),
        "joint": float(np.mean(jerr)) if jerr else float("nan"),
        "s/frame": float(np.median(sec)),
        "frames": len(sec),
    }


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--frames", type=int, default=40)
    ap.add_argument("--bodies", nargs="*", default=bundled_templates())
    ap.add_argument("--flare", type=float, default=25.0)
    ap.add_argument("--no-skirt", action="store_true")
    ap.add_argument("--skirt-bodies", nargs="+", default=["auto", "reference"])
    ap.add_argument("--crane", action="store_true", help="also the crane (175 frames)")
    ap.add_argument("--crane-bodies", nargs="+", default=["auto", "reference"])
    ap.add_argument("--work", default="/tmp/meshmocap-cage-performers")
    args = ap.parse_args()
    work = Path(args.work)
    rows = []
    spec = parse_capture("walk", frames=args.frames)
    for name in args.bodies:
        capture = make_capture(spec, work, template=name, show_progress=False)
        rows.append((f"{name}, walk", track(load_template(name), capture, args.frames)))
        print(rows[-1], flush=True)
    if not args.no_skirt:
        t = skirt(load_template("neutral_5k"), flare=args.flare)
        (work / "templates").mkdir(parents=True, exist_ok=True)
        path = save_template(work / "templates" / f"{t.name}.npz", t)
        out = work / "captures" / f"walk-{args.frames}@{t.name}-{args.flare:g}"
        synth = SynthSpec(motion="walk", template=str(path), stop=args.frames)
        capture = synthesize(out, synth, show_progress=False)
        for body in args.skirt_bodies:
            r = track(t, capture, args.frames, body)
            rows.append((f"{t.name} ({args.flare:g}°), walk, body={body}", r))
            print(rows[-1], flush=True)
    if args.crane:
        if not (DATA / "meshes" / "crane").is_dir():
            print(f"crane skipped: {DATA / 'meshes' / 'crane'} is absent")
        else:
            capture = make_capture(parse_capture("crane", data=DATA), work, show_progress=True)
            t = mesh_template(capture, cache=work / "templates" / f"{capture.path.name}.npz")
            for body in args.crane_bodies:
                r = track(t, capture, len(capture), body)
                rows.append((f"crane (ring8 hulls), body={body}", r))
                print(rows[-1], flush=True)
            print(rows[-1], flush=True)
    print(
        f"\n### cage on every performer; {args.frames}-frame walks; load average "
        f"{os.getloadavg()[0]:.2f} on {os.cpu_count()} cores"
    )
    print("| performer | cage built on | setup s | vertex mm | joint mm | s/frame |")
    print("|---|---|---:|---:|---:|---:|")
    for name, r in rows:
        if "error" in r:
            print(f"| {name} | fails in {r['setup']:.0f} s: {r['error']} | | | | |")
            continue
        print(
            f"| {name} | {r['body']} | {r['setup']:.1f} | {r['vertex']:.1f} | {r['joint']:.1f} "
            f"| {r['s/frame']:.3f} |"
        )


if __name__ == "__main__":
    main()
