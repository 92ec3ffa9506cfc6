"""A plan flown with external axes: each view's setting is where the arm flies most of it,
the fit and export's check see the part where the axes put it."""

from __future__ import annotations

import numpy as np
import trimesh
from typer.testing import CliRunner

from scanplan.cli import app
from scanplan.core.sensor_spec import SensorSpec
from scanplan.core.trajectory import Trajectory
from scanplan.planning.swaths import Swath
from scanplan.robot import check_reach
from scanplan.robot.axes import ExternalAxes, Track, Turntable, part_poses
from scanplan.robot.axes_fit import (
    NEAR_BEST,
    _pick,
    _scores,
    candidates,
    choose_values,
    hangs,
)
from scanplan.robot.axes_kept import kept_each, reach_bound_each, values_at
from scanplan.robot.axes_place import place_on_axes
from scanplan.robot.export import parse_pose_arg
from scanplan.robot.fit import fit_to_robot
from scanplan.robot.flyable import check_flyable, stands_clear
from scanplan.robot.links import column_clear, obstacles_for
from scanplan.robot.presets import get_robot
from scanplan.world.cell import Cell
from scanplan.world.part import Part

TCP = parse_pose_arg("0,0,90,0,0,0")
# The turntable's axis 700 mm out along the UR5e's x: its near side within reach, its far
# side (300 mm beyond the axis) out of it until the table turns it round.
T0 = parse_pose_arg("700,0,-150,0,0,0")
TURNTABLE = ExternalAxes(turntable=Turntable(axis_point_mm=[0.0, 0.0, 0.0]))


def _near_and_far(n: int = 40) -> Trajectory:
    """Two views, one pass each, 300 mm either side of the axis (part frame), looking down."""
    poses, swath = [], []
    for k, x in enumerate((-300.0, 300.0)):
        a, b = np.array([x, -60.0, 150.0]), np.array([x, 60.0, 150.0])
        sw = Swath(k, a, b, np.array([0.0, 1.0, 0]), np.array([-1.0, 0.0, 0]))
        poses.append(sw.poses(np.linspace(0, 120, n), np.zeros(n), np.zeros(n)))
        swath.append(np.full(n, k))
    views = [
        {"index": k, "axis": [0.0, 0.0, 1.0], "first_swath": k, "last_swath": k, "passes": 1}
        for k in range(2)
    ]
    return Trajectory(
        np.concatenate(poses), np.concatenate(swath), np.ones(2 * n, bool), meta={"views": views}
    )


def _reached(traj: Trajectory, T: np.ndarray) -> np.ndarray:
    flange = T @ traj.poses @ np.linalg.inv(TCP)
    report = check_reach(flange, "ur5e", swath=traj.swath, scanning=traj.scanning)
    return ~np.isnan(report.joints).any(axis=1)


def test_the_far_view_is_turned_round_and_the_near_one_left():
    traj = _near_and_far()
    far = traj.swath == 1
    assert not _reached(traj, T0)[far].any()  # the arm alone cannot reach the far view
    with_axes, settings = choose_values(traj, "ur5e", TCP, T0, TURNTABLE)
    assert with_axes.external is not None
    angles = with_axes.external[:, 0]
    # Each view holds one angle; the far one is turned well round towards the arm (the
    # first angle that brings it all within reach, nearest the last view's), the near one
    # kept near where it is.
    assert len(np.unique(angles[far])) == 1 and len(np.unique(angles[~far])) == 1
    assert abs(angles[far][0]) >= 60.0
    assert abs(angles[~far][0]) <= 45.0
    assert [float(s[0]) for s in settings] == [angles[~far][0], angles[far][0]]
    reached = _reached(with_axes, part_poses(T0, with_axes.external, TURNTABLE))
    assert reached.all()
    fit = fit_to_robot(with_axes, "ur5e", TCP, T0, axes=TURNTABLE)
    assert fit.flyable and not fit.given_up
    assert fit.traj.external is not None and len(fit.traj.external) == len(fit.traj)
    # The same fit without the axes gives the far view up.
    alone = fit_to_robot(traj.subset(~far | far), "ur5e", TCP, T0)
    assert alone.given_up.get(1, 0) > 0


def test_the_track_follows_the_sensor_at_the_offset_held():
    traj = _near_and_far()
    track = ExternalAxes(track=Track(direction=[1.0, 0.0, 0.0], length_mm=1000.0))
    values = values_at(track, np.array([200.0]), T0, traj.poses, np.linalg.inv(TCP))
    flange_x = (T0 @ traj.poses @ np.linalg.inv(TCP))[:, 0, 3]
    assert np.allclose(values[:, 0], np.clip(flange_x - 200.0, -500.0, 500.0))
    with_axes, _ = choose_values(traj, "ur5e", TCP, T0, track)
    assert with_axes.external is not None
    assert _reached(with_axes, part_poses(T0, with_axes.external, track)).all()


def test_plan_options_need_an_arm_and_name_a_bad_file(tmp_path):
    runner = CliRunner()
    out = tmp_path / "p.json"
    result = runner.invoke(app, ["plan", "training-piece", "-o", str(out), "--track", "1000"])
    assert result.exit_code != 0 and "--track needs --robot" in result.output
    bad = tmp_path / "bad.toml"
    bad.write_text("[turntable]\nspeed_deg_s = 0.0\n")
    result = runner.invoke(
        app, ["plan", "training-piece", "-o", str(out), "--robot", "ur5e", "--positioner", str(bad)]
    )
    assert result.exit_code != 0
    assert "turntable.speed_deg_s" in result.output
    assert "Traceback" not in result.output and not out.exists()


def test_the_arm_stands_clear_of_the_table_all_along_its_rail():
    """A 400 x 200 mm plate on its table, the arm's base 800 mm off its centre in x and
    300 mm above the table (beside it, on the floor's riser): clear on a short track along
    the table's side, not on a 2 m track running towards it, whose far stands hang over
    the table (checked at the track's zero only, this placement passed)."""
    plate = Part(trimesh.creation.box((400.0, 200.0, 10.0)), name="plate")
    obstacles = obstacles_for(plate, Cell.around(plate))
    arm = get_robot("kr6-r900")
    T = np.eye(4)
    T[:3, 3] = [800.0, 0.0, -295.0]  # the part's origin in the base frame: the base at x = -800
    assert column_clear(arm, T, obstacles.table_block, obstacles.clearance_mm).all()
    alone = ExternalAxes(track=Track(direction=[0.0, 1.0, 0.0], length_mm=200.0))
    assert stands_clear(arm, T, alone, obstacles)
    towards = ExternalAxes(track=Track(direction=[1.0, 0.0, 0.0], length_mm=2000.0))
    assert not stands_clear(arm, T, towards, obstacles)


def test_export_check_refuses_an_arm_whose_rail_runs_into_the_table():
    """The same plate and stand: a pass over the plate flown with the arm on the short
    track beside the table is flyable as far as the column goes, on the 2 m track running
    towards the table it is refused, and the problem names the column and the base."""
    plate = Part(trimesh.creation.box((400.0, 200.0, 10.0)), name="plate")
    cell = Cell.around(plate)
    arm = get_robot("kr6-r900")
    T = np.eye(4)
    T[:3, 3] = [800.0, 0.0, -295.0]
    n = 20
    sw = Swath(
        0,
        np.array([-100.0, -60.0, 150.0]),
        np.array([-100.0, 60.0, 150.0]),
        np.array([0.0, 1.0, 0]),
        np.array([-1.0, 0.0, 0]),
    )
    poses = sw.poses(np.linspace(0, 120, n), np.zeros(n), np.zeros(n))
    traj = Trajectory(poses, np.zeros(n, int), np.ones(n, bool), external=np.zeros((n, 1)))
    for length, direction, refused in (
        (200.0, [0.0, 1.0, 0.0], False),
        (2000.0, [1.0, 0.0, 0.0], True),
    ):
        axes = ExternalAxes(track=Track(direction=direction, length_mm=length))
        found = check_flyable(traj, arm, T, TCP, plate, cell, SensorSpec(), axes=axes)
        columns = [p for p in found.problems if "column" in p[1]]
        assert bool(columns) == refused, found.problems
    assert "(base at -800, 0, 295 mm in the part's frame)" in columns[0][1]


def _raster(width_x: float, length_y: float, z: float, step: float = 100.0) -> Trajectory:
    """Passes along y over a width_x x length_y plate centred on the origin, looking down
    from z, `step` apart (one view)."""
    poses, swath = [], []
    xs = np.arange(-width_x / 2 + step / 2, width_x / 2, step)
    for k, x in enumerate(xs):
        a, b = np.array([x, -length_y / 2, z]), np.array([x, length_y / 2, z])
        sw = Swath(k, a, b, np.array([0.0, 1.0, 0]), np.array([-1.0, 0.0, 0]))
        poses.append(sw.poses(np.linspace(0, length_y, 30), np.zeros(30), np.zeros(30)))
        swath.append(np.full(30, k))
    n = sum(len(p) for p in poses)
    return Trajectory(np.concatenate(poses), np.concatenate(swath), np.ones(n, bool))


def test_a_panel_beyond_a_floor_track_is_flown_from_an_overhead_one():
    """A 1.4 x 1.6 m panel: from a floor track beside its table a KR 6 reaches less than
    half of it, hung from an overhead track over it nearly all; the tool hangs the arm
    (its base's z down, the track's mount 'overhead') unless the track is given as a floor
    one, and a small plate keeps the floor track."""
    arm = get_robot("kr6-r900")
    for size, traj_z in (((1400.0, 1600.0), 300.0), ((400.0, 200.0), 300.0)):
        plate = Part(trimesh.creation.box((*size, 10.0)), name="plate")
        obstacles = obstacles_for(plate, Cell.around(plate))
        traj = _raster(size[0] - 100.0, size[1] - 100.0, traj_z)
        beside = np.eye(4)
        beside[:3, 3] = [size[0] / 2 + 600.0, 0.0, -295.0]
        chosen = {}
        for mount in (None, "floor"):
            axes = ExternalAxes(track=Track(length_mm=2000.0, mount=mount))
            T, resolved = place_on_axes(traj, arm, TCP, axes, plate, beside, obstacles)
            assert resolved.track is not None
            assert resolved.track.mount == ("overhead" if hangs(T) else "floor")
            assert stands_clear(arm, T, resolved, obstacles)
            chosen[mount] = resolved.track.mount
        assert chosen["floor"] == "floor"
        assert chosen[None] == ("overhead" if size[0] > 1000 else "floor")


def test_a_hung_arm_clears_the_table_above_it_not_in_it():
    plate = Part(trimesh.creation.box((400.0, 200.0, 10.0)), name="plate")
    obstacles = obstacles_for(plate, Cell.around(plate))
    arm = get_robot("kr6-r900")
    ok = []
    for height in (900.0, 100.0):  # the base above the table's top
        T_part_base = np.diag([1.0, -1.0, -1.0, 1.0])
        T_part_base[:3, 3] = [0.0, 0.0, -5.0 + height]
        ok.append(column_clear(arm, np.linalg.inv(T_part_base), obstacles.table_block, 20.0)[0])
    assert ok == [True, False]


def test_a_turntable_and_a_track_are_placed_together():
    """A turntable with a track (mount open) on the small plate: a placement whose column
    stands clear and, upright, outside the disk (a hung arm may hang over it)."""
    plate = Part(trimesh.creation.box((400.0, 200.0, 10.0)), name="plate")
    obstacles = obstacles_for(plate, Cell.around(plate))
    arm = get_robot("kr6-r900")
    axes = ExternalAxes(Turntable(limits_deg=[-30.0, 30.0]), Track(length_mm=2000.0))
    beside = np.eye(4)
    beside[:3, 3] = [800.0, 0.0, -295.0]
    T, resolved = place_on_axes(
        _raster(300.0, 100.0, 300.0), arm, TCP, axes, plate, beside, obstacles
    )
    assert stands_clear(arm, T, resolved, obstacles)
    assert resolved.turntable is not None and resolved.turntable.axis_point_mm is not None
    base = np.linalg.inv(T)[:3, 3]
    off_axis = np.hypot(*(base - resolved.turntable.axis_point_mm)[:2])
    assert hangs(T) or off_axis >= resolved.turntable.radius_mm


def test_the_placement_judges_a_turntable_with_a_track_on_a_coarser_grid():
    arm = get_robot("kr6-r900")
    both = ExternalAxes(Turntable(), Track(length_mm=2000.0))
    fine, coarse = candidates(both, arm), candidates(both, arm, coarse=True)
    assert len(fine) == 24 * 9 and len(coarse) == 8 * 5
    # Every coarse setting is one the views may be given (the grid thinned, not moved).
    assert all((np.abs(fine - c).sum(axis=1) < 1e-9).any() for c in coarse)
    # One axis alone keeps its grid: the coarse one would lose settings it can afford.
    alone = ExternalAxes(Turntable())
    np.testing.assert_array_equal(candidates(alone, arm, coarse=True), candidates(alone, arm))


def _box_cell():
    """The cell of a 500 x 200 x 60 mm box on its table, as the links and sensor see it."""
    box = Part(trimesh.creation.box((500.0, 200.0, 60.0)))
    return obstacles_for(box, Cell.around(box), SensorSpec(), 20.0)


def test_several_paths_in_one_reach_check_are_followed_as_if_alone():
    # The far view turned to each of a few angles: one check with restarts gives each
    # copy the joints it gets checked alone (no joints carried over from the copy before).
    traj = _near_and_far(12)
    inv = np.linalg.inv(TCP)
    alone, copies, swaths = [], [], []
    for k, angle in enumerate((0.0, 90.0, 180.0, 270.0)):
        T = part_poses(T0, np.full((len(traj), 1), angle), TURNTABLE)
        flange = T @ traj.poses @ inv
        alone.append(check_reach(flange, "ur5e", swath=traj.swath, scanning=traj.scanning).joints)
        copies.append(flange)
        swaths.append(traj.swath + 2 * k)
    restarts = np.zeros(4 * len(traj), bool)
    restarts[:: len(traj)] = True
    scanning = np.tile(traj.scanning, 4)
    together = check_reach(
        np.concatenate(copies),
        "ur5e",
        swath=np.concatenate(swaths),
        scanning=scanning,
        restarts=restarts,
    ).joints
    assert np.array_equal(np.isnan(together), np.isnan(np.concatenate(alone)))
    assert np.allclose(np.nan_to_num(together), np.nan_to_num(np.concatenate(alone)))
    assert (~np.isnan(together).any(axis=1)).sum() > len(traj)  # several copies reached


def _settings_case():
    """A near and a far view, a UR5e beside a turntable in the box cell, and the turntable's
    settings: what the settings-judging tests judge."""
    arm = get_robot("ur5e")
    return _near_and_far(12), np.linalg.inv(TCP), arm, candidates(TURNTABLE, arm), _box_cell()


def _kept(traj, obstacles, settings, index):
    """What a UR5e at T0 keeps of `traj`'s poses `index` at each turntable setting, as one
    job of `kept_each`."""
    return kept_each(
        traj, get_robot("ur5e"), T0, np.linalg.inv(TCP), obstacles, TURNTABLE, [(settings, index)]
    )[0]


def test_settings_judged_together_keep_what_each_keeps_alone():
    traj, inv, arm, settings, obstacles = _settings_case()
    index = np.arange(len(traj))
    for obs in (None, obstacles):
        together = _kept(traj, obs, settings, index)
        alone = [_kept(traj, obs, s[None], index)[0] for s in settings]
        assert together.tolist() == alone
        assert together.max() > together.min()  # the angle matters
        # Two views' jobs in one call keep what each keeps in a call of its own.
        near, far = np.flatnonzero(traj.swath == 0), np.flatnonzero(traj.swath == 1)
        jobs = [(settings, near), (settings[::2], far)]
        both = kept_each(traj, arm, T0, inv, obs, TURNTABLE, jobs)
        assert [b.tolist() for b in both] == [_kept(traj, obs, s, i).tolist() for s, i in jobs]
    # The inverse kinematics' bound is at least what the reach check keeps, and is met
    # where it keeps every pose.
    bound = reach_bound_each(traj, arm, T0, inv, TURNTABLE, [(settings, index)])[0]
    kept = _kept(traj, None, settings, index)
    assert (bound >= kept).all() and (bound[kept == len(traj)] == len(traj)).all()
    assert bound.min() < len(traj)  # some angle puts poses out of reach


def test_place_keeps_a_turntable_plans_placement_and_searches_no_arm_alone(tmp_path):
    # A plan flown with a turntable is judged with it, as export judges it: its own
    # placement kept. Another arm gets no placement searched without the axes (its answer
    # would be about a cell without the turntable): one line, exit 2.
    out = tmp_path / "p.json"
    made = CliRunner().invoke(
        app,
        ["plan", "training-piece", "--views", "top", "--robot", "ur5e",
         "--tcp", "0,0,90,0,0,0", "--positioner", "turntable", "-o", str(out)],
    )  # fmt: skip
    assert made.exit_code == 0, made.output
    planned = next(ln for ln in made.output.splitlines() if ln.startswith("ur5e at --part-pose"))
    kept = CliRunner().invoke(app, ["place", str(out), "--robot", "ur5e", "--quiet"])
    assert kept.exit_code == 0, kept.output
    assert "the plan's own placement flies every pose" in kept.output
    assert planned.split()[3].rstrip(":") in kept.output  # the same --part-pose
    other = CliRunner().invoke(app, ["place", str(out), "--robot", "kr6-r900", "--quiet"])
    assert other.exit_code == 2
    assert "flown with external axes" in other.output and "--positioner" in other.output
    assert "Traceback" not in other.output


def test_the_settings_left_unjudged_could_not_be_picked():
    # choose_values judges only the settings whose inverse-kinematics bound may come within
    # NEAR_BEST of the best: it picks what judging every setting picks.
    traj, inv, arm, settings, obstacles = _settings_case()
    jobs = [(settings, np.flatnonzero(traj.swath == k)) for k in (0, 1)]
    some = _scores(traj, arm, T0, inv, obstacles, TURNTABLE, jobs)
    every = kept_each(traj, arm, T0, inv, obstacles, TURNTABLE, jobs)
    for few, full in zip(some, every, strict=True):
        assert _pick(few, settings, None) == _pick(full, settings, None)
        assert np.array_equal(few[few >= 0], full[few >= 0])  # judged: as judged alone
        near = full >= full.max() * (1.0 - NEAR_BEST) - 1e-9  # what _pick looks among
        assert np.array_equal(few[near], full[near])
    assert sum(int((few < 0).sum()) for few in some) > 0  # some settings left unjudged
