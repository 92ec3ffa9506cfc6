"""The sensor's datasheet (sensor.SensorSpec): non-finite and implausible values refused."""

from __future__ import annotations

import math

import pytest

from scanplan.core.sensor_spec import PRESETS


def test_sensor_spec_refuses_non_finite_and_implausible_values():
    import dataclasses

    base = PRESETS["at-c5-4090cs30-495"]
    for change in (
        {"working_distance_mm": math.nan},
        {"fov_rad": math.inf},
        {"working_distance_mm": 0.4},
        {"points_per_profile": 100_001},
        {"body_min_mm": (0, 0, 0), "body_max_mm": (1, -1, 1)},
        {"body_min_mm": (0, 0, 0)},
    ):
        with pytest.raises(ValueError, match="sensor"):
            dataclasses.replace(base, **change)
