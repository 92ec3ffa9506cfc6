"""The plan record validated when read (issue 46: A, B, G, and the property tests of item 8):
every record a plan file carries (context, robot, views and their pass lines, cycle_time_s),
from a CSV's comment lines or a JSON's keys, either loads or ends in one ValueError naming
the file and the field; the context's numbers obey the ranges the same values have as
options (`core.limits`), and a recorded pass line is checked before any work."""

from __future__ import annotations

import copy
import json
import math
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from helpers import FAST, JSON_VALUES, one_line_or_ok, recorded_trajectory
from scanplan.core.limits import (
    ANGLE_DEG,
    CLEARANCE_MM,
    ORIENTATION_ERROR_DEG,
    PROFILE_RATE_HZ,
    REWARD_WEIGHT,
    SPEED_MM_S,
    STEP_MM,
    TOLERANCE_MM,
    Limit,
)
from scanplan.core.plan import Plan, read_plan
from scanplan.core.plan_file import CSV_COLUMNS, to_csv_text, to_json_dict
from scanplan.core.quantities import ScanSpec
from scanplan.planning.swaths import swath_from_record

SUFFIXES = (".csv", ".json")
QUICK = settings(
    max_examples=12, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture]
)
TRAJ = recorded_trajectory()
DELETE = object()  # a field left out


def write_plan(path: Path, records: dict[str, Any]) -> Path:
    """TRAJ's poses with `records` as they are (any JSON value, falsy ones and NaN too):
    `# key: <JSON>` lines under the CSV's header, or the JSON's top-level keys."""
    bare = replace(TRAJ, meta={})
    if path.suffix == ".json":
        path.write_text(json.dumps(to_json_dict(bare) | records))
    else:
        header, *poses = to_csv_text(bare).splitlines()
        lines = [f"# {key}: {json.dumps(value)}" for key, value in records.items()]
        path.write_text("\n".join([header, *lines, *poses]) + "\n")
    return path


def records() -> dict[str, Any]:
    return copy.deepcopy(TRAJ.meta)


def use(path: Path) -> Plan:
    """Read the plan and use every record as the commands do."""
    plan = read_plan(path)
    plan.context.to_json_dict()
    plan.counts()
    assert plan.cycle_time_s is None or math.isfinite(plan.cycle_time_s)
    if plan.arm is not None:
        assert plan.arm.flyable in (True, False)
    for k, view in enumerate(plan.views):
        for i, line in enumerate(view.record.get("swaths") or ()):
            swath_from_record(line, f"views[{k}].swaths[{i}]")
    return plan


@pytest.mark.parametrize("suffix", SUFFIXES)
def test_every_record_reads_back_as_written(tmp_path, suffix):
    plan = use(write_plan(tmp_path / f"plan{suffix}", records()))
    assert plan.context.to_json_dict() == TRAJ.meta["context"]
    assert plan.spec.tolerance_mm == ScanSpec().tolerance_mm == 12.5
    assert plan.traj.meta["views"] == TRAJ.meta["views"]
    sw = swath_from_record(plan.views[0].record["swaths"][0], "here")
    assert sw.length_mm == 640.0 and np.array_equal(sw.u, [1.0, 0.0, 0.0])
    assert plan.arm is not None and plan.arm.robot == "ur10e"
    assert np.array_equal(plan.arm.T_base_part, TRAJ.meta["robot"]["T_base_part"])
    assert plan.cycle_time_s == 12.5
    assert plan.counts() == "1 view, 1 pass, 11 profiles"


# The context's numbers and the range each has, as an option and in a file.
CONTEXT_RANGES: dict[str, Limit] = {
    "scan_spec.delta_s_opt_mm": STEP_MM,  # export --spacing
    "scan_spec.alpha_max_deg": ORIENTATION_ERROR_DEG,
    "scan_spec.weights[1]": REWARD_WEIGHT,
    "scan_spec.tolerance_mm": TOLERANCE_MM,  # --tolerance MM,
    "scan_spec.tolerance_deg": ORIENTATION_ERROR_DEG,  # --tolerance ,DEG
    "scan_spec.profile_rate_hz": PROFILE_RATE_HZ,  # export --profile-rate
    "scan_spec.travel_speed_mm_s": SPEED_MM_S,  # export --travel-speed
    "scan_spec.clearance_mm": CLEARANCE_MM,
    "step_limits.dy_max_mm": STEP_MM,  # a policy's dy_max_mm
    "step_limits.dz_max_mm": STEP_MM,
    "step_limits.dtheta_max_deg": ANGLE_DEG,
    "step_limits.dphi_max_deg": ANGLE_DEG,
}


def with_value(data: dict[str, Any], path: str, value: Any) -> dict[str, Any]:
    """`data` with the field at `path` ('context.scan_spec.weights[1]') set to `value`, or
    left out (DELETE)."""
    node: Any = data
    *head, last = path.replace("[", ".").replace("]", "").split(".")
    for key in head:
        node = node[int(key)] if isinstance(node, list) else node[key]
    if value is DELETE:
        del node[last]
    else:
        node[int(last) if isinstance(node, list) else last] = value
    return data


def context_with(field: str, value: Any) -> dict[str, Any]:
    """The records with the context's `field` set to `value` (and the scan speed, rate x
    spacing, kept in the allowed range when one of the two is drawn)."""
    data = records()
    spec = data["context"]["scan_spec"]
    if field == "scan_spec.delta_s_opt_mm":
        spec["profile_rate_hz"] = PROFILE_RATE_HZ.lo
    if field == "scan_spec.profile_rate_hz":
        spec["delta_s_opt_mm"] = STEP_MM.lo
    with_value(data["context"], field, value)
    return data


def outside(limit: Limit) -> st.SearchStrategy[float]:
    below = st.floats(max_value=limit.lo, exclude_max=not limit.lo_open, allow_nan=False)
    above = st.floats(min_value=limit.hi, exclude_min=not limit.hi_open, allow_nan=False)
    return st.one_of(below, above, st.sampled_from([math.nan, math.inf, -math.inf]))


@pytest.mark.parametrize("suffix", SUFFIXES)
@pytest.mark.parametrize("field", sorted(CONTEXT_RANGES))
@QUICK
@given(data=st.data())
def test_a_context_number_out_of_its_range_is_one_line_naming_file_and_field(
    tmp_path, field, suffix, data
):
    limit = CONTEXT_RANGES[field]
    path = write_plan(tmp_path / f"plan{suffix}", context_with(field, data.draw(outside(limit))))
    with pytest.raises(ValueError) as err:
        read_plan(path)
    message = str(err.value)
    assert message.startswith(f"plan {path}: context.{field}: ") and "\n" not in message
    assert message.endswith(f"is not in {limit}")


@pytest.mark.parametrize("suffix", SUFFIXES)
@pytest.mark.parametrize("field", sorted(CONTEXT_RANGES))
@QUICK
@given(data=st.data())
def test_a_context_number_in_its_range_loads(tmp_path, field, suffix, data):
    limit = CONTEXT_RANGES[field]
    value = data.draw(st.floats(limit.lo, limit.hi, exclude_min=limit.lo_open))
    plan = use(write_plan(tmp_path / f"plan{suffix}", context_with(field, value)))
    node: Any = plan.context.to_json_dict()
    for key in field.replace("[", ".").replace("]", "").split("."):
        node = node[int(key)] if isinstance(node, list) else node[key]
    assert node == pytest.approx(value, rel=1e-12, abs=1e-300)


@pytest.mark.parametrize("suffix", SUFFIXES)
@pytest.mark.parametrize(
    ("field", "value", "message"),
    [
        # The three: an OverflowError, a 7e5 s cycle time, 564 lines from FCL.
        ("scan_spec.tolerance_mm", 1e200, r"tolerance_mm: 1e\+200 is not in \[0.001, 1000\] mm"),
        ("scan_spec.delta_s_opt_mm", 1e-6, r"delta_s_opt_mm: 1e-06 is not in \[0.001, 1000\] mm"),
        ("scan_spec.clearance_mm", 1e300, r"clearance_mm: 1e\+300 is not in \[0, 5000\] mm"),
        ("scan_spec.profile_rate_hz", 1e5, r"scan_spec: .* a scan speed of 50000 mm/s, more"),
        ("scan_spec.weights", [0, 0, 0], "scan_spec: weights: all 0"),
        ("scan_spec.weights", [1, 1], "weights: List should have at least 3"),
        ("scan_spec.tolerance_mm", "5", "tolerance_mm: Input should be a valid number"),
        pytest.param(
            "scan_spec.tolerance_mm",
            10**400,
            "tolerance_mm: Input should be a valid number",
            id="int",
        ),
        ("step_limits.dtheta_max_deg", 1e300, r"dtheta_max_deg: 1e\+300 is not in \[0.001, 180\]"),
    ],
)
def test_the_context_examples(tmp_path, suffix, field, value, message):
    path = write_plan(tmp_path / f"plan{suffix}", with_value(records(), f"context.{field}", value))
    with pytest.raises(ValueError, match=message) as err:
        read_plan(path)
    assert str(err.value).startswith(f"plan {path}: context.")


ROTATED = np.array([[0.0, -1, 0, 0], [1, 0, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]])


@pytest.mark.parametrize("suffix", SUFFIXES)
@pytest.mark.parametrize(
    ("path", "value", "message"),
    [
        # Records of the wrong JSON type, each in one line (once AttributeError, KeyError).
        ("context", [1, 2], "context: expected a JSON object"),
        ("context", "top", "context: expected a JSON object"),
        ("context", 3, "context: expected a JSON object"),
        ("context", {}, "context.format: Field required"),
        ("robot", [1], "robot: expected a JSON object"),
        ("robot", "ur10e", "robot: expected a JSON object"),
        ("robot.robot", DELETE, "robot.robot: Field required"),  # the arm without its name
        ("robot.T_base_part", ROTATED * 2, "robot.T_base_part: its 3x3 block is not a rotation"),
        ("robot.T_base_part.0.3", 1e300, r"T_base_part: translation x 1e\+300 is not in"),
        ("robot.T_flange_sensor.3.0", 1.0, r"T_flange_sensor: its last row is \[1.0, 0.0, 0.0"),
        # The configuration each pass is entered with: six finite joints at a pose index.
        ("robot.pass_entry_joints_deg", {"0": [0.0] * 5}, r"pass_entry_joints_deg.'0': List sh"),
        ("robot.pass_entry_joints_deg", {"first": [0.0] * 6}, r"pass_entry_joints_deg.first"),
        ("robot.pass_entry_joints_deg", [[0.0] * 6], r"pass_entry_joints_deg: expected a JSON"),
        ("views", {"index": 0}, "views: Input should be a valid list"),
        ("views", 7, "views: Input should be a valid list"),
        ("views.0", "top", r"views\[0\]: expected a JSON object"),
        ("views.0.passes", "4", r"views\[0\].passes: Input should be a valid integer"),
        ("views.0.axis", [0, 0, 2], r"views\[0\]: axis \[0.0, 0.0, 2.0\] is not a unit vector"),
        ("views.0.swaths", "lines", r"views\[0\].swaths: Input should be a valid list"),
        # Pass lines out of the part's frame or too long: refused before a closed loop runs.
        ("views.0.swaths.0.end_mm", [1e7, 0, 400], r"swaths\[0\].end_mm\[0\]: 10000000 is not"),
        ("views.0.swaths.0.start_mm.1", 1e300, r"swaths\[0\].start_mm\[1\]: 1e\+300 is not"),
        ("views.0.swaths.0.u", [0.6, 0.8, 0.0], r"swaths\[0\]: v \[0.0, 1.0, 0.0\] is not up x u"),
        ("cycle_time_s", [1], "cycle_time_s: Input should be a valid number"),
        ("cycle_time_s", "12", "cycle_time_s: Input should be a valid number"),
        ("cycle_time_s", 1e300, r"cycle_time_s: 1e\+300 is not in \[0, 1000000000\] s"),
        ("cycle_time_s", -1, r"cycle_time_s: -1 is not in \[0, 1000000000\] s"),
    ],
)
def test_records_of_the_wrong_type_or_size(tmp_path, suffix, path, value, message):
    data = with_value(records(), path, value.tolist() if isinstance(value, np.ndarray) else value)
    file = write_plan(tmp_path / f"plan{suffix}", data)
    with pytest.raises(ValueError, match=message) as err:
        read_plan(file)
    assert str(file) in str(err.value) and "\n" not in str(err.value)


def paths(node: Any, prefix: tuple = ()) -> list[tuple]:
    """Every path into a record: its keys, indices and nested ones."""
    out = [prefix] if prefix else []
    if isinstance(node, dict):
        for key, value in node.items():
            out += paths(value, (*prefix, key))
    elif isinstance(node, list):
        for i, value in enumerate(node):
            out += paths(value, (*prefix, i))
    return out


PATHS = paths(TRAJ.meta)


@pytest.mark.parametrize("suffix", SUFFIXES)
@FAST
@given(path=st.sampled_from(PATHS), value=st.one_of(st.just(DELETE), JSON_VALUES))
def test_any_value_in_any_field_of_the_record_loads_or_is_one_line(tmp_path, suffix, path, value):
    data = records()
    node: Any = data
    for key in path[:-1]:
        node = node[key]
    if value is DELETE:
        del node[path[-1]]
    else:
        node[path[-1]] = value
    one_line_or_ok(use, write_plan(tmp_path / f"plan{suffix}", data))


@pytest.mark.parametrize("suffix", SUFFIXES)
@FAST
@given(
    whole=st.fixed_dictionaries(
        {},
        optional={
            "context": JSON_VALUES,
            "robot": JSON_VALUES,
            "views": JSON_VALUES,
            "cycle_time_s": JSON_VALUES,
        },
    )
)
def test_any_value_as_a_whole_record_loads_or_is_one_line(tmp_path, suffix, whole):
    one_line_or_ok(use, write_plan(tmp_path / f"plan{suffix}", records() | whole))


def test_the_csv_header_stays_first_and_other_comments_are_free(tmp_path):
    path = write_plan(tmp_path / "plan.csv", records())
    lines = path.read_text().splitlines()
    assert lines[0] == ",".join(CSV_COLUMNS)
    path.write_text("\n".join([lines[0], "# made by hand: not a record", *lines[1:]]))
    assert use(path).cycle_time_s == 12.5
