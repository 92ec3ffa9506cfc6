"""The laser-triangulation line profilometer's datasheet (`SensorSpec`) and the presets;
`profilometer` simulates it. Sensor frame: z_s = laser axis towards the part, x_s = along
the line, y_s = z_s x x_s = scan direction; the camera sits at baseline W_d*tan(gamma) on y_s.
"""

from __future__ import annotations

import math
import numbers
from dataclasses import dataclass, field, replace
from typing import ClassVar

import numpy as np

from scanplan.core.limits import FOV_DEG, MAX_PROFILE_POINTS, WORKING_DISTANCE_MM
from scanplan.core.noise import NoiseModel


@dataclass(frozen=True)
class SensorSpec:
    """Datasheet of a line profilometer. Lengths in mm, angles in radians."""

    name: str = "at-c5-4090cs30-495"
    working_distance_mm: float = 400.0
    z_range_mm: float = 250.0
    fov_rad: float = math.radians(63.5)
    points_per_profile: int = 4096
    z_resolution_mm: float = 0.0038
    triangulation_angle_rad: float = math.radians(30.0)
    camera_side: int = 1  # +1: camera on +y_s (ahead), -1: behind
    incidence_cutoff_rad: float = math.radians(80.0)
    noise: NoiseModel | None = field(default_factory=NoiseModel)
    # The sensor body, a box in the sensor frame (mm) for collision checks; None: the SPEC §2
    # default from the datasheet (see `body_bounds_mm`).
    body_min_mm: tuple[float, float, float] | None = None
    body_max_mm: tuple[float, float, float] | None = None

    # Datasheet values no real line profilometer has (SPEC §2).
    MIN_WORKING_DISTANCE_MM: ClassVar[float] = WORKING_DISTANCE_MM.lo
    MAX_WORKING_DISTANCE_MM: ClassVar[float] = WORKING_DISTANCE_MM.hi
    MAX_FOV_RAD: ClassVar[float] = math.radians(FOV_DEG.hi)
    MAX_POINTS: ClassVar[int] = MAX_PROFILE_POINTS

    def __post_init__(self) -> None:
        fields = {
            "working distance": self.working_distance_mm,
            "Z range": self.z_range_mm,
            "fan angle": self.fov_rad,
            "Z resolution": self.z_resolution_mm,
            "triangulation angle": self.triangulation_angle_rad,
            "incidence cutoff": self.incidence_cutoff_rad,
        }
        for what, value in fields.items():
            if isinstance(value, bool) or not isinstance(value, numbers.Real):
                raise ValueError(f"sensor {self.name}: {what} must be a number, got {value!r}")
            if not math.isfinite(value):
                raise ValueError(f"sensor {self.name}: {what} must be finite, got {value}")
        wd = self.working_distance_mm
        ppp = self.points_per_profile
        checks = [
            (
                self.MIN_WORKING_DISTANCE_MM <= wd <= self.MAX_WORKING_DISTANCE_MM,
                f"working distance {wd:g} mm is outside {self.MIN_WORKING_DISTANCE_MM:g}–"
                f"{self.MAX_WORKING_DISTANCE_MM:g} mm (lengths are in millimetres, not metres)",
            ),
            (0 < self.z_range_mm < 2 * wd, "Z range must be in (0, 2*W_d)"),
            (0 < self.fov_rad < self.MAX_FOV_RAD, "fan angle must be in (0, 170) degrees"),
            (
                isinstance(ppp, int | np.integer) and not isinstance(ppp, bool),
                "points per profile must be an integer",
            ),
            (2 <= ppp <= self.MAX_POINTS, f"points per profile must be in 2..{self.MAX_POINTS}"),
            (self.z_resolution_mm >= 0, "Z resolution must be >= 0"),
            (0 < self.triangulation_angle_rad < math.pi / 2, "triangulation angle in (0, 90) deg"),
            (self.camera_side in (-1, 1), "camera side must be +1 or -1"),
            (0 < self.incidence_cutoff_rad <= math.pi / 2, "incidence cutoff in (0, 90] deg"),
        ]
        for ok, message in checks:
            if not ok:
                raise ValueError(f"sensor {self.name}: {message}")
        if self.noise is not None:
            self._check_noise(self.noise)
        if (self.body_min_mm is None) != (self.body_max_mm is None):
            raise ValueError(f"sensor {self.name}: give both corners of the body box or neither")
        if self.body_min_mm is not None:
            lo, hi = np.asarray(self.body_min_mm, float), np.asarray(self.body_max_mm, float)
            if lo.shape != (3,) or hi.shape != (3,):
                raise ValueError(f"sensor {self.name}: body box corners must be (x, y, z) in mm")
            if not (np.isfinite(lo).all() and np.isfinite(hi).all()):
                raise ValueError(f"sensor {self.name}: body box must be finite")
            if not (lo < hi).all():
                axis = "xyz"[int(np.flatnonzero(lo >= hi)[0])]
                raise ValueError(f"sensor {self.name}: body box {axis}: min must be < max")

    def _check_noise(self, noise: NoiseModel) -> None:
        for name in ("sigma0_mm", "speckle_amplitude_mm", "speckle_scale_mm"):
            value = getattr(noise, name)
            if not (isinstance(value, numbers.Real) and math.isfinite(value) and float(value) >= 0):
                raise ValueError(f"sensor {self.name}: noise {name} must be finite and >= 0")
        if not noise.speckle_scale_mm > 0:
            raise ValueError(f"sensor {self.name}: noise speckle_scale_mm must be > 0")
        seed = noise.seed
        if isinstance(seed, bool) or not isinstance(seed, int | np.integer) or seed < 0:
            raise ValueError(f"sensor {self.name}: noise seed must be an integer >= 0")

    @property
    def body_bounds_mm(self) -> np.ndarray:
        """(2, 3) min and max corners of the sensor body in the sensor frame. Default (SPEC
        §2): x_s in [-50, 50], y_s from -40 to b + 40 on the camera side, z_s in [-90, 0]."""
        if self.body_min_mm is not None and self.body_max_mm is not None:
            return np.array([self.body_min_mm, self.body_max_mm], dtype=np.float64)
        y = np.array([-40.0, self.baseline_mm + 40.0])
        if self.camera_side < 0:
            y = -y[::-1]
        return np.array([[-50.0, y[0], -90.0], [50.0, y[1], 0.0]])

    @property
    def line_width_mm(self) -> float:
        """Length of the laser line at the working distance."""
        return 2.0 * self.working_distance_mm * math.tan(self.fov_rad / 2)

    @property
    def baseline_mm(self) -> float:
        return self.working_distance_mm * math.tan(self.triangulation_angle_rad)

    @property
    def depth_window_mm(self) -> tuple[float, float]:
        half = self.z_range_mm / 2
        return self.working_distance_mm - half, self.working_distance_mm + half

    @property
    def camera_sensor(self) -> np.ndarray:
        """Camera centre in the sensor frame, (3,)."""
        return np.array([0.0, self.camera_side * self.baseline_mm, 0.0])

    def ray_directions(self, points: int | None = None) -> np.ndarray:
        """Unit ray directions in the sensor frame, (N, 3): the pixel columns are evenly spaced
        in x across the line at z = W_d (not evenly spaced in angle)."""
        n = points or self.points_per_profile
        half = self.line_width_mm / 2
        x = np.linspace(-half, half, n)
        d = np.stack([x, np.zeros(n), np.full(n, self.working_distance_mm)], axis=1)
        return d / np.linalg.norm(d, axis=1, keepdims=True)

    def without_noise(self) -> SensorSpec:
        return replace(self, noise=None)

    def with_points(self, points_per_profile: int) -> SensorSpec:
        """The same sensor with a sub-sampled fan (the same line width)."""
        return replace(self, points_per_profile=points_per_profile)


PRESETS: dict[str, SensorSpec] = {SensorSpec().name: SensorSpec()}
# The sensor a command uses when none is given: the paper's.
DEFAULT_SENSOR = SensorSpec().name
# The fan the demo judges with: 256 of the sensor's 4096 columns give the door's figures of
# 1024 columns to 0.2 % of in-spec coverage and 1 % of the predicted dent, in half the time.
DEMO_POINTS = 256
