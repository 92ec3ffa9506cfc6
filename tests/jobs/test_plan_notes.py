"""What `plan --robot` prints about the arm beside the coverage: the notes of its record."""

from __future__ import annotations

from dataclasses import replace
from types import SimpleNamespace

import numpy as np

from scanplan.core.plan import ArmRecord
from scanplan.jobs.plan import _arm_notes
from scanplan.robot.export.rotations import pose_from_xyzabc
from scanplan.robot.links import where_it_stands


def _notes(arm: ArmRecord) -> list[str]:
    return [text for text, _ in _arm_notes(SimpleNamespace(arm=arm))]  # type: ignore[arg-type]


def test_a_sensor_across_a_kuka_flange_is_noted_with_the_straight_tcp() -> None:
    record = {"part_pose": "500,0,0,0,0,0", "in_spec_free_plan": 0.9, "in_spec": 0.8}
    sideways = ArmRecord(
        "kr6-r900",
        pose_from_xyzabc([500, 0, 0, 0, 0, 0]),
        pose_from_xyzabc([0, 0, 90, 0, 0, 0]),
        record,
    )
    noted = [line for line in _notes(sideways) if line.startswith("note:")]
    assert noted == [
        "note: the sensor's beam is 90° off the flange's axis (kr6-r900: its flange's x axis "
        "points out of it); the sensor 90 mm straight out, looking along it, is "
        "--tcp 90,0,0,0,90,0"
    ]
    straight = replace(sideways, T_flange_sensor=pose_from_xyzabc([90, 0, 0, 0, 90, 0]))
    assert not [line for line in _notes(straight) if line.startswith("note:")]
    ur = replace(sideways, robot="ur5e")  # z is out of a UR's flange
    assert not [line for line in _notes(ur) if line.startswith("note:")]
    gone = replace(sideways, robot="/nowhere/arm.toml")  # an arm file no longer there
    assert not [line for line in _notes(gone) if line.startswith("note:")]


def test_where_the_arm_stands_is_said_for_setting_up_the_cell() -> None:
    block = (np.array([-300.0, -300.0, -800.0]), np.array([300.0, 300.0, 0.0]))
    # The part 250 mm out along the base's x, the base frame 1 mm over the table's top.
    on_top = pose_from_xyzabc([250, 0, -1, 0, 0, 0])
    stands = where_it_stands(on_top, block)
    assert stands == {
        "on_table": True,
        "level_with_top": True,
        "base_in_part_mm": [-250.0, 0.0, 1.0],
        "above_top_mm": 1.0,
    }
    # 700 mm out and 400 mm lower: beside the table, 400 mm below its top.
    beside = where_it_stands(pose_from_xyzabc([700, 0, 400, 0, 0, 0]), block)
    assert beside is not None and not beside["on_table"]
    assert beside["from_edge_mm"] == 400.0 and beside["above_top_mm"] == -400.0
    assert where_it_stands(on_top, None) is None  # no table: nothing to say
    record = {"part_pose": "250,0,-1,0,0,0", "in_spec_free_plan": 0.9, "in_spec": 0.9}
    arm = ArmRecord("ur5e", on_top, np.eye(4), record | {"stands": stands})
    assert (
        "the arm stands on the table's top, its base at (-250, 0, 1) mm in the part's frame, "
        "1 mm above it"
    ) in _notes(arm)
    arm = replace(arm, record=record | {"stands": beside})
    assert (
        "the arm stands beside the table, its base at (-700, 0, -400) mm in the part's frame, "
        "400 mm off its edge, 400 mm below the top"
    ) in _notes(arm)
    # Beyond the table's edge at its top's height: on a stand level with it.
    edge = where_it_stands(pose_from_xyzabc([350, 0, -1, 0, 0, 0]), block)
    assert edge is not None and edge["level_with_top"] and not edge["on_table"]
    arm = replace(arm, record=record | {"stands": edge})
    assert (
        "the arm stands level with the table's top beside it, its base at (-350, 0, 1) mm in "
        "the part's frame, 50 mm off its edge, 1 mm above the top"
    ) in _notes(arm)
    assert not [line for line in _notes(replace(arm, record=record)) if "stands" in line]
