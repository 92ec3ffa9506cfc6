"""Trajectory files (CSV and JSON): exact round trips, and bad input of any shape in one line
naming the file, the line and the field."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from helpers import FAST, JSON_VALUES, one_line_or_ok
from scanplan.core.plan_file import read_csv, read_json, read_trajectory, write_csv, write_json
from scanplan.core.trajectory import Trajectory, half_turns, lead_ins, lead_tops, pass_entries
from scanplan.planning.swaths import Swath


def _trajectory() -> Trajectory:
    sw = Swath(0, np.array([0.0, 5, 400]), np.array([100.0, 5, 400]), np.eye(3)[0], np.eye(3)[1])
    poses = sw.poses(np.linspace(0, 100, 11), np.linspace(0, 3, 11), np.linspace(-0.2, 0.2, 11))
    swath = np.r_[np.zeros(6, int), np.ones(5, int)]
    return Trajectory(poses, swath, np.arange(11) != 5, planner="test")


def test_trajectory_csv_and_json_round_trip(tmp_path):
    traj = _trajectory()
    write_csv(traj, tmp_path / "t.csv")
    back = read_csv(tmp_path / "t.csv")
    assert np.allclose(back.poses, traj.poses, atol=1e-6)
    assert np.array_equal(back.swath, traj.swath)
    assert np.array_equal(back.scanning, traj.scanning)
    header = (tmp_path / "t.csv").read_text().splitlines()[0]
    assert header == "swath,scanning,x_mm,y_mm,z_mm,qw,qx,qy,qz"
    write_json(traj, tmp_path / "t.json")
    assert np.allclose(read_json(tmp_path / "t.json").poses, traj.poses, atol=1e-9)


@pytest.mark.parametrize(
    ("body", "message"),
    [
        ("", "empty"),
        ("a,b,c\n1,2,3\n", "line 1: header"),
        ("swath,scanning,x_mm,y_mm,z_mm,qw,qx,qy,qz\n", "no poses"),
        ("swath,scanning,x_mm,y_mm,z_mm,qw,qx,qy,qz\n0,1,0,0,400,1,0,0\n", "line 2: expected 9"),
        ("swath,scanning,x_mm,y_mm,z_mm,qw,qx,qy,qz\n0,1,0,0,x,1,0,0,0\n", "z_mm: not a number"),
        ("swath,scanning,x_mm,y_mm,z_mm,qw,qx,qy,qz\n0,1,0,0,nan,1,0,0,0\n", "non-finite"),
        ("swath,scanning,x_mm,y_mm,z_mm,qw,qx,qy,qz\n0,1,0,0,4,0,0,0,0\n", "zero length"),
        ("swath,scanning,x_mm,y_mm,z_mm,qw,qx,qy,qz\n0,3,0,0,4,1,0,0,0\n", "scanning column"),
    ],
)
def test_malformed_trajectory_files(tmp_path, body, message):
    path = tmp_path / "bad.csv"
    path.write_text(body)
    with pytest.raises(ValueError, match=message):
        read_csv(path)


def test_trajectory_json_fields_are_checked(tmp_path):
    traj = _trajectory()
    write_json(traj, tmp_path / "t.json")
    good = json.loads((tmp_path / "t.json").read_text())
    cases = [
        ({"planner": 3}, "planner"),
        ({"plan_time_s": "fast"}, "plan_time_s"),
        ({"poses": [{**good["poses"][0], "position_mm": [0, 0]}]}, r"poses\[0\].position_mm"),
        ({"poses": [{**good["poses"][0], "swath": 10**20}]}, r"poses\[0\].swath"),
        ({"poses": [{**good["poses"][0], "scanning": "yes"}]}, r"poses\[0\].scanning"),
        ({"poses": [{**good["poses"][0], "quaternion_wxyz": [0, 0, 0, 0]}]}, "zero length"),
        ({"poses": []}, "poses"),
    ]
    for change, message in cases:
        path = tmp_path / "bad.json"
        path.write_text(json.dumps({**good, **change}))
        with pytest.raises(ValueError, match=message) as err:
            read_json(path)
        assert str(path) in str(err.value) and "\n" not in str(err.value)
    path.write_text(json.dumps({**good, "plan_time_s": math.nan}))  # Python's json writes NaN
    with pytest.raises(ValueError, match="plan_time_s"):
        read_json(path)
    path.write_text("[" * 100_000 + "]" * 100_000)
    with pytest.raises(ValueError, match="nested too deeply"):
        read_json(path)


def test_json_writer_never_writes_nan(tmp_path):
    traj = _trajectory()
    write_json(Trajectory(traj.poses, traj.swath, traj.scanning, planner="p"), tmp_path / "t.json")
    text = (tmp_path / "t.json").read_text()
    assert "NaN" not in text and "Infinity" not in text


def test_trajectory_csv_with_bom_and_swath_overflow(tmp_path):
    traj = _trajectory()
    write_csv(traj, tmp_path / "t.csv")
    text = (tmp_path / "t.csv").read_text()
    (tmp_path / "bom.csv").write_text("\ufeff" + text)
    assert len(read_csv(tmp_path / "bom.csv")) == len(traj)
    lines = text.splitlines()
    lines[3] = "1e20" + lines[3][lines[3].index(",") :]
    (tmp_path / "big.csv").write_text("\n".join(lines))
    with pytest.raises(ValueError, match="line 4, column swath"):
        read_csv(tmp_path / "big.csv")
    with pytest.raises(ValueError, match="32-bit"):
        Trajectory(traj.poses, np.full(len(traj), 1e20), traj.scanning)


@pytest.mark.parametrize("suffix", [".csv", ".json"])
@FAST
@given(content=st.binary(max_size=600))
def test_trajectory_files_of_arbitrary_bytes(tmp_path, suffix, content):
    path = tmp_path / f"t{suffix}"
    path.write_bytes(content)
    one_line_or_ok(read_trajectory, path)


POSE_KEYS = ["swath", "scanning", "position_mm", "quaternion_wxyz"]


def _pose_like() -> st.SearchStrategy[dict]:
    good = {
        "swath": 0,
        "scanning": True,
        "position_mm": [0, 0, 400],
        "quaternion_wxyz": [1, 0, 0, 0],
    }
    return st.dictionaries(st.sampled_from(POSE_KEYS + ["extra"]), JSON_VALUES, max_size=5).map(
        lambda d: {**good, **d}
    )


@FAST
@given(
    doc=st.one_of(
        JSON_VALUES,
        st.fixed_dictionaries(
            {"poses": st.lists(_pose_like(), max_size=4)},
            optional={"planner": JSON_VALUES, "plan_time_s": JSON_VALUES},
        ),
    )
)
def test_trajectory_json_of_arbitrary_values(tmp_path, doc):
    path = tmp_path / "t.json"
    path.write_text(json.dumps(doc))
    one_line_or_ok(read_trajectory, path)


def test_the_top_of_the_move_into_a_pass_and_where_a_plan_enters_it():
    # Pass 0, a move up 100, over 300 in three steps and down 100 (carrying pass 1's index),
    # pass 1; then pass 2 straight after pass 1, with no move of its own.
    xyz = [[0, 0, 0], [200, 0, 0]]
    xyz += [[200, 0, 100], [200, 100, 100], [200, 200, 100], [200, 300, 100]]
    xyz += [[200, 300, 0], [0, 300, 0], [0, 400, 0], [200, 400, 0]]
    poses = np.tile(np.eye(4), (len(xyz), 1, 1))
    poses[:, :3, 3] = xyz
    swath = [0, 0, 1, 1, 1, 1, 1, 1, 2, 2]
    scanning = [True, True, False, False, False, False, True, True, True, True]
    traj = Trajectory(poses, swath, scanning)
    top = lead_tops(traj)
    # The via point farthest from both passes: (200, 100, 100) and (200, 200, 100) tie at
    # 141 mm; the first is taken. A pass no move leads into is its own top.
    assert {int(i): int(t) for i, t in enumerate(top) if t >= 0} == {0: 0, 6: 3, 8: 8}
    # A plan that starts with a move: its top is where the move is farthest from the pass.
    start = Trajectory(poses[2:], swath[2:], scanning[2:])
    assert lead_tops(start)[4] == 0
    # The moves into the passes: pass 1's four, no other pose.
    np.testing.assert_array_equal(np.flatnonzero(lead_ins(traj)), [2, 3, 4, 5])
    # A sensor turned half about its beam between two poses, not one turned 60°.
    turned = poses.copy()
    turned[3:, :3, :3] = np.diag([-1.0, -1.0, 1.0])  # from pose 3 on: half a turn
    c, s60 = 0.5, np.sqrt(3) / 2
    turned[8:, :3, :3] = turned[8:, :3, :3] @ [[c, -s60, 0], [s60, c, 0], [0, 0, 1]]
    np.testing.assert_array_equal(
        np.flatnonzero(half_turns(Trajectory(turned, swath, scanning))), [3]
    )
    # Entered at each pass's first pose, unless the plan's arm record says where.
    np.testing.assert_array_equal(np.flatnonzero(pass_entries(traj)), [0, 6, 8])
    record = {"pass_entry_joints_deg": {"0": [0.0] * 6, "3": [0.0] * 6, "8": [0.0] * 6}}
    entered = Trajectory(poses, swath, scanning, meta={"robot": record})
    np.testing.assert_array_equal(np.flatnonzero(pass_entries(entered)), [0, 3, 8])
    # A part of the plan has other pose indices: it enters at each pass's first pose.
    part = entered.subset(np.arange(len(entered)) >= 2)
    assert "pass_entry_joints_deg" not in part.meta["robot"]
    np.testing.assert_array_equal(np.flatnonzero(pass_entries(part)), [4, 6])
