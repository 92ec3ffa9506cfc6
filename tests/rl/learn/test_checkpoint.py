"""Checkpoints (learn.checkpoint): parameters and optimizer restored exactly, a resume takes the
recorded config, a checkpoint is never unpickled (library and CLI), and one that a full disk
stops is an OSError that leaves no file."""

from __future__ import annotations

import errno
import json

import pytest
import torch

from helpers import Exploit, full_disk, listing, ppo, tiny_config
from scanplan.rl.learn.checkpoint import save_checkpoint


def test_checkpoint_restores_parameters_and_optimizer_exactly(tmp_path):
    from scanplan.rl.learn.checkpoint import latest_checkpoint, load_checkpoint, restore

    trained = ppo(0)
    trained.learn(128)
    path = save_checkpoint(trained, tiny_config(tmp_path), tmp_path)
    assert path == latest_checkpoint(tmp_path) and path.name == "ppo_128.json"
    assert path.with_suffix(".safetensors").is_file()
    fresh = ppo(1)  # other initial weights: everything must come from the checkpoint
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


def test_resume_takes_the_recorded_config(tmp_path):
    from dataclasses import asdict

    from scanplan.rl.learn.checkpoint import Checkpoint, CheckpointMeta, resumed_config

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


def _sb3_style_zip(path, marker) -> None:
    """What `PPO.load` reads: `data` JSON whose ':serialized:' entries it cloudpickle-loads,
    and torch pickles (policy.pth) — here each carrying the payload."""
    import base64
    import pickle
    import zipfile

    payload = base64.b64encode(pickle.dumps(Exploit(marker))).decode()
    data = {"policy_class": {":type:": "<class 'abc.ABCMeta'>", ":serialized:": payload}}
    buffer = path.parent / "policy.pth"
    torch.save({"x": Exploit(marker)}, buffer)
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
    pickle.loads(pickle.dumps(Exploit(tmp_path / "control")))  # the payload is live
    assert (tmp_path / "control").exists()

    old = tmp_path / "old" / "checkpoints"
    old.mkdir(parents=True)
    _sb3_style_zip(old / "ppo_2048.zip", marker)
    # A new-format checkpoint whose tensor file is a torch pickle instead of safetensors.
    disguised = tmp_path / "disguised"
    path = save_checkpoint(ppo(0), tiny_config(disguised), disguised)
    torch.save({"x": Exploit(marker)}, path.with_suffix(".safetensors"))
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
    from scanplan.rl.learn.checkpoint import load_checkpoint

    marker = tmp_path / "pwned"
    trained = ppo(0)
    path = save_checkpoint(trained, tiny_config(tmp_path), tmp_path)
    torch.save({"x": Exploit(marker)}, path.with_suffix(".safetensors"))
    with pytest.raises(ValueError, match="checkpoint .*ppo_0.safetensors: not a safetensors file"):
        load_checkpoint(path)
    assert not marker.exists()


@pytest.mark.parametrize("fail_at", [1, 2], ids=["weights", "json"])
def test_a_checkpoint_on_a_full_disk_is_an_oserror_and_leaves_nothing(
    tmp_path, monkeypatch, fail_at
):
    model = ppo(0)
    full_disk(monkeypatch, fail_at=fail_at)
    with pytest.raises(OSError) as caught:
        save_checkpoint(model, tiny_config(tmp_path), tmp_path)
    assert caught.value.errno == errno.ENOSPC
    assert "cannot write" in str(caught.value) and "No space left on device" in str(caught.value)
    assert listing(tmp_path / "checkpoints") == []
