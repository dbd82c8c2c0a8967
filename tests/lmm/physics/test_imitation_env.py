"""The imitation environment (lmm.physics.env): sizes, reset from a database frame, steps, reward terms."""
import numpy as np
import pytest


def test_env_smoke():
    pytest.importorskip("mujoco")
    from lmm.data.build import load_or_build
    from lmm.physics.env import REWARD_TERMS, ImitationEnv

    db, _ = load_or_build(None)
    env = ImitationEnv(db)
    start = int(db.range_starts[1]) + 10
    obs = env.reset(start)
    assert obs.shape == (env.observation_size,) and np.all(np.isfinite(obs))
    # the reset pose is the database frame: the hips where the database puts them (lifted out of the floor)
    rot, pos = db.global_transforms(slice(start, start + 1))
    np.testing.assert_allclose(env.data.qpos[[0, 2]], pos[0, env.body.root, [0, 2]], atol=1e-5)
    assert 0.0 <= env.data.qpos[1] - pos[0, env.body.root, 1] < 0.1
    rewards = []
    for _ in range(10):
        res = env.step(np.zeros(env.action_size))
        assert res.observation.shape == (env.observation_size,)
        assert set(res.reward_terms) == set(REWARD_TERMS)
        assert res.reward_terms["adversarial"] is None and res.reward_terms["conditional"] is None
        rewards.append(res.reward_terms["pose"])
    assert all(0.0 <= r <= 1.0 for r in rewards)
    assert np.mean(rewards) > 0.05          # PD towards the reference keeps the pose near it for 10 ticks
    with pytest.raises(ValueError):
        env.step(np.zeros(env.action_size + 1))
