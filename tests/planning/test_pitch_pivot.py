"""Where a pitch step turns (`scanplan train --pitch-pivot`, beyond the paper): the sensor's
origin, or the footprint W_d along the beam, which a pitch step then does not move."""

from __future__ import annotations

import math

import numpy as np
import pytest

from helpers import plate_swath
from scanplan.planning.step_model import apply_step
from scanplan.rl.env import SwathScanEnv
from scanplan.rl.learn.config import recipe_config
from scanplan.rl.planner import RLPlanner
from scanplan.rl.policy import EnvOptions
from scanplan.world.part import Part

WD = 400.0


def footprint(state: np.ndarray) -> tuple[float, float]:
    s, h, th = state
    return s - WD * math.sin(th), h - WD * math.cos(th)


def test_a_pitch_about_the_footprint_keeps_it_and_about_the_sensor_swings_it():
    start = np.array([10.0, 400.0, math.radians(5.0)])
    step = np.array([0.0, 0.0, math.radians(1.0)])
    kept = apply_step(start, step, WD, pitch_pivot_mm=WD)
    swung = apply_step(start, step, WD)
    assert footprint(kept) == pytest.approx(footprint(start), abs=1e-9)
    # About the sensor the footprint moves back by W_d·Δθ (7 mm per degree).
    assert footprint(swung)[0] - footprint(start)[0] == pytest.approx(
        -WD * math.radians(1.0), rel=0.01
    )
    assert kept[2] == swung[2] == pytest.approx(math.radians(6.0))
    # Advance and depth steps are the same either way.
    move = np.array([0.7, -0.4, 0.0])
    assert apply_step(start, move, WD, WD) == pytest.approx(apply_step(start, move, WD))


def plate_env(plate: Part, **kwargs) -> SwathScanEnv:
    return SwathScanEnv(
        parts=[plate], swaths=[plate_swath()], noise=False, segment_mm=None, **kwargs
    )


def test_the_env_pitches_about_the_footprint_without_moving_the_scan(plate):
    env = plate_env(plate, pitch_pivot="footprint")
    other = plate_env(plate)
    ds = []
    for e in (env, other):
        e.reset(seed=0)
        for _ in range(40):  # in from the plate's edge
            e.step(np.array([1.0, 0.0, 0.0], np.float32))
        # α = 0 on the plate: the limitation allows Δθ ≥ 0.
        _, _, _, _, info = e.step(np.array([0.0, 0.0, 0.5], np.float32))
        ds.append(info["delta_s_mm"])
        assert info["d_mm"] == pytest.approx(WD / math.cos(math.radians(0.5)), abs=0.5)
    assert abs(ds[0]) < 0.05  # the footprint stays
    assert ds[1] == pytest.approx(-WD * math.radians(0.5), rel=0.05)  # swung back 3.5 mm
    with pytest.raises(ValueError, match="pitch_pivot"):
        plate_env(plate, pitch_pivot="flange")
    with pytest.raises(ValueError, match="pitch_pivot"):
        plate_env(plate, pitch_pivot="footprint", roll=True)


def test_the_trainer_records_the_pivot_only_when_set_and_the_planner_steps_so():
    assert "pitch_pivot" not in recipe_config("/tmp/x").env
    cfg = recipe_config("/tmp/x", pitch_pivot="footprint")
    assert cfg.env["pitch_pivot"] == "footprint"
    assert EnvOptions.model_validate(cfg.env).pitch_pivot == "footprint"
    with pytest.raises(ValueError, match="pitch-pivot"):
        recipe_config("/tmp/x", pitch_pivot="flange")
    with pytest.raises(ValueError, match="pitch_pivot"):
        EnvOptions.model_validate(cfg.env | {"pitch_pivot": "flange"})
    # A policy.json without one (the default policy's) pitches about the sensor.
    assert RLPlanner.from_file("default").pitch_pivot == "sensor"
    assert RLPlanner.from_file("paper").pitch_pivot == "footprint"


def test_a_pass_run_online_steps_with_the_policy_s_pivot():
    from scanplan.core.quantities import ScanSpec
    from scanplan.planning.online import OnlinePass
    from scanplan.planning.planners.feedback import FeedbackController

    spec = ScanSpec()
    kept = OnlinePass(plate_swath(), spec, FeedbackController(), pitch_pivot="footprint")
    plain = OnlinePass(plate_swath(), spec, FeedbackController())
    assert kept.dynamics.pitch_pivot_mm == spec.working_distance_mm
    assert plain.dynamics.pitch_pivot_mm == 0.0
