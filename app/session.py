"""The studio's simulation side, with no GUI: controllers, the shared tuning, input sources, the
rewind history, recording (:mod:`app.recording`), the open reference clip (:mod:`app.reference_clip`)
and background jobs (:mod:`app.jobs`). The dearpygui studio (:mod:`app.studio`) drives one
:class:`Session` per run, stepped by :class:`app.tick_worker.TickWorker`; tests and the benchmark can
drive it headless.

Tuning: one :class:`lmm.tuning.Tuning` object is shared by both controllers. A side-by-side
comparison is only meaningful when both characters get the same springs, speeds, thresholds and
weights, and a slider then acts on both on the next tick. (The LMM networks were trained on the
database's feature normalisation; the LMM controller decides itself how it treats changed feature
weights.)
"""
from __future__ import annotations

import sqlite3
from pathlib import Path

from lmm.controller import Controller, InputState
from lmm.runner import step_controllers
from lmm.tuning import Tuning

from .history import History, Tick
from .jobs import Jobs
from .recording import Recording, RecordingResult, free_recording_paths, session_path_of
from .reference_clip import ReferenceClip
from .session_log import SessionLog
from .quality_live import LiveQuality
from .undo import TuningUndo

TICK_RATE_HZ = 60.0


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
        self.pose_error = ""           # one line: the first tick since the reset whose pose was unusable
        self._good_poses: dict = {}    # controller name -> its last usable Pose (drawn in place of one that is not)
        self.report = None             # report(title, line), on the GUI thread: the studio's errors (app.engine)
        self._unreported: list[tuple[str, str]] = []
        self._latent_status = ""       # see latent_table_status
        self._latent_job = None        # the latent table being computed (a Job), or None
        self.jobs = Jobs()             # the session's background work, delivered at a tick boundary
        self.reference: ReferenceClip | None = None   # the reference BVH drawn beside the characters
        self.ragdolls = None           # an lmm.physics.ragdoll.RagdollTracker (see start_ragdolls), or None
        self.physics_status = "physics off"   # one line: why there is no ragdoll ("" when there is)
        self.manifest = None           # the database's manifest (None: the shipped one), named in session files
        self.log = SessionLog(self)    # since the last reset: what a recording's session file replays
        self.undo = TuningUndo(tuning)  # undo / redo of tuning changes (app.undo)
        self.quality = LiveQuality(db)  # pops, knee snaps, stops since the reset (app.quality_live)

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
        """Compute the compressor's latent of every database frame as a background job, when a
        compressor file lies next to the LMM weights, and attach it to the MM controller (whose snapshots
        then carry ``matched_latent``). ``latent_table_status`` says why there is none (yet)."""
        from lmm.latents import cached_database_latents

        caps = {name: c.capabilities() for name, c in self.controllers.items()}
        mm = next((self.controllers[n] for n, cap in caps.items() if cap.latent_table), None)
        if mm is None:
            self._latent_status = "MM is not running: no MM latents"
            return
        mm.set_latent_table(None)      # a table from other networks' compressor is not comparable
        if self._latent_job is not None:
            self._latent_job.cancel()  # superseded: its table is dropped
            self._latent_job = None
        path = None
        networks = next((cap.networks_path for cap in caps.values() if cap.networks_path), None)
        if weights_path is not None:
            path = Path(weights_path)
        elif networks is not None:
            path = Path(networks)
        if path is None:
            self._latent_status = "no LMM networks: no compressor latents"
            return
        comp = path.with_name("compressor.npz")
        if not comp.is_file():
            self._latent_status = f"no compressor next to the weights ({comp.name}): MM latents unavailable"
            return
        self._latent_status = "computing the compressor latent of every frame..."

        def work(job):
            for c in list(self.controllers.values()):
                c.warm_up()   # e.g. the LMM idle set's small table, so the first stop does not hitch (~80 ms)
            return cached_database_latents(comp, self.db, self.features)

        def attach(table):
            mm.set_latent_table(table)
            self._latent_status = ""

        def fail(line):               # shown in the latent panel; nothing else depends on it
            self._latent_status = f"compressor latents unavailable: {line}"

        self._latent_job = self.jobs.submit("latent-table", work, on_done=attach, on_error=fail)

    @property
    def latent_table_status(self) -> str:
        """"" once MM's latent table is attached, else why not (one line). Asking takes a finished table:
        ask on the thread that owns the session (the GUI thread between ticks, or the stepping one)."""
        self.jobs.poll()
        return self._latent_status

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
        self.log.reset()
        self.quality.reset()
        self.pose_error, self._good_poses = "", {}

    # -- input ---------------------------------------------------------------------------------
    def replay(self, log) -> None:
        """Replay an input log from its start; the characters restart so the replay is reproducible."""
        self.reset()
        self.input_log = log
        self.log.input_name = log.name
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
        """One tick of every controller (:func:`lmm.runner.step_controllers`), recorded and kept in the history
        (background results, such as MM's latent table, are taken first: between two ticks)."""
        self.jobs.poll()
        self.log.before_step(inp)
        poses, snaps, self.step_ms = step_controllers(self.controllers, inp, self.dt)
        self.log.after_step(poses)
        self._guard_poses(self.tick + 1, snaps)
        tick = Tick(self.tick + 1, (self.tick + 1) * self.dt, snaps, dict(extra or {}))
        for name, n in self.quality.add(tick.time_s, snaps).items():
            tick.series[(name, "quality_flag")] = float(n)     # the timeline's markers (app.panels.timeline)
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

    def _guard_poses(self, tick: int, snaps: dict) -> None:
        """A pose no one can use (:func:`lmm.metrics.pose_problem`: NaN, infinite, or a joint 1000 km away: an
        LMM given weights it cannot handle) is never drawn or recorded: the controller's last usable pose (the
        database's first frame before there is one) stands in. The first such tick since the reset is reported
        once, with the tick (``pose_error``, and ``report`` at the next :meth:`deliver_reports`)."""
        from lmm.metrics import pose_problem

        for name, snap in snaps.items():
            problem = pose_problem(snap.pose)
            if problem is None:
                self._good_poses[name] = snap.pose
                continue
            snap.pose = self._good_poses.get(name) or first_frame_pose(self.db)
            if not self.pose_error:
                self.pose_error = (f"tick {tick}: the {name} pose is {problem}; its last usable pose is drawn and "
                                   f"recorded instead")
                self._unreported.append(("Pose guard", self.pose_error))

    def deliver_reports(self) -> None:
        """Hand what the ticks found to ``report``: on the GUI thread, between ticks (:class:`app.tick_worker.TickWorker`)."""
        notes, self._unreported = self._unreported, []
        for title, line in notes if self.report is not None else ():
            self.report(title, line)

    # -- recording -----------------------------------------------------------------------------
    def start_recording(self, base, which=("mm", "lmm")) -> dict[str, Path]:
        """Start recording the chosen controllers to BVH (and the input to CSV); returns the paths it
        will write: those of ``base`` (see :func:`app.recording.recording_paths`), or the next free numbered ones when
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
            # the session file that replays it: from the last reset (app.session_log)
            rec.session = self.log.start_writing(session_path_of(paths), self.manifest)
        except BaseException as e:
            rec.close()       # nothing was written yet: no file exists
            if rec.session is not None:
                self.log.close()
                rec.session.unlink(missing_ok=True)
            if isinstance(e, sqlite3.Error):
                raise OSError(f"{session_path_of(paths)}: cannot write the session file: {e}") from None
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
            self.log.close(tick.snapshots and {n: sn.pose for n, sn in tick.snapshots.items()})
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
        latest = self.history.latest()
        self.log.close(None if latest is None else {n: sn.pose for n, sn in latest.snapshots.items()})
        error = error or (errors[0] if errors else "")
        written = rec.written()
        # after a write error each BVH keeps its last complete flush: report the shortest
        frames = rec.frames if not error else min(
            (r.frames_written for name, r in rec.recorders.items() if name in written), default=0)
        if not written or frames == 0:
            if rec.session is not None:
                rec.session.unlink(missing_ok=True)      # nothing to replay either
            if error:
                return RecordingResult(written, 0, 0.0, f"recording failed: {error}")
            return RecordingResult({}, 0, 0.0, "nothing recorded (0 frames): no file written")
        seconds = frames * self.dt
        names = ", ".join(Path(p).name for p in written.values())
        if error:
            return RecordingResult(written, frames, seconds, f"recording stopped by a write error: {error}; "
                                                             f"kept {seconds:.2f} s ({frames} frames) in {names}")
        session = rec.session if rec.session is not None and rec.session.exists() else None
        kept = "" if session is None else f"; session {session.name}" + (f" ({self.log.ended})" if self.log.ended else "")
        return RecordingResult(written, frames, seconds, f"recorded {seconds:.2f} s ({frames} frames) to {names}{kept}",
                               session)


def first_frame_pose(db):
    """The database's first frame as a :class:`lmm.controller.Pose` (at its recorded place)."""
    import numpy as np

    from lmm.controller import Pose
    from lmm.kinematics import forward_kinematics

    rot, pos = np.asarray(db.rotations[0], np.float32), np.asarray(db.positions[0], np.float32)
    g_rot, g_pos = forward_kinematics(rot, pos, db.parents)
    return Pose(local_positions=pos, local_rotations=rot, global_positions=g_pos.astype(np.float32),
                global_rotations=g_rot.astype(np.float32), contacts=np.zeros(2, bool))
