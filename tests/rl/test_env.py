"""SwathScanEnv v0 (the paper) and v1 (roll): checkers, determinism, the paper's action
limitation and reward, episode ends."""

from __future__ import annotations

import math
import warnings

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env as gym_check_env
from stable_baselines3.common.env_checker import check_env as sb3_check_env

from helpers import plate_swath
from scanplan.core.quantities import advance, mean_distance, signed_alpha
from scanplan.core.reward import reward_terms
from scanplan.core.sensor_spec import SensorSpec
from scanplan.planning.step_model import limit_action
from scanplan.planning.swaths import Swath
from scanplan.rl.env import ENV_ID, ENV_ID_ROLL, SwathScanEnv
from scanplan.sensor.profilometer import LineProfilometer
from scanplan.world.part import Part, load_part

WD = 400.0


def plate_env(plate: Part, **kwargs) -> SwathScanEnv:
    defaults = {"noise": False, "segment_mm": None}
    return SwathScanEnv(parts=[plate], swaths=[plate_swath()], **(defaults | kwargs))


@pytest.mark.parametrize(
    "kwargs", [{}, {"use_position": False}, {"lookahead": True, "use_position": False}]
)
def test_both_env_checkers_are_clean(kwargs):
    env = gym.make(ENV_ID, disable_env_checker=True, **kwargs).unwrapped
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        gym_check_env(env)
        sb3_check_env(env, warn=True)
    assert env.observation_space.shape == (
        7 - 3 * (not kwargs.get("use_position", True)) + 10 * kwargs.get("lookahead", False),
    )


def rollout(seed: int, steps: int = 60) -> tuple[np.ndarray, np.ndarray]:
    env = SwathScanEnv()  # noisy sensor: the noise must come from env.np_random too
    obs, _ = env.reset(seed=seed)
    rng = np.random.default_rng(1)
    all_obs, rewards = [obs], []
    for _ in range(steps):
        obs, r, term, trunc, _ = env.step(rng.uniform(-1, 1, 3))
        all_obs.append(obs)
        rewards.append(r)
        if term or trunc:
            break
    return np.array(all_obs), np.array(rewards)


def test_seeded_rollouts_are_identical():
    a, b, c = rollout(3), rollout(3), rollout(4)
    np.testing.assert_array_equal(a[0], b[0])
    np.testing.assert_array_equal(a[1], b[1])
    assert not np.array_equal(a[0], c[0])


@pytest.mark.parametrize(
    ("d", "alpha", "action", "expected"),
    [
        (410.0, 0.1, (0.5, -0.7, -0.4), (0.5, 0.0, 0.0)),  # far: only towards; α>0: only +
        (410.0, 0.1, (0.5, 0.7, 0.4), (0.5, 0.7, 0.4)),
        (390.0, -0.1, (-0.2, 0.7, 0.4), (-0.2, 0.0, 0.0)),  # near: only away; α<0: only −
        (390.0, -0.1, (1.0, -0.3, -0.9), (1.0, -0.3, -0.9)),
        (400.0, 0.0, (0.0, -1.0, -1.0), (0.0, 0.0, 0.0)),  # D−W_d ≥ 0 and α ≥ 0 at equality
        (400.0, 0.0, (0.0, 2.0, 2.0), (0.0, 1.0, 1.0)),  # outside [-1, 1]: clipped
        (math.nan, math.nan, (0.3, 0.8, -0.8), (0.3, 0.0, 0.0)),  # no valid point: hold
    ],
)
def test_dynamic_action_limitation_is_the_papers(plate, d, alpha, action, expected):
    env = plate_env(plate)
    env.reset(seed=0)
    got = limit_action(np.array(action), d, alpha, env.limits, WD)
    np.testing.assert_allclose(got, np.array(expected) * [1.0, 1.0, math.radians(1.0)])


def test_info_terms_are_reward_terms_of_the_steps_measurements():
    env = SwathScanEnv(noise=True)
    env.reset(seed=5)
    rng = np.random.default_rng(0)
    for _ in range(30):
        prev = env.dynamics.profile
        _, r, _, _, info = env.step(rng.uniform(-1, 1, 3))
        prof = env.dynamics.profile
        d = mean_distance(prof.z_sensor, prof.valid)
        a = signed_alpha(prof.normals_part, prof.valid, prof.T_part_sensor)
        ds = advance(
            prev.points_part, prev.valid, prof.points_part, prof.valid, env.dynamics.swath.u
        )
        terms = reward_terms(d, a, ds, env.scan_spec)
        assert info["d_mm"] == pytest.approx(float(d), nan_ok=True)
        assert info["delta_s_mm"] == pytest.approx(float(ds), nan_ok=True)
        for key in ("r_d", "r_alpha", "r_delta_s"):
            assert info[key] == pytest.approx(float(terms[key]))
        assert r == pytest.approx(float(terms["reward"]) + info["lost_penalty"])


def test_flat_plate_aligned_half_millimetre_step_has_zero_reward(plate):
    env = plate_env(plate)
    _, info = env.reset(seed=0)
    assert info["d_mm"] == pytest.approx(WD, abs=1e-3)  # started at W_d, aligned
    assert info["alpha_rad"] == pytest.approx(0.0, abs=1e-9)
    _, r, term, trunc, info = env.step(np.array([0.5, 0.0, 0.0]))  # Δy = 0.5 mm
    assert info["delta_s_mm"] == pytest.approx(0.5, abs=1e-6)
    assert r == pytest.approx(0.0, abs=1e-6)
    assert not (term or trunc)
    _, r, _, _, _ = env.step(np.array([1.0, 0.0, 0.0]))  # Δs = 1 mm = 2 Δs_opt: R_Δs = −1
    assert r == pytest.approx(-1 / 3, abs=1e-6)


def test_reaching_the_pass_end_terminates(plate):
    env = plate_env(plate)
    env.reset(seed=0)
    env.dynamics.state[0] = env.s_end_mm - 0.3  # pitch 0: the scan advance is the sensor s
    _, _, term, trunc, _ = env.step(np.array([0.5, 0.0, 0.0]))
    assert term and not trunc


def test_losing_the_surface_charges_the_remaining_nominal_steps(plate):
    env = plate_env(plate, lost_patience=5)
    env.reset(seed=0)
    total, steps = 0.0, 0
    while True:  # back off the plate's edge: no valid point any more
        _, r, term, trunc, info = env.step(np.array([-1.0, 0.0, 0.0]))
        total += r
        steps += 1
        if term or trunc:
            break
    assert term and not trunc and steps < 100
    remaining = math.ceil((env.s_end_mm - env.dynamics.progress_mm) / 0.5)
    assert remaining > 1000
    assert info["lost_penalty"] == -min(remaining, env.step_limit - steps)
    # Never cheaper than finishing: at worst −1 per remaining step.
    assert total <= -min(remaining, env.step_limit - steps)


def test_subsampled_fan_agrees_with_the_full_fan_on_the_training_piece():
    """Tolerance for training with 128 columns: |ΔD| ≤ 0.1 mm, |Δα| ≤ 0.3°, |ΔΔs| ≤ 0.005 mm
    (max over 150 station pairs along the training piece, heights and pitches varied)."""
    part = load_part("training-piece")
    spec = SensorSpec().without_noise()
    u, v = np.array([1.0, 0, 0]), np.array([0, 1.0, 0])
    sw = Swath(0, np.array([-545.0, 0, 450.0]), np.array([545.0, 0, 450.0]), u, v)
    rng = np.random.default_rng(0)
    s = np.repeat(np.sort(rng.uniform(30, 1060, 150)), 2)
    s[1::2] += 0.5
    h = np.repeat(rng.uniform(-40, 0, 150), 2)
    th = np.repeat(rng.uniform(-0.3, 0.3, 150), 2)
    poses = sw.poses(s, h, th)
    out = []
    for n in (128, 4096):
        sc = LineProfilometer(part, spec.with_points(n)).measure_many(poses)
        d = mean_distance(sc.z_sensor, sc.valid)
        a = signed_alpha(sc.normals_part, sc.valid, poses)
        ds = advance(sc.points_part[::2], sc.valid[::2], sc.points_part[1::2], sc.valid[1::2], u)
        out.append((d, a, ds))
    for k, tol in enumerate((0.1, math.radians(0.3), 0.005)):
        err = np.abs(out[0][k] - out[1][k])
        assert np.isfinite(err).mean() > 0.9
        assert np.nanmax(err) <= tol


@pytest.mark.parametrize("kwargs", [{}, {"use_position": False}])
def test_v1_env_checkers_are_clean_and_rollouts_seeded(kwargs):
    env = gym.make(ENV_ID_ROLL, disable_env_checker=True, **kwargs).unwrapped
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        gym_check_env(env)
        sb3_check_env(env, warn=True)
    assert env.action_space.shape == (4,)
    assert env.observation_space.shape == (9 - 3 * (not kwargs.get("use_position", True)),)

    def rollout(seed):
        e = SwathScanEnv(roll=True)
        obs, _ = e.reset(seed=seed)
        rng = np.random.default_rng(seed)
        out = [obs]
        for _ in range(40):
            obs, *_ = e.step(rng.uniform(-1, 1, 4).astype(np.float32))
            out.append(obs)
        return np.array(out)

    np.testing.assert_array_equal(rollout(3), rollout(3))
