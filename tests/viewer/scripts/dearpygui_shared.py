"""Render with the viewer inside dearpygui's GL context (run under Xvfb by test_viewer_window.py).

argv: output PNG of the dearpygui viewport, folder holding viewer_testutil.py. Prints JSON.
"""
import json
import sys

import dearpygui.dearpygui as dpg
import numpy as np

from viewer import Ground, OrbitCamera, Renderer, Scene, Skeleton, attach_current_context

sys.path.insert(0, sys.argv[2])
from viewer_testutil import TPOSE_PARENTS, TPOSE_POSITIONS  # noqa: E402

out = sys.argv[1]
W, H = 320, 240
dpg.create_context()
dpg.create_viewport(title="shared", width=400, height=300)
dpg.setup_dearpygui()
tex = np.zeros(W * H * 4, np.float32)
with dpg.texture_registry():
    dpg.add_raw_texture(W, H, tex, format=dpg.mvFormat_Float_rgba, tag="view")
with dpg.window(tag="main"):
    dpg.add_image("view", uv_min=(0, 1), uv_max=(1, 0))
dpg.set_primary_window("main", True)
dpg.show_viewport()
dpg.render_dearpygui_frame()
ctx = attach_current_context()
renderer = Renderer(ctx, W, H)
scene = Scene()
scene.add(Ground(ctx))
skel = scene.add(Skeleton(ctx, TPOSE_PARENTS, color=(0.95, 0.5, 0.1)))
skel.update(TPOSE_POSITIONS)
cam = OrbitCamera(yaw_deg=20, pitch_deg=10)
cam.fit(TPOSE_POSITIONS, W / H)
for i in range(4):
    renderer.render(scene, cam, dtype=np.float32, out=tex, flip=False)
    dpg.render_dearpygui_frame()
dpg.output_frame_buffer(file=out)
for i in range(4):
    renderer.render(scene, cam, dtype=np.float32, out=tex, flip=False)
    dpg.render_dearpygui_frame()
img = tex.reshape(H, W, 4)[::-1]
hips = cam.project(TPOSE_POSITIONS[:1], W, H)[0].astype(int)
print(json.dumps({"hips_rgba": img[hips[1], hips[0]].tolist(), "renderer": ctx.info["GL_RENDERER"]}))
dpg.destroy_context()
