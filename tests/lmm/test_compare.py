"""DTW-aligned comparison of two motions (lmm.compare, ``lmm-studio compare``)."""
import subprocess
import sys

import numpy as np
import pytest

from lmm.compare import CompareError, compare_motions, dtw_align, dtw_reference, motion_from_animation, \
    resample_motion
from lmm.data import bvh

AXIS = (0.0, 1.0, 0.0)  # LAFAN1 hips forward axis (the shipped manifest's)


@pytest.fixture(scope="module")
def take():
    from lmm import DEFAULT_MANIFEST
    from lmm.data.manifest import load_manifest
    clip = load_manifest(DEFAULT_MANIFEST).clips[0]
    return clip.file, bvh.load(clip.file)


@pytest.fixture(scope="module")
def motion(take):
    path, anim = take
    return motion_from_animation(anim, "A", frames=(1200, 1500), hips_forward_axis=AXIS)


@pytest.mark.parametrize("seed", range(40))
def test_dtw_equals_the_plain_double_loop(seed):
    rng = np.random.default_rng(seed)
    n, m = (int(x) for x in rng.integers(1, 14, 2))
    cost = rng.random((n, m))
    window = [None, 1, 2, 4][seed % 4]
    value, path = dtw_align(lambda i, lo, hi: cost[i, lo:hi], n, m, window)
    assert abs(value - dtw_reference(cost, window)) < 1e-6
    # the path is connected, monotone, from corner to corner, and its cost is the value
    assert tuple(path[0]) == (0, 0) and tuple(path[-1]) == (n - 1, m - 1)
    steps = np.diff(path, axis=0)
    assert np.all((steps >= 0) & (steps <= 1)) and np.all(steps.sum(axis=1) >= 1)
    assert abs(cost[path[:, 0], path[:, 1]].sum() - value) < 1e-9


def test_a_motion_against_itself_is_zero(motion):
    r = compare_motions(motion, motion)
    assert r["rotation_error_rad"] < 1e-12           # 0 up to rounding (~1e-17)
    assert r["dtw_value"] < 1e-4                     # the alignment's cheap cost: acos of rounded dots
    assert r["position_error_cm"] == {"root_relative": 0.0, "world": 0.0} and not r["world_aligned_at_start"]
    assert len(r["path"]) == r["frames"][0]


def test_time_warped_copy_is_close_and_a_shifted_one_is_not(motion, take):
    n = len(motion.rotations)
    idx = np.minimum(np.rint(np.arange(int(n * 1.25)) / 1.25).astype(int), n - 1)   # 1.25x, nearest frame
    warped = type(motion)("B", motion.joints, motion.rotations[idx], motion.world_cm[idx], motion.local_cm[idx],
                          motion.fps)
    r = compare_motions(motion, warped)
    assert r["rotation_error_rad"] < 0.02 and r["frames"] == [n, len(idx)]
    # frame by frame without warping the two are far apart: DTW is doing the work
    from lmm.compare import geodesic
    straight = geodesic(motion.rotations, warped.rotations[:n]).mean()
    assert straight > 5 * r["rotation_error_rad"] + 0.01
    # another stretch of the take is a different pose sequence
    path, anim = take
    other = motion_from_animation(anim, "C", frames=(2200, 2500), hips_forward_axis=AXIS)
    assert compare_motions(motion, other)["rotation_error_rad"] > 0.05


def test_frame_rates_are_matched(motion):
    half = resample_motion(motion, motion.fps / 2)
    assert len(half.rotations) == (len(motion.rotations) - 1) // 2 + 1
    r = compare_motions(motion, half)
    assert r["resampled_to_fps"] == motion.fps / 2 and r["rotation_error_rad"] < 0.02


def test_other_skeleton_or_empty_range_is_one_line(take, motion, tmp_path):
    path, anim = take
    fewer = type(motion)("D", motion.joints[:-1], motion.rotations[:, :-1], motion.world_cm[:, :-1],
                         motion.local_cm[:, :-1], motion.fps)
    with pytest.raises(CompareError, match="different skeletons"):
        compare_motions(motion, fewer)
    with pytest.raises(CompareError, match="frames 7:7"):
        motion_from_animation(anim, "A", frames=(7, 7))
    other = tmp_path / "other.bvh"
    other.write_text("HIERARCHY\nROOT Hips\n{\n OFFSET 0 0 0\n CHANNELS 6 Xposition Yposition Zposition Zrotation "
                     "Yrotation Xrotation\n End Site\n {\n  OFFSET 0 10 0\n }\n}\nMOTION\nFrames: 4\n"
                     "Frame Time: 0.0333333\n" + "0 90 0 0 0 0\n" * 4)
    r = subprocess.run([sys.executable, "-m", "app.cli", "compare", str(path), str(other)], capture_output=True,
                       text=True)
    lines = r.stderr.strip().splitlines()
    assert r.returncode == 1 and len(lines) == 1 and "other.bvh" in lines[0] and "skeletons" in lines[0], r.stderr


def test_a_rigidly_moved_copy_is_zero_in_the_world_once_the_starts_are_aligned(take):
    from lmm import quat
    from lmm.compare import motion_from_arrays

    path, anim = take
    g_rot, g_pos = anim.global_transforms()
    a, b = 1200, 1400
    yaw = quat.from_axis_angle(np.array([0.0, 1.0, 0.0]), np.array(2.0))
    moved_pos = quat.mul_vec(yaw, g_pos[a:b]) + np.array([300.0, 0.0, -200.0])
    first = motion_from_arrays("A", list(anim.names), anim.local_rotations()[a:b], g_rot[a:b], g_pos[a:b], 30.0, AXIS)
    moved = motion_from_arrays("B", list(anim.names), anim.local_rotations()[a:b], quat.mul(yaw, g_rot[a:b]),
                               moved_pos, 30.0, AXIS)
    aligned = compare_motions(first, moved, align_start=True)
    assert aligned["world_aligned_at_start"] and aligned["position_error_cm"]["world"] < 1e-6
    assert compare_motions(first, moved)["position_error_cm"]["world"] > 100.0


def test_compare_of_a_run_against_the_take_it_was_derived_from_aligns_the_starts(take, tmp_path):
    """input-from turns a take's root path into an input log; the run it drives starts at the origin, the
    take 10 m away: aligned at the start the world error is the motion's, --no-align keeps the offset."""
    import json

    from app.cli import main

    path, _ = take
    log, run, out = tmp_path / "in.csv", tmp_path / "run.bvh", tmp_path / "c.json"
    assert main(["input-from", str(path), "--frames", "1200:1500", "--out", str(log)]) == 0
    assert main(["run", "--controller", "mm", "--input", str(log), "--record", str(run), "--quiet"]) == 0
    assert main(["compare", str(path), str(run), "--frames-a", "1200:1500", "--json", str(out)]) == 0
    aligned = json.loads(out.read_text())
    assert main(["compare", str(path), str(run), "--frames-a", "1200:1500", "--no-align", "--json", str(out)]) == 0
    unaligned = json.loads(out.read_text())
    assert aligned["world_aligned_at_start"] and not unaligned["world_aligned_at_start"]
    assert aligned["position_error_cm"]["world"] < 40.0 < 200.0 < unaligned["position_error_cm"]["world"]
    assert aligned["position_error_cm"]["root_relative"] == unaligned["position_error_cm"]["root_relative"]
