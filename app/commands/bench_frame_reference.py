"""Whole frames against the C++ reference, for ``lmm-studio bench``'s ``frame`` section (issue 38).

``frame_reference.cpp`` (its header comment lists what one C++ frame includes) runs motion matching and
learned motion matching frames on our database, features, networks, tuning and inputs, built with the
reference demo's flags (:data:`app.commands.cpp_reference.FLAGS`). :func:`measure_frames` alternates
rounds: one C++ run (an LMM pass, then an MM pass over the inputs), then our two controllers over the
same inputs; each round gives each controller's median and mean tick and its median tick among those
that searched (MM: the tick with a search; most ticks do not search), and the figures are the medians
over the rounds (ratios: the median of the rounds' ratios, each of two figures of the same minutes).
Before any figure counts, the C++ program's first searches are checked against an exact numpy search on
the same queries and its decoding of the start state against ours: the time is of the same work.
"""
from __future__ import annotations

import json
import struct
import subprocess
import tempfile
import time
from pathlib import Path

import numpy as np

from . import cpp_reference
from .cpp_reference import f32

SOURCE = Path(__file__).with_name("frame_reference.cpp")
#: the tuning fields the C++ frame reads, in the order of its TUNING enum
TUNING_FIELDS = ("simulation_velocity_halflife_s", "simulation_rotation_halflife_s", "stick_deadzone",
                 "run_forward_speed_m_s", "run_sideways_speed_m_s", "run_backwards_speed_m_s",
                 "walk_forward_speed_m_s", "walk_sideways_speed_m_s", "walk_backwards_speed_m_s",
                 "inertialization_halflife_s", "search_interval_s", "forced_search_threshold", "transition_cost",
                 "exclude_current_window_frames", "idle_delay_s", "adjustment_position_halflife_s",
                 "adjustment_rotation_halflife_s", "adjustment_max_speed_ratio", "clamp_max_distance_m",
                 "clamp_max_angle_deg", "ik_unlock_radius_m", "ik_blend_halflife_s", "ik_foot_height_m")


def frame_inputs(ticks: int, dt: float = 1.0 / 60.0) -> list:
    """``ticks`` inputs: 10 s of each built-in scenario in turn (as the bench's runs take them)."""
    from lmm.data.inputs import builtin, builtin_names

    names = builtin_names((1, 2))
    logs = {n: builtin(n, 3600.0) for n in names}
    chunk, out = int(round(10.0 / dt)), []
    while len(out) < ticks:
        k = len(out) // (chunk * len(names))
        for n in names:
            out += [logs[n].at(i * dt) for i in range(k * chunk, (k + 1) * chunk)]
    return out[:ticks]


def search_sets(mm) -> tuple:
    """(per-frame bias, candidate mask, idle-set mask) of a motion matching controller's tuning, as its
    searches use them (the idle set: the idle-tagged candidates; all candidates without any, or with the
    idle set off)."""
    from lmm.tuning import IDLE_TAG

    bias = np.zeros(mm.db.n_frames, np.float32)
    mask = np.zeros(mm.db.n_frames, bool)
    for b, m in mm.tag_groups():
        bias[m] = b
        mask |= m
    idle = mask & mm.db.tag_mask(IDLE_TAG)
    return bias, mask, idle if idle.any() and mm.tuning.idle_set_enabled else mask


def write_frame_file(path, mm, nets, inputs) -> None:
    """The C++ frame's input file (layout: the header comment of ``frame_reference.cpp``)."""
    from lmm.mm import default_start_frame
    from lmm.nn import pose_vector_slices
    from lmm.source_pose import root_local_velocities

    db, feats, tun = mm.db, mm.features, mm.tuning
    i32 = struct.Struct("<i").pack
    pos, rot = db.positions.astype(np.float32), db.rotations.astype(np.float32)
    vel, ang = db.velocities.astype(np.float32), db.angular_velocities.astype(np.float32)
    root_vel, root_ang = root_local_velocities(db)
    pos[:, 0], rot[:, 0], vel[:, 0], ang[:, 0] = 0.0, (1.0, 0.0, 0.0, 0.0), root_vel, root_ang
    bias, mask, idle = search_sets(mm)
    stops = np.asarray(db.range_stop_of(np.arange(db.n_frames)), np.int32)
    dims, picks = mm._query_columns
    dims = np.arange(feats.n_dims)[dims]
    slices = pose_vector_slices(db.n_bones)
    ins = np.array([[i.left_x, i.left_y, i.right_x, i.right_y, float(i.walk), float(i.strafe), i.camera_azimuth]
                    for i in inputs], np.float32)
    parts = [b"LMMFR1", i32(db.n_bones), np.asarray(db.parents, "<i4").tobytes(),
             np.asarray(mm.leg_chains, "<i4").tobytes(), i32(db.n_frames), i32(feats.n_dims),
             f32(pos), f32(rot), f32(vel), f32(ang), np.asarray(db.contacts, np.uint8).tobytes(),
             f32(feats.normalized), f32(feats.mean), f32(feats.inv_scale), f32(bias),
             mask.astype(np.uint8).tobytes(), idle.astype(np.uint8).tobytes(), stops.astype("<i4").tobytes(),
             i32(len(mm.traj_offsets)), np.asarray(mm.traj_offsets, "<i4").tobytes(), i32(len(picks)),
             np.array([[d, *p] for d, p in zip(dims, picks)], "<i4").tobytes(),
             f32(nets.feature_mean), f32(nets.feature_inv_scale),
             np.array([slices[k].start for k in ("positions", "rotations", "velocities", "angular_velocities",
                                                  "root_velocity", "root_angular_velocity", "contacts")],
                      "<i4").tobytes(),
             i32(default_start_frame(db))]
    parts += cpp_reference.network_blocks(
        {n: getattr(nets, n) for n in ("decompressor", "stepper", "projector")},
        {n: np.zeros((1, getattr(nets, n).n_in), np.float32) for n in ("decompressor", "stepper", "projector")})
    parts += [i32(len(ins)), f32(ins), i32(len(TUNING_FIELDS)), f32([float(getattr(tun, f)) for f in TUNING_FIELDS])]
    Path(path).write_bytes(b"".join(parts))


def check_output(out: dict, mm, nets) -> str:
    """"" when the C++ frame did our work: each search it reports chose a frame whose cost is the exact
    least (numpy over every candidate, the rules of :mod:`lmm.search`), and its decoding of the start
    state gives our rotations; else the first difference, one line."""
    from lmm.pose_decoding import PoseDecoder

    X = mm.features.normalized
    bias, mask, idle = search_sets(mm)
    window, tc = int(mm.tuning.exclude_current_window_frames), np.float32(mm.tuning.transition_cost)
    for s in out["searches"]:
        q, cur, best = np.asarray(s["query"], np.float32), int(s["current"]), int(s["best"])
        allowed = idle if s["idle"] else mask
        d = X - q
        costs = np.einsum("ij,ij->i", d, d) + bias
        pool = np.where(allowed, costs + tc, np.inf)
        pool[max(cur - window, 0):cur + window + 1] = np.inf
        if allowed[cur]:
            pool[cur] = costs[cur]
        if not np.isfinite(pool[best]) or pool[best] > pool.min() + 1e-4 * (1.0 + abs(pool.min())):
            return f"the C++ search chose frame {best} (cost {pool[best]:.6g}), the least is {pool.min():.6g}"
    state = np.asarray(out["start_state"], np.float32)
    ours = PoseDecoder(mm.db.n_bones)(nets.decompressor(state[None])[0]).rotations
    theirs = np.asarray(out["start_rotations"])
    err = float(np.max(1.0 - np.abs(np.sum(ours * theirs, axis=1))))
    return "" if err < 1e-4 else f"the C++ decoding of the start state differs from ours (1 - |dot| up to {err:.3g})"


def _jumped(controller, snap) -> bool:
    """The tick's pose source jumped and an inertialization started, as a C++ jump: MM's
    ``transitioned``; LMM's decompressor call on a taken projection (its ``transitioned`` is narrower: a
    jump that does not continue the matched frame, see :mod:`lmm.learned`)."""
    if controller.name == "lmm":
        return "decompressor_transition" in snap.timings_us
    return bool(snap.transitioned)


def _our_pass(controller, inputs, dt: float) -> dict:
    """A pass of ours over ``inputs`` from a reset, with the figures a C++ pass reports."""
    controller.reset()
    us, searched, jumps = [], [], 0
    for inp in inputs:
        t0 = time.perf_counter()
        _, snap = controller.step(inp, dt)
        us.append((time.perf_counter() - t0) * 1e6)
        if snap.searched:
            searched.append(us[-1])
        jumps += _jumped(controller, snap)
    return {"median_us": float(np.median(us)), "mean_us": float(np.mean(us)),
            "searching_us": float(np.median(searched)) if searched else 0.0, "searches": len(searched), "jumps": jumps}


def measure_frames(mm, lmm, inputs, cache_dir, rounds: int = 5) -> tuple[dict | None, str]:
    """(figures, "") from ``rounds`` alternating rounds of the C++ frames and ours (``mm`` and ``lmm``
    controllers, reset each round) over ``inputs`` at 60 Hz, or (None, a one-line reason)."""
    try:
        exe = cpp_reference.build(cache_dir, SOURCE)
        runs = {"cpp_mm": [], "cpp_lmm": [], "mm": [], "lmm": []}
        with tempfile.TemporaryDirectory(prefix="lmm-frames-") as tmp:
            data = Path(tmp) / "frames.bin"
            write_frame_file(data, mm, lmm.nets, inputs)
            for r in range(rounds):
                proc = subprocess.run([str(exe), str(data), "1"], capture_output=True, text=True, timeout=300)
                if proc.returncode != 0:
                    return None, f"{exe.name}: {(proc.stderr.strip().splitlines() or ['failed'])[0][:200]}"
                out = json.loads(proc.stdout)
                if r == 0:
                    why = check_output(out, mm, lmm.nets)
                    if why:
                        return None, why
                for name in ("mm", "lmm"):
                    runs["cpp_" + name].append({k: v[0] for k, v in out[name].items()})
                runs["mm"].append(_our_pass(mm, inputs, 1.0 / 60.0))
                runs["lmm"].append(_our_pass(lmm, inputs, 1.0 / 60.0))
    except (OSError, RuntimeError, ValueError, KeyError, TypeError, subprocess.SubprocessError) as e:
        return None, str(e)
    fig = {"frame_rounds": rounds, "frame_ticks": len(inputs)}
    for name, per_round in runs.items():
        for stat, key in (("median_us", "frame_us"), ("mean_us", "frame_mean_us"),
                          ("searching_us", "frame_searching_us")):
            fig[f"{name}_{key}"] = float(np.median([r[stat] for r in per_round]))
        fig[f"{name}_frame_searches"] = int(per_round[0]["searches"])
        fig[f"{name}_frame_jumps"] = int(per_round[0]["jumps"])
    for name in ("mm", "lmm"):
        for stat, key in (("median_us", "frame"), ("mean_us", "frame_mean"), ("searching_us", "frame_searching")):
            fig[f"{name}_{key}_over_cpp"] = float(np.median(
                [o[stat] / c[stat] for o, c in zip(runs[name], runs["cpp_" + name])]))
    return fig, ""
