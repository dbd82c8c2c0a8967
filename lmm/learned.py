"""Learned motion matching: the pose source is the state ``[features, latent]`` of three small networks.

Per tick (Holden et al. 2020, section 4):

* when a search would run (the same search interval, forced searches and :class:`lmm.tuning.Tuning`
  as motion matching), the **projector** maps the query to the ``[features, latent]`` of its nearest
  neighbour; when the projected features match the query better than the playing state does (by more
  than the transition cost) the state jumps there and the base class inertializes the pose jump;
* every tick the **stepper** advances the state by ``dt`` and the **decompressor** turns it into a pose.

The networks run in numpy (:mod:`lmm.nn`); torch is never imported here. For the debugger the snapshot
also carries the latent, the projector's features and, with ``compare_with_search`` (off in benchmarks),
what the exact nearest-neighbour search returns for the same query (``nn_frame``) and the database frame
nearest to the projector's features (``projected_frame``: the frame the projector "chose").

The networks work in the feature normalisation they were trained with (stored in the weights file);
changing feature weights in the tuning changes the queries' exact costs and the nearest-neighbour
comparison, not what the networks learned.
"""
from __future__ import annotations

import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from lmm.character import CharacterController, SearchOutcome, SourcePose
from lmm.controller import Candidates
from lmm.mm import default_start_frame
from lmm.nn import MLP, pose_vector_slices
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


_QUAT_DIAG_SIGNS = np.array([[1.0, 1.0, 1.0], [1.0, -1.0, -1.0], [-1.0, 1.0, -1.0], [-1.0, -1.0, 1.0]])
# columns of the rotation matrix rows (J, 9) = [a0 a1 a2 b0 b1 b2 c0 c1 c2] (a, b, c: its columns)
_CROSS_LEFT = np.array([1, 2, 0, 2, 0, 1])     # c = (left * right)[:, :3] - (left * right)[:, 3:]
_CROSS_RIGHT = np.array([5, 3, 4, 4, 5, 3])
_DIAG = np.array([0, 4, 8])                    # m00, m11, m22
_SIGN_PLUS = np.array([5, 6, 1])               # m21 - m12, m02 - m20, m10 - m01
_SIGN_MINUS = np.array([7, 2, 3])


def xform_xy_to_quat(xy: np.ndarray) -> np.ndarray:
    """2-axis rotations (J, 3, 2) -> unit quaternions (J, 4) via Gram-Schmidt, in few numpy calls.

    Same rotations as :func:`lmm.quat.from_xform_xy` (up to sign), about 6x faster for one pose: the
    quaternion's magnitudes come from the matrix diagonal, its signs from the off-diagonal differences.
    The cross product and the sign differences gather whole columns at once; the quaternion is built
    component-major (4, J). The dot products are summed in a fixed order, written out: the order of the
    ``np.einsum`` calls of the earlier version on this numpy (left to right on strided rows, (0 + 2) + 1
    on a contiguous 3-wide row), so the output is bit-identical to it (tested against it).
    """
    m = np.empty((xy.shape[0], 9))
    a = xy[:, :, 0]
    p = a * a
    n = p[:, 0] + p[:, 1]
    n += p[:, 2]
    np.sqrt(n, out=n)
    a = np.divide(a, n[:, None], out=m[:, 0:3])
    b = xy[:, :, 1]
    p = a * b
    n = p[:, 0] + p[:, 1]
    n += p[:, 2]
    b = np.subtract(b, n[:, None] * a, out=m[:, 3:6])
    p = b * b
    n = p[:, 0] + p[:, 2]
    n += p[:, 1]
    np.sqrt(n, out=n)
    b /= n[:, None]
    lr = m.take(_CROSS_LEFT, axis=1)
    lr *= m.take(_CROSS_RIGHT, axis=1)
    np.subtract(lr[:, :3], lr[:, 3:], out=m[:, 6:9])
    q4 = _QUAT_DIAG_SIGNS @ m.take(_DIAG, axis=1).T     # (4, J): 4 |q_i|^2 - 1 from the diagonal
    q4 += 1.0
    np.maximum(q4, 0.0, out=q4)
    np.sqrt(q4, out=q4)
    q4 *= 0.5
    d = m.take(_SIGN_PLUS, axis=1).T
    d -= m.take(_SIGN_MINUS, axis=1).T
    v = q4[1:]
    np.negative(v, out=v, where=d < 0.0)                # sign(m21 - m12), sign(m02 - m20), sign(m10 - m01)
    p = q4 * q4
    n = p[0] + p[1]
    n += p[2]
    n += p[3]
    return q4.T / np.sqrt(n)[:, None]


def decode_source_pose(y: np.ndarray, n_bones: int, slices: dict | None = None) -> SourcePose:
    """A decompressor output vector as a :class:`SourcePose` (float64; bone 0 carries root velocities)."""
    s = slices or pose_vector_slices(n_bones)
    j = n_bones - 1
    y = y.astype(np.float64)
    pos = np.zeros((n_bones, 3))
    rot = np.zeros((n_bones, 4))
    vel = np.zeros((n_bones, 3))
    ang = np.zeros((n_bones, 3))
    pos[1:] = y[s["positions"]].reshape(j, 3)
    rot[0, 0] = 1.0
    rot[1:] = xform_xy_to_quat(y[s["rotations"]].reshape(j, 3, 2))
    vel[1:] = y[s["velocities"]].reshape(j, 3)
    ang[1:] = y[s["angular_velocities"]].reshape(j, 3)
    vel[0] = y[s["root_velocity"]]
    ang[0] = y[s["root_angular_velocity"]]
    return SourcePose(pos, rot, vel, ang, y[s["contacts"]] > 0.5, -1)


class LearnedMotionMatchingController(CharacterController):
    """Learned motion matching over ``db``/``features`` with ``networks`` (default: the shipped ones)."""

    name = "lmm"

    def __init__(self, db, features, tuning: Tuning | None = None, networks: LMMNetworks | None = None,
                 compare_with_search: bool = True):
        self.nets = networks if networks is not None else load_default_networks(db, features)
        if self.nets.n_bones != db.n_bones:
            raise WeightsError(f"{self.nets.path}: networks for {self.nets.n_bones} bones, database has {db.n_bones}")
        self.compare_with_search = compare_with_search
        self._slices = pose_vector_slices(db.n_bones)
        d = self.nets.n_features
        self.state = np.zeros(d + self.nets.n_latent, np.float32)
        self._deriv = np.zeros_like(self.state)
        self._pose_vec = np.zeros(self.nets.decompressor.n_out, np.float32)
        self._index: SearchIndex | None = None
        self._all_frames = np.ones(db.n_frames, dtype=bool)
        self._nn_frame = -1
        self._nn_cost = float("nan")
        self._projected = None
        self._projected_cost = float("nan")
        self._projected_frame = -1
        self._idle = None            # (frames, their network states) of the idle set, built on first use
        self.idle_note = ""          # why the idle set cannot be used ("" when it can)
        self._idle_playing = False   # the state was last set from the idle set
        super().__init__(db, features, tuning)

    # -- the networks ---------------------------------------------------------------------------
    def project(self, query_norm: np.ndarray) -> np.ndarray:
        """Projector on a query normalised with the controller's current feature weights -> state."""
        raw = self.features.denormalize(query_norm)
        return self.nets.projector(self.nets.to_network_space(raw))

    def decompress(self, state: np.ndarray) -> SourcePose:
        self.nets.decompressor(state, out=self._pose_vec)
        return decode_source_pose(self._pose_vec, self.n_bones, self._slices)

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
        """The three runtime networks (weights, biases, normalisation); the debug comparison's search
        index is not counted (it is off in a shipped runtime)."""
        return {name: int(getattr(self.nets, name).nbytes()) for name in RUNTIME_NETWORKS}

    # -- the idle set ------------------------------------------------------------------------------
    def idle_set_active(self) -> bool:
        """The stick has been released long enough for the idle set (see :class:`lmm.tuning.Tuning`)."""
        tun = self.tuning
        return bool(tun.idle_set_enabled) and self.stick_released_s >= tun.idle_delay_s - 1e-9

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

    def _idle_search(self, query_norm: np.ndarray):
        """(state, frame, cost) of the idle frame nearest the query, or None without an idle set."""
        idle = self.idle_states()
        if idle is None:
            return None
        frames, states = idle
        costs = np.sum((self.features.normalized[frames] - query_norm) ** 2, axis=1)
        k = int(np.argmin(costs))
        return states[k], int(frames[k]), float(costs[k])

    # -- hooks ----------------------------------------------------------------------------------
    def _reset_source(self, frame: int | None) -> None:
        frame = default_start_frame(self.db) if frame is None else int(frame)
        if not 0 <= frame < self.db.n_frames:
            raise ValueError(f"start frame {frame} is outside the database (0..{self.db.n_frames - 1})")
        self.state[:] = self.nets.projector(self.nets.to_network_space(self.features.raw[frame]))
        self._nn_frame = frame
        self._nn_cost = 0.0
        self._projected = self.features.normalize(self.nets.from_network_space(self.state[:self.nets.n_features]))
        self._projected_cost = float("nan")
        self._projected_frame = -1
        self._idle_playing = False

    def _source_features(self) -> np.ndarray:
        return self.nets.from_network_space(self.state[:self.nets.n_features])

    def _source_frame(self) -> int:
        return int(self._nn_frame)

    def _on_features_changed(self) -> None:
        if self._index is not None:
            self._index.update(self.features.normalized)

    def _search(self, query_norm: np.ndarray, forced: bool) -> SearchOutcome:
        timings = {}
        t0 = time.perf_counter()
        idle = self._idle_search(query_norm) if self.idle_set_active() else None
        projected = self.project(query_norm) if idle is None else idle[0].copy()
        timings["projector" if idle is None else "idle_search"] = (time.perf_counter() - t0) * 1e6
        d = self.nets.n_features
        proj_norm = self.features.normalize(self.nets.from_network_space(projected[:d]))
        projected_cost = float(np.sum((query_norm - proj_norm) ** 2))
        current_norm = self.features.normalize(self._source_features())
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
            t0 = time.perf_counter()
            self._projected_frame = int(self.exact_nearest(proj_norm, top_k=1)[0])
            timings["projected_frame_search"] = (time.perf_counter() - t0) * 1e6
        target = None
        if idle is not None:
            self._projected_frame = idle[1]     # the frame the "projection" stands for
        # entering the idle set always jumps (as MM's search then only sees idle frames); inside it, and
        # outside it, the usual rule: jump when the projection matches the query better
        entering_idle = idle is not None and not self._idle_playing
        if idle is None:
            self._idle_playing = False
        if entering_idle or projected_cost + float(self.tuning.transition_cost) < current_cost:
            self._idle_playing = idle is not None
            self.state[:] = projected
            t0 = time.perf_counter()
            target = self.decompress(self.state)
            timings["decompressor_transition"] = (time.perf_counter() - t0) * 1e6
        return SearchOutcome(target=target, best_frame=self._nn_frame, best_cost=projected_cost,
                             candidates=candidates, timings_us=timings)

    def _advance_pose(self, dt: float) -> SourcePose:
        if dt > 0:
            self.nets.stepper(self.state, out=self._deriv)
            self.state += np.float32(dt) * self._deriv
        return self.decompress(self.state)

    def _snapshot_extras(self) -> dict:
        d = self.nets.n_features
        # the projected frame belongs to the tick that projected: handed to its snapshot once, then cleared
        projected_frame, self._projected_frame = self._projected_frame, -1
        return {"latent": self.state[d:].copy(),
                "projected_features": None if self._projected is None else self._projected.copy(),
                "nn_frame": int(self._nn_frame), "nn_cost": float(self._nn_cost),
                "search_note": self.idle_note if self.idle_set_active() else "",
                "projected_cost": float(self._projected_cost),
                "projected_frame": int(projected_frame)}
