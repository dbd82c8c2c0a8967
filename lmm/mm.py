"""Motion matching: the pose source plays database frames and jumps to the best match of each search."""
from __future__ import annotations

import math

import numpy as np

from lmm.character import CharacterController
from lmm.source_pose import SearchOutcome, SourcePose, database_source_pose, root_local_velocities
from lmm.controller import Candidates, Capabilities
from lmm.data.derived import cached
from lmm.search import SearchIndex, biased_search, brute_force_search, candidate_mask
from lmm.tuning import DEFAULT_TAG_BIAS, IDLE_TAG, Tuning, TuningError


def default_start_frame(db) -> int:
    """A standing frame: the slowest root and hips among frames away from the ends of their ranges
    (cached beside the database file)."""
    return int(cached(db, "default_start_frame", [], lambda: np.array(_slowest_frame(db), dtype=np.int64)))


def _slowest_frame(db) -> int:
    root_speed = np.linalg.norm(db.velocities[:, 0], axis=-1)
    hips_speed = np.linalg.norm(db.velocities[:, db.bone("hips")], axis=-1)
    score = root_speed + hips_speed
    ok = candidate_mask(db.n_frames, db.range_starts, db.range_stops, 60)
    for start in db.range_starts:
        ok[int(start):int(start) + 60] = False
    if not ok.any():
        ok[:] = True
    return int(np.flatnonzero(ok)[np.argmin(score[ok])])


class MotionMatchingController(CharacterController):
    """Motion matching over ``db`` with ``features``; every tunable comes from ``tuning``.

    The pose source is a database frame index advanced at the database rate (one frame per tick at
    60 Hz; other tick rates advance by the elapsed whole frames). A search compares the query with
    every candidate frame (exactly, accelerated by :class:`lmm.search.SearchIndex` unless
    ``tuning.accelerated_search`` is off) and jumps when a frame other than the playing one wins.
    """

    name = "mm"

    def __init__(self, db, features, tuning: Tuning | None = None):
        self.index: SearchIndex | None = None
        self._root_vel, self._root_ang = root_local_velocities(db)
        self.frame = 0
        self.phase = 0.0
        self._range_bounds = (0, 0)  # [first frame, stop) of the range _range_stop last looked up
        self.last_search = None
        self._hint = None          # the last search's candidates ...
        self._frames_since = 0     # ... and the frames played since (they seed the next search's bound)
        self.search_log: list | None = None  # set to a list to collect (query, frame, hint) per search
        self.latent_table: np.ndarray | None = None
        self.tag_error: str | None = None  # a tag filter or bias that could not apply (the search used all frames)
        self._tag_groups: tuple | None = None  # (key, [(bias, mask)]) cached for the tuning it was made for
        self._tag_tuning: tuple | None = None  # (tags, bias, excluded, unknown) of the tuning's tag fields, see below
        super().__init__(db, features, tuning)

    def set_latent_table(self, table: np.ndarray | None) -> None:
        """Attach the compressor latent of every database frame, (N, L) (see
        :func:`lmm.latents.database_latents`), or detach it with None. While one is attached, each
        snapshot's ``matched_latent`` is the latent of the frame being played. May be called from another
        thread between two steps (a single attribute store)."""
        if table is not None:
            table = np.asarray(table)
            if table.ndim != 2 or table.shape[0] != self.db.n_frames:
                raise ValueError(f"a latent table needs one row per database frame ({self.db.n_frames}), "
                                 f"got shape {table.shape}")
        self.latent_table = table

    def capabilities(self) -> Capabilities:
        return Capabilities(latent_table=True)

    def memory_bytes(self) -> dict[str, int]:
        """Pose data (Y), normalised features (X) and, once the first search has built it, the search
        index's own arrays."""
        parts = {"pose data (Y)": int(self.db.pose_bytes()), "features (X)": int(self.features.normalized.nbytes)}
        if self.index is not None:
            parts["search index"] = self.index.nbytes()
        return parts

    # -- hooks ----------------------------------------------------------------------------------
    def _reset_source(self, frame: int | None) -> None:
        self.frame = default_start_frame(self.db) if frame is None else int(frame)
        if not 0 <= self.frame < self.db.n_frames:
            raise ValueError(f"start frame {frame} is outside the database (0..{self.db.n_frames - 1})")
        self.phase = 0.0
        self._hint = None
        self._frames_since = 0

    def _source_features(self) -> np.ndarray:
        return self.features.raw[self.frame]

    def _source_frame(self) -> int:
        return int(self.frame)

    def _must_jump(self) -> bool:
        return self.frame >= self._range_stop(self.frame) - 1

    def _range_stop(self, frame: int) -> int:
        """``db.range_stop_of(frame)``, remembered for the range last asked about (the source plays on in
        one range between jumps)."""
        lo, hi = self._range_bounds
        if not lo <= frame < hi:
            i = int(self.db.range_index(frame))
            lo = int(self.db.range_stops[i - 1]) if i > 0 else 0
            hi = int(self.db.range_stops[i]) if i < len(self.db.range_stops) else lo
            self._range_bounds = (lo, hi)
            if not lo <= frame < hi:        # outside every range: no caching
                return int(self.db.range_stop_of(frame))
        return hi

    def _on_features_changed(self) -> None:
        if self.index is not None:
            self.index.update(self.features.normalized)

    def _on_tuning_change(self, change) -> None:
        super()._on_tuning_change(change)
        if change.field in ("tag_bias", "tag_excluded"):
            self._tag_tuning = None

    def tag_groups(self) -> list[tuple[float, np.ndarray]]:
        """The candidate mask split into (tag bias, mask) groups under the current tuning: without the
        frames of excluded tags, restricted to the idle set while it is active, one group per distinct sum
        of tag biases. An exclusion or idle set leaving no frame, or a bias or exclusion on a tag the
        database lacks, sets ``tag_error`` (a TuningError's one line) and is ignored."""
        mask = self.candidate_mask()
        idle = self.idle_set_active()
        tags = tuple(self.db.tag_names)
        if self._tag_tuning is None or self._tag_tuning[0] != tags:   # again after a tag field's change event
            tun = self.tuning
            # a bias or exclusion the user set on a tag this database lacks is worth a note; a shipped default
            # is not
            self._tag_tuning = (
                tags, tuple(float(tun.tag_bias.get(t, 0.0)) for t in tags), tun.excluded_tags(tags),
                tuple(sorted([("tag_bias", t) for t, b in tun.tag_bias.items()
                              if b != DEFAULT_TAG_BIAS.get(t, 0.0) and t not in tags]
                             + [("tag_excluded", t) for t, on in tun.tag_excluded.items() if on and t not in tags])))
        _, bias, excluded, unknown = self._tag_tuning
        key = (id(mask), idle, bias, excluded, unknown)
        if self._tag_groups is not None and self._tag_groups[0] == key:
            return self._tag_groups[1]
        errors = []
        excluding = False
        if excluded:
            kept = mask & ~self.db.tag_mask(excluded)
            excluding = bool(kept.any())
            if excluding:
                mask = kept
            else:
                errors.append(TuningError(f"tuning field 'tag_excluded': excluding {', '.join(excluded)} leaves no "
                                          f"candidate frame of database {self.db.name!r}; excluding nothing"))
        if idle:
            idle_mask = mask & self.db.tag_mask(IDLE_TAG)
            if idle_mask.any():
                mask = idle_mask
            else:
                errors.append(TuningError(f"tuning field 'idle_set_enabled': no candidate frame of database "
                                          f"{self.db.name!r} is tagged {IDLE_TAG!r}"
                                          f"{' outside the excluded tags' if excluding else ''}; searching every "
                                          f"frame{' not excluded' if excluding else ''}"))
        if unknown:
            field_name, tag = unknown[0]
            errors.append(TuningError(f"tuning field '{field_name}.{tag}': database {self.db.name!r} has no "
                                      f"range tagged {tag!r} (tags: {', '.join(tags) or 'none'})"))
        self.tag_error = str(errors[0]) if errors else None
        if any(bias):
            frame_bias = (self.db.frame_tags.astype(np.float32) @ np.asarray(bias, dtype=np.float32))
            groups = [(float(b), mask & (frame_bias == b)) for b in np.unique(frame_bias[mask])]
        else:
            groups = [(0.0, mask)]
        self._tag_groups = (key, groups)
        return groups

    def search_hint(self) -> np.ndarray | None:
        """Where the last search's candidates are now: a good first guess for the next search."""
        return None if self._hint is None else self._hint + self._frames_since

    def search(self, query_norm: np.ndarray, accelerated: bool | None = None, hint=None, top_k: int | None = None,
               near: int = 0, groups=None):
        """Run the search for a normalised query from the current state (no side effects): the ranked top
        ``top_k`` (default: the tuning's, as the debugger shows them). ``near``: see
        :meth:`lmm.search.SearchIndex.group_search` (the accelerated search only); ``groups``: the
        :meth:`tag_groups` when the caller has them."""
        tun = self.tuning
        if self.index is None:
            self.index = SearchIndex(self.features.normalized)
        self.index.update(self.features.normalized)
        accelerated = tun.accelerated_search if accelerated is None else accelerated
        hint = self.search_hint() if hint is None else hint
        return _run_search(self.index if accelerated else None, self.features.normalized, query_norm,
                           self.tag_groups() if groups is None else groups, hint,
                           self.search_args(int(tun.top_k) if top_k is None else int(top_k)), near)

    def search_args(self, top_k: int) -> dict:
        """The search's arguments from the playing frame and the tuning, as they are now (``top_k``
        ranked frames)."""
        tun = self.tuning
        return dict(current=int(self.frame), transition_cost=tun.transition_cost,
                    exclude_window=int(tun.exclude_current_window_frames), top_k=top_k,
                    slices=self.features.slices)

    def _search(self, query_norm: np.ndarray, forced: bool) -> SearchOutcome:
        hint = self.search_hint()
        if self.search_log is not None:
            self.search_log.append((np.array(query_norm, copy=True), int(self.frame),
                                    None if hint is None else hint.copy()))
        # the tick needs the best frame only; the debugger's ranked top K is searched when read
        top_k = int(self.tuning.top_k)
        groups = self.tag_groups()
        res = self.search(query_norm, hint=hint, top_k=1, near=top_k, groups=groups)
        ranked = _RankedLater(self, query_norm, hint, top_k, groups) if top_k > 1 else None
        self.last_search = res
        near = res.near_frames
        self._hint, self._frames_since = (near if near is not None and near.size else res.frames), 0
        cands = ranked if ranked is not None else _candidates(res, self.features.names)
        best = res.best_frame
        target = None
        if best >= 0 and best != self.frame:
            self.frame = best
            self.phase = 0.0
            target = self._pose(best)
        return SearchOutcome(target=target, best_frame=best, best_cost=res.best_cost, candidates=cands)

    def _advance_pose(self, dt: float) -> SourcePose:
        self.phase += dt * self.db.fps
        steps = math.floor(self.phase + 1e-6)
        if steps > 0:
            self.phase -= steps
            self._frames_since += steps
            last = self._range_stop(self.frame) - 1
            self.frame = min(self.frame + steps, last)
        return self._pose(self.frame)

    def _snapshot_extras(self) -> dict:
        table = self.latent_table
        extras = {"search_note": self.tag_error or ""}
        if table is not None:
            extras["matched_latent"] = np.array(table[self.frame], np.float32)
        return extras

    def _pose(self, frame: int) -> SourcePose:
        return database_source_pose(self.db, frame, self._root_vel, self._root_ang)


def _run_search(index, features_norm, query, groups, hint, args, near: int = 0):
    """One search of ``features_norm``: through ``index`` (every tag group in one pass, the same answer as
    one search per group) when it indexes those features, else by brute force."""
    if index is not None and index.features_norm is features_norm:
        return index.group_search(query, groups, hint=hint, near=near, **args)
    return biased_search(lambda **kw: brute_force_search(features_norm, query, **kw), groups[0][1], None,
                         group_masks=groups, **args)


def _candidates(res, names) -> Candidates:
    return Candidates(frames=res.frames, costs=res.costs, channel_costs=res.channel_costs, bias=res.bias,
                      channel_names=names)


class _RankedLater:
    """A search's ranked top K for the debugger (:class:`lmm.controller.Candidates`), searched on the first
    call and kept: the controller's tick searches for the best frame only, and a headless run never asks
    for the rest. Everything the search reads is taken at the tick (the features, the tag groups, the
    playing frame and the tuning; none of them is written once made, a change replaces them), so a later
    call gives the top K the tick would have found: from the index while it still indexes those features,
    else by brute force (the same answer, exactly)."""

    __slots__ = ("_index", "_norm", "_query", "_groups", "_args", "_hint", "_names", "_value")

    def __init__(self, controller: MotionMatchingController, query_norm: np.ndarray, hint, top_k: int, groups):
        self._index = controller.index if controller.tuning.accelerated_search else None
        self._norm, self._query, self._hint = controller.features.normalized, query_norm, hint
        self._groups = groups           # the tick's tag groups (each made once, never written)
        self._args = controller.search_args(int(top_k))
        self._names = controller.features.names
        self._value = None

    def __call__(self) -> Candidates:
        if self._value is None:
            res = _run_search(self._index, self._norm, self._query, self._groups, self._hint, self._args)
            self._value = _candidates(res, self._names)
        return self._value
