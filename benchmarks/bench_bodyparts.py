"""Benchmark the body-part classifier of the patch tracker (§III-B): speed and accuracy.

For each method: fit time on 3,000 training vertices, predict time for 10,000 points,
accuracy on the next frame's template vertices (procedural walk at 60 fps, frames 1 and 10
apart), and on the visual-hull vertices of a synthetic capture (each hull vertex labelled
by its nearest truth vertex), with the fraction of hull points each method calls outliers
(Eq. (6): p ≤ 0.5) and, as the extension, farther than 10 cm from the previous mesh.

The faster method is the default only where it is as accurate on this benchmark.

Run: ``python benchmarks/bench_bodyparts.py`` (about a minute; the capture is synthesised
in a temporary folder).
"""

from __future__ import annotations

import itertools
import tempfile
import time

import numpy as np
from scipy.spatial import cKDTree

from meshmocap.body.procedural import procedural_motion
from meshmocap.body.template import load_template
from meshmocap.models.bodyparts import METHODS, OUTLIER, BodyPartClassifier, partition
from meshmocap.studio.synth import SynthSpec, synthesize

SURFACE = 0.03  # metres: hull vertices this close to a truth vertex are on the body
PHANTOM = 0.10  # metres: hull vertices this far from every truth vertex are phantom volume
GATE = 0.10  # metres: partition(max_distance=) of the extension

#: Non-leaf bone labels the tracker uses: head→thorax, wrists→elbows, ankles→knees.
_LEAF_TO_PARENT = {2: 1, 5: 4, 8: 7, 11: 10, 14: 13}


def bone_labels(parts: np.ndarray) -> np.ndarray:
    """Map the 15 evaluation-part labels onto the 10 non-leaf bones."""
    out = parts.copy()
    for leaf, parent in _LEAF_TO_PARENT.items():
        out[parts == leaf] = parent
    return out


def best(fn, repeat: int = 3) -> float:
    """Best wall time of ``repeat`` calls, seconds."""
    out = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        out.append(time.perf_counter() - t0)
    return min(out)


def main() -> None:
    t = load_template("neutral_5k")
    walk = procedural_motion("walk", t, duration=2.0, fps=60.0)
    V = t.pose(walk.rotations, walk.root_positions).V
    starts = list(range(0, 100, 10))  # 10 training frames spread over the gait cycle
    rng = np.random.default_rng(0)
    Y10k = V[1][rng.integers(len(V[1]), size=10_000)] + rng.normal(scale=0.01, size=(10_000, 3))

    with tempfile.TemporaryDirectory() as tmp:
        t0 = time.perf_counter()
        cap = synthesize(
            tmp, SynthSpec(motion="walk", template="neutral_5k", stop=12), show_progress=False
        )
        frames = [(f.truth.vertices, f.hull_mesh[0]) for f in cap]
        synth_s = time.perf_counter() - t0
    n_hull = int(np.mean([len(h) for _, h in frames]))
    print(
        f"neutral_5k: {t.n_vertices} vertices; walk at 60 fps; capture of {len(frames)} "
        f"frames synthesised in {synth_s:.0f} s, {n_hull} hull vertices per frame\n"
    )

    names = [
        "acc +1",
        "acc +10",
        "err>.9",
        "hull acc",
        "hull out",
        "surf out",
        "phant out",
        "gate out",
        "gate ph",
        "kept",
    ]
    head = f"{'method':9s} {'labels':7s} {'fit 3k':>8s} {'pred 10k':>9s} " + " ".join(
        f"{n:>9s}" for n in names
    )
    print(head)
    print("-" * len(head))
    for method in METHODS:
        for lname in ("parts15", "bones10"):
            lab = t.part_labels if lname == "parts15" else bone_labels(t.part_labels)

            def clf(method=method, lab=lab, X=V[0]):
                return BodyPartClassifier(method, random_state=0).fit(X, lab)

            fit_s = best(clf)
            c = clf()
            pred_s = best(lambda c=c: c.predict(Y10k))
            acc, sure = {1: [], 10: []}, []
            for s in starts:
                c = BodyPartClassifier(method, random_state=s).fit(V[s], lab)
                for gap in (1, 10):
                    pred, p = c.predict(V[s + gap])
                    acc[gap].append(np.mean(pred == lab))
                    if gap == 1:
                        sure.append(np.mean(p[pred != lab] > 0.9))
            # hull: train on the previous frame's truth mesh, classify this frame's hull
            h_acc, h_out, h_sf, h_ph, h_gate, h_gph, h_keep = [], [], [], [], [], [], []
            for (prev, _), (truth, hull) in itertools.pairwise(frames):
                c = BodyPartClassifier(method, random_state=0).fit(prev, lab)
                d, nearest = cKDTree(truth).query(hull)
                surface, phantom = d <= SURFACE, d > PHANTOM
                part = partition(c, hull, random_state=0)
                gated = partition(c, hull, max_distance=GATE, random_state=0)
                h_acc.append(np.mean(part.labels[surface] == lab[nearest[surface]]))
                h_out.append(np.mean(part.kind == OUTLIER))
                h_sf.append(np.mean(part.kind[surface] == OUTLIER))
                h_ph.append(np.mean(part.kind[phantom] == OUTLIER))
                h_gate.append(np.mean(gated.kind == OUTLIER))
                h_gph.append(np.mean(gated.kind[phantom] == OUTLIER))
                h_keep.append(np.mean(part.keep))
            cols = [
                np.mean(acc[1]),
                np.mean(acc[10]),
                np.mean(sure),
                np.mean(h_acc),
                np.mean(h_out),
                np.mean(h_sf),
                np.mean(h_ph),
                np.mean(h_gate),
                np.mean(h_gph),
                np.mean(h_keep),
            ]
            print(
                f"{method:9s} {lname:7s} {fit_s * 1e3:6.0f}ms {pred_s * 1e3:7.1f}ms "
                + " ".join(f"{v:9.1%}" for v in cols)
            )
    print(f"""
acc +k     next-frame accuracy on template vertices k frames later (mean of 10 starts)
err>.9     fraction of the misclassified vertices at +1 with p > 0.9 (Eq. (6) keeps them as
           on-bone points: wrong and confident)
hull       frames 1-11 of the capture, each classified by a model trained on the previous
           frame's truth mesh (bundled-template labels, max_train 3000)
hull acc   accuracy on hull vertices within {SURFACE * 100:.0f} cm of a truth vertex (the \
label of the nearest)
hull out   fraction of all hull vertices with p ≤ 0.5 (Eq. (6) outliers)
surf out   fraction of the hull vertices within 3 cm of a truth vertex with p ≤ 0.5 (lost)
phant out  fraction of phantom hull vertices (> {PHANTOM * 100:.0f} cm from every truth vertex) \
with p ≤ 0.5
gate out   outliers with partition(max_distance={GATE}) (p ≤ 0.5 or > {GATE * 100:.0f} cm from \
the previous mesh)
gate ph    phantom vertices caught with that gate
kept       fraction of hull vertices kept at keep_fraction 0.3""")


if __name__ == "__main__":
    main()
