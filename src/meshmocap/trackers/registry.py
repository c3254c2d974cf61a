"""Trackers by name, for the command line and the benchmark."""

from __future__ import annotations

import importlib
import os
from typing import TYPE_CHECKING, Any

from meshmocap.errors import InputError
from meshmocap.trackers.base import Tracker
from meshmocap.trackers.patch.options import PAPER

if TYPE_CHECKING:
    from meshmocap.body.template import Template
    from meshmocap.models.gplvm import GPLVM
    from meshmocap.trackers.cage.manifold import PoseManifold

_CAGE = ("meshmocap.trackers.cage.tracker", "CageTracker", "CageOptions")
#: The cage tracker's terms (meshmocap.trackers.cage.terms.ALL_TERMS, without importing it).
_CAGE_TERMS = ("distance", "variance", "coverage", "silhouette", "anchor", "articulation")

#: method name → (module, tracker class, options class, fixed options)
METHODS: dict[str, tuple[str, str, str, dict[str, Any]]] = {
    "patch": ("meshmocap.trackers.patch.tracker", "PatchTracker", "PatchOptions", {}),
    # the paper's classifier (libsvm linear SVC, Platt probabilities) instead of the default
    "patch_svc": (
        "meshmocap.trackers.patch.tracker",
        "PatchTracker",
        "PatchOptions",
        {"classifier": "svc"},
    ),
    "patch_noclf": (
        "meshmocap.trackers.patch.tracker",
        "PatchTracker",
        "PatchOptions",
        {"classifier": "none"},
    ),
    # the patch tracker with or without each of its extensions beyond the paper (issue 20;
    # PATCH_ABLATIONS), and the paper's method alone (Eq. 1 and the SVM of §III-B)
    **{
        name: ("meshmocap.trackers.patch.tracker", "PatchTracker", "PatchOptions", fixed)
        for name, fixed in (
            ("patch_gate", {"accel_gate": 72.0}),
            ("patch_interior", {"interior_scale": 0.01}),
            ("patch_sil", {"lambda_silhouette": 10.0}),
            ("patch_coarse", {"coarse_iter": 2}),
            ("patch_temporal", {"lambda_temporal": 1.0}),
            ("patch_paper", PAPER),
        )
    },
    "articulated_icp": ("meshmocap.trackers.articulated_icp", "ArticulatedICP", "ICPOptions", {}),
    # the cage tracker and its ablations (cage-manifold-tracking Fig. 5, Table 1); a cage
    # variant is a term list (CageOptions.terms, trackers/cage/terms.py) plus options
    "cage": (*_CAGE, {}),
    "cage_quads": (*_CAGE, {"space": "quads"}),
    "cage_noreg": (*_CAGE, {"terms": tuple(t for t in _CAGE_TERMS if t != "variance")}),
    "cage_nolocal": (*_CAGE, {"local_iters": 0}),
    # without each extension beyond the paper (issue 20; CAGE_ABLATIONS)
    "cage_nosil": (*_CAGE, {"terms": tuple(t for t in _CAGE_TERMS if t != "silhouette")}),
    "cage_nowiden": (*_CAGE, {"off_manifold": 0.0}),
    "cage_green": (*_CAGE, {"surface": "green", "joints": "green"}),
    # exactly the paper's energy (Eq. 4 and 5), its surface (Eq. 1), joints (§6.2) and
    # cage (on the template, §3), no widening
    "cage_paper": (
        *_CAGE,
        {
            "terms": ("distance", "variance"),
            "surface": "green",
            "joints": "green",
            "body": "template",
            "off_manifold": 0.0,
        },
    ),
}

#: The patch tracker's ablations (bench's ablation table): method → what it changes.
PATCH_ABLATIONS: dict[str, str] = {
    "patch_noclf": "− body-part classifier (§III-B)",
    "patch_gate": "+ acceleration gate of the prediction",
    "patch_interior": "+ hull points inside the model as outliers",
    "patch_sil": "+ silhouette coverage",
    "patch_coarse": "+ part-rigid first iterations",
    "patch_temporal": "+ temporal prior on the joints",
    "patch_paper": "− every extension (the paper alone)",
}

#: Methods whose tracker needs a pose manifold (``make_tracker(..., manifold=)``).
MANIFOLD_METHODS = tuple(m for m, spec in METHODS.items() if spec[:3] == _CAGE)


def make_tracker(
    method: str,
    *,
    manifold: GPLVM | PoseManifold | str | os.PathLike | None = None,
    template: Template | None = None,
    **options: Any,
) -> Tracker:
    """Return the tracker ``method`` (see :data:`METHODS`) with ``options`` (fields of its
    options dataclass; unknown names are rejected).

    Parameters
    ----------
    method : str
        A key of :data:`METHODS`.
    manifold : GPLVM, PoseManifold, path or None
        Cage methods (:data:`MANIFOLD_METHODS`) only: the pose manifold, see
        :func:`~meshmocap.trackers.cage.manifold.resolve_manifold` (None: the template's
        default manifold, learned from the bundled pose library at first use and cached).
    template : Template, optional
        The tracking template. Cage methods need it unless ``manifold`` is a fitted GPLVM:
        the tracker is set up for it and the manifold checked against it (one-line
        :class:`InputError` when built for another template).
    **options
        Fields of the method's options dataclass.
    """
    if method not in METHODS:
        raise InputError(f"track: method must be one of {sorted(METHODS)}, found {method!r}")
    module, cls, opts_cls, fixed = METHODS[method]
    if manifold is not None and method not in MANIFOLD_METHODS:
        raise InputError(
            f"track: a manifold is only used by {list(MANIFOLD_METHODS)}, not {method!r}"
        )
    mod = importlib.import_module(module)
    try:
        opts = getattr(mod, opts_cls)(**{**options, **fixed})
    except TypeError as exc:
        raise InputError(f"track: {exc}") from None
    except InputError as exc:  # one line: the method, then the option and its constraint
        raise InputError(f"track: method {method!r}: {exc}") from None
    if method not in MANIFOLD_METHODS:
        return getattr(mod, cls)(opts)
    from meshmocap.trackers.cage.body import cage_body
    from meshmocap.trackers.cage.manifold import PoseManifold, resolve_manifold

    # the body the cage is built on (the template, or a body posed on its skeleton) and
    # its rigging, built once: the manifold is the body's, the driver keeps the rigging
    rig = cage_body(template, body=opts.body) if template is not None else None
    body = rig[0] if rig is not None else None
    pm = resolve_manifold(manifold, body, rig[1] if rig is not None else None)
    tracker = getattr(mod, cls)(pm.gp if isinstance(pm, PoseManifold) else pm, opts)
    if template is not None:
        tracker.setup(template, rig=rig)
        if isinstance(pm, PoseManifold):
            named = isinstance(manifold, str | os.PathLike)
            pm.check(body, tracker.oqr, source=manifold if named else None)
    return tracker


def resolved_options(method: str) -> Any:
    """The options dataclass ``method`` runs with by default (its fixed options over the
    class's defaults): two methods that resolve to equal options are the same method."""
    if method not in METHODS:
        raise InputError(f"track: method must be one of {sorted(METHODS)}, found {method!r}")
    module, _, opts_cls, fixed = METHODS[method]
    return getattr(importlib.import_module(module), opts_cls)(**fixed)


def method_options(method: str) -> tuple[str, ...]:
    """The options ``method`` takes (fields of its options dataclass, less those the method
    fixes), for front ends that offer only what a method uses."""
    import dataclasses

    if method not in METHODS:
        raise InputError(f"track: method must be one of {sorted(METHODS)}, found {method!r}")
    module, _, opts_cls, fixed = METHODS[method]
    opts = getattr(importlib.import_module(module), opts_cls)
    return tuple(f.name for f in dataclasses.fields(opts) if f.name not in fixed)


#: The cage tracker's ablations (issue 20): method → what it leaves out of ``cage``.
CAGE_ABLATIONS: dict[str, str] = {
    "cage_nolocal": "local adjustment (Table 1)",
    "cage_nosil": "silhouette coverage (hull coverage instead)",
    "cage_nowiden": "off-manifold widening",
    "cage_green": "skinned surface and quad joints (Green coordinates, §6.2)",
    "cage_paper": "every extension: only the paper's terms, surface, joints and cage",
}
