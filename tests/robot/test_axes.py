"""External axes: the turntable's and the track's frames, their files, their values per
pose in the plan files, the programs that carry them and the time the arm waits on them."""

from __future__ import annotations

import numpy as np
import pytest

from scanplan.core.plan_file import read_trajectory, write_csv, write_json
from scanplan.core.quantities import ScanSpec
from scanplan.core.trajectory import Trajectory
from scanplan.planning.swaths import Swath
from scanplan.robot.axes import (
    ExternalAxes,
    Track,
    Turntable,
    axes_seconds,
    combined,
    load_positioner,
    plan_axes,
    track_of,
)
from scanplan.robot.export import (
    FORMATS,
    ExportOptions,
    export_program,
    parse_pose_arg,
    parse_program_details,
)
from scanplan.robot.export.axes_lines import HUNG_WORLD_BASE
from scanplan.robot.export.common import plan_motion
from scanplan.robot.export.krl import _frames as krl_frames

T0 = parse_pose_arg("600,100,-200,0,0,30")
TURNTABLE = ExternalAxes(turntable=Turntable(axis_point_mm=[50.0, -20.0, 0.0]))
TRACK = ExternalAxes(track=Track(direction=[0.0, 1.0, 0.0], length_mm=2000.0))
BOTH = ExternalAxes(TURNTABLE.turntable, TRACK.track)


def _rz(deg: float) -> np.ndarray:
    a = np.radians(deg)
    T = np.eye(4)
    T[:2, :2] = [[np.cos(a), -np.sin(a)], [np.sin(a), np.cos(a)]]
    return T


def test_the_turntable_turns_the_part_about_its_axis():
    T = TURNTABLE.base_part(T0, np.array([[0.0], [90.0], [-45.0]]))
    assert np.allclose(T[0], T0)
    p = np.array([50.0, -20.0, 0.0])
    shift, back = np.eye(4), np.eye(4)
    shift[:3, 3], back[:3, 3] = p, -p
    for k, deg in enumerate((0.0, 90.0, -45.0)):
        assert np.allclose(T[k], T0 @ shift @ _rz(deg) @ back)
    # A point on the axis stays where it is; one beside it turns round it.
    on_axis = np.array([50.0, -20.0, 123.0, 1.0])
    assert np.allclose(T[1] @ on_axis, T0 @ on_axis)
    beside = np.array([150.0, -20.0, 0.0, 1.0])
    assert np.allclose((np.linalg.inv(T0) @ T[1] @ beside)[:3], [50.0, 80.0, 0.0])


def test_the_track_moves_the_part_against_the_arm():
    T = TRACK.base_part(T0, np.array([[0.0], [300.0]]))
    assert np.allclose(T[0], T0)
    assert np.allclose(T[1][:3, :3], T0[:3, :3])
    assert np.allclose(T[1][:3, 3], T0[:3, 3] - [0.0, 300.0, 0.0])
    both = BOTH.base_part(T0, np.array([[90.0, 300.0]]))[0]
    assert np.allclose(both, TRACK.base_part(TURNTABLE.base_part(T0, [[90.0]])[0], [[300.0]])[0])


def test_positioner_files_and_presets(tmp_path):
    assert load_positioner("turntable").turntable is not None
    path = tmp_path / "cell.toml"
    path.write_text(
        "[turntable]\nlimits_deg = [-90.0, 90.0]\nspeed_deg_s = 30.0\n"
        "[track]\nlength_mm = 1500.0\ndirection = [1.0, 0.0, 0.0]\n"
    )
    axes = load_positioner(path)
    assert axes.names == ("turntable_deg", "track_mm")
    assert np.allclose(axes.limits, [[-90, 90], [-750, 750]])
    assert np.allclose(axes.speeds, [30.0, 500.0])
    assert ExternalAxes.of_record(axes.record(), "x") == axes


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("[turntable]\nlimits_deg = [90.0, -90.0]\n", "turntable: Value error, limits_deg"),
        ("[turntable]\nspeed_deg_s = -1.0\n", "turntable.speed_deg_s"),
        ("[turntable]\nradius = 3.0\n", "turntable.radius"),
        ("[track]\nlength_mm = 1e9\n", "track.length_mm"),
        ("", "give a [turntable] or a [track]"),
        ("[turntable\n", "cannot be parsed"),
    ],
)
def test_a_bad_positioner_file_is_one_line(tmp_path, text, message):
    path = tmp_path / "bad.toml"
    path.write_text(text)
    with pytest.raises(ValueError) as err:
        load_positioner(path)
    assert message.split(": Value error")[0] in str(err.value)
    assert "\n" not in str(err.value)


def test_options_name_what_is_wrong():
    with pytest.raises(ValueError, match="choose turntable"):
        load_positioner("carousel")
    with pytest.raises(ValueError, match="--track -5"):
        track_of(-5.0)
    with pytest.raises(ValueError, match="give the track once"):
        combined(BOTH, track_of(1000.0))
    assert combined(None, None) is None
    assert combined(TURNTABLE, track_of(1000.0)).names == ("turntable_deg", "track_mm")


def _views_traj(external: np.ndarray | None = None) -> Trajectory:
    """Two views of two passes each, a move into each view, in the part frame."""
    poses, swath, scanning = [], [], []
    for k, y in enumerate((-40.0, -10.0, 10.0, 40.0)):
        a, b = np.array([-80.0, y, 120.0]), np.array([80.0, y, 120.0])
        sw = Swath(k, a, b, np.array([1.0, 0, 0]), np.array([0, 1.0, 0]))
        n = 30
        move = sw.poses(np.zeros(3), np.zeros(3), np.zeros(3))
        move[:, 2, 3] += [80.0, 60.0, 40.0]
        poses += [move, sw.poses(np.linspace(0, 160, n), np.zeros(n), np.zeros(n))]
        swath += [np.full(3, k), np.full(n, k)]
        scanning += [np.zeros(3, bool), np.ones(n, bool)]
    views = [
        {"index": v, "axis": [0.0, 0.0, 1.0], "first_swath": 2 * v, "last_swath": 2 * v + 1}
        for v in range(2)
    ]
    return Trajectory(
        np.concatenate(poses),
        np.concatenate(swath),
        np.concatenate(scanning),
        meta={"views": views},
        external=external,
    )


def test_plan_files_carry_the_values_per_pose(tmp_path):
    n = len(_views_traj())
    values = np.column_stack([np.repeat([0.0, 90.0], n // 2), np.linspace(-100, 100, n)])
    traj = _views_traj(values)
    for name, write in (("p.csv", write_csv), ("p.json", write_json)):
        write(traj, tmp_path / name)
        back = read_trajectory(tmp_path / name)
        assert back.external is not None
        assert np.allclose(back.external, values, atol=1e-6)
        assert back.subset(back.scanning).external.shape == (int(traj.scanning.sum()), 2)
    # A plan of the arm alone stays as it was: no columns, no field, nothing read back.
    write_csv(_views_traj(), tmp_path / "old.csv")
    assert (tmp_path / "old.csv").read_text().splitlines()[0].endswith("qz")
    assert read_trajectory(tmp_path / "old.csv").external is None


def test_a_plan_whose_values_and_axes_disagree_is_refused():
    n = len(_views_traj())
    record = {"external_axes": TURNTABLE.record()}
    with pytest.raises(ValueError, match="2 external axis values per pose, 1 axes"):
        plan_axes(record, np.zeros((n, 2)), "plan p")
    with pytest.raises(ValueError, match="beyond its range"):
        plan_axes(record, np.full((n, 1), 400.0), "plan p")
    with pytest.raises(ValueError, match="no external_axes record"):
        plan_axes({}, np.zeros((n, 1)), "plan p")
    assert plan_axes(record, np.zeros((n, 1)), "plan p") == TURNTABLE
    assert plan_axes({}, None, "plan p") is None


def _turntable_traj() -> Trajectory:
    traj = _views_traj()
    first = traj.swath >= 2
    return Trajectory(
        traj.poses,
        traj.swath,
        traj.scanning,
        meta=traj.meta,
        external=np.where(first, 120.0, -30.0)[:, None],
    )


@pytest.mark.parametrize("fmt", list(FORMATS))
@pytest.mark.parametrize("which", ["turntable", "track", "overhead track"])
def test_programs_carry_the_axes_and_read_back_to_the_planned_poses(fmt, which):
    part_pose = T0
    if which == "turntable":
        axes, traj = TURNTABLE, _turntable_traj()
    else:
        axes = TRACK
        if which == "overhead track":  # the arm hung upside down: its base's z points down
            axes = ExternalAxes(track=TRACK.track.model_copy(update={"mount": "overhead"}))
            part_pose = HUNG_WORLD_BASE @ T0
        base = _views_traj()
        traj = Trajectory(
            base.poses, base.swath, base.scanning, meta=base.meta,
            external=base.positions_mm[:, :1] * 0.5 - 30.0,
        )  # fmt: skip
    options = ExportOptions(part_pose=part_pose, scan=ScanSpec(), axes=axes)
    if fmt == "urscript" and which != "turntable":
        with pytest.raises(ValueError, match="drives no external axes"):
            export_program(traj, fmt, options)
        return
    motion = plan_motion(traj, options)
    text = export_program(traj, fmt, options)
    parsed = parse_program_details(text, fmt)
    assert traj.external is not None
    expected = axes.base_part(part_pose, traj.external) @ traj.poses
    assert np.allclose(parsed.poses, expected[motion.source], atol=1e-4)
    assert parsed.external is not None
    assert np.allclose(parsed.external, traj.external[motion.source], atol=1e-5)
    if which == "overhead track" and fmt == "krl":  # $BASE in the upright $WORLD
        assert "$ROBROOT = {X 0.000000,Y 0.000000,Z 0.000000,A 0.000000,B 0.000000,C 180" in text
        assert f"$BASE = {krl_frames(T0[None])[0]}" in text
    if which == "overhead track" and fmt == "rapid":
        assert "ceiling-mounted (gravity beta 180 deg" in text
    # Read as if the part stood still, the targets of the turned view would be elsewhere.
    still = part_pose @ traj.poses[motion.source]
    moved = np.abs(traj.external[motion.source, 0]) > 1e-9
    assert not np.allclose(parsed.poses[moved], still[moved], atol=1.0)


def test_a_plan_with_axes_exports_only_with_them():
    with pytest.raises(ValueError, match="external axis values and the program's axes"):
        plan_motion(_turntable_traj(), ExportOptions(part_pose=T0))


def test_the_turntable_turns_between_views_on_a_joint_move():
    traj = _turntable_traj()
    joints = np.zeros((len(traj), 6))
    options = ExportOptions(part_pose=T0, axes=TURNTABLE, joints_rad=joints)
    motion = plan_motion(traj, options)
    assert motion.axis_step is not None and motion.external is not None
    (step,) = np.flatnonzero(motion.axis_step)
    assert motion.external[step - 1, 0] == -30.0 and motion.external[step, 0] == 120.0
    assert motion.blend_mm[step - 1] == 0.0 and motion.blend_mm[step] == 0.0
    text = export_program(traj, "krl", options)
    assert "E1 120.000000" in text and "E1 -30.000000" in text
    script = export_program(traj, "urscript", options)
    assert script.count("wait for input") == 2  # the first angle, then one turn
    assert "turntable's controller steps" in script


def test_the_arm_waits_on_the_turntable_and_on_a_track_too_slow_to_follow():
    spec = ScanSpec()
    traj = _turntable_traj()
    # One turn of 150 degrees at 60 deg/s and 120 deg/s^2: 150/60 + 60/120 s.
    assert axes_seconds(traj, TURNTABLE, spec, 100.0) == pytest.approx(3.0)
    base = _views_traj()
    follow = Trajectory(
        base.poses, base.swath, base.scanning, external=base.positions_mm[:, :1].copy()
    )
    # Following the sensor at 100 mm/s with a 500 mm/s track: no wait; at 20 mm/s, a wait.
    assert axes_seconds(follow, TRACK, spec, 100.0) == pytest.approx(0.0, abs=1e-9)
    slow = ExternalAxes(track=Track(direction=[0.0, 1.0, 0.0], length_mm=2000, speed_mm_s=20))
    assert axes_seconds(follow, slow, spec, 100.0) > 4 * 160 * (1 / 20 - 1 / 100) * 0.9


def test_a_rosbag_of_a_plan_with_axes_is_refused_not_misread(tmp_path):
    from scanplan.robot.export import export_rosbag

    options = ExportOptions(part_pose=T0, axes=TURNTABLE)
    with pytest.raises(ValueError, match="rosbag2 does not carry external axes"):
        export_rosbag(_turntable_traj(), tmp_path / "bag", options)
    assert not (tmp_path / "bag").exists()


def test_the_turntable_disk_is_an_obstacle_of_the_links():
    from scanplan.robot.axes import with_disk
    from scanplan.robot.links import obstacles_for
    from scanplan.world.cell import Cell
    from scanplan.world.part import load_part

    part = load_part("training-piece")
    lo = part.bounds[0]
    axes = ExternalAxes(turntable=Turntable(axis_point_mm=[float(v) for v in lo], radius_mm=900))
    cell = Cell()
    # A capsule 800 mm out from the axis, 100 mm below the disk's top: inside its body.
    ends = np.array([[[lo + [800.0, 0.0, -100.0], lo + [800.0, 0.0, -150.0]]]])
    radii = np.array([10.0])
    assert obstacles_for(part, cell).capsules_hit(ends, radii, 5.0)[0, 0] == -1
    hit = obstacles_for(part, with_disk(cell, axes)).capsules_hit(ends, radii, 5.0)[0, 0]
    assert hit == 2  # counted with the table
    beyond = ends + [200.0, 0.0, 0.0]  # 1000 mm out: beside the disk
    assert obstacles_for(part, with_disk(cell, axes)).capsules_hit(beyond, radii, 5.0)[0, 0] == -1
