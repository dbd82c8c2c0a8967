"""The exact accelerated nearest-frame search (:class:`SearchIndex`; the costs, candidates and
ranking it reproduces are described in :mod:`lmm.search`) keeps axis-aligned bounding boxes of the features over
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

import numpy as np

from lmm import search_native
from lmm.search_ranking import (SearchResult, continuing_cost, frame_costs, least_frames, make_result, rank, rank_groups,
                                rank_top1, top1_arrays)

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
        self._native = None       # the compiled filter over these arrays (False: none), made on first use
        return True

    # the arrays :meth:`update` builds (the per-mask cache of :meth:`_valid` is not part of the structure)
    _STRUCTURE = ("X", "l1_dims", "l1_lo", "l1_hi", "l2_lo", "l2_hi", "rows", "_offsets", "_per_offsets",
                  "_large_offsets", "_current", "_tile_index", "_q1", "_g1", "_ones1", "_ones")

    def nbytes(self) -> int:
        """Bytes the index adds to the features it searches: its arrays, except those that are the
        features themselves or views of them (``X`` and ``rows`` are, when no copy was needed), and the
        compiled filter's own arrays once a search has made it."""
        own = sum(a.nbytes for a in (getattr(self, n) for n in self._STRUCTURE)
                  if not np.shares_memory(a, self.features_norm))
        return int(own + (self._native.nbytes() if self._native else 0))   # the compiled filter's top boxes

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
        """Same arguments and same answer as :func:`lmm.search.brute_force_search`.

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
            cont = continuing_cost(self.X, q, mask, current)
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
        f, total, bias = rank(frames[keep], costs[keep], current, cont, transition_cost, k)
        slices = slices if slices is not None else [slice(0, self.n_dims)]
        return make_result(self.X, q, slices, f, total, bias, current, cont, evaluated)

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
        search ranks them, and the groups merged as :func:`lmm.search.biased_search` merges them
        (:func:`lmm.search_ranking.rank_groups`: both at once, over the few candidates that can reach the top K).

        ``near`` > ``top_k``: the result's ``near_frames`` holds up to that many of the frames evaluated with
        the least totals, unordered, outside the exclusion windows of the playing frame and of the answer
        (which plays next: its neighbours advance with it and stay in its window): the controller's top-1
        search at a tick keeps them as the next search's hint, in place of a ranked top K. The numpy
        index's only: with the compiled filter, which needs no hint, ``near_frames`` is None.
        """
        q = np.asarray(query, dtype=np.float32)
        k = max(int(top_k), 1)
        frame_bias, frame_group, small_min, large_min, valid, candidates, spread, all_bias, b32 = \
            self._groups(group_masks)
        tc = np.float32(transition_cost)
        slices = slices if slices is not None else [slice(0, self.n_dims)]
        # the window around the playing frame is excluded for this search only
        lo_w, hi_w = (max(current - exclude_window, 0), current + exclude_window + 1) if current >= 0 else (0, 0)
        found = self._native_group_search(q, frame_bias, small_min, large_min, candidates, spread, current, tc, k,
                                          all_bias, lo_w, hi_w)
        if found is None:
            if current >= 0:       # numpy reads the window from the bias and candidate arrays
                frame_bias[lo_w:hi_w] = np.inf
                valid[lo_w:hi_w] = False
            try:
                found = self._group_search(q, frame_bias, all_bias, small_min, large_min, valid, candidates, spread,
                                           current, tc, k, hint)
            finally:
                if current >= 0:
                    frame_bias[lo_w:hi_w] = all_bias[lo_w:hi_w]
                    valid[lo_w:hi_w] = candidates[lo_w:hi_w]
        elif len(found) == 3:      # the compiled filter ranked the top 1 itself
            cont, evaluated, (f, total, bias) = found
            return make_result(self.X, q, slices, f, total, bias, current, cont, evaluated)
        frames, costs, keys, cont, in_group, evaluated, seeds = found
        ranked = None
        if keys is None:      # the compiled filter's few frames: their keys only when the full ranking needs them
            if k == 1:
                ranked = rank_top1(frames, costs, frame_bias, frame_group, b32, current, cont, in_group, tc)
            if ranked is None:
                keys = costs + tc
                keys += frame_bias[frames]
        if ranked is not None:
            f, total, bias = ranked
        elif len(group_masks) == 1 and float(group_masks[0][0]) == 0.0:
            ok = keys < np.inf
            f, total, bias = rank(frames[ok], costs[ok], current, cont, transition_cost, k)
        else:
            f, total, bias = rank_groups(frames, costs, keys, frame_group, b32, current, cont, in_group, tc, k)
        result = make_result(self.X, q, slices, f, total, bias, current, cont, evaluated)
        if near > k and seeds is not None:   # the numpy index's (the compiled filter needs no hint)
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
            result.near_frames = least_frames(np.concatenate((frames, seed_frames)), np.concatenate((keys, seed_keys)),
                                        int(near))
        return result

    def nearest_frames(self, queries: np.ndarray) -> tuple[np.ndarray, np.ndarray] | None:
        """The nearest frame of each row of ``queries`` (Q, D) over every frame and its squared distance,
        through the compiled filter (the same answers as :meth:`search` with every frame allowed, ties to the
        lower frame); None when the filter is missing (callers then search their own way). The projector's
        training asks this for its 512 targets an iteration: a plain search costs several times the filter's
        own work in arguments and ranking, which this skips."""
        if self._native is None:
            self._native = search_native.group_filter(self) or False
        if not self._native:
            return None
        all_frames = getattr(self, "_all_frames", None)
        if all_frames is None:
            self._all_frames = all_frames = [(0.0, np.ones(self.n_frames, dtype=bool))]
        frame_bias, _, small_min, large_min, *_ = self._groups(all_frames)
        native = self._native
        Q = np.ascontiguousarray(queries, dtype=np.float32)
        frames, costs = np.empty(len(Q), dtype=np.int64), np.empty(len(Q), dtype=np.float32)
        tc = np.float32(0.0)
        for i, q in enumerate(Q):
            n = native.tick(q, frame_bias, small_min, large_min, tc, 0.0, -1, 0.0, 1)
            if n <= 0:
                return None
            ranked, f, cost = native.res[:3].tolist()
            if ranked:         # one least cost (its total: cost + 0 + 0), costed as numpy costs it
                frames[i], costs[i] = int(f), cost
                continue
            rows = self._candidate_rows(native, n, q)
            c = np.einsum("ij,ij->i", rows, rows)   # the brute force's reduction
            j = int(c.argmin())                      # the first least (ascending frames): the lower frame on a tie
            frames[i], costs[i] = native.out[j], c[j]
        return frames, costs

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

    def _native_group_search(self, q, frame_bias, small_min, large_min, candidates, spread, current, tc, k,
                             all_bias, lo_w, hi_w):
        """:meth:`_group_search`'s result from the compiled filter (:mod:`lmm.search_native`), keys and seeds
        None (the caller works out the keys only if its ranking needs them; the filter needs no hint): the
        frames that may reach the answer (ascending), and the playing frame when it competes, costed here in
        one row gather by the brute force's row reduction; or, when the filter ranked a top-1 search itself,
        ``(the playing frame's cost, frames evaluated, (frames, totals, biases))``; None when the filter is off
        or cannot say (then numpy searches). The frames ``lo_w`` <= f < ``hi_w`` are not candidates."""
        native = self._native
        if native is None:
            native = self._native = search_native.group_filter(self) or False
        if not native:
            return None
        in_group = current >= 0 and bool(candidates[current])
        n = native.tick(q, frame_bias, small_min, large_min, tc, spread, current if in_group else -1,
                        all_bias[current] if in_group else 0.0, k, lo_w, hi_w)
        if n < 0:
            return None
        ranked, f, total, bias, cont = native.res.tolist()
        if ranked:
            return cont, n, top1_arrays(int(f), total, bias)
        if n == 0 and not in_group:    # nothing can be the answer
            return np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.float32), None, float("nan"), False, 0, None
        rows = self._candidate_rows(native, n + in_group, q)
        costs = np.einsum("ij,ij->i", rows, rows)   # the brute force's reduction: the same value per row
        if in_group:
            cont, costs = float(costs[n]), costs[:n]
        else:
            cont = float("nan")
        # a view of the filter's buffer: read by this search's ranking only (the next search overwrites it)
        return native.out[:n], costs, None, cont, in_group, n, None

    def _candidate_rows(self, native, m: int, q: np.ndarray) -> np.ndarray:
        """The first ``m`` frames the compiled filter returned, their features minus the query: the rows the
        filter wrote, or gathered here when there were more than its buffer holds."""
        if m <= search_native.DIFF_ROWS:
            return native.diff[:m]
        rows = self.X[native.out[:m]]
        rows -= q
        return rows
