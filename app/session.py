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

import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from lmm.controller import Controller, InputState
from lmm.tuning import Tuning

from .history import History, Tick

CONTROLLER_LABELS = {"mm": "Motion Matching", "lmm": "Learned Motion Matching"}
TICK_RATE_HZ = 60.0


# ------------------------------------------------------------------------------------------------
# building the controllers
# ------------------------------------------------------------------------------------------------

def controller_memory_bytes(name: str, controller, db, features) -> dict[str, int]:
    """What each method keeps in memory at run time, by part (bytes)."""
    own = getattr(controller, "memory_bytes", None)
    if callable(own):
        try:
            parts = own()
            if isinstance(parts, dict):
                return {str(k): int(v) for k, v in parts.items()}
            return {"total": int(parts)}
        except Exception:
            pass
    if name == "mm":
        parts = {"pose data (Y)": int(db.pose_bytes()), "features (X)": int(features.normalized.nbytes)}
        index = getattr(controller, "index", None)
        if index is not None:
            extra = sum(int(getattr(v, "nbytes", 0)) for v in vars(index).values() if isinstance(v, np.ndarray)
                        and v is not getattr(index, "features", None))
            if extra:
                parts["search index"] = extra
        return parts
    nets = getattr(controller, "nets", None)
    if nets is not None and callable(getattr(nets, "nbytes", None)):
        parts = {}
        for part in ("decompressor", "stepper", "projector"):
            net = getattr(nets, part, None)
            if net is not None and callable(getattr(net, "nbytes", None)):
                parts[part] = int(net.nbytes())
        return parts or {"networks": int(nets.nbytes())}
    total = 0
    for attr in ("networks", "decompressor", "stepper", "projector"):
        obj = getattr(controller, attr, None)
        if obj is not None:
            total += _array_bytes(obj)
    return {"networks": total} if total else {}


def _array_bytes(obj, depth: int = 0) -> int:
    if isinstance(obj, np.ndarray):
        return int(obj.nbytes)
    if depth > 3:
        return 0
    if isinstance(obj, dict):
        return sum(_array_bytes(v, depth + 1) for v in obj.values())
    if isinstance(obj, (list, tuple)):
        return sum(_array_bytes(v, depth + 1) for v in obj)
    if hasattr(obj, "__dict__"):
        return sum(_array_bytes(v, depth + 1) for v in vars(obj).values())
    return 0


# ------------------------------------------------------------------------------------------------
# recording
# ------------------------------------------------------------------------------------------------

class _Recorder:
    """One controller's BVH file (:class:`lmm.data.recording.BVHRecorder`: streamed, crash-safe)."""

    def __init__(self, db, path: Path, fps: float):
        from lmm.data.recording import BVHRecorder

        Path(path).parent.mkdir(parents=True, exist_ok=True)
        self.path = Path(path)
        self.rec = BVHRecorder(self.path, db, fps=fps)

    def add(self, pose) -> None:
        self.rec.write(pose)

    def close(self) -> Path:
        self.rec.close()
        return self.path


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


@dataclass
class Recording:
    paths: dict[str, Path]
    recorders: dict
    input_writer: object
    start_tick: int
    frames: int = 0


# ------------------------------------------------------------------------------------------------
# the session
# ------------------------------------------------------------------------------------------------

@dataclass
class StepTimes:
    """Milliseconds spent in the last tick, per controller."""
    per_controller_ms: dict = field(default_factory=dict)


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
        self.recording: Recording | None = None
        self.step_ms: dict[str, float] = {}
        self._projection_index: dict = {}
        self.latent_table: np.ndarray | None = None
        self.latent_table_status = ""
        self._all_frames = None

    # -- the compressor latent of every database frame (for "the latent of the frames MM plays") ----
    def start_latent_table(self, weights_path=None) -> None:
        """Compute the compressor's latent of every database frame in a background thread, when a
        compressor file lies next to the LMM weights. ``latent_table`` stays None until it is ready
        (or when there is no compressor); ``latent_table_status`` says which."""
        import threading

        lmm_c = self.controllers.get("lmm")
        path = None
        nets = getattr(lmm_c, "nets", None)
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
            try:
                from lmm.offline.evaluation import database_latents, load_compressor

                compressor = load_compressor(comp, self.db, self.features)
                self.latent_table = database_latents(compressor, self.db).astype(np.float32)
                self.latent_table_status = ""
            except Exception as e:  # shown in the latent panel; nothing else depends on it
                self.latent_table_status = f"compressor latents unavailable: {e}"

        threading.Thread(target=work, name="latent-table", daemon=True).start()

    def matched_latents(self, frames: np.ndarray) -> np.ndarray | None:
        """Compressor latents (n, L) of database frames (NaN rows for invalid frames), or None."""
        z = self.latent_table
        if z is None:
            return None
        f = np.asarray(frames, np.float64)
        ok = np.isfinite(f) & (f >= 0) & (f < len(z))
        out = np.full((len(f), z.shape[1]), np.nan)
        out[ok] = z[f[ok].astype(np.int64)]
        return out

    @property
    def memory(self) -> dict[str, dict[str, int]]:
        """Bytes each method keeps at run time, by part (recomputed: indexes appear after a search)."""
        return {name: controller_memory_bytes(name, c, self.db, self.features)
                for name, c in self.controllers.items()}

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
        self.history.clear()
        self.tick = 0

    # -- input ---------------------------------------------------------------------------------
    def replay(self, log) -> None:
        """Replay an input log from its start; the characters restart so the replay is reproducible."""
        self.reset()
        self.input_log = log
        self.input_log_start_tick = 0

    def stop_replay(self) -> None:
        self.input_log = None

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
        snaps = {}
        for name, c in self.controllers.items():
            t0 = time.perf_counter()
            pose, snap = c.step(inp, self.dt)
            self.step_ms[name] = (time.perf_counter() - t0) * 1e3
            snaps[name] = snap
        tick = Tick(self.tick + 1, (self.tick + 1) * self.dt, snaps, dict(extra or {}))
        tick.extra.setdefault("input", inp)
        for name, snap in snaps.items():
            if snap.searched and snap.projected_features is not None:
                tick.extra[f"projected_frame:{name}"] = self.projected_frame(name, snap.projected_features)
        if self.recording is not None:
            self._record(tick, inp)
        self.history.append(tick)
        self.tick += 1
        return tick

    def projected_frame(self, name: str, projected_features) -> int:
        """The database frame nearest to a projector output (what the projector 'chose'), exact."""
        from lmm.search import SearchIndex

        features = getattr(self.controllers[name], "features", self.features)
        index = self._projection_index.get(name)
        if index is None:
            index = self._projection_index[name] = SearchIndex(features.normalized)
        index.update(features.normalized)
        if self._all_frames is None or len(self._all_frames) != features.normalized.shape[0]:
            self._all_frames = np.ones(features.normalized.shape[0], dtype=bool)
        res = index.search(np.asarray(projected_features, np.float32), mask=self._all_frames, current=-1,
                           transition_cost=0.0, exclude_window=0, top_k=1, slices=features.slices)
        return int(res.best_frame)

    # -- recording -----------------------------------------------------------------------------
    def start_recording(self, base, which=("mm", "lmm")) -> dict[str, Path]:
        """Start recording the chosen controllers to BVH (and the input to CSV); returns the paths."""
        from lmm.data.inputs import InputCsvWriter

        if self.recording is not None:
            self.stop_recording()
        which = tuple(n for n in which if n in self.controllers)
        if not which:
            raise ValueError("nothing to record: none of the chosen controllers is running")
        paths = recording_paths(base, which)
        Path(paths["input"]).parent.mkdir(parents=True, exist_ok=True)
        recorders = {n: _Recorder(self.db, paths[n], 1.0 / self.dt) for n in which}
        writer = InputCsvWriter(paths["input"], with_camera=True)
        self.recording = Recording(paths, recorders, writer, self.tick)
        return paths

    def _record(self, tick: Tick, inp: InputState) -> None:
        rec = self.recording
        writer_time = rec.frames * self.dt
        rec.input_writer.write(writer_time, inp)
        for name, r in rec.recorders.items():
            r.add(tick.snapshots[name].pose)
        rec.frames += 1

    def stop_recording(self) -> dict[str, Path]:
        rec = self.recording
        if rec is None:
            return {}
        self.recording = None
        out = {}
        for name, r in rec.recorders.items():
            out[name] = r.close()
        rec.input_writer.close()
        out["input"] = rec.paths["input"]
        return out


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
        self._thread = threading.Thread(target=self._loop, name="studio-ticks", daemon=True)
        self._thread.start()

    def submit(self, inputs: list[InputState]) -> None:
        if not inputs:
            return
        self._idle.clear()
        self._jobs.put(list(inputs))

    def wait(self) -> list[tuple[Tick, dict]]:
        """The ticks finished since the last call, with each one's per-controller milliseconds."""
        self._idle.wait()
        if self._error is not None:
            err, self._error = self._error, None
            raise err
        out, self._results = self._results, []
        return out

    def _loop(self) -> None:
        while True:
            inputs = self._jobs.get()
            if inputs is None:
                return
            try:
                for inp in inputs:
                    tick = self.session.step(inp)
                    self._results.append((tick, dict(self.session.step_ms)))
            except BaseException as e:  # handed to the GUI thread by wait()
                self._error = e
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
    return ReferenceClip(Path(path).name, anim.parents, pos.astype(np.float32), float(anim.frame_time))
