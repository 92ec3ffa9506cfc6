"""R_D's scale (`scanplan train --reward-distance-scale`, a deviation from the paper's Z_r/2):
the paper's reward is unchanged unless it is set, and when set the env charges −1 at it."""

from __future__ import annotations

import numpy as np
import pytest

from helpers import plate_swath
from scanplan.core.quantities import ScanSpec
from scanplan.core.reward import reward_distance
from scanplan.rl.env import SwathScanEnv
from scanplan.rl.learn.config import recipe_config
from scanplan.rl.policy import EnvOptions

WD = 400.0


def test_the_paper_scale_is_the_default():
    spec = ScanSpec()
    assert spec.distance_scale_mm == spec.half_range_mm
    e = np.array([0.0, 10.0, 62.5, 125.0, 200.0])
    expected = np.maximum(-((e / spec.half_range_mm) ** 2), -1.0)
    np.testing.assert_allclose(reward_distance(WD + e, spec), expected, rtol=1e-12)


def test_a_set_scale_charges_minus_one_at_it_and_a_quarter_at_half_of_it():
    spec = ScanSpec(reward_distance_scale_mm=25.0)
    r = reward_distance(np.array([WD, WD + 12.5, WD - 25.0, WD + 40.0, np.nan]), spec)
    np.testing.assert_allclose(r, [0.0, -0.25, -1.0, -1.0, -1.0])
    with pytest.raises(ValueError, match="reward distance scale"):
        ScanSpec(reward_distance_scale_mm=0.0)


def test_the_env_rewards_with_the_scale_and_only_r_d_changes(plate):
    def env(**kw):
        return SwathScanEnv(
            parts=[plate],
            swaths=[plate_swath()],
            noise=False,
            segment_mm=None,
            start_offset_mm=30.0,  # a depth error to charge
            **kw,
        )

    paper, scaled = env(), env(reward_distance_scale_mm=10.0)
    assert scaled.scan_spec.distance_scale_mm == 10.0
    assert paper.scan_spec.distance_scale_mm == paper.scan_spec.half_range_mm
    paper.reset(seed=0)
    scaled.reset(seed=0)
    action = np.array([0.5, 0.0, 0.0], dtype=np.float32)
    for _ in range(3):
        _, _, _, _, a = paper.step(action)
        _, _, _, _, b = scaled.step(action)
    assert a["d_mm"] == b["d_mm"] and a["r_alpha"] == b["r_alpha"]
    err = a["d_mm"] - WD
    assert abs(err) > 1.0
    assert a["r_d"] == pytest.approx(-((err / 125.0) ** 2))
    assert b["r_d"] == pytest.approx(max(-1.0, -((err / 10.0) ** 2)))


def test_the_trainer_records_the_scale_only_when_set():
    assert "reward_distance_scale_mm" not in recipe_config("/tmp/x").env
    cfg = recipe_config("/tmp/x", reward_distance_scale=25.0)
    assert cfg.env["reward_distance_scale_mm"] == 25.0
    assert EnvOptions.model_validate(cfg.env).reward_distance_scale_mm == 25.0
    with pytest.raises(ValueError, match="--reward-distance-scale"):
        recipe_config("/tmp/x", reward_distance_scale=-1.0)
