"""The policy file: the actor's weights as safetensors plus `policy.json` (architecture, env
options, training record), written by training and read by the rl planner. Loading validates
the JSON against a schema and the tensors against its architecture, and never unpickles.
"""

from __future__ import annotations

import json
import math
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path, PurePosixPath, PureWindowsPath
from typing import Annotated, Any, Literal

import torch
from pydantic import BaseModel, ConfigDict, Field, StrictStr, ValidationError, field_validator
from pydantic import model_validator as _model_validator
from torch import nn

from scanplan.core.context import scan_spec_from_record
from scanplan.core.files import atomic_write_bytes, atomic_write_text
from scanplan.core.limits import (
    ANGLE_RAD,
    LENGTH_MM,
    MAX_POLICY_PARAMS,
    REWARD_DISTANCE_SCALE_MM,
    STEP_MM,
    check_count,
    in_range,
)
from scanplan.core.quantities import ScanSpec
from scanplan.core.sensor_spec import SensorSpec
from scanplan.planning.observation import observation_size
from scanplan.planning.step_model import DEFAULT_PITCH_PIVOT, check_pitch_pivot
from scanplan.sensor.perturb import Perturbation

FORMAT: Literal["scanplan-policy/2"] = "scanplan-policy/2"
POLICY_JSON = "policy.json"
WEIGHTS = "policy.safetensors"
OUTPUT: Literal["deterministic action = clip(mean, -1, 1)"] = (
    "deterministic action = clip(mean, -1, 1)"
)
OBSERVATION = (
    "SwathScanEnv observation (see scanplan.rl.env docstring): normalized P (if use_position), "
    "theta, D, alpha, delta-s (+ look-ahead if lookahead)"
)
MAX_POLICY_JSON_BYTES = 16 * 1024**2
StrictBool = Annotated[bool, Field(strict=True)]
PositiveInt = Annotated[int, Field(strict=True, gt=0)]
Finite = Annotated[float, Field(strict=True, allow_inf_nan=False)]
Positive = Annotated[float, Field(strict=True, gt=0, allow_inf_nan=False)]
Length = Annotated[float, Field(strict=True), in_range(LENGTH_MM)]
StepMm = Annotated[float, Field(strict=True), in_range(STEP_MM)]
StepRad = Annotated[float, Field(strict=True), in_range(ANGLE_RAD)]


class _Model(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True)


class Architecture(_Model):
    """The actor MLP: obs_dim -> hidden Linear+activation layers -> action_dim (the mean)."""

    type: Literal["mlp"] = "mlp"
    obs_dim: PositiveInt
    hidden: tuple[PositiveInt, ...] = Field(min_length=1)
    activation: Literal["relu", "tanh"]
    action_dim: Annotated[int, Field(strict=True)]
    output: Literal["deterministic action = clip(mean, -1, 1)"] = OUTPUT

    @field_validator("action_dim")
    @classmethod
    def _v0_or_v1(cls, v: int) -> int:
        if v not in (3, 4):
            raise ValueError(f"must be 3 (Δy, Δz, Δθ) or 4 (v1: + Δφ), got {v}")
        return v

    @_model_validator(mode="after")
    def _bounded(self) -> Architecture:
        # Before any weight is read or a layer allocated: hidden = [1e9, 1e9] is 4 EB.
        count = sum(math.prod(shape) for shape in self.tensor_shapes().values())
        check_count(count, MAX_POLICY_PARAMS, "the architecture's parameters")
        return self

    def tensor_shapes(self) -> dict[str, tuple[int, ...]]:
        """Names and shapes of the `nn.Sequential` state dict that `build_actor` makes."""
        sizes = [self.obs_dim, *self.hidden, self.action_dim]
        shapes: dict[str, tuple[int, ...]] = {}
        for i, (a, b) in enumerate(zip(sizes[:-1], sizes[1:], strict=True)):
            shapes[f"{2 * i}.weight"] = (b, a)
            shapes[f"{2 * i}.bias"] = (b,)
        return shapes


class EnvOptions(_Model):
    """The `SwathScanEnv` options the policy was trained with. The action limits are None
    when training used the env's defaults (planning then uses them too)."""

    use_position: StrictBool
    lookahead: StrictBool
    fan_points: Annotated[int, Field(strict=True, ge=2, le=SensorSpec.MAX_POINTS)]
    noise: StrictBool
    segment_mm: tuple[Length, Length] | None
    procedural_parts: Annotated[int, Field(strict=True, ge=0, le=1000)]
    dy_max_mm: StepMm | None = None
    dz_max_mm: StepMm | None = None
    dtheta_max_rad: StepRad | None = None
    dphi_max_rad: StepRad | None = None
    roll: StrictBool = False
    # Training only (random start offsets, beyond the paper); planning starts aligned.
    start_offset_mm: Annotated[float, Field(ge=0, lt=1e4, allow_inf_nan=False)] = 0.0
    start_pitch_deg: Annotated[float, Field(ge=0, le=60, allow_inf_nan=False)] = 0.0
    # Training only (R_D's scale, a deviation from the paper's Z_r/2); None = the paper's.
    reward_distance_scale_mm: (
        Annotated[float, Field(strict=True), in_range(REWARD_DISTANCE_SCALE_MM)] | None
    ) = None
    # Where a pitch step turns (step_model.PITCH_PIVOTS): planning steps the same way.
    pitch_pivot: StrictStr = DEFAULT_PITCH_PIVOT
    # Training only (the perturbation each episode was drawn from, a `Perturbation` spec).
    perturb: StrictStr | None = None

    @field_validator("segment_mm")
    @classmethod
    def _ordered(cls, v: tuple[float, float] | None) -> tuple[float, float] | None:
        if v is not None and v[0] > v[1]:
            raise ValueError(f"[lo, hi] needs lo <= hi, got {list(v)}")
        return v

    @field_validator("perturb")
    @classmethod
    def _known_perturbation(cls, v: str | None) -> str | None:
        if v is not None:
            Perturbation.parse(v)
        return v

    @field_validator("pitch_pivot")
    @classmethod
    def _known_pivot(cls, v: str) -> str:
        return check_pitch_pivot(v)

    def env_kwargs(self) -> dict[str, Any]:
        """The options as `SwathScanEnv` keyword arguments (limits left out when None)."""
        return self.model_dump(exclude_none=True)


def _finite_or_none(v: Any) -> Any:
    """NaN/inf (e.g. no episode finished yet) is recorded as null: JSON has no NaN."""
    return None if isinstance(v, float) and not math.isfinite(v) else v


class TrainingRecord(_Model):
    """How the policy was made: the `scanplan train` command line, seed, timesteps, wall
    time, the final metrics (mean of the last updates) and the full training config."""

    command: str
    seed: Annotated[int, Field(strict=True)]
    timesteps: Annotated[int, Field(strict=True, ge=0)]
    wall_time_s: Annotated[float, Field(strict=True, ge=0, allow_inf_nan=False)]
    final_metrics_last5_updates: dict[str, Finite | None]
    behaviour_cloning_mse: Finite | None = None
    config: dict[str, Any] = Field(default_factory=dict)
    machine_cores: PositiveInt | None = None

    @field_validator("final_metrics_last5_updates", mode="before")
    @classmethod
    def _metrics_nan(cls, v: Any) -> Any:
        return {k: _finite_or_none(x) for k, x in v.items()} if isinstance(v, dict) else v

    @field_validator("behaviour_cloning_mse", mode="before")
    @classmethod
    def _mse_nan(cls, v: Any) -> Any:
        return _finite_or_none(v)


class PolicyMeta(_Model):
    """The schema of policy.json."""

    format: Literal["scanplan-policy/2"]
    weights: str = WEIGHTS
    architecture: Architecture
    observation: str = OBSERVATION
    env: EnvOptions
    training: TrainingRecord
    # The ScanSpec it was trained under (`context.scan_spec_record`): its Z range, α_max and
    # Δs_opt normalize the observation. Files written before it was recorded were all trained
    # with the default sensor and parameters (training has no sensor option).
    scan_spec: dict[str, Any] | None = None

    @property
    def trained_spec(self) -> ScanSpec:
        if self.scan_spec is None:
            return ScanSpec()
        return scan_spec_from_record(self.scan_spec, "scan_spec")

    @field_validator("weights")
    @classmethod
    def _plain_file_name(cls, v: str) -> str:
        # A plain name inside the policy directory: the JSON must not point anywhere else.
        if (
            not v
            or v in (".", "..")
            or PurePosixPath(v).is_absolute()
            or PureWindowsPath(v).is_absolute()
            or any(c in v for c in "/\\\0:")
        ):
            raise ValueError(f"must be a plain file name in the policy directory, got {v!r}")
        if not v.endswith(".safetensors"):
            raise ValueError(f"must be a .safetensors file, got {v!r}")
        return v

    @_model_validator(mode="after")
    def _consistent(self) -> PolicyMeta:
        arch, env = self.architecture, self.env
        n = observation_size(env.use_position, env.lookahead, roll=arch.action_dim == 4)
        if env.roll != (arch.action_dim == 4):
            raise ValueError(
                f"env.roll {env.roll} does not match architecture.action_dim "
                f"{arch.action_dim} (a roll-capable v1 policy has 4 actions)"
            )
        if arch.obs_dim != n:
            raise ValueError(
                f"architecture.obs_dim {arch.obs_dim} does not match the env options "
                f"(use_position={env.use_position}, lookahead={env.lookahead}, "
                f"action_dim={arch.action_dim} give {n})"
            )
        self.trained_spec  # noqa: B018 - validates the record (ValueError names the field)
        return self


@dataclass(frozen=True)
class Policy:
    """A loaded policy: the deterministic actor (eval mode, mean action) and its metadata."""

    actor: nn.Sequential
    meta: PolicyMeta


def build_actor(arch: Architecture | Mapping[str, Any]) -> nn.Sequential:
    """The MLP of `architecture` in policy.json: Linear/activation pairs, then the head."""
    if not isinstance(arch, Architecture):
        arch = Architecture.model_validate(dict(arch))
    act = {"relu": nn.ReLU, "tanh": nn.Tanh}[arch.activation]
    sizes = [arch.obs_dim, *arch.hidden]
    layers: list[nn.Module] = []
    for a, b in zip(sizes[:-1], sizes[1:], strict=True):
        layers += [nn.Linear(a, b), act()]
    layers.append(nn.Linear(sizes[-1], arch.action_dim))
    return nn.Sequential(*layers)


def first_error(exc: ValidationError) -> str:
    """One line: the field's dotted location and what is wrong with it."""
    err = exc.errors()[0]
    loc = ".".join(str(p) for p in err["loc"])
    msg = str(err["msg"]).removeprefix("Value error, ")
    return f"{loc}: {msg}" if loc else msg


def tensor_problem(state: Mapping[str, torch.Tensor], arch: Architecture) -> str | None:
    """What keeps `state` from being exactly the weights of `arch`, or None."""
    want = arch.tensor_shapes()
    if missing := [k for k in want if k not in state]:
        return f"missing tensor {missing[0]!r}"
    if extra := [k for k in state if k not in want]:
        return f"unexpected tensor {extra[0]!r}"
    for name, shape in want.items():
        t = state[name]
        if tuple(t.shape) != shape:
            return f"tensor {name!r} has shape {tuple(t.shape)}, the architecture needs {shape}"
        if t.dtype != torch.float32:
            return f"tensor {name!r} is {t.dtype}, expected torch.float32"
        if not torch.isfinite(t).all():
            return f"tensor {name!r} has non-finite values"
    return None


def _weights_path(directory: Path, name: str) -> Path:
    path = directory / name
    if path.is_symlink() and not path.resolve().is_relative_to(directory.resolve()):
        raise ValueError(f"policy {path}: weights symlink points outside the policy directory")
    if not path.is_file():
        raise ValueError(f"policy {path}: weights file not found")
    return path


def read_tensors(path: Path, what: str = "policy") -> dict[str, torch.Tensor]:
    """A safetensors file's tensors, or `ValueError(f"{what} {path}: ...")`."""
    from safetensors import SafetensorError
    from safetensors.torch import load

    try:
        data = path.read_bytes()
    except OSError as exc:
        raise ValueError(f"{what} {path}: cannot be read ({exc.strerror})") from None
    if not data:
        raise ValueError(f"{what} {path}: empty weights file")
    try:
        return load(data)
    except (SafetensorError, ValueError, RuntimeError, OverflowError) as exc:
        first = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        raise ValueError(f"{what} {path}: not a safetensors file ({first})") from None


def read_meta(path: str | Path) -> tuple[Path, PolicyMeta]:
    """policy.json (of a policy directory, or the file itself), validated: (its path, meta)."""
    path = Path(path)
    json_path = path / POLICY_JSON if path.is_dir() else path
    if not json_path.is_file():
        raise ValueError(f"policy {path}: no policy.json found")
    if json_path.stat().st_size > MAX_POLICY_JSON_BYTES:
        raise ValueError(f"policy {json_path}: larger than 16 MiB, not a policy's description")
    try:
        data = json.loads(json_path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, json.JSONDecodeError, RecursionError) as exc:
        why = "nested too deeply" if isinstance(exc, RecursionError) else str(exc).splitlines()[0]
        raise ValueError(f"policy {json_path}: not a valid JSON file ({why})") from None
    if isinstance(data, dict) and data.get("format") == "scanplan-policy/1":
        raise ValueError(
            f"policy {json_path}: format scanplan-policy/1 (pickle-era .pt weights) is not "
            f"read; convert it to {FORMAT} with safetensors weights"
        )
    try:
        return json_path, PolicyMeta.model_validate(data)
    except ValidationError as exc:
        raise ValueError(f"policy {json_path}: {first_error(exc)}") from None
    except RecursionError:
        raise ValueError(f"policy {json_path}: nested too deeply") from None


def load_policy(path: str | Path) -> Policy:
    """A policy directory or its policy.json: validated metadata and the actor with its
    weights (safetensors only: no pickle is read). Any problem is one-line ValueError."""
    json_path, meta = read_meta(path)
    weights = _weights_path(json_path.parent, meta.weights)
    # The architecture fixes the weights' size: a larger file is not its weights (and is not
    # read whole); the safetensors header is small.
    params = sum(math.prod(shape) for shape in meta.architecture.tensor_shapes().values())
    if weights.stat().st_size > 4 * params + 1024**2:
        raise ValueError(
            f"policy {weights}: {weights.stat().st_size:,} bytes, more than the "
            f"architecture's {params:,} float32 weights take"
        )
    state = read_tensors(weights)
    if problem := tensor_problem(state, meta.architecture):
        raise ValueError(f"policy {weights}: {problem}")
    actor = build_actor(meta.architecture)
    actor.load_state_dict(state)
    actor.eval()
    return Policy(actor=actor, meta=meta)


def save_policy(
    actor_state: Mapping[str, torch.Tensor], meta: PolicyMeta, out_dir: str | Path
) -> Path:
    """Write the actor's weights (`meta.weights`, safetensors) and policy.json into `out_dir`
    after the same checks as loading; returns the JSON path."""
    from safetensors.torch import save

    out = Path(out_dir)
    state = {k: v.detach().cpu().contiguous() for k, v in actor_state.items()}
    if problem := tensor_problem(state, meta.architecture):
        raise ValueError(f"policy {out / meta.weights}: {problem}")
    # Serialized here, written whole by `atomic_write_bytes` (safetensors' file writer does
    # not report a full disk reliably).
    atomic_write_bytes(out / meta.weights, save(state, metadata={"format": FORMAT}))
    path = out / POLICY_JSON
    atomic_write_text(path, meta.model_dump_json(indent=1) + "\n")
    return path
