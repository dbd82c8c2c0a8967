"""The tick's values that only a search or a reader of the :class:`lmm.controller.DebugSnapshot` needs,
worked out on first read from what the tick took: the predicted trajectory and the query
(:class:`TickQuery`), the feature values the debugger shows (:class:`SnapshotFeatures`), arrays of the
tick's float tuples (:func:`array_of`). A headless run computes none of them on a tick without a search."""
from __future__ import annotations

import functools

import numpy as np

from lmm.features import build_query_from_columns, normalize_with
from lmm.kinematics import pose_forward_kinematics
from lmm.trajectory import trajectory_in_root_space, trajectory_predict


def made(value):
    """``value``, or what it makes when it is a zero-argument function (a value given for later)."""
    return value() if callable(value) else value


def ghost_positions(source, root_position, root_rotation, parents):
    """A function making the ghost's world positions (J, 3) float32: the source pose without offsets,
    placed at the character root (``root_*``: tuples). A source pose and the root tuples are new every
    tick, never written in place, so the function may read them whenever it is called."""
    def ghost():
        ghost_rot = source.rotations.copy()
        ghost_pos = source.positions.copy()
        ghost_rot[0] = root_rotation
        ghost_pos[0] = root_position
        return np.array(pose_forward_kinematics(ghost_rot, ghost_pos, parents)[1]).astype(np.float32)
    return ghost


def array_of(floats: tuple):
    """A function making a new float64 array of ``floats`` (a tuple, never written): a snapshot field
    made when read (see :class:`lmm.controller.LazyField`)."""
    return functools.partial(np.array, floats)


class SnapshotFeatures:
    """A tick's debug-only feature values for :class:`lmm.controller.DebugSnapshot`'s lazy fields: the
    playing pose's normalised features (``current``), their cost against the query (``cost``) and the
    matched frame's normalised features (``matched``), each computed on first read with the operations
    :meth:`lmm.features.Features.normalize` and the squared distance use. The feature scaling is taken
    now (a weight change replaces those arrays, never writes them), as are the raw features and the
    query (neither is written once made; each may be given as a function that makes it, see
    :meth:`CharacterController._source_features_later` and :meth:`TickQuery.query`), so a later read
    gives this tick's values."""

    __slots__ = ("_raw", "_mean", "_inv_scale", "_normalized", "_query", "_frame", "_current")

    def __init__(self, features, raw, query, frame: int):
        self._raw, self._query, self._frame = raw, query, int(frame)
        self._mean, self._inv_scale, self._normalized = features.mean, features.inv_scale, features.normalized
        self._current = None

    def current(self) -> np.ndarray:
        if self._current is None:
            self._current = normalize_with(made(self._raw), self._mean, self._inv_scale)
        return self._current

    def cost(self) -> float:
        query = self._query = made(self._query)     # the tick's query, worked out on first read (_TickQuery)
        diff = query - self.current()
        diff *= diff                    # the same squares as (query - current) ** 2
        return float(diff.sum())

    def matched(self) -> np.ndarray:
        return self._normalized[self._frame].copy() if self._frame >= 0 else self.current()


class TickQuery:
    """One tick's predicted trajectory (world positions and rotations at the feature offsets) and its
    query (normalised features: the pose channels from the playing pose, the trajectory channels from
    the prediction seen from the character root, as every database frame's features are seen from its
    own root, so a character lagging behind the simulation object asks for the motion that catches up).

    A search needs the query and the debugger both; a tick that does not search needs neither, so each is
    worked out on first call (:class:`lmm.controller.LazyField` takes the methods). Everything they read
    is taken now: the simulation state and goals (tuples), the character root before this tick's
    integration, the playing pose's raw features and the feature scaling (replaced, never written, when
    they change), so a later call gives this tick's values, with the same float operations."""

    __slots__ = ("_args", "_times", "_root", "_source", "_columns", "_mean", "_inv_scale", "_traj", "_query")

    def __init__(self, controller, state, des_vel, des_rot, vel_halflife, rot_halflife, source):
        """``source``: the playing pose's raw features, or a function giving them (see
        :meth:`CharacterController._source_features_later`)."""
        self._args = (*state, des_vel, des_rot, vel_halflife, rot_halflife)
        self._times = controller._traj_times
        self._root = (controller._root_position_t, controller._root_rotation_t)
        self._source = source
        self._columns = controller._query_columns
        features = controller.features
        self._mean, self._inv_scale = features.mean, features.inv_scale
        self._traj = self._query = None

    def _trajectory(self) -> tuple:
        traj = self._traj
        if traj is None:
            traj = self._traj = trajectory_predict(*self._args, self._times)
        return traj

    def positions(self) -> np.ndarray:
        return np.array(self._trajectory()[0])

    def rotations(self) -> np.ndarray:
        return np.array(self._trajectory()[1])

    def query(self) -> np.ndarray:
        if self._query is None:
            traj_pos, traj_rot = self._trajectory()
            local_pos, local_dir = trajectory_in_root_space(traj_pos, traj_rot, *self._root)
            raw = build_query_from_columns(made(self._source), self._columns, local_pos, local_dir)
            self._query = normalize_with(raw, self._mean, self._inv_scale)
        return self._query
