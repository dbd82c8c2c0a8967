"""Camera math: projection of known points and the orbit/zoom/pan/follow/fit controls."""
import numpy as np
import pytest

from viewer.camera import (OrbitCamera, _look_at_rows, _perspective_terms, apply_drag, apply_scroll, look_at,
                           perspective, project_points, project_points_floats)


def test_look_at_maps_eye_to_origin_and_target_to_minus_z():
    eye, target = np.array([1.0, 2.0, 3.0]), np.array([-2.0, 0.5, 0.0])
    v = look_at(eye, target).astype(np.float64)
    assert np.allclose(v @ np.r_[eye, 1], [0, 0, 0, 1], atol=1e-5)
    t = v @ np.r_[target, 1]
    assert np.allclose(t[:2], 0, atol=1e-5) and t[2] < 0
    assert np.allclose(v[:3, :3] @ v[:3, :3].T, np.eye(3), atol=1e-5)   # a rotation
    assert np.isclose(np.linalg.det(v[:3, :3]), 1.0, atol=1e-5)           # right-handed


def test_perspective_maps_near_and_far_to_ndc_depth_bounds():
    p = perspective(60.0, 2.0, 0.1, 100.0).astype(np.float64)
    for z, expected in ((-0.1, -1.0), (-100.0, 1.0)):
        c = p @ [0, 0, z, 1]
        assert np.isclose(c[2] / c[3], expected, atol=1e-5)
    # a point on the top edge of the 60 degree field of view lands on ndc y = 1
    c = p @ [0, np.tan(np.radians(30)) * 5, -5, 1]
    assert np.isclose(c[1] / c[3], 1.0, atol=1e-5)


def test_perspective_in_floats_is_the_numpy_matrix_bit_for_bit():
    """perspective() works in Python floats; the float32 matrix is the one numpy's arithmetic gives."""
    rng = np.random.default_rng(4)
    for _ in range(2000):
        fov, aspect = float(rng.uniform(10, 120)), float(rng.uniform(0.2, 5))
        near, far = float(rng.uniform(1e-3, 1)), float(rng.uniform(10, 1e4))
        f = 1.0 / np.tan(np.radians(fov) / 2.0)
        m = np.zeros((4, 4))
        m[0, 0], m[1, 1] = f / aspect, f
        m[2, 2], m[2, 3], m[3, 2] = (far + near) / (near - far), 2.0 * far * near / (near - far), -1.0
        assert np.array_equal(perspective(fov, aspect, near, far), m.astype(np.float32))


def test_project_known_points():
    cam = OrbitCamera(target=[0, 1, 0], distance=5.0, yaw_deg=0.0, pitch_deg=0.0, fov_y_deg=90.0)
    w, h = 800, 600
    px = cam.project([[0, 1, 0], [0, 1 + 5 * 0.5, 0], [5 * 0.5 * w / h, 1, 0]], w, h)
    assert np.allclose(px[0], [400, 300], atol=1e-3)           # the target is the image centre
    assert np.allclose(px[1], [400, 150], atol=1e-3)           # above the target: up in the image
    assert np.allclose(px[2], [600, 300], atol=1e-3)           # +X is to the right seen from +Z
    _, _, in_front = project_points([[0, 1, 10]], cam.view_projection(w / h), w, h)   # behind the eye
    assert not in_front[0]


def test_orbit_keeps_target_and_distance_and_clamps_pitch():
    cam = OrbitCamera(target=[1, 2, 3], distance=4.0)
    cam.orbit(120, -40)
    assert np.allclose(cam.target, [1, 2, 3])
    assert np.isclose(np.linalg.norm(cam.eye - cam.target), 4.0)
    cam.orbit(0, 10000)
    assert cam.pitch_deg == cam.max_pitch_deg
    cam.orbit(0, -10000)
    assert cam.pitch_deg == cam.min_pitch_deg


def test_orbit_drag_right_turns_scene_right():
    cam = OrbitCamera(target=[0, 0, 0], distance=5.0, yaw_deg=0.0, pitch_deg=0.0)
    before = cam.project([[0, 0, 1]], 800, 600)[0, 0]
    cam.orbit(30, 0)
    assert cam.project([[0, 0, 1]], 800, 600)[0, 0] > before


def test_zoom_is_multiplicative_and_reversible():
    cam = OrbitCamera(distance=4.0)
    cam.zoom(2)
    assert cam.distance < 4.0
    cam.zoom(-2)
    assert np.isclose(cam.distance, 4.0)
    apply_scroll(cam, 1)
    assert cam.distance < 4.0


def test_pan_moves_the_target_point_with_the_cursor():
    cam = OrbitCamera(target=[0, 1, 0], distance=6.0, yaw_deg=40.0, pitch_deg=20.0)
    w, h = 1000, 500
    anchor = cam.target.copy()
    before = cam.project([anchor], w, h)[0]
    apply_drag(cam, "right", 50, -30, h)
    after = cam.project([anchor], w, h)[0]
    assert np.allclose(after - before, [50, -30], atol=0.5)
    assert np.isclose(np.linalg.norm(cam.eye - cam.target), 6.0)


def test_follow_tracks_horizontally_and_keeps_the_offset():
    cam = OrbitCamera(target=[0, 1, 0], distance=3.0, yaw_deg=10.0, pitch_deg=15.0)
    offset = cam.eye - cam.target
    cam.follow([5.0, 0.7, -2.0])
    assert np.allclose(cam.target, [5.0, 1.0, -2.0])
    assert np.allclose(cam.eye - cam.target, offset)
    cam.follow([7.0, 0.7, -2.0], blend=0.5)
    assert np.allclose(cam.target, [6.0, 1.0, -2.0])


@pytest.mark.parametrize("scale", [0.02, 1.0, 100.0])
@pytest.mark.parametrize("aspect", [0.5, 16 / 9])
def test_fit_puts_every_point_in_view_at_any_scale(scale, aspect):
    rng = np.random.default_rng(0)
    pts = (rng.normal(size=(50, 3)) * [0.3, 0.8, 0.2] + [2, 1, -1]) * scale
    cam = OrbitCamera(yaw_deg=25.0, pitch_deg=20.0)
    cam.fit(pts, aspect=aspect)
    h = 600
    w = int(h * aspect)
    px, depth, in_front = project_points(pts, cam.view_projection(aspect), w, h)
    assert in_front.all() and (np.abs(depth) < 1).all()
    assert (px >= 0).all() and (px[:, 0] <= w).all() and (px[:, 1] <= h).all()
    # and not tiny: the points span a good part of the narrower image side
    span = (px.max(axis=0) - px.min(axis=0)) / [w, h]
    assert span.max() > 0.3
    assert cam.near < cam.distance - np.linalg.norm(pts - cam.target, axis=1).max()


def test_projecting_a_few_points_in_floats_equals_the_numpy_form():
    """The labels' plain-float projection gives project_points' pixels and in-front flags (points behind
    the eye included)."""
    from viewer.camera import project_points_floats

    rng = np.random.default_rng(4)
    cam = OrbitCamera(yaw_deg=40.0, pitch_deg=25.0, distance=3.0)
    w, h = 754, 492
    vp = cam.view_projection(w / h)
    pts = rng.normal(size=(40, 3)) * 4.0
    pts[0] = cam.eye + (cam.eye - cam.target)          # behind the eye
    px, _, front = project_points(pts, vp, w, h)
    got = project_points_floats(pts, vp, w, h)
    assert [g[2] for g in got] == front.tolist() and not got[0][2]
    assert np.allclose(np.array([g[:2] for g in got]), px, rtol=1e-12, atol=1e-9)


def test_view_projection_is_remade_whenever_the_camera_or_the_aspect_changes():
    """The product is kept per camera placement and aspect (the labels and the render ask each frame):
    every change must give the matrix made from scratch, and a caller's copy is its own."""
    cam = OrbitCamera(target=np.array([0.5, 0.9, -1.0]), distance=3.0, yaw_deg=20.0, pitch_deg=10.0)

    def fresh(aspect):
        """The float64 product of the two matrices before their float32 rounding."""
        a, f, c, d = _perspective_terms(cam.fov_y_deg, aspect, cam.near, cam.far)
        proj = np.array([[a, 0, 0, 0], [0, f, 0, 0], [0, 0, c, d], [0, 0, -1, 0]], np.float64)
        view = np.array([*_look_at_rows(cam.eye, cam.target), (0, 0, 0, 1)], np.float64)
        out = proj @ view
        # and within float32 rounding of the float32 matrices' product
        assert np.allclose(out, cam.projection_matrix(aspect).astype(np.float64)
                           @ cam.view_matrix().astype(np.float64), rtol=1e-6, atol=1e-6)
        return out

    def rows(aspect):
        return np.array(cam.view_projection_rows(aspect))

    first = cam.view_projection(1.5)
    assert first.dtype == np.float32 and np.array_equal(first, fresh(1.5).astype(np.float32))
    first[:] = 0.0                                    # the caller's own array
    assert np.allclose(rows(1.5), fresh(1.5), rtol=1e-13, atol=1e-13)
    changes = [lambda: setattr(cam, "yaw_deg", 21.0), lambda: setattr(cam, "pitch_deg", 12.0),
               lambda: setattr(cam, "distance", 2.5), lambda: setattr(cam, "fov_y_deg", 50.0),
               lambda: cam.follow([1.0, 0.0, 2.0], blend=0.5), lambda: cam.pan(10.0, 5.0, 600.0),
               lambda: setattr(cam, "near_ratio", 0.02)]
    for change in changes:
        before = rows(1.5)
        change()
        after = rows(1.5)
        assert np.allclose(after, fresh(1.5), rtol=1e-13, atol=1e-13)
        assert not np.array_equal(after, before)
    assert np.allclose(rows(0.75), fresh(0.75), rtol=1e-13, atol=1e-13)
    # the labels' plain-float projection through the rows is project_points' through the matrix
    pts = np.array([[0.3, 1.6, -0.4], [2.0, 0.1, 1.0], [-1.0, 1.0, -3.0]])
    px, _, front = project_points(pts, rows(0.75), 640, 480)
    floats = project_points_floats(pts, cam.view_projection_rows(0.75), 640, 480)
    assert np.allclose([(x, y) for x, y, _ in floats], px, rtol=1e-12, atol=1e-9)
    assert [ok for _, _, ok in floats] == front.tolist()


def test_follow_in_plain_floats_gives_numpys_bits():
    rng = np.random.default_rng(3)
    for _ in range(200):
        start = rng.normal(size=3) * 10
        goal = rng.normal(size=3) * 10
        blend = float(rng.uniform(0.01, 1.0))
        for keep in (True, False):
            cam = OrbitCamera(target=start.copy())
            cam.follow(goal, blend=blend, keep_height=keep)
            g = goal.copy()
            if keep:
                g[1] = start[1]
            assert np.array_equal(cam.target, start + blend * (g - start))
            assert cam.target.dtype == np.float64 and cam.target.shape == (3,)
