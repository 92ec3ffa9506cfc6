"""The metrics table (report.table): in-spec coverage leads, beside its visibility ceiling."""

from __future__ import annotations

import numpy as np

from helpers import straight
from scanplan.core.quantities import ScanSpec
from scanplan.core.sensor_spec import SensorSpec
from scanplan.judging import evaluate
from scanplan.judging.report.table import table_rows

SENSOR = SensorSpec()
SPEC = ScanSpec(SENSOR)


def test_the_table_leads_with_in_spec_coverage(plate):
    m = evaluate(plate, SPEC, straight(np.arange(0, 320.0, 1.0)), points_per_profile=128)
    rows = table_rows([m.to_json_dict()])
    assert rows[0][0].startswith("in-spec coverage (±12.5 mm, 15°) of the top surface, ")
    assert rows[0][1] == [f"{m.in_spec_coverage:.1%}"]
    # Beside it, how much of what any plan could hold in spec that is: the plate's top is
    # all within reach, so the share is the coverage itself.
    assert rows[1] == ("in-spec share of the visibility ceiling", [f"{m.in_spec_coverage:.1%}"])
    assert rows[2] == ("visibility ceiling (some beam within tolerance)", ["100.0%"])
    assert rows[3][0] == "coverage (any valid point)"


def test_the_cycle_time_row_names_the_limits_it_was_timed_with(plate):
    m = evaluate(plate, SPEC, straight(np.arange(0, 320.0, 1.0)), points_per_profile=64)
    rows = dict(table_rows([m.to_json_dict()]))
    assert rows["cycle time (s) (trapezoidal, nominal limits)"] == [f"{m.cycle_time_s:.1f}"]
