"""Learned motion matching: the pose source is the state ``[features, latent]`` of three small networks.

Per tick (Holden et al. 2020, section 4):

* when a search would run (the same search interval, forced searches and :class:`lmm.tuning.Tuning`
  as motion matching), the **projector** maps the query to the ``[features, latent]`` of its nearest
  neighbour; when the projected features match the query better than the playing state does (by more
  than the transition cost) the state jumps there and the base class inertializes the pose jump;
* every tick the **stepper** advances the state by ``dt`` and the **decompressor** turns it into a pose.

The networks run in numpy (:mod:`lmm.nn`); torch is never imported here. What LMM "matched", for the
debugger, the trace and the metrics (per-tag shares, transitions), headless or not:

* ``projected_frame`` (on a tick that projected): the database frame nearest to the projector's features
  (exact search; the idle frame found inside the idle set), the frame the projector "chose";
* ``matched_frame``: the last projected frame the state jumped to, advanced by the frames played since
  (at the database's rate, kept inside its range); a projection the state does not take leaves it;
* ``transitioned``: a **projector jump**: the state jumped to a projection whose frame is not the
  continuation of the matched frame (another range, or more than :attr:`CONTINUATION_TOLERANCE_S` away);
  a jump to the continuation (most projections while moving steadily) is not a transition.

With ``compare_with_search`` (off in benchmarks) it also carries what the exact nearest-neighbour search
returns for the same query (``nn_frame``). None of this is read by the pose: the motion is the same.

The networks work in the feature normalisation they were trained with (stored in the weights file);
changing feature weights in the tuning changes the queries' exact costs and the nearest-neighbour
comparison, not what the networks learned.
"""
from __future__ import annotations

import functools
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from lmm.character import CharacterController
from lmm.source_pose import SearchOutcome, SourcePose
from lmm.controller import Candidates, Capabilities
from lmm.mm import default_start_frame
from lmm.nn import MLP, pose_vector_slices, pose_vector_tick_columns
from lmm.pose_decoding import PoseDecoder
from lmm.search import SearchIndex
from lmm.tuning import IDLE_TAG, Tuning
from lmm.data.weights import WeightsError, load as load_weights

WEIGHTS_DIR = Path(__file__).resolve().parent / "data" / "weights"
DEFAULT_WEIGHTS = WEIGHTS_DIR / "default.npz"
RUNTIME_NETWORKS = ("decompressor", "stepper", "projector")


@dataclass
class LMMNetworks:
    """The three runtime networks plus the feature space they were trained in."""
    decompressor: MLP
    stepper: MLP
    projector: MLP
    feature_mean: np.ndarray       # (D,) raw feature offset of the networks' feature space
    feature_inv_scale: np.ndarray  # (D,)
    n_features: int
    n_latent: int
    n_bones: int
    metadata: dict
    path: Path | None = None

    @classmethod
    def load(cls, path, db=None, features=None) -> "LMMNetworks":
        """Load and validate (against ``db``'s key and ``features``' layout when given)."""
        wf = load_weights(path, require=RUNTIME_NETWORKS, db_key=None if db is None else db.key,
                          layout_dicts=None if features is None else features.layout_dicts())
        meta = wf.metadata
        nets = {n: MLP.from_spec(wf.arrays, n, wf.spec(n)) for n in RUNTIME_NETWORKS}
        n_features = len(meta["feature_mean"])
        n_latent = int(meta["latent"])
        n_bones = int(meta["n_bones"])
        state = n_features + n_latent
        checks = (("decompressor", nets["decompressor"].n_in, state), ("stepper", nets["stepper"].n_in, state),
                  ("stepper", nets["stepper"].n_out, state), ("projector", nets["projector"].n_in, n_features),
                  ("projector", nets["projector"].n_out, state),
                  ("decompressor", nets["decompressor"].n_out, pose_vector_slices(n_bones)["contacts"].stop))
        for name, got, want in checks:
            if got != want:
                raise WeightsError(f"{wf.path}: {name} has a {got}-wide input/output where {want} is expected")
        if db is not None and n_bones != db.n_bones:
            raise WeightsError(f"{wf.path}: trained for {n_bones} bones, the database has {db.n_bones}")
        if db is not None and int(meta.get("n_frames", db.n_frames)) != db.n_frames:
            # the key should already differ; this catches a cache rebuilt under an unchanged key
            raise WeightsError(f"{wf.path}: trained on a database of {meta['n_frames']} frames, the loaded one "
                               f"has {db.n_frames}; retrain with `lmm-studio train`")
        return cls(nets["decompressor"], nets["stepper"], nets["projector"],
                   np.asarray(meta["feature_mean"], np.float32), np.asarray(meta["feature_inv_scale"], np.float32),
                   n_features, n_latent, n_bones, meta, wf.path)

    def nbytes(self) -> int:
        """Bytes the runtime keeps for the networks (weights, biases, normalisation)."""
        return self.decompressor.nbytes() + self.stepper.nbytes() + self.projector.nbytes()

    def to_network_space(self, raw: np.ndarray) -> np.ndarray:
        return ((raw - self.feature_mean) * self.feature_inv_scale).astype(np.float32)

    def from_network_space(self, x: np.ndarray) -> np.ndarray:
        return (x / self.feature_inv_scale + self.feature_mean).astype(np.float32)


def load_default_networks(db, features, path=None) -> LMMNetworks:
    """The shipped networks (``lmm/data/weights/default.npz``), checked against ``db`` and ``features``."""
    return LMMNetworks.load(path or DEFAULT_WEIGHTS, db, features)


class LearnedMotionMatchingController(CharacterController):
    """Learned motion matching over ``db``/``features`` with ``networks`` (default: the shipped ones)."""

    name = "lmm"

    def __init__(self, db, features, tuning: Tuning | None = None, networks: LMMNetworks | None = None,
                 compare_with_search: bool = True):
        self.nets = networks if networks is not None else load_default_networks(db, features)
        if self.nets.n_bones != db.n_bones:
            raise WeightsError(f"{self.nets.path}: networks for {self.nets.n_bones} bones, database has {db.n_bones}")
        self.compare_with_search = compare_with_search
        self._decode = PoseDecoder(db.n_bones)
        d = self.nets.n_features
        # the state lives in a buffer ending with a constant 1 that both networks read directly (their
        # first layer's bias row, see lmm.nn.MLP.bind_single): no copy of the state per network call
        self._state1 = np.ones(d + self.nets.n_latent + 1, np.float32)
        self.state = self._state1[:-1]
        self.state[:] = 0.0
        self._deriv = np.zeros_like(self.state)
        self._pose_vec = np.zeros(self.nets.decompressor.n_out, np.float32)
        self._projected_state = np.zeros(self.nets.projector.n_out, np.float32)
        self._run_stepper = self.nets.stepper.bind_single(self._deriv, self._state1)
        self._run_decompressor = self.nets.decompressor.bind_single(self._pose_vec, self._state1)
        # per tick the decompressor computes the pose vector's tick columns only; the bones' velocities
        # (a third of its last layer) from a copy of its hidden layer when a transition reads them
        tick_columns = pose_vector_tick_columns(db.n_bones)
        self._pose_tick = np.zeros(len(tick_columns), np.float32)
        self._run_decompressor_tick, self._decompressor_hidden, self._decompressor_velocities = \
            self.nets.decompressor.bind_single_split(tick_columns, self._pose_tick, self._state1)
        self._dt32 = (None, None)    # (dt, np.float32(dt)) of the last tick
        self._source_raw = None      # from_network_space of the state's features (None: not computed since it changed)
        self._index: SearchIndex | None = None
        self._all_frames = np.ones(db.n_frames, dtype=bool)
        self._nn_frame = -1
        self._nn_cost = float("nan")
        self._projected = None
        self._projected_cost = float("nan")
        self._projected_frame = -1
        self._match = (0, 0, 0.0)    # (matched frame, its range's stop, seconds played since): see _source_frame
        self._jumped = False         # this tick's projection was a projector jump (the snapshot's transitioned)
        self._idle = None            # (frames, their network states) of the idle set, built on first use
        self.idle_note = ""          # why the idle set cannot be used ("" when it can)
        self._idle_playing = False   # the state was last set from the idle set
        self._calib_frame = -1       # a database frame like the playing state, for ground calibration
        self._calib_table = None     # (normalised features it was built from, every stride-th row of them)
        super().__init__(db, features, tuning)

    # -- the networks ---------------------------------------------------------------------------
    def project(self, query_norm: np.ndarray) -> np.ndarray:
        """Projector on a query normalised with the controller's current feature weights -> state."""
        raw = self.features.denormalize(query_norm)
        # into the controller's own buffer (the projector keeps a bound call for it), then a new array
        return self.nets.projector(self.nets.to_network_space(raw), self._projected_state).copy()

    def decompress(self, state: np.ndarray) -> SourcePose:
        if state is self.state:
            self._run_decompressor()
        else:
            self.nets.decompressor(state, out=self._pose_vec)
        return self._decode(self._pose_vec)

    def exact_nearest(self, query_norm: np.ndarray, top_k: int | None = None):
        """The exact nearest neighbour of a query over every frame (no exclusions): (frame, cost, result)
        with the ``top_k`` best (default: the tuning's) ranked in the result."""
        if self._index is None:
            self._index = SearchIndex(self.features.normalized)
        self._index.update(self.features.normalized)
        k = int(self.tuning.top_k) if top_k is None else int(top_k)
        res = self._index.search(query_norm, mask=self._all_frames, current=-1, transition_cost=0.0,
                                 exclude_window=0, top_k=k, slices=self.features.slices)
        return res.best_frame, res.best_cost, res

    def memory_bytes(self) -> dict[str, int]:
        """The three runtime networks (each layer once, with its normalisation folded in; the
        decompressor also keeps the per-tick split of its last layer) and the idle set (built here if it
        was not): its frames, their network states and their normalised features (read from the shared
        feature table, counted as if kept, since a learned controller on its own would need them). The
        search index over the database's features that the matched frame (and the debug comparison)
        searches is not counted: the debugger's, not the controller's."""
        out = {name: int(getattr(self.nets, name).nbytes()) for name in RUNTIME_NETWORKS}
        out["decompressor"] += self._run_decompressor_tick.nbytes
        idle = self.idle_states()      # built here if not yet: a run holds it from its first idle
        if idle is not None:
            frames, states = idle
            out["idle_set"] = int(frames.nbytes + states.nbytes + len(frames) * self.features.n_dims * 4)
        return out

    def capabilities(self) -> Capabilities:
        path = self.nets.path
        return Capabilities(latent_dims=int(self.nets.n_latent), networks_path=None if path is None else str(path),
                            idle_set_table=True)

    def warm_up(self) -> None:
        self.idle_states()

    # -- the idle set ------------------------------------------------------------------------------
    def idle_states(self):
        """``(frames, states)`` of the database's idle-tagged frames: each state is the frame's features
        (in the networks' space) and its compressor latent, what the projector would ideally output for
        it. A projector cannot be told to keep to a subset, so while the idle set is active the learned
        controller finds the nearest idle frame exactly and jumps its state there; the table is small
        (a few thousand frames x 59 floats). Needs ``compressor.npz`` beside the weights; without it
        (or without idle tags) it is None and ``idle_note`` says why."""
        if self._idle is None:
            frames = np.nonzero(self.db.tag_mask(IDLE_TAG))[0]
            comp = None if self.nets.path is None else Path(self.nets.path).with_name("compressor.npz")
            if len(frames) == 0:
                self._idle, self.idle_note = False, f"database {self.db.name!r} has no {IDLE_TAG!r}-tagged range"
            elif comp is None or not comp.is_file():
                self._idle, self.idle_note = False, "no compressor.npz beside the weights: LMM has no idle set"
            else:
                from lmm.latents import database_latents, load_compressor

                try:
                    latents = database_latents(load_compressor(comp, self.db, self.features), self.db, frames)
                except (WeightsError, OSError, ValueError) as e:
                    self._idle, self.idle_note = False, f"LMM idle set unavailable: {e}"
                else:
                    feats = self.nets.to_network_space(self.features.raw[frames])
                    self._idle = (frames, np.concatenate([feats, latents], axis=1).astype(np.float32))
        return self._idle or None

    def _idle_search(self, query_norm: np.ndarray, around: int | None = None):
        """(state, frame, cost) of the idle frame nearest the query, or None without an idle set (or without a
        candidate): not the last ``exclude_range_end_frames`` of a range, nor within
        ``exclude_current_window_frames`` of ``around`` (the continuing frame), as motion matching's search."""
        idle = self.idle_states()
        if idle is None:
            return None
        frames, states = idle
        costs = np.sum((self.features.normalized[frames] - query_norm) ** 2, axis=1)
        costs[~self.candidate_mask()[frames]] = np.inf
        if around is not None:
            w = int(self.tuning.exclude_current_window_frames)
            costs[np.abs(frames - around) <= w] = np.inf
        k = int(np.argmin(costs))
        if not costs[k] < np.inf:
            return None
        return states[k], int(frames[k]), float(costs[k])

    def _idle_continuation(self):
        """``(frame, state)``: the idle take's frame the playing one has reached (the matched idle frame
        advanced by the time played since) and its state, None when that frame is its range's last or not in
        the idle set (the take ends: the search moves on to another idle frame)."""
        frames, states = self.idle_states()
        frame, stop, played_s = self._match
        nxt = frame + int(round(played_s * self.db.fps))
        k = int(np.searchsorted(frames, nxt))
        if nxt >= stop - 1 or k >= len(frames) or frames[k] != nxt:
            return nxt, None
        return nxt, states[k]

    # -- hooks ----------------------------------------------------------------------------------
    def _reset_source(self, frame: int | None) -> None:
        frame = default_start_frame(self.db) if frame is None else int(frame)
        if not 0 <= frame < self.db.n_frames:
            raise ValueError(f"start frame {frame} is outside the database (0..{self.db.n_frames - 1})")
        self.state[:] = self.nets.projector(self.nets.to_network_space(self.features.raw[frame]))
        self._source_raw = None
        self._nn_frame = frame
        self._match = (frame, int(self.db.range_stop_of(frame)), 0.0)
        self._calib_frame = frame
        self._nn_cost = 0.0
        self._projected = self.features.normalize(self.nets.from_network_space(self.state[:self.nets.n_features]))
        self._projected_cost = float("nan")
        self._projected_frame = -1
        self._idle_playing = False

    def _source_features(self) -> np.ndarray:
        # asked twice per tick for the same state (the query, then the snapshot's current features):
        # computed once per change of the state (callers copy it, never write it)
        raw = self._source_raw
        if raw is None:
            raw = self._source_raw = self.nets.from_network_space(self.state[:self.nets.n_features])
        return raw

    def _source_features_later(self):
        # the state changes every tick: its features are converted once a reader asks (a debug snapshot, a
        # query on a tick that does not search), from a copy of the state taken now; the same operations
        raw = self._source_raw
        if raw is not None:
            return raw
        state = self.state[:self.nets.n_features].copy()
        return functools.partial(self.nets.from_network_space, state)

    #: a projection whose frame is within this time of the matched frame's continuation continues it
    CONTINUATION_TOLERANCE_S = 0.1

    def _source_frame(self) -> int:
        frame, stop, played_s = self._match
        return min(frame + int(round(played_s * self.db.fps)), stop - 1)

    def _take_match(self, frame: int) -> None:
        """The state jumped to a projection whose nearest frame is ``frame``: a projector jump unless it
        continues the matched frame (same range, within the tolerance)."""
        cont = self._source_frame()
        near = abs(frame - cont) <= self.CONTINUATION_TOLERANCE_S * self.db.fps
        stop = int(self.db.range_stop_of(frame))
        self._jumped = not (near and stop == self._match[1])
        self._match = (frame, stop, 0.0)

    def _search_when_due(self, state, des_vel, des_rot, forced, dt, timings) -> tuple:
        # the base reports every jump of the state as a transition; LMM's is the projector jump (_take_match)
        frame, stop, played_s = self._match
        self._match, self._jumped = (frame, stop, played_s + dt), False
        tick_query, searched, _, must = super()._search_when_due(state, des_vel, des_rot, forced, dt, timings)
        return tick_query, searched, self._jumped, must

    def _calibration_frame(self) -> int:
        return self._calib_frame

    #: every CALIBRATION_STRIDE-th database frame is a candidate for :meth:`_calibration_lookup`
    CALIBRATION_STRIDE = 16

    def _calibration_lookup(self, features_norm: np.ndarray) -> int:
        """The database frame nearest ``features_norm`` among every :attr:`CALIBRATION_STRIDE`-th frame:
        which take the state set from a projection looks like, so the ground calibration can use that
        take's floor (the networks reproduce each take's own floor height). Always computed, whether or
        not the debug comparison runs, so the motion never depends on it; a take-level answer is all
        that is needed (the shift is a spring, and takes of one session share a floor), hence the
        subsample: about 3,600 rows for the default data, a few tens of microseconds per jump."""
        table = self._calib_table
        if table is None or table[0] is not self.features.normalized:
            table = self._calib_table = (self.features.normalized,
                                         self.features.normalized[::self.CALIBRATION_STRIDE].copy())
        d = table[1] - np.asarray(features_norm, np.float32)
        return int(np.argmin(np.einsum("ij,ij->i", d, d))) * self.CALIBRATION_STRIDE

    def _on_features_changed(self) -> None:
        if self._index is not None:
            self._index.update(self.features.normalized)

    def _search(self, query_norm: np.ndarray, forced: bool) -> SearchOutcome:
        timings = {}
        t0 = time.perf_counter()
        active = self.idle_set_active()
        # in the idle set the learned controller searches as motion matching does there: the idle take's frame
        # the playing one has reached competes as the continuing pose, the frames around it and the last ones of
        # each range are not candidates
        reached, follow = None, None
        if active and self._idle_playing and self.tuning.idle_follow_take and self.idle_states() is not None:
            reached, state = self._idle_continuation()
            follow = None if state is None else (reached, state)
        idle = self._idle_search(query_norm, reached) if active else None
        if idle is None:
            follow = None
        projected = self.project(query_norm) if idle is None else idle[0].copy()
        timings["projector" if idle is None else "idle_search"] = (time.perf_counter() - t0) * 1e6
        d = self.nets.n_features
        proj_norm = self.features.normalize(self.nets.from_network_space(projected[:d]))
        projected_cost = float(np.sum((query_norm - proj_norm) ** 2))
        if follow is None:
            current_norm = self.features.normalize(self._source_features())
        else:
            current_norm = self.features.normalized[follow[0]]
        current_cost = float(np.sum((query_norm - current_norm) ** 2))
        self._projected, self._projected_cost = proj_norm, projected_cost
        candidates = None
        if self.compare_with_search:
            t0 = time.perf_counter()
            nn, nn_cost, res = self.exact_nearest(query_norm)
            timings["nn_search"] = (time.perf_counter() - t0) * 1e6
            self._nn_frame, self._nn_cost = int(nn), float(nn_cost)
            candidates = Candidates(frames=res.frames, costs=res.costs, channel_costs=res.channel_costs,
                                    bias=res.bias, channel_names=self.features.names)
        target = None
        if idle is not None:
            self._projected_frame = idle[1]     # the frame the "projection" stands for
        else:   # the exact search, once a projection: 111 us p50, 130 us mean, 22 us a tick on average
            t0 = time.perf_counter()    # (measured: 60 s of builtin:random:1, the default database)
            self._projected_frame = int(self.exact_nearest(proj_norm, top_k=1)[0])
            timings["projected_frame_search"] = (time.perf_counter() - t0) * 1e6
        # entering the idle set always jumps (as MM's search then only sees idle frames); inside it, and
        # outside it, the usual rule: jump when the projection matches the query better
        entering_idle = idle is not None and not self._idle_playing
        if idle is None:
            self._idle_playing = False
        # the idle take ends (its last frames are not candidates): on to the best idle frame, as motion matching's
        # end of a range forces a jump
        ending = idle is not None and self._idle_playing and self.tuning.idle_follow_take and follow is None
        jump = entering_idle or ending or projected_cost + float(self.tuning.transition_cost) < current_cost
        if jump:
            self._idle_playing = idle is not None
            self.state[:] = projected
            frame = self._projected_frame
            self._calib_frame = idle[1] if idle is not None else self._calibration_lookup(proj_norm)
        elif follow is not None:
            frame, self.state[:] = follow
            self._calib_frame = frame
        if jump or follow is not None:
            self._source_raw = None
            self._take_match(frame)
            t0 = time.perf_counter()
            target = self.decompress(self.state)
            timings["decompressor_transition"] = (time.perf_counter() - t0) * 1e6
        return SearchOutcome(target=target, best_frame=self._nn_frame, best_cost=projected_cost,
                             candidates=candidates, timings_us=timings)

    def _advance_pose(self, dt: float) -> SourcePose:
        if dt > 0:
            deriv = self._deriv
            self._run_stepper()
            last_dt, dt32 = self._dt32
            if dt != last_dt:
                dt32 = np.float32(dt)
                self._dt32 = (dt, dt32)
            np.multiply(deriv, dt32, deriv)
            np.add(self.state, deriv, self.state)
            self._source_raw = None
        self._run_decompressor_tick()
        return self._decode.tick(self._pose_tick, functools.partial(np.dot, self._decompressor_hidden.copy(),
                                                                    self._decompressor_velocities))

    def _snapshot_extras(self) -> dict:
        d = self.nets.n_features
        # the projected frame belongs to the tick that projected: handed to its snapshot once, then cleared
        projected_frame, self._projected_frame = self._projected_frame, -1
        return {"latent": self.state[d:].copy(),
                # replaced by each projection, never written in place: shared, not copied
                "projected_features": self._projected,
                "nn_frame": int(self._nn_frame), "nn_cost": float(self._nn_cost),
                "search_note": self.idle_note if self.idle_note and self.idle_set_active() else "",
                "projected_cost": float(self._projected_cost),
                "projected_frame": int(projected_frame)}
