"""The cost of a candidate frame and the order of candidates: a nearest-frame search's answer, best first
(see :mod:`lmm.search`).

Every search computes a frame's cost by :func:`frame_costs`' row reduction, so the searches agree bit for bit.
Ranking is by total cost, ties broken by frame index; the continuing (playing) frame goes before the first
candidate whose total is not lower (a tie keeps playing). With tag biases the candidates fall into groups of
equal bias: each group is ranked on its own and the groups merged by total (:func:`merge_groups`), or both at
once over the few candidates that can reach the top K (:func:`rank_groups`, the index's one-pass search).
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np


@dataclass
class SearchResult:
    """Top-K candidates, best first. ``frames[0]`` is the answer.

    ``channel_costs`` (K, C) float32, the per-channel breakdown for the debugger, is computed on first
    access (a headless run never pays for it).
    """
    frames: np.ndarray          # (K,) int64
    costs: np.ndarray           # (K,) float32 total cost (feature cost + bias)
    bias: np.ndarray            # (K,) float32 transition cost added (0 for the continuing frame)
    continuing_frame: int = -1  # the playing frame, -1 when none
    continuing_cost: float = float("nan")  # its feature cost, NaN when it could not compete
    evaluated: int = 0          # frames whose exact cost was computed
    # (group_search with ``near``) up to ``near`` evaluated frames of least total away from the playing
    # frame and the answer, unordered: the next search's hint (cheaper than ranking a top K for it)
    near_frames: np.ndarray | None = None
    _breakdown: tuple | None = field(default=None, repr=False)   # (features_norm, query, slices)
    _channel_costs: np.ndarray | None = field(default=None, repr=False)

    @property
    def channel_costs(self) -> np.ndarray:
        if self._channel_costs is None:
            features_norm, query, slices = self._breakdown
            self._channel_costs = channel_costs(features_norm, self.frames, query, slices)
        return self._channel_costs

    @property
    def best_frame(self) -> int:
        return int(self.frames[0]) if self.frames.size else -1

    @property
    def best_cost(self) -> float:
        return float(self.costs[0]) if self.costs.size else float("inf")


def frame_costs(rows: np.ndarray, query: np.ndarray) -> np.ndarray:
    """Squared distances (n,) of feature rows (n, D) to the query (D,), float32."""
    d = rows - query
    return np.einsum("ij,ij->i", d, d)


def continuing_cost(features_norm, query, mask, current):
    """The playing frame's feature cost (float32 value), NaN when it may not compete."""
    if current >= 0 and mask[current]:
        d = features_norm[current:current + 1] - query
        return float(np.einsum("ij,ij->i", d, d)[0])
    return float("nan")


def channel_costs(features_norm: np.ndarray, frames: np.ndarray, query: np.ndarray, slices) -> np.ndarray:
    """(K, C) per-channel costs of the given frames."""
    if not len(frames):
        return np.zeros((0, len(slices)), dtype=np.float32)
    d = features_norm[frames] - query
    d *= d
    starts = [s.start for s in slices]
    if all(s.step in (None, 1) for s in slices) and starts == sorted(starts) and \
            all(a.stop == b.start for a, b in zip(slices, slices[1:])) and slices[-1].stop == d.shape[1]:
        return np.add.reduceat(d, starts, axis=1).astype(np.float32, copy=False)
    return np.stack([d[:, s].sum(axis=1) for s in slices], axis=1).astype(np.float32)


def rank(frames, costs, current, cont_cost, transition_cost, top_k):
    """Top-K of the non-continuing candidates merged with the continuing one, best first.

    ``frames`` must be ascending (both searches produce them so): ties in cost go to the lower frame.
    The continuing frame goes before any candidate with the same total (a tie keeps playing).
    Returns (frames int64, total costs float32, bias float32).
    """
    if costs.size > top_k:
        # everything tied with or better than the k-th cost: a handful of candidates
        kth = np.partition(costs, top_k - 1)[top_k - 1]
        keep = (costs <= kth).nonzero()[0]
        frames, costs = frames[keep], costs[keep]
    tc = np.float32(transition_cost)
    total = costs + tc                       # float32 sums (monotonic in the cost)
    ranked = sorted(zip(costs.tolist(), frames.tolist(), total.tolist()))[:top_k]
    frames = [f for _, f, _ in ranked]
    totals = [t for _, _, t in ranked]
    bias = [float(tc)] * len(frames)
    if current >= 0 and cont_cost == cont_cost:  # not NaN
        at = next((i for i, t in enumerate(totals) if t >= cont_cost), len(totals))
        if at < top_k:
            frames.insert(at, int(current))
            totals.insert(at, cont_cost)
            bias.insert(at, 0.0)
            del frames[top_k:], totals[top_k:], bias[top_k:]
    return (np.array(frames, dtype=np.int64), np.array(totals, dtype=np.float32),
            np.array(bias, dtype=np.float32))


def make_result(features_norm, query, slices, frames, total, bias, current, cont_cost, evaluated):
    return SearchResult(frames=frames, costs=total, bias=bias, continuing_frame=int(current),
                        continuing_cost=float(cont_cost), evaluated=int(evaluated),
                        _breakdown=(features_norm, query, slices))


def rank_groups(frames, costs, keys, frame_group, b32, current, cont_cost, in_group, tc, top_k):
    """Exactly ``merge_groups`` of every group's ``rank`` (same frames, totals, biases and order), for the
    frames evaluated (ascending) with their feature ``costs`` and ``keys`` (the merge's totals,
    ``(cost + tc) + group bias`` in float32, inf for frames that are not candidates), from only the few that
    can reach the answer. ``b32``: the groups' biases (float32); ``tc`` the transition cost (float32).

    Let ``kth`` be the k-th smallest key. Rounding is monotonic, so each group's own top-K holds that group's
    smallest keys, and the groups' lists together hold k candidates with key <= kth: nothing above ``kth``
    can be in the answer, the playing frame included. The candidates with key <= kth are, in each group, all
    those ranked before any of them (a lower cost never has a higher key), so each group's ranking and cut at
    K over them alone is its full ranking's start. The playing frame goes where the full ranking puts it:
    before the first of them whose total is not lower, else after them all (where, when a later candidate
    of its group has a lower total, its key is above ``kth`` and it is cut in the merge either way).
    """
    cont_group = int(frame_group[current]) if in_group and cont_cost == cont_cost else -1  # NaN: not competing
    cont_row = _cont_row(frame_group, b32, current, cont_cost, in_group)
    if top_k == 1 and keys.size:
        # the controller's tick search: usually one least key, and the playing frame's total differs from
        # it; then the ranking below keeps that frame and the playing frame and sorts the two, which is
        # what this does without building it (a tie falls through to the full ranking)
        i = int(keys.argmin())
        least = keys[i]
        if least < np.inf and np.count_nonzero(keys == least) == 1:
            row = (float(least), 1, int(frames[i]), float(tc + b32[frame_group[frames[i]]]))
            if cont_row is None:
                return _rows_result([row])
            if cont_row[0] != row[0]:
                return _rows_result([min(row, cont_row)])
    if keys.size > top_k:
        kth = np.partition(keys, top_k - 1)[top_k - 1]
        few = (keys <= kth).nonzero()[0] if kth < np.inf else (keys < np.inf).nonzero()[0]
    else:
        few = (keys < np.inf).nonzero()[0]
    f_few = frames[few]
    key_list, group_list = keys[few].tolist(), frame_group[f_few].tolist()
    # usually no two of these keys are equal: then each group's ranking is its key order and the playing
    # frame sits at its key's place in it, so every cut at K that the groups make only drops rows that K
    # rows of the same group precede anyway: the merge is a plain sort by key
    if len(set(key_list)) == len(key_list) and (cont_group < 0 or cont_row[0] not in key_list):
        bias = {g: float(tc + b32[g]) for g in set(group_list)}
        rows = [(key, 1, f, bias[g]) for key, f, g in zip(key_list, f_few.tolist(), group_list)]
        if cont_group >= 0:
            rows.append(cont_row)
        rows.sort()
        del rows[top_k:]
        return _rows_result(rows)
    costs = costs[few]
    by_group = {}
    for row in zip(costs.tolist(), f_few.tolist(), (costs + tc).tolist(), key_list, group_list):
        by_group.setdefault(row[4], []).append(row)
    if cont_group >= 0:
        by_group.setdefault(cont_group, [])
    rows = []
    for g, members in by_group.items():
        members.sort()                      # each group's ranking: cost, then frame
        del members[top_k:]
        bias = float(tc + b32[g])
        group_rows = [(key, 1, f, bias) for _, f, _, key, _ in members]
        if g == cont_group:
            at = next((i for i, m in enumerate(members) if m[2] >= cont_cost), len(members))
            group_rows.insert(at, cont_row)
            del group_rows[top_k:]
        rows += group_rows
    rows.sort()                             # the merge: total, the playing frame first, then frame
    del rows[top_k:]
    return _rows_result(rows)


_INF = float("inf")


def rank_top1(frames, costs, frame_bias, frame_group, b32, current, cont_cost, in_group, tc):
    """``rank_groups(..., top_k=1)`` (and, with one group of bias 0, ``rank``'s top 1) for a few frames,
    the compiled filter's: their keys ``(cost + tc) + bias`` worked out here as float32 scalars, the same
    float32 sums as the arrays' (no arrays for two or three frames). None when there are more than 8 or the
    least key ties (another frame, or the playing frame's total): the caller then ranks in full."""
    if len(frames) > 8:
        return None
    best_key, best_f, tie = _INF, -1, False
    for c, f in zip(costs, frames.tolist()):      # float32 scalars: float32 sums
        key = (c + tc) + frame_bias[f]
        if key < best_key:
            best_key, best_f, tie = key, f, False
        elif key == best_key:
            tie = True
    cont_row = _cont_row(frame_group, b32, current, cont_cost, in_group)
    if best_f < 0 or not best_key < _INF:        # no candidate: the playing frame, if it competes
        if cont_row is None:
            return top1_arrays(-1, 0.0, 0.0)
        row = cont_row
    elif tie:
        return None
    else:
        row = (float(best_key), 1, best_f, float(tc + b32[frame_group[best_f]]))
        if cont_row is not None:
            if cont_row[0] == row[0]:
                return None
            row = min(row, cont_row)
    return top1_arrays(row[2], row[0], row[3])


def top1_arrays(frame: int, total: float, bias: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(frames, totals, biases) of a top-1 answer: one row, or none for ``frame`` -1."""
    if frame < 0:
        return np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.float32), np.zeros(0, dtype=np.float32)
    return (np.array((frame,), dtype=np.int64), np.array((total,), dtype=np.float32),
            np.array((bias,), dtype=np.float32))


def _cont_row(frame_group, b32, current, cont_cost, in_group):
    """The playing frame's ranking row ``(total, 0, frame, bias)`` (its total: cost + its group's bias in
    float32, no transition cost; its bias: float32 0 + the group's, which is the group's (+0.0 for -0.0, as
    x + 0.0 gives)), or None when it does not compete (NaN cost or not a candidate)."""
    if not (in_group and cont_cost == cont_cost):
        return None
    g = int(frame_group[current])
    return float(np.float32(cont_cost) + b32[g]), 0, int(current), float(b32[g]) + 0.0


def least_frames(frames: np.ndarray, keys: np.ndarray, n: int) -> np.ndarray:
    """Up to ``n`` of ``frames`` with the least finite ``keys``, unordered."""
    if keys.size > n:
        pick = keys.argpartition(n - 1)[:n]
        frames, keys = frames[pick], keys[pick]
    return frames[keys < np.inf]


def _rows_result(rows) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(frames, totals, biases) of ranked ``(total, order, frame, bias)`` rows."""
    return (np.array([r[2] for r in rows], dtype=np.int64), np.array([r[0] for r in rows], dtype=np.float32),
            np.array([r[3] for r in rows], dtype=np.float32))


def merge_groups(per_group, biases, current, k, features_norm, query, slices, cont, evaluated) -> SearchResult:
    """Merge per-group (frames, totals, bias) by total + group bias (ties: the continuing frame first, then
    the lower frame) into the top K."""
    rows = []
    for (frames, costs, bias), b in zip(per_group, biases):
        b32 = np.float32(b)   # float32 sums, as the per-frame totals are computed everywhere else
        for f, c, fb in zip(frames.tolist(), (costs + b32).tolist(), (bias + b32).tolist()):
            # the playing frame is never an ordinary candidate (exclusion window): it goes first on a tie
            rows.append((c, 0 if f == current else 1, f, fb))
    rows.sort()
    rows = rows[:k]
    frames = np.array([r[2] for r in rows], dtype=np.int64)
    total = np.array([r[0] for r in rows], dtype=np.float32)
    bias = np.array([r[3] for r in rows], dtype=np.float32)
    return make_result(features_norm, query, slices, frames, total, bias, current, cont, evaluated)
