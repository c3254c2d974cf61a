"""Tiny rigs and meshes generated in code for unit tests."""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from meshmocap.body.names import CMU_MB_NAMES
from meshmocap.body.skeleton import Skeleton
from meshmocap.body.template import EVAL_NAMES, EVAL_PARENTS, EvalSkeleton, Template

# Rest positions of the MotionBuilder joints of a 1.75 m T-posed figure (Z up, facing −Y,
# left towards +X), metres.
_REST = {
    "Hips": (0, 0, 0.95),
    "LHipJoint": (0, 0, 0.95),
    "LeftUpLeg": (0.09, 0, 0.9),
    "LeftLeg": (0.09, 0, 0.5),
    "LeftFoot": (0.09, 0, 0.08),
    "LeftToeBase": (0.09, -0.12, 0.02),
    "RHipJoint": (0, 0, 0.95),
    "RightUpLeg": (-0.09, 0, 0.9),
    "RightLeg": (-0.09, 0, 0.5),
    "RightFoot": (-0.09, 0, 0.08),
    "RightToeBase": (-0.09, -0.12, 0.02),
    "LowerBack": (0, 0, 0.98),
    "Spine": (0, 0, 1.1),
    "Spine1": (0, 0, 1.25),
    "Neck": (0, 0, 1.45),
    "Neck1": (0, 0, 1.52),
    "Head": (0, 0, 1.58),
    "LeftShoulder": (0.03, 0, 1.42),
    "LeftArm": (0.18, 0, 1.42),
    "LeftForeArm": (0.46, 0, 1.42),
    "LeftHand": (0.72, 0, 1.42),
    "LeftFingerBase": (0.78, 0, 1.42),
    "LeftHandIndex1": (0.82, 0, 1.42),
    "LThumb": (0.74, -0.03, 1.42),
    "RightShoulder": (-0.03, 0, 1.42),
    "RightArm": (-0.18, 0, 1.42),
    "RightForeArm": (-0.46, 0, 1.42),
    "RightHand": (-0.72, 0, 1.42),
    "RightFingerBase": (-0.78, 0, 1.42),
    "RightHandIndex1": (-0.82, 0, 1.42),
    "RThumb": (-0.74, -0.03, 1.42),
}
_PARENT = {
    "LHipJoint": "Hips",
    "LeftUpLeg": "LHipJoint",
    "LeftLeg": "LeftUpLeg",
    "LeftFoot": "LeftLeg",
    "LeftToeBase": "LeftFoot",
    "RHipJoint": "Hips",
    "RightUpLeg": "RHipJoint",
    "RightLeg": "RightUpLeg",
    "RightFoot": "RightLeg",
    "RightToeBase": "RightFoot",
    "LowerBack": "Hips",
    "Spine": "LowerBack",
    "Spine1": "Spine",
    "Neck": "Spine1",
    "Neck1": "Neck",
    "Head": "Neck1",
    "LeftShoulder": "Spine1",
    "LeftArm": "LeftShoulder",
    "LeftForeArm": "LeftArm",
    "LeftHand": "LeftForeArm",
    "LeftFingerBase": "LeftHand",
    "LeftHandIndex1": "LeftFingerBase",
    "LThumb": "LeftHand",
    "RightShoulder": "Spine1",
    "RightArm": "RightShoulder",
    "RightForeArm": "RightArm",
    "RightHand": "RightForeArm",
    "RightFingerBase": "RightHand",
    "RightHandIndex1": "RightFingerBase",
    "RThumb": "RightHand",
}
_END = {
    "LeftToeBase": (0, -0.06, 0),
    "RightToeBase": (0, -0.06, 0),
    "Head": (0, 0, 0.2),
    "LeftHandIndex1": (0.04, 0, 0),
    "RightHandIndex1": (-0.04, 0, 0),
    "LThumb": (0.03, -0.02, 0),
    "RThumb": (-0.03, -0.02, 0),
}
_PART = [
    0,
    9,
    9,
    10,
    11,
    11,
    12,
    12,
    13,
    14,
    14,
    0,
    1,
    1,
    1,
    2,
    2,
    1,
    3,
    4,
    5,
    5,
    5,
    5,
    1,
    6,
    7,
    8,
    8,
    8,
    8,
]


def toy_skeleton() -> Skeleton:
    """The 31-joint CMU MotionBuilder skeleton of a T-posed 1.75 m figure."""
    names = CMU_MB_NAMES
    P = np.array([_REST[n] for n in names], dtype=float)
    parents = np.array([-1] + [names.index(_PARENT[n]) for n in names[1:]])
    off = P - np.where((parents >= 0)[:, None], P[np.maximum(parents, 0)], 0.0)
    end = np.array([_END.get(n, (0, 0, 0)) for n in names], dtype=float)
    return Skeleton(names, parents, off, end)


def octahedron(centre: np.ndarray, r: float) -> tuple[np.ndarray, np.ndarray]:
    """A closed octahedron (6 vertices, 8 outward faces) around ``centre``."""
    V = centre + r * np.array([[1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1], [0, 0, -1]])
    F = np.array(
        [[0, 2, 4], [2, 1, 4], [1, 3, 4], [3, 0, 4], [2, 0, 5], [1, 2, 5], [3, 1, 5], [0, 3, 5]]
    )
    return V.astype(float), F


def toy_template() -> Template:
    """A template made of one small octahedron per bone midpoint, rigidly weighted to it.

    Not one component (so not a valid tracking mesh), but every vertex moves with exactly
    one joint, which makes skinning results predictable.
    """
    sk = toy_skeleton()
    P = sk.rest_positions
    Vs, Fs, rows = [], [], []
    for j in range(sk.n_joints):
        kids = sk.children[j]
        tail = P[list(kids)].mean(axis=0) if kids else P[j] + sk.end_offsets[j]
        V, F = octahedron(0.5 * (P[j] + tail), 0.02)
        Fs.append(F + 6 * j)
        Vs.append(V)
        rows += [j] * 6
    V = np.concatenate(Vs)  # the toe octahedra touch z = 0
    n = len(V)
    W = sp.csr_matrix((np.ones(n), (np.arange(n), rows)), shape=(n, sk.n_joints))
    labels = np.array(_PART)[rows]
    src = [0, 13, 16, 18, 19, 20, 25, 26, 27, 2, 3, 4, 7, 8, 9]
    ev = EvalSkeleton(EVAL_NAMES, EVAL_PARENTS, sk.rest_positions[src], np.eye(31)[src])
    return Template("toy", V, np.concatenate(Fs), sk, W, labels, ev)


#: A tiny BVH file (two joints, three frames), shared by the BVH tests and the fuzzer.
TINY_BVH = """HIERARCHY
ROOT Hips
{
  OFFSET 1 2 3
  CHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation
  JOINT Spine
  {
    OFFSET 0 10 0
    CHANNELS 3 Zrotation Xrotation Yrotation
    End Site
    {
      OFFSET 0 5 0
    }
  }
  JOINT Leg
  {
    OFFSET 5 -10 0
    CHANNELS 3 Xrotation Yrotation Zrotation
    End Site
    {
      OFFSET 0 -40 0
    }
  }
}
MOTION
Frames: 2
Frame Time: 0.04
0 0 0 0 0 0 0 0 0 0 0 0
1 2 3 90 0 0 0 0 0 0 0 45
"""


#: A tiny ASF skeleton and AMC motion, shared by the ASF/AMC tests and the fuzzer.
TINY_ASF = """# a tiny skeleton
:version 1.10
:name tiny
:units
  mass 1.0
  length 1.0
  angle deg
:documentation
  made up for the tests
:root
   order TX TY TZ RX RY RZ
   axis XYZ
   position 0 0 0
   orientation 0 0 0
:bonedata
  begin
     id 1
     name spine
     direction 0 1 0
     length 10
     axis 0 0 0 XYZ
    dof rx ry rz
    limits (-10 10)
           (-10 10)
           (-10 10)
  end
  begin
     id 2
     name arm
     direction 1 0 0
     length 5
     axis 0 0 90 XYZ
    dof rx
    limits (-180 180)
  end
  begin
     id 3
     name hip
     direction 0 -1 0
     length 4
     axis 0 0 0 XYZ
  end
:hierarchy
  begin
    root spine hip
    spine arm
  end
"""

TINY_AMC = """#!OML:ASF tiny.asf
# a second comment line, as in CMU 01_01.amc
:FULLY-SPECIFIED
:DEGREES
1
root 1 2 3 0 0 0
spine 0 0 0
arm 0
2
arm 90
root 1 2 3 0 0 90
# a comment between bone lines
spine 0 0 0
"""


def observed_frame(V: np.ndarray, F: np.ndarray | None = None, index: int = 0):
    """Frame ``index`` of a mesh (``F`` given) or point cloud (``F`` None) sequence, its
    points, normals, occupancy and signed distance computed once
    (:class:`~meshmocap.estimate.recovery.observe.ObservedFrame`)."""
    from meshmocap.estimate.recovery.observe import ObservedFrame
    from meshmocap.io.capture import SequenceFrame

    return ObservedFrame(SequenceFrame(index, (V, F), None))
