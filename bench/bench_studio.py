"""Studio frame rate under Xvfb at 1600x900 with every panel shown, and the Python-side time per frame.

Runs the real studio (``lmm-studio --frames N --input builtin:circle``) in a subprocess on its own Xvfb
display (or on $DISPLAY with --display), with the default layout (all nine panels), both characters when
LMM weights are available, and reads the per-frame timings from its state dump.

    python bench/bench_studio.py [--frames 600] [--warmup 120] [--weights PATH] [--samples -1]
                                 [--readback-3d] [--paused] [--ui-antialiasing auto|on|off] [--json]

Printed: fps (from the median frame time, and frames / wall time), and the median milliseconds per
frame of each part: the controllers (MM, LMM), the studio's own Python (input, 3D scene update,
panels: what this project's GUI code costs), the 3D render and its copy into dearpygui's texture (or
its readback, with --readback-3d), and dearpygui's frame (UI layout and rasterisation, swap).
``--paused`` pauses at the end of the warm-up (a paused view is not drawn again). What a first start
works out and keeps (the database, the compressor latent table) is worked out before the studio starts,
so a first run on a machine measures the same studio as later ones. Software OpenGL (llvmpipe) is the
floor: users have GPUs.
"""
from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--frames", type=int, default=600)
    ap.add_argument("--warmup", type=int, default=120, help="frames left out of the statistics")
    ap.add_argument("--weights", help="LMM weights (default: the shipped ones; MM only when missing)")
    ap.add_argument("--samples", type=int, default=-1, help="3D multisampling (-1: auto)")
    ap.add_argument("--render-scale", type=float, default=1.0, help="3D view resolution scale (default 1)")
    ap.add_argument("--readback-3d", action="store_true",
                    help="the studio's --readback-3d: read the 3D view back and upload it (for comparison)")
    ap.add_argument("--ui-antialiasing", choices=("auto", "on", "off"), default="auto",
                    help="the studio's --ui-antialiasing (default auto: off on software GL)")
    ap.add_argument("--paused", action="store_true",
                    help="pause at the end of the warm-up: the frame of a studio paused on one tick")
    ap.add_argument("--display", help="use this X display instead of starting Xvfb")
    ap.add_argument("--lp-threads", help="set LP_NUM_THREADS for llvmpipe (default: leave as is)")
    ap.add_argument("--json", action="store_true", help="print one JSON object")
    args = ap.parse_args()

    xvfb = None
    display = args.display
    if display is None:
        from viewer.xvfb import Xvfb, XvfbUnavailable

        try:
            xvfb = Xvfb("1920x1080x24")
        except XvfbUnavailable as e:
            sys.exit(f"{e}, or pass --display")
        display = xvfb.display
    warm_note = warm_caches(args.weights)
    tmp = Path(tempfile.mkdtemp(prefix="bench-studio-"))
    try:
        env = dict(os.environ, DISPLAY=display, LMM_STUDIO_CONFIG=str(tmp / "config"), PYTHONPATH=str(ROOT))
        if args.lp_threads is not None:
            env["LP_NUM_THREADS"] = args.lp_threads
        dump = tmp / "dump.json"
        cmd = [sys.executable, "-m", "app.cli", "--frames", str(args.frames), "--input", "builtin:circle",
               "--layout", "default", "--width", "1600", "--height", "900", "--no-gamepads",
               "--no-save-layout", "--samples", str(args.samples), "--render-scale", str(args.render_scale),
               "--ui-antialiasing", args.ui_antialiasing, "--dump-state", str(dump)]
        if args.weights:
            cmd += ["--weights", args.weights]
        if args.readback_3d:
            cmd += ["--readback-3d"]
        if args.paused:
            script = tmp / "pause.json"
            script.write_text(json.dumps({"actions": [{"frame": max(args.warmup - 10, 0), "do": "pause"}]}))
            cmd += ["--script", str(script)]
        t0 = time.perf_counter()
        proc = subprocess.run(cmd, env=env, cwd=tmp, capture_output=True, text=True)
        wall = time.perf_counter() - t0
        if proc.returncode != 0 or not dump.exists():
            print(proc.stderr[-4000:], file=sys.stderr)
            return 1
        d = json.loads(dump.read_text())
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
        if xvfb is not None:
            xvfb.stop()

    frames = d["frames"][args.warmup:]
    ms = {k: np.array([f["ms"].get(k, np.nan) for f in frames], float) for k in frames[0]["ms"]}
    frame_ms = np.array([f["frame_ms"] for f in frames], float)
    t = np.array([f["t"] for f in frames], float)
    cpu = np.array([f["cpu"] for f in frames], float)
    python_ms = ms["input"] + ms["viewport"] + ms["panels"]
    # (a paused studio steps no controller)
    controllers_ms = sum((ms[n] for n in d["controllers"] if n in ms), np.zeros(len(frames)))
    out = {
        "controllers": d["controllers"], "frames": len(frames), "window": "1600x900",
        "fps_median": 1000.0 / float(np.median(frame_ms)),
        "fps_wall": (len(t) - 1) / float(t[-1] - t[0]) if len(t) > 1 else float("nan"),
        "frame_ms_median": float(np.median(frame_ms)),
        # CPU time of the studio process (all its threads, llvmpipe's included) per frame: what the
        # frame costs whatever else the machine is doing
        "process_cpu_ms_per_frame": 1000.0 * float(cpu[-1] - cpu[0]) / max(len(cpu) - 1, 1),
        "python_ms_median": float(np.median(python_ms)),
        "controllers_ms_median": float(np.median(controllers_ms)),
        "parts_ms_median": {k: float(np.nanmedian(v)) for k, v in ms.items()},
        "viewport_3d": d["final"]["viewport"].get("size"),
        "render_3d": d["final"]["viewport"].get("render_size"),
        "view_path": d["final"]["viewport"].get("view_path"),
        "paused": bool(args.paused),
        "ui_antialiasing": d.get("ui_antialiasing", {}).get("anti_aliased_fill"),
        "renders_3d_measured": int(sum(1 for f in frames if f["ms"].get("render", 0) > 0)),
        "readback_why": d["final"]["viewport"].get("readback_why"),
        "load_average": os.getloadavg(),
        "cpu_count": os.cpu_count(),
        "process_wall_s": wall,
        "lmm_problem": d.get("lmm_problem"),
        "warm_caches": warm_note,
    }
    if args.json:
        print(json.dumps(out, indent=2))
        return 0
    print(f"studio, default layout (all panels), 1600x900, {' + '.join(n.upper() for n in out['controllers'])}, "
          f"{out['frames']} frames after {args.warmup} warm-up" + (", paused" if args.paused else ""))
    print(f"  fps: {out['fps_median']:.1f} (median frame {out['frame_ms_median']:.1f} ms), "
          f"{out['fps_wall']:.1f} frames / wall second")
    print(f"  process CPU time per frame: {out['process_cpu_ms_per_frame']:.1f} ms (all threads, llvmpipe included)")
    print(f"  Python-side per frame (studio: input + 3D scene update + panels): {out['python_ms_median']:.2f} ms median")
    print(f"  controllers per frame: {out['controllers_ms_median']:.2f} ms median")
    labels = {"input": "input", "mm": "MM step", "lmm": "LMM step", "viewport": "3D scene update (Python)",
              "render": "3D render (GL)", "readback": "3D copy (direct) / readback", "panels": "panels (Python)",
              "ui": "dearpygui frame (UI raster + swap)", "dump": "state dump (this benchmark's, not counted)"}
    for k, v in out["parts_ms_median"].items():
        print(f"    {labels.get(k, k):38s} {v:7.2f} ms")
    print(f"  3D view {out['viewport_3d']} rendered at {out['render_3d']} ({out['renders_3d_measured']} of the "
          f"{out['frames']} frames drew it), {out['view_path']}"
          + (f" ({out['readback_why']})" if out["readback_why"] else "") + f", load average {out['load_average'][0]:.2f} on {out['cpu_count']} CPUs")
    print(f"  UI anti-aliasing (--ui-antialiasing {args.ui_antialiasing}): {'on' if out['ui_antialiasing'] else 'off'}")
    if out["lmm_problem"]:
        print(f"  note: {out['lmm_problem']}")
    print(f"  caches: {warm_note}")
    return 0


def warm_caches(weights: str | None) -> str:
    """Work out, in this process, what a studio's first start works out and keeps in the cache (the
    database, its derived arrays and, on a background thread that competes with the GUI for the GIL for
    several seconds, the compressor latent of every frame), so the measured frames are those of a studio
    started before on this machine, not of a first start. Returns a line saying what was done."""
    from lmm.data.build import load_or_build
    from lmm.data.weights import WeightsError
    from lmm.features import build_features
    from lmm.latents import cached_database_latents
    from lmm.learned import DEFAULT_WEIGHTS

    t0 = time.perf_counter()
    db, _ = load_or_build(None)
    features = build_features(db)
    compressor = Path(weights or DEFAULT_WEIGHTS).with_name("compressor.npz")
    if not compressor.is_file():
        return f"database ready; no {compressor.name} beside the weights (no latent table)"
    try:
        cached_database_latents(compressor, db, features)
    except WeightsError as e:
        return f"database ready; no latent table ({e})"
    return f"database and latent table ready before the run ({time.perf_counter() - t0:.1f} s)"


if __name__ == "__main__":
    sys.exit(main())
