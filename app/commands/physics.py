"""``lmm-studio physics``: is this motion physically possible?

    lmm-studio physics FILE.bvh [--json OUT] [--png OUT] [--mass KG] [--unit-scale M] [--frames A:B]

Builds a MuJoCo body for the file's skeleton (:mod:`lmm.physics.body`) and computes per frame the root
residual force and torque a real body would need beyond ground contact, ground penetration and contact
sliding per foot (:mod:`lmm.physics.plausibility`). Prints the summary; ``--json`` writes the per-frame
arrays (``residual_force_bw`` one value per file frame, ``penetration_cm``, ``sliding_cm_s`` per foot) and
the summary; ``--png`` draws them. Needs the optional ``mujoco`` (``pip install -e '.[physics]'``).
"""
from __future__ import annotations

import sys

from app.cli import number_in


def add_arguments(p) -> None:
    p.add_argument("file", help="a BVH file (.bvh or .bvh.gz), or a glTF (.glb, .gltf) or FBX file")
    p.add_argument("--json", metavar="OUT", help="write the per-frame arrays and the summary here as JSON")
    p.add_argument("--png", metavar="OUT", help="draw residual force, penetration and sliding here as a PNG")
    p.add_argument("--mass", type=number_in(1.0, 1000.0, unit="kg"), default=70.0, help="total body mass (default 70 kg)")
    p.add_argument("--unit-scale", type=number_in(1e-5, 100.0, unit="m"), default=None,
                   help="metres per file unit (default: guessed from the leg length: m, cm, mm or inches)")
    p.add_argument("--frames", metavar="A:B", help="summarise only the file's frames [A, B) (the arrays cover the file)")
    p.add_argument("--friction", type=number_in(0.0, 10.0), default=1.0, help="floor friction coefficient (default 1)")


def parse_frames(text: str, n_frames: int, path: str):
    from lmm.physics.plausibility import PlausibilityError

    try:
        a, b = (int(x) if x else None for x in text.split(":"))
    except ValueError:
        raise PlausibilityError(f"--frames {text[:40]!r}: expected A:B (file frames, B exclusive)") from None
    a, b = a or 0, n_frames if b is None else b
    if not 0 <= a < b <= n_frames:
        raise PlausibilityError(f"--frames {text}: outside the {n_frames} frames of {path}")
    return slice(a, b)


def main(args) -> int:
    from app.commands.extras import require
    if not require("physics", "mujoco"):
        return 2
    from lmm.data.motion_files import load_motion
    from lmm.data.outputs import check_outputs
    from lmm.physics.body import body_for_animation
    from lmm.physics.plausibility import plausibility

    check_outputs([("--json", args.json), ("--png", args.png)], [("FILE", args.file)])
    anim = load_motion(args.file)
    frames = parse_frames(args.frames, anim.n_frames, args.file) if args.frames else slice(None)
    body, pos, rot, scale = body_for_animation(anim, args.unit_scale, args.mass)
    result = plausibility(body, pos, rot, anim.fps, friction=args.friction)
    s = result.summary(frames)
    print(f"file      {args.file}: {anim.n_frames} frames at {anim.fps:.4g} fps, unit {scale:g} m, "
          f"body {body.height_m:.2f} m, {body.total_mass:g} kg")
    print(f"residual  root force median {s['residual_force_bw_median']:.3f} BW, p95 {s['residual_force_bw_p95']:.3f} BW; "
          f"torque median {s['residual_torque_bw_m_median']:.3f} BW*m")
    print(f"ground    penetration max {s['penetration_cm_max']:.2f} cm (in {100 * s['penetration_frames_fraction']:.0f}% "
          f"of frames); sliding in contact mean {s['sliding_cm_s_mean_in_contact']:.1f} cm/s; contact "
          f"left {100 * s['contact_fraction'][0]:.0f}% right {100 * s['contact_fraction'][1]:.0f}%")
    if args.json:
        from lmm.data.jsonio import write_json

        data = {"file": str(args.file), "unit_scale": scale, "body_height_m": body.height_m, **result.to_dict()}
        if args.frames:
            data["frames"] = [frames.start, frames.stop]
            data["summary_of_frames"] = s
        write_json(args.json, data)
        print(f"wrote     {args.json}")
    if args.png:
        from lmm.reporting import draw_plausibility_png

        draw_plausibility_png(result, args.png, title=str(args.file))
        print(f"wrote     {args.png}")
    return 0
