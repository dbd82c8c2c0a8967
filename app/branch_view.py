"""Branch here: the rest of a reopened session re-simulated with another tuning (arm B of ``ab``), beside A.

From the shown tick of a reopened session, :meth:`BranchView.branch_here` makes a second
:class:`lmm.session.seek.SessionSeeker` with the branch (the Tuning panel's tuning, or the what-if scratch
tuning of :mod:`app.why_not_probe`) set at that tick: its own controllers and checkpoints, started from A's
checkpoint before that tick (:meth:`lmm.session.seek.SessionSeeker.branched`), so any tick of B is reached
as fast as A's. For the shown tick, :meth:`BranchView.difference` gives the difference row (pose
difference between A and B, each arm's played-pose cost and transition) the Stats panel shows
(:func:`app.panels.stats.branch_text`), and draws
B's inspected character as a ghost beside A (the 3D view's preview ghosts, owner ``branch``).
"""
from __future__ import annotations

import numpy as np

from lmm import quat

from .panels.base import PreviewPose

BRANCH_COLOR = (0.95, 0.70, 0.30)


class BranchView:
    def __init__(self, studio, probe):
        self.studio, self.probe = studio, probe
        self.seeker = None            # arm B (None: no branch)
        self.from_tick = -1           # the history tick B starts after (its first own pose is from_tick)
        self.tuning: dict = {}
        self._row_for, self._row = None, None     # the difference row of (tick, controller, arm B) last shown

    def branch_here(self, scratch: bool = False) -> dict:
        """Branch at the shown tick with the scratch tuning (``scratch``) or the Tuning panel's."""
        s = self.studio
        seeker, step, name, _ = self.probe.shown_any()
        if scratch:
            with seeker.before(step):
                tuning = self.probe.scratch(seeker.tuning).to_dict()
        else:
            tuning = s.session.tuning.to_dict()
        self.clear()
        self.seeker = seeker.branched(tuning, step)     # from A's checkpoint before the tick, not the start
        self.from_tick, self.tuning = step + 1, tuning
        return {"from_tick": self.from_tick, "tuning": tuning}

    def clear(self) -> None:
        self.seeker, self._row_for = None, None
        viewport = getattr(self.studio, "viewport", None)
        if viewport is not None:
            viewport.set_preview("branch", ())

    def difference(self) -> dict | None:
        """The difference row at the shown tick (None without a branch or a shown tick), B's ghost drawn."""
        if self.seeker is None:
            return None
        s = self.studio
        same = s.playback.reviewing and getattr(s, "reviewed", None) is self.seeker.session
        shown = s.playback.displayed_tick() if same else None
        if shown is None:                                  # live again, or another session opened
            self.clear()
            return None
        name = s.inspected
        if self._row_for == (int(shown.tick), name, id(self.seeker)):
            return self._row
        poses_b, snaps_b = self.seeker.seek(int(shown.tick) - 1)
        snap_a, snap_b = shown.snapshots[name], snaps_b[name]
        a = np.asarray(snap_a.pose.global_positions, np.float64)
        b = np.asarray(poses_b[name].global_positions, np.float64)
        d = np.linalg.norm(a - b, axis=-1)
        row = {"tick": int(shown.tick), "from_tick": self.from_tick, "controller": name,
               "mean_difference_m": float(d.mean()), "max_difference_m": float(d.max()),
               "cost": [float(snap_a.current_cost), float(snap_b.current_cost)],
               "transitioned": [bool(snap_a.transitioned), bool(snap_b.transitioned)],
               "frames": [int(snap_a.matched_frame), int(snap_b.matched_frame)]}
        s.viewport.set_preview("branch", (_ghost(s.session.db, poses_b[name], f"B (from tick {self.from_tick})"),))
        self._row_for, self._row = (int(shown.tick), name, id(self.seeker)), row
        return row


def _ghost(db, pose, label: str) -> PreviewPose:
    """B's pose in the frame of its root (what a preview ghost is drawn from)."""
    pos, rot = np.asarray(pose.global_positions, np.float64), np.asarray(pose.global_rotations, np.float64)
    local = quat.inv_mul_vec(rot[0][None], pos - pos[0][None])
    return PreviewPose(label=label, positions=local, parents=np.asarray(db.parents), names=tuple(db.names),
                       color=BRANCH_COLOR)

