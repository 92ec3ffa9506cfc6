"""The `rl` planner (SPEC §4): a trained PPO actor run pass by pass, deterministic actions.

A policy is a directory (or its `policy.json`) read by `scanplan.policy.load_policy`:
safetensors weights and validated JSON, so loading a policy never unpickles code. The
packaged default lives in `scanplan/policies/default/`.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import torch
from torch import nn

from scanplan.part import Part
from scanplan.policy import load_policy
from scanplan.sensor import SensorSpec
from scanplan.swaths import Swath
from scanplan.trajectory import Trajectory

DEFAULT_POLICY = Path(__file__).resolve().parent.parent / "policies" / "default"
# Env options a planning run takes from the policy file; the rest is fixed for planning.
_ENV_KEYS = ("use_position", "lookahead", "dy_max_mm", "dz_max_mm", "dtheta_max_rad")


@dataclass
class RLPlanner:
    """Runs `SwathScanEnv` dynamics on each swath (noise-free sensor) with the deterministic
    actor; every station of the episode becomes a scanning pose.

    fan_points: columns of the planning sensor. More than training's 128: on narrow curved
    parts (the drone) 128 columns put D off by ~1 mm; 512 agree with the full fan to ~0.2 mm.
    stall_window: stall guard. Out of its training range (e.g. pitched > 30° on a curling
    sheet edge) a policy can pitch on while Δy only cancels the footprint's backward swing,
    and the pass stalls until truncation. If the scan advanced less than a quarter spacing
    per step over the last `stall_window` steps, that step holds the pitch and advances by
    Δs_opt (counted in `Trajectory.meta["stall_overrides"]`); 0 switches it off.
    min_advance: forward-only guard. A fast backward pitch swings the footprint back by
    ~W_d·Δθ (7 mm per degree), more than Δy can make up, and the scan re-measures what it
    has already measured (a backward step). Each step's profile is measured before it is
    accepted; if it advanced less than `min_advance` × Δs_opt over the previous one, the
    step is replaced by: hold the pitch, advance Δs_opt (counted in
    `Trajectory.meta["backward_overrides"]`); None switches it off. Costs nothing when the
    policy's step is accepted (its profile is the one the episode goes on with).
    """

    actor: nn.Sequential
    config: dict[str, Any] = field(default_factory=dict)
    fan_points: int = 512
    stall_window: int = 20
    min_advance: float | None = 0.25
    name: str = "rl"

    @classmethod
    def from_file(cls, path: str | Path | None = None) -> RLPlanner:
        """A policy directory or its policy.json; None = the packaged default policy."""
        policy = load_policy(path if path is not None else DEFAULT_POLICY)
        # `config` is policy.json as a dict; env holds only the options it sets, as
        # `SwathScanEnv` keyword arguments.
        config = policy.meta.model_dump(mode="json")
        config["env"] = policy.meta.env.env_kwargs()
        return cls(actor=policy.actor, config=config)

    @classmethod
    def default(cls) -> RLPlanner:
        return cls.from_file(None)

    def act(self, obs: np.ndarray) -> np.ndarray:
        """Deterministic action in [-1, 1]^3 for one observation."""
        with torch.no_grad():
            out = self.actor(torch.as_tensor(obs, dtype=torch.float32)[None])[0].numpy()
        return np.clip(out, -1.0, 1.0)

    def make_env(self, part: Part, swath: Swath, sensor: SensorSpec):
        from scanplan.env import SwathScanEnv

        env_cfg = self.config.get("env", {})
        kwargs = {k: env_cfg[k] for k in _ENV_KEYS if k in env_cfg}
        return SwathScanEnv(
            parts=[part],
            swaths=[swath],
            sensor=sensor,
            noise=False,
            fan_points=self.fan_points,
            segment_mm=None,
            lost_patience=None,
            **kwargs,
        )

    def _went_back(self, env: Any, profile: Any, ds_opt: float) -> bool:
        """Did `profile` advance less than min_advance·Δs_opt over the episode's last one?
        (Unknown — no column valid in both — counts as not.)"""
        from scanplan.quantities import advance

        prev = env.profile
        ds = advance(prev.points_part, prev.valid, profile.points_part, profile.valid, env.swath.u)
        assert self.min_advance is not None
        return bool(np.isfinite(ds) and ds < self.min_advance * ds_opt)

    def plan(self, part: Part, swath: Swath, sensor: SensorSpec) -> Trajectory:
        start = time.perf_counter()
        env = self.make_env(part, swath, sensor)
        obs, _ = env.reset(seed=0, options={"swath": 0})
        poses = [swath.pose(*env.state)]
        progress = [env.progress_mm]
        ds_opt = env.reward_config.delta_s_opt_mm
        stall_overrides = backward_overrides = 0
        done = False
        while not done:
            action = self.act(obs)
            w = self.stall_window
            if w and len(progress) > w and progress[-1] - progress[-1 - w] < 0.25 * ds_opt * w:
                action[0], action[2] = ds_opt / env.limits[0], 0.0
                stall_overrides += 1
            before = env.state.copy()
            profile = env.measure_at(env.begin_step(action))
            if self.min_advance is not None and self._went_back(env, profile, ds_opt):
                env.state = before
                action[0], action[2] = ds_opt / env.limits[0], 0.0
                profile = env.measure_at(env.begin_step(action))
                backward_overrides += 1
            obs, _, terminated, truncated, _ = env.finish_step(profile)
            poses.append(swath.pose(*env.state))
            progress.append(env.progress_mm)
            done = terminated or truncated
        poses_arr = np.stack(poses)
        return Trajectory(
            poses_arr,
            np.full(len(poses_arr), swath.index),
            np.ones(len(poses_arr), bool),
            plan_time_s=time.perf_counter() - start,
            planner=self.name,
            meta={
                "stall_overrides": stall_overrides,
                "backward_overrides": backward_overrides,
            },
        )
