"""The character as a body: capsules vs sticks, the ground shadow, ghosts, any skeleton.

Headless EGL renders of a known pose; images are saved under tests/viewer/_out/ for inspection.
"""
import numpy as np
import pytest
from PIL import Image

from lmm.skeleton import body_radii
from viewer import Ground, Lines, OrbitCamera, Renderer, Scene, Skeleton
from viewer.renderables import body
from viewer.renderables.base import Resources
from viewer_testutil import TPOSE_PARENTS, TPOSE_POSITIONS, colour_mask, near_any, write_bvh

W, H = 480, 360
ORANGE = (0.95, 0.5, 0.1)
BLUE = (0.15, 0.4, 1.0)
YELLOW = (0.95, 0.85, 0.1)
OFFSET = np.array([1.5, 0.0, -1.0])   # away from the world axes at the origin
POSE = TPOSE_POSITIONS + OFFSET
TPOSE_NAMES = ["Hips", "Spine", "Neck", "Head", "LeftShoulder", "LeftForeArm", "LeftHand", "RightShoulder",
               "RightForeArm", "RightHand", "LeftUpLeg", "LeftLeg", "LeftFoot", "RightUpLeg", "RightLeg",
               "RightFoot"]
LAFAN1_NAMES = ["Hips", "LeftUpLeg", "LeftLeg", "LeftFoot", "LeftToe", "RightUpLeg", "RightLeg", "RightFoot",
                "RightToe", "Spine", "Spine1", "Spine2", "Neck", "Head", "LeftShoulder", "LeftArm", "LeftForeArm",
                "LeftHand", "RightShoulder", "RightArm", "RightForeArm", "RightHand"]
LAFAN1_PARENTS = [-1, 0, 1, 2, 3, 0, 5, 6, 7, 0, 9, 10, 11, 12, 11, 14, 15, 16, 11, 18, 19, 20]


@pytest.fixture(scope="module")
def renderer(gl_ctx):
    r = Renderer(gl_ctx, W, H, samples=0)
    yield r
    r.release()


def named(names) -> dict:
    """A Skeleton's names and the body radii they say, as the studio hands them over."""
    return {"names": names, "body_radii": body_radii(names)}


def camera_on(points, pitch=14.0):
    cam = OrbitCamera(yaw_deg=25.0, pitch_deg=pitch)
    cam.fit(points, aspect=W / H, margin=1.3)
    return cam


def shadow_point(scene, p, ground=0.0):
    """Where the key light casts world point ``p`` on the ground plane."""
    d = np.asarray(scene.light.direction, dtype=float)
    d /= np.linalg.norm(d)
    return np.asarray(p, dtype=float) - d * (p[1] - ground) / d[1]


def luminance(img):
    return img[..., :3].astype(float) @ [0.299, 0.587, 0.114]


# -- body proportions (no GL) ------------------------------------------------------------------------

def test_given_joint_radii_follow_the_body():
    lengths = np.ones(len(LAFAN1_PARENTS))
    r = dict(zip(LAFAN1_NAMES, body.joint_radii(LAFAN1_PARENTS, body_radii(LAFAN1_NAMES), lengths, height=1.7)))
    assert r["LeftUpLeg"] > r["LeftLeg"] > r["LeftFoot"]          # thigh, shin, ankle
    assert r["LeftArm"] > r["LeftForeArm"] and r["LeftArm"] == r["RightArm"]
    assert r["Spine2"] > r["Neck"] and r["Spine"] > r["LeftForeArm"] and r["Hips"] > r["LeftLeg"]
    assert 0.08 < r["Spine2"] < 0.15 and 0.03 < r["LeftForeArm"] < 0.05   # metres, for a 1.7 m body
    # scales with the height: the same body in centimetres
    cm = body.joint_radii(LAFAN1_PARENTS, body_radii(LAFAN1_NAMES), lengths, height=170.0)
    assert np.allclose(cm, 100 * np.array(list(r.values())))
    # joints of unknown size (NaN) come from the tree, a root of unknown size at least a pelvis's
    given = np.full(len(LAFAN1_PARENTS), np.nan)
    given[1] = 0.05
    mixed = body.joint_radii(LAFAN1_PARENTS, given, lengths)
    tree = body.joint_radii(LAFAN1_PARENTS, None, lengths)
    assert mixed[1] == 0.05 and np.array_equal(mixed[2:], tree[2:])
    assert mixed[0] == max(tree[0], body.PELVIS_RADIUS)


def test_unnamed_skeleton_gets_a_body_from_its_tree():
    lengths = body.bone_lengths(TPOSE_PARENTS, TPOSE_POSITIONS)
    r = body.joint_radii(TPOSE_PARENTS, None, lengths, height=1.0)
    leaves = [j for j in range(len(TPOSE_PARENTS)) if j not in TPOSE_PARENTS]
    assert all(r[0] > r[j] for j in leaves)                       # pelvis thicker than every tip
    assert r[10] > r[11] > r[12] and r[4] > r[6]                  # limbs taper towards hands and feet
    assert (r > 0.01).all() and (r < 0.1).all()
    # height from bone lengths alone, in any pose: the T-pose is 1.75 m tall
    assert 1.3 < body.estimate_height(TPOSE_PARENTS, lengths) < 2.2
    ext, _ = body.leaf_extensions(TPOSE_PARENTS, None, lengths, height=1.0)
    assert (ext[leaves] > 0).all() and (np.delete(ext, leaves) == 0).all()


def test_simulation_bone_and_head_sphere(gl_ctx):
    names = ["Simulation"] + TPOSE_NAMES
    parents = np.r_[-1, TPOSE_PARENTS + 1]
    parents[1] = 0
    positions = np.r_[[[0.0, 0.0, 0.0]], TPOSE_POSITIONS]
    skel = Skeleton(gl_ctx, parents, **named(names))
    skel.update(positions)
    radii = skel.joint_radii()
    assert radii[0] == 0 and (radii[1:] > 0).all()
    # the hidden bone does not count for the size: the same body as without the Simulation joint
    plain = Skeleton(gl_ctx, TPOSE_PARENTS, **named(TPOSE_NAMES))
    plain.update(TPOSE_POSITIONS)
    assert skel.body_height() == pytest.approx(plain.body_height())
    assert np.allclose(radii[1:], plain.joint_radii())
    plain.release()
    caps = np.frombuffer(skel._capsules.buffer.read(), np.float32)[:skel._capsules.count * 12].reshape(-1, 12)
    ends = np.r_[caps[:, 0:3], caps[:, 3:6]]
    assert not np.isclose(ends, [0.0, 0.0, 0.0], atol=1e-6).all(axis=1).any()   # nothing at the sim bone
    head = positions[4]
    spheres = caps[np.all(caps[:, 0:3] == caps[:, 3:6], axis=1)]
    assert len(spheres) == 1 and spheres[0, 1] > head[1]          # the head sphere sits above the head joint
    skel.release()


# -- rendering -------------------------------------------------------------------------------------

def render_one(gl_ctx, renderer, pose=POSE, ground=True, cam=None, **kwargs):
    scene = Scene()
    if ground:
        scene.add(Ground(gl_ctx))
    skel = scene.add(Skeleton(gl_ctx, TPOSE_PARENTS, color=ORANGE, **kwargs))
    skel.update(pose)
    cam = cam or camera_on(pose)
    img = renderer.render(scene, cam)
    scene.release()
    return img, cam


@pytest.fixture(params=[False, True], ids=["mesh", "exact"])
def exact(gl_ctx, request):
    """Capsules drawn as their mesh, then ray-cast per pixel (whatever this machine's default)."""
    res = Resources.of(gl_ctx)
    default = res.exact_capsules
    res.exact_capsules = request.param
    yield request.param
    res.exact_capsules = default


def test_capsules_cover_more_than_sticks_and_style_switches(gl_ctx, renderer, out_dir, exact):
    scene = Scene()
    scene.add(Ground(gl_ctx))
    skel = scene.add(Skeleton(gl_ctx, TPOSE_PARENTS, color=ORANGE, **named(TPOSE_NAMES), shadow=False))
    assert skel.exact == exact
    skel.update(POSE)
    cam = camera_on(POSE)
    capsules = renderer.render(scene, cam)
    Image.fromarray(capsules).save(out_dir / f"body_capsules_{'exact' if exact else 'mesh'}.png")
    skel.style = "sticks"                      # applies on the next draw, no new update needed
    sticks = renderer.render(scene, cam)
    Image.fromarray(sticks).save(out_dir / "body_sticks.png")
    n_capsules, n_sticks = colour_mask(capsules, ORANGE).sum(), colour_mask(sticks, ORANGE).sum()
    assert n_capsules > 2.5 * n_sticks > 0, (n_capsules, n_sticks)
    # sticks are exactly what a sticks skeleton draws; switching back gives the capsules again
    fresh, _ = render_one(gl_ctx, renderer, cam=cam, **named(TPOSE_NAMES), style="sticks", shadow=False)
    assert np.array_equal(sticks, fresh)
    skel.style = "capsules"
    assert np.array_equal(renderer.render(scene, cam), capsules)
    # every joint and bone middle is covered, in both styles
    px = cam.project(POSE, W, H)
    mids = cam.project((POSE[1:] + POSE[TPOSE_PARENTS[1:]]) / 2, W, H)
    for img in (capsules, sticks):
        mask = colour_mask(img, ORANGE)
        assert all(near_any(mask, p, 1) for p in np.r_[px, mids])
    # thickness scales the body
    skel.thickness = 0.5
    thin = colour_mask(renderer.render(scene, cam), ORANGE).sum()
    assert n_sticks < thin < 0.7 * n_capsules
    with pytest.raises(ValueError, match="style"):
        skel.style = "blobs"
    scene.release()


def test_shadow_darkens_the_ground_once_and_only_with_shadow_on(gl_ctx, renderer, out_dir):
    cam = camera_on(np.r_[POSE, [shadow_point(Scene(), p) for p in POSE]], pitch=40.0)
    on, _ = render_one(gl_ctx, renderer, cam=cam, **named(TPOSE_NAMES), shadow=True)
    off, _ = render_one(gl_ctx, renderer, cam=cam, **named(TPOSE_NAMES), shadow=False)
    empty, _ = render_one(gl_ctx, renderer, cam=cam, pose=POSE + [0, -50, 0])   # character far below
    Image.fromarray(on).save(out_dir / "body_shadow_on.png")
    Image.fromarray(off).save(out_dir / "body_shadow_off.png")
    body_px = colour_mask(on, ORANGE) | colour_mask(off, ORANGE)
    ground = ~body_px
    # with the shadow off the ground is untouched
    assert np.abs(off[ground].astype(int) - empty[ground].astype(int)).max() <= 1
    # under the hips, spine and knees (cast along the key light) the ground is darker with it on
    for j in (0, 1, 11, 14):
        x, y = cam.project([shadow_point(Scene(), POSE[j])], W, H)[0].astype(int)
        assert ground[y, x], f"the shadow of joint {j} is hidden behind the body"
        assert luminance(on)[y, x] < 0.75 * luminance(off)[y, x], j
    # ... and only there: far from the shadow, nothing changes
    ratio = luminance(on)[ground] / np.maximum(luminance(off)[ground], 1.0)
    assert (ratio > 0.995).mean() > 0.8
    # overlapping bones darken once: never below 1 - strength (0.55), however many parts overlap
    assert 0.42 < ratio.min() < 0.52, ratio.min()
    assert (on[..., 3] == 255).all()                               # the image stays opaque


def test_shadow_needs_a_ground_and_leaves_lines_alone(gl_ctx, renderer, out_dir):
    cam = camera_on(np.r_[POSE, [shadow_point(Scene(), p) for p in POSE]], pitch=40.0)
    # no ground in the scene: no shadow anywhere
    a, _ = render_one(gl_ctx, renderer, cam=cam, ground=False, shadow=True)
    b, _ = render_one(gl_ctx, renderer, cam=cam, ground=False, shadow=False)
    assert np.array_equal(a, b)
    # a trail (transparent) and a path (opaque) lying on the ground through the shadow keep their colour
    path = np.array([shadow_point(Scene(), POSE[j]) for j in (0, 3)])   # hips' to head's shadow
    along = (path[1] - path[0]) / np.linalg.norm(path[1] - path[0])
    side = np.cross(along, [0.0, 1.0, 0.0]) * 0.05
    probe = shadow_point(Scene(), POSE[1])                                # the spine's shadow
    images = {}
    for shadow in (True, False):
        for lines in (True, False):
            scene = Scene()
            scene.add(Ground(gl_ctx))
            skel = scene.add(Skeleton(gl_ctx, TPOSE_PARENTS, color=ORANGE, shadow=shadow))
            skel.update(POSE)
            opaque = scene.add(Lines(gl_ctx, color=YELLOW, width_px=5.0))
            opaque.update(path + side)
            trail = scene.add(Lines(gl_ctx, color=(0.2, 0.9, 0.3, 0.8), width_px=5.0))
            trail.update(path - side)
            opaque.visible = trail.visible = lines
            images[shadow, lines] = renderer.render(scene, cam).astype(int)
            scene.release()
    Image.fromarray(images[True, True].astype(np.uint8)).save(out_dir / "body_shadow_lines.png")
    x, y = cam.project([probe + side], W, H)[0].astype(int)
    assert colour_mask(images[True, True].astype(np.uint8), YELLOW)[y, x]
    assert np.abs(images[True, True][y, x] - images[False, True][y, x]).max() <= 2   # opaque: untouched
    x, y = cam.project([probe - side], W, H)[0].astype(int)
    ground_change = np.abs(images[True, False][y, x] - images[False, False][y, x]).max()
    assert ground_change > 20                                                          # shadowed ground...
    trail_change = np.abs(images[True, True][y, x] - images[False, True][y, x]).max()
    assert trail_change <= 0.2 * ground_change + 2     # ...shows only through the trail's 20 % transparency


def test_ghost_capsules_blend_and_cast_a_fainter_shadow(gl_ctx, renderer, out_dir, exact):
    cam = camera_on(np.r_[POSE, [shadow_point(Scene(), p) for p in POSE]], pitch=40.0)

    def render(alpha, visible=True, shadow=False):
        scene = Scene()
        scene.add(Ground(gl_ctx))
        ghost = scene.add(Skeleton(gl_ctx, TPOSE_PARENTS, color=BLUE, alpha=alpha, shadow=shadow))
        ghost.update(POSE)
        ghost.visible = visible
        img = renderer.render(scene, cam).astype(float)
        scene.release()
        return img

    blended, opaque, behind = render(0.5), render(1.0), render(0.5, visible=False)
    Image.fromarray(render(0.5, shadow=True).astype(np.uint8)).save(out_dir / "body_ghost.png")
    for x, y in cam.project(POSE[[0, 1, 2, 5, 11]], W, H).astype(int):
        expected = 0.5 * opaque[y, x, :3] + 0.5 * behind[y, x, :3]
        assert np.abs(blended[y, x, :3] - expected).max() <= 6, (blended[y, x], expected)
    # the ghost's shadow is there, fainter than a solid character's
    x, y = cam.project([shadow_point(Scene(), POSE[0])], W, H)[0].astype(int)
    ground = luminance(behind)[y, x]
    ghost_shadow = luminance(render(0.5, shadow=True))[y, x]
    solid_shadow = luminance(render(1.0, shadow=True))[y, x]
    assert solid_shadow < ghost_shadow < 0.95 * ground


def test_any_skeleton_from_a_bvh_draws(gl_ctx, renderer, tmp_path, out_dir, exact):
    bvh = pytest.importorskip("lmm.data.bvh")
    names = ["pelvis", "back", "skull", "wing_l", "claw_l", "wing_r", "claw_r", "thigh_l", "shin_l", "thigh_r",
             "shin_r", "tail1", "tail2"]
    parents = [-1, 0, 1, 1, 3, 1, 5, 0, 7, 0, 9, 0, 11]
    offsets = np.array([[0, 0, 0], [0, 0.5, 0], [0, 0.45, 0.05], [0.3, 0.35, 0], [0.45, 0, 0], [-0.3, 0.35, 0],
                        [-0.45, 0, 0], [0.15, -0.05, 0], [0, -0.6, 0.05], [-0.15, -0.05, 0], [0, -0.6, 0.05],
                        [0, 0, -0.3], [0, 0, 0]])            # the last bone has length 0
    path = tmp_path / "creature.bvh"
    write_bvh(path, names, parents, offsets, np.array([[2.0, 0.7, -1.0]] * 3))
    anim = bvh.load(path)
    pose = anim.global_positions()[1]
    for with_names in (True, False):
        scene = Scene()
        scene.add(Ground(gl_ctx))
        skel = scene.add(Skeleton(gl_ctx, anim.parents, color=ORANGE, **(named(anim.names) if with_names else {})))
        skel.update(pose)
        cam = camera_on(pose)
        img = renderer.render(scene, cam)
        Image.fromarray(img).save(out_dir / f"body_creature_{'named' if with_names else 'unnamed'}.png")
        mask = colour_mask(img, ORANGE)
        for j, p in enumerate(cam.project(pose, W, H)):
            assert near_any(mask, p, 2), f"no body near joint {anim.names[j]}"
        assert np.isfinite(skel.joint_radii()).all() and (skel.joint_radii() > 0).all()
        scene.release()
    # a single joint and two coincident joints draw too
    for parents_, pose_ in (([-1], [[1.5, 1.0, -1.0]]), ([-1, 0], [[1.5, 1.0, -1.0], [1.5, 1.0, -1.0]])):
        scene = Scene()
        skel = scene.add(Skeleton(gl_ctx, parents_, color=ORANGE, height=1.7))
        skel.update(pose_)
        img = renderer.render(scene, camera_on(np.r_[pose_, np.add(pose_, 0.3)]))
        assert colour_mask(img, ORANGE).sum() > 50
        scene.release()
