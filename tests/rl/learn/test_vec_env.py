"""Training environments (learn.vec_env): the config's step limits reach every env and the
policy file; finished episodes reach SB3's VecMonitor."""

from __future__ import annotations

import numpy as np
import pytest

from helpers import tiny_config
from scanplan.rl.learn.config import TrainConfig, env_options


def test_step_limits_in_the_config_reach_the_envs_and_the_policy_file():
    import math

    from scanplan.core.quantities import StepLimits
    from scanplan.rl.learn.vec_env import make_vec_env, swath_env_kwargs

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

    from scanplan.rl.learn.vec_env import make_vec_env

    vec = make_vec_env(tiny_config("unused", env={"fan_points": 32, "segment_mm": (5.0, 6.0)}))
    assert isinstance(vec, VecMonitor)
    vec.reset()
    ended = []
    for _ in range(40):
        _, rewards, dones, infos = vec.step(np.tile([1.0, 0.0, 0.0], (2, 1)).astype(np.float32))
        ended += [i["episode"] for i, d in zip(infos, dones, strict=True) if d]
        assert all(("episode" in i) == d for i, d in zip(infos, dones, strict=True))
    assert ended and all(e["l"] >= 1 and e["r"] <= 0 for e in ended)


@pytest.mark.parametrize(
    ("roll", "perturb"),
    [
        (False, None),
        (True, None),
        (False, "place:5mm,2deg"),
        (False, "place:2mm,1deg;warp:1mm@200mm"),
    ],
)
def test_batched_vec_env_steps_as_its_envs_do_one_by_one(roll, perturb):
    """The batch computes poses, D, α, Δs and rewards as arrays over its envs: the numbers
    each env's own `step` gives, bit for bit (noise-free, as training runs), resets included;
    perturbed episodes too (their parts placed apart, measured in one call)."""
    from scanplan.rl.learn.vec_env import make_env, make_vec_env

    env = {"fan_points": 32, "noise": False, "segment_mm": (8.0, 15.0), "roll": roll}
    if perturb is not None:
        env["perturb"] = perturb
    vec = make_vec_env(TrainConfig(n_envs=3, seed=5, env=env))
    singles = [make_env(["training-piece"], env) for _ in range(3)]
    obs = vec.reset()
    assert np.array_equal(obs, np.stack([e.reset(seed=5 + i)[0] for i, e in enumerate(singles)]))
    rng = np.random.default_rng(0)
    dones_seen = 0
    for _ in range(60):
        actions = rng.uniform(-1.0, 1.0, (3, vec.action_space.shape[0])).astype(np.float32)
        actions[:, 0] = np.abs(actions[:, 0])  # advance, so that episodes end and reset
        obs, rewards, dones, infos = vec.step(actions)
        for i, single in enumerate(singles):
            o, r, term, trunc, info = single.step(actions[i])
            assert dones[i] == (term or trunc)
            if dones[i]:
                dones_seen += 1
                assert np.array_equal(infos[i]["terminal_observation"], o)
                o, _ = single.reset()
            assert np.array_equal(obs[i], o) and rewards[i] == np.float32(r)
            for key in ("d_mm", "alpha_rad", "delta_s_mm", "r_d", "r_alpha", "r_delta_s"):
                assert np.array_equal(infos[i][key], info[key], equal_nan=True), key
    assert dones_seen > 0
