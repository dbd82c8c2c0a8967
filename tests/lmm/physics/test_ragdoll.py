"""The stable-PD ragdoll (lmm.physics.ragdoll): it tracks a walking range of the database with the residual
force without falling, it falls without it when standing still (PD tracking alone does not balance), a
fall is counted and reset, and the studio session steps one per controller."""
from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("mujoco")

from lmm.physics.ragdoll import Ragdoll, RagdollSettings, body_for_database  # noqa: E402


@pytest.fixture(scope="module")
def body(db):
    return body_for_database(db)


def walking_range(db, seconds: float = 6.0):
    """Global rotations and positions of the first unmirrored range at least ``seconds`` long."""
    n = int(seconds * db.fps)
    for i, name in enumerate(db.range_names):
        start, stop = int(db.range_starts[i]), int(db.range_stops[i])
        if "mirrored" not in name and stop - start >= n:
            return db.global_transforms(slice(start, start + n))
    pytest.skip("no range long enough")


def test_tracks_a_walking_range_with_the_residual_force(db, body):
    rot, pos = walking_range(db)
    ragdoll = Ragdoll(body, dt=1.0 / db.fps, settings=RagdollSettings(residual=True))
    ticks = [ragdoll.step(pos[f], rot[f]) for f in range(len(pos))]
    err = np.array([t.tracking_error_cm for t in ticks])
    assert ragdoll.falls == 0 and not any(t.fallen for t in ticks)
    assert err.mean() < 8.0, err.mean()
    # the ragdoll's joints are where it says they are: its hips follow the take's
    assert np.linalg.norm(ticks[-1].positions[1] - pos[-1, 1]) < 0.1
    # it walks on its feet: each foot touches the floor for a part of the range, not all of it
    contacts = np.array([t.foot_contacts for t in ticks])
    assert np.all(contacts.mean(0) > 0.2) and np.all(contacts.mean(0) < 1.0)
    residual = np.array([t.residual_force_bw for t in ticks])
    assert np.all(np.isfinite(residual)) and residual.max() > 0


def test_a_pose_held_in_the_air_needs_the_whole_weight_as_residual(db, body):
    rot, pos = db.global_transforms(slice(0, 1))
    lifted = pos[0] + np.array([0.0, 0.5, 0.0])
    ragdoll = Ragdoll(body, dt=1.0 / db.fps)
    ticks = [ragdoll.step(lifted, rot[0]) for _ in range(60)]
    assert not ticks[-1].foot_contacts.any()
    assert ticks[-1].residual_force_bw == pytest.approx(1.0, abs=0.05)


def test_without_the_residual_it_falls_is_counted_and_reset(db, body):
    rot, pos = db.global_transforms(slice(0, 1))
    settings = RagdollSettings(residual=False, reset_after_fall_s=0.5)
    ragdoll = Ragdoll(body, dt=1.0 / db.fps, settings=settings)
    ticks = [ragdoll.step(pos[0], rot[0]) for _ in range(4 * 60)]
    assert all(t.residual_force_bw == 0.0 for t in ticks)
    first = next(i for i, t in enumerate(ticks) if t.fallen)
    assert ticks[first].falls == 1
    # half a second later it stands on the tracked pose again
    back = next(i for i, t in enumerate(ticks) if i > first and t.reset)
    assert (back - first) == pytest.approx(30, abs=2)
    assert ticks[back].tracking_error_cm < 6.0 and not ticks[back].fallen     # one tick after the reset
    assert abs(ticks[back].positions[1, 1] - ragdoll.target_qpos(pos[0], rot[0])[1]) < 0.01   # lifted out of the floor
    ragdoll.reset(pos[0], rot[0])
    assert ragdoll.step(pos[0], rot[0]).tracking_error_cm < 1.0
