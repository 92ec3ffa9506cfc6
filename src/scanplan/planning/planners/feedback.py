"""The `feedback` planner (SPEC §4): a proportional controller on the measured D and α, the
teacher a policy may be warm-started from — a planner of its own, so every policy is measured
against the controller it learned from.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from scanplan.core.quantities import PLANNING_FAN_POINTS, ScanSpec, StepLimits
from scanplan.core.trajectory import Trajectory
from scanplan.planning.dynamics import PassDynamics
from scanplan.planning.planners.closed_loop import Guards, PoseGuard, SensorFactory, drive_passes
from scanplan.planning.swaths import Swath
from scanplan.world.part import Part


@dataclass(frozen=True)
class FeedbackController:
    """From the current D and α only, in action units: Δz = k_z (D − W_d), Δθ = k_θ α
    (capped at `theta_rate_deg` per step so the footprint, W_d·Δθ away, moves less than a
    spacing), Δy = Δs_opt plus the footprint shift of that pitch (at least Δs_opt/2); with
    roll, Δφ = k_φ β (rolling about the working-distance point does not move the footprint,
    so it may use the full Δφ_max). It obeys the paper's action limitation by construction."""

    k_z: float = 0.3
    k_theta: float = 0.1
    theta_rate_deg: float = 0.08
    k_phi: float = 0.3

    def __call__(self, dyn: PassDynamics, start_state: np.ndarray | None = None) -> np.ndarray:
        lim = dyn.limits.array
        wd = dyn.spec.working_distance_mm
        d, a = dyn.d_mm, dyn.alpha_rad
        known = np.isfinite(d) and np.isfinite(a)
        dz = float(np.clip(self.k_z * (d - wd), -lim[1], lim[1])) if known else 0.0
        cap = math.radians(self.theta_rate_deg)
        dth = float(np.clip(self.k_theta * a, -cap, cap)) if known else 0.0
        ds_opt = dyn.spec.delta_s_opt_mm
        dy = max(ds_opt + (d if known else wd) * dth, 0.5 * ds_opt)  # always advance
        if dyn.roll:
            lim4 = dyn.limits.array_roll
            b = dyn.beta_rad
            dphi = float(np.clip(self.k_phi * b, -lim4[3], lim4[3])) if np.isfinite(b) else 0.0
            return np.clip(np.array([dy, dz, dth, dphi]) / lim4, -1.0, 1.0)
        return np.clip(np.array([dy, dz, dth]) / lim, -1.0, 1.0)


@dataclass(frozen=True)
class FeedbackPlanner:
    """`FeedbackController` in the loop of `closed_loop.drive_passes`, with the rl planner's
    guards and planning fan, so the two are compared like for like."""

    controller: FeedbackController = field(default_factory=FeedbackController)
    fan_points: int = PLANNING_FAN_POINTS
    guards: Guards = field(default_factory=Guards)
    roll: bool = False
    limits: StepLimits = field(default_factory=StepLimits)
    name: str = "feedback"
    measure_with: SensorFactory | None = None  # `closed_loop.SensorFactory`
    arm_guard: PoseGuard | None = None  # a fitted plan's arm (`closed_loop.PoseGuard`)

    def plan(self, part: Part, swath: Swath, spec: ScanSpec) -> Trajectory:
        return self.plan_passes(part, [swath], spec)[0]

    def plan_passes(self, part: Part, swaths: list[Swath], spec: ScanSpec) -> list[Trajectory]:
        """Every pass at once, in lockstep (`closed_loop.drive_passes`)."""
        return drive_passes(
            part,
            swaths,
            spec,
            self.controller,
            self.name,
            fan_points=self.fan_points,
            guards=self.guards,
            limits=self.limits,
            roll=self.roll,
            measure_with=self.measure_with,
            arm=self.arm_guard,
        )
