"""Procedural motions that need no data file: walk, jog, squat, arm raises, jumping jacks,
turning in place.

Every motion is deterministic and parameterised, and posed on any skeleton that uses the
CMU MotionBuilder joint names (the bundled templates do). Limbs are driven by *world*
bone rotations relative to the rest pose, so the motions do not depend on whether the rest
pose is a T-pose or an A-pose: arms are first brought down along the body, then swung.
Angles are in degrees in the parameters, radians inside. Sign conventions in the body frame
(subject facing −Y, left towards +X, Z up): a rotation ``Rx(−a)`` swings a hanging limb
forward by ``a``; ``Ry(−a)`` lifts the left arm sideways by ``a`` (``Ry(+a)`` the right).

Root translation comes from the feet: the stance foot (the lower one) stays planted, so
the body advances exactly by its strides (no foot sliding), and the lowest foot point
touches the floor (z = 0) when the motion has no flight phase.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Literal, get_args

import numpy as np

from meshmocap.body.contact import canonical_indices, foot_heights
from meshmocap.body.motion import Motion
from meshmocap.body.names import canonical_name_map
from meshmocap.body.skeleton import Skeleton, local_rotations
from meshmocap.body.template import Template
from meshmocap.errors import InputError
from meshmocap.geometry.rotations import axis_rotation, rotation_between

ProceduralName = Literal["walk", "jog", "squat", "arm_raises", "jumping_jacks", "turn"]
PROCEDURAL_MOTIONS: tuple[str, ...] = get_args(ProceduralName)

_DOWN = np.array([0.0, 0.0, -1.0])
_SPINE = ("LowerBack", "Spine", "Spine1")
_HEAD = ("Neck", "Neck1", "Head")


def _rx(a: np.ndarray) -> np.ndarray:
    return axis_rotation(a, "X")


def _ry(a: np.ndarray) -> np.ndarray:
    return axis_rotation(a, "Y")


def _rz(a: np.ndarray) -> np.ndarray:
    return axis_rotation(a, "Z")


def _bump(phase: np.ndarray, centre: float, width: float) -> np.ndarray:
    """Periodic Gaussian bump of unit height on the gait cycle ``phase`` ∈ [0, 1)."""
    d = (phase - centre + 0.5) % 1.0 - 0.5
    return np.exp(-0.5 * (d / width) ** 2)


class _Rig:
    """Collects world bone rotations by canonical joint name and turns them into a Motion."""

    def __init__(self, skeleton: Skeleton, T: int):
        self.sk = skeleton
        self.T = T
        self.names = canonical_name_map(skeleton.names)
        missing = [
            n
            for n in ("Hips", "LeftUpLeg", "LeftLeg", "RightUpLeg", "RightLeg")
            if n not in self.names
        ]
        if missing:
            raise InputError(
                f"procedural motions need MotionBuilder-named joints; skeleton lacks {missing}"
            )
        self.G: dict[int, np.ndarray] = {}

    def base(self, name: str, direction: np.ndarray) -> np.ndarray:
        """Rotation taking ``name``'s rest bone direction onto ``direction`` (body frame)."""
        if name not in self.names:
            return np.eye(3)
        d = self.sk.bone_directions[self.sk.index(self.names[name])]
        return rotation_between(d, direction) if np.linalg.norm(d) > 0.5 else np.eye(3)

    def set(self, name: str, R: np.ndarray) -> None:
        if name in self.names:
            self.G[self.sk.index(self.names[name])] = np.broadcast_to(R, (self.T, 3, 3))

    def rotations(self, yaw: np.ndarray) -> np.ndarray:
        """Local rotations (T, J, 3, 3) with the whole body turned by ``yaw`` about Z."""
        H = _rz(yaw)
        G = np.empty((self.T, self.sk.n_joints, 3, 3))
        for level in self.sk.levels:
            for j in level:  # ≤ 50 joints; every product is vectorised over frames
                G[:, j] = H @ self.G[j] if j in self.G else G[:, self.sk.parents[j]]
                if j not in self.G and self.sk.parents[j] < 0:
                    G[:, j] = H
        return local_rotations(self.sk, G)


def _legs(
    rig: _Rig,
    side: str,
    hip: np.ndarray,
    knee: np.ndarray,
    ankle: np.ndarray,
    abduction: np.ndarray | float = 0.0,
) -> None:
    """Sagittal leg angles (radians): hip flexion, knee flexion, ankle dorsiflexion."""
    prefix = "Left" if side == "left" else "Right"
    A = _ry(-np.asarray(abduction) if side == "left" else np.asarray(abduction))
    rig.set(f"{prefix}UpLeg", _rx(-hip) @ A)
    rig.set(f"{prefix}Leg", _rx(-(hip - knee)) @ A)
    rig.set(f"{prefix}Foot", _rx(-(hip - knee) - ankle) @ A)


def _arms(
    rig: _Rig,
    side: str,
    flexion: np.ndarray,
    elbow: np.ndarray,
    abduction: np.ndarray | float = 0.15,
) -> None:
    """Arm angles (radians): shoulder flexion (forward), elbow flexion, abduction (sideways)."""
    prefix, s = ("Left", 1.0) if side == "left" else ("Right", -1.0)
    A = _ry(-s * np.asarray(abduction))
    rig.set(f"{prefix}Arm", _rx(-flexion) @ A @ rig.base(f"{prefix}Arm", _DOWN))
    rig.set(f"{prefix}ForeArm", _rx(-flexion - elbow) @ A @ rig.base(f"{prefix}ForeArm", _DOWN))


def _trunk(rig: _Rig, lean: np.ndarray | float, twist: np.ndarray | float = 0.0) -> None:
    """Forward lean spread over the spine, head kept level; pelvis/shoulder counter-twist."""
    lean = np.asarray(lean, dtype=float)
    twist = np.asarray(twist, dtype=float)
    rig.set("Hips", _rz(twist))
    for k, name in enumerate(_SPINE, start=1):
        rig.set(name, _rx(-lean * k / 3) @ _rz(twist * (1 - 2 * k / 3)))
    for name in _HEAD:
        rig.set(name, _rx(-0.3 * lean) @ _rz(-twist))


def _assemble(
    rig: _Rig,
    target: Template | Skeleton,
    fps: float,
    *,
    yaw: np.ndarray,
    planted: bool,
    lift: np.ndarray | float = 0.0,
) -> Motion:
    """Place the root: stance foot planted (``planted``) or in place, feet on the floor."""
    R = rig.rotations(yaw)
    zero = Motion(rig.sk, R, np.zeros((rig.T, 3)), fps)
    h = foot_heights(zero, target)  # (T, 2) relative to the root
    root = np.zeros((rig.T, 3))
    root[:, 2] = -h.min(axis=1) + lift
    if planted:
        ankles = canonical_indices(rig.sk, ("LeftFoot", "RightFoot"))
        if ankles is None:
            raise InputError("a walking motion needs LeftFoot and RightFoot joints")
        p = zero.joint_positions[:, ankles, :2]  # (T, 2, 2) ankle xy relative to the root
        stance = np.argmin(h, axis=1)
        step = np.diff(p, axis=0)[np.arange(rig.T - 1), stance[1:]]
        root[1:, :2] = -np.cumsum(step, axis=0)
    return Motion(rig.sk, R, root, fps)


def _frames(duration: float, fps: float) -> tuple[int, np.ndarray]:
    for name, v in (("duration", duration), ("fps", fps)):
        if not (np.isfinite(v) and v > 0):
            raise InputError(f"procedural motion: {name} must be a positive number, found {v}")
    T = round(duration * fps) + 1
    return T, np.arange(T) / fps


def walk(
    target: Template | Skeleton,
    *,
    duration: float = 4.0,
    fps: float = 60.0,
    cadence: float = 110.0,
    hip_amplitude: float = 22.0,
    knee_swing: float = 60.0,
    arm_swing: float = 18.0,
    turn_rate: float = 0.0,
    bounce: float = 0.0,
    lean: float = 3.0,
    elbow: float = 15.0,
) -> Motion:
    """Return a walk (or, with larger parameters, a jog) that advances along −Y.

    Parameters
    ----------
    target : Template or Skeleton
        MotionBuilder-named rig to animate.
    duration, fps : float
        Seconds and frames per second.
    cadence : float
        Steps per minute (two steps per gait cycle).
    hip_amplitude, knee_swing, arm_swing, lean, elbow : float
        Degrees: hip flexion amplitude, peak knee flexion in swing, shoulder swing, trunk
        lean, mean elbow flexion.
    turn_rate : float
        Degrees per second about the vertical (a curved path); 0 walks straight.
    bounce : float
        Metres of extra vertical bounce per step (a flight phase for jogging).
    """
    T, t = _frames(duration, fps)
    rig = _Rig(target.skeleton if isinstance(target, Template) else target, T)
    phase = (t * cadence / 120.0) % 1.0  # left heel strike at phase 0
    hip_a, knee_a, arm_a = np.deg2rad([hip_amplitude, knee_swing, arm_swing])
    for side, ph in (("left", phase), ("right", (phase + 0.5) % 1.0)):
        hip = np.deg2rad(5.0) + hip_a * np.cos(2 * np.pi * ph)
        knee = (
            np.deg2rad(4.0)
            + np.deg2rad(15.0) * _bump(ph, 0.12, 0.06)
            + knee_a * _bump(ph, 0.72, 0.11)
        )
        ankle = np.deg2rad(8.0) * _bump(ph, 0.45, 0.1) - np.deg2rad(12.0) * _bump(ph, 0.62, 0.05)
        _legs(rig, side, hip, knee, ankle + np.deg2rad(3.0))
        # arms swing against the opposite leg: forward when this side's leg is back
        _arms(
            rig,
            side,
            -arm_a * np.cos(2 * np.pi * ph),
            np.deg2rad(elbow) + 0.5 * arm_a * (1 - np.cos(2 * np.pi * ph)),
        )
    _trunk(rig, np.deg2rad(lean), np.deg2rad(4.0) * np.cos(2 * np.pi * phase))
    lift = bounce * np.abs(np.sin(2 * np.pi * phase))
    return _assemble(rig, target, fps, yaw=np.deg2rad(turn_rate) * t, planted=True, lift=lift)


def jog(
    target: Template | Skeleton,
    *,
    duration: float = 4.0,
    fps: float = 60.0,
    cadence: float = 160.0,
    hip_amplitude: float = 32.0,
    knee_swing: float = 100.0,
    arm_swing: float = 28.0,
    turn_rate: float = 0.0,
    bounce: float = 0.04,
) -> Motion:
    """Return a jog along −Y: a faster, bouncier walk with bent elbows and a forward lean.

    Parameters are those of :func:`walk` (degrees, steps per minute, metres).
    """
    return walk(
        target,
        duration=duration,
        fps=fps,
        cadence=cadence,
        hip_amplitude=hip_amplitude,
        knee_swing=knee_swing,
        arm_swing=arm_swing,
        turn_rate=turn_rate,
        bounce=bounce,
        lean=8.0,
        elbow=85.0,
    )


def squat(
    target: Template | Skeleton,
    *,
    duration: float = 6.0,
    fps: float = 60.0,
    period: float = 3.0,
    depth: float = 85.0,
) -> Motion:
    """Return repeated squats: feet flat, hips flexing to ``depth`` degrees every ``period`` s,
    arms raised forward for balance."""
    T, t = _frames(duration, fps)
    rig = _Rig(target.skeleton if isinstance(target, Template) else target, T)
    s = 0.5 * (1 - np.cos(2 * np.pi * t / period))
    hip = np.deg2rad(depth) * s
    knee = 1.7 * hip
    for side in ("left", "right"):
        _legs(rig, side, hip, knee, knee - hip, abduction=np.deg2rad(6.0))
        _arms(rig, side, 1.0 * hip, np.deg2rad(10.0) * s)
    _trunk(rig, 0.45 * hip)
    return _assemble(rig, target, fps, yaw=np.zeros(T), planted=False)


def arm_raises(
    target: Template | Skeleton,
    *,
    duration: float = 6.0,
    fps: float = 60.0,
    period: float = 3.0,
    height: float = 165.0,
) -> Motion:
    """Return arm raises, alternating a forward raise and a sideways raise to ``height``
    degrees, one raise per ``period`` seconds; legs still."""
    T, t = _frames(duration, fps)
    rig = _Rig(target.skeleton if isinstance(target, Template) else target, T)
    s = np.deg2rad(height) * 0.5 * (1 - np.cos(2 * np.pi * t / period))
    front = (np.floor(t / period) % 2) == 0
    for side in ("left", "right"):
        _legs(rig, side, np.zeros(T), np.zeros(T), np.zeros(T), abduction=np.deg2rad(3.0))
        _arms(rig, side, np.where(front, s, 0.0), np.zeros(T), np.where(front, 0.1, s + 0.1))
    _trunk(rig, 0.0)
    return _assemble(rig, target, fps, yaw=np.zeros(T), planted=False)


def jumping_jacks(
    target: Template | Skeleton,
    *,
    duration: float = 4.0,
    fps: float = 60.0,
    period: float = 1.0,
    jump_height: float = 0.08,
) -> Motion:
    """Return jumping jacks: arms from the sides to overhead, legs apart, a small jump
    (``jump_height`` metres) at each change, one jack per ``period`` seconds."""
    T, t = _frames(duration, fps)
    rig = _Rig(target.skeleton if isinstance(target, Template) else target, T)
    s = 0.5 * (1 - np.cos(2 * np.pi * t / period))
    for side in ("left", "right"):
        _legs(
            rig,
            side,
            np.deg2rad(4.0) * np.ones(T),
            np.deg2rad(8.0) * np.ones(T),
            np.zeros(T),
            abduction=np.deg2rad(3.0 + 14.0 * s),
        )
        _arms(rig, side, np.zeros(T), np.deg2rad(10.0) * np.ones(T), np.deg2rad(12.0 + 150.0 * s))
    _trunk(rig, 0.0)
    lift = jump_height * np.abs(np.sin(2 * np.pi * t / period))
    return _assemble(rig, target, fps, yaw=np.zeros(T), planted=False, lift=lift)


def turn(
    target: Template | Skeleton,
    *,
    duration: float = 4.0,
    fps: float = 60.0,
    turn_rate: float = 90.0,
    step_rate: float = 100.0,
    knee_lift: float = 35.0,
) -> Motion:
    """Return turning in place at ``turn_rate`` degrees per second while marching
    (``step_rate`` steps per minute, knees lifted ``knee_lift`` degrees)."""
    T, t = _frames(duration, fps)
    rig = _Rig(target.skeleton if isinstance(target, Template) else target, T)
    phase = (t * step_rate / 120.0) % 1.0
    lift = np.deg2rad(knee_lift)
    for side, ph in (("left", phase), ("right", (phase + 0.5) % 1.0)):
        up = np.clip(np.sin(2 * np.pi * ph), 0.0, None)
        _legs(rig, side, lift * up, 2 * lift * up, lift * up)
        _arms(rig, side, np.deg2rad(-10.0) * np.sin(2 * np.pi * ph), np.deg2rad(20.0) * np.ones(T))
    _trunk(rig, 0.0)
    return _assemble(rig, target, fps, yaw=np.deg2rad(turn_rate) * t, planted=False)


_BY_NAME: dict[str, Callable[..., Motion]] = {
    "walk": walk,
    "jog": jog,
    "squat": squat,
    "arm_raises": arm_raises,
    "jumping_jacks": jumping_jacks,
    "turn": turn,
}


def procedural_motion(name: ProceduralName, target: Template | Skeleton, **params: float) -> Motion:
    """Return the procedural motion ``name`` on ``target`` (see each function's parameters)."""
    if name not in _BY_NAME:
        raise InputError(
            f"procedural motion: name must be one of {list(PROCEDURAL_MOTIONS)}, found {name!r}"
        )
    try:
        return _BY_NAME[name](target, **params)
    except TypeError as exc:
        raise InputError(f"procedural motion {name!r}: {exc}") from None
