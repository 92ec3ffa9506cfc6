"""End-to-end training: a learn(256)-sized PPO run writes the log, the curves and a policy that
the rl planner loads (without unpickling) and plans with; resuming continues the count."""

from __future__ import annotations

import csv
import importlib.util
import json

import numpy as np
import pytest
from safetensors.torch import load_file

from scanplan.planners.rl import RLPlanner
from scanplan.sensor import SensorSpec
from scanplan.train import LOG_COLUMNS, TrainConfig, train
from test_env import plate, plate_swath  # noqa: F401  (fixture)


def tiny_config(out, **kw) -> TrainConfig:
    base = {
        "output_dir": str(out),
        "total_timesteps": 256,
        "n_envs": 2,
        "n_steps": 64,
        "batch_size": 32,
        "n_epochs": 2,
        "checkpoint_every_updates": 1,
        "progress_bar": False,
        "command": "pytest tiny",
        "env": {"fan_points": 64, "noise": False, "segment_mm": (20.0, 40.0)},
        "bc_samples": 200,  # exercise the warm start too
    }
    return TrainConfig(**(base | kw))


@pytest.mark.slow
def test_tiny_training_run_end_to_end(tmp_path, plate):  # noqa: F811
    result = train(tiny_config(tmp_path / "pol"))
    assert result.timesteps >= 256
    rows = list(csv.DictReader(result.log_csv.open()))
    assert len(rows) == 2 and tuple(rows[0]) == LOG_COLUMNS  # 256 / (2 x 64) updates
    assert all(-1.0 <= float(r["r_alpha"]) <= 0.0 for r in rows)
    for png in result.plots:
        assert png.stat().st_size > 5_000 and png.read_bytes()[:4] == b"\x89PNG"
    meta = json.loads(result.policy_json.read_text())
    assert meta["architecture"]["hidden"] == [64, 64] and meta["training"]["seed"] == 0
    # Plain tensors in a safetensors file (no code is unpickled).
    assert result.weights.name == "policy.safetensors"
    state = load_file(result.weights)
    assert state["0.weight"].shape == (64, 7) and state["4.weight"].shape == (3, 64)

    # TensorBoard event files exactly when TensorBoard is installed (an optional extra).
    events = list((result.output_dir / "tensorboard").glob("**/events.out.tfevents.*"))
    assert bool(events) == (importlib.util.find_spec("tensorboard") is not None)

    planner = RLPlanner.from_file(result.output_dir)
    traj = planner.plan(plate, plate_swath(), SensorSpec())
    assert len(traj) > 10 and traj.scanning.all() and (traj.swath == 0).all()
    assert np.isfinite(traj.poses).all() and traj.planner == "rl"

    # Resume: continues from the last checkpoint, appends to the log.
    again = train(tiny_config(tmp_path / "pol", total_timesteps=512, resume=str(tmp_path / "pol")))
    assert again.timesteps >= 512
    assert len(list(csv.DictReader(again.log_csv.open()))) == 4


def test_bad_training_config_is_a_value_error(tmp_path):
    with pytest.raises(ValueError, match="timesteps"):
        train(tiny_config(tmp_path, total_timesteps=0))
    with pytest.raises(ValueError, match="no checkpoint"):
        train(tiny_config(tmp_path / "x", resume=str(tmp_path / "empty")))
