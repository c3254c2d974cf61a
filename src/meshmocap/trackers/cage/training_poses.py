"""Training poses of the cage tracker's pose manifold (cage-manifold-tracking §4, §6.2).

A training pose is one Oriented Quads Rigging configuration of the tracking template,
expressed relative to the pelvis quad (:func:`~meshmocap.trackers.cage.oqr.configuration_vector`,
180 numbers). The paper gets them either "by manually locating the oriented quads" on a
few frames (§6.1) or "automatically ... by rigidly mapping the quads of the OQR to the
skeleton" of motion-capture frames (§6.2). :func:`load_pose_source` reads one source:

* a **procedural motion name** (``"walk"``, ``"jog"``, any of
  :data:`~meshmocap.body.procedural.PROCEDURAL_MOTIONS`): generated on the template's own
  skeleton, so the installed package alone can learn a manifold;
* a **motion-capture file**, ``.bvh`` or ``.amc`` (its ``.asf`` beside it, or ``asf=``):
  retargeted onto the template (:func:`~meshmocap.body.retarget.retarget`), then the quads
  mapped rigidly to the bones (:func:`~meshmocap.trackers.cage.oqr.quads_from_pose`);
* a **MATLAB ``.mat`` table of AMC channel rows** with one-hot trial labels, such as the
  CMU subject-35 walk/jog set ``cmu35WalkJog.mat`` (:func:`read_mat_trials`), decoded with
  the subject's ASF, split into trials, retargeted and mapped like an AMC file;
* a **hand-labelled pose file** (``.npz``, format below; :func:`save_poses` writes it);
* ``"library"`` or ``"library:N"``: the first ``N`` poses (all by default) of the bundled
  CMU pose library (:mod:`~meshmocap.body.pose_library`, diverse poses of many motion
  categories in farthest-point order), retargeted onto the template; trials are CMU
  trials, groups their motion categories.

Hand-labelled pose files (``.npz``, ``format = "meshmocap-poses-1"``). Either quad
configurations (what the paper's manual labelling produces) or local joint rotations of
the template's rig (what a pose editor produces); metres, radians, world frame Z up:

===================  ====================  ==================================================
key                  shape / dtype         meaning
===================  ====================  ==================================================
format               str                   ``"meshmocap-poses-1"``
template             str, optional         name of the template labelled; must match the
                                           template the manifold is learned for
centres              (N, 21, 3) float      quad centres (``QUAD_NAMES`` order), world frame
rotations            (N, 21, 3, 3) float   quad orientations, columns ``u, v, n``
joint_names          (J',) str             *instead of the two above:* rig joints named
joint_rotations      (N, J', 3) or         their local rotations relative to the rest frames,
                     (N, J', 3, 3) float   axis-angle (radians) or matrices; the template's
                                           other joints stay at rest
labels               (N,) str, optional    name of each pose (default ``"<stem>:<k>"``)
===================  ====================  ==================================================

Every source gives a :class:`PoseSet`: configurations plus, per pose, its trial (the clip
it comes from, e.g. ``"35_01"``) and group (e.g. ``"walk"``; used to colour the latent
plot). Only the pelvis-relative configuration is kept, so root translation, heading and
floor height of a clip do not matter (clips are retargeted with ``floor="none"``).

References
----------
- E. Duveau, S. Courtemanche, L. Reveret, E. Boyer, *Cage-based motion recovery
  using manifold learning*, International Conference on 3D Imaging, Modeling,
  Processing, Visualization and Transmission (3DIMPVT), 2012.
"""

from __future__ import annotations

import os
import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from meshmocap._atomic import atomic_open
from meshmocap._npz import read_npz
from meshmocap.body.motion import Motion
from meshmocap.body.procedural import PROCEDURAL_MOTIONS, procedural_motion
from meshmocap.body.retarget import retarget
from meshmocap.body.template import Template
from meshmocap.errors import FormatError, InputError, MeshmocapFileNotFoundError
from meshmocap.geometry.rotations import so3_exp
from meshmocap.trackers.cage.oqr import (
    N_QUADS,
    OQR,
    build_oqr,
    configuration_vector,
    quads_from_pose,
)

__all__ = [
    "CMU35_TEST_TRIALS",
    "CMU35_TRIALS",
    "POSES_FORMAT",
    "PoseSet",
    "library_poses",
    "load_pose_source",
    "load_pose_sources",
    "poses_from_motion",
    "read_mat_trials",
    "read_poses",
    "save_poses",
]

POSES_FORMAT = "meshmocap-poses-1"

#: Trials of ``cmu35WalkJog.mat`` in the column order of its ``lbls`` (trial, kind). The
#: columns follow the trial numbers: columns 17–25 hold 35–42 rows each (the short jogs,
#: 1.2–1.4 s at 30 Hz) between 16 and 6 walks of 90–114 rows; rows 0–89 are 35_01.amc[0::4].
CMU35_TRIALS: tuple[tuple[str, str], ...] = (
    *((f"35_{k:02d}", "walk") for k in range(1, 17)),
    ("35_17", "jog"),
    *((f"35_{k:02d}", "jog") for k in range(19, 27)),
    ("35_28", "walk"),
    *((f"35_{k:02d}", "walk") for k in range(30, 35)),
)
#: Trials of its ``lblstest`` columns: 35_18 (jog, 44 rows) and 35_29 (walk, 125 rows).
CMU35_TEST_TRIALS: tuple[tuple[str, str], ...] = (("35_18", "jog"), ("35_29", "walk"))


@dataclass(frozen=True, eq=False)
class PoseSet:
    """Training configurations of a pose manifold.

    Attributes
    ----------
    configurations : (N, 180) float64
        Pelvis-relative quad configurations
        (:func:`~meshmocap.trackers.cage.oqr.configuration_vector`):
        per quad 1…20 its centre (metres, pelvis quad frame) and the first two columns of
        its rotation.
    trials : (N,) str
        Clip each pose comes from (``"35_01"``, ``"walk"``, a file stem, a pose label).
    groups : (N,) str
        Coarser class of each pose (``"walk"``, ``"jog"``, a file stem).
    template_name : str
        The template whose OQR the configurations belong to.
    sources : tuple of str
        What was read, one entry per source.
    """

    configurations: np.ndarray
    trials: np.ndarray
    groups: np.ndarray
    template_name: str
    sources: tuple[str, ...]

    def __len__(self) -> int:
        return len(self.configurations)

    def subsample(self, n: int) -> PoseSet:
        """At most ``n`` poses evenly spread over all of them (in order), as in §6.2."""
        if not isinstance(n, int | np.integer) or n < 1:
            raise InputError(f"PoseSet.subsample: n must be a positive int, found {n!r}")
        N = len(self)
        pick = np.unique(np.linspace(0, N - 1, min(int(n), N)).round().astype(np.int64))
        return PoseSet(
            self.configurations[pick],
            self.trials[pick],
            self.groups[pick],
            self.template_name,
            self.sources,
        )

    @staticmethod
    def concatenate(sets: list[PoseSet]) -> PoseSet:
        """One set of every pose of ``sets`` (same template), in order."""
        if not sets:
            raise InputError("PoseSet.concatenate: no pose sets given")
        names = {s.template_name for s in sets}
        if len(names) > 1:
            raise InputError(f"PoseSet.concatenate: poses of different templates {sorted(names)}")
        return PoseSet(
            np.concatenate([s.configurations for s in sets]),
            np.concatenate([s.trials for s in sets]),
            np.concatenate([s.groups for s in sets]),
            sets[0].template_name,
            tuple(src for s in sets for src in s.sources),
        )


def _strings(values, n: int) -> np.ndarray:
    return np.asarray(np.broadcast_to(np.asarray(values, dtype=str), (n,)))


def poses_from_motion(
    motion: Motion,
    template: Template,
    *,
    oqr: OQR | None = None,
    trial: str = "motion",
    group: str | None = None,
    source: str | None = None,
) -> PoseSet:
    """Map the quads rigidly to every frame of a motion (§6.2).

    Parameters
    ----------
    motion : Motion
        On ``template``'s skeleton, or on any CMU-flavoured skeleton (then retargeted
        like :func:`~meshmocap.io.clips.clip_on` does for synthetic captures, by
        :func:`~meshmocap.body.retarget.retarget`; ``floor="none"``: the configurations
        are pelvis-relative).
    template : Template
    oqr : OQR, optional
        The template's rigging (built when omitted, about a second).
    trial, group : str
        Labels of the poses (``group`` defaults to ``trial``).
    source : str, optional
        Description kept in :attr:`PoseSet.sources` (default ``trial``).

    Returns
    -------
    PoseSet
        ``motion.n_frames`` poses.
    """
    oqr = oqr or build_oqr(template)
    if motion.skeleton.names != template.skeleton.names:
        motion = retarget(motion, template, floor="none")
    c, Q = quads_from_pose(oqr, template, motion.rotations, motion.root_positions)
    T = motion.n_frames
    return PoseSet(
        configuration_vector(c, Q),
        _strings(trial, T),
        _strings(group if group is not None else trial, T),
        template.name,
        (source or trial,),
    )


# ------------------------------------------------------------------------------ .mat tables
def _find_asf(path: Path) -> Path:
    """``SS.asf`` beside a file whose name holds the subject number SS, else the only
    ``.asf`` in its folder."""
    tried = []
    m = re.search(r"(\d+)", path.stem)
    if m:
        for name in (f"{m.group(1)}.asf", f"{int(m.group(1)):02d}.asf"):
            tried.append(name)
            if (path.parent / name).is_file():
                return path.parent / name
    found = sorted(path.parent.glob("*.asf"))
    if len(found) == 1:
        return found[0]
    looked = f"looked for {' or '.join(dict.fromkeys(tried))}" if tried else "none beside it"
    raise MeshmocapFileNotFoundError(
        f"{path}: cannot tell which ASF skeleton decodes it ({looked}, {len(found)} .asf files "
        "in its folder); pass asf=PATH (--asf)"
    )


def read_mat_trials(
    path: str | os.PathLike,
    *,
    asf: str | os.PathLike | None = None,
    fps: float = 30.0,
    test: bool = False,
) -> list[tuple[str, str, Motion]]:
    """Split a MATLAB table of AMC channel rows into its trials and decode them.

    The file (read with :func:`scipy.io.loadmat`) holds ``Y`` (N, C): raw AMC channels
    (``asf.channel_names`` order, degrees), and ``lbls`` (N, K): one-hot trial of every
    row; with ``test`` the held-out ``Ytest``/``lblstest`` instead. ``cmu35WalkJog.mat``
    gets its CMU trial names (:data:`CMU35_TRIALS`); other files name trial ``k`` of
    ``stem.mat`` ``"stem#k"``, group ``stem``.

    Parameters
    ----------
    path : path
        The ``.mat`` file.
    asf : path, optional
        The subject's ASF skeleton (default: ``SS.asf`` beside the file, SS the first
        number in its name, e.g. ``35.asf`` for ``cmu35WalkJog.mat``).
    fps : float
        Frame rate of the rows (cmu35WalkJog: every 4th frame of 120 Hz, 30).
    test : bool
        Read the test rows.

    Returns
    -------
    list of (trial, group, Motion)
        One entry per trial with rows, in column order; motions on the ASF skeleton,
        metres, world frame Z up.

    Raises
    ------
    MeshmocapFileNotFoundError, FormatError, InputError
    """
    import scipy.io

    from meshmocap.io.asf_amc import motion_from_channels, read_asf

    path = Path(path)
    if not path.is_file():
        raise MeshmocapFileNotFoundError(f"{path}: no such .mat file")
    try:
        d = scipy.io.loadmat(path)
    except (OSError, ValueError, NotImplementedError) as exc:
        raise FormatError(f"{path}: not a readable MATLAB file ({exc})") from None
    ykey, lkey = ("Ytest", "lblstest") if test else ("Y", "lbls")
    if ykey not in d:
        keys = sorted(k for k in d if not k.startswith("__"))
        raise FormatError(f"{path}: expected a channel table {ykey!r}, found keys {keys}")
    Y = np.asarray(d[ykey], dtype=np.float64)
    N = len(Y)
    L = np.asarray(d[lkey]) if lkey in d else np.ones((N, 1))
    if Y.ndim != 2 or L.shape[0] != N or L.ndim != 2 or not np.all(np.isin(L, (0, 1))):
        raise FormatError(
            f"{path}: expected {ykey} (N, C) and one-hot {lkey} (N, K), "
            f"found {Y.shape} and {L.shape}"
        )
    if not np.all(L.sum(axis=1) == 1):
        raise FormatError(f"{path}: {lkey} must have exactly one 1 per row")
    skel = read_asf(Path(asf) if asf is not None else _find_asf(path))
    K = L.shape[1]
    known = CMU35_TEST_TRIALS if test else CMU35_TRIALS
    if path.stem.lower() == "cmu35walkjog" and len(known) == K:
        names = list(known)
    else:
        names = [(f"{path.stem}#{k}", path.stem) for k in range(K)]
    out = []
    for k, (trial, group) in enumerate(names):
        rows = np.flatnonzero(L[:, k])
        if len(rows):
            m = motion_from_channels(Y[rows], skel, fps=fps, source=f"{path}[{trial}]")
            out.append((trial, group, m))
    return out


# ------------------------------------------------------------------------------ pose files
def save_poses(
    path: str | os.PathLike,
    *,
    centres: np.ndarray | None = None,
    rotations: np.ndarray | None = None,
    joint_names: list[str] | tuple[str, ...] | None = None,
    joint_rotations: np.ndarray | None = None,
    labels: list[str] | np.ndarray | None = None,
    template: str | None = None,
) -> Path:
    """Write a hand-labelled pose file (module docstring) atomically; returns the path.

    Give either ``centres`` (N, 21, 3) and ``rotations`` (N, 21, 3, 3) (quad
    configurations), or ``joint_names`` (J',) and ``joint_rotations`` (N, J', 3) or
    (N, J', 3, 3).
    """
    arrays: dict[str, np.ndarray] = {"format": np.str_(POSES_FORMAT)}
    if (centres is None) == (joint_rotations is None):
        raise InputError(
            "save_poses: give either centres and rotations, or joint_names and joint_rotations"
        )
    if centres is not None:
        arrays["centres"] = np.asarray(centres, dtype=np.float64)
        arrays["rotations"] = np.asarray(rotations, dtype=np.float64)
    else:
        arrays["joint_names"] = np.asarray(joint_names, dtype=str)
        arrays["joint_rotations"] = np.asarray(joint_rotations, dtype=np.float64)
    if labels is not None:
        arrays["labels"] = np.asarray(labels, dtype=str)
    if template is not None:
        arrays["template"] = np.str_(template)
    path = Path(path)
    if path.suffix != ".npz":
        raise InputError(f"save_poses: path must end in .npz, found {path.name!r}")
    with atomic_open(path) as f:
        np.savez_compressed(f, **arrays)
    return path


def _rotations(path: Path, key: str, R: np.ndarray, shape: tuple[int, ...]) -> np.ndarray:
    if R.shape == (*shape, 3) and R.ndim == len(shape) + 1:
        R = so3_exp(R)
    if R.shape != (*shape, 3, 3):
        raise FormatError(
            f"{path}: {key} must have shape {(*shape, 3)} or {(*shape, 3, 3)}, found {R.shape}"
        )
    if not np.all(np.isfinite(R)):
        raise FormatError(f"{path}: {key} contains NaN or infinite values")
    err = np.abs(np.swapaxes(R, -1, -2) @ R - np.eye(3)).max() if R.size else 0.0
    if err > 1e-3 or (R.size and np.linalg.det(R).min() < 0):
        raise FormatError(f"{path}: {key} must be rotation matrices, found one off by {err:.2g}")
    return R


def read_poses(path: str | os.PathLike, template: Template, *, oqr: OQR | None = None) -> PoseSet:
    """Read a hand-labelled pose file (module docstring) for ``template``.

    Raises
    ------
    MeshmocapFileNotFoundError, FormatError
        Missing file, wrong format, bad shapes, non-rotations, unknown joint names, or
        poses labelled on another template.
    """
    path = Path(path)
    if not path.is_file():
        raise MeshmocapFileNotFoundError(f"{path}: no such pose file")
    d = read_npz(path, "pose file")
    if str(d.get("format", "")) != POSES_FORMAT:
        raise FormatError(
            f"{path}: expected format {POSES_FORMAT!r}, found {str(d.get('format', 'none'))!r}"
        )
    if "template" in d and str(d["template"]) != template.name:
        raise FormatError(
            f"{path}: poses labelled on template {str(d['template'])!r}, expected {template.name!r}"
        )
    oqr = oqr or build_oqr(template)
    if "centres" in d:
        c = np.asarray(d["centres"], dtype=np.float64)
        if c.ndim != 3 or c.shape[1:] != (N_QUADS, 3) or not np.all(np.isfinite(c)):
            raise FormatError(f"{path}: centres must be finite (N, {N_QUADS}, 3), found {c.shape}")
        Q = _rotations(path, "rotations", np.asarray(d.get("rotations", np.zeros(0))), c.shape[:2])
        Y = configuration_vector(c, Q)
    elif "joint_rotations" in d and "joint_names" in d:
        sk = template.skeleton
        names = [str(s) for s in d["joint_names"]]
        unknown = sorted(set(names) - set(sk.names))
        if unknown or len(set(names)) != len(names):
            found = unknown or "duplicates"
            raise FormatError(
                f"{path}: joint_names must be distinct joints of template "
                f"{template.name!r}, found {found}"
            )
        jr = np.asarray(d["joint_rotations"], dtype=np.float64)
        R = _rotations(path, "joint_rotations", jr, (jr.shape[0] if jr.ndim else 0, len(names)))
        full = np.tile(np.eye(3), (len(R), sk.n_joints, 1, 1))
        full[:, [sk.index(n) for n in names]] = R
        root = np.broadcast_to(sk.rest_positions[0], (len(R), 3))
        Y = configuration_vector(*quads_from_pose(oqr, template, full, root))
    else:
        raise FormatError(
            f"{path}: expected centres and rotations, or joint_names and "
            f"joint_rotations, found keys {sorted(d)}"
        )
    N = len(Y)
    if N == 0:
        raise FormatError(f"{path}: holds no poses")
    labels = d.get("labels")
    if labels is not None and np.shape(labels) != (N,):
        raise FormatError(f"{path}: labels must have shape ({N},), found {np.shape(labels)}")
    trials = (
        np.asarray(labels, dtype=str)
        if labels is not None
        else np.array([f"{path.stem}:{k}" for k in range(N)])
    )
    return PoseSet(Y, trials, _strings(path.stem, N), template.name, (str(path),))


# ------------------------------------------------------------------------------ dispatch
def load_pose_source(
    source: str | os.PathLike,
    template: Template,
    *,
    oqr: OQR | None = None,
    asf: str | os.PathLike | None = None,
    duration: float = 4.0,
    fps: float = 30.0,
) -> PoseSet:
    """Training poses of ``template`` from one source (see the module docstring).

    Parameters
    ----------
    source : str or path
        A procedural motion name, or a ``.bvh``, ``.amc``, ``.mat`` or ``.npz`` file.
    template : Template
    oqr : OQR, optional
        The template's rigging (built when omitted).
    asf : path, optional
        ASF skeleton of an ``.amc`` or ``.mat`` source (default: found beside it).
    duration, fps : float
        Seconds and frame rate of a procedural motion.

    Returns
    -------
    PoseSet
    """
    from meshmocap.io.clips import load_clip

    oqr = oqr or build_oqr(template)
    name = os.fspath(source)
    if name == "library" or name.startswith("library:"):
        return library_poses(template, _library_count(name), oqr=oqr)
    if name in PROCEDURAL_MOTIONS:
        m = procedural_motion(name, template, duration=duration, fps=fps)  # type: ignore[arg-type]
        return poses_from_motion(
            m, template, oqr=oqr, trial=name, source=f"{name} ({duration:g} s at {fps:g} fps)"
        )
    path = Path(name)
    suffix = path.suffix.lower()
    if suffix not in (".bvh", ".amc", ".mat", ".npz"):
        raise InputError(
            f"pose source: expected one of {list(PROCEDURAL_MOTIONS)}, 'library' "
            "or 'library:N', or a .bvh, .amc, .mat or .npz file, "
            f"found {name!r}"
        )
    if not path.is_file():
        raise MeshmocapFileNotFoundError(f"pose source: {path} does not exist")
    if suffix == ".npz":
        return read_poses(path, template, oqr=oqr)
    if suffix == ".mat":
        trials = read_mat_trials(path, asf=asf)
        if not trials:
            raise FormatError(f"{path}: holds no rows")
        sets = [poses_from_motion(m, template, oqr=oqr, trial=t, group=g) for t, g, m in trials]
        all_ = PoseSet.concatenate(sets)
        return PoseSet(
            all_.configurations,
            all_.trials,
            all_.groups,
            template.name,
            (f"{path} ({len(trials)} trials)",),
        )
    m = load_clip(path, asf=asf) if suffix == ".amc" else load_clip(path)
    return poses_from_motion(m, template, oqr=oqr, trial=path.stem, source=str(path))


def _library_count(name: str) -> int | None:
    n = name.partition(":")[2]
    if not n:
        return None
    if not n.isdigit() or int(n) < 1:
        raise InputError(f"pose source: 'library:N' takes a count N ≥ 1, found {name!r}")
    return int(n)


def library_poses(template: Template, n: int | None = None, *, oqr: OQR | None = None) -> PoseSet:
    """The first ``n`` poses (all by default) of the bundled pose library
    (:func:`~meshmocap.body.pose_library.load_pose_library`) as configurations of
    ``template``'s quads: trials are their CMU trials, groups their motion categories."""
    from meshmocap.body.pose_library import load_pose_library

    lib = load_pose_library()
    oqr = oqr or build_oqr(template)
    n = len(lib) if n is None else min(int(n), len(lib))
    R = lib.on(template, n)
    root = np.broadcast_to(template.skeleton.rest_positions[0], (n, 3))
    Y = configuration_vector(*quads_from_pose(oqr, template, R, root))
    return PoseSet(
        Y,
        lib.trials[:n].copy(),
        lib.categories[:n].copy(),
        template.name,
        (f"library:{n} (CMU pose library {lib.digest})",),
    )


def load_pose_sources(
    sources: list[str | os.PathLike] | tuple[str | os.PathLike, ...],
    template: Template,
    *,
    oqr: OQR | None = None,
    **kwargs,
) -> PoseSet:
    """Every pose of several sources (:func:`load_pose_source`, same keyword options)."""
    if not sources:
        raise InputError("pose sources: none given")
    oqr = oqr or build_oqr(template)
    return PoseSet.concatenate([load_pose_source(s, template, oqr=oqr, **kwargs) for s in sources])
