"""The random start offsets of SwathScanEnv (beyond the paper): an episode may start off the
aligned pose, by a depth error along the beam and a pitch error about the footprint."""

from __future__ import annotations

import math

import numpy as np
import pytest

from helpers import plate_swath
from scanplan.rl.env import SwathScanEnv
from scanplan.rl.learn.config import recipe_config
from scanplan.rl.policy import EnvOptions
from scanplan.world.part import Part

WD = 400.0


def plate_env(plate: Part, **kwargs) -> SwathScanEnv:
    return SwathScanEnv(
        parts=[plate], swaths=[plate_swath()], noise=False, segment_mm=None, **kwargs
    )


def test_no_offset_starts_aligned_and_draws_nothing(plate):
    env, other = plate_env(plate), plate_env(plate, start_offset_mm=0.0, start_pitch_deg=0.0)
    _, info = env.reset(seed=3)
    other.reset(seed=3)
    assert info["d_mm"] == pytest.approx(WD, abs=1e-3)
    assert info["alpha_rad"] == pytest.approx(0.0, abs=1e-9)
    # The same draws follow: the offsets' absence changes no other random number.
    assert env.np_random.random() == other.np_random.random()


def test_offsets_spread_the_start_within_their_bounds_about_the_footprint(plate):
    env = plate_env(plate, start_offset_mm=80.0, start_pitch_deg=10.0)
    depth, pitch = [], []
    for seed in range(12):
        _, info = env.reset(seed=seed)
        depth.append(info["d_mm"] - WD)
        pitch.append(math.degrees(env.dynamics.state[2]))
        # Pitched about the footprint: the beam still meets W_d where the aligned start's did.
        s, h, th = env.dynamics.state
        assert s - WD * math.sin(th) == pytest.approx(env.start_state[0] - WD * math.sin(th))
    depth_a, pitch_a = np.abs(depth), np.abs(pitch)
    # On a flat plate the depth error along a pitched beam is (W_d − dz)/cos θ·cos θ = −dz
    # give or take the mean over the fan: within the bounds, and spread over them.
    assert depth_a.max() <= 80.0 * 1.01 + 1.0 and pitch_a.max() <= 10.0 + 1e-9
    assert depth_a.max() > 40.0 and pitch_a.max() > 5.0
    assert np.std(depth) > 15.0
    again = plate_env(plate, start_offset_mm=80.0, start_pitch_deg=10.0)
    _, info = again.reset(seed=11)
    assert info["d_mm"] - WD == pytest.approx(depth[-1])  # seeded


def test_offsets_are_refused_out_of_range_and_with_roll(plate):
    with pytest.raises(ValueError, match="pitch"):
        plate_env(plate, start_pitch_deg=61.0)
    with pytest.raises(ValueError, match="v0 only"):
        plate_env(plate, start_offset_mm=10.0, roll=True)


def test_the_trainer_records_offsets_only_when_set():
    plain = recipe_config("/tmp/x")
    offset = recipe_config("/tmp/x", start_offset=(100.0, 20.0))
    assert "start_offset_mm" not in plain.env
    assert offset.env["start_offset_mm"] == 100.0 and offset.env["start_pitch_deg"] == 20.0
    assert EnvOptions.model_validate(offset.env).start_pitch_deg == 20.0
    with pytest.raises(ValueError, match="two values"):
        recipe_config("/tmp/x", start_offset=(1.0,))
    with pytest.raises(ValueError, match="v0 only"):
        recipe_config("/tmp/x", env_version="v1", start_offset=(10.0, 0.0))


@pytest.mark.parametrize(
    ("value", "fragment"),
    [("5000,0", "--start-offset"), ("10", "two values"), ("a,b", "expected numbers")],
)
def test_train_refuses_a_bad_start_offset_before_training(tmp_path, value, fragment):
    from typer.testing import CliRunner

    from scanplan.cli import app

    out = tmp_path / "pol"
    result = CliRunner().invoke(app, ["train", "-o", str(out), "--start-offset", value, "-q"])
    assert result.exit_code != 0
    assert fragment in result.stderr and "Traceback" not in result.output
    assert not out.exists()
