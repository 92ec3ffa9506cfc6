"""A controller run online, for a robot-side loop (a ROS 2 node, an RTDE servo loop): the
sensor's profile in, the next sensor pose out, one `OnlinePass` per pass of a plan.

The controller sees what it sees when the feedback and rl planners run it on the simulator:
D, α (β with roll) and Δs of the profile, computed by `dynamics.PassDynamics` with the same
functions (`quantities`), the same step model and limits. One thing differs: a real sensor
gives points, not surface normals, so the normals behind α and β are estimated from the
profile and the one before it (`estimate_normals`). The planners' guards
(`closed_loop.Guards`) are not applied: the forward-only guard measures a step before taking
it, which a robot cannot.

    swaths = trials.plan_swaths_of(read_trajectory("plan.json"), "plan.json")
    loop = OnlinePass(swaths[0], spec, FeedbackController())   # or RLPlanner.controller()
    pose = first_pose_of_the_pass                               # T_part_sensor, mm
    while not loop.done:
        robot.servo(pose)                                       # part frame, mm
        x_mm, z_mm = sensor.profile()                           # NaN or 0 where no point
        pose = loop.step(robot.pose(), x_mm, z_mm)

A plan of several views (or one tilted view): `trials.plan_views_of` gives each view's pass
lines in that view's frame; run the loop there, a part-frame pose T being view.R @ T.
"""

from __future__ import annotations

import math

import numpy as np

from scanplan.core.quantities import UP, ScanSpec, StepLimits
from scanplan.planning.dynamics import PassDynamics, Step
from scanplan.planning.planners.closed_loop import Controller
from scanplan.planning.step_model import DEFAULT_PITCH_PIVOT
from scanplan.planning.swaths import Swath
from scanplan.sensor.profilometer import PointStatus, Profile
from scanplan.world.part import Part

# Columns apart of the two points whose difference is the tangent along the line: a baseline
# of a few tenths of a millimetre on a 4096-column line, long against the depth noise.
LINE_BASELINE_COLUMNS = 4


def pass_state(swath: Swath, T_part_sensor: np.ndarray, roll: bool = False) -> np.ndarray:
    """The state on `swath` of a sensor pose: (s, h, θ), or with roll (s, h, θ, φ, l) (the
    inverse of `Swath.pose`; a pose off the pass's plane is projected onto it)."""
    T = np.asarray(T_part_sensor, dtype=np.float64)
    d = T[:3, 3] - swath.start_mm
    x_s, y_s, z_s = T[:3, 0], T[:3, 1], T[:3, 2]
    theta = math.atan2(-float(z_s @ swath.u), float(y_s @ swath.u))
    s, h = float(d @ swath.u), float(d @ UP)
    if not roll:
        return np.array([s, h, theta])
    phi = math.atan2(float(x_s @ UP), float(x_s @ swath.v))
    return np.array([s, h, theta, phi, float(d @ swath.v)])


def estimate_normals(
    points_part: np.ndarray,
    valid: np.ndarray,
    T_part_sensor: np.ndarray,
    previous_points: np.ndarray | None = None,
    previous_valid: np.ndarray | None = None,
    baseline: int = LINE_BASELINE_COLUMNS,
) -> np.ndarray:
    """(N, 3) unit surface normals at a profile's (N, 3) points (part frame), facing the
    sensor, 0 where unknown: the cross product of the tangent along the line (points
    `baseline` columns either side) and the tangent along the scan (each column's point in
    the previous profile to this one). Without a previous profile (a pass's first) the scan
    tangent is taken square to the beam: the pitch error reads as 0 until the second."""
    p = np.asarray(points_part, dtype=np.float64)
    ok = np.asarray(valid, dtype=bool) & np.isfinite(p).all(axis=1)
    n = len(p)
    k = max(1, min(baseline, (n - 1) // 2))
    lo, hi = np.clip(np.arange(n) - k, 0, n - 1), np.clip(np.arange(n) + k, 0, n - 1)
    line = np.where((ok[lo] & ok[hi])[:, None], p[hi] - p[lo], np.nan)
    z_s, y_s = T_part_sensor[:3, 2], T_part_sensor[:3, 1]
    scan = np.broadcast_to(y_s, p.shape).copy()
    if previous_points is not None and previous_valid is not None:
        step = p - np.asarray(previous_points, dtype=np.float64)
        both = ok & np.asarray(previous_valid, dtype=bool) & np.isfinite(step).all(axis=1)
        moved = both & (np.linalg.norm(np.where(both[:, None], step, 0.0), axis=1) > 1e-6)
        scan[moved] = step[moved]
    normals = np.cross(line, scan)
    length = np.linalg.norm(normals, axis=1)
    good = ok & np.isfinite(length) & (length > 0)
    normals = np.where(good[:, None], normals / np.where(good, length, 1.0)[:, None], 0.0)
    return normals * np.where(normals @ z_s > 0, -1.0, 1.0)[:, None]  # towards the sensor


class OnlinePass:
    """A controller run on one pass of a plan, online: `step` takes the pose the sensor was
    at and the profile it measured there and returns the next pose (part frame, mm).

    swath: the pass line the plan records (`trials.plan_swaths_of`); spec: the plan's
    ScanSpec (W_d, Δs_opt, α_max); controller: a `closed_loop.Controller`, e.g.
    `FeedbackController()` or `RLPlanner.controller()`; limits: the plan's step limits;
    roll: the controller gives 4-D actions (a v1 policy, feedback with roll); part: the CAD,
    needed only by a policy that looks ahead on it; end_mm: the advance along the pass at
    which it is `done` (default: the pass line's end); pitch_pivot: where pitch steps turn
    (a policy's `RLPlanner.pitch_pivot`).
    """

    def __init__(
        self,
        swath: Swath,
        spec: ScanSpec,
        controller: Controller,
        limits: StepLimits | None = None,
        roll: bool = False,
        part: Part | None = None,
        end_mm: float | None = None,
        pitch_pivot: str = DEFAULT_PITCH_PIVOT,
    ) -> None:
        self.swath, self.spec, self.controller = swath, spec, controller
        self.roll = roll
        self.end_mm = swath.length_mm if end_mm is None else float(end_mm)
        # The CAD is read only by a look-ahead observation; a pass without it has none.
        self.dynamics = PassDynamics(
            part,  # type: ignore[arg-type]
            swath,
            spec,
            None,
            limits,
            roll=roll,
            pitch_pivot=pitch_pivot,
        )
        self._start: np.ndarray | None = None
        self._last: Step | None = None

    @property
    def done(self) -> bool:
        """The scan's footprint has passed the end of the pass."""
        return self._start is not None and self.dynamics.progress_mm >= self.end_mm

    def profile(
        self,
        T_part_sensor: np.ndarray,
        x_mm: np.ndarray,
        z_mm: np.ndarray,
        previous: Profile | None = None,
    ) -> Profile:
        """A sensor's profile as the controller reads it: (N,) lateral positions and depths
        in the sensor frame (NaN or 0 where no point), placed at the pose it was taken
        from; normals estimated with the `previous` profile (`estimate_normals`)."""
        T = np.asarray(T_part_sensor, dtype=np.float64)
        x = np.asarray(x_mm, dtype=np.float64).reshape(-1)
        z = np.asarray(z_mm, dtype=np.float64).reshape(-1)
        if x.shape != z.shape:
            raise ValueError(f"profile: {len(x)} lateral positions for {len(z)} depths")
        valid = np.isfinite(x) & np.isfinite(z) & (z > 0)
        local = np.stack([x, np.zeros_like(x), z], axis=1)
        points = np.where(valid[:, None], local @ T[:3, :3].T + T[:3, 3], np.nan)
        normals = estimate_normals(
            points,
            valid,
            T,
            None if previous is None else previous.points_part,
            None if previous is None else previous.valid,
        )
        return Profile(
            T_part_sensor=T,
            z_sensor=np.where(valid, z, np.nan),
            x_sensor=np.where(valid, x, np.nan),
            points_part=points,
            true_z_sensor=np.where(valid, z, np.inf),
            normals_part=normals,
            face=np.full(len(z), -1, dtype=np.int64),
            status=np.where(valid, PointStatus.VALID, PointStatus.NO_HIT).astype(np.uint8),
        )

    def step(self, T_part_sensor: np.ndarray, x_mm: np.ndarray, z_mm: np.ndarray) -> np.ndarray:
        """The next sensor pose (4, 4), part frame, mm, from the profile (x_mm, z_mm) the
        sensor measured at `T_part_sensor` (where the robot reports it was)."""
        dyn = self.dynamics
        previous = dyn.profile if self._start is not None else None
        profile = self.profile(T_part_sensor, x_mm, z_mm, previous)
        state = pass_state(self.swath, profile.T_part_sensor, self.roll)
        if self._start is None or self._last is None:
            dyn.begin(state, profile)
            self._start = state.copy()
        else:
            # The state the robot reached (not the one commanded), with the step that led there.
            dyn.accept(Step(self._last.action_mm_rad, state), profile)
        action = np.asarray(self.controller(dyn, self._start), dtype=np.float64)
        self._last = dyn.propose(action)
        return dyn.pose(self._last.state)
