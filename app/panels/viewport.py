"""3D viewport: both characters, their simulation objects, predicted trajectories, ghosts of the
matched frames, foot contacts and feature markers, drawn by :mod:`viewer` into its own framebuffer
in dearpygui's GL context and copied on the GPU into the OpenGL texture of a dearpygui static texture
(:mod:`app.gl_texture`); where that texture cannot be found (or with ``--readback-3d``) the pixels are
read back into a raw texture instead, which dearpygui uploads again every frame.

Mouse on the image: left-drag orbits, right/middle-drag pans, wheel zooms. The camera follows the
characters unless "Follow" is off. The camera's azimuth has one owner, the input layer (sticks and
keys move the characters relative to it): a drag asks it to turn (``actions.orbit_camera``) and the
camera takes ``view.camera_azimuth`` each frame; pitch, distance and target are the viewport's own. "Side by side" draws the LMM character (and everything of it)
shifted to the right of the MM one; both simulate from the same start with the same input.
Preview ghosts that panels ask for (``Actions.set_preview``: a database frame, a search result) stand
to the left of the inspected character, facing its way, labelled.
"""
from __future__ import annotations

import time

import numpy as np

from ..gl_texture import SharedTexture, marker_image, texture_names
from .base import Panel, PanelContext, View
from .common import COLORS, RAGDOLL_COLOR, SHORT
from .viewport_scene import (LEGEND, CharacterDrawing, CharacterParts, MarkerBatch, Markers, PreviewDrawings,
                             apply_character, character_parts)

FORWARD = np.array([0.0, 0.0, 1.0])
SIDE_OFFSET_M = 1.6
TRAIL_SECONDS = 4.0
_ALL_MARKERS, _RAGDOLL, _HEADS = " markers", " ragdoll", " heads"    # prepared entries beside the controllers' names
LABEL_CHAR_PX, LABEL_HEIGHT_PX = 8.5, 17.0      # a character label's size per character at font size 16
BYTE_TO_UNIT = np.float32(1.0 / 255.0)          # an 8-bit colour channel to the raw texture's 0..1

def yaw_deg_from_azimuth(azimuth: float) -> float:
    """The orbit camera's yaw for an input-layer azimuth (radians; 0 looks along +Z)."""
    return float(np.degrees(azimuth - np.pi)) % 360.0

def separate_labels(anchors: dict, sizes: dict, gap: float = 2.0) -> dict:
    """Screen positions for text labels so that none overlaps another (pure, for tests).

    ``anchors``: name -> (x, y) top-left where a label wants to be; ``sizes``: name -> (w, h). Labels
    are placed top to bottom; one that would overlap a placed label moves down below it.
    """
    placed: dict = {}
    for name in sorted(anchors, key=lambda n: (anchors[n][1], anchors[n][0])):
        x, y = (float(v) for v in anchors[name])
        w, h = sizes[name]
        moved = True
        while moved:
            moved = False
            for other, (ox, oy) in placed.items():
                ow, oh = sizes[other]
                if x < ox + ow and ox < x + w and y < oy + oh + gap and oy < y + h + gap:
                    y = oy + oh + gap
                    moved = True
        placed[name] = (x, y)
    return placed

class ViewportPanel(Panel):
    """The 3D view. GL objects are created in ``init_gl`` after dearpygui's first frame."""
    key = "viewport"

    TOGGLES = (("ghost", "Ghost", True), ("trajectory", "Trajectory", True), ("matched", "Matched traj.", True),
               ("contacts", "Contacts", True), ("features", "Features", True), ("trail", "Trail", True),
               ("sticks", "Sticks", False), ("shadow", "Shadow", True))

    #: frames to wait for dearpygui to make a static texture before reading back instead
    SHARED_TEXTURE_TRIES = 3
    #: an unchanged view is drawn again after this many frames all the same (see _scene_key)
    REDRAW_EVERY = 60

    def __init__(self, ctx: PanelContext, samples: int = -1, render_scale: float = 1.0, readback: bool = False):
        super().__init__(ctx)
        self.gl = None
        self._screen_fbo = None
        self._window_rect = None
        self._resized = True          # the window's size changed (its resize handler) since the last check
        self._size_checks = 0
        self.renderer = None
        self.scene = None
        self.camera = None
        self.drawings: dict[str, CharacterDrawing] = {}
        self.reference = None
        self.followed = None               # the lmm.follow.FollowedTake the characters follow, or None
        self.reference_overlay = False     # followed reference drawn over the inspected character
        self.size = (0, 0)
        self.texture = None
        self.tex_array = None              # the raw texture's pixels (readback path only)
        self._shared = None                # the static texture's SharedTexture (direct path)
        # why the view is read back instead of drawn into dearpygui's texture (None: it is not)
        self.readback_why = "--readback-3d" if readback else None
        self.side_by_side = True
        self.follow = True
        self.show = {k: v for k, _, v in self.TOGGLES}
        self.drag = None
        self.last_mouse = None
        self.wheel = 0.0
        self.drawn: dict = {}
        self.render_ms = 0.0
        self.readback_ms = 0.0
        self._render_due = False      # update() placed a new scene that render() has not drawn yet
        self._unread = False          # render() drew a view that finish() has not read yet
        self._drawn_key = None        # _scene_key of the last render
        self._drawn_before = None     # drawn of the last render
        self._unchanged = 0           # frames since then whose view was the same
        self._preview_version = 0     # counts set_preview calls
        self.renders = 0              # views rendered (the state dump's; tests)
        self.gl_error = None
        self._texture_counter = 0
        self._legend_items: list[str] = []
        self._inspected_shown = "mm"
        self.samples = samples             # -1: auto (4x MSAA on a GPU, none on software GL)
        self.render_scale = render_scale   # 3D image resolution / displayed size
        self.render_size = (0, 0)
        self.gl_renderer = ""
        self.previews: dict[str, tuple] = {}   # owner -> PreviewPose tuple (see set_preview)
        self.preview_drawings = None
        self._preview_labels = 0
        self.ragdoll_skeleton = None

    # -- items ------------------------------------------------------------------------------
    def build(self, parent_window_kwargs: dict) -> None:
        dpg = self.dpg
        with self.window(parent_window_kwargs, no_scrollbar=True):
            with dpg.group(horizontal=True):
                dpg.add_text("Inspect:")
                dpg.add_radio_button([SHORT[n] for n in COLORS], tag="vp_inspect", horizontal=True,
                                     default_value=SHORT[self._inspected_shown], callback=self._on_inspect)
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
        # the window's size is asked for only when dearpygui says it changed (a query costs tens of
        # microseconds a frame in a studio of thousands of items), and every CHECK_SIZE_EVERY frames
        with dpg.item_handler_registry(tag="vp_handlers"):
            dpg.add_item_resize_handler(callback=self._on_resize)
        dpg.bind_item_handler_registry(self.tag, "vp_handlers")

    def _on_resize(self, *_):
        self._resized = True

    def _on_inspect(self, sender, value):
        for name in COLORS:
            if SHORT[name] == value:
                self.ctx.actions.set_inspected(name)

    def _on_toggle(self, sender, value, key):
        self.show[key] = bool(value)
        if key in ("sticks", "shadow"):
            for d in self.drawings.values():
                d.set_style(self._style(), self.show["shadow"])
            for sk in (self.reference_skeleton, self.ragdoll_skeleton):
                if sk is not None:
                    sk.style = self._style()
                    sk.shadow = self.show["shadow"]

    def _style(self) -> str:
        return "sticks" if self.show["sticks"] else "capsules"

    def _body_style(self) -> dict:
        return {"names": self.ctx.engine.db.names, "style": self._style(), "shadow": self.show["shadow"]}

    def toggle_follow(self) -> None:
        self.follow = not self.follow
        self.dpg.set_value("vp_follow", self.follow)

    def software_gl(self) -> bool:
        """The 3D view's GL renderer rasterises on the CPU (False when there is no GL context)."""
        from viewer.renderer import is_software_renderer

        return self.gl is not None and is_software_renderer(self.gl)

    def render_info(self) -> str:
        return (f"3D {self.render_size[0]}x{self.render_size[1]} {max(self.samples, 0)}x MSAA, "
                f"{self.view_path()} ({self.gl_renderer[:24]})")

    def view_path(self) -> str:
        """How the 3D view reaches the screen: "direct" (copied on the GPU into dearpygui's texture),
        "readback" (read back and uploaded each frame) or "pending" (looking for the texture)."""
        if self._shared is None:
            return "readback"
        return "direct" if self._shared.fbo is not None else "pending"

    # -- GL -----------------------------------------------------------------------------------
    def init_gl(self) -> None:
        import viewer

        try:
            self.gl = viewer.attach_current_context()
        except Exception as e:
            self.gl_error = f"3D view unavailable: {e}"
            raise
        self.viewer = viewer
        self.scene = viewer.Scene(background=(0.13, 0.14, 0.17))
        self.ground = viewer.Ground(self.gl, size_m=60.0, tile_m=1.0)
        self.scene.add(self.ground)
        parents = self.ctx.engine.db.parents
        for name in self.ctx.engine.controller_names():
            d = CharacterDrawing(viewer, self.gl, parents, COLORS.get(name, (0.8, 0.8, 0.8)), **self._body_style())
            self.drawings[name] = d
            self.scene.add(*d.all())
        self.batch = MarkerBatch(viewer, self.gl)
        self.preview_drawings = PreviewDrawings(viewer, self.gl, self.scene)
        self.scene.add(*self.batch.renderables())
        self.reference_skeleton = None
        # the simulated ragdoll (lmm.physics.ragdoll), a third character beside the two
        self.ragdoll_skeleton = viewer.Skeleton(self.gl, parents, color=RAGDOLL_COLOR, **self._body_style())
        self.ragdoll_skeleton.visible = False
        self.scene.add(self.ragdoll_skeleton)
        self.camera = viewer.OrbitCamera(target=np.array([0.8, 0.8, 0.0]), distance=4.6, yaw_deg=35.0,
                                         pitch_deg=16.0)
        self.gl_renderer = str(self.gl.info.get("GL_RENDERER", ""))
        # auto (None): the renderer picks 4x MSAA on a GPU and none on software GL, where it costs several
        # times the whole scene
        self.renderer = viewer.Renderer(self.gl, 64, 64, samples=None if self.samples < 0 else self.samples)
        self.samples = self.renderer.samples
        if self.readback_why is None:
            self._names, why = texture_names()
            if self._names is None:
                self.readback_why = why

    def add_controller(self, name: str) -> None:
        """A controller appeared (e.g. LMM weights loaded at run time)."""
        if self.gl is None or name in self.drawings:
            return
        d = CharacterDrawing(self.viewer, self.gl, self.ctx.engine.db.parents, COLORS.get(name, (0.8, 0.8, 0.8)),
                             **self._body_style())
        self.drawings[name] = d
        self.scene.add(*d.all())

    def set_preview(self, owner: str, poses) -> None:
        """Show ``poses`` (:class:`app.panels.base.PreviewPose`) as ``owner``'s preview ghosts (replacing
        its earlier ones; an empty tuple removes them)."""
        if poses:
            self.previews[owner] = tuple(poses)
        else:
            self.previews.pop(owner, None)
        self._preview_version += 1

    def preview_poses(self) -> list:
        return [p for owner in sorted(self.previews) for p in self.previews[owner]]

    def set_reference(self, clip) -> None:
        if self.gl is None:
            self.reference = clip
            return
        if self.reference_skeleton is not None:
            self.scene.remove(self.reference_skeleton)
            self.reference_skeleton.release()
            self.reference_skeleton = None
        self.reference = clip
        if clip is not None:
            self.reference_skeleton = self.viewer.Skeleton(self.gl, clip.parents, color=(0.7, 0.72, 0.75),
                                                           names=clip.names, style=self._style(),
                                                           shadow=self.show["shadow"],
                                                           joint_radius=0.024, bone_radius=0.016)
            self.scene.add(self.reference_skeleton)

    def set_followed(self, take) -> None:
        """The reference the characters follow (drawn aligned with them at each tick's aligned frame), or
        None (the reference plays by time, to the left)."""
        self.followed = take

    def reference_pose(self, view: View):
        """Where the reference is drawn for the displayed tick: ``(positions (J, 3), offset (3,), frame)``;
        frame -1 when it plays by time (not followed, or before the first tick)."""
        tick = view.tick
        take = self.followed
        if take is not None and tick is not None:
            name = view.inspected if (view.inspected, "reference_frame") in tick.series else \
                next((n for n, k in tick.series if k == "reference_frame"), None)
            if name is not None:
                frame = int(tick.series[(name, "reference_frame")])
                off = self.offset_of(name) if self.reference_overlay else np.array([-SIDE_OFFSET_M, 0.0, 0.0])
                return take.positions[frame], off, frame
        t = tick.time_s if tick is not None else 0.0
        return self.reference.at(t), np.array([-SIDE_OFFSET_M, 0.0, 0.0]), -1

    CHECK_SIZE_EVERY = 60     # frames between two looks at the window's size without a resize event

    def _ensure_size(self) -> None:
        dpg = self.dpg
        self._size_checks += 1
        if not self._resized and self.texture is not None and self._size_checks % self.CHECK_SIZE_EVERY:
            return
        self._resized = False
        avail = dpg.get_item_rect_size(self.tag)
        # the drawing's place in the window moves only when the window's size does (its toolbar wraps)
        if avail == self._window_rect and self.texture is not None:
            return
        self._window_rect = avail
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
        old, old_shared = self.texture, self._shared
        self._texture_counter += 1
        self.texture = f"vp_texture_{self._texture_counter}"
        self._shared = None
        if self.readback_why is None:
            # a static texture dearpygui makes during this frame and never writes again: finish fills
            # it with this frame's picture first, the view is copied into it from the next frame on
            marker = marker_image(rw, rh, self.scene.background, self._texture_counter)
            dpg.add_static_texture(rw, rh, marker.ravel(), tag=self.texture, parent="texture_registry")
            self.tex_array = self._read_bytes = None
            try:
                self._shared = SharedTexture(self.gl, self._names, rw, rh, marker)
            except Exception as e:      # a GL library that does not answer: read back instead
                self._give_up_shared(f"texture names not readable: {e}")
        else:
            self.tex_array = np.zeros((rh, rw, 4), dtype=np.float32)
            self.tex_array[..., 3] = 1.0
            self._read_bytes = np.zeros((rh, rw, 4), dtype=np.uint8)
            dpg.add_raw_texture(rw, rh, self.tex_array, format=dpg.mvFormat_Float_rgba, tag=self.texture,
                                parent="texture_registry")
        dpg.configure_item("vp_drawlist", width=w, height=h)
        if dpg.does_item_exist("vp_image"):
            dpg.configure_item("vp_image", texture_tag=self.texture, pmax=(w, h))
        else:
            dpg.draw_image(self.texture, (0, 0), (w, h), uv_min=(0, 1), uv_max=(1, 0), tag="vp_image",
                           parent="vp_drawlist")
            dpg.draw_text((0, 0), "", tag="vp_label_ragdoll", parent="vp_drawlist", size=16,
                          color=tuple(int(c * 255) for c in RAGDOLL_COLOR) + (255,))
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
        if old_shared is not None:
            old_shared.release()
        if old is not None:
            dpg.delete_item(old)

    def _fill_new_texture(self, marker_row: np.ndarray) -> None:
        """The static texture added this frame is made by dearpygui later in the frame, from its value:
        make that value this frame's picture (read back once, with the marker in its first texels), so
        a new texture (a resize, a window being dragged) never shows an empty view."""
        image = self._read_view()
        image[0, :len(marker_row)] = marker_row
        self.dpg.set_value(self.texture, image.ravel())

    def _read_view(self, byte_buf: np.ndarray | None = None, out: np.ndarray | None = None) -> np.ndarray:
        """The rendered view as float32 RGBA in 0..1, OpenGL's row order (into ``out`` when given, via
        ``byte_buf``). Bytes read and scaled here: several times cheaper than the driver's float read on
        software GL, and the same numbers (x * float32(1/255) is what llvmpipe computes)."""
        pixels = self.renderer.read(dtype=np.uint8, out=byte_buf, flip=False)
        return np.multiply(pixels, BYTE_TO_UNIT, out=out, dtype=np.float32)

    def _give_up_shared(self, why: str) -> None:
        """Read the view back from now on (``why``: shown in the stats); the texture is remade as a raw
        texture on the next update."""
        self.readback_why = why
        if self._shared is not None:
            self._shared.release()
            self._shared = None
        self._window_rect = None
        self._resized = True
        self.size = (0, 0)

    # -- input ----------------------------------------------------------------------------------
    def on_wheel(self, delta: float) -> None:
        if self.dpg.is_item_hovered("vp_drawlist"):
            self.wheel += float(delta)

    def _mouse(self) -> None:
        dpg = self.dpg
        if self.camera is None:
            return
        mouse = dpg.get_mouse_pos(local=False)
        buttons = {"left": dpg.mvMouseButton_Left, "right": dpg.mvMouseButton_Right,
                   "middle": dpg.mvMouseButton_Middle}
        if self.drag is None:
            # a drag starts with a button down over the view (hovering is asked only then: a query of
            # an item costs tens of microseconds)
            down = next((name for name, b in buttons.items() if dpg.is_mouse_button_down(b)), None)
            if down is not None and dpg.is_item_hovered("vp_drawlist"):
                self.drag = down
                self.last_mouse = mouse
        else:
            if not dpg.is_mouse_button_down(buttons[self.drag]):
                self.drag = None
            else:
                dx, dy = mouse[0] - self.last_mouse[0], mouse[1] - self.last_mouse[1]
                self.last_mouse = mouse
                if dx or dy:
                    if self.drag == "left":
                        # the input layer owns the azimuth (sticks are camera relative): ask it to turn
                        self.ctx.actions.orbit_camera(float(np.radians(-dx * 0.4)))
                        self.camera.orbit(0.0, dy)
                    else:
                        self.viewer.apply_drag(self.camera, self.drag, dx, dy, max(self.size[1], 1))
                    if self.drag != "left":
                        self.follow = False
                        dpg.set_value("vp_follow", False)
        if self.wheel:
            self.viewer.apply_scroll(self.camera, self.wheel)
            self.wheel = 0.0

    # -- per frame ----------------------------------------------------------------------------
    def offset_of(self, name: str) -> np.ndarray:
        names = list(self.drawings)
        if not self.side_by_side or len(names) < 2:
            return np.zeros(3)
        i = names.index(name) if name in names else 0
        return np.array([SIDE_OFFSET_M * i, 0.0, 0.0])

    def prepare_key(self, view: View) -> tuple:
        return (tuple(self.drawings), tuple(sorted(self.show.items())), self.side_by_side,
                tuple(sorted(view.ragdoll.items())), self.ragdoll_skeleton is not None,
                self.reference is not None and self.reference_skeleton is not None)

    def prepare(self, view: View) -> dict:
        """Each shown character's skeleton, ghost and markers at the view's tick (see
        :func:`character_parts`): the numpy share of :meth:`update`, safe on the tick worker."""
        out = {}
        tick = view.tick
        if self.renderer is None or tick is None:
            return out
        heads = {}
        for name, d in self.drawings.items():
            snap = tick.snapshots.get(name)
            if snap is not None:
                out[name] = self._character_parts(d, name, snap, self.offset_of(name), view)
                heads[name] = self._label_anchor(name, snap)
        out[_HEADS] = heads
        # every character's markers joined in drawing order: what update adds when it uses them all
        out[_ALL_MARKERS] = self._all_markers(p.markers for p in out.values() if isinstance(p, CharacterParts))
        ragdoll = self.ragdoll_pose(view) if self.ragdoll_skeleton is not None else None
        if ragdoll is not None:
            name, positions, off = ragdoll
            out[_RAGDOLL] = (name, positions, off, self.ragdoll_skeleton.prepare(positions + off))
        return out

    def update(self, view: View, prepared: dict | None = None) -> None:
        if self.renderer is None:
            return
        self._ensure_size()
        if view.inspected != self._inspected_shown:
            self._inspected_shown = view.inspected
            self.dpg.set_value("vp_inspect", SHORT.get(view.inspected, view.inspected))
        self._mouse()
        self.camera.yaw_deg = yaw_deg_from_azimuth(view.camera_azimuth)
        tick = view.tick
        roots = []
        self.drawn = {"tick": view.tick_number, "roots": {}, "offsets": {}}
        self.batch.clear()
        all_prepared = prepared is not None and _ALL_MARKERS in prepared
        markers = []
        for name, d in self.drawings.items():
            snap = tick.snapshots.get(name) if tick is not None else None
            if snap is None:
                d.hide()
                continue
            off = self.offset_of(name)
            parts = prepared.get(name) if prepared is not None else None
            all_prepared = all_prepared and parts is not None
            parts = parts or self._character_parts(d, name, snap, off, view)
            apply_character(d, parts)
            markers.append(parts.markers)
            root = np.asarray(snap.pose.global_positions[0], np.float64) + off
            roots.append(root)
            self.drawn["roots"][name] = [float(x) for x in snap.pose.global_positions[0]]
            self.drawn["offsets"][name] = [float(x) for x in off]
        self.batch.extend(prepared[_ALL_MARKERS] if all_prepared else self._all_markers(markers))
        if self.reference is not None and self.reference_skeleton is not None:
            positions, off, frame = self.reference_pose(view)
            self.reference_skeleton.update(positions + off)
            self.drawn["reference"] = {"frame": frame, "root": [float(x) for x in positions[0]],
                                       "offset": [float(x) for x in off]}
            if frame >= 0:       # the camera keeps the reference in view with the characters
                self.drawn["reference"]["root_path"] = [float(x) for x in self.followed.root_at(view.tick_number)]
                roots.append(np.asarray(positions[0], np.float64) + off)
        self._update_ragdoll(view, roots, None if prepared is None else prepared.get(_RAGDOLL))
        self._update_previews(view, roots)
        self.batch.flush()
        if roots and self.follow:
            n = len(roots)     # their mean, in plain floats (numpy's mean of a few rows costs 10-20 us)
            centre = [sum(float(r[i]) for r in roots) / n for i in range(3)]
            self.camera.follow(centre, blend=0.12 if view.live else 1.0)
        self._labels(view, roots, None if prepared is None else prepared.get(_HEADS))
        self.readback_ms = 0.0
        self.render_ms = 0.0
        key = self._scene_key(view)
        if key == self._drawn_key and self._unchanged < self.REDRAW_EVERY and self._same_drawn():
            # the same picture (paused, nothing moved): the texture still holds it
            self._unchanged += 1
            return
        self._drawn_key, self._drawn_before, self._unchanged = key, self.drawn, 0
        self._render_due = True

    def render(self) -> None:
        """Draw the scene :meth:`update` placed, when it differs from the last one drawn. The studio calls
        it after the other panels' updates, then :meth:`finish`: on software GL the driver rasterises on
        its own threads from here until the copy, and Python run meanwhile shares the cores with it
        (panels measured 1.23 ms a frame that way against 0.86 ms before the render, and the frame was
        shorter too: ``bench/bench_studio.py``, README)."""
        if not self._render_due:
            return
        self._render_due = False
        t0 = time.perf_counter()
        self.renderer.render_to(self.scene, self.camera)
        self.render_ms = (time.perf_counter() - t0) * 1e3
        self.renders += 1
        self._unread = True

    def _same_drawn(self) -> bool:
        """``drawn`` equals the last render's (plain numbers and lists; anything that cannot be compared
        counts as changed)."""
        try:
            return bool(self.drawn == self._drawn_before)
        except (TypeError, ValueError):
            return False

    def _scene_key(self, view: View) -> tuple:
        """What the 3D picture is made from, besides what was placed where (``drawn``, a new dict each
        frame, compared apart: characters, reference, ragdoll, previews, labels): the displayed tick (its
        snapshots, markers, ragdoll, trail), the camera, the toggles, the inspected character, the
        previews and the texture (a new one with every size). An equal key and ``drawn`` is an equal
        picture, so a paused, untouched view is not drawn again (on software GL that is most of a frame);
        as a safety net it is drawn again every :attr:`REDRAW_EVERY` frames."""
        cam = self.camera
        t = cam.target
        return (id(view.tick), view.tick_number, view.inspected,
                (float(t[0]), float(t[1]), float(t[2]), cam.distance, cam.yaw_deg, cam.pitch_deg, cam.fov_y_deg),
                tuple(self.show.items()), self.side_by_side, self.reference_overlay, self._preview_version,
                self.texture)    # a new texture tag with every new size

    def finish(self) -> None:
        """Put the 3D view drawn by :meth:`render` into the texture dearpygui shows: a copy on the GPU
        into dearpygui's own texture, or (readback path) a read into the raw texture's array. Does
        nothing when nothing new was rendered."""
        shared = self._shared
        found = False
        if shared is not None and shared.fbo is None:
            # also on frames that drew nothing new: the last picture is still in the renderer's framebuffer
            try:
                if shared.tries == 0 and self._unread:
                    self._fill_new_texture(shared.marker_row)
                found = shared.find()
                if not found and shared.tries >= self.SHARED_TEXTURE_TRIES:
                    self._give_up_shared(f"dearpygui's texture not found in {shared.tries} frames")
            except Exception as e:      # a GL error while looking: read back instead
                self._give_up_shared(f"dearpygui's texture not usable: {e}")
        if not (self._unread or found):
            return
        self._unread = False
        t1 = time.perf_counter()
        if self._shared is not None and self._shared.fbo is not None:
            self.gl.copy_framebuffer(self._shared.fbo, self.renderer.fbo)
        elif self.tex_array is not None:
            self._read_view(self._read_bytes, self.tex_array)
        if self._screen_fbo is None:     # dearpygui's own framebuffer: the same one every frame
            self._screen_fbo = self.gl.detect_framebuffer(0)
        self._screen_fbo.use()
        self.readback_ms = (time.perf_counter() - t1) * 1e3

    def ragdoll_pose(self, view: View):
        """The ragdoll the 3D view draws at the displayed tick: ``(controller, positions (J, 3), offset (3,))``,
        or None. It stands beside the characters, to the left of the first one (further left when a
        reference clip stands there)."""
        tick = view.tick
        poses = tick.extra.get("ragdoll") if tick is not None else None
        if not poses:
            return None
        name = view.ragdoll.get("drawn", "mm")
        if name not in poses:
            name = next(iter(poses))
        slots = 2 if self.reference is not None and self.reference_skeleton is not None else 1
        off = np.array([-SIDE_OFFSET_M * slots, 0.0, 0.0])
        return name, np.asarray(poses[name], np.float64), off

    def _update_ragdoll(self, view: View, roots: list, prepared=None) -> None:
        sk = self.ragdoll_skeleton
        if prepared is not None and sk is not None:
            name, positions, off, pose = prepared
        else:
            drawn = self.ragdoll_pose(view) if sk is not None else None
            if drawn is None:
                if sk is not None:
                    sk.visible = False
                self.drawn["ragdoll"] = None
                return
            name, positions, off = drawn
            pose = positions + off
        sk.visible = True
        sk.update(pose)
        roots.append(positions[0] + off)
        self.drawn["ragdoll"] = {"controller": name, "root": [float(x) for x in positions[0]],
                                 "offset": [float(x) for x in off]}

    def _update_previews(self, view: View, roots: list) -> None:
        poses = self.preview_poses()
        snap = view.snap() if poses else None
        if not poses:
            anchor_pos = anchor_rot = None     # nothing to place (the drawings hide what they showed)
        elif snap is not None:
            # the inspected character's place without its side-by-side shift: left of the first character
            anchor_pos = np.asarray(snap.simulation_position, np.float64)
            anchor_rot = np.asarray(snap.simulation_rotation, np.float64)
        else:
            anchor_pos, anchor_rot = np.zeros(3), np.array([1.0, 0.0, 0.0, 0.0])
        drawn = self.preview_drawings.update(poses, self.batch, anchor_pos, anchor_rot, self._style(),
                                             self.show["shadow"]) if self.preview_drawings else []
        self.drawn["previews"] = drawn
        if drawn and roots:   # the camera keeps the first ghost in view with the characters
            roots.append(np.asarray(drawn[0]["root"]))

    def _character_parts(self, d: CharacterDrawing, name: str, snap, off, view: View):
        trail = None
        if self.show["trail"]:
            n = int(TRAIL_SECONDS / self.ctx.engine.dt)
            trail = view.history.window(name, "root_position", view.tick_number, n)
        return character_parts(d, snap, off, self.show, self._features_of(name), self.ctx.engine.db, trail)

    def _all_markers(self, markers) -> Markers:
        """The characters' markers joined in drawing order, with their arrows' geometry."""
        joined = Markers()
        for m in markers:
            joined.extend(m)
        return self.batch.prepare_arrows(joined)

    def _features_of(self, name: str):
        return self.ctx.engine.features_of(name)

    def _label_anchor(self, name: str, snap) -> np.ndarray:
        """Where a character's name label hangs: above its highest joint."""
        g = np.asarray(snap.pose.global_positions, np.float64)
        return g[g[:, 1].argmax()] + self.offset_of(name) + [0, 0.25, 0]

    def _labels(self, view: View, roots, heads: dict | None = None) -> None:
        """Name labels over the characters' (and the ragdoll's and the preview ghosts') heads, and the
        overlay line. Only changed label options reach dearpygui (positions move, texts rarely do)."""
        dpg = self.dpg
        cache = self.text
        w, h = self.size
        vp = self.camera.view_projection_rows(w / max(h, 1))
        from viewer.camera import project_points_floats

        # every label's anchor above a head, projected in one call
        wanted = []     # (label key, item tag, text, world point)
        for name in COLORS:
            tag = f"vp_label_{name}"
            snap = view.tick.snapshots.get(name) if view.tick is not None and name in self.drawings else None
            if snap is None:
                cache.configure(tag, show=False)
                continue
            text = SHORT.get(name, name) + (" (inspected)" if name == view.inspected and len(self.drawings) > 1 else "")
            head = heads.get(name) if heads is not None else None
            wanted.append((name, tag, text, self._label_anchor(name, snap) if head is None else head))
        rag = self.drawn.get("ragdoll")
        if rag is not None:
            _, positions, off = self.ragdoll_pose(view)
            hx, hy, hz = positions[int(np.argmax(positions[:, 1]))].tolist()   # the highest joint, floats
            ox, oy, oz = off.tolist()
            wanted.append(("ragdoll", "vp_label_ragdoll",
                           f"ragdoll ({SHORT.get(rag['controller'], rag['controller'])})",
                           (hx + ox, hy + oy + 0.25, hz + oz)))
        else:
            cache.configure("vp_label_ragdoll", show=False)
        previews = self.drawn.get("previews", [])
        for i, p in enumerate(previews):
            tag = f"vp_preview_label_{i}"
            if i >= self._preview_labels:
                dpg.draw_text((0, 0), "", tag=tag, parent="vp_drawlist", size=15,
                              color=(150, 240, 150, 255))
                self._preview_labels = i + 1
            wanted.append((tag, tag, p["label"], np.asarray(p["head"], np.float64) + [0, 0.25, 0]))
        for i in range(len(previews), self._preview_labels):
            cache.configure(f"vp_preview_label_{i}", show=False)
        anchors, sizes, texts, tags = {}, {}, {}, {}
        if wanted:
            for (key, tag, text, _), (x, y, ok) in zip(wanted, project_points_floats([wt[3] for wt in wanted],
                                                                                     vp, w, h)):
                if ok and 0 <= x < w and 0 <= y < h:
                    texts[key], tags[key] = text, tag
                    anchors[key] = (float(x) - 12, float(y) - 18)
                    sizes[key] = (LABEL_CHAR_PX * len(text), LABEL_HEIGHT_PX)
                else:
                    cache.configure(tag, show=False)
        placed = separate_labels(anchors, sizes)
        for key, pos in placed.items():
            cache.configure(tags[key], show=True, pos=pos, text=texts[key])
        self.drawn["labels"] = {n: [float(pos[0]), float(pos[1]), *map(float, sizes[n])] for n, pos in placed.items()}
        state = view.mode
        t = view.tick.time_s if view.tick is not None else 0.0
        text = f"{state}  tick {view.tick_number}  t={t:6.2f} s"
        if not view.live:
            text += f"   ({(view.tick_number - view.history.newest_tick) * self.ctx.engine.dt:+.2f} s)"
        cache.configure("vp_overlay", text=text)

    def state(self) -> dict:
        out = dict(self.drawn)
        out["size"] = list(self.size)
        out["render_size"] = list(self.render_size)
        out["view_path"] = self.view_path()
        out["gl_renderer"] = self.gl_renderer
        out["renders"] = self.renders
        out["readback_why"] = self.readback_why
        out["side_by_side"] = self.side_by_side
        if self.camera is not None:
            out["camera"] = {"target": [float(x) for x in self.camera.target], "yaw_deg": self.camera.yaw_deg,
                             "distance": self.camera.distance}
        return out
