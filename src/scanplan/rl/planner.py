"""The `rl` planner (SPEC §4): a trained PPO actor run pass by pass, deterministic actions.

A policy is a directory (or its `policy.json`) read by `scanplan.rl.policy.load_policy`:
safetensors weights and validated JSON, so loading a policy never unpickles code. The
packaged default lives in `scanplan/policies/default/`.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import torch
from torch import nn

from scanplan.core.quantities import PLANNING_FAN_POINTS, ScanSpec, StepLimits
from scanplan.core.trajectory import Trajectory
from scanplan.planning.dynamics import PassDynamics
from scanplan.planning.observation import observe
from scanplan.planning.planners.closed_loop import (
    Controller,
    Guards,
    PoseGuard,
    SensorFactory,
    drive_passes,
)
from scanplan.planning.step_model import DEFAULT_PITCH_PIVOT
from scanplan.planning.swaths import Swath
from scanplan.rl.policy import load_policy
from scanplan.world.part import Part

_SHIPPED = Path(__file__).resolve().parent.parent / "policies"
DEFAULT_POLICY = _SHIPPED / "default"
# Policies that ship with the package, by name: `--policy v1` (a path of that name wins);
# `paper` is pure PPO from scratch (issue 22), the others are warm-started.
SHIPPED_POLICIES = {"default": DEFAULT_POLICY, "v1": _SHIPPED / "v1", "paper": _SHIPPED / "paper"}
# Step limits a planning run takes from the policy file's env options.
_LIMIT_KEYS = ("dy_max_mm", "dz_max_mm", "dtheta_max_rad", "dphi_max_rad")
# The most a planning sensor's working distance may differ from the policy's, as a share.
MAX_WORKING_DISTANCE_CHANGE = 0.1


@dataclass
class RLPlanner:
    """The deterministic actor in the loop of `closed_loop.drive_passes` on each swath
    (noiseless sensor): the observation is the env's (`observation.observe`, with the options the
    policy was trained with), every station of the pass becomes a scanning pose.

    fan_points: columns of the planning sensor (`closed_loop.PLANNING_FAN_POINTS`).
    guards: the stall and forward-only guards (`closed_loop.Guards`).
    trained_spec: the ScanSpec the policy was trained under: its Z range, α_max and Δs_opt
    normalize the observation, and a sensor it never saw is refused (`check_sensor`).
    """

    actor: nn.Sequential
    config: dict[str, Any] = field(default_factory=dict)
    trained_spec: ScanSpec = field(default_factory=ScanSpec)
    source: str = "the policy"
    fan_points: int = PLANNING_FAN_POINTS
    guards: Guards = field(default_factory=Guards)
    name: str = "rl"
    measure_with: SensorFactory | None = None  # `closed_loop.SensorFactory`
    arm_guard: PoseGuard | None = None  # a fitted plan's arm (`closed_loop.PoseGuard`)

    @classmethod
    def from_file(cls, path: str | Path | None = None) -> RLPlanner:
        """A policy directory or its policy.json, or the name of a shipped policy
        (`SHIPPED_POLICIES`); None = the packaged default (v0) policy."""
        if path is None:
            path = DEFAULT_POLICY
        elif str(path) in SHIPPED_POLICIES and not Path(path).exists():
            path = SHIPPED_POLICIES[str(path)]
        policy = load_policy(path)
        # `config` is policy.json as a dict; env holds only the options it sets, as
        # `SwathScanEnv` keyword arguments.
        config = policy.meta.model_dump(mode="json")
        config["env"] = policy.meta.env.env_kwargs()
        return cls(policy.actor, config, policy.meta.trained_spec, f"policy {path}")

    @classmethod
    def default(cls) -> RLPlanner:
        return cls.from_file(None)

    def act(self, obs: np.ndarray) -> np.ndarray:
        """Deterministic action in [-1, 1]^3 for one observation."""
        with torch.no_grad():
            out = self.actor(torch.as_tensor(obs, dtype=torch.float32)[None])[0].numpy()
        return np.clip(out, -1.0, 1.0)

    @property
    def roll(self) -> bool:
        """A v1 policy (4-D actions) rolls the line."""
        return int(self.config.get("architecture", {}).get("action_dim", 3)) == 4

    @property
    def limits(self) -> StepLimits:
        """The step limits the policy was trained with (policy.json `env`), else the defaults."""
        env_cfg = self.config.get("env", {})
        return StepLimits(**{k: env_cfg[k] for k in _LIMIT_KEYS if k in env_cfg})

    def plan(self, part: Part, swath: Swath, spec: ScanSpec) -> Trajectory:
        return self.plan_passes(part, [swath], spec)[0]

    def check_sensor(self, spec: ScanSpec) -> None:
        """Refuse (ValueError, one line) a sensor whose depth window reaches beyond the one
        the policy was trained on (its depth error would leave the observed range), or whose
        working distance differs by more than `MAX_WORKING_DISTANCE_CHANGE` (a pitch step
        swings the footprint by W_d·Δθ: the dynamics it learned change with W_d)."""
        trained, given = self.trained_spec.sensor, spec.sensor
        if given.z_range_mm > trained.z_range_mm * (1 + 1e-9):
            raise ValueError(
                f"{self.source} was trained with a Z range of {trained.z_range_mm:g} mm; sensor "
                f"{given.name} has {given.z_range_mm:g} mm: its depth error would reach outside "
                "what the policy observed (use a policy trained for it, or --planner geometric)"
            )
        change = abs(given.working_distance_mm / trained.working_distance_mm - 1.0)
        if change > MAX_WORKING_DISTANCE_CHANGE:
            raise ValueError(
                f"{self.source} was trained at a working distance of "
                f"{trained.working_distance_mm:g} mm; sensor {given.name} works at "
                f"{given.working_distance_mm:g} mm (use a policy trained for it, or "
                "--planner geometric)"
            )

    def plan_passes(self, part: Part, swaths: list[Swath], spec: ScanSpec) -> list[Trajectory]:
        """Every pass at once, in lockstep (`closed_loop.drive_passes`)."""
        self.check_sensor(spec)
        return drive_passes(
            part,
            swaths,
            spec,
            self.controller(),
            self.name,
            limits=self.limits,
            fan_points=self.fan_points,
            guards=self.guards,
            roll=self.roll,
            measure_with=self.measure_with,
            arm=self.arm_guard,
            pitch_pivot=self.pitch_pivot,
        )

    @property
    def pitch_pivot(self) -> str:
        """Where the policy's pitch steps turn (policy.json `env`; trained so)."""
        return str(self.config.get("env", {}).get("pitch_pivot", DEFAULT_PITCH_PIVOT))

    def controller(self) -> Controller:
        """The policy as a `closed_loop.Controller`: the observation the env gives
        (`observation.observe`, with the options and the scale it was trained with) to the
        deterministic actor."""
        env_cfg = self.config.get("env", {})
        use_position = bool(env_cfg.get("use_position", True))
        lookahead = bool(env_cfg.get("lookahead", False))
        scale = self.trained_spec

        def policy(dyn: PassDynamics, start_state: np.ndarray) -> np.ndarray:
            return self.act(observe(dyn, start_state, use_position, lookahead, scale))

        return policy
