"""Training checkpoints without pickle: `checkpoints/ppo_<steps>.safetensors` holds the policy
and value parameters and the optimizer's state tensors, `ppo_<steps>.json` the rest (step
count, the TrainConfig, optimizer hyperparameters, log std, versions). Resuming rebuilds PPO
from the recorded config as a new run does and loads these into it; SB3's `.zip`
checkpoints are refused, since loading one unpickles whatever its `data` holds.
"""

from __future__ import annotations

import json
import re
from dataclasses import asdict, dataclass, replace
from pathlib import Path
from typing import Any, Literal

import torch
from pydantic import BaseModel, ConfigDict, Field, TypeAdapter, ValidationError

from scanplan.core.files import atomic_write_bytes, atomic_write_text
from scanplan.rl.learn.config import TrainConfig
from scanplan.rl.policy import read_tensors

FORMAT: Literal["scanplan-checkpoint/1"] = "scanplan-checkpoint/1"
CHECKPOINT_DIR = "checkpoints"
_NAME = re.compile(r"ppo_(\d+)\.json")
_POLICY = "policy."
_OPTIM = "optimizer.state."


class _Optimizer(BaseModel):
    model_config = ConfigDict(extra="forbid")

    type: str
    param_groups: list[dict[str, Any]] = Field(min_length=1)
    steps: list[float]  # per parameter, for the reader (the tensors hold them exactly)


class CheckpointMeta(BaseModel):
    """The JSON half of a checkpoint."""

    model_config = ConfigDict(extra="forbid")

    format: Literal["scanplan-checkpoint/1"]
    num_timesteps: int = Field(strict=True, ge=0)
    n_updates: int = Field(strict=True, ge=0)
    config: dict[str, Any]
    optimizer: _Optimizer
    log_std: list[float]
    sb3_version: str
    torch_version: str


@dataclass(frozen=True)
class Checkpoint:
    """A loaded checkpoint: `path` is its JSON; `tensors` are named `policy.<state-dict key>`
    and `optimizer.state.<param index>.<key>`."""

    path: Path
    meta: CheckpointMeta
    tensors: dict[str, torch.Tensor]


def _error(path: Path, what: str) -> ValueError:
    return ValueError(f"checkpoint {path}: {what}")


def _config_record(config: TrainConfig) -> dict[str, Any]:
    data = asdict(config)
    # Only part names can be recorded (and resumed): an in-memory Part is named by its type.
    data["parts"] = [p if isinstance(p, str) else f"<{type(p).__name__}>" for p in config.parts]
    return data


def save_checkpoint(model: Any, config: TrainConfig, run_dir: str | Path) -> Path:
    """Write `run_dir/checkpoints/ppo_<steps>.safetensors` and `.json` for an SB3 PPO model;
    returns the JSON path. The JSON is written last, so a listed checkpoint is complete."""
    import stable_baselines3
    from safetensors.torch import save

    out = Path(run_dir) / CHECKPOINT_DIR
    out.mkdir(parents=True, exist_ok=True)
    stem = f"ppo_{int(model.num_timesteps)}"
    tensors = {
        _POLICY + k: v.detach().cpu().contiguous() for k, v in model.policy.state_dict().items()
    }
    opt = model.policy.optimizer.state_dict()
    steps: list[float] = []
    for index, state in opt["state"].items():
        for key, value in state.items():
            if isinstance(value, torch.Tensor):
                tensors[f"{_OPTIM}{index}.{key}"] = value.detach().cpu().contiguous()
        step = state.get("step", 0)
        steps.append(float(step.item() if isinstance(step, torch.Tensor) else step))
    meta = CheckpointMeta(
        format=FORMAT,
        num_timesteps=int(model.num_timesteps),
        n_updates=int(model._n_updates),
        config=_config_record(config),
        optimizer=_Optimizer(
            type=type(model.policy.optimizer).__name__,
            param_groups=opt["param_groups"],
            steps=steps,
        ),
        log_std=model.policy.log_std.detach().cpu().tolist(),
        sb3_version=stable_baselines3.__version__,
        torch_version=torch.__version__,
    )
    # Serialized here and written by `atomic_write_bytes`: safetensors' own file writer
    # neither reports a full disk reliably nor removes what it half wrote.
    weights = out / f"{stem}.safetensors"
    atomic_write_bytes(weights, save(tensors, metadata={"format": FORMAT}))
    path = out / f"{stem}.json"
    try:
        atomic_write_text(path, meta.model_dump_json(indent=1) + "\n")
    except BaseException:
        weights.unlink(missing_ok=True)  # no weights without the JSON that lists them
        raise
    return path


def latest_checkpoint(run_dir: str | Path) -> Path:
    """The JSON of the newest checkpoint in `run_dir/checkpoints`."""
    ckpt_dir = Path(run_dir) / CHECKPOINT_DIR
    found = [(int(m[1]), p) for p in ckpt_dir.glob("ppo_*.json") if (m := _NAME.fullmatch(p.name))]
    if found:
        return max(found)[1]
    if any(ckpt_dir.glob("*.zip")):
        raise ValueError(
            f"checkpoint {ckpt_dir}: old checkpoint format (SB3 .zip), not loaded: "
            "it would unpickle code"
        )
    raise ValueError(f"cannot resume: no checkpoint in {ckpt_dir}")


def load_checkpoint(path: str | Path) -> Checkpoint:
    """A checkpoint's JSON (validated) and its tensors (safetensors, all finite)."""
    path = Path(path)
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, json.JSONDecodeError, RecursionError) as exc:
        why = "nested too deeply" if isinstance(exc, RecursionError) else str(exc).splitlines()[0]
        raise _error(path, f"not a valid JSON file ({why})") from None
    try:
        meta = CheckpointMeta.model_validate(data)
    except ValidationError as exc:
        err = exc.errors()[0]
        loc = ".".join(str(p) for p in err["loc"])
        raise _error(path, f"{loc}: {err['msg']}") from None
    tensors_path = path.with_suffix(".safetensors")
    if not tensors_path.is_file():
        raise _error(tensors_path, "tensor file not found")
    tensors = read_tensors(tensors_path, what="checkpoint")
    for name, t in tensors.items():
        if not (name.startswith(_POLICY) or name.startswith(_OPTIM)):
            raise _error(tensors_path, f"unexpected tensor {name!r}")
        if t.is_floating_point() and not torch.isfinite(t).all():
            raise _error(tensors_path, f"tensor {name!r} has non-finite values")
    return Checkpoint(path=path, meta=meta, tensors=tensors)


def resumed_config(ckpt: Checkpoint, config: TrainConfig) -> TrainConfig:
    """The recorded config (everything that shapes the model and its envs: parts, seed,
    PPO hyperparameters, net, env options), with this run's output, total timesteps, resume,
    checkpoint interval, progress bar and command."""
    try:
        recorded = TypeAdapter(TrainConfig).validate_python(ckpt.meta.config)
    except ValidationError as exc:
        err = exc.errors()[0]
        loc = ".".join(str(p) for p in err["loc"])
        raise _error(ckpt.path, f"config.{loc}: {err['msg']}") from None
    return replace(
        recorded,
        output_dir=config.output_dir,
        total_timesteps=config.total_timesteps,
        resume=config.resume,
        checkpoint_every_updates=config.checkpoint_every_updates,
        progress_bar=config.progress_bar,
        command=config.command,
    )


def restore(model: Any, ckpt: Checkpoint) -> None:
    """Load the checkpoint into a freshly built PPO `model` of the same config: parameters
    (exact), optimizer state, timestep and update counts."""
    policy_state = {
        k.removeprefix(_POLICY): v for k, v in ckpt.tensors.items() if k.startswith(_POLICY)
    }
    want = model.policy.state_dict()
    tensors_path = ckpt.path.with_suffix(".safetensors")
    for key, value in want.items():
        if key not in policy_state:
            raise _error(tensors_path, f"missing tensor {_POLICY + key!r}")
        if policy_state[key].shape != value.shape:
            raise _error(
                tensors_path,
                f"tensor {_POLICY + key!r} has shape {tuple(policy_state[key].shape)}, "
                f"the model needs {tuple(value.shape)}",
            )
    if extra := sorted(set(policy_state) - set(want)):
        raise _error(tensors_path, f"unexpected tensor {_POLICY + extra[0]!r}")
    model.policy.load_state_dict(policy_state, strict=True)

    optimizer = model.policy.optimizer
    params = [p for group in optimizer.param_groups for p in group["params"]]
    state: dict[int, dict[str, Any]] = {}
    for name, value in ckpt.tensors.items():
        if name.startswith(_OPTIM):
            index, _, key = name.removeprefix(_OPTIM).partition(".")
            if not index.isdigit() or int(index) >= len(params) or not key:
                raise _error(tensors_path, f"unexpected tensor {name!r}")
            if key != "step" and value.shape != params[int(index)].shape:
                raise _error(tensors_path, f"tensor {name!r} does not fit parameter {index}")
            state.setdefault(int(index), {})[key] = value
    groups = [
        {k: tuple(v) if isinstance(v, list) and k != "params" else v for k, v in g.items()}
        for g in ckpt.meta.optimizer.param_groups
    ]
    if type(optimizer).__name__ != ckpt.meta.optimizer.type:
        raise _error(
            ckpt.path,
            f"optimizer {ckpt.meta.optimizer.type}, the model has {type(optimizer).__name__}",
        )
    try:
        optimizer.load_state_dict({"state": state, "param_groups": groups})
    except (ValueError, KeyError, TypeError, RuntimeError) as exc:
        first = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        raise _error(ckpt.path, f"optimizer state does not fit the model ({first})") from None
    model.num_timesteps = ckpt.meta.num_timesteps
    model._n_updates = ckpt.meta.n_updates
