"""What `plan --robot` prints about the arm beside the coverage: the notes of its record."""

from __future__ import annotations

from dataclasses import replace
from types import SimpleNamespace

from scanplan.core.plan import ArmRecord
from scanplan.jobs.plan import _arm_notes
from scanplan.robot.export.rotations import pose_from_xyzabc


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
