"""The compiled filter of the runtime search (``lmm/native/search.c``), built on first use and loaded with
ctypes; numpy stays the reference and the fallback.

:meth:`lmm.search_index.SearchIndex.group_search` asks it for every candidate frame whose total may be in the
top K (it walks boxes over 256, 32 and 8 frames in C, the first two its own (:func:`top_boxes`), with a
threshold that tightens as frames are costed, and keeps a relative 1e-4 margin, far more than its own float
rounding). Those few frames are then costed with numpy's row reduction and ranked as the brute force ranks
them: for a top-1 search (the one a tick makes) in C, by a sum that rounds as numpy's ``einsum`` does
(checked against numpy on the index's own rows when the filter is made, :func:`sums_as_numpy`; where it
differs, and for a larger top K or a tie, numpy costs and ranks them). The answer is the brute force's, bit
for bit, whether or not the compiled filter runs. It only changes how long a search takes (its tail above
all: the numpy index's worst searches on half a million frames take milliseconds).

The source is compiled with ``$CC`` (default ``cc``) ``-O3 -ffp-contract=off -shared -fPIC`` into the cache
folder (:func:`lmm.data.cache.default_cache_dir`, ``native/``), named from a hash of the source, the compiler
and the flags, so a changed source or compiler builds anew and later processes load the built library. GCC's
``target_clones`` in the source makes one build run at native speed on any x86-64. Without a compiler, or
when the build fails, one note goes to stderr (once per process) and numpy runs. ``LMM_STUDIO_NATIVE=0``
turns the compiled filter off.
"""
from __future__ import annotations

import ctypes
import hashlib
import os
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

SOURCE = Path(__file__).with_name("native") / "search.c"
ENV_SWITCH = "LMM_STUDIO_NATIVE"
MAX_K = 64          # the largest top K the C filter ranks (the source's MAX_K); above it numpy runs
TOP_BLOCK = 8       # large blocks per top box (the source's PER_TOP): 256 frames with 32-frame blocks
_OUT = 4096         # frames the filter may return before it gives up (many exact ties): numpy runs then
DIFF_ROWS = 256     # frames whose rows minus the query the tick filter writes (more: the caller gathers them)

_state: dict = {}   # "lib": the loaded library or None, "note": why not ("" when loaded or switched off)


def _compiler_id(cc: str) -> str:
    try:
        return subprocess.run([cc, "--version"], capture_output=True, text=True, timeout=30).stdout
    except (OSError, subprocess.SubprocessError):
        return ""


def _build() -> tuple[ctypes.CDLL | None, str]:
    """(library, "") or (None, why not)."""
    cc = os.environ.get("CC") or "cc"
    path = shutil.which(cc)
    if path is None:
        return None, f"no C compiler ({cc!r} not found)"
    source = SOURCE.read_bytes()
    key = hashlib.sha256(source + path.encode() + _compiler_id(path).encode() + " ".join(_FLAGS).encode()
                         ).hexdigest()[:20]
    from lmm.data.cache import default_cache_dir

    folder = default_cache_dir() / "native"
    lib = folder / f"search-{key}.so"
    if not lib.is_file():
        try:
            folder.mkdir(parents=True, exist_ok=True)
            fd, tmp = tempfile.mkstemp(suffix=".so", dir=folder)
            os.close(fd)
            run = subprocess.run([path, *_FLAGS, "-o", tmp, str(SOURCE), "-lm"],
                                 capture_output=True, text=True, timeout=120)
            if run.returncode != 0:
                os.unlink(tmp)
                last = (run.stderr.strip().splitlines() or ["no message"])[-1]
                return None, f"building {SOURCE.name} with {cc} failed: {last}"
            os.replace(tmp, lib)     # atomic: another process loads a whole library or builds its own
        except (OSError, subprocess.SubprocessError) as exc:
            return None, f"building {SOURCE.name} with {cc} failed: {exc}"
    try:
        dll = ctypes.CDLL(str(lib))
    except OSError as exc:
        return None, f"loading {lib.name} failed: {exc}"
    tick = dll.lmm_tick_filter
    tick.argtypes = [_P, ctypes.c_float, ctypes.c_float, _I64, ctypes.c_float, _I, _I64, _I64]
    tick.restype = _I
    costs = dll.lmm_numpy_costs
    costs.argtypes = [_P, _I64, _I, _P, _P]
    costs.restype = None
    return dll, ""


_P, _I, _I64 = ctypes.c_void_p, ctypes.c_int, ctypes.c_int64
# no fused multiply-adds: the source's numpy_row_cost must round each product and sum as numpy does
_FLAGS = ("-O3", "-ffp-contract=off", "-shared", "-fPIC")


class FilterArgs(ctypes.Structure):
    """The source's ``filter_args``: what stays the same from one search to the next."""
    _fields_ = [("rows", _P), ("t_lo", _P), ("t_hi", _P), ("n_top", _I64), ("per_top", _I),
                ("g_lo", _P), ("g_hi", _P), ("l2_lo", _P), ("l2_hi", _P), ("n_large", _I64),
                ("per", _I), ("sb", _I), ("dims", _I), ("bias", _P), ("small_min", _P), ("large_min", _P),
                ("q", _P), ("top_min", _P), ("tb", _P), ("out", _P), ("out_key", _P), ("max_out", _I),
                ("diff", _P), ("diff_rows", _I), ("exact", _I), ("res", _P)]


def library() -> ctypes.CDLL | None:
    """The compiled filter, built and loaded on the first call; None when switched off or unavailable (the
    first such call prints the one note)."""
    if "lib" not in _state:
        if os.environ.get(ENV_SWITCH, "1").strip() in ("0", "false", "off", "no"):
            _state["lib"], _state["note"] = None, ""
        else:
            _state["lib"], _state["note"] = _build()
            if _state["note"]:
                print(f"note: compiled search unavailable ({_state['note']}); using the numpy search",
                      file=sys.stderr)
    return _state["lib"]


def reset() -> None:
    """Forget the loaded library (tests: the next :func:`library` call reads the switch and builds again)."""
    _state.clear()


def note() -> str:
    """Why the compiled filter is not running ("" when it is, or when it was switched off)."""
    library()
    return _state["note"]


def _ptr(a: np.ndarray) -> int:
    return a.__array_interface__["data"][0]


class GroupFilter:
    """The compiled filter bound to one :class:`lmm.search_index.SearchIndex`'s arrays (rebuild it after
    :meth:`~lmm.search_index.SearchIndex.update`).

    ``exact``: whether the source's cost sum gives numpy's costs bit for bit on this index's rows (checked here,
    :func:`sums_as_numpy`); then a top-1 :meth:`tick` ranks its frames itself and writes the answer in ``res``.
    """

    def __init__(self, index, dll, top_block: int = TOP_BLOCK):
        self.index, self.tick_fn = index, dll.lmm_tick_filter
        t_lo, t_hi, g_lo, g_hi = top_boxes(index, top_block)
        self._own = (t_lo, t_hi, g_lo, g_hi)
        self._keep = (np.ascontiguousarray(index.rows, dtype=np.float32), t_lo, t_hi, g_lo, g_hi, index.l2_lo,
                      index.l2_hi)
        for a in self._keep[1:]:
            assert a.flags.c_contiguous
        rows, t_lo, t_hi, g_lo, g_hi, l2_lo, l2_hi = (_ptr(a) for a in self._keep)
        self._n_top = n_top = self._own[0].shape[1]
        self._tb = np.empty(n_top, dtype=np.float32)
        self._q = np.empty(index.n_dims, dtype=np.float32)
        self.out = np.empty(_OUT + 1, dtype=np.int64)      # what tick() wrote: out[:n], then the playing frame
        self._out_key = np.empty(_OUT, dtype=np.float32)
        self.diff = np.empty((DIFF_ROWS, index.n_dims), dtype=np.float32)   # see tick()
        # a ranked top-1 answer: ranked (1.0 or 0.0), frame (-1: none), total, bias, the playing frame's cost
        self.res = np.zeros(5, dtype=np.float64)
        self.exact = sums_as_numpy(dll, index.X)
        # the bias pointers (and each top block's least bias) are set by tick() for the arrays it is given
        self._args = FilterArgs(rows, t_lo, t_hi, n_top, top_block, g_lo, g_hi, l2_lo, l2_hi, index.n_large,
                                index.per_large, index.small_block, index.n_dims, 0, 0, 0, _ptr(self._q), 0,
                                _ptr(self._tb), _ptr(self.out), _ptr(self._out_key), _OUT, _ptr(self.diff), DIFF_ROWS,
                                int(self.exact), _ptr(self.res))
        self._args_ptr = ctypes.addressof(self._args)
        self._tick_biases = None                           # the bias arrays the struct points at

    def tick(self, q: np.ndarray, frame_bias: np.ndarray, small_min: np.ndarray, large_min: np.ndarray,
             tc: float, spread: float, cont_frame: int, cont_bias: float, k: int, wlo: int = 0, whi: int = 0) -> int:
        """The filter as a tick's search calls it: ``n``, the number of frames (ascending, in ``out[:n]``)
        whose totals may be in the top ``k``, the frames ``wlo`` <= f < ``whi`` (the playing frame's exclusion
        window) left out, and ``out[n]`` the playing frame ``cont_frame`` when it competes (>= 0;
        ``cont_bias`` its group's bias: the filter costs it itself for a first bound); -1 when the filter cannot
        say (numpy runs). A top-1 search with :attr:`exact` ranks them as well: ``res[0]`` is then 1.0 and
        ``res[1:5]`` the answer's frame (-1: no answer), total and bias and the playing frame's cost (NaN when
        it does not compete). When not ranked and those frames (the playing frame included) are at most
        :data:`DIFF_ROWS`, ``diff[i]`` holds ``out[i]``'s features minus the query, float32 as numpy subtracts
        them. ``out``, ``diff`` and ``res`` are overwritten by the next call."""
        if k > MAX_K:
            return -1
        seen = self._tick_biases
        if seen is None or seen[0] is not frame_bias or seen[1] is not small_min or seen[2] is not large_min:
            # the index passes the same cached arrays every search: the struct is written when they change
            # and each top block's least bias, worked out once for them (the filter's first pass reads it)
            top = np.full(self._n_top * TOP_BLOCK, np.inf, dtype=np.float32)
            top[:len(large_min)] = large_min
            self._top_min = np.ascontiguousarray(top.reshape(self._n_top, TOP_BLOCK).min(axis=1))
            self._tick_biases = (frame_bias, small_min, large_min)
            self._args.bias, self._args.small_min, self._args.large_min, self._args.top_min = \
                (_ptr(a) for a in (*self._tick_biases, self._top_min))
        np.copyto(self._q, q)
        return self.tick_fn(self._args_ptr, tc, spread, cont_frame, cont_bias, k, wlo, whi)

    def nbytes(self) -> int:
        """Bytes of its own arrays (the top boxes and buffers; the index's arrays it reads are the index's)."""
        return int(sum(a.nbytes for a in (*self._own, self._tb, self.out, self._out_key, self.diff)))


def top_boxes(index, top_block: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The filter's upper levels over ``index``, every dimension: the boxes of its top blocks (``top_block``
    consecutive large blocks), dimension-major (D, n_top), and the large blocks' boxes grouped by top block,
    (n_top, D, top_block), so that a top block's are one contiguous piece (a missing block's box is empty:
    lo inf, hi -inf)."""
    d, per = index.n_dims, index.per_large
    n_top = -(-index.n_large // top_block)
    lo = np.full((n_top * top_block, d), np.inf, dtype=np.float32)
    hi = np.full((n_top * top_block, d), -np.inf, dtype=np.float32)
    lo[:index.n_large] = index.l2_lo.reshape(index.n_large, per, d).min(axis=1)
    hi[:index.n_large] = index.l2_hi.reshape(index.n_large, per, d).max(axis=1)
    lo, hi = lo.reshape(n_top, top_block, d), hi.reshape(n_top, top_block, d)
    return (np.ascontiguousarray(lo.min(axis=1).T), np.ascontiguousarray(hi.max(axis=1).T),
            np.ascontiguousarray(lo.transpose(0, 2, 1)), np.ascontiguousarray(hi.transpose(0, 2, 1)))


def group_filter(index) -> GroupFilter | None:
    """The compiled filter for ``index``, or None when the compiled path is off or missing."""
    dll = library()
    return None if dll is None else GroupFilter(index, dll)


def sums_as_numpy(dll, X: np.ndarray, rows: int = 4096, queries: int = 3) -> bool:
    """Whether the source's ``numpy_row_cost`` gives numpy's row reduction (``einsum("ij,ij->i")`` of the
    rows minus the query, the brute force's) bit for bit: on up to ``rows`` of ``X`` (N, D) spread over it,
    against ``queries`` queries made from its rows. A numpy that sums in another order differs on almost every
    row, so a sample tells."""
    X = np.ascontiguousarray(X, dtype=np.float32)
    if not len(X):
        return False
    sample = np.ascontiguousarray(X[np.unique(np.linspace(0, len(X) - 1, min(rows, len(X))).astype(np.int64))])
    rng = np.random.default_rng(0)
    out = np.empty(len(sample), dtype=np.float32)
    for i in range(queries):
        q = (X[rng.integers(len(X))] + rng.normal(0.0, 0.5, X.shape[1])).astype(np.float32)
        d = sample - q
        dll.lmm_numpy_costs(_ptr(sample), len(sample), X.shape[1], _ptr(q), _ptr(out))
        if not np.array_equal(out, np.einsum("ij,ij->i", d, d)):
            return False
    return True
