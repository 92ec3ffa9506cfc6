"""Training environments (learn.vec_env): the config's step limits reach every env and the
policy file; finished episodes reach SB3's VecMonitor."""

from __future__ import annotations

import numpy as np

from helpers import tiny_config
from scanplan.learn.config import TrainConfig, env_options


def test_step_limits_in_the_config_reach_the_envs_and_the_policy_file():
    import math

    from scanplan.learn.vec_env import make_vec_env, swath_env_kwargs
    from scanplan.quantities import StepLimits

    limits = {"dy_max_mm": 0.5, "dz_max_mm": 0.8, "dtheta_max_rad": math.radians(0.5)}
    env = {"fan_points": 32, "noise": False, "segment_mm": [20.0, 40.0], **limits}
    want = StepLimits(**limits)
    vec = make_vec_env(TrainConfig(n_envs=2, env=env))
    assert [e.limits for e in vec.unwrapped.envs] == [want, want]  # type: ignore[attr-defined]
    obs = vec.reset()
    assert obs.shape == (2, 7) and vec.action_space.shape == (3,)
    # What policy.json records gives the same env back (the rl planner's side).
    recorded = env_options(env).env_kwargs()
    assert swath_env_kwargs(recorded)["limits"] == want
    assert "limits" not in swath_env_kwargs({"fan_points": 32})  # the env's defaults


def test_batched_vec_env_reports_episodes_through_sb3_vec_monitor():
    from stable_baselines3.common.vec_env import VecMonitor

    from scanplan.learn.vec_env import make_vec_env

    vec = make_vec_env(tiny_config("unused", env={"fan_points": 32, "segment_mm": (5.0, 6.0)}))
    assert isinstance(vec, VecMonitor)
    vec.reset()
    ended = []
    for _ in range(40):
        _, rewards, dones, infos = vec.step(np.tile([1.0, 0.0, 0.0], (2, 1)).astype(np.float32))
        ended += [i["episode"] for i, d in zip(infos, dones, strict=True) if d]
        assert all(("episode" in i) == d for i, d in zip(infos, dones, strict=True))
    assert ended and all(e["l"] >= 1 and e["r"] <= 0 for e in ended)
