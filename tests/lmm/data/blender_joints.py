"""Run by Blender (``blender -b --python tests/lmm/data/blender_joints.py -- FILE OUT.json FPS FRAMES``): import a glTF or
FBX file with Blender's own importer and write every pose bone's head in world space, Y up, metres, at the times
k / FPS (k < FRAMES) from the start of the armature's action. The tests compare it with our readers."""
import json
import sys

import bpy
import numpy

if not hasattr(numpy, "bool"):      # Debian's Blender 3.4 glTF importer still says np.bool (gone in numpy 1.24)
    numpy.bool = bool

path, out, fps, frames = sys.argv[sys.argv.index("--") + 1:][:4]
fps, frames = float(fps), int(frames)
bpy.ops.wm.read_factory_settings(use_empty=True)
if path.lower().endswith(".fbx"):
    bpy.ops.import_scene.fbx(filepath=path)
else:
    bpy.ops.import_scene.gltf(filepath=path)
scene = bpy.context.scene
arm = next(o for o in scene.objects if o.type == "ARMATURE")
action = arm.animation_data.action
start = action.frame_range[0]
scene_fps = scene.render.fps / scene.render.fps_base
joints = {b.name: [] for b in arm.pose.bones}
for k in range(frames):
    at = start + k / fps * scene_fps
    scene.frame_set(int(at), subframe=at - int(at))
    for b in arm.pose.bones:
        x, y, z = arm.matrix_world @ b.head
        joints[b.name].append([x, z, -y])          # Blender is Z up: back to Y up
with open(out, "w") as f:
    json.dump({"scene_fps": scene_fps, "start": start, "joints": joints}, f)
