"""The studio's pose guard (issue 36): a controller's unusable pose (NaN, infinite, a joint 1000 km away: an
LMM with weights it cannot handle) is reported once with its tick, and never drawn or recorded: the last
usable pose stands in (the database's first frame before there is one)."""
import numpy as np

from app.session import Session, first_frame_pose
from app.tick_worker import TickWorker
from lmm.controller import InputState
from lmm.factory import make_controllers
from lmm.metrics import pose_problem
from lmm.tuning import Tuning


class Breaks:
    """A controller whose poses at the chosen ticks (1-based) are NaN, or 1e9 m away."""

    def __init__(self, inner, bad: dict):
        self.inner, self.bad, self.ticks = inner, bad, 0

    def __getattr__(self, name):
        return getattr(self.inner, name)

    def reset(self):
        self.ticks = 0
        self.inner.reset()

    def step(self, inp, dt):
        pose, snap = self.inner.step(inp, dt)
        self.ticks += 1
        value = self.bad.get(self.ticks)
        if value is not None:
            pose.global_positions = np.full_like(pose.global_positions, value)
        return pose, snap


def test_an_unusable_pose_is_reported_once_and_never_drawn_or_recorded(dbf, tmp_path):
    from lmm.data import bvh

    db, features = dbf
    tuning = Tuning()
    controllers, _ = make_controllers(db, features, tuning, with_lmm=False)
    controllers["mm"] = Breaks(controllers["mm"], {1: np.nan, 4: np.inf, 5: 1e9, 6: np.nan})
    session = Session(db, features, tuning, controllers)
    reports = []
    session.report = lambda title, line: reports.append((title, line))
    paths = session.start_recording(tmp_path / "take.bvh", ("mm",))
    worker = TickWorker(session)
    try:
        worker.submit([InputState(left_y=1.0)] * 8)
        ticks = [t for t, _ in worker.wait()]
    finally:
        worker.close()
    poses = [t.snapshots["mm"].pose for t in ticks]
    assert all(pose_problem(p) is None for p in poses)
    assert np.array_equal(poses[0].global_positions, first_frame_pose(db).global_positions)   # none usable yet
    assert all(p is poses[2] for p in poses[3:6]) and poses[6] is not poses[2]   # the last usable one stays
    assert reports == [("Pose guard", session.pose_error)]   # once, on the GUI thread (wait), with the tick
    assert session.pose_error.startswith("tick 1: the mm pose is not finite")
    result = session.stop_recording()
    assert result.frames == 8
    motion = bvh.load(paths["mm"]).motion   # our reader refuses NaN and runaway values
    assert motion.shape[0] == 8 and np.isfinite(motion).all() and np.abs(motion).max() < 1e5
    assert np.array_equal(motion[3], motion[2]) and np.array_equal(motion[5], motion[2])   # held, not skipped
    session.reset()   # a new start: reported again
    assert session.pose_error == ""
    for _ in range(6):
        session.step(InputState())
    assert session.pose_error.startswith("tick 1: ") and len(session._unreported) == 1


def test_the_studio_reports_an_lmm_that_runs_away_once_and_draws_only_usable_poses(run_studio, tmp_path):
    """The corpus's decompressor at 1e4 (within every load limit): a joint 7e8 m away from tick 1; the
    studio loaded it without a word and drew the LMM root at [null, null, null]."""
    from lmm.learned import DEFAULT_WEIGHTS

    with np.load(DEFAULT_WEIGHTS, allow_pickle=False) as z:
        arrays = {k: np.full_like(z[k], 1e4) if k.startswith("decompressor.W") else z[k] for k in z.files}
    np.savez(tmp_path / "runaway.npz", **arrays)
    r = run_studio("--weights", tmp_path / "runaway.npz", "--input", "builtin:circle", "--frames", "40",
                   "--no-physics")
    assert r.rc == 0, r
    guard = [e for e in r.dump["errors"] if e["title"] == "Pose guard"]
    assert len(guard) == 1 and guard[0]["message"].startswith("tick 1: the lmm pose is a joint "), r.dump["errors"]
    roots = [t["roots"]["lmm"] for t in r.dump["ticks"]]
    assert len(roots) == 40 and np.isfinite(roots).all() and np.abs(roots).max() < 100
