"""The studio's simulation side, with no GUI: controllers, the shared tuning, input sources, the
rewind history and recording. The dearpygui studio (:mod:`app.studio`) drives one :class:`Session`
per run; tests and the benchmark can drive it headless.

Tuning: one :class:`lmm.tuning.Tuning` object is shared by both controllers. A side-by-side
comparison is only meaningful when both characters get the same springs, speeds, thresholds and
weights, and a slider then acts on both on the next tick. (The LMM networks were trained on the
database's feature normalisation; the LMM controller decides itself how it treats changed feature
weights.)
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from lmm.controller import Controller, InputState
from lmm.runner import step_controllers
from lmm.tuning import Tuning

from .history import History, Tick

TICK_RATE_HZ = 60.0


# ------------------------------------------------------------------------------------------------
# recording
# ------------------------------------------------------------------------------------------------

def recording_paths(base, which: tuple[str, ...]) -> dict[str, Path]:
    """Files written by one recording: a BVH per controller and the input CSV.

    ``base`` is what the user picked (``take.bvh`` or ``take``): one controller writes ``take.bvh``,
    several write ``take_mm.bvh`` / ``take_lmm.bvh``; the input goes to ``take_input.csv``.
    """
    base = Path(base)
    stem = base.name[:-4] if base.name.lower().endswith(".bvh") else base.name
    folder = base.parent
    out = {}
    for name in which:
        out[name] = folder / (f"{stem}.bvh" if len(which) == 1 else f"{stem}_{name}.bvh")
    out["input"] = folder / f"{stem}_input.csv"
    return out


def free_recording_paths(base, which: tuple[str, ...]) -> dict[str, Path]:
    """:func:`recording_paths` of ``base``, or, when any of those files exists, of the first numbered
    base none of whose files exists (``take.bvh`` -> ``take_001.bvh``, ``take_002.bvh``, ...; one
    number for all files of the recording). A recording never overwrites a file."""
    paths = recording_paths(base, which)
    if not any(p.exists() for p in paths.values()):
        return paths
    base = Path(base)
    stem = base.name[:-4] if base.name.lower().endswith(".bvh") else base.name
    number = 1
    while True:
        paths = recording_paths(base.parent / f"{stem}_{number:03d}.bvh", which)
        if not any(p.exists() for p in paths.values()):
            return paths
        number += 1


@dataclass
class RecordingResult:
    """What :meth:`Session.stop_recording` left on disk."""
    paths: dict[str, Path]   # controller name (and "input") -> file written; empty when nothing was written
    frames: int
    seconds: float
    message: str             # one line for the studio's status bar


@dataclass
class Recording:
    """A recording in progress: one streaming BVH per controller and the input CSV, checked from the
    start (so a folder that cannot be written fails at once). Each file appears with its first flushed
    frames (:mod:`lmm.data.stream`), so a recording that gets no frame leaves no file."""
    paths: dict[str, Path]
    recorders: dict          # controller name -> lmm.data.recording.BVHRecorder
    input_writer: object     # lmm.data.inputs.InputCsvWriter
    start_tick: int
    frames: int = 0

    def writers(self) -> dict:
        """Controller name (and "input") -> its writer."""
        out = dict(self.recorders)
        if self.input_writer is not None:
            out["input"] = self.input_writer
        return out

    def close(self) -> list[str]:
        """Close every file, even when one fails (e.g. a full disk); returns one line per failure."""
        errors = []
        for w in self.writers().values():
            try:
                w.close()
            except OSError as e:
                errors.append(str(e))
        return errors

    def written(self) -> dict[str, Path]:
        """The files that exist (a file appears with its first flushed frames)."""
        return {name: self.paths[name] for name, w in self.writers().items() if w.exists}


# ------------------------------------------------------------------------------------------------
# the session
# ------------------------------------------------------------------------------------------------

class Session:
    """Steps every controller with the same input each tick and keeps the rewind history."""

    def __init__(self, db, features, tuning: Tuning, controllers: dict[str, Controller],
                 dt: float = 1.0 / TICK_RATE_HZ, history_seconds: float = 20.0):
        self.db, self.features, self.tuning = db, features, tuning
        self.controllers = controllers
        self.dt = float(dt)
        self.history = History(max(int(round(history_seconds / self.dt)), 1))
        self.tick = 0
        self.input_log = None          # an lmm.data.inputs.InputLog being replayed, or None (live input)
        self.input_log_start_tick = 0
        self.following = None         # an lmm.follow.FollowedTake whose input is replayed, or None
        self._trackers: dict = {}      # controller name -> lmm.follow.FrameTracker
        self.recording: Recording | None = None
        self.recording_error = ""           # one line: why the recording stopped by itself ("" = it did not)
        self._failed_recording: Recording | None = None
        self.step_ms: dict[str, float] = {}
        self.latent_table_status = ""  # "" once MM's latent table is attached, else why not (one line)
        self._latent_job = 0
        self.ragdolls = None           # an lmm.physics.ragdoll.RagdollTracker (see start_ragdolls), or None
        self.physics_status = "physics off"   # one line: why there is no ragdoll ("" when there is)

    # -- the simulated characters (lmm.physics.ragdoll) -------------------------------------------
    def start_ragdolls(self) -> None:
        """A stable-PD ragdoll tracking each controller (needs the optional mujoco package; without it
        ``physics_status`` says how to install it and the session runs without ragdolls)."""
        from lmm.errors import InputError

        try:
            from lmm.physics.ragdoll import RagdollTracker, body_for_database

            self.ragdolls = RagdollTracker(body_for_database(self.db), self.dt)
            self.physics_status = ""
        except InputError as e:       # mujoco missing (PhysicsUnavailable) or a skeleton with no body
            self.ragdolls = None
            self.physics_status = str(e)

    # -- the compressor latent of every database frame (for "the latent of the frames MM plays") ----
    def start_latent_table(self, weights_path=None) -> None:
        """Compute the compressor's latent of every database frame in a background thread, when a
        compressor file lies next to the LMM weights, and attach it to the MM controller (whose snapshots
        then carry ``matched_latent``). ``latent_table_status`` says why there is none (yet)."""
        import threading

        from lmm.latents import cached_database_latents

        mm = self.controllers.get("mm")
        if mm is None:
            self.latent_table_status = "MM is not running: no MM latents"
            return
        mm.set_latent_table(None)      # a table from other networks' compressor is not comparable
        self._latent_job += 1
        job = self._latent_job
        path = None
        nets = getattr(self.controllers.get("lmm"), "nets", None)
        if weights_path is not None:
            path = Path(weights_path)
        elif nets is not None and getattr(nets, "path", None) is not None:
            path = Path(nets.path)
        if path is None:
            self.latent_table_status = "no LMM networks: no compressor latents"
            return
        comp = path.with_name("compressor.npz")
        if not comp.is_file():
            self.latent_table_status = f"no compressor next to the weights ({comp.name}): MM latents unavailable"
            return
        self.latent_table_status = "computing the compressor latent of every frame..."

        def work():
            lmm = self.controllers.get("lmm")
            if lmm is not None and hasattr(lmm, "idle_states"):
                lmm.idle_states()   # the LMM idle set's small table, so the first stop does not hitch (~80 ms)
            try:
                table = cached_database_latents(comp, self.db, self.features)
                if job == self._latent_job:          # not superseded by a later call
                    mm.set_latent_table(table)
                    self.latent_table_status = ""
            except Exception as e:  # shown in the latent panel; nothing else depends on it
                if job == self._latent_job:
                    self.latent_table_status = f"compressor latents unavailable: {e}"

        threading.Thread(target=work, name="latent-table", daemon=True).start()

    @property
    def memory(self) -> dict[str, dict[str, int]]:
        """Bytes each method keeps at run time, by part (asked each time: MM's index appears after a search)."""
        return {name: c.memory_bytes() for name, c in self.controllers.items()}

    @property
    def time_s(self) -> float:
        return self.tick * self.dt

    @property
    def names(self) -> list[str]:
        return list(self.controllers)

    def reset(self) -> None:
        """Both characters back to the start; the history is cleared."""
        for c in self.controllers.values():
            c.reset()
        for t in self._trackers.values():
            t.reset()
        if self.ragdolls is not None:
            self.ragdolls.reset()
        self.history.clear()
        self.tick = 0

    # -- input ---------------------------------------------------------------------------------
    def replay(self, log) -> None:
        """Replay an input log from its start; the characters restart so the replay is reproducible."""
        self.reset()
        self.input_log = log
        self.input_log_start_tick = 0
        self.following = None

    def stop_replay(self) -> None:
        self.input_log = None
        self.following = None

    def follow(self, take) -> None:
        """Follow a reference take (:mod:`lmm.follow`): its derived input drives every controller from a
        reset, and each tick carries, per controller, the aligned take frame and the pose error
        (history series ``reference_frame`` and ``reference_error``, radians)."""
        from lmm.follow import FrameTracker

        self.replay(take.input_log())
        self.following = take
        self._trackers = {name: FrameTracker(take) for name in self.controllers}

    def follow_series(self, tick: Tick) -> dict:
        """``(controller, key) -> value`` of the followed take for a stepped tick (see :meth:`follow`)."""
        from lmm.follow import FrameTracker, pose_rotations

        take = self.following
        time_s = (tick.tick - self.input_log_start_tick) * self.dt
        out = {}
        for name, snap in tick.snapshots.items():
            tracker = self._trackers.get(name)
            if tracker is None:                # a controller that appeared since (LMM weights loaded)
                tracker = self._trackers[name] = FrameTracker(take)
            rot = pose_rotations(snap.pose.local_rotations, snap.pose.global_rotations, self.db.names,
                                 take.hips_forward_axis)
            frame, error = tracker.track(time_s, rot)
            out[(name, "reference_frame")] = float(frame)
            out[(name, "reference_error")] = error
        return out

    def replay_time(self) -> float:
        return (self.tick - self.input_log_start_tick) * self.dt

    def replay_finished(self) -> bool:
        return self.input_log is not None and self.replay_time() > self.input_log.duration + self.dt

    def input_for_next_tick(self, live: InputState, ahead: int = 0) -> InputState:
        """The input of tick ``self.tick + 1 + ahead``: the replayed log's, else ``live``."""
        if self.input_log is not None:
            return self.input_log.at(self.replay_time() + ahead * self.dt)
        return live

    # -- ticking -------------------------------------------------------------------------------
    def step(self, inp: InputState, extra: dict | None = None) -> Tick:
        """One tick of every controller (:func:`lmm.runner.step_controllers`), recorded and kept in the history."""
        _, snaps, self.step_ms = step_controllers(self.controllers, inp, self.dt)
        tick = Tick(self.tick + 1, (self.tick + 1) * self.dt, snaps, dict(extra or {}))
        tick.extra.setdefault("input", inp)
        if self.following is not None:
            tick.series.update(self.follow_series(tick))
        if self.ragdolls is not None:
            series, positions = self.ragdolls.step(snaps)
            tick.series.update(series)
            if positions:
                tick.extra["ragdoll"] = positions
        if self.recording is not None:
            self._record(tick, inp)
        self.history.append(tick)
        self.tick += 1
        return tick

    # -- recording -----------------------------------------------------------------------------
    def start_recording(self, base, which=("mm", "lmm")) -> dict[str, Path]:
        """Start recording the chosen controllers to BVH (and the input to CSV); returns the paths it
        will write: those of ``base`` (see :func:`recording_paths`), or the next free numbered ones when
        any of them exists (:func:`free_recording_paths`). Raises ``ValueError`` when none of ``which`` is
        running and ``OSError`` when a file cannot be created (nothing is left behind then)."""
        from lmm.data.inputs import InputCsvWriter
        from lmm.data.recording import BVHRecorder

        if self.recording is not None:
            self.stop_recording()
        which = tuple(n for n in which if n in self.controllers)
        if not which:
            raise ValueError("nothing to record: none of the chosen controllers is running")
        paths = free_recording_paths(base, which)
        rec = Recording(paths, {}, None, self.tick)
        try:
            Path(paths["input"]).parent.mkdir(parents=True, exist_ok=True)
            for name in which:
                rec.recorders[name] = BVHRecorder(paths[name], self.db, fps=1.0 / self.dt, overwrite=False)
            rec.input_writer = InputCsvWriter(paths["input"], with_camera=True, overwrite=False)
        except BaseException:
            rec.close()       # nothing was written yet: no file exists
            raise
        self.recording = rec
        self.recording_error = ""
        return dict(paths)

    def _record(self, tick: Tick, inp: InputState) -> None:
        rec = self.recording
        try:
            rec.input_writer.write(rec.frames * self.dt, inp)
            for name, r in rec.recorders.items():
                r.write(tick.snapshots[name].pose)
        except OSError as e:
            # a full disk (or a vanished folder): the files keep their last complete flush; the
            # recording stops here and the studio shows why (see stop_recording)
            self.recording_error = str(e)
            self.recording = None
            rec.close()
            self._failed_recording = rec
            return
        rec.frames += 1

    def stop_recording(self) -> RecordingResult:
        """Finish the recording, or report the one a write error stopped (``recording_error``). Only
        files that received frames exist; with no frame recorded nothing is written."""
        rec, error = self.recording, self.recording_error
        if rec is None:
            rec, self._failed_recording = self._failed_recording, None
            if rec is None:
                return RecordingResult({}, 0, 0.0, "not recording")
        self.recording, self.recording_error = None, ""
        errors = rec.close()
        error = error or (errors[0] if errors else "")
        written = rec.written()
        # after a write error each BVH keeps its last complete flush: report the shortest
        frames = rec.frames if not error else min(
            (r.frames_written for name, r in rec.recorders.items() if name in written), default=0)
        if not written or frames == 0:
            if error:
                return RecordingResult(written, 0, 0.0, f"recording failed: {error}")
            return RecordingResult({}, 0, 0.0, "nothing recorded (0 frames): no file written")
        seconds = frames * self.dt
        names = ", ".join(Path(p).name for p in written.values())
        if error:
            return RecordingResult(written, frames, seconds, f"recording stopped by a write error: {error}; "
                                                             f"kept {seconds:.2f} s ({frames} frames) in {names}")
        return RecordingResult(written, frames, seconds, f"recorded {seconds:.2f} s ({frames} frames) to {names}")


#: a snapshot's fields made on their first read that the default layout's panels read every frame
_DRAWN_LAZY_FIELDS = ("matched_pose_positions", "trajectory_positions", "trajectory_rotations", "query",
                      "simulation_position", "simulation_rotation")


class TickWorker:
    """Steps the session on a worker thread while the GUI draws.

    dearpygui releases the GIL while it renders a frame, so the controllers of the next tick run in
    parallel with the drawing of this one. The studio hands over a list of inputs (``submit``) just
    before it draws, and collects the finished ticks (``wait``) at the start of the next frame; in
    between it must not touch the session, and everything that changes the session (sliders,
    recording, replay, reset) runs after ``wait`` and before ``submit``.
    """

    def __init__(self, session: Session):
        import queue
        import threading

        self.session = session
        self._jobs: queue.Queue = queue.Queue()
        self._idle = threading.Event()
        self._idle.set()
        self._results: list = []
        self._error: BaseException | None = None
        self.prepared = None
        self._thread = threading.Thread(target=self._loop, name="studio-ticks", daemon=True)
        self._thread.start()

    def submit(self, inputs: list[InputState], prepare=None, release=None) -> None:
        """Step ``inputs``; then, when given, call ``prepare(newest tick)`` on the worker too (the panels'
        numeric work for the next frame, see ``Studio``): its result is ``prepared`` after ``wait``.
        ``release``: an object the GUI thread is done with, dropped on the worker (freeing a frame's
        prepared numbers, thousands of small objects, took 0.1 ms of the GUI thread's frame)."""
        if not inputs:
            return
        self._idle.clear()
        self._jobs.put((list(inputs), prepare, release))

    def wait(self) -> list[tuple[Tick, dict]]:
        """The ticks finished since the last call, with each one's per-controller milliseconds
        (``prepared`` then holds what the last job's ``prepare`` returned, or None)."""
        self._idle.wait()
        if self._error is not None:
            err, self._error = self._error, None
            raise err
        out, self._results = self._results, []
        return out

    def take_prepared(self):
        """What the last job's ``prepare`` returned (once; None when there was none or it failed)."""
        out, self.prepared = self.prepared, None
        return out

    def _loop(self) -> None:
        while True:
            job = self._jobs.get()
            if job is None:
                return
            inputs, prepare, release = job
            job = release = None       # freed here, while the GUI thread draws
            self.prepared = None
            try:
                for inp in inputs:
                    tick = self.session.step(inp)
                    self._results.append((tick, dict(self.session.step_ms)))
                # the newest tick is the one a live studio draws next: what its panels read that is worked
                # out on the first read (the ghost poses' forward kinematics, the trajectory and query of a
                # tick that did not search) is worked out here, while the GUI thread draws, not on it
                for snap in tick.snapshots.values():
                    for name in _DRAWN_LAZY_FIELDS:
                        getattr(snap, name, None)
            except BaseException as e:  # handed to the GUI thread by wait()
                self._error = e
            else:
                if prepare is not None:
                    try:
                        self.prepared = prepare(tick)
                    except Exception:    # the GUI thread works it out itself, and reports what fails
                        self.prepared = None
            finally:
                self._idle.set()

    def close(self) -> None:
        self._idle.wait()
        self._jobs.put(None)
        self._thread.join(timeout=5.0)


# ------------------------------------------------------------------------------------------------
# a reference BVH drawn beside the characters
# ------------------------------------------------------------------------------------------------

@dataclass
class ReferenceClip:
    name: str
    parents: np.ndarray
    positions: np.ndarray     # (F, J, 3) metres, first root at the origin (x, z)
    frame_time: float
    names: tuple[str, ...] = ()   # joint names (they size the drawn body parts)

    def at(self, t: float) -> np.ndarray:
        f = int(t / self.frame_time) % len(self.positions)
        return self.positions[f]


def load_reference_clip(path) -> ReferenceClip:
    """A BVH file as global joint positions in metres (centimetre files are detected by size).
    Raises ``lmm.data.bvh.BVHError`` / ``OSError`` / ``ValueError`` with a readable message."""
    from lmm.data import bvh

    anim = bvh.load(path)
    pos = anim.global_positions()
    if pos.ndim != 3 or len(pos) == 0 or pos.shape[1] == 0:
        raise ValueError(f"{path}: no frames to show")
    if not np.isfinite(pos).all():
        raise ValueError(f"{path}: the joint positions are not finite")
    height = float(np.ptp(pos[0, :, 1])) if pos.shape[1] > 1 else 0.0
    if height > 10.0:        # centimetres (or larger): bring to metres
        pos = pos * (0.01 if height < 1000 else 0.001)
    pos = pos - np.array([pos[0, 0, 0], 0.0, pos[0, 0, 2]])
    return ReferenceClip(Path(path).name, anim.parents, pos.astype(np.float32), float(anim.frame_time),
                         tuple(anim.names))
