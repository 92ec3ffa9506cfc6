"""A pass planned by a controller in the loop (the rl and feedback planners): the controller
picks each action from what the sensor measures, the shared step model (`step_model`, through
`dynamics.PassDynamics`) turns it into the next pose, and two guards keep the pass going forward.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Protocol

import numpy as np

from scanplan.core.quantities import ScanSpec, StepLimits
from scanplan.core.sensor_spec import SensorSpec
from scanplan.core.trajectory import Trajectory
from scanplan.planning.dynamics import PassDynamics, Step, pass_geometry, step_budget
from scanplan.planning.step_model import DEFAULT_PITCH_PIVOT
from scanplan.planning.swaths import Swath, frame_poses
from scanplan.sensor.profilometer import LineProfilometer, Profile
from scanplan.world.part import Part

# (the sensor on the pass, the state it started the pass at) -> action in [-1, 1]^3 (^4 with roll)
Controller = Callable[[PassDynamics, np.ndarray], np.ndarray]
# (the part planned on, the planning sensor) -> the sensor whose profiles the controller acts
# on: None in a planner is that sensor on the part itself; a robustness trial gives one on the
# part as built and placed (`sensor.placed.PlacedProfilometer`), the closed loop online.
SensorFactory = Callable[[Part, SensorSpec], LineProfilometer]


class PoseGuard(Protocol):
    """What keeps a controller's poses within an arm (`arm_guard.ArmGuard`): the states
    (k, n) proposed on passes `indices` (swath indices) in, the states the arm follows out."""

    def admit(self, indices: list[int], states: np.ndarray) -> np.ndarray: ...


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


@dataclass
class _Run:
    """One pass in `drive_passes`: its sensor, where it ends, and what it has done."""

    dyn: PassDynamics
    s_last_mm: float
    step_limit: int
    start_state: np.ndarray
    poses: list[np.ndarray]
    progress: list[float]
    stall_overrides: int = 0
    backward_overrides: int = 0
    steps: int = 0
    plan_time_s: float = 0.0
    done: bool = False


def drive_passes(
    part: Part,
    swaths: list[Swath],
    spec: ScanSpec,
    controller: Controller,
    name: str,
    *,
    fan_points: int,
    limits: StepLimits | None = None,
    guards: Guards | None = None,
    roll: bool = False,
    measure_with: SensorFactory | None = None,
    pitch_pivot: str = DEFAULT_PITCH_PIVOT,
    arm: PoseGuard | None = None,
) -> list[Trajectory]:
    """Run `controller` over each whole pass on a noiseless sensor of `fan_points` columns,
    from an aligned start at the first station that sees the part to the last (SPEC §5's
    episode, planning form); every station becomes a scanning pose. roll: the controller
    gives 4-D actions (env v1's step model). The passes are independent and step in
    lockstep, so that each step measures every pass's proposed pose in one batch (a single
    pose's ray cast is mostly overhead); each pass's poses are those it would have alone.
    measure_with: the sensor the controller measures with (`SensorFactory`); where each pass
    starts and ends is the planned part's (the CAD's), whatever that sensor sees.
    pitch_pivot: where the controller's pitch steps turn (`step_model.PITCH_PIVOTS`).
    arm: the arm the passes are flown by (a fitted plan's, `PoseGuard`): every pose the
    controller proposes, the aligned start too, is first made one the arm follows."""
    guards = guards or Guards()
    limits = limits or StepLimits()
    sensor = spec.sensor.with_points(fan_points).without_noise()
    plan_spec = spec.with_sensor(sensor)
    sim = LineProfilometer(part, sensor) if measure_with is None else measure_with(part, sensor)
    ds_opt = spec.delta_s_opt_mm
    hold = ds_opt / limits.dy_max_mm  # the action "advance Δs_opt"
    runs = [
        _start_run(
            PassDynamics(part, swath, plan_spec, sim, limits, roll=roll, pitch_pivot=pitch_pivot),
            arm,
        )
        for swath in swaths
    ]

    def admitted(batch: list[_Run], steps: list[Step]) -> list[Step]:
        if arm is None:
            return steps
        indices = [run.dyn.swath.index for run in batch]
        states = arm.admit(indices, np.stack([step.state for step in steps]))
        return [Step(step.action_mm_rad, x) for step, x in zip(steps, states, strict=True)]

    def measure(batch: list[tuple[_Run, Step]]) -> list[Profile]:
        passes = [run.dyn.swath for run, _ in batch]
        states = np.stack([step.state for _, step in batch]).T  # (s, h, θ[, φ, l]) rows
        poses = frame_poses(
            np.stack([sw.start_mm for sw in passes]),
            np.stack([sw.u for sw in passes]),
            np.stack([sw.v for sw in passes]),
            *states,
        )
        scan = sim.measure_many(poses)
        return [scan.profile(k) for k in range(len(batch))]

    w = guards.stall_window
    while active := [run for run in runs if not run.done]:
        start_time = time.perf_counter()
        actions = [_action(run, controller, w, hold, ds_opt) for run in active]
        proposed = admitted(
            active, [run.dyn.propose(a) for run, a in zip(active, actions, strict=True)]
        )
        profiles = measure(list(zip(active, proposed, strict=True)))
        # The accepted profile's advance, where already known.
        advances: list[float | None] = [None] * len(active)
        if guards.min_advance is not None:
            redo = []
            for k, run in enumerate(active):
                ds = run.dyn.advance_to(profiles[k])  # unknown (no valid pair) is not backwards
                advances[k] = ds
                if np.isfinite(ds) and ds < guards.min_advance * ds_opt:
                    actions[k][0], actions[k][2] = hold, 0.0
                    proposed[k] = run.dyn.propose(actions[k])
                    run.backward_overrides += 1
                    advances[k] = None
                    redo.append(k)
            if redo:
                fixed = admitted([active[k] for k in redo], [proposed[k] for k in redo])
                for k, step in zip(redo, fixed, strict=True):
                    proposed[k] = step
                again = measure([(active[k], proposed[k]) for k in redo])
                for k, profile in zip(redo, again, strict=True):
                    profiles[k] = profile
        share = (time.perf_counter() - start_time) / len(active)
        for run, step, profile, known in zip(active, proposed, profiles, advances, strict=True):
            run.dyn.accept(step, profile, known)
            run.steps += 1
            run.poses.append(profile.T_part_sensor)  # the pose it was measured at
            run.progress.append(run.dyn.progress_mm)
            run.plan_time_s += share
            run.done = run.dyn.progress_mm >= run.s_last_mm or run.steps >= run.step_limit
    return [_trajectory_of(run, name) for run in runs]


def _action(
    run: _Run, controller: Controller, window: int, hold: float, ds_opt: float
) -> np.ndarray:
    """The controller's action for `run`'s next step; overridden to "advance Δs_opt, level"
    (`hold`) where the pass advanced less than a quarter of Δs_opt a step over the last
    `window` steps (stalled)."""
    action = np.array(controller(run.dyn, run.start_state), dtype=np.float64)
    p = run.progress
    if window and len(p) > window and p[-1] - p[-1 - window] < 0.25 * ds_opt * window:
        action[0], action[2] = hold, 0.0
        run.stall_overrides += 1
    return action


def _start_run(dyn: PassDynamics, arm: PoseGuard | None = None) -> _Run:
    """A pass ready to drive: the sensor aligned at the first station that sees the part
    (where the `arm` follows it), ending at the last (the planned part's, whatever `dyn`'s
    sensor sees), with its step budget. Its plan time starts with the alignment's."""
    start_time = time.perf_counter()
    part, swath, plan_spec = dyn.part, dyn.swath, dyn.spec
    geo = pass_geometry(part, swath, plan_spec)
    _, step_limit = step_budget(geo.s_last_mm - geo.s_first_mm, plan_spec)
    state = dyn.aligned_start(geo.s_first_mm)
    if arm is not None:
        state = arm.admit([swath.index], state[None])[0]
    dyn.start(state)
    run = _Run(dyn, geo.s_last_mm, step_limit, dyn.state.copy(), [dyn.pose()], [dyn.progress_mm])
    run.plan_time_s = time.perf_counter() - start_time
    return run


def _trajectory_of(run: _Run, name: str) -> Trajectory:
    """A driven pass as a trajectory of planner `name`: every pose scans, and its meta counts
    the guards' overrides."""
    poses_arr = np.stack(run.poses)
    return Trajectory(
        poses_arr,
        np.full(len(poses_arr), run.dyn.swath.index),
        np.ones(len(poses_arr), bool),
        plan_time_s=run.plan_time_s,
        planner=name,
        meta={
            "stall_overrides": run.stall_overrides,
            "backward_overrides": run.backward_overrides,
        },
    )
