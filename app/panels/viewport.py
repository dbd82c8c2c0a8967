"""3D viewport: the scene assembled each frame from the displayed tick: both characters, their simulation
objects, predicted trajectories, ghosts of the matched frames, foot contacts and feature markers
(:mod:`.viewport_scene`, :mod:`.viewport_markers`), the reference clip the session holds, the ragdoll,
the preview ghosts (:mod:`.viewport_previews`) and the labels (:mod:`.viewport_labels`). The camera and
the mouse input that moves it are :mod:`.viewport_camera`; how the picture reaches dearpygui's texture
is :mod:`.viewport_texture`.

"Side by side" draws the LMM character (and everything of it) shifted to the right of the MM one; both
simulate from the same start with the same input. Preview ghosts that panels ask for
(``Actions.set_preview``: a database frame, a search result) stand to the left of the inspected
character, facing its way, labelled.
"""
from __future__ import annotations

import time

import numpy as np

from lmm.skeleton import body_radii

from .base import Panel, PanelContext, View
from .common import COLORS, RAGDOLL_COLOR, SHORT
from .viewport_camera import CameraControl, drawn_root
from .viewport_figures import RAGDOLL_HELP, RagdollFigure, ReferenceFigure, ragdoll_shown
from .viewport_labels import Labels
from .viewport_markers import MarkerBatch, Markers
from .viewport_previews import PreviewDrawings, Previews
from .viewport_scene import Characters, CharacterParts
from .viewport_texture import ViewTexture

_ALL_MARKERS, _RAGDOLL, _HEADS = " markers", " ragdoll", " heads"    # prepared entries beside the controllers' names


class ViewportPanel(Panel):
    """The 3D view. GL objects are created in ``init_gl`` after dearpygui's first frame."""
    key = "viewport"
    commands = ("inspect", "orbit_camera")

    TOGGLES = (("ghost", "Ghost", True), ("trajectory", "Trajectory", True), ("matched", "Matched traj.", True),
               ("contacts", "Contacts", True), ("features", "Features", True), ("trail", "Trail", True),
               ("sticks", "Sticks", False), ("shadow", "Shadow", True))

    #: an unchanged view is drawn again after this many frames all the same (see _scene_key)
    REDRAW_EVERY = 60

    def __init__(self, ctx: PanelContext, samples: int = -1, render_scale: float = 1.0, readback: bool = False):
        super().__init__(ctx)
        self.gl = None
        self._window_rect = None
        self._resized = True          # the window's size changed (its resize handler) since the last check
        self._size_checks = 0
        self.renderer = None
        self.scene = None
        self.cam: CameraControl | None = None      # the camera and its mouse input (made in init_gl)
        self.tex = ViewTexture(ctx.dpg, readback)  # the texture the picture is shown in
        self.labels = Labels(ctx.dpg, self.text, "vp_drawlist")
        self.characters = Characters(ctx.engine)   # the controllers' characters (drawn with GL)
        self.reference = ReferenceFigure()   # the session's reference clip, drawn
        self.ragdoll: RagdollFigure | None = None   # made with GL
        self.size = (0, 0)
        self._follow = True                # the camera follows the characters (before init_gl: see follow)
        self.show = {k: v for k, _, v in self.TOGGLES}
        self.show["ragdoll"] = False       # the physics ragdoll's figure: see ragdoll_shown
        self.drawn: dict = {}
        self.render_ms = 0.0
        self._render_due = False      # update() placed a new scene that render() has not drawn yet
        self._drawn_key = None        # _scene_key of the last render
        self._drawn_before = None     # drawn of the last render
        self._unchanged = 0           # frames since then whose view was the same
        self.renders = 0              # views rendered (the state dump's; tests)
        self.gl_error = None
        self._inspected_shown = "mm"
        self.samples = samples             # -1: auto (4x MSAA on a GPU, none on software GL)
        self.render_scale = render_scale   # 3D image resolution / displayed size
        self.render_size = (0, 0)
        self.gl_renderer = ""
        self.previews = Previews()         # the preview ghosts panels ask for

    @property
    def follow(self) -> bool:
        return self.cam.follow if self.cam is not None else self._follow

    @follow.setter
    def follow(self, on: bool) -> None:
        self._follow = bool(on)
        if self.cam is not None:
            self.cam.follow = self._follow

    @property
    def reference_overlay(self) -> bool:
        """A followed reference is drawn over the inspected character (else to the characters' left)."""
        return self.reference.overlay

    @reference_overlay.setter
    def reference_overlay(self, on: bool) -> None:
        self.reference.overlay = bool(on)

    # -- items ------------------------------------------------------------------------------
    def build(self, parent_window_kwargs: dict) -> None:
        dpg = self.dpg
        # the wheel over the view zooms the camera: it never scrolls the window (the toolbar stays in view)
        with self.window(parent_window_kwargs, no_scrollbar=True, no_scroll_with_mouse=True):
            with dpg.group(horizontal=True):
                dpg.add_text("Inspect:")
                dpg.add_radio_button([SHORT[n] for n in COLORS], tag="vp_inspect", horizontal=True,
                                     default_value=SHORT[self._inspected_shown], callback=self._on_inspect)
                dpg.add_checkbox(label="Side by side", tag="vp_side", default_value=self.characters.side_by_side,
                                 callback=lambda s, a: setattr(self.characters, "side_by_side", bool(a)))
                dpg.add_checkbox(label="Follow", tag="vp_follow", default_value=self.follow,
                                 callback=lambda s, a: setattr(self, "follow", bool(a)))
                dpg.add_checkbox(label="Ragdoll", tag="vp_show_ragdoll", default_value=self.show["ragdoll"],
                                 callback=self._on_toggle, user_data="ragdoll")
                dpg.add_text(RAGDOLL_HELP, parent=dpg.add_tooltip("vp_show_ragdoll"))
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
                self.ctx.actions.inspect(name)

    def _on_toggle(self, sender, value, key):
        self.show[key] = bool(value)
        if key in ("sticks", "shadow"):
            for d in self.characters.drawings.values():
                d.set_style(self._style(), self.show["shadow"])
            for sk in (self.reference.skeleton, self.ragdoll and self.ragdoll.skeleton):
                if sk is not None:
                    sk.style = self._style()
                    sk.shadow = self.show["shadow"]

    def _style(self) -> str:
        return "sticks" if self.show["sticks"] else "capsules"

    def _body_style(self) -> dict:
        names = self.ctx.engine.db.names
        return {"names": names, "body_radii": body_radii(names), "style": self._style(), "shadow": self.show["shadow"]}

    def toggle_follow(self) -> None:
        self.follow = not self.follow
        self.dpg.set_value("vp_follow", self.follow)

    def on_wheel(self, delta: float) -> None:
        if self.cam is not None:
            self.cam.on_wheel(delta)

    def software_gl(self) -> bool:
        """The 3D view's GL renderer rasterises on the CPU (False when there is no GL context)."""
        from viewer.renderer import is_software_renderer

        return self.gl is not None and is_software_renderer(self.gl)

    def render_info(self) -> str:
        return (f"3D {self.render_size[0]}x{self.render_size[1]} {max(self.samples, 0)}x MSAA, "
                f"{self.view_path()} ({self.gl_renderer[:24]})")

    def view_path(self) -> str:
        """How the 3D view reaches the screen (see :meth:`ViewTexture.path`)."""
        return self.tex.path()

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
            self.characters.add(viewer, self.gl, self.scene, name, COLORS.get(name, (0.8, 0.8, 0.8)),
                                self._body_style())
        self.batch = MarkerBatch(viewer, self.gl)
        self.previews.drawings = PreviewDrawings(viewer, self.gl, self.scene)
        self.scene.add(*self.batch.renderables())
        # the simulated ragdoll (lmm.physics.ragdoll), a third character beside the two
        self.ragdoll = RagdollFigure(viewer.Skeleton(self.gl, parents, color=RAGDOLL_COLOR, **self._body_style()))
        self.scene.add(self.ragdoll.skeleton)
        self.cam = CameraControl(viewer, self.dpg, self.ctx.actions.orbit_camera, "vp_drawlist", "vp_follow")
        self.cam.follow = self._follow
        self.gl_renderer = str(self.gl.info.get("GL_RENDERER", ""))
        # auto (None): the renderer picks 4x MSAA on a GPU and none on software GL, where it costs several
        # times the whole scene
        self.renderer = viewer.Renderer(self.gl, 64, 64, samples=None if self.samples < 0 else self.samples)
        self.samples = self.renderer.samples
        self.tex.attach(self.gl, self.renderer)

    def add_controller(self, name: str) -> None:
        """A controller appeared (e.g. LMM weights loaded at run time)."""
        if self.gl is None or name in self.characters.drawings:
            return
        self.characters.add(self.viewer, self.gl, self.scene, name, COLORS.get(name, (0.8, 0.8, 0.8)),
                            self._body_style())

    def set_preview(self, owner: str, poses) -> None:
        """Show ``poses`` (:class:`app.panels.base.PreviewPose`) as ``owner``'s preview ghosts (replacing
        its earlier ones; an empty tuple removes them)."""
        self.previews.set(owner, poses)

    def set_reference(self, clip) -> None:
        """Draw the session's reference clip (:attr:`app.session.Session.reference`; None: none)."""
        if self.gl is None:
            self.reference.clip = clip
            return
        self.reference.set_clip(clip, self.viewer, self.gl, self.scene, self._style(), self.show["shadow"])

    def set_followed(self, take) -> None:
        """The reference the characters follow (drawn aligned with them at each tick's aligned frame), or
        None (the reference plays by time, to the left)."""
        self.reference.followed = take

    CHECK_SIZE_EVERY = 60     # frames between two looks at the window's size without a resize event

    def _ensure_size(self) -> None:
        dpg = self.dpg
        self._size_checks += 1
        if not self._resized and self.tex.tag is not None and self._size_checks % self.CHECK_SIZE_EVERY:
            return
        self._resized = False
        avail = dpg.get_item_rect_size(self.tag)
        # the drawing's place in the window moves only when the window's size does (its toolbar wraps)
        if avail == self._window_rect and self.tex.tag is not None:
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
        if self.tex.show(w, h, rw, rh, self.scene.background, "vp_drawlist"):
            self.labels.create(h)       # the text over the image, made with the first one
        if self.tex.remake_due:         # no shared texture after all: a raw one on the next update
            self._remake_texture()
        self.labels.keep_legend_at_bottom(h)

    def _remake_texture(self) -> None:
        """The texture is remade (as a raw one) on the next update: the shared one was given up."""
        self.tex.remake_due = False
        self._window_rect = None
        self._resized = True
        self.size = (0, 0)

    # -- per frame ----------------------------------------------------------------------------
    def offset_of(self, name: str) -> np.ndarray:
        return self.characters.offset_of(name)

    def prepare_key(self, view: View) -> tuple:
        return (tuple(self.characters.drawings), tuple(sorted(self.show.items())), self.characters.side_by_side,
                tuple(sorted(view.ragdoll.items())), self.ragdoll is not None, self.reference.shown,
                ragdoll_shown(self.show, view))

    def prepare(self, view: View) -> dict:
        """Each shown character's skeleton, ghost and markers at the view's tick (see
        :func:`character_parts`): the numpy share of :meth:`update`, safe on the tick worker."""
        out = {}
        tick = view.tick
        if self.renderer is None or tick is None:
            return out
        heads = {}
        for name in self.characters.drawings:
            snap = tick.snapshots.get(name)
            if snap is not None:
                out[name] = self.characters.parts(name, snap, view, self.show)
                heads[name] = self.characters.label_anchor(name, snap)
        out[_HEADS] = heads
        # every character's markers joined in drawing order: what update adds when it uses them all
        out[_ALL_MARKERS] = self._all_markers(p.markers for p in out.values() if isinstance(p, CharacterParts))
        ragdoll = (self.ragdoll.prepare(view, self.reference.shown)
                   if self.ragdoll is not None and ragdoll_shown(self.show, view) else None)
        if ragdoll is not None:
            out[_RAGDOLL] = ragdoll
        return out

    def update(self, view: View, prepared: dict | None = None) -> None:
        if self.renderer is None:
            return
        self._ensure_size()
        if view.inspected != self._inspected_shown:
            self._inspected_shown = view.inspected
            self.dpg.set_value("vp_inspect", SHORT.get(view.inspected, view.inspected))
        self.cam.mouse(self.size[1])
        roots = []
        self.drawn = {"tick": view.tick_number, "roots": {}, "offsets": {}}
        self.batch.clear()
        markers = self.characters.update(view, self.show, prepared, self.drawn, roots)
        all_prepared = markers is None and prepared is not None and _ALL_MARKERS in prepared
        self.batch.extend(prepared[_ALL_MARKERS] if all_prepared else self._all_markers(markers or []))
        self.reference.update(view, self.offset_of, self.drawn, roots)
        self.ragdoll.update(view, self.reference.shown, self.drawn, roots,
                            None if prepared is None else prepared.get(_RAGDOLL), ragdoll_shown(self.show, view))
        self.drawn["previews"] = self.previews.update(view, self.batch, self._style(), self.show["shadow"], roots)
        self.batch.flush()
        self.cam.aim(view.camera_azimuth, roots, view.live, drawn_root(self.drawn, view.inspected))
        ragdoll = self.drawn.get("ragdoll")
        self.drawn["labels"] = self.labels.update(
            view, self.characters, None if prepared is None else prepared.get(_HEADS),
            None if ragdoll is None else (ragdoll["controller"], self.ragdoll.head(view, self.reference.shown)),
            self.drawn.get("previews", []), self.cam.camera, self.size, self.ctx.engine.dt)
        self.tex.readback_ms = 0.0
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
        self.renderer.render_to(self.scene, self.cam.camera)
        self.render_ms = (time.perf_counter() - t0) * 1e3
        self.renders += 1
        self.tex.unread = True

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
        return (id(view.tick), view.tick_number, view.inspected, self.cam.key(),
                tuple(self.show.items()), self.characters.side_by_side, self.reference_overlay, self.previews.version,
                self.tex.tag)    # a new texture tag with every new size

    def finish(self) -> None:
        """Put the 3D view drawn by :meth:`render` into the texture dearpygui shows (see
        :meth:`ViewTexture.finish`)."""
        self.tex.finish()
        if self.tex.remake_due:
            self._remake_texture()

    @property
    def readback_ms(self) -> float:
        return self.tex.readback_ms

    def _all_markers(self, markers) -> Markers:
        """The characters' markers joined in drawing order, with their arrows' geometry."""
        joined = Markers()
        for m in markers:
            joined.extend(m)
        return self.batch.prepare_arrows(joined)

    def state(self) -> dict:
        out = dict(self.drawn)
        out["size"] = list(self.size)
        out["render_size"] = list(self.render_size)
        out["view_path"] = self.view_path()
        out["gl_renderer"] = self.gl_renderer
        out["renders"] = self.renders
        out["readback_why"] = self.tex.readback_why
        out["side_by_side"] = self.characters.side_by_side
        if self.cam is not None:
            out["camera"] = self.cam.state()
        return out
