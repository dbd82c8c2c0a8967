"""3D viewport: both characters, their simulation objects, predicted trajectories, ghosts of the
matched frames, foot contacts and feature markers, drawn by :mod:`viewer` into its own framebuffer
in dearpygui's GL context and shown as a raw texture.

Mouse on the image: left-drag orbits, right/middle-drag pans, wheel zooms. The camera follows the
characters unless "Follow" is off. "Side by side" draws the LMM character (and everything of it)
shifted to the right of the MM one; both simulate from the same start with the same input.
"""
from __future__ import annotations

import numpy as np

from lmm import quat

from .common import COLORS, SHORT, View, darker, lighter, window_tag

FORWARD = np.array([0.0, 0.0, 1.0])
SIDE_OFFSET_M = 1.6
TRAIL_SECONDS = 4.0


def world_from_root(root_pos, root_rot, local_xyz):
    """Root-space points (N, 3) to world."""
    return np.asarray(root_pos, np.float64) + np.asarray(local_xyz, np.float64) @ quat.to_matrix(
        np.asarray(root_rot, np.float64)).T


def feature_markers(features, normalized, root_pos, root_rot, bone_positions: dict) -> dict:
    """World-space markers of a normalised feature vector, by channel kind.

    Returns ``{"points": (N,3), "arrows": (origins (M,3), vectors (M,3)), "traj": (T,3),
    "traj_dirs": (T,3)}``: bone positions as points, bone velocities as arrows starting at the
    bone (``bone_positions[channel.bone]`` when known, else at the feature's own position) scaled to
    0.1 s of motion, and trajectory points/directions on the ground.
    """
    raw = features.denormalize(np.asarray(normalized, np.float32)).astype(np.float64)
    rot_t = quat.to_matrix(np.asarray(root_rot, np.float64)).T     # row vectors: v @ R^T == R v
    root = np.asarray(root_pos, np.float64)
    points, origins, vectors, traj, dirs = [], [], [], [], []
    positions_by_bone = {}
    for ch, s in zip(features.layout, features.slices):
        if ch.kind == "bone_position":
            p = root + raw[s] @ rot_t
            points.append(p)
            positions_by_bone[ch.bone] = p
    for ch, s in zip(features.layout, features.slices):
        v = raw[s]
        if ch.kind == "bone_velocity":
            start = bone_positions.get(ch.bone, positions_by_bone.get(ch.bone))
            if start is not None:
                origins.append(start)
                vectors.append((v @ rot_t) * 0.1)
        elif ch.kind.startswith("trajectory"):
            xz = v.reshape(-1, 2)
            ground = np.zeros((len(xz), 3))
            ground[:, 0], ground[:, 2] = xz[:, 0], xz[:, 1]
            if ch.kind == "trajectory_position":
                traj.append(root + ground @ rot_t)
            else:
                dirs.append(ground @ rot_t)
    z3 = np.zeros((0, 3))
    return {"points": np.array(points) if points else z3,
            "arrows": (np.array(origins) if origins else z3, np.array(vectors) if vectors else z3),
            "traj": np.concatenate(traj) if traj else z3, "traj_dirs": np.concatenate(dirs) if dirs else z3}


def is_software_renderer(name: str) -> bool:
    """True for Mesa's CPU rasterisers (llvmpipe, softpipe, swrast) and similar."""
    n = name.lower()
    return any(k in n for k in ("llvmpipe", "softpipe", "swrast", "software", "swiftshader"))


class MarkerBatch:
    """Every marker of every character, gathered per frame and drawn with one sphere, one arrow and
    one line renderable (few draw calls matter on software GL, where each costs about a millisecond)."""

    def __init__(self, viewer, ctx):
        self.spheres = viewer.Spheres(ctx, radius=0.04)
        self.arrows = viewer.Arrows(ctx, shaft_radius=0.011, head_radius=0.032, head_length=0.07)
        self.lines = viewer.Lines(ctx, width_px=2.5)
        self.clear()

    def renderables(self):
        return [self.lines, self.spheres, self.arrows]

    def clear(self) -> None:
        self._centers, self._radii, self._sphere_colors = [], [], []
        self._origins, self._vectors, self._arrow_colors = [], [], []
        self._segments, self._segment_colors = [], []

    def add_spheres(self, centers, radius: float, color) -> None:
        c = np.asarray(centers, np.float64).reshape(-1, 3)
        if len(c):
            self._centers.append(c)
            self._radii.append(np.full(len(c), radius))
            self._sphere_colors.append(np.broadcast_to(np.asarray(color, np.float64)[:3], (len(c), 3)))

    def add_arrows(self, origins, vectors, color) -> None:
        o = np.asarray(origins, np.float64).reshape(-1, 3)
        v = np.asarray(vectors, np.float64).reshape(-1, 3)
        n = min(len(o), len(v))
        if n:
            self._origins.append(o[:n])
            self._vectors.append(v[:n])
            self._arrow_colors.append(np.broadcast_to(np.asarray(color, np.float64)[:3], (n, 3)))

    def add_polyline(self, points, color) -> None:
        p = np.asarray(points, np.float64).reshape(-1, 3)
        if len(p) >= 2:
            seg = np.empty((2 * (len(p) - 1), 3))
            seg[0::2] = p[:-1]
            seg[1::2] = p[1:]
            self._segments.append(seg)
            self._segment_colors.append(np.broadcast_to(np.asarray(color, np.float64)[:3], (len(seg), 3)))

    def flush(self) -> None:
        z3 = np.zeros((0, 3))
        if self._centers:
            self.spheres.update(np.concatenate(self._centers), np.concatenate(self._radii),
                                np.concatenate(self._sphere_colors))
        else:
            self.spheres.update(z3)
        if self._origins:
            self.arrows.update(np.concatenate(self._origins), np.concatenate(self._vectors),
                               np.concatenate(self._arrow_colors))
        else:
            self.arrows.update(z3, z3)
        if self._segments:
            self.lines.update(np.concatenate(self._segments), mode="segments",
                              colors=np.concatenate(self._segment_colors))
        else:
            self.lines.update(z3, mode="segments")


class CharacterDrawing:
    """A character's skeleton and ghost; its markers go into the shared :class:`MarkerBatch`."""

    def __init__(self, viewer, ctx, parents, color):
        self.color = color
        self.skeleton = viewer.Skeleton(ctx, parents, color=color, joint_radius=0.028, bone_radius=0.02)
        self.ghost = viewer.Skeleton(ctx, parents, color=lighter(color, 0.55), alpha=0.32,
                                     joint_radius=0.024, bone_radius=0.017)
        self.traj_color = lighter(color, 0.35)
        self.trail_color = darker(color, 0.3)

    def all(self):
        return [self.skeleton, self.ghost]

    def hide(self) -> None:
        self.skeleton.visible = False
        self.ghost.visible = False


SIM_COLOR = (0.95, 0.88, 0.3)
MATCHED_COLOR = (0.9, 0.9, 0.92)
FEATURE_COLOR = (0.85, 0.4, 0.95)
CONTACT_COLOR = (0.3, 0.95, 0.4)
LOCKED_COLOR = (0.2, 0.9, 0.95)
LEGEND = (("simulation object", SIM_COLOR), ("desired trajectory", (0.85, 0.85, 0.85)),
          ("matched frame's trajectory", MATCHED_COLOR), ("foot contact", CONTACT_COLOR),
          ("locked", LOCKED_COLOR), ("pose features", FEATURE_COLOR), ("ghost = matched pose", (0.75, 0.75, 0.8)))


class ViewportPanel:
    """The 3D view. GL objects are created in ``init_gl`` after dearpygui's first frame."""

    TOGGLES = (("ghost", "Ghost", True), ("trajectory", "Trajectory", True), ("matched", "Matched traj.", True),
               ("contacts", "Contacts", True), ("features", "Features", True), ("trail", "Trail", True))

    def __init__(self, dpg, studio):
        self.dpg = dpg
        self.studio = studio
        self.tag = window_tag("viewport")
        self.ctx = None
        self.renderer = None
        self.scene = None
        self.camera = None
        self.drawings: dict[str, CharacterDrawing] = {}
        self.reference = None
        self.size = (0, 0)
        self.texture = None
        self.tex_array = None
        self.side_by_side = True
        self.follow = True
        self.show = {k: v for k, _, v in self.TOGGLES}
        self.drag = None
        self.last_mouse = None
        self.wheel = 0.0
        self.drawn: dict = {}
        self.render_ms = 0.0
        self.readback_ms = 0.0
        self.gl_error = None
        self._texture_counter = 0
        self._legend_items: list[str] = []
        self.samples = -1          # -1: auto (4x MSAA on a GPU, none on software GL)
        self.render_scale = 1.0    # 3D image resolution / displayed size
        self.render_size = (0, 0)
        self.gl_renderer = ""

    # -- items ------------------------------------------------------------------------------
    def build(self, parent_window_kwargs: dict) -> None:
        dpg = self.dpg
        with dpg.window(tag=self.tag, label="3D Viewport", no_scrollbar=True, **parent_window_kwargs):
            with dpg.group(horizontal=True):
                dpg.add_text("Inspect:")
                dpg.add_radio_button([SHORT[n] for n in COLORS], tag="vp_inspect", horizontal=True,
                                     default_value=SHORT.get(self.studio.inspected, self.studio.inspected),
                                     callback=self._on_inspect)
                dpg.add_checkbox(label="Side by side", tag="vp_side", default_value=self.side_by_side,
                                 callback=lambda s, a: setattr(self, "side_by_side", bool(a)))
                dpg.add_checkbox(label="Follow", tag="vp_follow", default_value=self.follow,
                                 callback=lambda s, a: setattr(self, "follow", bool(a)))
                with dpg.tooltip("vp_side"):
                    dpg.add_text("Draw the LMM character 1.6 m to the right of the MM one\n"
                                 "(both simulate from the same start; off: overlaid)")
            with dpg.group(horizontal=True):
                for key, label, default in self.TOGGLES:
                    dpg.add_checkbox(label=label, tag=f"vp_show_{key}", default_value=default,
                                     callback=self._on_toggle, user_data=key)
            dpg.add_drawlist(width=64, height=64, tag="vp_drawlist")

    def _on_inspect(self, sender, value):
        for name in COLORS:
            if SHORT[name] == value:
                self.studio.set_inspected(name)
        self.dpg.set_value("vp_inspect", SHORT.get(self.studio.inspected, "MM"))

    def _on_toggle(self, sender, value, key):
        self.show[key] = bool(value)

    # -- GL -----------------------------------------------------------------------------------
    def init_gl(self) -> None:
        import viewer

        try:
            self.ctx = viewer.attach_current_context()
        except Exception as e:
            self.gl_error = f"3D view unavailable: {e}"
            raise
        self.viewer = viewer
        self.scene = viewer.Scene(background=(0.13, 0.14, 0.17))
        self.ground = viewer.Ground(self.ctx, size_m=60.0, tile_m=1.0)
        self.scene.add(self.ground)
        parents = self.studio.session.db.parents
        for name in self.studio.session.names:
            d = CharacterDrawing(viewer, self.ctx, parents, COLORS.get(name, (0.8, 0.8, 0.8)))
            self.drawings[name] = d
            self.scene.add(*d.all())
        self.batch = MarkerBatch(viewer, self.ctx)
        self.scene.add(*self.batch.renderables())
        self.reference_skeleton = None
        self.camera = viewer.OrbitCamera(target=np.array([0.8, 0.8, 0.0]), distance=4.6, yaw_deg=35.0,
                                         pitch_deg=16.0)
        self.gl_renderer = str(self.ctx.info.get("GL_RENDERER", ""))
        if self.samples < 0:  # auto: multisampling costs several times the whole scene on software GL
            self.samples = 0 if is_software_renderer(self.gl_renderer) else 4
        self.renderer = viewer.Renderer(self.ctx, 64, 64, samples=self.samples)

    def add_controller(self, name: str) -> None:
        """A controller appeared (e.g. LMM weights loaded at run time)."""
        if self.ctx is None or name in self.drawings:
            return
        d = CharacterDrawing(self.viewer, self.ctx, self.studio.session.db.parents, COLORS.get(name, (0.8, 0.8, 0.8)))
        self.drawings[name] = d
        self.scene.add(*d.all())

    def set_reference(self, clip) -> None:
        if self.ctx is None:
            self.reference = clip
            return
        if self.reference_skeleton is not None:
            self.scene.remove(self.reference_skeleton)
            self.reference_skeleton.release()
            self.reference_skeleton = None
        self.reference = clip
        if clip is not None:
            self.reference_skeleton = self.viewer.Skeleton(self.ctx, clip.parents, color=(0.7, 0.72, 0.75),
                                                           joint_radius=0.024, bone_radius=0.016)
            self.scene.add(self.reference_skeleton)

    def _ensure_size(self) -> None:
        dpg = self.dpg
        avail = dpg.get_item_rect_size(self.tag)
        pos = dpg.get_item_pos("vp_drawlist") if dpg.does_item_exist("vp_drawlist") else (0, 0)
        w = int(avail[0]) - 16
        h = int(avail[1]) - int(pos[1]) - 8
        w, h = max(w, 64), max(h, 64)
        if (w, h) == self.size:
            return
        self.size = (w, h)
        # the 3D image may be rendered smaller and stretched (--render-scale): its cost is per pixel
        rw, rh = max(int(round(w * self.render_scale)), 16), max(int(round(h * self.render_scale)), 16)
        self.render_size = (rw, rh)
        self.renderer.resize(rw, rh)
        old = self.texture
        self._texture_counter += 1
        self.tex_array = np.zeros((rh, rw, 4), dtype=np.float32)
        self.tex_array[..., 3] = 1.0
        self.texture = f"vp_texture_{self._texture_counter}"
        dpg.add_raw_texture(rw, rh, self.tex_array, format=dpg.mvFormat_Float_rgba, tag=self.texture,
                            parent="studio_textures")
        dpg.configure_item("vp_drawlist", width=w, height=h)
        if dpg.does_item_exist("vp_image"):
            dpg.configure_item("vp_image", texture_tag=self.texture, pmax=(w, h))
        else:
            dpg.draw_image(self.texture, (0, 0), (w, h), uv_min=(0, 1), uv_max=(1, 0), tag="vp_image",
                           parent="vp_drawlist")
            for name in COLORS:
                if not dpg.does_item_exist(f"vp_label_{name}"):
                    dpg.draw_text((0, 0), SHORT.get(name, name), tag=f"vp_label_{name}", parent="vp_drawlist",
                                  size=16, color=tuple(int(c * 255) for c in COLORS.get(name, (1, 1, 1))) + (255,))
            dpg.draw_text((8, 6), "", tag="vp_overlay", parent="vp_drawlist", size=14,
                          color=(230, 230, 230, 220))
            x = 8
            for text, color in LEGEND:
                dpg.draw_text((x, h - 20), text, tag=f"vp_legend_{x}", parent="vp_drawlist", size=13,
                              color=tuple(int(c * 255) for c in color) + (235,))
                self._legend_items.append(f"vp_legend_{x}")
                x += 7 * len(text) + 14
        for item in self._legend_items:
            pos = dpg.get_item_configuration(item)["pos"]
            dpg.configure_item(item, pos=(pos[0], h - 20))
        if old is not None:
            dpg.delete_item(old)

    # -- input ----------------------------------------------------------------------------------
    def on_wheel(self, delta: float) -> None:
        if self.dpg.is_item_hovered("vp_drawlist"):
            self.wheel += float(delta)

    def _mouse(self) -> None:
        dpg = self.dpg
        if self.camera is None:
            return
        mouse = dpg.get_mouse_pos(local=False)
        hovered = dpg.is_item_hovered("vp_drawlist")
        buttons = {"left": dpg.mvMouseButton_Left, "right": dpg.mvMouseButton_Right,
                   "middle": dpg.mvMouseButton_Middle}
        if self.drag is None and hovered:
            for name, b in buttons.items():
                if dpg.is_mouse_button_down(b):
                    self.drag = name
                    self.last_mouse = mouse
                    break
        elif self.drag is not None:
            if not dpg.is_mouse_button_down(buttons[self.drag]):
                self.drag = None
            else:
                dx, dy = mouse[0] - self.last_mouse[0], mouse[1] - self.last_mouse[1]
                self.last_mouse = mouse
                if dx or dy:
                    manager = self.studio.input
                    if self.drag == "left" and manager is not None:
                        # the input layer owns the azimuth (sticks are camera relative): feed it the turn
                        manager.add_camera_orbit(float(np.radians(-dx * 0.4)))
                        self.camera.orbit(0.0, dy)
                    else:
                        self.viewer.apply_drag(self.camera, self.drag, dx, dy, max(self.size[1], 1))
                    if self.drag != "left":
                        self.follow = False
                        dpg.set_value("vp_follow", False)
        if self.wheel:
            self.viewer.apply_scroll(self.camera, self.wheel)
            self.wheel = 0.0

    def turn_camera(self, degrees: float) -> None:
        if self.camera is not None:
            self.camera.yaw_deg = (self.camera.yaw_deg + degrees) % 360.0

    def camera_azimuth(self) -> float:
        """The camera's azimuth in the input convention (0: looking along +Z)."""
        if self.camera is None:
            return 0.0
        return float(np.radians(self.camera.yaw_deg) + np.pi)

    # -- per frame ----------------------------------------------------------------------------
    def offset_of(self, name: str) -> np.ndarray:
        names = list(self.drawings)
        if not self.side_by_side or len(names) < 2:
            return np.zeros(3)
        i = names.index(name) if name in names else 0
        return np.array([SIDE_OFFSET_M * i, 0.0, 0.0])

    def update(self, view: View) -> None:
        if self.renderer is None:
            return
        import time

        self._ensure_size()
        self._mouse()
        session = self.studio.session
        tick = view.tick
        roots = []
        self.drawn = {"tick": view.tick_number, "roots": {}, "offsets": {}}
        self.batch.clear()
        for name, d in self.drawings.items():
            snap = tick.snapshots.get(name) if tick is not None else None
            if snap is None:
                d.hide()
                continue
            off = self.offset_of(name)
            self._update_character(d, name, snap, off, view)
            root = np.asarray(snap.pose.global_positions[0], np.float64) + off
            roots.append(root)
            self.drawn["roots"][name] = [float(x) for x in snap.pose.global_positions[0]]
            self.drawn["offsets"][name] = [float(x) for x in off]
        if self.reference is not None and self.reference_skeleton is not None:
            t = tick.time_s if tick is not None else 0.0
            self.reference_skeleton.update(self.reference.at(t) + np.array([-SIDE_OFFSET_M, 0.0, 0.0]))
        self.batch.flush()
        if roots and self.follow:
            centre = np.mean(roots, axis=0)
            self.camera.follow(centre, blend=0.12 if view.live else 1.0)
        self._labels(view, roots)
        t0 = time.perf_counter()
        self.renderer.render_to(self.scene, self.camera)
        t1 = time.perf_counter()
        self.renderer.read(dtype=np.float32, out=self.tex_array, flip=False)
        t2 = time.perf_counter()
        self.ctx.detect_framebuffer(0).use()
        self.render_ms = (t1 - t0) * 1e3
        self.readback_ms = (t2 - t1) * 1e3

    def _update_character(self, d: CharacterDrawing, name: str, snap, off, view: View) -> None:
        b = self.batch
        pose = snap.pose
        g = np.asarray(pose.global_positions, np.float64)
        d.skeleton.visible = True
        d.skeleton.update(g + off)
        d.ghost.visible = self.show["ghost"]
        if self.show["ghost"]:
            d.ghost.update(np.asarray(snap.matched_pose_positions, np.float64) + off)
        lift = np.array([0.0, 0.02, 0.0])
        # simulation object and its predicted trajectory
        if self.show["trajectory"]:
            sim = np.asarray(snap.simulation_position, np.float64) + off + lift
            traj = np.asarray(snap.trajectory_positions, np.float64) + off + lift
            b.add_polyline(np.vstack([sim[None], traj]), d.traj_color)
            b.add_spheres(traj, 0.045, d.traj_color)
            dirs = quat.to_matrix(np.asarray(snap.trajectory_rotations, np.float64))[..., :, 2] * 0.35  # +Z axis
            b.add_arrows(traj, dirs, d.traj_color)
            b.add_spheres(sim, 0.06, SIM_COLOR)
            sim_dir = quat.to_matrix(np.asarray(snap.simulation_rotation, np.float64))[:, 2] * 0.5
            b.add_arrows(np.array([sim, sim]), np.array([sim_dir, np.asarray(snap.desired_velocity) * 0.25]),
                         SIM_COLOR)
        features = self._features_of(name)
        root_pos, root_rot = g[0], np.asarray(pose.global_rotations[0], np.float64)
        # where the matched frame's own future goes (its features, placed at the character)
        if self.show["matched"] and features is not None:
            m = feature_markers(features, snap.matched_features, root_pos, root_rot, {})
            up = off + np.array([0.0, 0.035, 0.0])
            b.add_spheres(m["traj"] + up, 0.028, MATCHED_COLOR)
            n = min(len(m["traj"]), len(m["traj_dirs"]))
            b.add_arrows(m["traj"][:n] + up, m["traj_dirs"][:n] * 0.28, MATCHED_COLOR)
        # the pose features of the playing frame: foot positions and foot/hip velocities
        if self.show["features"] and features is not None:
            db = self.studio.session.db
            bones = {}
            for ch in features.layout:
                if ch.bone:
                    try:
                        bones[ch.bone] = g[db.bone(ch.bone)]
                    except KeyError:
                        pass
            m = feature_markers(features, snap.current_features, root_pos, root_rot, bones)
            b.add_spheres(m["points"] + off, 0.035, FEATURE_COLOR)
            o, v = m["arrows"]
            b.add_arrows(o + off, v, FEATURE_COLOR)
        if self.show["contacts"]:
            db = self.studio.session.db
            toes = g[[db.bone("left_toe"), db.bone("right_toe")]]
            contacts = np.asarray(snap.foot_contacts, bool)
            locked = np.asarray(snap.foot_locked, bool)
            for i in range(2):
                if contacts[i]:
                    b.add_spheres(toes[i] + off, 0.05, LOCKED_COLOR if locked[i] else CONTACT_COLOR)
        if self.show["trail"]:
            n = int(TRAIL_SECONDS / self.studio.session.dt)
            trail = view.history.window(name, "root_position", view.tick_number, n)
            if trail.ndim == 2:
                trail = trail[np.isfinite(trail).all(axis=1)]
                if len(trail) >= 2:
                    b.add_polyline(trail[::3] + off + np.array([0.0, 0.01, 0.0]), d.trail_color)

    def _features_of(self, name: str):
        c = self.studio.session.controllers.get(name)
        return getattr(c, "features", None) or self.studio.session.features

    def _labels(self, view: View, roots) -> None:
        dpg = self.dpg
        w, h = self.size
        vp = self.camera.view_projection(w / max(h, 1))
        from viewer.camera import project_points

        for name in COLORS:
            tag = f"vp_label_{name}"
            if not dpg.does_item_exist(tag):
                continue
            snap = view.tick.snapshots.get(name) if view.tick is not None and name in self.drawings else None
            if snap is None:
                dpg.configure_item(tag, show=False)
                continue
            head = np.asarray(snap.pose.global_positions, np.float64)[:, 1].argmax()
            p = np.asarray(snap.pose.global_positions[head], np.float64) + self.offset_of(name) + [0, 0.25, 0]
            px, _, front = project_points(p[None], vp, w, h)
            if front[0] and 0 <= px[0, 0] < w and 0 <= px[0, 1] < h:
                label = SHORT.get(name, name) + (" (inspected)" if name == view.inspected and len(self.drawings) > 1 else "")
                dpg.configure_item(tag, show=True, pos=(float(px[0, 0]) - 12, float(px[0, 1]) - 18), text=label)
            else:
                dpg.configure_item(tag, show=False)
        state = "LIVE" if view.live else ("PAUSED" if view.paused else "REWIND")
        t = view.tick.time_s if view.tick is not None else 0.0
        text = f"{state}  tick {view.tick_number}  t={t:6.2f} s"
        if not view.live:
            text += f"   ({(view.tick_number - view.history.newest_tick) * self.studio.session.dt:+.2f} s)"
        dpg.configure_item("vp_overlay", text=text)

    def state(self) -> dict:
        out = dict(self.drawn)
        out["size"] = list(self.size)
        out["render_size"] = list(self.render_size)
        out["side_by_side"] = self.side_by_side
        if self.camera is not None:
            out["camera"] = {"target": [float(x) for x in self.camera.target], "yaw_deg": self.camera.yaw_deg,
                             "distance": self.camera.distance}
        return out
