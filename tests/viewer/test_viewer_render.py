"""Headless EGL rendering: a known pose, a trajectory, markers, ghosts and the readback paths.

Every test projects world points with the camera used to render and checks the pixels there;
images are saved under tests/viewer/_out/ for inspection.
"""
import numpy as np
import pytest
from PIL import Image

from viewer import Arrows, Ground, Lines, OrbitCamera, Renderer, Scene, Skeleton, Spheres
from viewer_testutil import (TPOSE_PARENTS, TPOSE_POSITIONS, colour_mask, mask_bbox, near_any,
                             segment_distance_map)

W, H = 640, 480
ORANGE = (0.95, 0.5, 0.1)
GREEN = (0.95, 0.85, 0.1)   # a trajectory colour (yellow: unlike the green Y axis)
MAGENTA = (0.9, 0.15, 0.75)
BLUE = (0.15, 0.4, 1.0)
OFFSET = np.array([1.5, 0.0, -1.0])  # away from the world axes at the origin


@pytest.fixture(scope="module")
def renderer(gl_ctx):
    r = Renderer(gl_ctx, W, H, samples=4)
    yield r
    r.release()


def camera_on(points):
    cam = OrbitCamera(yaw_deg=20.0, pitch_deg=12.0)
    cam.fit(points, aspect=W / H)
    return cam


def near_world_axes(cam, length=1.0, px=4):
    """Pixels within ``px`` of the ground's X/Y/Z axes (saturated colours of their own)."""
    axes = cam.project([[0, 0, 0], [length, 0, 0], [0, length, 0], [0, 0, length]], W, H)
    return segment_distance_map((H, W), np.array([[axes[0], axes[k]] for k in (1, 2, 3)])) < px


def bone_segments(cam, positions, parents):
    px = cam.project(positions, W, H)
    return np.array([[px[p], px[j]] for j, p in enumerate(parents) if p >= 0])


def test_known_pose_lands_on_skeleton_coloured_pixels(gl_ctx, renderer, out_dir):
    pose = TPOSE_POSITIONS + OFFSET
    scene = Scene()
    scene.add(Ground(gl_ctx))
    skel = scene.add(Skeleton(gl_ctx, TPOSE_PARENTS, color=ORANGE, joint_radius=0.03, bone_radius=0.02,
                              style="sticks"))
    skel.update(pose)
    cam = camera_on(pose)
    img = renderer.render(scene, cam)
    Image.fromarray(img).save(out_dir / "render_tpose.png")
    assert img.shape == (H, W, 4) and img.dtype == np.uint8

    mask = colour_mask(img, ORANGE)
    joints_px = cam.project(pose, W, H)
    for j, (x, y) in enumerate(joints_px):
        assert mask[int(y), int(x)], f"joint {j} at pixel {(int(x), int(y))} is {img[int(y), int(x)]}"

    # midpoints of the bones too
    segs = bone_segments(cam, pose, TPOSE_PARENTS)
    for a, b in segs:
        m = (a + b) / 2
        assert mask[int(m[1]), int(m[0])]

    # nothing orange far from the bones, and far pixels are grey ground/background
    dist = segment_distance_map((H, W), segs)
    joint_px_radius = 0.03 / np.tan(np.radians(cam.fov_y_deg) / 2) / cam.distance * H / 2 * 1.5
    assert not mask[dist > joint_px_radius + 3].any()
    far = img[(dist > 40) & ~near_world_axes(cam)][:, :3].astype(int)
    assert (far.max(axis=1) - far.min(axis=1)).max() < 40      # unsaturated: ground, grid, sky
    # the skeleton fills the frame the way fit() promised
    x0, y0, x1, y1 = mask_bbox(mask)
    assert 0 < x0 and x1 < W - 1 and 0 < y0 and y1 < H - 1
    assert (y1 - y0) > 0.4 * H


def test_ground_and_background(gl_ctx, renderer, out_dir):
    scene = Scene(background=(0.1, 0.2, 0.3))
    scene.add(Ground(gl_ctx, size_m=20.0, tile_m=1.0))
    cam = OrbitCamera(target=[0, 0, 0], distance=6.0, yaw_deg=30.0, pitch_deg=25.0)
    img = renderer.render(scene, cam)
    Image.fromarray(img).save(out_dir / "render_ground.png")
    assert np.allclose(img[2, W // 2, :3], np.array([0.1, 0.2, 0.3]) * 255, atol=2)  # sky is background
    # the floor under the target is a grey checker, two tile shades visible
    below = img[H // 2 + 20:, :, :3].reshape(-1, 3).astype(int)
    assert (below.max(axis=1) - below.min(axis=1) < 30).mean() > 0.9
    assert len(np.unique(below[:, 0] // 8)) >= 2
    # world axes at the origin: X red, Z blue near their projected midpoints
    px = cam.project([[0.5, 0, 0], [0, 0, 0.5], [0, 0.5, 0]], W, H)
    assert near_any(colour_mask(img, (0.9, 0.2, 0.2), min_sat=0.4), px[0], 2)
    assert near_any(colour_mask(img, (0.25, 0.45, 0.95), min_sat=0.4), px[1], 2)
    assert near_any(colour_mask(img, (0.25, 0.85, 0.3), min_sat=0.4), px[2], 2)


def test_trajectory_polyline_pixels(gl_ctx, renderer, out_dir):
    scene = Scene()
    scene.add(Ground(gl_ctx))
    t = np.linspace(0, np.pi, 9)
    traj = np.c_[2.0 + 1.2 * np.cos(t), np.zeros_like(t), 1.0 + 0.8 * np.sin(t)]
    line = scene.add(Lines(gl_ctx, color=GREEN, width_px=3.0))
    line.update(traj, mode="strip")
    cam = OrbitCamera(target=[2.0, 0.0, 1.2], distance=4.0, yaw_deg=15.0, pitch_deg=35.0)
    img = renderer.render(scene, cam)
    Image.fromarray(img).save(out_dir / "render_trajectory.png")
    mask = colour_mask(img, GREEN)
    mids = cam.project((traj[1:] + traj[:-1]) / 2, W, H)
    for m in mids:
        assert near_any(mask, m, 1), f"no line colour at {m}"
    # a 3 px line: thin, and only near the polyline
    dist = segment_distance_map((H, W), np.stack([cam.project(traj[:-1], W, H), cam.project(traj[1:], W, H)], 1))
    assert not mask[(dist > 4) & ~near_world_axes(cam)].any()
    assert mask[dist < 0.7].mean() > 0.9

    # segments mode and per-point colours
    line.update(np.r_[traj[:2], traj[4:6]], mode="segments", colors=np.array([GREEN, GREEN, MAGENTA, MAGENTA]))
    img = renderer.render(scene, cam)
    m01 = cam.project([(traj[0] + traj[1]) / 2, (traj[4] + traj[5]) / 2, (traj[2] + traj[3]) / 2], W, H)
    assert near_any(colour_mask(img, GREEN), m01[0], 1)
    assert near_any(colour_mask(img, MAGENTA), m01[1], 1)
    assert not near_any(colour_mask(img, GREEN) | colour_mask(img, MAGENTA), m01[2], 1)   # gap: not drawn


def test_line_crossing_the_near_plane_is_clipped_not_lost(gl_ctx, renderer):
    scene = Scene()
    line = scene.add(Lines(gl_ctx, color=GREEN, width_px=4.0))
    cam = OrbitCamera(target=[0, 0, 0], distance=3.0, yaw_deg=0.0, pitch_deg=0.0)
    line.update([[0.3, 0.0, -2.0], [0.3, 0.0, 10.0]])   # ends behind the eye (eye at z=3)
    img = renderer.render(scene, cam)
    assert near_any(colour_mask(img, GREEN), cam.project([[0.3, 0.0, -1.0]], W, H)[0], 1)


def test_spheres_and_arrows(gl_ctx, renderer, out_dir):
    scene = Scene()
    scene.add(Ground(gl_ctx))
    centers = np.array([[x, 0.1, z] for x in (-1.0, 0.0, 1.0) for z in (-0.5, 0.5)]) + [0.3, 0, 0.2]
    spheres = scene.add(Spheres(gl_ctx, radius=0.08))
    colors = np.array([MAGENTA, BLUE] * 3)
    spheres.update(centers, colors=colors)
    arrows = scene.add(Arrows(gl_ctx, color=ORANGE, shaft_radius=0.02, head_radius=0.05, head_length=0.15))
    origins = np.array([[-1.0, 0.5, 0.0], [1.0, 0.5, 0.0]])
    dirs = np.array([[0.0, 0.0, 0.8], [0.6, 0.0, -0.4]])
    arrows.update(origins, dirs)
    cam = OrbitCamera(target=[0, 0.3, 0], distance=4.0, yaw_deg=20.0, pitch_deg=40.0)
    img = renderer.render(scene, cam)
    Image.fromarray(img).save(out_dir / "render_markers.png")
    px = cam.project(centers, W, H)
    for c, (x, y) in zip(colors, px):
        assert colour_mask(img, c)[int(y), int(x)]
    orange = colour_mask(img, ORANGE)
    for p in cam.project(np.r_[origins + 0.4 * dirs, origins + 0.93 * dirs], W, H):  # shaft and head
        assert near_any(orange, p, 1)
    # one radius for all, then per-sphere radii: a big sphere covers more pixels
    spheres.update(centers[:1], radii=[0.3], colors=MAGENTA)
    big = colour_mask(renderer.render(scene, cam), MAGENTA).sum()
    spheres.update(centers[:1], radii=0.1, colors=MAGENTA)
    small = colour_mask(renderer.render(scene, cam), MAGENTA).sum()
    assert big > 5 * small > 0


def test_ghost_skeleton_blends_over_the_scene(gl_ctx, renderer, out_dir):
    pose = TPOSE_POSITIONS + OFFSET
    ghost_pose = pose + [0.0, 0.0, 0.6]
    scene = Scene()
    scene.add(Ground(gl_ctx))
    # no shadows here: the ghost's own (fainter) shadow would change the background it blends over
    solid = scene.add(Skeleton(gl_ctx, TPOSE_PARENTS, color=ORANGE, shadow=False))
    solid.update(pose)
    ghost = scene.add(Skeleton(gl_ctx, TPOSE_PARENTS, color=BLUE, alpha=0.5, shadow=False))
    ghost.update(ghost_pose)
    cam = camera_on(np.r_[pose, ghost_pose])
    blended = renderer.render(scene, cam).astype(float)
    Image.fromarray(blended.astype(np.uint8)).save(out_dir / "render_ghost.png")
    ghost.alpha = 1.0
    opaque = renderer.render(scene, cam).astype(float)
    ghost.visible = False
    behind = renderer.render(scene, cam).astype(float)
    px = cam.project(ghost_pose, W, H).astype(int)
    for x, y in px:
        expected = 0.5 * opaque[y, x, :3] + 0.5 * behind[y, x, :3]
        assert np.abs(blended[y, x, :3] - expected).max() <= 6, (blended[y, x], expected)
        assert blended[y, x, 3] == 255   # the image stays opaque
    # where the ghost passes in front of the solid skeleton, the orange shows through
    assert colour_mask(behind.astype(np.uint8), ORANGE).sum() > 0
    ghost.visible = True
    ghost.alpha = 0.5
    assert ghost.transparent and scene.draw_order()[-1] is ghost


def test_float_readback_unflipped_and_render_to_target(gl_ctx, renderer):
    scene = Scene()
    skel = scene.add(Skeleton(gl_ctx, TPOSE_PARENTS, color=ORANGE))
    skel.update(TPOSE_POSITIONS)
    cam = camera_on(TPOSE_POSITIONS)
    u8 = renderer.render(scene, cam)
    # dearpygui-style: a float32 texture array filled in place, rows bottom-up
    tex = np.zeros(W * H * 4, dtype=np.float32)
    out = renderer.render(scene, cam, dtype=np.float32, out=tex, flip=False)
    assert np.shares_memory(out, tex)
    assert np.abs(tex.reshape(H, W, 4)[::-1] * 255 - u8).max() <= 1
    # resolve into someone else's framebuffer (a window's screen, a studio texture)
    target_tex = gl_ctx.texture((W, H), 4)
    target = gl_ctx.framebuffer(color_attachments=[target_tex])
    renderer.render_to(scene, cam, target=target)
    got = np.frombuffer(target.read(components=4), dtype=np.uint8).reshape(H, W, 4)[::-1]
    assert np.array_equal(got, u8)
    target.release()
    target_tex.release()


def test_previous_framebuffer_is_bound_again(gl_ctx, renderer):
    other_tex = gl_ctx.texture((32, 32), 4)
    other = gl_ctx.framebuffer(color_attachments=[other_tex])
    other.use()
    renderer.render_to(Scene(), OrbitCamera())
    assert gl_ctx.fbo is other
    other.release()
    other_tex.release()


def test_resize_and_no_msaa(gl_ctx):
    r = Renderer(gl_ctx, 100, 80, samples=0)
    scene = Scene()
    skel = scene.add(Skeleton(gl_ctx, TPOSE_PARENTS, color=ORANGE))
    skel.update(TPOSE_POSITIONS)
    cam = camera_on(TPOSE_POSITIONS)
    assert r.render(scene, cam).shape == (80, 100, 4)
    r.resize(200, 120)
    img = r.render(scene, cam)
    assert img.shape == (120, 200, 4)
    assert colour_mask(img, ORANGE).any()
    r.release()


def test_buffers_grow_and_shrink_without_new_objects(gl_ctx, renderer):
    scene = Scene()
    line = scene.add(Lines(gl_ctx, color=GREEN))
    buffer = line._buf.buffer
    for n in (2, 5000, 3, 0, 800):
        line.update(np.c_[np.linspace(0, 1, n), np.zeros(n), np.zeros(n)])
        renderer.render_to(scene, OrbitCamera())
        assert line._buf.count == max(n - 1, 0)
    assert line._buf.buffer is buffer and buffer.size >= 4999 * 14 * 4


def test_bad_input_is_rejected(gl_ctx):
    skel = Skeleton(gl_ctx, TPOSE_PARENTS)
    with pytest.raises(ValueError, match="16 joints"):
        skel.update(np.zeros((3, 3)))
    with pytest.raises(ValueError, match="3 joint names for 16 joints"):
        Skeleton(gl_ctx, TPOSE_PARENTS, names=["a", "b", "c"])
    with pytest.raises(ValueError, match="style"):
        Skeleton(gl_ctx, TPOSE_PARENTS, style="wireframe")
    line = Lines(gl_ctx)
    with pytest.raises(ValueError, match="even"):
        line.update(np.zeros((3, 3)), mode="segments")
    with pytest.raises(ValueError, match="mode"):
        line.update(np.zeros((3, 3)), mode="loop")


def test_capsule_records_keep_their_fixed_columns_until_colour_or_size_changes(gl_ctx):
    """The radius and colour columns of the capsule records are written once and kept from pose to
    pose; a new colour, alpha or thickness reaches them on the next update, and a new pose always does."""
    skel = Skeleton(gl_ctx, TPOSE_PARENTS, color=(0.9, 0.5, 0.1), shadow=False)
    skel.update(TPOSE_POSITIONS)
    first = skel._capsule_data.copy()
    assert np.allclose(first[:, 8:12], [0.9, 0.5, 0.1, 1.0])
    # a marker in the colour column: an unchanged colour is not written again, so it stays
    skel._capsule_data[:, 11] = 0.25
    moved = TPOSE_POSITIONS + [0.5, 0.0, 0.0]
    skel.update(moved)
    c = skel._capsule_data
    assert np.allclose(c[:, 11], 0.25)
    assert np.allclose(c[:, 0:6], first[:, 0:6] + [0.5, 0.0, 0.0, 0.5, 0.0, 0.0], atol=1e-6)
    assert np.array_equal(c[:, 6:8], first[:, 6:8])
    skel.color = (0.1, 0.2, 0.9)
    skel.update(moved)
    assert np.allclose(skel._capsule_data[:, 8:12], [0.1, 0.2, 0.9, 1.0])
    skel.alpha = 0.5
    skel.update(moved)
    assert np.allclose(skel._capsule_data[:, 11], 0.5)
    skel.thickness = 2.0
    skel.update(moved)
    assert np.allclose(skel._capsule_data[:, 6:8], 2.0 * first[:, 6:8], atol=1e-6)
    # sticks write other radii into the records; back to capsules, the capsule radii return
    skel.style = "sticks"
    skel.update(moved)
    skel.style = "capsules"
    skel.update(moved)
    assert np.allclose(skel._capsule_data[:, 6:8], 2.0 * first[:, 6:8], atol=1e-6)


def test_capsule_ends_follow_a_zero_length_leaf(gl_ctx):
    """A leaf on top of its parent has no direction: its extension points up, as before the fast path."""
    skel = Skeleton(gl_ctx, TPOSE_PARENTS, shadow=False)
    p = TPOSE_POSITIONS.copy()
    p[12] = p[11]                      # the left foot on its knee
    skel.update(p)
    assert np.isfinite(skel._capsule_data).all()


def test_marker_colours_and_sizes_are_kept_while_the_same_frozen_arrays_come_again(gl_ctx):
    """Spheres, arrows and lines keep the colour (and size) columns written from read-only arrays while
    the same arrays come again; other arrays, a writable one or other defaults are written again."""
    def frozen(a):
        a = np.array(a, np.float64)
        a.flags.writeable = False
        return a

    pts = np.array([[0.0, 0, 0], [1, 0, 0], [2, 0, 0], [3, 0, 0]])
    red, blue = frozen([[1.0, 0, 0]] * 4), frozen([[0, 0, 1.0]] * 4)
    sizes = frozen([0.1, 0.2, 0.3, 0.4])
    spheres, arrows, lines = Spheres(gl_ctx), Arrows(gl_ctx), Lines(gl_ctx)
    bufs = (spheres._buf, arrows._shafts, lines._buf)

    def update(colors, move=0.0, radii=sizes):
        spheres.update(pts + move, radii, colors)
        arrows.update(pts + move, np.ones_like(pts), colors)
        lines.update(pts + move, mode="segments", colors=colors)

    update(red)
    colour_cols = (slice(7, 11), slice(7, 11), slice(6, 10))
    for buf, cols in zip(bufs, colour_cols):
        assert np.allclose(buf._staging[:1, cols], [1, 0, 0, 1])
        buf._staging[:, cols.start] = 0.5           # a marker: kept while nothing changes
    update(red, move=1.0)
    for buf, cols in zip(bufs, colour_cols):
        assert np.allclose(buf._staging[0, cols.start], 0.5)
    assert np.allclose(spheres._buf._staging[:4, 0], pts[:, 0] + 1.0)         # the positions moved
    assert np.allclose(lines._buf._staging[:2, 0], [1.0, 3.0])
    assert np.allclose(spheres._buf._staging[:4, 6], [0.1, 0.2, 0.3, 0.4])
    update(blue, move=1.0)                          # another array: written
    for buf, cols in zip(bufs, colour_cols):
        assert np.allclose(buf._staging[:1, cols], [0, 0, 1, 1])
    spheres.update(pts, frozen([0.5] * 4), blue)    # other sizes, same colours
    assert np.allclose(spheres._buf._staging[:4, 6], 0.5)
    writable = np.array([[0, 1.0, 0]] * 4)
    update(writable)
    writable[:] = [1.0, 1.0, 0]                     # changed in place: a writable array is written again
    update(writable)
    for buf, cols in zip(bufs, colour_cols):
        assert np.allclose(buf._staging[:1, cols], [1, 1, 0, 1])
    spheres.update(pts, None, None)                 # back to the renderable's own colour and radius
    assert np.allclose(spheres._buf._staging[:4, 6], spheres.radius)
    assert np.allclose(spheres._buf._staging[:1, 7:10], spheres.color)
    spheres.update(pts, None, frozen([[1.0, 0, 0, 0.5]] * 4))
    assert spheres.transparent
    spheres.update(pts, None, red)
    assert not spheres.transparent


def test_a_prepared_pose_gives_the_records_of_a_direct_update(gl_ctx):
    """``Skeleton.prepare`` (run on the studio's tick worker) makes the capsule records ``update`` would
    make, bit for bit, without touching the skeleton; a pose prepared before the body changed is made
    again by ``update`` for the new body."""
    rng = np.random.default_rng(2)
    skel = Skeleton(gl_ctx, TPOSE_PARENTS, color=(0.9, 0.5, 0.1), shadow=False)
    direct = Skeleton(gl_ctx, TPOSE_PARENTS, color=(0.9, 0.5, 0.1), shadow=False)
    assert skel.prepare(TPOSE_POSITIONS).records is None           # no body before the first pose
    skel.update(TPOSE_POSITIONS)
    direct.update(TPOSE_POSITIONS)
    for _ in range(5):
        pose = TPOSE_POSITIONS + rng.normal(scale=0.05, size=TPOSE_POSITIONS.shape)
        before = skel._capsule_data.copy()
        prepared = skel.prepare(pose)
        assert prepared.records is not None and np.array_equal(skel._capsule_data, before)
        skel.update(prepared)
        direct.update(pose)
        assert np.array_equal(skel._capsule_data, direct._capsule_data)
    # the body changes after the pose was prepared: its records are not used
    pose = TPOSE_POSITIONS + [0.3, 0.0, 0.0]
    prepared = skel.prepare(pose)
    skel.thickness = direct.thickness = 1.5
    skel.update(prepared)
    direct.update(pose)
    assert np.array_equal(skel._capsule_data, direct._capsule_data)
    # sticks style makes no capsule records ahead
    skel.style = "sticks"
    assert skel.prepare(pose).records is None


def test_line_instances_pair_the_points_of_strips_and_segments(gl_ctx):
    """Each instance holds a segment's two ends and their colours: consecutive points for a strip, (0, 1),
    (2, 3), ... for segments, read back from the GPU buffer."""
    pts = np.arange(18, dtype=np.float32).reshape(6, 3)
    cols = np.linspace(0.0, 1.0, 24, dtype=np.float32).reshape(6, 4)
    line = Lines(gl_ctx)
    for mode, pairs in (("strip", [(0, 1), (1, 2), (2, 3), (3, 4), (4, 5)]), ("segments", [(0, 1), (2, 3), (4, 5)])):
        line.update(pts, mode=mode, colors=cols)
        got = np.frombuffer(line._buf.buffer.read(), np.float32).reshape(-1, 14)[:line._buf.count]
        want = np.array([np.concatenate([pts[a], pts[b], cols[a], cols[b]]) for a, b in pairs], np.float32)
        assert np.array_equal(got, want), mode
    for n in (0, 1):                                   # no segment at all
        line.update(pts[:n], mode="strip")
        assert line._buf.count == 0
    line.update(pts[:0], mode="segments")
    assert line._buf.count == 0
