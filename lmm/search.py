"""Nearest-frame search over the normalised database features: brute force and an exact accelerated index.

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

The accelerated search (:class:`SearchIndex`) keeps axis-aligned bounding boxes of the features over
blocks of 32 consecutive frames and, under each, over its blocks of 8 frames (consecutive frames are
close in every dimension at once, which keeps temporal boxes tight; clustered or k-d orderings gave
looser boxes on this data). Per query it

1. bounds the cost of every large block from below: the squared distance from the query to its box,
   over the 16 dimensions in which large boxes are thinnest (a bound over fewer dimensions is still a
   lower bound, and cheaper);
2. gets an upper bound ``ub`` on the k-th best cost from real frames: the ``hint`` and its neighbours
   (at run time, the previous search's candidates advanced by the frames played since) or, without
   one, the best small blocks of the most promising large blocks;
3. keeps the large blocks with bound <= ub, bounds their small blocks over every dimension, keeps those
   with bound <= ub, and computes the exact cost of their frames (a few hundred of 54,608).

Every frame in the true top-K costs at most ub, so its blocks survive both cuts: the answer is exactly the
brute-force one, whatever the hint. Bounds are compared after shrinking by a relative 1e-5, far more
than float32 rounding of a 27-term sum, so rounding can never make a bound exceed a computed cost.
Everything is vectorised numpy; the boxes are stored dimension-major so numpy's inner loops run along
blocks. The index temporarily marks the exclusion window in its cached candidate mask, so one index
must not be searched from two threads at once.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

SMALL_BLOCK = 8   # frames per small box
LARGE_BLOCK = 32  # frames per large box (a multiple of SMALL_BLOCK)
_BOUND_SLACK = np.float32(1.0 - 1e-5)
_HINT_SPREAD = np.arange(-2, 3)  # a hinted frame and its neighbours seed the upper bound
# for a top-K search (K > 1), more neighbours: the K best come in runs of consecutive frames, so further ones
# give a lower k-th cost, and fewer hints fall short of k valid seeds when the playing frame's exclusion
# window covers some (measured: about 2% faster runtime calls than with the top-1 spread)
_HINT_SPREAD_TOPK = np.arange(-4, 5)
_PAD = 4                          # the candidate mask's extra False tail (hint neighbours may step outside)


def _hint_seeds(hint, valid: np.ndarray, extra=None, k: int = 1) -> np.ndarray:
    """The frames around the hinted ones (``_HINT_SPREAD``, ``_HINT_SPREAD_TOPK`` for ``k`` > 1) and the
    ``extra`` frames, sorted, unique and valid: real frames whose costs give an upper bound on the k-th best
    before the blocks are scanned."""
    spread = _HINT_SPREAD if k == 1 else _HINT_SPREAD_TOPK
    if hint is not None:
        # a hint outside the frames (e.g. candidates advanced past the end by a long search interval)
        # is clipped to them: only the speed depends on it
        hint = np.clip(np.asarray(hint, dtype=np.int64), 0, len(valid) - _PAD - 1)
        seeds = (hint[:, None] + spread).ravel()
    else:
        seeds = np.zeros(0, dtype=np.int64)
    if extra is not None:
        seeds = np.concatenate((seeds, extra))
    seeds.sort()
    ok = valid[seeds]
    ok[1:] &= seeds[1:] != seeds[:-1]
    return seeds[ok]


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


def candidate_mask(n_frames: int, range_starts, range_stops, exclude_end: int) -> np.ndarray:
    """(N,) bool: frames that may be jumped to (not in the last ``exclude_end`` frames of their range)."""
    mask = np.ones(n_frames, dtype=bool)
    if exclude_end > 0:
        for start, stop in zip(np.asarray(range_starts), np.asarray(range_stops)):
            mask[max(int(stop) - exclude_end, int(start)):int(stop)] = False
    return mask


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


def _rank(frames, costs, current, cont_cost, transition_cost, top_k):
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


def _result(features_norm, query, slices, frames, total, bias, current, cont_cost, evaluated):
    return SearchResult(frames=frames, costs=total, bias=bias, continuing_frame=int(current),
                        continuing_cost=float(cont_cost), evaluated=int(evaluated),
                        _breakdown=(features_norm, query, slices))


def _continuing_cost(features_norm, query, mask, current):
    """The playing frame's feature cost (float32 value), NaN when it may not compete."""
    if current >= 0 and mask[current]:
        d = features_norm[current:current + 1] - query
        return float(np.einsum("ij,ij->i", d, d)[0])
    return float("nan")


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
    cont = _continuing_cost(features_norm, query, mask, current)
    f, total, bias = _rank(frames, costs[frames], current, cont, transition_cost, k)
    return _result(features_norm, query, slices, f, total, bias, current, cont, costs.size)


def _padded_rows(X: np.ndarray, rows: int) -> np.ndarray:
    """``X`` (N, D) followed by copies of its last row up to ``rows`` rows. Without a copy of ``X`` when it
    is the start of a larger contiguous buffer whose next rows already are such copies (as
    :class:`lmm.features.Features` keeps its normalised features), else concatenated."""
    base = X.base
    n = len(X)
    if (isinstance(base, np.ndarray) and base.dtype == X.dtype and base.ndim == 2 and base.shape[1] == X.shape[1]
            and base.shape[0] >= rows and base.flags.c_contiguous and X.flags.c_contiguous
            and base.__array_interface__["data"][0] == X.__array_interface__["data"][0]
            and np.array_equal(base[n:rows], np.broadcast_to(X[-1], (rows - n, X.shape[1])))):
        return base[:rows]
    return np.concatenate([X, np.repeat(X[-1:], rows - n, axis=0)])


class SearchIndex:
    """Exact accelerated search over ``features_norm`` (N, D) with two levels of bounding boxes.

    Frames are padded to a whole number of large blocks (padding is never a candidate). Boxes are stored
    as lower and upper corners, dimension-major, so numpy's inner loops run along blocks: the large ones
    (D1, n_large) over the ``coarse_dims`` dimensions in which blocks are thinnest relative to the spread
    of the data (a box bound over a subset of dimensions is still a lower bound), the small ones over
    every dimension, grouped by large block, (D, n_large, per). The frames are kept grouped by small
    block, so the last level is one gather of contiguous rows.

    Call :meth:`update` when the normalised features change (e.g. a weight change: the boxes are
    recomputed from the new features, so the search stays exact); it is a no-op for the same array.
    """

    def __init__(self, features_norm: np.ndarray, small_block: int = SMALL_BLOCK, large_block: int = LARGE_BLOCK,
                 coarse_dims: int = 16, seed_blocks: int = 8):
        if large_block % small_block:
            raise ValueError("the large block size must be a multiple of the small block size")
        self.small_block, self.large_block = small_block, large_block
        self.coarse_dims, self.seed_blocks = coarse_dims, seed_blocks
        self.features_norm = None
        self._mask_key = None
        self.update(features_norm)

    def update(self, features_norm: np.ndarray) -> bool:
        """Recompute the bounds if ``features_norm`` is a different array. Returns True when rebuilt."""
        if features_norm is self.features_norm:
            return False
        self.features_norm = features_norm
        X = np.ascontiguousarray(features_norm, dtype=np.float32)
        n, d = X.shape
        self.X, self.n_frames, self.n_dims = X, n, d
        sb, lb = self.small_block, self.large_block
        per = lb // sb
        n_large = max(-(-n // lb), 1)
        pad = n_large * lb - n
        Xp = _padded_rows(X, n_large * lb) if pad else X
        small = Xp.reshape(n_large * per, sb, d)
        lo, hi = small.min(axis=1), small.max(axis=1)                        # (n_small, D)
        lo_l = lo.reshape(n_large, per, d).min(axis=1)
        hi_l = hi.reshape(n_large, per, d).max(axis=1)
        # coarse level: the dimensions where large boxes are thinnest relative to the data's spread
        spread = X.std(axis=0)
        thinness = np.where(spread > 0, (hi_l - lo_l).mean(axis=0) / np.maximum(spread, 1e-12), np.inf)
        dims = np.sort(np.argsort(thinness, kind="stable")[:max(1, min(self.coarse_dims, d))])
        self.l1_dims = dims
        self.l1_lo = np.ascontiguousarray(lo_l.T[dims])                      # (D1, n_large)
        self.l1_hi = np.ascontiguousarray(hi_l.T[dims])
        # small boxes grouped by large block, (n_large, per * D): a survivor's boxes are one contiguous row
        self.l2_lo = np.ascontiguousarray(lo.reshape(n_large, per * d))
        self.l2_hi = np.ascontiguousarray(hi.reshape(n_large, per * d))
        self.rows = np.ascontiguousarray(small)                              # (n_small, sb, D) row-major
        self.per_large, self.n_large = per, n_large
        self._offsets = np.arange(sb)
        self._per_offsets = np.arange(per)
        self._current = np.zeros(1, dtype=np.int64)   # the playing frame, appended to the seeds
        self._large_offsets = np.arange(lb)
        self._tile_index = np.tile(np.arange(d), max(per, sb))   # q[_tile_index]: q repeated
        self._q1 = np.empty_like(self.l1_lo)
        self._g1 = np.empty_like(self.l1_lo)
        self._ones1 = np.ones(len(dims), dtype=np.float32)
        self._ones = np.ones(d, dtype=np.float32)
        self._mask_key = None
        return True

    # the arrays :meth:`update` builds (the per-mask cache of :meth:`_valid` is not part of the structure)
    _STRUCTURE = ("X", "l1_dims", "l1_lo", "l1_hi", "l2_lo", "l2_hi", "rows", "_offsets", "_per_offsets",
                  "_large_offsets", "_current", "_tile_index", "_q1", "_g1", "_ones1", "_ones")

    def nbytes(self) -> int:
        """Bytes the index adds to the features it searches: its arrays, except those that are the
        features themselves or views of them (``X`` and ``rows`` are, when no copy was needed)."""
        return int(sum(a.nbytes for a in (getattr(self, n) for n in self._STRUCTURE)
                       if not np.shares_memory(a, self.features_norm)))

    def _valid(self, mask: np.ndarray) -> np.ndarray:
        """``mask`` padded with False to whole blocks plus ``_PAD`` (so a hint's neighbours -4..n+3 index it
        safely; negative indices wrap onto the padding), cached per mask array."""
        if self._mask_key is not mask:
            padded = np.zeros(self.n_large * self.large_block + _PAD, dtype=bool)
            padded[:self.n_frames] = mask
            self._mask_padded, self._mask_key = padded, mask
        return self._mask_padded

    def search(self, query: np.ndarray, mask: np.ndarray, current: int = -1, transition_cost: float = 0.0,
               exclude_window: int = 20, top_k: int = 1, slices=None, hint=None) -> SearchResult:
        """Same arguments and same answer as :func:`brute_force_search`.

        ``hint``: frames likely to be good (e.g. the previous search's candidates advanced by the frames
        played since). Only the speed depends on it: it and its neighbours give the first upper bound.
        """
        q = np.asarray(query, dtype=np.float32)
        k = max(int(top_k), 1)
        valid = self._valid(mask)
        if current >= 0:  # exclude the window around the playing frame for this search only
            lo_w, hi_w = max(current - exclude_window, 0), current + exclude_window + 1
            saved = valid[lo_w:hi_w].copy()
            valid[lo_w:hi_w] = False
        try:
            return self._search(q, valid, mask, current, transition_cost, k, slices, hint)
        finally:
            if current >= 0:
                valid[lo_w:hi_w] = saved

    def _search(self, q, valid, mask, current, transition_cost, k, slices, hint) -> SearchResult:
        # 1. coarse lower bound of every large block: squared distance from the query to its box
        q1, gap = self._q1, self._g1
        np.copyto(q1, q[self.l1_dims, None])
        np.maximum(q1, self.l1_lo, out=gap)
        np.minimum(gap, self.l1_hi, out=gap)       # the query clamped into the box...
        np.subtract(q1, gap, out=gap)              # ...and its offset from it
        gap *= gap
        lb_large = self._ones1 @ gap

        # 2. an upper bound on the k-th best cost, from real frames (the playing frame's own cost, which
        #    competes separately, comes with them: same rows, same reduction)
        ub = np.float32(np.inf)
        evaluated = 0
        cont = float("nan")
        if hint is not None and len(hint):
            seeds = _hint_seeds(hint, valid, k=k)
            if seeds.size >= k:
                if current >= 0:
                    c = self.X[np.concatenate((seeds, (current,)))]
                    c -= q
                    c = np.einsum("ij,ij->i", c, c)
                    cont = float(c[-1]) if mask[current] else cont
                    c = c[:-1]
                else:
                    c = self.X[seeds]
                    c -= q
                    c = np.einsum("ij,ij->i", c, c)
                ub = np.partition(c, k - 1)[k - 1]
                evaluated += seeds.size
        if not ub < np.inf:
            ub, n = self._seed_bound(lb_large, q, valid, k)
            evaluated += n
            cont = _continuing_cost(self.X, q, mask, current)
        cut = ub / _BOUND_SLACK  # keep a box when bound * (1 - 1e-5) <= ub

        # 3. surviving large blocks -> their small blocks' exact box bounds -> frames' exact costs
        q_tile = q[self._tile_index]                             # q repeated, for long inner loops
        large = (lb_large <= cut).nonzero()[0]
        small = (large[:, None] * self.per_large + self._per_offsets).ravel()           # ascending
        small = small[self._small_bounds(large, q_tile) <= cut]
        d = self.rows[small]                                    # (S, sb, D)
        width = self.small_block * self.n_dims       # a block's rows as one row (explicit: there may be none)
        d.reshape(len(small), width).__isub__(q_tile[:width])                           # same values
        costs = np.einsum("ijk,ijk->ij", d, d).ravel()          # the brute force's reduction, bit for bit
        frames = (small[:, None] * self.small_block + self._offsets).ravel()
        keep = valid[frames]
        evaluated += frames.size
        f, total, bias = _rank(frames[keep], costs[keep], current, cont, transition_cost, k)
        slices = slices if slices is not None else [slice(0, self.n_dims)]
        return _result(self.X, q, slices, f, total, bias, current, cont, evaluated)

    def _small_bounds(self, large: np.ndarray, q_tile: np.ndarray) -> np.ndarray:
        """Lower bounds (L * per,) of the small blocks of the given large blocks (before the slack);
        ``q_tile`` is the query repeated at least ``per`` times."""
        lo = self.l2_lo[large]                                  # (L, per * D)
        hi = self.l2_hi[large]
        q_tile = q_tile[:self.per_large * self.n_dims]          # matches a row's layout
        np.maximum(lo, q_tile, out=lo)
        np.minimum(lo, hi, out=lo)                              # the query clamped into each box...
        np.subtract(q_tile, lo, out=lo)                         # ...and its offset from it
        lo *= lo
        return lo.reshape(-1, self.n_dims) @ self._ones         # (L * per,)

    def _seed_bound(self, lb_large, q, valid, k):
        """Upper bound on the k-th best cost without a hint: the exact costs of the frames
        :meth:`_seed_frames` picks. Returns (bound, frames evaluated)."""
        frames = self._seed_frames(lb_large, q, valid, k)
        if frames.size < k:
            return np.float32(np.inf), 0
        return np.partition(frame_costs(self.X[frames], q), k - 1)[k - 1], int(frames.size)

    def _seed_frames(self, lb_large, q, valid, k):
        """Valid frames of a greedy descent: the best ``seed_blocks`` small blocks within the best
        ``seed_blocks`` large blocks (widened until k valid frames are found, or everything was looked at)."""
        m = s = self.seed_blocks
        while True:
            large = np.argpartition(lb_large, m - 1)[:m] if m < self.n_large else np.arange(self.n_large)
            lb_small = self._small_bounds(large, q[self._tile_index])
            pick = np.argpartition(lb_small, s - 1)[:s] if s < lb_small.size else np.arange(lb_small.size)
            small = large[pick // self.per_large] * self.per_large + pick % self.per_large
            frames = (small[:, None] * self.small_block + self._offsets).ravel()
            frames = frames[valid[frames]]
            if frames.size >= k or (m >= self.n_large and s >= lb_small.size):
                return frames
            m, s = min(m * 4, self.n_large), s * 4

    # -- tag-biased search: every bias group in one pass ---------------------------------------------
    def _groups(self, group_masks):
        """Per-frame bias (inf: not a candidate) and group number, and the least bias of each small and
        large block (inf for a block without candidates), cached for the same (bias, mask) groups."""
        cached = getattr(self, "_group_cache", None)
        # fast path, taken at run time (the controller passes the same list of tuples every search): the very
        # same (bias, mask) tuples, which cannot have been rebound since
        if cached is not None and len(cached[3]) == len(group_masks) and \
                all(a is g for a, g in zip(cached[3], group_masks)):
            return cached[2]
        key = tuple((float(b), id(m)) for b, m in group_masks)
        if cached is not None and cached[0] == key and all(a is m for a, (_, m) in zip(cached[1], group_masks)):
            return cached[2]
        size = self.n_large * self.large_block
        bias = np.full(size + _PAD, np.inf, dtype=np.float32)
        group = np.full(size + _PAD, -1, dtype=np.int64)
        for g, (b, m) in enumerate(group_masks):
            m = np.asarray(m, dtype=bool)
            bias[:self.n_frames][m] = np.float32(b)
            group[:self.n_frames][m] = g
        small_min = bias[:size].reshape(-1, self.small_block).min(axis=1)          # (n_small,)
        large_min = small_min.reshape(self.n_large, self.per_large).min(axis=1)    # (n_large,)
        biases = [float(b) for b, _ in group_masks]
        spread = max(abs(b) for b in biases) if biases else 0.0
        valid = np.isfinite(bias)                                                  # padded, like _valid
        # the searched copies (bias, valid) get the exclusion window marked in them; their pristine copies
        # restore it
        out = (bias, group, small_min, large_min, valid, valid.copy(), spread, bias.copy(),
               [np.float32(b) for b in biases])
        same = tuple(g for g in group_masks if type(g) is tuple)   # only tuples are safe to compare by identity
        self._group_cache = (key, [m for _, m in group_masks], out, same if len(same) == len(group_masks) else (None,))
        return out

    def group_search(self, query: np.ndarray, group_masks, current: int = -1, transition_cost: float = 0.0,
                     exclude_window: int = 20, top_k: int = 1, slices=None, hint=None, near: int = 0) -> SearchResult:
        """Exactly ``biased_search(lambda **kw: self.search(query, hint=hint, **kw), ..., group_masks=...)``
        (same frames, totals and biases), in one pass over the index instead of one search per group.

        ``group_masks``: disjoint (bias, mask) groups. A block's bound is its box bound plus the least bias
        of its candidate frames (blocks without candidates are skipped); the upper bound is the k-th best
        cost plus bias of real frames, widened by a relative 1e-5 so that float32 rounding of the totals
        can never drop a frame of the answer. The surviving frames are ranked per group as each group's own
        search ranks them, and the groups merged as :func:`biased_search` merges them (:func:`_rank_groups`:
        both at once, over the few candidates that can reach the top K).

        ``near`` > ``top_k``: the result's ``near_frames`` holds up to that many of the frames evaluated with
        the least totals, unordered, outside the exclusion windows of the playing frame and of the answer
        (which plays next: its neighbours advance with it and stay in its window): the controller's top-1
        search at a tick keeps them as the next search's hint, in place of a ranked top K.
        """
        q = np.asarray(query, dtype=np.float32)
        k = max(int(top_k), 1)
        frame_bias, frame_group, small_min, large_min, valid, candidates, spread, all_bias, b32 = \
            self._groups(group_masks)
        tc = np.float32(transition_cost)
        if current >= 0:  # exclude the window around the playing frame for this search only
            lo_w, hi_w = max(current - exclude_window, 0), current + exclude_window + 1
            valid[lo_w:hi_w] = False
            frame_bias[lo_w:hi_w] = np.inf
        try:
            frames, costs, keys, cont, in_group, evaluated, seeds = self._group_search(
                q, frame_bias, all_bias, small_min, large_min, valid, candidates, spread, current, tc, k, hint)
        finally:
            if current >= 0:
                valid[lo_w:hi_w] = candidates[lo_w:hi_w]
                frame_bias[lo_w:hi_w] = all_bias[lo_w:hi_w]
        slices = slices if slices is not None else [slice(0, self.n_dims)]
        if len(group_masks) == 1 and float(group_masks[0][0]) == 0.0:
            ok = keys < np.inf
            f, total, bias = _rank(frames[ok], costs[ok], current, cont, transition_cost, k)
        else:
            f, total, bias = _rank_groups(frames, costs, keys, frame_group, b32, current, cont, in_group, tc, k)
        result = _result(self.X, q, slices, f, total, bias, current, cont, evaluated)
        if near > k:
            # from the frames evaluated in blocks and the seeds (frames the hint kept, often far from the answer),
            # both ascending; ``keys`` is not read again, the seeds' totals (with the transition cost, as the
            # keys have it) are a new array
            seed_frames, seed_keys = seeds[0], seeds[1] + tc
            if f.size and f[0] != current:
                # the answer plays next: its exclusion window will cover its neighbours at the next search
                # (they advance with it), so they make no seeds there
                lo, hi = int(f[0]) - exclude_window, int(f[0]) + exclude_window
                for part, part_keys in ((frames, keys), (seed_frames, seed_keys)):
                    part_keys[part.searchsorted(lo):part.searchsorted(hi, "right")] = np.inf
            result.near_frames = _least(np.concatenate((frames, seed_frames)), np.concatenate((keys, seed_keys)),
                                        int(near))
        return result

    def _group_search(self, q, frame_bias, all_bias, small_min, large_min, valid, candidates, spread, current,
                      tc, k, hint):
        """The frames evaluated in blocks (ascending) with their feature costs and totals ``(cost + tc) + bias``
        (inf for frames that are not candidates), the playing frame's cost (NaN when it may not compete) and
        whether it is a candidate, how many frames were evaluated, and the seeds (the bound's frames:
        candidates, ascending) with their totals less the transition cost."""
        # 1. coarse lower bound of every large block (as in _search), plus its least candidate bias
        q1, gap = self._q1, self._g1
        np.copyto(q1, q[self.l1_dims, None])
        np.maximum(q1, self.l1_lo, out=gap)
        np.minimum(gap, self.l1_hi, out=gap)
        np.subtract(q1, gap, out=gap)
        gap *= gap
        lb_large = self._ones1 @ gap

        # 2. an upper bound on the k-th smallest merged total (counted without the transition cost, which every
        #    candidate but the playing frame carries), from real rows of the answer: the hinted frames and their
        #    neighbours, and the playing frame when it competes (its total less the transition cost): with it
        #    among the k, at most k - 1 other frames can come before it
        evaluated = 0
        cont = float("nan")
        seeds = _hint_seeds(hint, valid, k=k) if hint is not None and len(hint) else None
        if seeds is None or seeds.size < k:
            # the hint lies mostly in the exclusion window (a jump to a frame whose neighbours were the other
            # candidates): every frame of the most promising large block as well is usually enough, and
            # much cheaper than the descent
            best = int(np.argmin(lb_large + large_min))
            seeds = _hint_seeds(hint, valid, best * self.large_block + self._large_offsets, k)
            if seeds.size < k:
                seeds = np.sort(self._seed_frames(lb_large + large_min, q, valid, k))
        in_group = current >= 0 and candidates[current]
        if in_group:
            self._current[0] = current
            idx = np.concatenate((seeds, self._current))
        else:
            idx = seeds
        rows = self.X[idx]
        rows -= q
        c = np.einsum("ij,ij->i", rows, rows)       # the brute force's reduction: the same value per row
        if in_group:
            cont = float(c[-1])
        c += all_bias[idx]
        if in_group:
            c[-1] -= tc
        evaluated += seeds.size
        ub = np.partition(c, k - 1)[k - 1] if c.size >= k else np.float32(np.inf)
        # a frame whose box bound * (1 - 1e-5) + bias exceeds this cannot be in any group's answer
        cut = np.float32(float(ub) + 1e-5 * (abs(float(ub)) + abs(float(tc)) + spread)) \
            if ub < np.inf else np.float32(np.inf)

        # 3. surviving large blocks -> their small blocks' bounds -> frames' exact costs
        q_tile = q[self._tile_index]
        large = (lb_large * _BOUND_SLACK + large_min <= cut).nonzero()[0]
        small = (large[:, None] * self.per_large + self._per_offsets).ravel()
        small = small[self._small_bounds(large, q_tile) * _BOUND_SLACK + small_min[small] <= cut]
        d = self.rows[small]
        width = self.small_block * self.n_dims       # a block's rows as one row (explicit: there may be none)
        d.reshape(len(small), width).__isub__(q_tile[:width])
        costs = np.einsum("ijk,ijk->ij", d, d).ravel()
        frames = (small[:, None] * self.small_block + self._offsets).ravel()
        keys = costs + tc
        keys += frame_bias[frames]    # inf for frames that are not candidates (the window's included)
        return frames, costs, keys, cont, in_group, evaluated + frames.size, (seeds, c[:seeds.size])


def biased_search(search, mask: np.ndarray, frame_bias: np.ndarray | None, current: int = -1,
                  transition_cost: float = 0.0, top_k: int = 1, group_masks=None, **kwargs) -> SearchResult:
    """``search(mask=..., current=..., transition_cost=..., top_k=..., **kwargs)`` (either search above) with
    a per-frame cost ``frame_bias`` (N,) float32 added to every candidate, the continuing frame included.

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
    return _merge_groups(per_group, [b for b, _ in group_masks], current, k, features_norm, query, slices, cont,
                         evaluated)


def _rank_groups(frames, costs, keys, frame_group, b32, current, cont_cost, in_group, tc, top_k):
    """Exactly ``_merge_groups`` of every group's ``_rank`` (same frames, totals, biases and order), for the
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
    cont_row = None if cont_group < 0 else (float(np.float32(cont_cost) + b32[cont_group]), 0, int(current),
                                            float(np.float32(0.0) + b32[cont_group]))
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


def _least(frames: np.ndarray, keys: np.ndarray, n: int) -> np.ndarray:
    """Up to ``n`` of ``frames`` with the least finite ``keys``, unordered."""
    if keys.size > n:
        pick = keys.argpartition(n - 1)[:n]
        frames, keys = frames[pick], keys[pick]
    return frames[keys < np.inf]


def _rows_result(rows) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(frames, totals, biases) of ranked ``(total, order, frame, bias)`` rows."""
    return (np.array([r[2] for r in rows], dtype=np.int64), np.array([r[0] for r in rows], dtype=np.float32),
            np.array([r[3] for r in rows], dtype=np.float32))


def _merge_groups(per_group, biases, current, k, features_norm, query, slices, cont, evaluated) -> SearchResult:
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
    return _result(features_norm, query, slices, frames, total, bias, current, cont, evaluated)
