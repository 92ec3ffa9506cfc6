"""The paper's "traditional" baseline: each pass a straight line at constant height, pitch 0.

The height is set so that the surface under the pass sits, on average, at the working
distance: a coarse noiseless sub-sampled fan measures the pass and the line is shifted until
the mean of the profiles' D (`quantities.mean_distance`) equals W_d.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from scanplan.core.quantities import PROBE_FAN_POINTS, ScanSpec, StepLimits, mean_distance
from scanplan.core.trajectory import Trajectory
from scanplan.planning.swaths import Swath
from scanplan.sensor.profilometer import LineProfilometer
from scanplan.world.part import Part


def station_advances(length_mm: float, delta_s_mm: float) -> np.ndarray:
    """Advances 0, ds, 2 ds, ... <= length along the pass (at least the two ends)."""
    if length_mm <= 0:
        return np.zeros(1)
    s = np.arange(0.0, length_mm + 1e-9, delta_s_mm)
    return s if len(s) >= 2 else np.array([0.0, length_mm])


@dataclass(frozen=True)
class FixedPlanner:
    """Straight passes at one height and pitch 0, a station every Δs_opt along u.

    probe_step_mm / probe_points: spacing and fan size of the noiseless probe that sets the
    height; height_iterations: D re-measurements after the first guess (the depth window makes
    D depend on the height, so one shift is not always exact).
    """

    probe_step_mm: float = 5.0
    probe_points: int = PROBE_FAN_POINTS
    height_iterations: int = 3
    name: str = "fixed"
    # Recorded with its plans like any planner's; a straight pass takes no step to limit.
    limits: StepLimits = field(default_factory=StepLimits)

    @property
    def roll(self) -> bool:
        return False  # the paper's baseline: pitch 0, no roll

    def plan(self, part: Part, swath: Swath, spec: ScanSpec) -> Trajectory:
        sensor = spec.sensor
        s_probe = station_advances(swath.length_mm, self.probe_step_mm)
        probe = LineProfilometer(part, sensor.without_noise().with_points(self.probe_points))

        def measure(h_mm: float):
            return probe.measure_many(
                swath.poses(s_probe, np.full_like(s_probe, h_mm), 0 * s_probe)
            )

        # First guess from every first hit, in range or not: the depth window is not yet known
        # to contain the surface.
        scan = measure(0.0)
        depth = scan.true_z_sensor[np.isfinite(scan.true_z_sensor)]
        if depth.size == 0:
            raise swath.sees_nothing(part)
        h = -(float(depth.mean()) - sensor.working_distance_mm)
        for _ in range(self.height_iterations):
            scan = measure(h)
            d = mean_distance(scan.z_sensor, scan.valid)
            d = d[np.isfinite(d)]
            if d.size == 0:
                raise ValueError(
                    f"pass {swath.index} of part {part.name}: no profile in the sensor's range "
                    "at any height (the part is outside the sensor's reach)"
                )
            step = float(d.mean()) - sensor.working_distance_mm
            h -= step
            if abs(step) < 1e-3:
                break

        s = station_advances(swath.length_mm, spec.delta_s_opt_mm)
        poses = swath.poses(s, np.full_like(s, h), np.zeros_like(s))
        return Trajectory(
            poses, np.full(len(s), swath.index), np.ones(len(s), bool), planner=self.name
        )
