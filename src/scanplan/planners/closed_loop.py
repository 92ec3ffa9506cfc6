"""A pass planned by a controller in the loop (the rl and feedback planners): the controller
picks each action from what the sensor measures, the shared step model (`dynamics`) turns it
into the next pose, and two guards keep the pass going forward.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from scanplan.dynamics import PassDynamics, StepLimits, pass_geometry, step_budget
from scanplan.part import Part
from scanplan.quantities import ScanSpec
from scanplan.sensor import LineProfilometer
from scanplan.swaths import Swath
from scanplan.trajectory import Trajectory

# (the sensor on the pass, the state it started the pass at) -> action in [-1, 1]^3 (^4 with roll)
Controller = Callable[[PassDynamics, np.ndarray], np.ndarray]


@dataclass(frozen=True)
class Guards:
    """What keeps a controller's pass going forward.

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
    controller's step is accepted (its profile is the one the pass goes on with).
    """

    stall_window: int = 20
    min_advance: float | None = 0.25


def drive_pass(
    part: Part,
    swath: Swath,
    spec: ScanSpec,
    controller: Controller,
    name: str,
    limits: StepLimits | None = None,
    fan_points: int = 512,
    guards: Guards | None = None,
    roll: bool = False,
) -> Trajectory:
    """Run `controller` over the whole pass on a noiseless sensor of `fan_points` columns,
    from an aligned start at the first station that sees the part to the last (SPEC §5's
    episode, planning form); every station becomes a scanning pose. roll: the controller
    gives 4-D actions (env v1's step model)."""
    start_time = time.perf_counter()
    guards = guards or Guards()
    limits = limits or StepLimits()
    sensor = spec.sensor.with_points(fan_points).without_noise()
    plan_spec = spec.with_sensor(sensor)
    dyn = PassDynamics(part, swath, plan_spec, LineProfilometer(part, sensor), limits, roll=roll)
    geo = pass_geometry(part, swath, plan_spec)
    _, step_limit = step_budget(geo.s_last_mm - geo.s_first_mm, plan_spec)
    dyn.start(dyn.aligned_start(geo.s_first_mm))
    start_state = dyn.state.copy()
    ds_opt = spec.delta_s_opt_mm
    hold = ds_opt / limits.dy_max_mm  # the action "advance Δs_opt"
    poses = [dyn.pose()]
    progress = [dyn.progress_mm]
    stall_overrides = backward_overrides = steps = 0
    while True:
        action = np.array(controller(dyn, start_state), dtype=np.float64)
        w = guards.stall_window
        if w and len(progress) > w and progress[-1] - progress[-1 - w] < 0.25 * ds_opt * w:
            action[0], action[2] = hold, 0.0
            stall_overrides += 1
        proposed = dyn.propose(action)
        profile = dyn.measure(proposed.state)
        ds: float | None = None  # the accepted profile's advance, where already known
        if guards.min_advance is not None:
            ds = dyn.advance_to(profile)  # unknown (no column valid in both) is not backwards
            if np.isfinite(ds) and ds < guards.min_advance * ds_opt:
                action[0], action[2] = hold, 0.0
                proposed = dyn.propose(action)
                profile = dyn.measure(proposed.state)
                backward_overrides += 1
                ds = None
        dyn.accept(proposed, profile, ds)
        steps += 1
        poses.append(profile.T_part_sensor)  # the pose it was measured at: dyn.pose()
        progress.append(dyn.progress_mm)
        if dyn.progress_mm >= geo.s_last_mm or steps >= step_limit:
            break
    poses_arr = np.stack(poses)
    return Trajectory(
        poses_arr,
        np.full(len(poses_arr), swath.index),
        np.ones(len(poses_arr), bool),
        plan_time_s=time.perf_counter() - start_time,
        planner=name,
        meta={"stall_overrides": stall_overrides, "backward_overrides": backward_overrides},
    )
