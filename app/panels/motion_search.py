"""Motion Search: find the motion most like an example in a manifest's takes or a folder of BVH files.

The example is either the last seconds of the inspected character ending at the displayed tick (so it
follows the tick picked on the timeline while paused), or a frame range of any BVH file. Search runs the
engine's :mod:`lmm.motion_search.index` (cached index, exact k-NN, DTW re-ranking) and lists the results
(file, frames in the file's own numbering, distance); selecting a row plays that match as a preview ghost
in the 3D view, looping. The index is built (or read from its cache) and searched as a background job
(:mod:`app.jobs`): the studio keeps drawing and the panel's status line says what is being done. Bad input (joints that cannot be matched, an empty range, a range past the end,
an empty folder) is one line in the error dialog and in the panel; the studio runs on.
"""
from __future__ import annotations

import numpy as np

from ..jobs import Jobs
from .base import Panel, View

SOURCES = ("Timeline window", "BVH file range")
GHOST_COLOR = (0.85, 0.55, 0.95)


def history_positions(history, controller: str, end_tick: int, n_ticks: int) -> np.ndarray:
    """``(F, J, 3)`` global joint positions of ``controller`` over the held ticks ``end_tick - n + 1 ..
    end_tick`` (fewer when the history is shorter)."""
    ticks = history.ticks_between(end_tick - n_ticks + 1, end_tick)
    poses = [t.snapshots[controller].pose.global_positions for t in ticks if controller in t.snapshots]
    return np.asarray(poses, np.float64).reshape(len(poses), -1, 3) if poses else np.zeros((0, 0, 3))


def parse_frames(text: str, where: str) -> tuple[int, int]:
    """``"A:B"`` -> ``(A, B)``; a one-line :class:`~lmm.errors.InputError` naming ``where`` otherwise."""
    from lmm.errors import InputError

    parts = text.strip().split(":")
    try:
        a, b = (int(parts[0]), int(parts[1])) if len(parts) == 2 else (None, None)
    except ValueError:
        a = b = None
    if a is None or a < 0 or b < 0:
        raise InputError(f"{where}: frames {text.strip()[:40]!r} are not A:B (file frames, B excluded)")
    return a, b


class MotionSearchPanel(Panel):
    key = "motion_search"
    commands = ("show_error", "show")
    reads = ("frame", "history", "inspected", "snap_of", "tick", "tick_number")

    def __init__(self, ctx, jobs: Jobs | None = None):
        super().__init__(ctx)
        self.jobs = jobs if jobs is not None else Jobs()   # the index build and search, off the GUI thread
        self._search_job = None    # the search running (a Job), or None
        self.results = []          # lmm.motion_search.index.Match, best first
        self.selected = -1
        self._ghost = None         # (F, J, 3) positions of the selected match, and its parents
        self._parents = None
        self._names = None
        self._ghost_fps = 30.0
        self._pending_search = False
        self._view: View | None = None
        self._anims = {}           # path -> loaded Animation (previewed results)
        self._index = None

    # --- building --------------------------------------------------------------------------------
    def build(self, window_kwargs: dict) -> None:
        from lmm import DEFAULT_MANIFEST

        dpg = self.dpg
        manifest = getattr(self.ctx.engine, "manifest", None)
        default_in = str(getattr(manifest, "path", None) or DEFAULT_MANIFEST)
        with self.window(window_kwargs):
            dpg.add_radio_button(SOURCES, tag="ms_source", default_value=SOURCES[0], horizontal=True)
            with dpg.group(horizontal=True):
                dpg.add_slider_float(tag="ms_seconds", width=120, min_value=0.3, max_value=5.0, default_value=1.5,
                                     format="%.1f s")
                dpg.add_text("of the inspected character, up to the shown tick")
            with dpg.group(horizontal=True):
                dpg.add_input_text(tag="ms_file", width=-110, hint="query .bvh")
                dpg.add_input_text(tag="ms_frames", width=100, default_value="0:60", hint="A:B")
            with dpg.group(horizontal=True):
                dpg.add_text("in")
                dpg.add_input_text(tag="ms_in", width=-170, default_value=default_in, hint="manifest or folder")
                dpg.add_input_int(tag="ms_top", width=80, default_value=10, min_value=1, max_value=100,
                                  min_clamped=True, max_clamped=True)
                dpg.add_button(label="Search", tag="ms_search", callback=lambda: self.search())
            dpg.add_text("", tag="ms_status", wrap=0)
            with dpg.table(tag="ms_table", header_row=True, resizable=True, policy=dpg.mvTable_SizingStretchProp,
                           borders_innerH=True, scrollY=True, height=-1):
                for label, w in (("#", 0.3), ("file", 3.0), ("start", 0.8), ("end", 0.8), ("distance", 1.0)):
                    dpg.add_table_column(label=label, init_width_or_weight=w)

    # --- searching -------------------------------------------------------------------------------
    def _query(self):
        """What to search for: ``(make the query, where, end tick)``, where ``make()`` returns the
        example's key-joint frames (a file's are read by the search job). InputError on bad input, naming
        the file or the window."""
        from lmm.errors import InputError
        from lmm.motion_search.index import query_from_bvh, query_from_skeleton
        from lmm.motion_search.windows import match_key_joints, reference_height

        dpg = self.dpg
        if dpg.get_value("ms_source") == SOURCES[1]:
            path = dpg.get_value("ms_file").strip()
            if not path:
                raise InputError("Motion search: give the query's .bvh file")
            frames = parse_frames(dpg.get_value("ms_frames"), path)
            return (lambda: query_from_bvh(path, frames)), path, None
        view = self._view
        if view is None or view.tick is None:
            raise InputError("Motion search: no tick to take the example from yet")
        db = self.ctx.engine.db
        name = view.inspected if view.snap_of(view.inspected) is not None else next(iter(view.tick.snapshots))
        n_ticks = max(2, int(round(float(dpg.get_value("ms_seconds")) / self.ctx.engine.dt)))
        where = f"the {name.upper()} character's last {dpg.get_value('ms_seconds'):.1f} s"
        g = history_positions(view.history, name, view.tick_number, n_ticks)
        everything = history_positions(view.history, name, view.tick_number, len(view.history))
        hips = match_key_joints(db.names, where)["hips"]
        ref = reference_height(everything[:, hips, 1]) if len(everything) else None
        query = query_from_skeleton(db.names, g, 1.0 / self.ctx.engine.dt, ref, where)
        return (lambda: query), where, view.tick_number

    def search(self, wait: bool = False) -> bool:
        """Start the search for what the panel's fields say, as a job whose results fill the table when
        the panel next updates after it finished (``wait``: block until then, so a script's next step sees
        them); False (and one error line) on bad input found before the job starts."""
        from lmm.errors import InputError

        dpg = self.dpg
        try:
            make_query, where, end_tick = self._query()
        except InputError as e:
            self._failed(str(e))
            return False
        target = dpg.get_value("ms_in").strip()
        top = int(dpg.get_value("ms_top"))
        if self._search_job is not None:
            self._search_job.cancel()        # a newer search replaces it

        def work(job):
            import time

            from lmm.motion_search.index import MotionIndex, sources_from

            try:
                query = make_query()
                job.report(None, f"building the index of {target} ...")
                index = MotionIndex.build(sources_from(target),
                                          progress=lambda i, n, label: job.report(i / max(n, 1), f"indexing {label}"))
                t0 = time.perf_counter()
                results = index.search(query, top=top)
            except OSError as e:
                raise InputError(f"{e.filename}: {e.strerror}") from e
            return query, index, results, (time.perf_counter() - t0) * 1000.0

        def done(result):
            self._search_job = None
            self._show_results(*result, where, end_tick)

        def failed(line):
            self._search_job = None
            self._failed(line)

        def progress(fraction, message):
            dpg.set_value("ms_status", message + ("" if fraction is None else f" ({100 * fraction:.0f}%)"))

        dpg.set_value("ms_status", f"searching {target} for {where} ...")
        self._search_job = job = self.jobs.submit("motion-search", work, on_done=done, on_error=failed,
                                                  on_progress=progress)
        if wait:
            job.wait()
            self.jobs.poll()
            return not job.error
        return True

    def _failed(self, message: str) -> None:
        self.dpg.set_value("ms_status", message)
        self.ctx.actions.show_error("Motion search", message)
        self.last = {"error": message, "results": []}

    def _show_results(self, query, index, results, ms: float, where: str, end_tick) -> None:
        """A finished search: its results in the table, the best one previewed (GUI thread)."""
        self._index, self.results = index, results
        status = (f"{len(query)} frames of {where}: {len(self.results)} results from {index.n_windows} windows "
                  f"of {len(index.sources)} files ({index.embedder.name}) in {ms:.0f} ms")
        self.dpg.set_value("ms_status", status)
        self._fill_table()
        self.last = {"status": status, "query_frames": len(query), "query_end_tick": end_tick,
                     "results": [m.to_dict() for m in self.results]}
        self.select(0 if self.results else -1)

    def _fill_table(self) -> None:
        dpg = self.dpg
        for row in dpg.get_item_children("ms_table", 1) or []:
            dpg.delete_item(row)
        for i, m in enumerate(self.results):
            with dpg.table_row(parent="ms_table"):
                dpg.add_selectable(label=str(i + 1), span_columns=True, tag=f"ms_row_{i}",
                                   callback=lambda s, a, u: self.select(u), user_data=i)
                dpg.add_text(m.file)
                dpg.add_text(str(m.start_frame))
                dpg.add_text(str(m.end_frame))
                dpg.add_text(f"{m.distance:.3f}")

    def run_script(self, action: dict) -> None:
        """A scripted search (tests, demos): the fields ``source`` ("timeline" or "file"), ``seconds``,
        ``file``, ``frames``, ``in``, ``top`` set the panel's inputs; the window is shown and :meth:`search`
        runs on its next update (with the tick the studio shows then, as a click would) and waits for its
        job, so that the script's next step sees the results."""
        dpg = self.dpg
        self.ctx.actions.show(self.key, True)
        dpg.set_value("ms_source", SOURCES[1] if action.get("source") == "file" else SOURCES[0])
        for key, tag in (("seconds", "ms_seconds"), ("file", "ms_file"), ("frames", "ms_frames"), ("in", "ms_in"),
                         ("top", "ms_top")):
            if key in action:
                dpg.set_value(tag, type(dpg.get_value(tag))(action[key]))
        self._pending_search = True

    # --- previewing ------------------------------------------------------------------------------
    def select(self, i: int) -> None:
        """Preview result ``i`` as a looping ghost (-1: none)."""
        from lmm.data import bvh
        from lmm.motion_search.ghost import segment_positions

        dpg = self.dpg
        for k in range(len(self.results)):
            if dpg.does_item_exist(f"ms_row_{k}"):
                dpg.set_value(f"ms_row_{k}", k == i)
        self.selected = i
        self._ghost = None
        if i < 0 or i >= len(self.results) or self._index is None:
            self._set_preview(())
            return
        m = self.results[i]
        path = self._index.sources[m.take].path
        try:
            anim = self._anims.get(path) or bvh.load(path)
            self._anims = {path: anim}           # keep one take in memory
            self._ghost = segment_positions(anim, m.start_frame, m.end_frame, self._hips_height(), str(path))
            self._parents, self._names = anim.parents, tuple(anim.names)
            self._ghost_fps = 1.0 / anim.frame_time
        except Exception as e:  # noqa: BLE001 - a file changed since indexing: say so, keep running
            self.ctx.actions.show_error("Motion search", f"{m.file}: cannot preview ({e})")
        self.last["selected"] = i

    def _hips_height(self) -> float:
        db = self.ctx.engine.db
        try:
            from lmm.motion_search.windows import match_key_joints, reference_height

            hips = match_key_joints(db.names)["hips"]
            view = self._view
            if view is not None and view.tick is not None:
                g = history_positions(view.history, view.inspected, view.tick_number, len(view.history))
                if len(g):
                    return reference_height(g[:, hips, 1])
        except Exception:  # noqa: BLE001 - a skeleton without matched joints: a typical hips height
            pass
        return 0.95

    def _set_preview(self, poses: tuple) -> None:
        set_preview = getattr(self.ctx.actions, "set_preview", None)   # the 3D view's preview hook
        if set_preview is not None:
            set_preview(self.key, poses)

    def update(self, view: View) -> None:
        self._view = view
        self.jobs.poll()
        if self._pending_search:
            self._pending_search = False
            self.search(wait=True)
        if self._ghost is None or not len(self._ghost):
            return
        try:
            from .base import PreviewPose
        except ImportError:      # a studio without preview ghosts
            return
        # loop at the take's own speed (the studio draws a frame per tick)
        f = int(view.frame * self.ctx.engine.dt * self._ghost_fps) % len(self._ghost)
        m = self.results[self.selected]
        self._set_preview((PreviewPose(label=f"{m.file} {m.start_frame + f}", positions=self._ghost[f],
                                       parents=self._parents, names=self._names, color=GHOST_COLOR),))
