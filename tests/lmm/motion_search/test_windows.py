"""The pose-window representation of motion search by example (lmm.motion_search.windows)."""
import numpy as np
import pytest

from lmm.data import bvh
from lmm.motion_search import windows as W


@pytest.fixture(scope="module")
def take():
    from lmm import DEFAULT_MANIFEST
    from lmm.data.manifest import load_manifest
    clip = load_manifest(DEFAULT_MANIFEST).clips[0]
    anim = bvh.load(clip.file)
    keys = W.match_key_joints(anim.names)
    g = anim.global_positions()[:600]
    return g[:, [keys[k] for k in W.KEY_JOINTS]], 1.0 / anim.frame_time


def _yaw(points, angle):
    c, s = np.cos(angle), np.sin(angle)
    out = points.copy()
    out[..., 0] = c * points[..., 0] + s * points[..., 2]
    out[..., 2] = -s * points[..., 0] + c * points[..., 2]
    return out


def test_features_do_not_depend_on_place_heading_or_size(take):
    kp, fps = take
    f = W.frame_features(kp, fps)
    moved = _yaw(kp, 1.1) * 1.7 + np.array([300.0, 0.0, -120.0])
    g = W.frame_features(moved, fps)
    assert f.shape == (len(kp), W.FRAME_DIM)
    np.testing.assert_allclose(f, g, atol=1e-3)


def test_mirror_is_an_involution_and_matches_the_mirrored_motion(take):
    kp, fps = take
    f = W.frame_features(kp, fps)
    np.testing.assert_array_equal(W.mirror_frames(W.mirror_frames(f)), f)
    flipped = kp.copy()
    flipped[..., 0] *= -1.0                       # reflect the world in x ...
    flipped = flipped[:, [0, 1, 3, 2, 5, 4]]      # ... and the left joints are now the right ones
    np.testing.assert_allclose(W.frame_features(flipped, fps), W.mirror_frames(f), atol=1e-3)
    assert not np.allclose(W.mirror_frames(f), f, atol=1e-2)


def test_resample_and_windows_and_frame_numbers():
    x = np.arange(61, dtype=np.float32)[:, None] * np.ones((1, W.FRAME_DIM), np.float32)
    r = W.resample(x, 60.0, 30.0)
    assert len(r) == 31 and r[-1, 0] == 60.0 and r[1, 0] == 2.0
    w = W.windows(r, 8, stride=2)
    assert w.shape == (12, 8, W.FRAME_DIM) and w[1, 0, 0] == 4.0
    assert W.window_start_frames(np.array([0, 5]), 60.0).tolist() == [0, 10]
    assert W.windows(r[:5], 8).shape[0] == 0


def test_key_joints_matched_by_name_or_listed_missing():
    names = ["mixamorig:Hips", "mixamorig:Head", "mixamorig:LeftHand", "mixamorig:RightHand",
             "mixamorig:LeftFoot", "mixamorig:RightFoot"]
    assert W.match_key_joints(names) == {k: i for i, k in enumerate(W.KEY_JOINTS)}
    assert W.match_key_joints(["pelvis", "head", "l_wrist", "r_wrist", "l_ankle", "r_ankle"])["left_hand"] == 2
    with pytest.raises(W.SkeletonMatchError, match=r"robot\.bvh: cannot match the key joints left_hand, right_hand"):
        W.match_key_joints(["Hips", "Head", "LeftFoot", "RightFoot"], "robot.bvh")


def test_take_frames_refuses_an_empty_or_outside_range(take):
    from lmm.errors import InputError
    from lmm import DEFAULT_MANIFEST
    from lmm.data.manifest import load_manifest
    anim = bvh.load(load_manifest(DEFAULT_MANIFEST).clips[0].file)
    t = W.take_frames(anim, "a.bvh", (100, 400))
    assert t.n_file_frames == 300 and abs(len(t.frames) - 300 * W.WINDOW_FPS * anim.frame_time) <= 1
    for bad in ((5, 5), (0, anim.n_frames + 1), (-1, 10)):
        with pytest.raises(InputError, match=r"a\.bvh: frames"):
            W.take_frames(anim, "a.bvh", bad)


def test_knn_equals_brute_force_and_features_embedder_shape():
    from lmm.motion_search.embed import FeatureEmbedder, knn
    rng = np.random.default_rng(3)
    db = rng.normal(size=(1000, 12)).astype(np.float32)
    q = rng.normal(size=(7, 12)).astype(np.float32)
    idx, dist = knn(db, q, 5, chunk=128)
    full = np.linalg.norm(q[:, None] - db[None], axis=2)
    np.testing.assert_array_equal(idx, np.argsort(full, axis=1)[:, :5])
    np.testing.assert_allclose(dist, np.sort(full, axis=1)[:, :5], rtol=1e-4, atol=1e-4)
    e = FeatureEmbedder(step=4).fit(rng.normal(size=(100, W.FRAME_DIM)))
    out = e.embed(rng.normal(size=(3, W.WINDOW_FRAMES, W.FRAME_DIM)).astype(np.float32))
    assert out.shape == (3, e.dim) and out.dtype == np.float32
