"""The metrics summary (Metrics.to_json_dict): the SPEC §8 keys, and never a NaN in the JSON."""

from __future__ import annotations

import json
import math
from dataclasses import replace

import pytest

from helpers import straight
from scanplan.core.quantities import ScanSpec
from scanplan.core.sensor_spec import SensorSpec
from scanplan.judging import evaluate

SENSOR = SensorSpec()
SPEC = ScanSpec(SENSOR)


def test_json_has_the_spec_keys_and_no_nan(plate):
    data = evaluate(plate, SPEC, straight([300.0]), points_per_profile=64).to_json_dict()
    for key in (
        "profiles",
        "in_range_fraction",
        "coverage_fraction",
        "path_length_mm",
        "plan_time_s",
    ):
        assert key in data
    assert set(data["distance_error_mm"]) >= {"mean_abs", "rms", "p95_abs"}
    assert set(data["orientation_error_deg"]) >= {"mean", "p95"}
    assert set(data["spacing_mm"]) >= {"mean", "cv", "max_gap", "backward_steps"}
    assert all(f"`{s}`" in data["coverage_definition"] for s in ("top", "hemisphere", "roi"))
    assert data["surface"]["name"] == "top" and data["surface"]["area_mm2"] > 0
    text = json.dumps(data, allow_nan=False)  # raises on NaN/inf
    assert "NaN" not in text


def test_json_never_emits_nan(plate):
    m = evaluate(plate, SPEC, straight([300.0]), points_per_profile=64)
    data = replace(m, spacing_cv=math.nan, cycle_time_s=math.inf).to_json_dict()
    assert data["spacing_mm"]["cv"] is None and data["cycle_time_s"] is None
    json.dumps(data, allow_nan=False)
    assert data["tolerance"] == {"mm": 12.5, "deg": pytest.approx(15.0)}
    assert "in_spec_coverage" in data and "in_spec_definition" in data
