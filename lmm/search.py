"""Nearest-frame search over the normalised database features: the costs, the candidates, the brute force.

The cost of frame ``i`` for a normalised query ``q`` is ``sum_d (X[i, d] - q[d])^2``. Candidates:

* the *continuing* frame (the one being played) competes with its bare cost, unless it lies in the
  excluded end of its range (it could not keep playing there);
* every other frame carries ``transition_cost`` on top of its cost, and is excluded when it lies within
  ``exclude_window`` frames of the continuing one (``|i - current| <= exclude_window``) or in the last
  ``exclude_end`` frames of its range (see :func:`candidate_mask`).

Ranking is by cost, ties broken by frame index (every other candidate carries the same transition cost);
the continuing frame goes before the first candidate whose total is not lower (a tie keeps playing). Both
searches give the same ordered top-K. Per-frame costs are always computed by the same ``einsum`` row
reduction (its result for a row does not depend on how many rows are passed), so the accelerated search
reproduces the brute-force costs bit for bit.

This module is the search's entry point. The exact accelerated search, :class:`SearchIndex` (same answers
bit for bit), is in :mod:`lmm.search_index`; the per-frame costs, the ranking of candidates (ties, the
continuing frame, tag-bias groups merged) and the result in :mod:`lmm.search_ranking`; the compiled filter
that the index's runtime call goes through when a C compiler is there (a tail of a fraction of a
millisecond on half a million frames; numpy is the fallback and the reference) in :mod:`lmm.search_native`.
"""
from __future__ import annotations

import numpy as np

from lmm.search_index import SearchIndex
from lmm.search_ranking import SearchResult, channel_costs, continuing_cost, frame_costs, make_result, merge_groups, rank

__all__ = ["SearchIndex", "SearchResult", "biased_search", "brute_force_search", "candidate_mask", "channel_costs",
           "frame_costs"]


def candidate_mask(n_frames: int, range_starts, range_stops, exclude_end: int) -> np.ndarray:
    """(N,) bool: frames that may be jumped to (not in the last ``exclude_end`` frames of their range)."""
    mask = np.ones(n_frames, dtype=bool)
    if exclude_end > 0:
        for start, stop in zip(np.asarray(range_starts), np.asarray(range_stops)):
            mask[max(int(stop) - exclude_end, int(start)):int(stop)] = False
    return mask


def brute_force_search(features_norm: np.ndarray, query: np.ndarray, mask: np.ndarray, current: int = -1,
                       transition_cost: float = 0.0, exclude_window: int = 20, top_k: int = 1,
                       slices=None) -> SearchResult:
    """The reference search: every frame's exact cost, vectorised.

    ``mask`` from :func:`candidate_mask`; ``current`` the playing frame (-1: none); ``slices`` the feature
    channels' dimension slices (for the per-channel breakdown; default one channel with every dim).
    """
    query = np.asarray(query, dtype=np.float32)
    slices = slices if slices is not None else [slice(0, features_norm.shape[1])]
    k = max(int(top_k), 1)
    costs = frame_costs(features_norm, query)
    pool = np.where(mask, costs, np.float32(np.inf))
    if current >= 0:
        pool[max(current - exclude_window, 0):current + exclude_window + 1] = np.inf
    kth = np.partition(pool, k - 1)[k - 1] if pool.size > k else np.float32(np.inf)
    frames = (pool <= kth).nonzero()[0] if kth < np.inf else (pool < np.inf).nonzero()[0]
    cont = continuing_cost(features_norm, query, mask, current)
    f, total, bias = rank(frames, costs[frames], current, cont, transition_cost, k)
    return make_result(features_norm, query, slices, f, total, bias, current, cont, costs.size)


def biased_search(search, mask: np.ndarray, frame_bias: np.ndarray | None, current: int = -1,
                  transition_cost: float = 0.0, top_k: int = 1, group_masks=None, **kwargs) -> SearchResult:
    """``search(mask=..., current=..., transition_cost=..., top_k=..., **kwargs)`` (:func:`brute_force_search`
    or :meth:`lmm.search_index.SearchIndex.search`) with a per-frame cost ``frame_bias`` (N,) float32 added
    to every candidate, the continuing frame included.

    Exact: the candidates split into groups of equal bias (a few: one per combination of biased tags);
    each group is searched on its own and the results are merged by total cost (ties: the continuing
    frame first, then the lower frame). ``group_masks``: the (bias, mask) groups when cached by the caller.
    A candidate is always a frame of ``mask``.
    """
    if group_masks is None:
        if frame_bias is None:
            group_masks = [(0.0, mask)]
        else:
            group_masks = [(float(b), mask & (frame_bias == b)) for b in np.unique(frame_bias[mask])]
    if len(group_masks) == 1 and group_masks[0][0] == 0.0:
        return search(mask=group_masks[0][1], current=current, transition_cost=transition_cost, top_k=top_k,
                      **kwargs)
    k = max(int(top_k), 1)
    per_group, first, cont, evaluated = [], None, float("nan"), 0
    for b, m in group_masks:
        r = search(mask=m, current=current, transition_cost=transition_cost, top_k=k, **kwargs)
        first = first or r
        evaluated += r.evaluated
        if r.continuing_cost == r.continuing_cost:
            cont = r.continuing_cost
        per_group.append((r.frames, r.costs, r.bias))
    features_norm, query, slices = first._breakdown
    return merge_groups(per_group, [b for b, _ in group_masks], current, k, features_norm, query, slices, cont,
                         evaluated)
