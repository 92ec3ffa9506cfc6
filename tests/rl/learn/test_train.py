"""End-to-end training: a learn(256)-sized PPO run writes the log, the curves and a policy that
the rl planner loads (without unpickling) and plans with; resuming continues the count."""

from __future__ import annotations

import csv
import importlib.util
import json

import numpy as np
import pytest
import torch
from safetensors.torch import load_file

from helpers import plate_swath, tiny_config
from scanplan.core.quantities import ScanSpec
from scanplan.judging.report.training import LOG_COLUMNS, LOG_KEYS, read_log
from scanplan.rl.learn.train import train
from scanplan.rl.planner import RLPlanner


@pytest.mark.slow
def test_tiny_training_run_end_to_end(tmp_path, plate):
    result = train(tiny_config(tmp_path / "pol"))
    assert result.timesteps >= 256
    # SB3's progress.csv: one row per update (256 / (2 x 64)), the paper's quantities in it.
    rows = list(csv.DictReader(result.log_csv.open()))
    assert result.log_csv.name == "progress.csv" and len(rows) == 2
    assert set(LOG_KEYS.values()) <= set(rows[0])
    log = read_log(result.log_csv)
    assert tuple(log) == LOG_COLUMNS
    assert log["update"].tolist() == [1, 2] and log["timesteps"].tolist() == [128, 256]
    for key in ("reward_per_step", "r_d", "r_alpha", "r_delta_s"):
        assert ((-1.0 <= log[key]) & (log[key] <= 0.0)).all(), key
    # Overall = weighted partial rewards (1/3 each) unless a lost pass was charged extra
    # (or SB3 bootstrapped a truncated pass's reward: none does in this seeded run).
    partial = (log["r_d"] + log["r_alpha"] + log["r_delta_s"]) / 3
    lost = log["lost_episodes"] > 0
    assert np.allclose(log["reward_per_step"][~lost], partial[~lost], atol=1e-6)
    assert (np.diff(log["episodes"]) >= 0).all() and (np.diff(log["wall_time_s"]) > 0).all()
    finished = np.isfinite(log["ep_len_mean"])
    assert (log["ep_len_mean"][finished] >= 1).all()
    assert (log["ep_rew_mean"][finished] <= 0).all()
    for png in result.plots:
        assert png.stat().st_size > 5_000 and png.read_bytes()[:4] == b"\x89PNG"
    meta = json.loads(result.policy_json.read_text())
    assert meta["architecture"]["hidden"] == [64, 64] and meta["training"]["seed"] == 0
    # Plain tensors in a safetensors file (no code is unpickled).
    assert result.weights.name == "policy.safetensors"
    state = load_file(result.weights)
    assert state["0.weight"].shape == (64, 7) and state["4.weight"].shape == (3, 64)

    # TensorBoard event files exactly when TensorBoard is installed (an optional extra).
    events = list(result.output_dir.glob("events.out.tfevents.*"))
    assert bool(events) == (importlib.util.find_spec("tensorboard") is not None)

    planner = RLPlanner.from_file(result.output_dir)
    traj = planner.plan(plate, plate_swath(), ScanSpec())
    assert len(traj) > 10 and traj.scanning.all() and (traj.swath == 0).all()
    assert np.isfinite(traj.poses).all() and traj.planner == "rl"

    # Resume: continues from the last checkpoint, appends to the log.
    again = train(tiny_config(tmp_path / "pol", total_timesteps=512, resume=str(tmp_path / "pol")))
    assert again.timesteps >= 512
    assert read_log(again.log_csv)["update"].tolist() == [1, 2, 3, 4]


def test_bad_training_config_is_a_value_error(tmp_path):
    with pytest.raises(ValueError, match="timesteps"):  # 0 PPO steps and nothing to clone
        train(tiny_config(tmp_path, total_timesteps=0, bc_samples=0))
    with pytest.raises(ValueError, match="no checkpoint"):
        train(tiny_config(tmp_path / "x", resume=str(tmp_path / "empty")))


@pytest.mark.slow
def test_resume_continues_from_the_saved_parameters(tmp_path):
    first = train(tiny_config(tmp_path / "run"))
    ckpts = sorted(p.name for p in (first.output_dir / "checkpoints").iterdir())
    assert ckpts == [
        "ppo_128.json",
        "ppo_128.safetensors",
        "ppo_256.json",
        "ppo_256.safetensors",
    ]  # no pickle-based .zip
    saved = load_file(first.output_dir / "checkpoints" / "ppo_256.safetensors")

    # Resume without new steps: the policy written is exactly the checkpoint's actor.
    same = train(tiny_config(tmp_path / "same", resume=str(first.output_dir)))
    actor = load_file(same.weights)
    assert same.timesteps == 256
    assert torch.equal(actor["0.weight"], saved["policy.mlp_extractor.policy_net.0.weight"])
    assert torch.equal(actor["4.bias"], saved["policy.action_net.bias"])

    # Resume to more steps: the count, the log and the checkpoints continue.
    more = train(tiny_config(tmp_path / "run", total_timesteps=512, resume=str(first.output_dir)))
    assert more.timesteps == 512
    log = read_log(more.log_csv)
    assert log["update"].tolist() == [1, 2, 3, 4]
    assert log["timesteps"].tolist() == [128, 256, 384, 512]
    assert (np.diff(log["episodes"]) >= 0).all() and (np.diff(log["wall_time_s"]) > 0).all()
    assert (more.output_dir / "checkpoints" / "ppo_512.json").is_file()
    assert json.loads(more.policy_json.read_text())["training"]["timesteps"] == 512


@pytest.mark.slow
def test_same_config_and_seed_train_bit_identical_weights(tmp_path):
    def actor(out, **kw):
        result = train(tiny_config(out, bc_samples=64, **kw))
        return load_file(result.weights), read_log(result.log_csv)

    first, log_first = actor(tmp_path / "a")
    again, log_again = actor(tmp_path / "b")
    other, _ = actor(tmp_path / "c", seed=1)
    assert first.keys() == again.keys() == other.keys()
    for key in first:
        assert torch.equal(first[key], again[key]), key
    assert not all(torch.equal(first[key], other[key]) for key in first)
    for key in ("reward_per_step", "r_d", "r_alpha", "r_delta_s", "episodes"):
        assert np.array_equal(log_first[key], log_again[key]), key


def test_zero_timesteps_is_behaviour_cloning_only(tmp_path):
    result = train(tiny_config(tmp_path / "bc", total_timesteps=0, bc_samples=64))
    meta = json.loads(result.policy_json.read_text())
    assert result.timesteps == 0 and meta["training"]["timesteps"] == 0
    assert meta["training"]["behaviour_cloning_mse"] > 0
    assert not result.log_csv.exists() and result.plots == ()
    with pytest.raises(ValueError, match="no behaviour cloning"):
        tiny_config(tmp_path, total_timesteps=0, bc_samples=0)
    with pytest.raises(ValueError, match="total_timesteps -1 is not in"):
        tiny_config(tmp_path, total_timesteps=-1)
