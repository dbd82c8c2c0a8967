"""How lmm/data/default_manifest.json was chosen: clean flat-ground ranges of LAFAN1 takes, tagged.

    python bench/curate_default_data.py [LAFAN1_FOLDER] > lmm/data/default_manifest.json

For each take it drops every frame near a finding of :mod:`lmm.checks` (calibration pose, airborne,
outliers, contact sliding) and near frames where a hand is raised above its shoulder, the hips are low
(crouching, crawling, lying), neither toe is on the ground or the arms are straight out (the
T-pose rule of check-data, moving or not); the rest splits into ranges of at least
3 s, tagged by what they hold for at least 1 s (walk < 1.8 m/s <= jog < 2.8 m/s <= run; strafe: moving
more than 50 degrees off the facing; turn: faster than 90 deg/s; stop: standing within the range).
Upright stretches standing (hips under 0.2 m/s, trunk within 15 degrees of vertical) for at least 1.5 s become extra ``idle`` ranges. Ranges marked in EXCLUDE were
rejected by looking at them (screenshots with ``lmm-studio view FILE --screenshot PNG --frame N``).

The shipped manifest is an earlier run of these rules edited by hand: the crouched run and walk ranges of
multipleActions1_subject3 kept (tagged ``crouch``, which these rules drop with the low hips), and, once
check-data had learned ``raised_leg`` and ``raised_arm``, the 31 raised legs and 3 raised arms inside used
ranges cut out at their edges (``check-data --used-only`` finds none). Run now, with those findings and a
0.5 s margin around each, this script gives nearly the same ranges: a few frames narrower at the cuts,
without the crouch ranges and the 2.4 s [2007:2080] of multipleActions1_subject1 (under its 3 s minimum).
"""
from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np

from lmm import quat
from lmm.data import bvh
from lmm.checks import check_take, moving_average, runs

TAKES = ("multipleActions1_subject1", "multipleActions1_subject2", "multipleActions1_subject3",
         "multipleActions1_subject4", "obstacles3_subject3", "obstacles3_subject4")
# looked at and rejected: obstacles3_subject3 frames 950-2500 lean, straddle and balance in place
EXCLUDE = {"obstacles3_subject3": [(950, 2500)]}
MARGIN = 15           # frames dropped on each side of a bad stretch (0.5 s)
MIN_RANGE = 90        # 3 s
MIN_IDLE = 45         # 1.5 s
FPS = 30.0


def bad_frames(path, name):
    findings, s = check_take(path, name)
    anim = bvh.load(path)
    rot, pos = anim.global_transforms()
    pos = pos * 0.01
    j = anim.names.index
    bad = np.zeros(len(pos), dtype=bool)

    def drop(a, b, margin=MARGIN):
        bad[max(a - margin, 0):b + margin] = True

    for f in findings:
        drop(f.start_frame, f.end_frame, MARGIN if f.kind != "contact_sliding" else 5)
    raised = ((pos[:, j("LeftHand"), 1] > pos[:, j("LeftArm"), 1] + 0.10)
              | (pos[:, j("RightHand"), 1] > pos[:, j("RightArm"), 1] + 0.10))
    hips = pos[:, j("Hips"), 1] - s.ground_m
    for a, b in runs(raised, 3) + runs(hips < 0.75 * np.median(hips), 3) + runs(s.toe_height_m.min(axis=1) > 0.10, 9):
        drop(a, b)
    for a, b in runs(s.tpose):  # arms straight out, even in motion: what a user reads as a T-pose
        drop(a, b)
    for a, b in EXCLUDE.get(name, []):
        bad[a:b] = True
    # strafing: moving well off the facing direction
    fwd = quat.mul_vec(rot[:, 0], np.array([0.0, 1.0, 0.0]))[:, [0, 2]]
    vel = moving_average(np.gradient(pos[:, 0, [0, 2]], axis=0) * FPS, 7)
    speed = np.linalg.norm(vel, axis=1)
    cos = (fwd * vel).sum(1) / np.maximum(np.linalg.norm(fwd, axis=1) * speed, 1e-9)
    strafe = (speed > 0.5) & (np.degrees(np.arccos(np.clip(cos, -1, 1))) > 50)
    trunk = pos[:, j("Head")] - pos[:, j("Hips")]
    lean_deg = np.degrees(np.arccos(trunk[:, 1] / np.linalg.norm(trunk, axis=1)))
    upright = moving_average(lean_deg, 15) < 15.0   # standing, not bent over
    return bad, s, strafe, upright


def ranges_of(path, name):
    bad, s, strafe, upright = bad_frames(path, name)
    out = []
    for a, b in runs(~bad, MIN_RANGE):
        v, turn = s.hips_speed_m_s[a:b], s.turn_rate_deg_s[a:b]
        kinds = {"walk": (v >= 0.2) & (v < 1.8), "jog": (v >= 1.8) & (v < 2.8), "run": v >= 2.8,
                 "strafe": strafe[a:b], "turn": turn > 90, "stop": v < 0.15}
        tags = [t for t, m in kinds.items() if m.sum() >= FPS]
        out.append({"range": [a, b], "tags": tags})
        for i, k in runs((v < 0.2) & upright[a:b], MIN_IDLE):
            out.append({"range": [a + i, a + k], "tags": ["idle"]})
    return sorted(out, key=lambda r: r["range"])


DESCRIPTION = ("Flat-ground walking, jogging, running, strafing, turning, starts and stops, and standing idles from "
               "six LAFAN1 takes, chosen by check-data and by looking (bench/curate_default_data.py): no calibration "
               "pose, no climbing or vaulting, no raised-arm gestures, no high leg raises while slow (check-data's raised_leg and "
               "raised_arm find none in the used ranges). Frames at 30 fps, [start, stop) half-open; "
               "'idle' ranges repeat upright standing stretches of a locomotion range so the idle set can be "
               "searched on its own.")


def manifest_text(clips, header: dict) -> str:
    """The manifest as JSON with one range per line."""
    lines = ["{"] + [f"  {json.dumps(k)}: {json.dumps(v)}," for k, v in header.items()] + ['  "clips": [']
    for i, c in enumerate(clips):
        lines.append(f'    {{"file": {json.dumps(c["file"])}, "ranges": [')
        lines.append(",\n".join(f'      {{"range": {json.dumps(r["range"])}, "tags": {json.dumps(r["tags"])}}}'
                                for r in c["ranges"]))
        lines.append("    ]}" + ("," if i < len(clips) - 1 else ""))
    return "\n".join(lines + ["  ]", "}"]) + "\n"


def main() -> int:
    from lmm import DEFAULT_MANIFEST

    folder = Path(sys.argv[1] if len(sys.argv) > 1 else "/work/shared/data/lafan1")
    clips, frames = [], 0
    for name in TAKES:
        rs = ranges_of(folder / f"{name}.bvh", name)
        frames += sum(r["range"][1] - r["range"][0] for r in rs)
        clips.append({"file": f"lafan1/{name}.bvh.gz", "ranges": rs})
    header = {k: v for k, v in json.loads(DEFAULT_MANIFEST.read_text()).items() if k != "clips"}
    header["description"] = DESCRIPTION
    sys.stdout.write(manifest_text(clips, header))
    print(f"{frames} source frames = {frames / FPS:.0f} s; at 60 fps mirrored {frames * 4} frames", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
