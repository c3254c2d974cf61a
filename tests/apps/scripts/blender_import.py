"""Open a meshmocap export (.bvh, .glb or .gltf) in Blender, check it, render a frame.

Runs with Blender's Python module (``pip install -e ".[blender]"``, which installs
``bpy``, Blender 4.2 to 5.0 on Python 3.11)::

    python blender_import.py walk.glb --render walk.png --blend walk.blend

or inside Blender itself: ``blender -b --python blender_import.py -- walk.glb``.

It starts from an empty scene and **sets the scene's frame rate to the file's before
importing**: glTF stores its keys in seconds and Blender turns them into frames at the
scene's rate (24 fps in a new scene), so 40 frames at 30 fps would otherwise come in as 32.
A BVH states its frame time; the importer's ``update_scene_fps`` sets the rate from it.
The BVH is in centimetres (``meshmocap export --bvh-unit`` chooses; ``--scale`` here
converts back to metres). Blender's world is Z up, in metres, like meshmocap's.

It prints what Blender made of the file (bones, frames, rate, the mesh's height), and
optionally renders one frame with Cycles on the CPU (no display or GPU needed), saves the
scene as a .blend, and writes a JSON report: each bone's world transform from its rest
pose (4 x 4, row-major, Z up, metres) at every frame, the bones' rest positions, and the
mesh's height per frame.
"""

import argparse
import json
import struct
import sys
from pathlib import Path

import bpy


def gltf_fps(path: Path) -> float:
    """The key rate of the first animation of a glTF/GLB file: (keys − 1) / last key time."""
    data = path.read_bytes()
    if data[:4] == b"glTF":  # binary: header, then the JSON chunk
        (length,) = struct.unpack_from("<I", data, 12)
        gltf = json.loads(data[20 : 20 + length])
    else:
        gltf = json.loads(data)
    sampler = gltf["animations"][0]["samplers"][0]
    times = gltf["accessors"][sampler["input"]]
    return (times["count"] - 1) / (times["max"][0] - times["min"][0])


def set_fps(scene, fps: float) -> None:
    """Set the scene's frame rate to ``fps`` (Blender keeps it as fps / fps_base)."""
    scene.render.fps = max(1, round(fps))
    scene.render.fps_base = scene.render.fps / fps


def mesh_heights(scene, meshes, frames) -> list[float]:
    """Height (Z extent, metres) of the deformed meshes at each frame."""
    heights = []
    for f in frames:
        scene.frame_set(f)
        depsgraph = bpy.context.evaluated_depsgraph_get()
        zs = []
        for obj in meshes:
            evaluated = obj.evaluated_get(depsgraph)
            mesh = evaluated.to_mesh()
            zs += [(evaluated.matrix_world @ v.co).z for v in mesh.vertices]
            evaluated.to_mesh_clear()
        heights.append(max(zs) - min(zs))
    return heights


def render(scene, meshes, frame: int, out: Path) -> None:
    """Render ``frame`` with Cycles on the CPU, 320 x 240, a camera looking at ``meshes``."""
    scene.frame_set(frame)
    depsgraph = bpy.context.evaluated_depsgraph_get()
    corners = []
    for obj in meshes:
        evaluated = obj.evaluated_get(depsgraph)
        corners += [evaluated.matrix_world @ v.co for v in evaluated.to_mesh().vertices]
        evaluated.to_mesh_clear()
    lo = [min(c[i] for c in corners) for i in range(3)]
    hi = [max(c[i] for c in corners) for i in range(3)]
    centre = [(a + b) / 2 for a, b in zip(lo, hi, strict=True)]
    size = max(b - a for a, b in zip(lo, hi, strict=True))
    bpy.ops.object.camera_add(location=(centre[0], centre[1] - 3 * size, centre[2] + size / 3))
    camera = bpy.context.object
    direction = camera.location - type(camera.location)(centre)
    camera.rotation_euler = direction.to_track_quat("Z", "Y").to_euler()
    scene.camera = camera
    bpy.ops.object.light_add(type="SUN", location=(0, 0, 5), rotation=(0.6, 0.2, 0.3))
    bpy.context.object.data.energy = 4.0
    scene.world = bpy.data.worlds.new("sky")
    scene.world.color = (0.6, 0.65, 0.7)
    scene.render.engine = "CYCLES"
    scene.cycles.device = "CPU"
    scene.cycles.samples = 8
    scene.render.resolution_x, scene.render.resolution_y = 320, 240
    scene.render.filepath = str(out)
    bpy.ops.render.render(write_still=True)


def main(argv: list[str]) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("file", type=Path, help="a meshmocap export: .bvh, .glb or .gltf")
    parser.add_argument("--scale", type=float, default=0.01, help="BVH units to metres")
    parser.add_argument("--fps", type=float, help="frame rate (default: the file's)")
    parser.add_argument("--render", type=Path, help="render a frame to this PNG")
    parser.add_argument("--frame", type=int, help="frame to render (default: the middle)")
    parser.add_argument("--blend", type=Path, help="save the scene as this .blend file")
    parser.add_argument("--report", type=Path, help="write what Blender made of it (JSON)")
    args = parser.parse_args(argv)
    path = args.file.resolve()

    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    if path.suffix.lower() == ".bvh":
        if args.fps:
            set_fps(scene, args.fps)
        bpy.ops.import_anim.bvh(
            filepath=str(path),
            global_scale=args.scale,
            update_scene_fps=not args.fps,
            update_scene_duration=True,
        )
    else:
        set_fps(scene, args.fps or gltf_fps(path))  # before the import: see above
        bpy.ops.import_scene.gltf(filepath=str(path))
    armature = next(o for o in scene.objects if o.type == "ARMATURE")
    # the skinned body (the glTF importer may add a mesh of its own to draw the bones)
    meshes = [o for o in scene.objects if o.type == "MESH" and o.find_armature() == armature]
    start, end = (round(x) for x in armature.animation_data.action.frame_range)
    scene.frame_start, scene.frame_end = start, end
    frames = range(start, end + 1)
    fps = scene.render.fps / scene.render.fps_base

    heights = mesh_heights(scene, meshes, frames) if meshes else []
    tall = f", mesh {heights[0]:.2f} m tall" if heights else ""
    print(
        f"{path.name}: {len(armature.pose.bones)} bones, {len(frames)} frames at "
        f"{fps:g} fps (frames {start}-{end}){tall}"
    )
    if args.report:
        world = armature.matrix_world
        rest = {b.name: (world @ b.bone.matrix_local).inverted() for b in armature.pose.bones}
        transforms = []
        for f in frames:
            scene.frame_set(f)
            transforms.append(
                [
                    [list(row) for row in world @ b.matrix @ rest[b.name]]
                    for b in armature.pose.bones
                ]
            )
        report = {
            "blender": bpy.app.version_string,
            "file": str(path),
            "fps": fps,
            "frame_start": start,
            "frame_end": end,
            "bones": [b.name for b in armature.pose.bones],
            "rest_heads": [list(world @ b.bone.head_local) for b in armature.pose.bones],
            "transforms": transforms,
            "mesh_heights": heights,
        }
        args.report.write_text(json.dumps(report))
    if args.render and not meshes:
        print("nothing to render: a BVH holds bones, no mesh (export a .glb for the body)")
    elif args.render:
        frame = args.frame if args.frame is not None else (start + end) // 2
        render(scene, meshes, frame, args.render.resolve())
        print(f"rendered frame {frame} to {args.render}")
    if args.blend:
        bpy.ops.wm.save_as_mainfile(filepath=str(args.blend.resolve()))
        print(f"saved {args.blend}")
    return 0


if __name__ == "__main__":
    # Blender passes the script's arguments after "--"; the bpy module gets them as usual
    sys.exit(main(sys.argv[sys.argv.index("--") + 1 :] if "--" in sys.argv else sys.argv[1:]))
