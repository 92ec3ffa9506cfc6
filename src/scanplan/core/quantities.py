"""The scan's parameters (`ScanSpec`) and the profile-level quantities of SPEC §2 — D,
signed alpha, per-point alpha_i, delta-s.

The environment, the planners, the metrics and the export all take one `ScanSpec` and call
these functions, so the agent's reward and the report's numbers can never disagree. Every
function works on leading batch dimensions.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np

from scanplan.core.sensor_spec import SensorSpec

# In-spec coverage (as the view choice estimates it) at which `--views auto` stops adding
# views. Its sub-sampled fan reads 1-4 points above the full sensor on curved parts, so 0.9
# stopped a sin·cos heightfield at 0.88 of the surface; the door's top view (0.94) still
# holds 0.93 alone.
COVERAGE_TARGET = 0.93
# Candidate views the view choice may plan (its budget, counted in work so that a busy and a
# quiet machine choose the same views); past it the views chosen by then are kept.
# `--view-candidates` sets it; `--view-seconds` adds a wall-clock limit only when asked.
VIEW_CHOICE_CANDIDATES = 400
# The yaw step (deg) of the placement search's coarse grid (`place`, `--yaw-step`).
PLACE_YAW_STEP_DEG = 30.0
# A defect call (`metrics.detection`): points beyond this many σ of the sensor noise from the
# nominal surface, clustered, at least this many points.
DEFECT_K_SIGMA = 4.0
DEFECT_MIN_POINTS = 3
# The defect `scanplan defects` injects and `scanplan evaluate` predicts unless told otherwise.
DEFECT_TYPE = "dent"
# A defect study's default: depths (mm) spread evenly in log between these, so many defective
# parts of so many defects each.
DEFECT_SIZES_MM = (0.01, 0.5)
DEFECT_TRIALS = 16
DEFECTS_PER_TRIAL = 8
# Perturbed trials of `evaluate --perturb` (and the robustness tables) unless told otherwise.
PERTURB_TRIALS = 16
# The part frame's up: the top view looks along −UP.
UP = np.array([0.0, 0.0, 1.0])
UP.flags.writeable = False
# The paper's raster: neighbouring passes share this share of the nominal line width.
OVERLAP = 0.2
# Fans (pixel columns) a simulated sensor is sub-sampled to, one name per purpose:
# The closed-loop planners' sensor (feedback, rl): on narrow curved parts (the drone) 128
# columns put D off by ~1 mm; 512 agree with the full fan to ~0.2 mm.
PLANNING_FAN_POINTS = 512
TRAINING_FAN_POINTS = 128  # the training env's (agrees with the full fan to 0.1 mm / 0.3°)
PROBE_FAN_POINTS = 128  # the fixed planner's probe of the surface under a pass
VIEW_CHOICE_FAN_POINTS = 128  # the evaluation that chooses views (finds the same samples)


@dataclass(frozen=True)
class ScanSpec:
    """What a good scan is, in one place: the sensor (W_d, Z_r) plus the profile spacing
    Δs_opt, α_max and the reward weights (SPEC §5), and the in-spec tolerances (SPEC §7).

    tol_distance_mm: |z_s − W_d| a point may have and count as in spec; None = Z_r/20.
    tol_angle_rad: orientation error α_i a point may have and count as in spec.
    profile_rate_hz, travel_speed_mm_s: the cycle-time model of the metrics and the robot
    programs: scan speed = profile rate × Δs_opt (profiles land Δs_opt apart), moves between
    passes at the travel speed.
    clearance_mm: how far the sensor body stays from the part on every pose (SPEC §3b).
    reward_distance_scale_mm: the depth error at which R_D reaches −1; None = Z_r/2, the
    paper's (a training deviation, `scanplan train --reward-distance-scale`).
    """

    sensor: SensorSpec = field(default_factory=SensorSpec)
    delta_s_opt_mm: float = 0.5
    alpha_max_rad: float = math.radians(30.0)
    w_d: float = 1.0 / 3.0
    w_alpha: float = 1.0 / 3.0
    w_delta_s: float = 1.0 / 3.0
    tol_distance_mm: float | None = None
    tol_angle_rad: float = math.radians(15.0)
    profile_rate_hz: float = 200.0
    travel_speed_mm_s: float = 250.0
    clearance_mm: float = 20.0
    reward_distance_scale_mm: float | None = None

    def __post_init__(self) -> None:
        checks = [
            (self.delta_s_opt_mm, "profile spacing (delta_s_opt_mm)"),
            (self.alpha_max_rad, "alpha_max_rad"),
            (self.tolerance_mm, "distance tolerance"),
            (self.tol_angle_rad, "angle tolerance"),
            (self.profile_rate_hz, "profile rate (profile_rate_hz)"),
            (self.travel_speed_mm_s, "travel speed (travel_speed_mm_s)"),
            (self.distance_scale_mm, "reward distance scale (reward_distance_scale_mm)"),
        ]
        for value, what in checks:
            if not (math.isfinite(value) and value > 0):
                raise ValueError(f"scan spec: {what} must be a finite number > 0, got {value}")
        if not (math.isfinite(self.clearance_mm) and self.clearance_mm >= 0):
            raise ValueError(
                f"scan spec: clearance (clearance_mm) must be a finite number >= 0, "
                f"got {self.clearance_mm}"
            )
        weights = (self.w_d, self.w_alpha, self.w_delta_s)
        if not all(math.isfinite(w) and w >= 0 for w in weights) or sum(weights) <= 0:
            raise ValueError(f"scan spec: reward weights must be >= 0, not all 0: {weights}")

    @property
    def working_distance_mm(self) -> float:
        return self.sensor.working_distance_mm

    @property
    def z_range_mm(self) -> float:
        return self.sensor.z_range_mm

    @property
    def half_range_mm(self) -> float:
        """Z_r/2: the depth window's half width, the scale of D in the reward and state."""
        return self.sensor.z_range_mm / 2

    @property
    def distance_scale_mm(self) -> float:
        """R_D's scale: the depth error it charges −1 (the paper's Z_r/2 unless set)."""
        if self.reward_distance_scale_mm is None:
            return self.half_range_mm
        return self.reward_distance_scale_mm

    @property
    def tolerance_mm(self) -> float:
        """The in-spec distance tolerance (default Z_r/20: 12.5 mm for the AT preset)."""
        return self.z_range_mm / 20 if self.tol_distance_mm is None else self.tol_distance_mm

    @property
    def scan_speed_mm_s(self) -> float:
        """Speed while recording: the profiles land Δs_opt apart."""
        return self.profile_rate_hz * self.delta_s_opt_mm

    @property
    def T_sensor_line(self) -> np.ndarray:
        """(4, 4) the point where the laser line meets a part at the working distance, in the
        sensor frame (W_d along the beam, +z_s), mm: the TCP a robot program flies, so its
        constant speed is the line's speed over the surface (export, cycle time)."""
        T = np.eye(4)
        T[2, 3] = self.working_distance_mm
        return T

    def with_sensor(self, sensor: SensorSpec) -> ScanSpec:
        """The same scan parameters with another sensor (e.g. a sub-sampled, noiseless fan)."""
        return replace(self, sensor=sensor)


def dot_rows(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """a · b over the last axis of (..., 3) arrays (broadcast against each other), added as
    `np.sum(a * b, axis=-1)` adds it, to the last bit: numpy's reduction over an axis of
    three costs several times the arithmetic on the three components."""
    return (a[..., 0] * b[..., 0] + a[..., 1] * b[..., 1]) + a[..., 2] * b[..., 2]


def norm_rows(a: np.ndarray) -> np.ndarray:
    """|a| over the last axis of (..., 3), as `np.linalg.norm(a, axis=-1)` to the last bit."""
    return np.sqrt(dot_rows(a, a))


def mean_distance(z_sensor: np.ndarray, valid: np.ndarray) -> np.ndarray:
    """D: mean z_s of the valid points. (..., N) -> (...); NaN where no point is valid."""
    count = valid.sum(axis=-1)
    total = np.where(valid, z_sensor, 0.0).sum(axis=-1)
    return np.where(count > 0, total / np.maximum(count, 1), np.nan)


def mean_normal(normals_part: np.ndarray, valid: np.ndarray) -> np.ndarray:
    """Unit mean of the valid points' normals. (..., N, 3) -> (..., 3); NaN if none valid."""
    kept = np.where(valid[..., None], normals_part, 0.0)
    # Summed over contiguous rows, column after column: numpy's order along axis -2, to the
    # last bit, at 0.6x the cost (its reduction there steps three values at a time).
    total = np.moveaxis(kept, -2, 0).copy().sum(axis=0)
    norm = norm_rows(total)[..., None]
    return np.where(norm > 0, total / np.where(norm > 0, norm, 1.0), np.nan)


def signed_alpha(normals_part: np.ndarray, valid: np.ndarray, poses: np.ndarray) -> np.ndarray:
    """alpha = atan2(n.y_s, -n.z_s) with n the mean valid normal: the pitch increment about +x_s
    that would align the beam with the surface. (..., N, 3), (..., N), (..., 4, 4) -> (...),
    NaN where no point is valid."""
    n = mean_normal(normals_part, valid)
    y_s = poses[..., :3, 1]
    z_s = poses[..., :3, 2]
    return np.arctan2(np.sum(n * y_s, axis=-1), -np.sum(n * z_s, axis=-1))


def signed_beta(normals_part: np.ndarray, valid: np.ndarray, poses: np.ndarray) -> np.ndarray:
    """β: the roll increment about +y_s that would align the beam with the mean valid normal
    across the line, atan2(−n·x_s, −n·z_s) (SPEC §5's cross angle, signed so that it is to
    roll what α is to pitch). (..., N, 3), (..., N), (..., 4, 4) -> (...), NaN if none valid."""
    n = mean_normal(normals_part, valid)
    x_s = poses[..., :3, 0]
    z_s = poses[..., :3, 2]
    return np.arctan2(-np.sum(n * x_s, axis=-1), -np.sum(n * z_s, axis=-1))


def beam_angle(normals_part: np.ndarray, valid: np.ndarray, poses: np.ndarray) -> np.ndarray:
    """The full angle between the beam and the mean valid normal, acos(−n·z_s): what pitch
    and roll together can correct (env v1's orientation term). (...) radians, NaN if none."""
    n = mean_normal(normals_part, valid)
    z_s = poses[..., :3, 2]
    return np.arccos(np.clip(-np.sum(n * z_s, axis=-1), -1.0, 1.0))


def profile_angles(
    normals_part: np.ndarray, valid: np.ndarray, poses: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(α, β, beam angle) of profiles from one mean normal: `signed_alpha`, `signed_beta` and
    `beam_angle` at the cost of one."""
    n = mean_normal(normals_part, valid)
    x_s, y_s, z_s = poses[..., :3, 0], poses[..., :3, 1], poses[..., :3, 2]
    facing = -dot_rows(n, z_s)
    alpha = np.arctan2(dot_rows(n, y_s), facing)
    beta = np.arctan2(-dot_rows(n, x_s), facing)
    return alpha, beta, np.arccos(np.clip(facing, -1.0, 1.0))


def point_orientation_error(normals_part: np.ndarray, poses: np.ndarray) -> np.ndarray:
    """alpha_i = acos(-z_s . n_i) per point, radians; includes what pitch cannot correct.
    (..., N, 3), (..., 4, 4) -> (..., N)."""
    z_s = poses[..., None, :3, 2]
    return np.arccos(np.clip(-dot_rows(normals_part, z_s), -1.0, 1.0))


def normal_in_laser_plane(
    normals_part: np.ndarray, poses: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """(n·x_s, n·z_s): the normals' components in the laser plane, the sensor's x-z plane.
    (..., 3) part-frame normals and (..., 4, 4) poses, broadcast -> (...) each; added in
    the order numpy's `n @ R` adds one normal's (the same bits here)."""
    return dot_rows(normals_part, poses[..., :3, 0]), dot_rows(normals_part, poses[..., :3, 2])


def cos_to_rays(n_x: np.ndarray, n_z: np.ndarray, rays_sensor: np.ndarray) -> np.ndarray:
    """|cos| of the angle between sensor-frame rays (..., 3) in the laser plane (y_s = 0)
    and the normals whose laser-plane components are n_x, n_z (`normal_in_laser_plane`),
    broadcast -> (...)."""
    return np.abs(n_x * rays_sensor[..., 0] + n_z * rays_sensor[..., 2])


def in_spec(
    z_sensor: np.ndarray, orientation_rad: np.ndarray, valid: np.ndarray, spec: ScanSpec
) -> np.ndarray:
    """The in-spec test of a point (SPEC §7): valid, |z_s − W_d| <= tol_d and alpha_i <= tol_alpha.
    (...), (...), (...) bool -> (...) bool; NaN depths or angles never pass."""
    near = np.abs(z_sensor - spec.working_distance_mm) <= spec.tolerance_mm
    return valid & near & (orientation_rad <= spec.tol_angle_rad)


def advance(
    points_prev: np.ndarray,
    valid_prev: np.ndarray,
    points_next: np.ndarray,
    valid_next: np.ndarray,
    scan_direction: np.ndarray,
) -> np.ndarray:
    """delta-s: signed 3-D advance between consecutive profiles (SPEC §2).

    Over the pixel columns valid in both, the mean of sign(d_i . u) * |d_i|, d_i the
    displacement of column i's point. (..., N, 3) x2, (..., N) x2, (3,) or (..., 3) -> (...);
    NaN where no column is valid in both.
    """
    both = valid_prev & valid_next
    d = points_next - points_prev
    u = np.asarray(scan_direction, dtype=np.float64)
    if u.ndim > 1:
        u = u[..., None, :]
    with np.errstate(invalid="ignore"):  # the columns not valid in both are NaN here
        signed = np.where(both, np.sign(dot_rows(d, u)) * norm_rows(d), 0.0)
    count = both.sum(axis=-1)
    return np.where(count > 0, signed.sum(axis=-1) / np.maximum(count, 1), np.nan)


@dataclass(frozen=True)
class StepLimits:
    """The per-step limits (SPEC §4, §5): Δy along u (mm), Δz along z_s (mm), Δθ about x_s
    (rad) and, with roll, Δφ about the scan direction (rad)."""

    dy_max_mm: float = 1.0
    dz_max_mm: float = 1.0
    dtheta_max_rad: float = math.radians(1.0)
    dphi_max_rad: float = math.radians(1.0)

    def __post_init__(self) -> None:
        for name in ("dy_max_mm", "dz_max_mm", "dtheta_max_rad", "dphi_max_rad"):
            value = getattr(self, name)
            if not (isinstance(value, int | float) and math.isfinite(value) and value > 0):
                raise ValueError(f"step limit {name} must be a finite number > 0, got {value!r}")

    @property
    def array(self) -> np.ndarray:
        """(Δy_max, Δz_max, Δθ_max), the scale of an action in [−1, 1]³."""
        return np.array([self.dy_max_mm, self.dz_max_mm, self.dtheta_max_rad])

    @property
    def array_roll(self) -> np.ndarray:
        """(Δy_max, Δz_max, Δθ_max, Δφ_max), the scale of an action in [−1, 1]⁴."""
        return np.array([self.dy_max_mm, self.dz_max_mm, self.dtheta_max_rad, self.dphi_max_rad])
