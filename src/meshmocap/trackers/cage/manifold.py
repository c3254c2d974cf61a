"""Pose manifolds for the cage tracker: learned, saved with what they were built for, checked.

A pose manifold is a back-constrained GPLVM (:class:`~meshmocap.models.gplvm.GPLVM`) over
the pelvis-relative quad configurations of one template's Oriented Quads Rigging
(cage-manifold-tracking §4, §6.2). Those configurations only make sense for the quads
they were measured with, so :class:`PoseManifold` keeps, beside the model, the template's
name and a digest of its mesh and skeleton, and the OQR's rest cage; :meth:`PoseManifold.check`
refuses a tracking template that differs, in one line.

File format: the GPLVM's own ``.npz`` (:meth:`GPLVM.save`; :meth:`GPLVM.load` reads these
files too) plus these keys:

=======================  ==============  ==================================================
key                      shape / dtype   meaning
=======================  ==============  ==================================================
manifold_format          str             ``"meshmocap-pose-manifold-1"``
manifold_template        str             template name
manifold_digest          str             :func:`template_digest` of the template
manifold_rest_cage       (85, 3) float   the OQR's rest cage, metres, world frame (Z up)
manifold_trials          (N,) str        trial of each training pose
manifold_groups          (N,) str        group of each training pose (``walk``, ``jog``…)
manifold_sources         (S,) str        the sources read
manifold_stats           (2,) float      poses available, fit seconds
=======================  ==============  ==================================================

References
----------
- E. Duveau, S. Courtemanche, L. Reveret, E. Boyer, *Cage-based motion recovery
  using manifold learning*, International Conference on 3D Imaging, Modeling,
  Processing, Visualization and Transmission (3DIMPVT), 2012.
- N. D. Lawrence, *Probabilistic non-linear principal component analysis with
  Gaussian process latent variable models*, Journal of Machine Learning Research
  6:1783–1816, 2005.
- N. D. Lawrence, J. Quiñonero-Candela, *Local distance preservation in the GP-LVM
  through back constraints*, International Conference on Machine Learning (ICML),
  2006. https://doi.org/10.1145/1143844.1143909
"""

from __future__ import annotations

import hashlib
import logging
import os
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from meshmocap._npz import read_npz
from meshmocap.body.motion import Motion
from meshmocap.body.template import Template
from meshmocap.errors import FormatError, InputError, MeshmocapFileNotFoundError
from meshmocap.models.gplvm import GPLVM
from meshmocap.trackers.cage.oqr import OQR, build_oqr, configuration_vector, quads_from_pose
from meshmocap.trackers.cage.training_poses import PoseSet, load_pose_sources

__all__ = [
    "DEFAULT_SOURCES",
    "MANIFOLD_FORMAT",
    "LatentStart",
    "PoseManifold",
    "default_manifold",
    "default_manifold_note",
    "default_manifold_path",
    "default_start",
    "fit_pose_manifold",
    "learn_manifold",
    "learn_pose_manifold",
    "resolve_manifold",
    "template_digest",
]

MANIFOLD_FORMAT = "meshmocap-pose-manifold-1"
#: Sources of the manifold learned when none is given: the first 400 poses of the bundled
#: CMU pose library (:mod:`~meshmocap.body.pose_library`; farthest-point order, so they
#: spread over walks, runs, jumps, dances and everyday actions). The procedural walk and
#: jog it replaces could not represent a dance: the cage fell off the body (issue 20).
DEFAULT_SOURCES = ("library:400",)
#: Latent dimension and training poses of the default manifold (the paper: q = 10 for
#: varied locomotion; 5 keeps the latent step cheap).
DEFAULT_COMPONENTS = 5
#: Training poses of the default manifold.
DEFAULT_POSES = 400
#: L-BFGS-B iterations of a manifold learned on the fly (GPLVM's default is 2000), from the
#: bundled start (:func:`default_start`). From the PCA start 1,000 left the fit far from an
#: optimum, where the last bits of its sums decided where it stopped, and the cage tracked
#: worse with fewer (``docs/guide/cage.rst``, the demo's manifold); from the bundled start
#: the likelihood begins above where 1,000 from PCA ended (``docs/measurements.rst``).
ON_THE_FLY_MAX_ITER = 300
#: The bundled start of the default manifold's fit (``tools/make_manifold_start.py``).
START_FILE = Path(__file__).with_name("data") / "manifold_start.npz"
#: Environment variable naming the folder where learned default manifolds are cached
#: (default ``$XDG_CACHE_HOME/meshmocap`` or ``~/.cache/meshmocap``; ``off``: no cache).
CACHE_ENV = "MESHMOCAP_CACHE"
#: How the cached default manifold was fitted, part of its cache key: manifolds cached
#: before the GPLVM fit ran on one BLAS thread (:meth:`~meshmocap.models.gplvm.GPLVM.fit`)
#: depend on the thread count of the call that learned them, and are learned again.
_FIT = "one BLAS thread"
#: Largest difference, metres, between a manifold's stored rest cage and the tracking
#: template's OQR (a rebuilt OQR is bit-identical; anything larger is another rigging).
CAGE_TOLERANCE = 1e-6

log = logging.getLogger(__name__)


def template_digest(template: Template) -> str:
    """16 hex digits of SHA-256 over the template's rest mesh and skeleton (names, rest
    positions): equal for the same template loaded twice, different for any other."""
    h = hashlib.sha256()
    sk = template.skeleton
    for a in (template.V, template.F, sk.rest_positions):
        a = np.ascontiguousarray(a, dtype=np.float64 if a.dtype.kind == "f" else np.int64)
        h.update(a.tobytes())
    h.update("\0".join(sk.names).encode())
    return h.hexdigest()[:16]


@dataclass(frozen=True, eq=False)
class PoseManifold:
    """A fitted pose manifold and what it was built for.

    Attributes
    ----------
    gp : GPLVM
        Fitted on ``(N, 180)`` pelvis-relative quad configurations.
    template_name : str
    template_digest : str
        :func:`template_digest` of the template.
    rest_cage : (85, 3) float64
        Rest cage of the template's OQR, metres, world frame (Z up).
    trials, groups : (N,) str
        Labels of the training poses (:class:`~meshmocap.trackers.cage.training_poses.PoseSet`).
    sources : tuple of str
        The sources read.
    n_poses : int
        Poses available before subsampling to N.
    fit_seconds : float
        Wall time of the GPLVM fit.
    """

    gp: GPLVM
    template_name: str
    template_digest: str
    rest_cage: np.ndarray
    trials: np.ndarray
    groups: np.ndarray
    sources: tuple[str, ...]
    n_poses: int
    fit_seconds: float

    @property
    def n_samples(self) -> int:
        """Training poses N."""
        return int(self.gp.X_.shape[0])

    @property
    def n_components(self) -> int:
        """Latent dimension q."""
        return int(self.gp.X_.shape[1])

    def check(self, template: Template, oqr: OQR | None = None, *, source: object = None) -> None:
        """Raise :class:`InputError` unless this manifold was built for ``template`` (and,
        when given, for its rigging ``oqr``). ``source`` (e.g. the file) names it."""
        what = f"{source}: manifold" if source is not None else "manifold"
        digest = template_digest(template)
        if (self.template_name, self.template_digest) != (template.name, digest):
            raise InputError(
                f"{what} was built for template {self.template_name!r} "
                f"(digest {self.template_digest}), not the tracking template {template.name!r} "
                f"(digest {digest}); learn one with 'meshmocap learn ... --template "
                f"{template.name}'"
            )
        if oqr is not None:
            cage = oqr.rest_vertices
            gap = (
                float(np.abs(cage - self.rest_cage).max())
                if cage.shape == self.rest_cage.shape
                else np.inf
            )
            if gap > CAGE_TOLERANCE:
                raise InputError(
                    f"{what} was built for another quad rigging of template "
                    f"{template.name!r} (rest cages differ by {gap:.3g} m); learn it again"
                )

    def save(self, path: str | os.PathLike) -> Path:
        """Write the manifold to ``path`` (``.npz``) atomically; returns the path."""
        path = Path(path)
        if path.suffix != ".npz":
            raise InputError(f"PoseManifold.save: path must end in .npz, found {path.name!r}")
        return self.gp.save(
            path,
            extra=dict(
                manifold_format=np.str_(MANIFOLD_FORMAT),
                manifold_template=np.str_(self.template_name),
                manifold_digest=np.str_(self.template_digest),
                manifold_rest_cage=np.asarray(self.rest_cage, dtype=np.float64),
                manifold_trials=np.asarray(self.trials, dtype=str),
                manifold_groups=np.asarray(self.groups, dtype=str),
                manifold_sources=np.asarray(self.sources, dtype=str),
                manifold_stats=np.array([self.n_poses, self.fit_seconds], dtype=np.float64),
            ),
        )

    @classmethod
    def load(cls, path: str | os.PathLike) -> PoseManifold:
        """Read a manifold written by :meth:`save`.

        Raises
        ------
        MeshmocapFileNotFoundError
            No such file.
        FormatError
            Not a pose-manifold file (a bare GPLVM file lacks the template it was built
            for: make it with ``meshmocap learn``).
        """
        path = Path(path)
        if not path.is_file():
            raise MeshmocapFileNotFoundError(f"{path}: no such manifold file")
        gp = GPLVM.load(path)
        d = read_npz(path, "pose manifold")
        if str(d.get("manifold_format", "")) != MANIFOLD_FORMAT:
            raise FormatError(
                f"{path}: a GPLVM without the template it was built for; make pose manifolds "
                "with 'meshmocap learn' (or PoseManifold.save)"
            )
        try:
            cage = d["manifold_rest_cage"]
            if cage.dtype.kind != "f" or cage.shape != (85, 3) or not np.isfinite(cage).all():
                raise ValueError(f"rest cage must be finite (85, 3) floats, found {cage.shape}")
            n_poses, seconds = d["manifold_stats"].tolist()
            return cls(
                gp,
                str(d["manifold_template"]),
                str(d["manifold_digest"]),
                d["manifold_rest_cage"],
                d["manifold_trials"],
                d["manifold_groups"],
                tuple(str(s) for s in d["manifold_sources"]),
                int(n_poses),
                float(seconds),
            )
        except (KeyError, ValueError, TypeError) as e:
            why = f"{type(e).__name__}: {e}".splitlines()[0][:160]
            raise FormatError(f"{path}: corrupt pose manifold ({why})") from None


@dataclass(frozen=True, eq=False)
class LatentStart:
    """Where a manifold's fit starts: the latent points and kernel of an earlier fit on the
    same training poses (other bodies' retargets of the same motions).

    Attributes
    ----------
    X : (N, q) float64
        Latent points.
    hyper : (3,) float64
        RBF variance α, inverse width γ and noise precision β.
    trials : (N,) str
        The trial of each training pose: a pose set whose trials differ is not started
        from here.
    digest : str
        16 hex digits of SHA-256 over the arrays (part of a cached manifold's key).
    """

    X: np.ndarray
    hyper: np.ndarray
    trials: np.ndarray
    digest: str

    @classmethod
    def load(cls, path: str | os.PathLike) -> LatentStart:
        """Read a start written by ``tools/make_manifold_start.py``."""
        d = read_npz(path, "manifold start")
        try:
            X, hyper = np.asarray(d["X"], np.float64), np.asarray(d["hyper"], np.float64)
            trials = np.asarray(d["trials"], dtype=str)
        except KeyError as e:
            raise FormatError(f"{path}: not a manifold start (no {e})") from None
        if X.ndim != 2 or hyper.shape != (3,) or trials.shape != (len(X),):
            raise FormatError(f"{path}: corrupt manifold start (X {X.shape}, hyper {hyper.shape})")
        h = hashlib.sha256()
        for a in (X, hyper):
            h.update(np.ascontiguousarray(a).tobytes())
        h.update("\0".join(trials.tolist()).encode())
        return cls(X, hyper, trials, h.hexdigest()[:16])

    def fits(self, poses: PoseSet, n_components: int) -> bool:
        """Whether ``poses`` are the poses this start was fitted on (same trials, in
        order) and the latent dimension is its own."""
        return self.X.shape == (len(poses), n_components) and bool(
            np.array_equal(self.trials, np.asarray(poses.trials, dtype=str))
        )


def default_start() -> LatentStart:
    """The bundled start of the default manifold's fit (:data:`START_FILE`)."""
    return LatentStart.load(START_FILE)


def learn_manifold(
    template: Template,
    motions: list[Motion],
    *,
    n_components: int = 2,
    n_samples: int = 120,
    oqr: OQR | None = None,
    random_state: int = 0,
) -> GPLVM:
    """Learn the pose manifold (§4, §6.2) from motions on ``template``'s skeleton.

    Every motion frame maps the quads rigidly to the skeleton (:func:`quads_from_pose`);
    ``n_samples`` configurations evenly spread over all frames train a back-constrained
    GPLVM with ``n_components`` latent dimensions.
    """
    if not motions:
        raise InputError("learn_manifold: no motions given")
    oqr = oqr or build_oqr(template)
    R = np.concatenate([m.rotations for m in motions])
    t = np.concatenate([m.root_positions for m in motions])
    pick = np.unique(np.linspace(0, len(R) - 1, min(n_samples, len(R))).round().astype(int))
    c, Q = quads_from_pose(oqr, template, R[pick], t[pick])
    Y = configuration_vector(c, Q)
    return GPLVM(n_components, back_constraint="rbf", random_state=random_state).fit(Y)


def fit_pose_manifold(
    poses: PoseSet,
    template: Template,
    *,
    oqr: OQR | None = None,
    n_components: int = 2,
    n_samples: int = 120,
    random_state: int = 0,
    max_iter: int = 2000,
    start: LatentStart | None = None,
) -> PoseManifold:
    """Fit a back-constrained GPLVM on ``n_samples`` poses evenly spread over ``poses``.

    Parameters
    ----------
    poses : PoseSet
        Training configurations of ``template`` (:mod:`meshmocap.trackers.cage.training_poses`).
    template : Template
    oqr : OQR, optional
        The template's rigging (built when omitted).
    n_components : int
        Latent dimension q (the paper: 2 for a walk, 10 for locomotion).
    n_samples : int
        Training poses kept (the paper: 120).
    random_state : int
    max_iter : int
        L-BFGS-B iterations at most.
    start : LatentStart, optional
        Where the fit starts when the poses kept are the ones ``start`` was fitted on
        (:meth:`LatentStart.fits`); otherwise, and by default, the PCA start.
    """
    if poses.template_name != template.name:
        raise InputError(
            f"fit_pose_manifold: poses of template {poses.template_name!r}, "
            f"expected {template.name!r}"
        )
    oqr = oqr or build_oqr(template)
    train = poses.subsample(n_samples)
    gp = GPLVM(n_components, back_constraint="rbf", max_iter=max_iter, random_state=random_state)
    if start is not None and start.fits(train, n_components):
        alpha, gamma, beta = start.hyper.tolist()
        gp.set_params(init=start.X, alpha=alpha, gamma=gamma, beta=beta)
    t0 = time.perf_counter()
    gp.fit(train.configurations)
    seconds = time.perf_counter() - t0
    return PoseManifold(
        gp,
        template.name,
        template_digest(template),
        np.array(oqr.rest_vertices),
        train.trials,
        train.groups,
        poses.sources,
        len(poses),
        seconds,
    )


def learn_pose_manifold(
    template: Template,
    sources: list[str | os.PathLike] | tuple[str | os.PathLike, ...] = DEFAULT_SOURCES,
    *,
    n_components: int = 2,
    n_samples: int = 120,
    oqr: OQR | None = None,
    asf: str | os.PathLike | None = None,
    random_state: int = 0,
    max_iter: int = 2000,
    start: LatentStart | None = None,
) -> PoseManifold:
    """Read pose sources
    (:func:`~meshmocap.trackers.cage.training_poses.load_pose_source`: procedural
    names, ``.bvh``/``.amc``/``.mat`` mocap, hand-labelled ``.npz``) and fit the manifold
    (:func:`fit_pose_manifold`, from ``start`` where it fits the poses)."""
    oqr = oqr or build_oqr(template)
    poses = load_pose_sources(list(sources), template, oqr=oqr, asf=asf)
    return fit_pose_manifold(
        poses,
        template,
        oqr=oqr,
        n_components=n_components,
        n_samples=n_samples,
        random_state=random_state,
        max_iter=max_iter,
        start=start,
    )


def resolve_manifold(
    manifold: GPLVM | PoseManifold | str | os.PathLike | None,
    template: Template | None,
    oqr: OQR | None = None,
) -> GPLVM | PoseManifold:
    """The pose manifold a cage tracker of ``template`` should use.

    Parameters
    ----------
    manifold : GPLVM, PoseManifold, path or None
        A fitted GPLVM (returned as given: nothing records its template), a
        :class:`PoseManifold` or the path of a saved one (checked against ``template``), or
        None: the default manifold of ``template`` (:func:`default_manifold`).
    template : Template or None
        The tracking template; needed unless ``manifold`` is a GPLVM.
    oqr : OQR, optional
        The template's rigging: also checked against the manifold's rest cage.

    Returns
    -------
    GPLVM or PoseManifold
        A GPLVM exactly when one was given.

    Raises
    ------
    InputError
        No template to check or learn with, or a manifold built for another template.
    MeshmocapFileNotFoundError, FormatError
        An unreadable manifold file.
    """
    if isinstance(manifold, GPLVM):
        if not hasattr(manifold, "X_"):
            raise InputError("cage: manifold must be a fitted GPLVM")
        return manifold
    if template is None:
        raise InputError("cage: template= is needed to check or learn its manifold")
    if manifold is None:
        return default_manifold(template, oqr)
    if isinstance(manifold, PoseManifold):
        manifold.check(template, oqr)
        return manifold
    if isinstance(manifold, str | os.PathLike):
        pm = PoseManifold.load(manifold)
        pm.check(template, oqr, source=manifold)
        return pm
    raise InputError(
        f"cage: manifold must be a GPLVM, PoseManifold, path or None, "
        f"found {type(manifold).__name__}"
    )


def _cache_dir() -> Path | None:
    env = os.environ.get(CACHE_ENV)
    if env is not None:
        return None if env.strip().lower() in ("off", "") else Path(env)
    xdg = os.environ.get("XDG_CACHE_HOME")
    return (Path(xdg) if xdg else Path.home() / ".cache") / "meshmocap"


def default_manifold_path(template: Template) -> Path | None:
    """Where :func:`default_manifold` caches ``template``'s default manifold (None: caching
    is off, :data:`CACHE_ENV`): the file name holds the template's name and a key of
    everything the manifold depends on (template digest, pose library digest, sources,
    q, poses, iterations, file format, how it is fitted, the bundled start)."""
    from meshmocap.body.pose_library import load_pose_library

    folder = _cache_dir()
    if folder is None:
        return None
    h = hashlib.sha256()
    parts = (
        MANIFOLD_FORMAT,
        template_digest(template),
        load_pose_library().digest,
        *DEFAULT_SOURCES,
        DEFAULT_COMPONENTS,
        DEFAULT_POSES,
        ON_THE_FLY_MAX_ITER,
        _FIT,
        default_start().digest,
    )
    for part in parts:
        h.update(f"{part}\0".encode())
    return folder / f"manifold-{template.name}-{h.hexdigest()[:16]}.npz"


def default_manifold_note(template: Template) -> str:
    """One line saying what :func:`default_manifold` will do for ``template`` (read its
    cached manifold, or learn one: what from, about how long), for front ends to print
    before a cage tracker is made (the cage's body, :mod:`~meshmocap.trackers.cage.body`,
    may be another than ``template``; the note names the template given)."""
    path = default_manifold_path(template)
    if path is not None and path.is_file():
        return f"cage: pose manifold of {template.name!r}: the cached default ({path.name})"
    return (
        f"cage: no --manifold given: learning a {DEFAULT_COMPONENTS}-D pose manifold from "
        f"{DEFAULT_POSES} poses of the bundled CMU pose library for the cage's body "
        f"(seconds, once: cached)"
    )


def default_manifold(template: Template, oqr: OQR | None = None) -> PoseManifold:
    """The cage tracker's default pose manifold of ``template``: learned at first use from
    :data:`DEFAULT_SOURCES` (:data:`DEFAULT_POSES` poses, q = :data:`DEFAULT_COMPONENTS`,
    :data:`ON_THE_FLY_MAX_ITER` iterations from the bundled start, :func:`default_start`;
    seconds) and cached
    (:func:`default_manifold_path`); a cached file that cannot be read is learned again.
    Logged at INFO level on the ``meshmocap.trackers.cage.manifold`` logger."""
    path = default_manifold_path(template)
    if path is not None and path.is_file():
        try:
            pm = PoseManifold.load(path)
            pm.check(template, oqr, source=path)
            return pm
        except (FormatError, InputError) as e:
            log.warning(
                "cage: cached default manifold %s unusable (%s); learning it again",
                path,
                str(e).splitlines()[0][:120],
            )
    pm = learn_pose_manifold(
        template,
        DEFAULT_SOURCES,
        n_components=DEFAULT_COMPONENTS,
        n_samples=DEFAULT_POSES,
        oqr=oqr,
        max_iter=ON_THE_FLY_MAX_ITER,
        start=default_start(),
    )
    log.info(
        "cage: no manifold given; learned a %d-D one from %s on %r (%d poses, %.1f s fit)",
        pm.n_components,
        "+".join(DEFAULT_SOURCES),
        template.name,
        pm.n_samples,
        pm.fit_seconds,
    )
    if path is not None:
        try:
            path.parent.mkdir(parents=True, exist_ok=True)
            pm.save(path)
        except OSError as e:
            log.warning("cage: could not cache the default manifold in %s (%s)", path, e)
    return pm
