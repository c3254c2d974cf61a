"""Joint-name tables mapping the mocap skeleton flavours onto the CMU MotionBuilder names.

The bundled templates are rigged with the 31 bones of the CMU MotionBuilder skeleton
(``Hips`` … ``RThumb``). Each table maps a source flavour's joint name to that canonical
name; joints absent from a table are left unmapped (they keep their rest orientation
relative to their parent when retargeted).
"""

from __future__ import annotations

#: The CMU MotionBuilder skeleton (31 bones), parents before children.
CMU_MB_NAMES = (
    "Hips",
    "LHipJoint",
    "LeftUpLeg",
    "LeftLeg",
    "LeftFoot",
    "LeftToeBase",
    "RHipJoint",
    "RightUpLeg",
    "RightLeg",
    "RightFoot",
    "RightToeBase",
    "LowerBack",
    "Spine",
    "Spine1",
    "Neck",
    "Neck1",
    "Head",
    "LeftShoulder",
    "LeftArm",
    "LeftForeArm",
    "LeftHand",
    "LeftFingerBase",
    "LeftHandIndex1",
    "LThumb",
    "RightShoulder",
    "RightArm",
    "RightForeArm",
    "RightHand",
    "RightFingerBase",
    "RightHandIndex1",
    "RThumb",
)

#: CMU ASF/AMC bone names (and raw amc2bvh BVHs) → MotionBuilder names.
ASF_TO_MB = {
    "root": "Hips",
    "hip": "Hips",
    "lhipjoint": "LHipJoint",
    "lfemur": "LeftUpLeg",
    "ltibia": "LeftLeg",
    "lfoot": "LeftFoot",
    "ltoes": "LeftToeBase",
    "rhipjoint": "RHipJoint",
    "rfemur": "RightUpLeg",
    "rtibia": "RightLeg",
    "rfoot": "RightFoot",
    "rtoes": "RightToeBase",
    "lowerback": "LowerBack",
    "upperback": "Spine",
    "thorax": "Spine1",
    "lowerneck": "Neck",
    "upperneck": "Neck1",
    "head": "Head",
    "lclavicle": "LeftShoulder",
    "lhumerus": "LeftArm",
    "lradius": "LeftForeArm",
    "lwrist": "LeftHand",
    "lhand": "LeftFingerBase",
    "lfingers": "LeftHandIndex1",
    "lthumb": "LThumb",
    "rclavicle": "RightShoulder",
    "rhumerus": "RightArm",
    "rradius": "RightForeArm",
    "rwrist": "RightHand",
    "rhand": "RightFingerBase",
    "rfingers": "RightHandIndex1",
    "rthumb": "RThumb",
}

#: Aliases used by the MotionBuilder-friendly CMU BVHs for the finger bones.
MB_ALIASES = {"LFingers": "LeftHandIndex1", "RFingers": "RightHandIndex1"}

#: "Daz-friendly" CMU BVHs (root ``hip``, 43 joints) → MotionBuilder names. Daz has no
#: toes, one spine bone fewer and no upper neck; fingers and eyes are not mapped.
DAZ_TO_MB = {
    "hip": "Hips",
    "abdomen": "LowerBack",
    "chest": "Spine1",
    "neck": "Neck",
    "head": "Head",
    "lCollar": "LeftShoulder",
    "lShldr": "LeftArm",
    "lForeArm": "LeftForeArm",
    "lHand": "LeftHand",
    "rCollar": "RightShoulder",
    "rShldr": "RightArm",
    "rForeArm": "RightForeArm",
    "rHand": "RightHand",
    "lButtock": "LHipJoint",
    "lThigh": "LeftUpLeg",
    "lShin": "LeftLeg",
    "lFoot": "LeftFoot",
    "rButtock": "RHipJoint",
    "rThigh": "RightUpLeg",
    "rShin": "RightLeg",
    "rFoot": "RightFoot",
}


def canonical_name_map(source_names: tuple[str, ...] | list[str]) -> dict[str, str]:
    """Return ``{canonical MotionBuilder name: source joint name}`` for a source skeleton.

    Tries every known flavour (MotionBuilder, its aliases, ASF/AMC, Daz) and keeps, for
    each canonical name, the first source joint that maps to it.
    """
    out: dict[str, str] = {}
    canon = set(CMU_MB_NAMES)
    for name in source_names:
        for table in (MB_ALIASES, ASF_TO_MB, DAZ_TO_MB):
            if name in table:
                target = table[name]
                break
        else:
            target = name if name in canon else None
        if target is not None and target not in out:
            out[target] = name
    return out
