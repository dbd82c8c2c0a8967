"""Physics plausibility (lmm.physics, ``lmm-studio physics``) on files the tests make from a shipped
walking range: the real walk needs little root residual force, the same walk raised 50 cm (no contact
possible) needs about its weight, lowered 10 cm it penetrates the floor; bad skeletons get one line."""
import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from lmm.data import bvh

ROOT = Path(__file__).resolve().parents[3]
TAKE = ROOT / "lmm/data/lafan1/multipleActions1_subject1.bvh.gz"
WALK = (545, 645)          # a walking range of the shipped manifest (file frames, 30 fps, centimetres)


@pytest.fixture(scope="module")
def walk():
    return bvh.load(TAKE).slice(*WALK)


def shifted(anim, dy_cm):
    out = anim.slice(0, anim.n_frames)
    out.motion[:, anim.channel_columns(0)[1]] += dy_cm    # the hips' Yposition
    return out


def run_cli(*args):
    return subprocess.run([sys.executable, "-m", "app.cli", "physics", *map(str, args)], cwd=ROOT,
                          capture_output=True, text=True, timeout=300)


@pytest.fixture(scope="module")
def files(walk, tmp_path_factory):
    d = tmp_path_factory.mktemp("physics")
    out = {}
    for name, dy in (("walk", 0.0), ("raised", 50.0), ("lowered", -10.0)):
        bvh.save(d / f"{name}.bvh", shifted(walk, dy))
        out[name] = d / f"{name}.bvh"
    return out


def analyse(path, tmp_path):
    pytest.importorskip("mujoco")
    out = tmp_path / (Path(path).stem + ".json")
    r = run_cli(path, "--json", out)
    assert r.returncode == 0, r.stderr
    return json.loads(out.read_text())


def test_walk_needs_little_root_force(files, walk, tmp_path):
    data = analyse(files["walk"], tmp_path)
    assert len(data["residual_force_bw"]) == walk.n_frames
    assert len(data["penetration_cm"]["left"]) == walk.n_frames
    assert len(data["sliding_cm_s"]["right"]) == walk.n_frames
    assert np.median(data["residual_force_bw"]) < 0.3
    assert data["summary"]["residual_force_bw_median"] < 0.3


def test_raised_walk_needs_its_weight(files, tmp_path):
    data = analyse(files["raised"], tmp_path)
    r = np.array(data["residual_force_bw"])
    assert np.median(r) >= 0.8 and r.mean() >= 0.8
    assert not any(data["contact"]["left"]) and not any(data["contact"]["right"])
    assert max(data["penetration_cm"]["left"]) == 0.0


def test_lowered_walk_penetrates(files, tmp_path):
    low = analyse(files["lowered"], tmp_path)
    walk = analyse(files["walk"], tmp_path)
    assert low["summary"]["penetration_cm_mean"] > walk["summary"]["penetration_cm_mean"] + 5.0
    assert low["summary"]["penetration_cm_max"] >= 9.0


def test_standing_still_needs_nothing_and_floating_needs_weight(walk):
    pytest.importorskip("mujoco")
    from lmm.physics.body import body_for_animation
    from lmm.physics.plausibility import plausibility

    body, pos, rot, _ = body_for_animation(walk)
    # one pose held still, feet on the floor where the body says its soles are, over its feet
    f = 30
    still_pos, still_rot = np.repeat(pos[f:f + 1], 10, 0), np.repeat(rot[f:f + 1], 10, 0)
    soles = body.sole_points(still_pos, still_rot)
    still_pos = still_pos - np.array([0, soles[0, :, 1].min(), 0])
    r = plausibility(body, still_pos, still_rot, 30.0)
    assert r.contact.all(axis=1).any()
    assert np.median(r.residual_force_bw) < 0.05
    up = still_pos + np.array([0.0, 1.0, 0.0])
    r = plausibility(body, up, still_rot, 30.0)
    np.testing.assert_allclose(r.residual_force_bw, 1.0, atol=1e-6)


def test_body_masses_and_pose_map(walk):
    mujoco = pytest.importorskip("mujoco")
    from lmm.physics.body import body_for_animation

    body, pos, rot, scale = body_for_animation(walk, total_mass=80.0)
    assert scale == 0.01
    assert abs(float(body.model.body_mass.sum()) - 80.0) < 1e-6
    assert set(body.foot_geoms) == {"left", "right"} and all(len(g) == 2 for g in body.foot_geoms.values())
    data = mujoco.MjData(body.model)
    data.qpos[:] = body.qpos_from_pose(pos, rot)[40]
    mujoco.mj_kinematics(body.model, data)
    np.testing.assert_allclose(data.xpos[body.body_id[body.joints]], pos[40, body.joints], atol=1e-5)


def _no_feet(anim):
    anim.names = [n.replace("Foot", "Paw") for n in anim.names]


def _zero_length_leg(anim):
    anim.offsets[anim.names.index("LeftLeg")] = 0.0


@pytest.mark.parametrize("break_it, name, expected", [
    (_no_feet, "nofeet.bvh", ("left_foot", "nofeet.bvh")),
    (_zero_length_leg, "zero.bvh", ("LeftUpLeg -> LeftLeg", "zero length")),
])
def test_bad_skeleton_is_one_line_error(walk, tmp_path, break_it, name, expected):
    pytest.importorskip("mujoco")
    bad = walk.slice(0, 10)
    break_it(bad)
    path = tmp_path / name
    bvh.save(path, bad)
    r = run_cli(path)
    assert r.returncode == 1 and "Traceback" not in r.stderr and r.stderr.count("\n") == 1, r.stderr
    assert all(text in r.stderr for text in expected), r.stderr


def test_png(files, tmp_path):
    pytest.importorskip("mujoco")
    out = tmp_path / "walk.png"
    assert run_cli(files["walk"], "--png", out).returncode == 0
    from PIL import Image
    assert Image.open(out).size[0] == 1000


def test_nnls_matches_brute_force():
    from lmm.physics.plausibility import nnls

    rng = np.random.default_rng(3)
    for _ in range(20):
        A, b = rng.normal(size=(6, 9)), rng.normal(size=6)
        x = nnls(A, b)
        assert (x >= 0).all()
        # KKT: gradient non-negative where x = 0, zero where x > 0
        g = A.T @ (A @ x - b)
        assert np.all(g[x == 0] >= -1e-8) and np.allclose(g[x > 0], 0, atol=1e-8)


def test_missing_mujoco_is_one_line(tmp_path, files):
    from tests.app.commands.test_extras import assert_one_line_error, run_without

    r, _ = run_without(["mujoco"], "physics", str(files["walk"]), tmp_path=tmp_path)
    assert_one_line_error(r, "mujoco", "pip install -e '.[physics]'")
    from lmm.physics import PhysicsUnavailable, require_mujoco
    import sys as _sys
    saved = _sys.modules.get("mujoco")
    _sys.modules["mujoco"] = None
    try:
        with pytest.raises(PhysicsUnavailable, match=r"\.\[physics\]"):
            require_mujoco("the ragdoll")
    finally:
        if saved is None:
            del _sys.modules["mujoco"]
        else:
            _sys.modules["mujoco"] = saved
