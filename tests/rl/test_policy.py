"""The policy file: a save/load round trip is exact, the env agrees on the observation size,
every malformed policy is a one-line ValueError naming the file and the field, and a pickled
payload is never executed (library and CLI)."""

from __future__ import annotations

import itertools
import json
import pickle
import shutil
from pathlib import Path

import pytest
import torch
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from safetensors.torch import save_file
from typer.testing import CliRunner

from helpers import Exploit, exploit_pickle, ppo, tiny_config
from scanplan.cli import app
from scanplan.planning.observation import observation_size
from scanplan.rl.learn.config import env_options
from scanplan.rl.planner import DEFAULT_POLICY, RLPlanner
from scanplan.rl.policy import (
    FORMAT,
    Architecture,
    EnvOptions,
    PolicyMeta,
    TrainingRecord,
    build_actor,
    load_policy,
    save_policy,
)


def make_meta(**env) -> PolicyMeta:
    env_options = {
        "use_position": True,
        "lookahead": False,
        "fan_points": 64,
        "noise": False,
        "segment_mm": (20.0, 40.0),
        "procedural_parts": 0,
    } | env
    arch = Architecture(
        obs_dim=observation_size(env_options["use_position"], env_options["lookahead"]),
        hidden=(16, 8),
        activation="tanh",
        action_dim=3,
    )
    return PolicyMeta(
        format=FORMAT,
        architecture=arch,
        env=EnvOptions(**env_options),
        training=TrainingRecord(
            command="scanplan train --seed 3 -o x",
            seed=3,
            timesteps=256,
            wall_time_s=1.5,
            final_metrics_last5_updates={"reward_per_step": -0.2, "ep_rew_mean": float("nan")},
            behaviour_cloning_mse=float("nan"),
        ),
    )


@pytest.fixture()
def saved(tmp_path) -> tuple[Path, torch.nn.Sequential]:
    meta = make_meta()
    torch.manual_seed(0)
    actor = build_actor(meta.architecture)
    save_policy(actor.state_dict(), meta, tmp_path / "pol")
    return tmp_path / "pol", actor


def test_round_trip_gives_identical_actor_outputs(saved):
    path, actor = saved
    policy = load_policy(path)
    obs = torch.randn(1000, 7, generator=torch.Generator().manual_seed(1)) * 3
    with torch.no_grad():
        assert torch.equal(policy.actor(obs), actor(obs))
    assert policy.meta == load_policy(path / "policy.json").meta
    data = json.loads((path / "policy.json").read_text(), parse_constant=pytest.fail)
    # Non-finite metrics are recorded as null: the file is valid JSON.
    assert data["training"]["final_metrics_last5_updates"]["ep_rew_mean"] is None
    assert data["training"]["behaviour_cloning_mse"] is None
    planner = RLPlanner.from_file(path)
    assert (
        planner.config["env"]["use_position"] is True and "dy_max_mm" not in planner.config["env"]
    )
    assert planner.config["architecture"]["hidden"] == [16, 8]


@pytest.mark.parametrize(
    ("use_position", "lookahead"), list(itertools.product([False, True], repeat=2))
)
def test_observation_size_agrees_with_the_env(use_position, lookahead):
    from scanplan.rl.env import SwathScanEnv

    for roll in (False, True):
        env = SwathScanEnv(use_position=use_position, lookahead=lookahead, roll=roll)
        obs, _ = env.reset(seed=0)
        assert obs.shape == (observation_size(use_position, lookahead, roll),)
        assert env.action_space.shape == (4 if roll else 3,)
    assert (
        observation_size(use_position, lookahead, True)
        == observation_size(use_position, lookahead, False) + 2
    )  # v1 adds φ and β


def _one_line_error(path: Path, *fragments: str, named: Path | None = None) -> str:
    """Loading `path` fails with one line that starts with `policy <named or path>`."""
    with pytest.raises(ValueError) as info:
        load_policy(path)
    message = str(info.value)
    assert "\n" not in message, message
    assert message.startswith(f"policy {named or path}:"), message
    for fragment in fragments:
        assert fragment in message, message
    return message


def _edit_json(path: Path, edit) -> None:
    data = json.loads((path / "policy.json").read_text())
    edit(data)
    (path / "policy.json").write_text(json.dumps(data))


def _set(*keys_and_value):
    *keys, value = keys_and_value

    def edit(data):
        node = data
        for k in keys[:-1]:
            node = node[k]
        node[keys[-1]] = value

    return edit


@pytest.mark.parametrize(
    ("edit", "fragments"),
    [
        (_set("architecture", "obs_dim", 4), ("architecture.obs_dim 4", "use_position=True")),
        (_set("env", "use_position", False), ("obs_dim 7", "give 4")),
        (_set("env", "lookahead", True), ("obs_dim 7", "give 17")),
        (_set("env", "use_position", "yes"), ("env.use_position", "boolean")),
        (_set("env", "noise", 0), ("env.noise",)),
        (_set("env", "fan_points", 1), ("env.fan_points", "greater than or equal to 2")),
        (_set("env", "fan_points", 64.0), ("env.fan_points", "integer")),
        (_set("env", "segment_mm", [40.0, 20.0]), ("env.segment_mm", "lo <= hi")),
        (_set("env", "segment_mm", [20.0]), ("env.segment_mm",)),
        (_set("env", "segment_mm", "20-40"), ("env.segment_mm",)),
        (_set("env", "procedural_parts", -1), ("env.procedural_parts",)),
        (_set("env", "dy_max_mm", 0.0), ("env.dy_max_mm", "0 is not in [0.001, 1000] mm")),
        (_set("env", "dz_max_mm", -1.0), ("env.dz_max_mm", "-1 is not in [0.001, 1000] mm")),
        # Issue 26: a step a real sensor could take, not a denormal or a kilometre.
        (_set("env", "dy_max_mm", 1e-300), ("env.dy_max_mm", "1e-300 is not in [0.001, 1000]")),
        (_set("env", "dy_max_mm", 1e300), ("env.dy_max_mm", "1e+300 is not in [0.001, 1000]")),
        (
            _set("env", "dtheta_max_rad", 7.0),
            ("env.dtheta_max_rad", "7 is not in [1.74533e-05, 3.14"),
        ),
        (_set("env", "dtheta_max_rad", 1e-300), ("env.dtheta_max_rad", "1e-300 is not in")),
        (_set("env", "dtheta_max_rad", float("nan")), ("env.dtheta_max_rad", "nan is not in")),
        (_set("env", "dy_max_mm", float("inf")), ("env.dy_max_mm", "inf is not in")),
        (_set("env", "dz_max_mm", "1"), ("env.dz_max_mm", "number")),
        (_set("env", "roll", True), ("env.roll True", "action_dim 3")),
        (_set("env", "roll", "yes"), ("env.roll",)),
        (_set("env", "dphi_max_rad", 0.0), ("env.dphi_max_rad", "0 is not in")),
        (_set("architecture", "action_dim", 5), ("architecture.action_dim", "3")),
        (_set("architecture", "action_dim", 3.0), ("architecture.action_dim",)),
        (_set("architecture", "hidden", [16, 0]), ("architecture.hidden.1", "greater than 0")),
        (_set("architecture", "hidden", []), ("architecture.hidden",)),
        (_set("architecture", "activation", "gelu"), ("architecture.activation",)),
        (_set("format", "scanplan-policy/3"), ("format",)),
        (_set("format", "scanplan-policy/1"), ("scanplan-policy/1", "not read")),
        (_set("weights", "/etc/passwd"), ("weights", "plain file name")),
        (_set("weights", "../policy.safetensors"), ("weights", "plain file name")),
        (_set("weights", "sub/policy.safetensors"), ("weights", "plain file name")),
        (_set("weights", "C:\\policy.safetensors"), ("weights", "plain file name")),
        (_set("weights", ".."), ("weights", "plain file name")),
        (_set("weights", "policy.pt"), ("weights", ".safetensors")),
        (_set("training", "seed", "0"), ("training.seed",)),
        (_set("training", "wall_time_s", -1.0), ("training.wall_time_s",)),
        (lambda d: d["training"].pop("command"), ("training.command", "required")),
        (lambda d: d.pop("env"), ("env", "required")),
        (_set("code", "__import__('os')"), ("code", "Extra inputs")),
        (_set("scan_spec", {"sensor": {}, "scan_spec": {}}), ("scan_spec",)),
        (_set("scan_spec", "default"), ("scan_spec",)),
    ],
)
def test_bad_policy_json_is_one_line_naming_the_field(saved, edit, fragments):
    path, _ = saved
    _edit_json(path, edit)
    _one_line_error(path / "policy.json", *fragments)


@pytest.mark.parametrize(
    ("text", "fragment"),
    [
        ("{not json", "not a valid JSON file"),
        ("", "not a valid JSON file"),
        ("[" * 100_000 + "]" * 100_000, "nested too deeply"),
        ('{"training": {"config": ' + "[" * 50_000 + "]" * 50_000 + "}}", "nested too deeply"),
        ("[1, 2]", "valid dictionary"),
        ("null", "valid dictionary"),
    ],
)
def test_policy_json_that_is_not_json_is_one_line(saved, text, fragment):
    path, _ = saved
    (path / "policy.json").write_text(text)
    _one_line_error(path / "policy.json", fragment)


def test_policy_json_not_utf8_is_one_line(saved):
    path, _ = saved
    (path / "policy.json").write_bytes(b"\xff\xfe{\x00")
    _one_line_error(path / "policy.json", "not a valid JSON file")


def _state(saved):
    path, actor = saved
    return path, {k: v.clone() for k, v in actor.state_dict().items()}


def test_bad_weights_are_one_line_naming_the_file(saved, tmp_path):
    path, state = _state(saved)
    weights = path / "policy.safetensors"
    good = weights.read_bytes()

    def check(*fragments):
        _one_line_error(path, *fragments, named=weights)

    weights.write_bytes(b"")
    check("empty weights file")
    weights.write_text("these are not the tensors you are looking for")
    check("not a safetensors file")
    weights.write_bytes(good[: len(good) // 2])
    check("not a safetensors file")
    weights.write_bytes(good[:5])
    check("not a safetensors file")
    torch.save(state, weights)  # a torch pickle archive, not safetensors
    check("not a safetensors file")
    for _case, bad, fragment in [
        ("missing", {k: v for k, v in state.items() if k != "4.bias"}, "missing tensor '4.bias'"),
        ("extra", state | {"6.weight": torch.zeros(3, 3)}, "unexpected tensor '6.weight'"),
        ("shape", state | {"2.weight": torch.zeros(8, 15)}, "'2.weight' has shape (8, 15)"),
        ("dtype", state | {"0.bias": state["0.bias"].double()}, "'0.bias' is torch.float64"),
        ("nan", state | {"2.bias": torch.full((8,), float("nan"))}, "'2.bias' has non-finite"),
        ("inf", state | {"0.weight": state["0.weight"] / 0.0}, "'0.weight' has non-finite"),
    ]:
        save_file(bad, str(weights))
        check(fragment)
    weights.unlink()
    check("weights file not found")


def test_weights_symlink_outside_the_directory_is_refused(saved, tmp_path):
    path, _ = saved
    outside = tmp_path / "elsewhere.safetensors"
    shutil.move(path / "policy.safetensors", outside)
    (path / "policy.safetensors").symlink_to(outside)
    _one_line_error(path, "points outside", named=path / "policy.safetensors")
    # A link that stays inside the directory is fine.
    (path / "policy.safetensors").unlink()
    shutil.move(outside, path / "real.safetensors")
    (path / "policy.safetensors").symlink_to(path / "real.safetensors")
    assert load_policy(path).meta.weights == "policy.safetensors"


def test_saving_checks_the_tensors_too(tmp_path):
    meta = make_meta()
    state = build_actor(meta.architecture).state_dict()
    state["0.weight"] = torch.zeros(16, 5)
    with pytest.raises(ValueError, match="'0.weight' has shape"):
        save_policy(state, meta, tmp_path)
    assert not (tmp_path / "policy.json").exists()
    with pytest.raises(ValueError, match="env options: env_option_that_does_not_exist"):
        env_options({"env_option_that_does_not_exist": 1})
    # Options not given are recorded with the env's own defaults.
    options = env_options({"fan_points": 64})
    assert options.use_position is True and options.noise is True and options.dy_max_mm is None


def test_shipped_policy_validates():
    policy = load_policy(DEFAULT_POLICY)
    assert policy.meta.training.command.startswith("scanplan train")
    assert policy.meta.architecture.obs_dim == 4 and not policy.meta.env.use_position


@settings(
    max_examples=150, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture]
)
@given(
    value=st.recursive(
        st.none() | st.booleans() | st.integers() | st.floats() | st.text(max_size=8),
        lambda inner: st.lists(inner, max_size=3) | st.dictionaries(st.text(max_size=5), inner),
        max_leaves=8,
    ),
    where=st.sampled_from(
        [
            ("architecture", "obs_dim"),
            ("architecture", "hidden"),
            ("env", "segment_mm"),
            ("env", "dy_max_mm"),
            ("env", "use_position"),
            ("weights",),
            ("training", "final_metrics_last5_updates"),
            ("format",),
        ]
    ),
)
def test_any_bad_value_is_one_line_or_loads(saved, value, where):
    """Whatever a field holds, loading ends in a policy or one clear line."""
    path, _ = saved
    original = (path / "policy.json").read_text()
    try:
        _edit_json(path, _set(*where, value))
        try:
            load_policy(path)
        except ValueError as exc:
            assert "\n" not in str(exc) and str(exc).startswith("policy ")
    finally:
        (path / "policy.json").write_text(original)


# ---- a pickled payload is never executed -------------------------------------------------


def test_the_exploit_is_live(tmp_path):
    """Control: the payload used below does run when unpickled."""
    marker = tmp_path / "control"
    pickle.loads(exploit_pickle(marker))
    assert marker.exists()


def test_loading_reads_no_pickle(monkeypatch, tmp_path):
    """Policy and checkpoint loading with every unpickling entry point booby-trapped."""
    from scanplan.rl.learn.checkpoint import load_checkpoint, save_checkpoint

    path = save_checkpoint(ppo(0), tiny_config(tmp_path), tmp_path)

    def trap(*args, **kwargs):
        raise AssertionError("unpickling attempted")

    for target in (pickle, torch):
        monkeypatch.setattr(target, "load", trap)
        monkeypatch.setattr(target, "loads", trap, raising=False)
    monkeypatch.setattr(pickle, "Unpickler", trap)
    assert load_policy(DEFAULT_POLICY).meta.architecture.obs_dim == 4
    assert load_checkpoint(path).meta.num_timesteps == 0


def test_cli_plan_never_unpickles_a_policy(tmp_path):
    marker = tmp_path / "pwned"
    runner = CliRunner()
    # Old-format directory (policy.pt), and a new-format one whose weights are a pickle.
    old = tmp_path / "old"
    shutil.copytree(DEFAULT_POLICY, old)
    _edit_json(old, lambda d: d.update(format="scanplan-policy/1", weights="policy.pt"))
    (old / "policy.pt").write_bytes(exploit_pickle(marker))
    torch_pickled = tmp_path / "new"
    shutil.copytree(DEFAULT_POLICY, torch_pickled)
    torch.save({"0.weight": Exploit(marker)}, torch_pickled / "policy.safetensors")
    raw = tmp_path / "raw"
    shutil.copytree(DEFAULT_POLICY, raw)
    (raw / "policy.safetensors").write_bytes(exploit_pickle(marker))
    for policy_dir in (old, torch_pickled, raw):
        out = tmp_path / "t.csv"
        result = runner.invoke(
            app,
            [
                "plan",
                "training-piece",
                "--planner",
                "rl",
                "--policy",
                str(policy_dir),
                "-o",
                str(out),
            ],
        )
        assert result.exit_code == 2, result.output
        assert result.stderr.strip().count("\n") == 0 and result.stderr.startswith("error: policy")
        assert not marker.exists()
        assert not out.exists()
