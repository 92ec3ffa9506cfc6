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

from scanplan.learn.checkpoint import save_checkpoint
from scanplan.learn.config import TrainConfig, env_options
from scanplan.learn.train import train
from scanplan.planners.rl import RLPlanner
from scanplan.quantities import ScanSpec
from scanplan.report.training import LOG_COLUMNS, LOG_KEYS, read_log
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


# ---- checkpoints: exact, and never unpickled ---------------------------------------------


def _ppo(seed: int):
    import gymnasium as gym
    from stable_baselines3 import PPO

    return PPO(
        "MlpPolicy",
        gym.make("Pendulum-v1"),
        n_steps=64,
        batch_size=32,
        n_epochs=2,
        seed=seed,
        device="cpu",
    )


def test_checkpoint_restores_parameters_and_optimizer_exactly(tmp_path):
    from scanplan.learn.checkpoint import latest_checkpoint, load_checkpoint, restore

    trained = _ppo(0)
    trained.learn(128)
    path = save_checkpoint(trained, tiny_config(tmp_path), tmp_path)
    assert path == latest_checkpoint(tmp_path) and path.name == "ppo_128.json"
    assert path.with_suffix(".safetensors").is_file()
    fresh = _ppo(1)  # other initial weights: everything must come from the checkpoint
    restore(fresh, load_checkpoint(path))
    assert fresh.num_timesteps == 128 and fresh._n_updates == trained._n_updates
    for key, value in trained.policy.state_dict().items():
        assert torch.equal(fresh.policy.state_dict()[key], value), key
    want, got = trained.policy.optimizer.state_dict(), fresh.policy.optimizer.state_dict()
    assert want["param_groups"] == got["param_groups"]
    for index, state in want["state"].items():
        for key, value in state.items():
            assert torch.equal(got["state"][index][key], value), (index, key)
    meta = json.loads(path.read_text())
    assert meta["config"]["n_steps"] == 64
    assert meta["log_std"] == trained.policy.log_std.tolist()
    assert meta["optimizer"]["type"] == "Adam" and len(meta["optimizer"]["steps"]) == len(
        want["state"]
    )


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


def test_resume_takes_the_recorded_config(tmp_path):
    from dataclasses import asdict

    from scanplan.learn.checkpoint import Checkpoint, CheckpointMeta, resumed_config

    recorded = tiny_config(tmp_path, seed=7, env={"fan_points": 32, "use_position": False})
    meta = CheckpointMeta.model_validate(
        {
            "format": "scanplan-checkpoint/1",
            "num_timesteps": 128,
            "n_updates": 2,
            "config": asdict(recorded),
            "optimizer": {"type": "Adam", "param_groups": [{"params": [0]}], "steps": [2.0]},
            "log_std": [0.0, 0.0, 0.0],
            "sb3_version": "x",
            "torch_version": "y",
        }
    )
    now = tiny_config(tmp_path / "new", total_timesteps=999, command="scanplan train --resume")
    config = resumed_config(Checkpoint(tmp_path / "ppo_128.json", meta, {}), now)
    assert config.seed == 7 and config.env == {"fan_points": 32, "use_position": False}
    assert config.total_timesteps == 999 and config.output_dir == str(tmp_path / "new")
    assert config.command == "scanplan train --resume" and config.parts == ("training-piece",)


class _Exploit:
    """Unpickling this creates `marker` (stands in for arbitrary code)."""

    def __init__(self, marker):
        self.marker = str(marker)

    def __reduce__(self):
        return (open, (self.marker, "w"))


def _sb3_style_zip(path, marker) -> None:
    """What `PPO.load` reads: `data` JSON whose ':serialized:' entries it cloudpickle-loads,
    and torch pickles (policy.pth) — here each carrying the payload."""
    import base64
    import pickle
    import zipfile

    payload = base64.b64encode(pickle.dumps(_Exploit(marker))).decode()
    data = {"policy_class": {":type:": "<class 'abc.ABCMeta'>", ":serialized:": payload}}
    buffer = path.parent / "policy.pth"
    torch.save({"x": _Exploit(marker)}, buffer)
    with zipfile.ZipFile(path, "w") as z:
        z.writestr("data", json.dumps(data))
        z.write(buffer, "policy.pth")
        z.writestr("_stable_baselines3_version", "2.3.0")
    buffer.unlink()


def test_cli_resume_never_unpickles_a_checkpoint(tmp_path):
    import pickle

    from typer.testing import CliRunner

    from scanplan.cli import app

    marker = tmp_path / "pwned"
    pickle.loads(pickle.dumps(_Exploit(tmp_path / "control")))  # the payload is live
    assert (tmp_path / "control").exists()

    old = tmp_path / "old" / "checkpoints"
    old.mkdir(parents=True)
    _sb3_style_zip(old / "ppo_2048.zip", marker)
    # A new-format checkpoint whose tensor file is a torch pickle instead of safetensors.
    disguised = tmp_path / "disguised"
    path = save_checkpoint(_ppo(0), tiny_config(disguised), disguised)
    torch.save({"x": _Exploit(marker)}, path.with_suffix(".safetensors"))
    runner = CliRunner()
    for resume, expected in [
        (old.parent, "old checkpoint format (SB3 .zip), not loaded: it would unpickle code"),
        (disguised, "ppo_0.safetensors: not a safetensors file"),
    ]:
        out = tmp_path / "out"
        result = runner.invoke(
            app,
            [
                "train",
                "--resume",
                str(resume),
                "-o",
                str(out),
                "--timesteps",
                "256",
                "--n-envs",
                "2",
                "--no-progress",
            ],
        )
        assert result.exit_code == 2, result.output
        assert result.stderr.strip().count("\n") == 0 and expected in result.stderr, result.stderr
        assert not marker.exists()


def test_checkpoint_with_pickled_tensors_is_refused(tmp_path):
    from scanplan.learn.checkpoint import load_checkpoint

    marker = tmp_path / "pwned"
    trained = _ppo(0)
    path = save_checkpoint(trained, tiny_config(tmp_path), tmp_path)
    torch.save({"x": _Exploit(marker)}, path.with_suffix(".safetensors"))
    with pytest.raises(ValueError, match="checkpoint .*ppo_0.safetensors: not a safetensors file"):
        load_checkpoint(path)
    assert not marker.exists()


# ---- reproducibility, env options, logs -------------------------------------------------


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


def test_read_log_reads_the_shipped_old_format_log_unchanged():
    from scanplan.planners.rl import DEFAULT_POLICY

    path = DEFAULT_POLICY / "training_log.csv"
    log = read_log(path)
    rows = list(csv.DictReader(path.open()))
    assert tuple(log) == LOG_COLUMNS and len(log["timesteps"]) == len(rows) == 30
    for column in LOG_COLUMNS:
        assert log[column].tolist() == [float(r[column]) for r in rows], column


def test_read_log_refuses_a_csv_that_is_no_training_log(tmp_path):
    path = tmp_path / "x.csv"
    path.write_text("a,b\n1,2\n")
    with pytest.raises(ValueError, match="x.csv: neither SB3's progress.csv"):
        read_log(path)


def test_training_comparison_plots_every_run_in_every_panel(tmp_path, monkeypatch):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from scanplan.planners.rl import DEFAULT_POLICY
    from scanplan.report.training import COMPARISON_PANELS, plot_training_comparison

    shipped = DEFAULT_POLICY / "training_log.csv"
    other = tmp_path / "other.csv"  # the same log at half the reward, as a second run
    rows = list(csv.DictReader(shipped.open()))
    with other.open("w", newline="") as f:
        writer = csv.DictWriter(f, list(rows[0]))
        writer.writeheader()
        for r in rows:
            writer.writerow(r | {"ep_rew_mean": str(float(r["ep_rew_mean"]) / 2)})
    figures = []
    monkeypatch.setattr(plt, "close", lambda fig: figures.append(fig))
    out = plot_training_comparison({"shipped": shipped, "half": other}, tmp_path / "c.png")
    assert out.is_file() and out.stat().st_size > 10_000
    (fig,) = figures
    assert [ax.get_title() for ax in fig.axes] == [t for _, t in COMPARISON_PANELS]
    reward = fig.axes[0].get_lines()
    assert len(reward) == 2 and all(len(ax.get_lines()) == 2 for ax in fig.axes)
    ys = read_log(shipped)["ep_rew_mean"]
    np.testing.assert_allclose(reward[0].get_ydata(), ys)
    np.testing.assert_allclose(reward[1].get_ydata(), ys / 2)
    with pytest.raises(ValueError, match="no log"):
        plot_training_comparison({}, tmp_path / "none.png")


def test_zero_timesteps_is_behaviour_cloning_only(tmp_path):
    result = train(tiny_config(tmp_path / "bc", total_timesteps=0, bc_samples=64))
    meta = json.loads(result.policy_json.read_text())
    assert result.timesteps == 0 and meta["training"]["timesteps"] == 0
    assert meta["training"]["behaviour_cloning_mse"] > 0
    assert not result.log_csv.exists() and result.plots == ()
    with pytest.raises(ValueError, match="no behaviour cloning"):
        tiny_config(tmp_path, total_timesteps=0, bc_samples=0)
    with pytest.raises(ValueError, match="total_timesteps must be >= 0"):
        tiny_config(tmp_path, total_timesteps=-1)
