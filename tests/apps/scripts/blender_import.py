"""Run by Blender (``blender -b --factory-startup --python blender_import.py -- FILE FPS
BONE OUT.json``): import a BVH or glTF file and write what Blender made of it as JSON:
the animation's frame range and the world position of BONE's head at every frame."""

import json
import sys

import bpy

path, fps, bone, out = sys.argv[sys.argv.index("--") + 1 :]
scene = bpy.context.scene
scene.render.fps = round(float(fps))
scene.render.fps_base = scene.render.fps / float(fps)
for obj in list(bpy.data.objects):
    bpy.data.objects.remove(obj)
if path.endswith(".bvh"):
    import io_anim_bvh.import_bvh as importer

    # Debian's Blender 3.4 on Python 3.11: its BVH importer opens files with mode "rU"
    def _open(f, mode="r", *args, **kwargs):
        return open(f, mode.replace("U", ""), *args, **kwargs)

    importer.open = _open
    bpy.ops.import_anim.bvh(
        filepath=path, global_scale=0.01, update_scene_fps=True, update_scene_duration=True
    )
else:
    import numpy

    # Debian's Blender 3.4 with NumPy ≥ 1.24: its glTF importer still uses np.bool
    if "bool" not in vars(numpy):
        numpy.bool = bool
    bpy.ops.import_scene.gltf(filepath=path)
arm = next(o for o in bpy.data.objects if o.type == "ARMATURE")
action = arm.animation_data.action
start, end = (round(x) for x in action.frame_range)
heads = []
for f in range(start, end + 1):
    scene.frame_set(f)
    heads.append(list(arm.matrix_world @ arm.pose.bones[bone].head))
meshes = [o.name for o in bpy.data.objects if o.type == "MESH"]
with open(out, "w") as fh:
    json.dump(
        {
            "start": start,
            "end": end,
            "heads": heads,
            "meshes": meshes,
            "bones": [b.name for b in arm.pose.bones],
            "fps": scene.render.fps,
        },
        fh,
    )
