"""Ground calibration (lmm/ground.py): the take's contact height looked up once per take."""
import numpy as np

from lmm.mm import MotionMatchingController


def test_ground_offset_target_follows_the_take_of_the_source_frame(db, features):
    """The take's contact height is looked up once per take: the target for every frame, in order and
    jumping around, equals the direct lookup."""
    c = MotionMatchingController(db, features)
    c.tuning.ik_ground_calibration = True
    frames = list(range(0, len(db.contacts), 7)) + list(np.random.default_rng(1).integers(0, len(db.contacts), 300))
    heights = c.ground._range_heights
    for f in frames:
        c.frame = int(f)
        h = float(heights[int(db.range_index(int(f)))])
        want = c.tuning.ik_foot_height_m - h if np.isfinite(h) else 0.0
        assert c.ground.target(c.tuning, c._calibration_frame()) == want
