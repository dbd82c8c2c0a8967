"""One pose's rows of floats packed into arrays (lmm/pose_rows.py)."""
import numpy as np

from lmm.pose_rows import pack_rows


def test_packed_rows_are_numpys_cast_bit_for_bit():
    """The pose arrays are packed by struct: the same bits as numpy's cast of the same floats, including
    values that round, overflow to infinity, underflow to zero or are NaN; new writable arrays each call,
    one per block, in the blocks' order and shapes."""
    rng = np.random.default_rng(3)
    rows = [tuple(v) for v in (rng.standard_normal((23, 4)) * 10.0 ** rng.integers(-45, 45, (23, 4))).tolist()]
    rows[3] = (float("nan"), float("inf"), -1e300, 5e-324)
    rows[4] = (3.4028235677973366e38, -3.4028235e38 * 1.0000001, 1e-46, -0.0)
    narrow = [tuple(v) for v in rng.standard_normal((23, 3)).tolist()]
    for dtype in (np.float32, np.float64, np.float16):    # float16: numpy's conversion
        with np.errstate(over="ignore"):
            want = np.array(rows).astype(dtype), np.array(narrow).astype(dtype)
            got = pack_rows(((rows, 4), (narrow, 3)), 23, dtype)
            again = pack_rows(((rows, 4), (narrow, 3)), 23, dtype)
        assert len(got) == 2
        for g, w in zip(got, want):
            assert g.dtype == w.dtype and g.shape == w.shape and g.tobytes() == w.tobytes(), dtype
            assert g.flags.writeable and g.flags.c_contiguous
        assert not np.may_share_memory(got[0], got[1]) and not np.may_share_memory(got[0], again[0])
