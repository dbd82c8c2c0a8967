"""Numbers a user sees as untrustworthy motion, from recordings and from an idle test.

    lmm-studio run --controller mm --input builtin:random:1 --seconds 600 --record R.bvh --metrics-json M.json
    python bench/motion_trust.py R.bvh [R2.bvh ...] [--idle MANIFEST|default] [--source MANIFEST|default]

For each recording (judged by :func:`lmm.checks.recording_report`, the rules check-data applies to
source takes): the fraction of frames with both toes more than 15 cm above the floor and the longest such
stretch, T-pose frames (both hands within 25 cm of shoulder height and more than 1.2 m apart) and the
fraction of ground-level toe frames faster than 30 cm/s. ``--source`` prints the same numbers for the
used ranges of a manifest's takes (their own ground level). ``--idle`` drives the MM controller with
``builtin:strafe`` (it stands still for 4 s of every 20) and reports which fraction of the frames played
3 s or more after the stick was released lie in an idle-tagged range.
"""
from __future__ import annotations

import argparse
import json



def _manifest(arg):
    from lmm import DEFAULT_MANIFEST
    return DEFAULT_MANIFEST if arg in (None, "default") else arg


def source_report(manifest_path) -> dict:
    from lmm.data import bvh
    from lmm.checks import motion_report, source_fps
    from lmm.data.manifest import load_manifest

    m = load_manifest(manifest_path)
    totals = {"frames": 0, "airborne_frames": 0, "tpose_frames": 0, "ground_steps": 0, "ground_skating_steps": 0}
    for clip in m.clips:
        anim = bvh.load(clip.file)
        g = anim.global_positions() * m.unit_scale
        for a, b in clip.ranges or [(0, anim.n_frames)]:
            r = motion_report(g[a:b], anim.names, source_fps(anim.frame_time), m.bones, ground_m=None)
            for k in totals:
                totals[k] += r[k]
    totals["airborne_fraction"] = totals["airborne_frames"] / max(totals["frames"], 1)
    totals["ground_toe_fast_fraction"] = totals["ground_skating_steps"] / max(totals["ground_steps"], 1)
    return totals


def idle_report(manifest_path, controller: str = "mm", input_spec: str = "builtin:strafe",
                seconds: float = 120.0) -> dict:
    """Which fraction of the ticks played 3 s or more after the stick was released lie in an idle-tagged
    range (MM: the frame it plays; LMM: whether an idle-tagged frame is (one of) the database frames
    nearest its state's features; the default data's idle ranges repeat standing stretches of locomotion
    ranges, so a standing pose has an idle-tagged and an untagged twin at the same distance)."""
    from lmm.data.build import load_or_build
    from lmm.data.inputs import open_input
    from lmm.factory import make_controller
    from lmm.features import build_features

    import numpy as np

    db, _ = load_or_build(manifest_path)
    features = build_features(db)
    c = make_controller(controller, db, features)
    c.reset()
    log, dt = open_input(input_spec, seconds), 1.0 / 60.0
    judged = idle = 0
    idle_mask = db.tag_mask("idle")
    for i in range(int(seconds / dt)):
        _, snap = c.step(log(i * dt), dt)
        if c.stick_released_s >= 3.0:
            judged += 1
            if controller == "mm":
                idle += "idle" in db.tags_of(snap.matched_frame)
            else:
                cost = np.sum((features.normalized - snap.current_features) ** 2, axis=1)
                idle += bool(cost[idle_mask].min() <= cost.min() + 1e-6)
    return {"controller": controller, "input": input_spec, "seconds": seconds,
            "ticks_3s_after_release": judged, "idle_tagged_fraction": idle / judged if judged else None,
            "idle_tags_in_database": "idle" in db.tag_names, "search_note": snap.search_note}


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("recordings", nargs="*", help="BVH recordings (lmm-studio run --record)")
    p.add_argument("--idle", metavar="MANIFEST", help="run the idle test on this manifest ('default': the shipped one)")
    p.add_argument("--source", metavar="MANIFEST", help="the same numbers over a manifest's used ranges")
    p.add_argument("--idle-controllers", default="mm", help="controllers of the idle test, e.g. mm,lmm")
    p.add_argument("--idle-input", default="builtin:strafe", help="input of the idle test (default builtin:strafe)")
    p.add_argument("--idle-seconds", type=float, default=120.0)
    args = p.parse_args()
    from lmm.checks import recording_report

    for path in args.recordings:
        r = recording_report(path)
        print(f"{path}: {r['seconds']:.0f} s; both toes > 15 cm: {100 * r['airborne_fraction']:.2f} % of frames, "
              f"longest {r['airborne_longest_s']:.2f} s, highest {100 * r['airborne_max_height_m']:.0f} cm; "
              f"T-pose frames: {r['tpose_frames']}; ground-level toe frames > 30 cm/s: "
              f"{100 * r['ground_toe_fast_fraction']:.1f} %")
    if args.source:
        r = source_report(_manifest(args.source))
        print(f"source ranges of {args.source}: {r['frames']} frames; both toes > 15 cm above the take's ground: "
              f"{100 * r['airborne_fraction']:.2f} %; T-pose frames: {r['tpose_frames']}; ground-level toe frames "
              f"> 30 cm/s: {100 * r['ground_toe_fast_fraction']:.1f} % (30 fps, per range)")
    if args.idle:
        for name in args.idle_controllers.split(","):
            r = idle_report(_manifest(args.idle), name, args.idle_input, args.idle_seconds)
            print(f"idle test on {args.idle}: " + json.dumps(r))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
