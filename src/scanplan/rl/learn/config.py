"""The training configuration: one typed object that `scanplan train` builds and
`learn.train.train` runs; checkpoints record it and resuming validates it back.
"""

from __future__ import annotations

import inspect
import typing
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

from pydantic import TypeAdapter, ValidationError

from scanplan.core.limits import (
    ACTION,
    CLIP_RANGE,
    DISCOUNT,
    LEARNING_RATE,
    LOG_STD,
    MAX_BC_SAMPLES,
    MAX_SEED,
    MAX_TIMESTEPS,
    REWARD_DISTANCE_SCALE_MM,
)
from scanplan.core.quantities import TRAINING_FAN_POINTS
from scanplan.planning.step_model import DEFAULT_PITCH_PIVOT, check_pitch_pivot
from scanplan.rl.env import TRAINING_SEGMENT_MM, SwathScanEnv, training_perturbation
from scanplan.rl.policy import EnvOptions, first_error

VEC_ENVS = ("batched", "subproc")
ACTIVATIONS = ("relu", "tanh")
MAX_ENVS = 1024
MAX_WIDTH = 4096  # units of a hidden layer
# --start-offset bounds: within the depth window (Z_r/2 = 125 mm for the default sensor) and
# SwathScanEnv's own pitch bound.
MAX_START_OFFSET_MM = 1000.0
MAX_START_PITCH_DEG = 60.0


@dataclass
class TrainConfig:
    """Everything a training run needs. PPO fields keep stable-baselines3's names; their
    defaults are the paper's table. SB3's `n_steps` counts steps per env: 16 batched envs x
    128 = the paper's update every 2048 steps. `env` holds `SwathScanEnv` keyword arguments,
    except that the step limits are given as numbers (`dy_max_mm`, `dz_max_mm`,
    `dtheta_max_rad`, as in policy.json) and `procedural_parts` is drawn once per run."""

    output_dir: str = "policy"
    parts: tuple[str, ...] = ("training-piece",)
    total_timesteps: int = 1_000_000  # PPO steps; 0 with bc_samples > 0: behaviour cloning only
    seed: int = 0
    n_envs: int = 16
    vec_env: str = "batched"
    learning_rate: float = 3e-4
    n_steps: int = 128
    batch_size: int = 64
    gamma: float = 0.99
    clip_range: float = 0.2
    n_epochs: int = 10
    net_arch: tuple[int, ...] = (64, 64)
    activation: str = "relu"
    log_std_init: float | tuple[float, ...] = 0.0  # one per action: (Δy, Δz, Δθ[, Δφ])
    init_advance: float | None = None  # initial mean Δy action (0.5 = Δs_opt at Δy_max 1 mm)
    bc_samples: int = 0  # > 0: behaviour-clone the feedback controller on this many states first
    env: dict[str, Any] = field(
        default_factory=lambda: {
            "fan_points": TRAINING_FAN_POINTS,
            "noise": False,  # µm-scale noise does not move mm-scale D, α, Δs; 20 % faster
            "use_position": True,
            "lookahead": False,
            "segment_mm": TRAINING_SEGMENT_MM,
            "procedural_parts": 0,
        }
    )
    checkpoint_every_updates: int = 10
    resume: str | None = None
    progress_bar: bool = True
    command: str = ""

    def __post_init__(self) -> None:
        positive = {
            "n_envs": self.n_envs,
            "n_steps": self.n_steps,
            "batch_size": self.batch_size,
            "n_epochs": self.n_epochs,
            "checkpoint_every_updates": self.checkpoint_every_updates,
        }
        for name, value in positive.items():
            if value < 1:
                raise ValueError(f"training config: {name} must be >= 1, got {value}")
        if not 0 <= self.total_timesteps <= MAX_TIMESTEPS:
            raise ValueError(
                f"training config: total_timesteps {self.total_timesteps} is not in "
                f"[0, {MAX_TIMESTEPS}]"
            )
        if not 0 <= self.seed <= MAX_SEED:
            raise ValueError(f"training config: seed {self.seed} is not in [0, {MAX_SEED}]")
        if self.n_envs > MAX_ENVS:
            raise ValueError(f"training config: n_envs {self.n_envs} is more than {MAX_ENVS}")
        DISCOUNT.check(self.gamma, "training config: gamma")
        CLIP_RANGE.check(self.clip_range, "training config: clip_range")
        if not (self.net_arch and all(0 < n <= MAX_WIDTH for n in self.net_arch)):
            raise ValueError(
                f"training config: net_arch {list(self.net_arch)}: layers of 1 to {MAX_WIDTH}"
            )
        stds = self.log_std_init if isinstance(self.log_std_init, tuple) else (self.log_std_init,)
        for std in stds:
            LOG_STD.check(std, "training config: log_std_init")
        if self.init_advance is not None:
            ACTION.check(self.init_advance, "training config: init_advance")
        if self.total_timesteps == 0 and self.bc_samples == 0:
            raise ValueError(
                "training config: 0 timesteps and no behaviour cloning: nothing to train"
            )
        if self.vec_env not in VEC_ENVS:
            raise ValueError(f"training config: vec_env {self.vec_env!r}, use one of {VEC_ENVS}")
        if self.activation not in ACTIVATIONS:
            raise ValueError(
                f"training config: activation {self.activation!r}, use one of {ACTIVATIONS}"
            )
        LEARNING_RATE.check(self.learning_rate, "training config: learning_rate")
        if not 0 <= self.bc_samples <= MAX_BC_SAMPLES:
            raise ValueError(
                f"training config: bc_samples {self.bc_samples} is not in [0, {MAX_BC_SAMPLES}]"
            )
        if self.bc_samples > 0 and self.vec_env != "batched":
            raise ValueError("training config: behaviour cloning needs vec_env 'batched'")


def typed_field(name: str, value: Any) -> Any:
    """`value` as TrainConfig's field `name` is typed (e.g. a sweep grid's JSON value), or a
    ValueError naming the field; ranges are checked when the config is made."""
    hints = typing.get_type_hints(TrainConfig)
    if name not in hints:
        raise ValueError(f"{name!r} is no training config field")
    try:
        return TypeAdapter(hints[name]).validate_python(value)
    except ValidationError as exc:
        raise ValueError(f"{name} {value!r}: {exc.errors()[0]['msg']}") from None


# `scanplan train --state`: (use_position, lookahead)
STATES = {
    "paper": (True, False),
    "no-position": (False, False),
    "lookahead": (False, True),
    "lookahead-position": (True, True),
}
ENV_VERSIONS = ("v0", "v1")


def recipe_config(
    output_dir: str,
    *,
    parts: tuple[str, ...] = ("training-piece",),
    timesteps: int = 1_000_000,
    seed: int = 0,
    n_envs: int = 16,
    vec_env: str = "batched",
    state: str = "paper",
    env_version: str = "v0",
    procedural: int = 0,
    fan_points: int | None = None,
    log_std_init: tuple[float, ...] = (0.0,),
    init_advance: float | None = None,
    start_offset: tuple[float, ...] = (0.0, 0.0),
    reward_distance_scale: float | None = None,
    pitch_pivot: str | None = None,
    bc_samples: int = 0,
    perturb: str | None = None,
    noise: bool = False,
    resume: str | None = None,
    progress_bar: bool = True,
    command: str = "",
) -> TrainConfig:
    """The config of `scanplan train` with these options (the CLI and `learn.sweep` both
    build theirs here, so a sweep's row is exactly the command it records)."""
    if state not in STATES:
        raise ValueError(f"unknown --state {state!r}; use one of {', '.join(STATES)}")
    if env_version not in ENV_VERSIONS:
        raise ValueError(f"unknown --env {env_version!r}; use v0 or v1")
    roll = env_version == "v1"
    if len(log_std_init) not in (1, 4 if roll else 3):
        raise ValueError(
            "--log-std-init takes one value or one per action (Δy,Δz,Δθ[,Δφ with --env v1])"
        )
    for std in log_std_init:
        LOG_STD.check(std, "--log-std-init")
    if len(start_offset) != 2:
        raise ValueError("--start-offset takes two values: MM,DEG (depth and pitch)")
    offset_mm, offset_deg = start_offset
    if not (0 <= offset_mm <= MAX_START_OFFSET_MM and 0 <= offset_deg <= MAX_START_PITCH_DEG):
        raise ValueError(
            f"--start-offset {offset_mm:g},{offset_deg:g}: depth in [0, {MAX_START_OFFSET_MM:g}]"
            f" mm and pitch in [0, {MAX_START_PITCH_DEG:g}]°"
        )
    if roll and (offset_mm or offset_deg):
        raise ValueError("--start-offset is for --env v0 only")
    # Recorded only when set: runs without it keep the env options they always had.
    start = (
        {"start_offset_mm": float(offset_mm), "start_pitch_deg": float(offset_deg)}
        if offset_mm or offset_deg
        else {}
    )
    if reward_distance_scale is not None:
        REWARD_DISTANCE_SCALE_MM.check(reward_distance_scale, "--reward-distance-scale")
    # Recorded only when set, as the start offsets.
    scale = (
        {"reward_distance_scale_mm": float(reward_distance_scale)}
        if reward_distance_scale is not None
        else {}
    )
    pitch_pivot = check_pitch_pivot(pitch_pivot or DEFAULT_PITCH_PIVOT, roll, "--pitch-pivot")
    # Recorded only when set, as the start offsets.
    pivot = {"pitch_pivot": pitch_pivot} if pitch_pivot != DEFAULT_PITCH_PIVOT else {}
    # Recorded only when set, in its canonical form, as the start offsets.
    model = training_perturbation(perturb)
    perturbed = {"perturb": model.text()} if model is not None else {}
    use_position, lookahead = STATES[state]
    return TrainConfig(
        output_dir=output_dir,
        parts=tuple(parts),
        total_timesteps=timesteps,
        seed=seed,
        n_envs=n_envs,
        vec_env=vec_env,
        n_steps=max(2048 // max(n_envs, 1), 8),  # the paper: an update every 2048 steps
        log_std_init=log_std_init[0] if len(log_std_init) == 1 else tuple(log_std_init),
        init_advance=init_advance,
        bc_samples=bc_samples,
        env={
            "fan_points": TRAINING_FAN_POINTS if fan_points is None else fan_points,
            "noise": noise,
            "use_position": use_position,
            "lookahead": lookahead,
            "segment_mm": TRAINING_SEGMENT_MM,
            "procedural_parts": procedural,
            "roll": roll,
            **start,
            **scale,
            **pivot,
            **perturbed,
        },
        resume=resume,
        progress_bar=progress_bar,
        command=command,
    )


def env_options(kwargs: Mapping[str, Any]) -> EnvOptions:
    """The policy file's record of `SwathScanEnv` keyword arguments; an option not given is
    recorded with the env's own default (read from its signature, so no default is declared
    twice)."""
    params = inspect.signature(SwathScanEnv.__init__).parameters
    required = [k for k, f in EnvOptions.model_fields.items() if f.is_required()]
    data = {k: params[k].default for k in required if k in params} | dict(kwargs)
    if data.get("segment_mm") is not None:
        data["segment_mm"] = tuple(data["segment_mm"])
    try:
        return EnvOptions.model_validate(data)
    except ValidationError as exc:
        raise ValueError(f"env options: {first_error(exc)}") from None
