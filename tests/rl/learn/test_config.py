"""The training config holds every number to a plausible range (scanplan.core.limits): a
reward scale, a learning rate or a discount that would train on nothing is refused, naming
the option or the field."""

from __future__ import annotations

import re

import pytest

from helpers import tiny_config
from scanplan.rl.learn.config import recipe_config
from scanplan.rl.policy import EnvOptions


@pytest.mark.parametrize("scale", [1e-300, 0.05, 1e5, float("nan"), float("inf"), -1.0])
def test_an_implausible_reward_scale_is_refused_naming_the_option(scale):
    with pytest.raises(
        ValueError, match=r"^--reward-distance-scale .* is not in \[0\.1, 10000\] mm$"
    ):
        recipe_config("/tmp/x", reward_distance_scale=scale)


def test_the_ends_of_the_reward_scale_are_taken():
    for scale in (0.1, 1e4):
        assert (
            recipe_config("/tmp/x", reward_distance_scale=scale).env["reward_distance_scale_mm"]
            == scale
        )


def test_a_policy_file_s_reward_scale_is_held_to_the_same_range():
    env = dict(recipe_config("/tmp/x", reward_distance_scale=12.5).env)
    assert EnvOptions.model_validate(env).reward_distance_scale_mm == 12.5
    with pytest.raises(ValueError, match=re.escape("1e-300 is not in [0.1, 10000] mm")):
        EnvOptions.model_validate(env | {"reward_distance_scale_mm": 1e-300})


@pytest.mark.parametrize(
    ("field", "value", "message"),
    [
        ("learning_rate", 1e-300, "learning_rate 1e-300 is not in [1e-08, 1]"),
        ("gamma", 1e-300, "gamma 1e-300 is not in [0.5, 1]"),
        ("gamma", 1.5, "gamma 1.5 is not in [0.5, 1]"),
        ("clip_range", 1e-300, "clip_range 1e-300 is not in [0.01, 1]"),
        ("log_std_init", 30.0, "log_std_init 30 is not in [-20, 2]"),
        ("log_std_init", (-2.0, -2.0, float("nan")), "log_std_init nan is not in [-20, 2]"),
    ],
)
def test_ppo_numbers_are_held_to_plausible_ranges(tmp_path, field, value, message):
    with pytest.raises(ValueError, match=f"^training config: {re.escape(message)}$"):
        tiny_config(tmp_path, **{field: value})


def test_the_log_std_option_is_named():
    with pytest.raises(ValueError, match=r"^--log-std-init 5 is not in \[-20, 2\]$"):
        recipe_config("/tmp/x", log_std_init=(5.0,))
    assert recipe_config("/tmp/x", log_std_init=(-2.0, -2.0, -4.0)).log_std_init == (-2, -2, -4)
