"""The player's unit-free sizing and its playback clock (no window)."""
import numpy as np
import pytest

from viewer.player import AnimationView, Playback, measure
from viewer_testutil import TPOSE_PARENTS, TPOSE_POSITIONS


def walking(frames=90, scale=1.0, floor=0.0):
    t = np.arange(frames) / 30.0
    pos = np.repeat(TPOSE_POSITIONS[None], frames, axis=0).copy()
    pos[..., 0] += 1.2 * t[:, None]
    pos[..., 1] += 0.02 * np.sin(8 * t)[:, None]
    pos[..., 1] += floor - 0.05  # the toes of TPOSE sit at y=0.07 (joint centres): floor a bit below
    return pos * scale


@pytest.mark.parametrize("scale", [1.0, 100.0, 39.37, 0.01])
def test_measure_scales_with_units(scale):
    props = measure(walking(scale=scale))
    assert props.height == pytest.approx(1.68 * scale, rel=0.05)
    assert props.unit_scale == pytest.approx(scale, rel=0.05)
    assert props.floor == 0.0   # close to the file origin: the origin is the floor


def test_measure_finds_a_raised_floor():
    props = measure(walking(floor=2.0))
    assert props.floor == pytest.approx(2.02, abs=0.05)
    assert props.lift(props.floor + props.root_height + 0.01) == 0.0       # walking bob: no lift
    assert props.lift(props.floor + props.root_height + 1.0) > 0.5         # on a box: lift


def test_animation_view_radii_and_camera_follow_scale(gl_ctx):
    small = AnimationView(gl_ctx, TPOSE_PARENTS, walking(scale=1.0))
    big = AnimationView(gl_ctx, TPOSE_PARENTS, walking(scale=100.0))
    assert big.skeleton.joint_radius == pytest.approx(100 * small.skeleton.joint_radius, rel=0.05)
    assert big.camera.distance == pytest.approx(100 * small.camera.distance, rel=0.05)
    assert big.ground.tile_m == pytest.approx(100 * small.ground.tile_m, rel=0.05)
    big.set_frame(60)
    assert big.camera.target[[0, 2]] == pytest.approx(big.positions[60, 0, [0, 2]], abs=1e-3)
    big.follow = False
    target = big.camera.target.copy()
    big.set_frame(10)
    assert np.allclose(big.camera.target, target)
    with pytest.raises(ValueError):
        AnimationView(gl_ctx, TPOSE_PARENTS, np.zeros((0, 16, 3)))
    small.scene.release()
    big.scene.release()


def test_playback_clock():
    pb = Playback(n_frames=10, frame_time=0.1)
    assert pb.advance(0.25) == 2
    assert pb.advance(0.8) == 0          # loops
    pb.faster()
    assert pb.speed == 2.0
    assert pb.advance(0.1) == 2
    pb.slower()
    pb.slower()
    assert pb.speed == 0.5
    assert pb.step(-3) == 9 and pb.paused
    assert pb.advance(1.0) == 9          # paused: time stands still
    pb.seek(12)
    assert pb.frame == 2
    for _ in range(20):
        pb.faster()
    assert pb.speed == pb.speeds[-1]
