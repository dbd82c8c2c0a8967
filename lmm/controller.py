"""The controller interface shared by motion matching and learned motion matching.

Everything downstream (viewer, studio panels, recorder, metrics, benchmarks) talks to a
:class:`Controller` and reads :class:`DebugSnapshot` objects, so MM and LMM side by side are two
instances, not two code paths. Data flows one way each tick::

    InputState -> Controller.step(input, dt) -> (Pose, DebugSnapshot)

A controller reads its :class:`lmm.tuning.Tuning` object on every step, so a value changed between
two steps acts on the next one.
"""
from __future__ import annotations

from abc import ABC, abstractmethod
from dataclasses import dataclass, field

import numpy as np

from lmm.data.inputs import InputState  # one tick of input: data the logs hold and controllers read


@dataclass
class Pose:
    """The character's pose this tick, in world space (metres), database skeleton (bone 0 = simulation/root)."""
    local_positions: np.ndarray   # (J, 3) float32
    local_rotations: np.ndarray   # (J, 4) float32 (w, x, y, z)
    global_positions: np.ndarray  # (J, 3) float32
    global_rotations: np.ndarray  # (J, 4) float32
    contacts: np.ndarray          # (2,) bool: left, right foot contact


@dataclass
class Candidates:
    """Ranked search candidates for the debugger (best first)."""
    frames: np.ndarray            # (K,) int64 database frame indices
    costs: np.ndarray             # (K,) float32 total cost (channel costs + bias)
    channel_costs: np.ndarray     # (K, C) float32 per feature channel
    bias: np.ndarray              # (K,) float32 transition cost / continuing-pose bias added
    channel_names: list[str] = field(default_factory=list)

    @classmethod
    def empty(cls, n_channels: int = 0, channel_names=None) -> "Candidates":
        return cls(np.zeros(0, np.int64), np.zeros(0, np.float32), np.zeros((0, n_channels), np.float32),
                   np.zeros(0, np.float32), list(channel_names or []))


class LazyField:
    """A dataclass field whose value may be given as a zero-argument function, called (once) on the
    first read: debug-only data that costs time to compute (the ghost pose's forward kinematics, the
    trajectory and query of a tick that did not search) is computed only when a reader (the studio's
    panels) asks for it, never in headless runs.
    ``default``: the field's default value (without one the field is required)."""

    _NO_DEFAULT = object()

    def __init__(self, default=_NO_DEFAULT):
        self._default = default

    def __set_name__(self, owner, name):
        self._key = "_lazy_" + name

    def __get__(self, obj, objtype=None):
        if obj is None:
            if self._default is LazyField._NO_DEFAULT:
                raise AttributeError(self._key)  # no class-level default: the field stays required
            return self._default
        value = obj.__dict__[self._key]
        if callable(value):
            value = obj.__dict__[self._key] = value()
        return value

    def __set__(self, obj, value):
        obj.__dict__[self._key] = value


@dataclass
class DebugSnapshot:
    """Everything the studio draws for one tick of one controller. Plain arrays: cheap to keep in a ring buffer."""
    controller: str                      # "mm" or "lmm"
    tick: int
    time_s: float
    input: InputState
    # simulation object (the 'desired' character) and its predicted future (made on first read)
    simulation_position: np.ndarray = LazyField()  # (3,)
    simulation_rotation: np.ndarray = LazyField()  # (4,)
    simulation_velocity: np.ndarray = LazyField()  # (3,)
    desired_velocity: np.ndarray = LazyField()     # (3,)
    desired_rotation: np.ndarray = LazyField()     # (4,)
    # (the trajectory and the query are worked out on first read on a tick that did not search)
    trajectory_positions: np.ndarray = LazyField()  # (T, 3) world, at the feature offsets
    trajectory_rotations: np.ndarray = LazyField()  # (T, 4) world
    trajectory_offsets: np.ndarray       # (T,) frames ahead
    # matching
    query: np.ndarray = LazyField()      # (D,) normalised query features
    current_features: np.ndarray = LazyField()  # (D,) normalised features of the pose being played
    matched_frame: int                   # database frame being played (MM) / nearest frame (LMM)
    matched_features: np.ndarray = LazyField()  # (D,) normalised features of the matched frame
    candidates: Candidates = LazyField()  # the last search's ranked top K (MM: searched on first read)
    searched: bool                       # a search (MM) / projection (LMM) ran this tick
    forced_search: bool                  # ... because the input changed sharply
    transitioned: bool                   # MM: the played frame jumped; LMM: a projector jump (see lmm.learned)
    best_cost: float
    # pose, ghost and contacts
    pose: Pose
    matched_pose_positions: np.ndarray = LazyField()  # (J, 3) the matched frame's pose placed at the character
                                         # root (ghost); a function returning it may be given (computed on first read)
    foot_contacts: np.ndarray            # (2,) bool
    foot_locked: np.ndarray              # (2,) bool
    timings_us: dict[str, float] = field(default_factory=dict)
    # learned motion matching extras (None for MM)
    latent: np.ndarray | None = None             # (L,)
    projected_features: np.ndarray | None = None  # (D,) projector output, normalised
    nn_frame: int = -1                            # exact nearest neighbour of the same query
    nn_cost: float = float("nan")
    projected_cost: float = float("nan")          # query cost of the projector's features
    projected_frame: int = -1                     # LMM, on every tick that projected: the exact nearest database
                                                  # frame to the projector's features
                                                  # (LMM, on ticks it projected with the debug comparison on)
    matched_latent: np.ndarray | None = None      # (L,) compressor latent of the played frame (MM, when a
                                                  # latent table is attached: MotionMatchingController.set_latent_table)
    # cost of the playing pose's features against this tick's query (a per-tick cost timeline; best_cost
    # is the last search's best, carried between searches like ``candidates``)
    current_cost: float = LazyField(float("nan"))
    # a one-line warning about this tick's search (e.g. a tag filter that matched no frame, so every frame
    # was searched); empty when all is well
    search_note: str = ""


@dataclass(frozen=True)
class Capabilities:
    """What a controller offers beyond stepping, so that the studio asks for a capability instead of
    reaching for a controller by its name."""
    latent_dims: int = 0                 # its snapshots carry a ``latent`` of this size (0: none)
    networks_path: str | None = None     # the learned networks' file it runs (a compressor may lie beside it)
    latent_table: bool = False           # :meth:`Controller.set_latent_table` gives its snapshots ``matched_latent``
    idle_set_table: bool = False         # :meth:`Controller.warm_up` builds its idle set's table (worth doing early)


class Controller(ABC):
    """A character animation controller: reset, then step once per tick."""

    name: str = "controller"

    def capabilities(self) -> Capabilities:
        """What this controller offers beyond the contract (none by default)."""
        return Capabilities()

    def set_latent_table(self, table) -> None:
        """Attach a latent per database frame (only where ``capabilities().latent_table``)."""
        raise NotImplementedError(f"controller {self.name!r} takes no latent table")

    def warm_up(self) -> None:
        """Build the tables a first use would build mid-tick (a hitch); may run on another thread
        before the first step. Nothing by default."""

    @abstractmethod
    def reset(self, position=None, rotation=None, frame: int | None = None) -> None:
        """Put the character (and its simulation object) at a start state."""

    @abstractmethod
    def step(self, inp: InputState, dt: float) -> tuple[Pose, DebugSnapshot]:
        """Advance one tick of ``dt`` seconds with the given input."""

    @abstractmethod
    def memory_bytes(self) -> dict[str, int]:
        """What the method keeps in memory at run time, by part (bytes); the studio's stats panel and
        ``lmm-studio bench``'s memory section both read this. Debug-only state is not counted."""
