"""Benchmark the viewer: two LAFAN1-sized characters, ground, two trajectories, ~30 feature spheres
and arrows at 1280x720 on a headless EGL context.

Prints the median per-frame time of: updating the renderables from arrays, drawing (with
``ctx.finish()`` so the GPU/llvmpipe work is counted; also the process CPU time of the draw, all
llvmpipe threads together, which a busy shared machine disturbs less than wall time) and reading
the image back (uint8 and the float32 a dearpygui texture wants).

    .venv/bin/python bench/bench_viewer.py [--width 1280 --height 720 --samples 4 0 --frames 60
                                          --styles capsules sticks --shadow on off
                                          --json out.json --save frame.png]

Every combination of samples x styles x shadow is timed; "sticks, shadow off" is the look the
viewer had before the capsule bodies.
"""
from __future__ import annotations

import argparse
import json
import platform
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from viewer import (Arrows, Ground, Lines, OrbitCamera, Renderer, Scene, Skeleton, Spheres,  # noqa: E402
                    create_headless_context, radii_for_height)


def load_motion(n_frames: int):
    """(parents, joint names or None, positions (F, 22, 3) in metres, source): a shipped LAFAN1
    take, or a synthetic stand-in."""
    takes = sorted((ROOT / "lmm" / "data" / "lafan1").glob("*.bvh.gz"))
    try:
        from lmm.data import bvh

        anim = bvh.load(min(takes, key=lambda p: p.stat().st_size))
        return anim.parents, anim.names, anim.global_positions()[1000:1000 + n_frames] / 100.0, "LAFAN1"
    except Exception:
        rng = np.random.default_rng(0)
        parents = np.array([-1, 0, 1, 2, 3, 0, 5, 6, 7, 0, 9, 10, 11, 12, 11, 14, 15, 16, 11, 18, 19, 20])
        offsets = rng.normal(scale=0.12, size=(22, 3)) + [0, 0.1, 0]
        pos = np.zeros((n_frames, 22, 3))
        for j, p in enumerate(parents):
            pos[:, j] = [0, 0.95, 0] if p < 0 else pos[:, p] + offsets[j]
        pos[:, :, 0] += np.linspace(0, 2, n_frames)[:, None]
        return parents, None, pos, "synthetic"


def build_scene(ctx, parents, names=None, style="capsules", shadow=True):
    scene = Scene()
    scene.add(Ground(ctx))
    radii = radii_for_height(1.7)
    look = {"names": names, "style": style, "shadow": shadow}
    chars = [scene.add(Skeleton(ctx, parents, color=(0.95, 0.55, 0.15), **radii, **look)),
             scene.add(Skeleton(ctx, parents, color=(0.2, 0.55, 0.95), alpha=0.6, **radii, **look))]
    trajs = [scene.add(Lines(ctx, color=(0.95, 0.85, 0.1))), scene.add(Lines(ctx, color=(0.3, 0.9, 0.9)))]
    spheres = scene.add(Spheres(ctx, radius=0.03))
    arrows = scene.add(Arrows(ctx, color=(0.95, 0.3, 0.3)))
    return scene, chars, trajs, spheres, arrows


def update(frame, positions, chars, trajs, spheres, arrows, camera):
    pose = positions[frame % len(positions)]
    camera.follow(pose[0] + [0.4, 0.0, 0.0])
    chars[0].update(pose)
    chars[1].update(pose + [0.8, 0.0, 0.0])
    t = np.linspace(0.0, 1.0, 60)[:, None]
    root = pose[0] * [1, 0, 1]
    trajs[0].update(root + t * [1.5, 0.0, 0.5])                    # future trajectory, 60 points
    trajs[1].update(root + t * [-1.2, 0.0, -0.3] + [0.8, 0, 0])     # the other character's
    markers = np.r_[pose[:10], root + t[::6] * [1.5, 0, 0.5], pose[10:20] + [0.8, 0, 0]]   # 30 feature spheres
    colors = np.tile([[1.0, 0.2, 0.7, 1.0], [0.2, 1.0, 0.4, 1.0]], (15, 1))
    spheres.update(markers, colors=colors)
    origins = root + t[::8] * [1.5, 0.0, 0.5] + [0, 0.02, 0]      # 8 facing arrows along the trajectory
    arrows.update(origins, np.tile([0.0, 0.0, 0.3], (len(origins), 1)))


def bench(ctx, width, height, samples, frames, positions, parents, names=None, style="capsules", shadow=True,
          save=None):
    scene, chars, trajs, spheres, arrows = build_scene(ctx, parents, names, style, shadow)
    renderer = Renderer(ctx, width, height, samples=samples)
    camera = OrbitCamera(yaw_deg=30.0, pitch_deg=15.0)
    camera.fit(np.r_[positions[0], positions[0] + [0.8, 0, 0]], aspect=width / height, margin=1.3)
    u8 = np.empty((height, width, 4), np.uint8)
    f32 = np.empty(height * width * 4, np.float32)
    t_update, t_draw, t_read_u8, t_read_f32, cpu_draw = [], [], [], [], []
    for i in range(frames + 5):
        a = time.perf_counter()
        update(i, positions, chars, trajs, spheres, arrows, camera)
        b = time.perf_counter()
        cpu = time.process_time()
        renderer.render_to(scene, camera)
        ctx.finish()
        c = time.perf_counter()
        cpu = time.process_time() - cpu
        renderer.read(np.uint8, out=u8)
        d = time.perf_counter()
        renderer.read(np.float32, out=f32, flip=False)
        e = time.perf_counter()
        if i >= 5:   # warm-up frames compile shaders and size buffers
            t_update.append(b - a)
            t_draw.append(c - b)
            cpu_draw.append(cpu)
            t_read_u8.append(d - c)
            t_read_f32.append(e - d)
    if save:
        from PIL import Image

        Image.fromarray(renderer.read(np.uint8)[..., :3]).save(save)
    renderer.release()
    scene.release()
    ms = lambda xs: round(float(np.median(xs)) * 1000.0, 3)  # noqa: E731
    return {"width": width, "height": height, "samples": renderer.samples, "frames": frames,
            "style": style, "shadow": shadow,
            "update_ms": ms(t_update), "draw_ms": ms(t_draw), "draw_cpu_ms": ms(cpu_draw),
            "read_uint8_ms": ms(t_read_u8),
            "read_float32_unflipped_ms": ms(t_read_f32),
            "draw_p90_ms": round(float(np.percentile(t_draw, 90)) * 1000.0, 3)}


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--width", type=int, default=1280)
    parser.add_argument("--height", type=int, default=720)
    parser.add_argument("--samples", type=int, nargs="+", default=[4, 0], help="MSAA sample counts to try")
    parser.add_argument("--frames", type=int, default=60, help="timed frames per configuration")
    parser.add_argument("--styles", nargs="+", default=["capsules", "sticks"], choices=["capsules", "sticks"],
                        help="skeleton styles to try")
    parser.add_argument("--shadow", nargs="+", default=["on", "off"], choices=["on", "off"],
                        help="ground shadow settings to try")
    parser.add_argument("--json", help="also write the results to this file")
    parser.add_argument("--save", metavar="PNG", help="save the last frame of the first configuration")
    args = parser.parse_args(argv)

    ctx = create_headless_context()
    parents, names, positions, source = load_motion(args.frames + 5)
    info = {"renderer": ctx.info["GL_RENDERER"], "gl_version": ctx.info["GL_VERSION"],
            "machine": platform.machine(), "python": platform.python_version(), "motion": source,
            "scene": "2 skeletons (22 joints, one ghost) + ground + 2x60-point trajectories + 30 spheres + 8 arrows"}
    print(f"{info['renderer']} | {info['scene']} | motion: {source}")
    results = []
    configs = [(samples, style, shadow == "on") for samples in args.samples for style in args.styles
               for shadow in args.shadow]
    for k, (samples, style, shadow) in enumerate(configs):
        r = bench(ctx, args.width, args.height, samples, args.frames, positions, parents, names, style, shadow,
                  save=args.save if k == 0 else None)
        results.append(r)
        print(f"{r['width']}x{r['height']} MSAA {r['samples']}x {style:8s} shadow {'on ' if shadow else 'off'}: "
              f"draw {r['draw_ms']:.2f} ms (p90 {r['draw_p90_ms']:.2f}, CPU {r['draw_cpu_ms']:.2f}), "
              f"update {r['update_ms']:.3f} ms, readback uint8 {r['read_uint8_ms']:.2f} ms, "
              f"float32 {r['read_float32_unflipped_ms']:.2f} ms (median of {r['frames']})")
    if args.json:
        Path(args.json).write_text(json.dumps({"info": info, "results": results}, indent=2) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
