"""Error maps, comparison plots and the markdown table (report.maps)."""

from __future__ import annotations

import numpy as np

from helpers import straight
from scanplan.core.quantities import ScanSpec
from scanplan.core.sensor_spec import SensorSpec
from scanplan.judging import evaluate
from scanplan.judging.report.maps import (
    metrics_table_markdown,
    plot_comparison,
    plot_error_maps,
)

SENSOR = SensorSpec()
SPEC = ScanSpec(SENSOR)


def test_maps_and_table(plate, tmp_path):
    a = evaluate(plate, SPEC, straight(np.arange(0, 640.0, 1.0), h_mm=5.0), points_per_profile=256)
    b = evaluate(plate, SPEC, straight(np.arange(0, 640.0, 1.0)), points_per_profile=256)
    files = plot_error_maps(a, tmp_path / "maps")
    assert sorted(f.name for f in files) == ["distance_error.png", "orientation_error.png"]
    assert all(f.stat().st_size > 10_000 for f in files)
    cmp = plot_comparison([("high", a), ("exact", b)], "distance", tmp_path / "cmp.png", "plate")
    assert cmp.is_file()
    table = metrics_table_markdown([a, b], ["high", "exact"])
    assert "| mean |distance error| (mm) | 5.00" in table.replace("5.000", "5.00")
    assert len(table.splitlines()) > 10


def test_fragility_map_is_written(tmp_path):
    from scanplan.judging import Robustness
    from scanplan.judging.report.maps import plot_fragility_map

    rng = np.random.default_rng(0)
    robust = Robustness(
        spec="place:1mm,0deg",
        seed=0,
        per_trial=np.array([0.9, 0.8]),
        points_part=rng.uniform(0, 100, (500, 3)),
        in_spec_share=rng.choice([0.0, 0.5, 1.0], 500),
    )
    path = plot_fragility_map(robust, tmp_path / "f.png", "plate")
    assert path.stat().st_size > 10_000
