"""Part placement: a small raster on a UR3e is placed fully reachable; a 3 m pass is not."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh
from typer.testing import CliRunner

from helpers import plate_file
from scanplan.cli import app
from scanplan.core.plan_file import write_csv
from scanplan.core.trajectory import Trajectory
from scanplan.planning.swaths import Swath
from scanplan.robot import check_reach
from scanplan.robot.export import ExportOptions, flange_poses, parse_pose_arg
from scanplan.robot.links import column_clear, obstacles_for
from scanplan.robot.place import (
    PER_HEIGHT_YAWS,
    _as_printed,
    _best_judged,
    _seeds,
    place,
)
from scanplan.robot.place_search import placement_poses
from scanplan.robot.place_weights import pose_weights, view_worths, weighted_sample
from scanplan.robot.presets import get_robot
from scanplan.world.cell import Cell
from scanplan.world.part import part_from_mesh

TCP = "0,0,90,0,0,0"


def _raster(length_mm: float, passes: int, n: int = 60, height_mm: float = 150.0) -> Trajectory:
    """Boustrophedon passes along x over a part of `length_mm`, 60 mm apart, sensor down."""
    poses, swath = [], []
    for k in range(passes):
        y = (k - (passes - 1) / 2) * 60.0
        a, b = np.array([-length_mm / 2, y, height_mm]), np.array([length_mm / 2, y, height_mm])
        if k % 2:
            a, b = b, a
        u = (b - a) / np.linalg.norm(b - a)
        sw = Swath(k, a, b, u, np.cross([0, 0, 1.0], u))
        poses.append(sw.poses(np.linspace(0, length_mm, n), np.zeros(n), np.zeros(n)))
        swath.append(np.full(n, k))
    return Trajectory(np.concatenate(poses), np.concatenate(swath), np.ones(passes * n, bool))


def test_small_raster_on_a_ur3e_is_placed_fully_reachable() -> None:
    traj = _raster(300.0, 4)
    result = place(traj, "ur3e", tcp=parse_pose_arg(TCP), height_range_mm=(-300, 100))
    assert result.reachable, result.report.summary()
    # The printed pose is the one checked: export's own reach check agrees.
    options = ExportOptions(part_pose=parse_pose_arg(result.pose_arg()), tcp=parse_pose_arg(TCP))
    report = check_reach(
        flange_poses(traj, options), "ur3e", swath=traj.swath, scanning=traj.scanning
    )
    assert report.reachable and len(report.unreachable) == 0
    assert -300 <= result.T_base_part[2, 3] <= 100
    m = report.worst_margins()
    assert m["limit_deg"] > 0 and m["wrist_deg"] > 0


def test_three_metre_pass_on_a_ur3e_is_not_placeable() -> None:
    result = place(_raster(3000.0, 1, n=100), "ur3e", tcp=parse_pose_arg(TCP))
    assert not result.reachable
    assert len(result.report.unreachable) > 0
    assert result.score < 0


def test_bad_arguments_are_value_errors() -> None:
    with pytest.raises(ValueError, match="yaw step"):
        place(_raster(100.0, 1), "ur3e", yaw_step_deg=0)
    with pytest.raises(ValueError, match="height range"):
        place(_raster(100.0, 1), "ur3e", height_range_mm=(100, -100))
    with pytest.raises(ValueError, match="unknown robot"):
        place(_raster(100.0, 1), "ur4e")


def test_cli_place_then_export(tmp_path) -> None:
    runner = CliRunner()
    path = tmp_path / "t.csv"
    write_csv(_raster(300.0, 3, n=40), path)
    plate = plate_file(tmp_path)
    result = runner.invoke(
        app,
        [
            "place",
            str(path),
            "--part",
            plate,
            "--robot",
            "kr6-r900",
            "--tcp",
            TCP,
            "--height-range",
            "-200,200",
            "--yaw-step",
            "45",
        ],
    )
    assert result.exit_code == 0, result.output
    line = result.output.splitlines()[0]
    assert line.startswith("--part-pose ")
    pose = line.split()[1]
    assert "0 unreachable" in result.output and "worst margins" in result.output
    out = tmp_path / "scan.src"
    result = runner.invoke(
        app,
        [
            "export",
            str(path),
            "--part",
            plate,
            "--format",
            "krl",
            "--robot",
            "kr6-r900",
            "--tcp",
            TCP,
            "--part-pose",
            pose,
            "-o",
            str(out),
        ],
    )
    assert result.exit_code == 0, result.output
    assert "kr6-r900: 120 poses, 0 unreachable, 0 beyond joint limits" in result.output
    assert "DEF scan( )" in out.read_text()

    # Unplaceable: exit 2, the best pose still printed; bad input: one line, exit 2.
    far = tmp_path / "far.csv"
    write_csv(_raster(3000.0, 1, n=50), far)
    result = runner.invoke(app, ["place", str(far), "--robot", "ur3e", "--part", plate])
    assert result.exit_code == 2 and result.output.startswith("--part-pose ")
    assert "poses out of the arm's reach" in result.stderr  # the binding constraint named
    for extra in (["--height-range", "1,x"], ["--robot", "ur4e"]):
        result = runner.invoke(
            app, ["place", str(path), "--robot", "ur3e", "--part", plate, *extra]
        )
        assert result.exit_code == 2 and result.output.startswith("error:")
        assert result.output.strip().count("\n") == 0


def test_cli_export_krl_refuses_what_its_own_arm_cannot_fly(tmp_path) -> None:
    # The KRL program is checked on the KR 6: a part 2 m away is out of its reach, so
    # nothing is written, and the error names the first pose and its pass.
    path = tmp_path / "t.csv"
    write_csv(_raster(300.0, 2, n=20), path)
    out = tmp_path / "p.src"
    args = ["export", str(path), "--format", "krl", "--robot", "kr6-r900"]
    args += ["--part", plate_file(tmp_path)]
    args += ["--part-pose", "2000,0,0,0,0,0", "-o", str(out)]
    result = CliRunner().invoke(app, args)
    assert result.exit_code == 2 and not out.exists()
    error = result.stderr.strip().splitlines()
    assert len(error) == 1 and "pose 0 (pass 0) is unreachable" in error[0]
    assert "kr6-r900: 40 poses, 40 unreachable" in error[0]
    # --allow-unreachable writes it anyway, with the same finding as a warning.
    result = CliRunner().invoke(app, [*args, "--allow-unreachable"])
    assert result.exit_code == 0 and out.exists()
    assert "warning: pose 0 (pass 0) is unreachable; kr6-r900: 40 poses, 40 unreachable" in (
        result.stderr
    )
    # No arm named: refused, never a silent default.
    result = CliRunner().invoke(app, ["export", str(path), "-o", str(tmp_path / "q.src")])
    assert result.exit_code == 2 and "--robot is required" in result.stderr


def test_seeds_in_a_cell_take_several_yaws_per_height_searched_at_that_height() -> None:
    """In a cell each height gives its best yaws at least 60° apart (not the near-equal yaw
    beside its best), marked to be searched at that height; out of a cell only the best."""
    yaws = np.radians(np.arange(0.0, 360.0, 10.0))
    heights = np.array([-200.0, 300.0])
    grid = np.array([[400.0, 0.0, z, a] for z in heights for a in yaws])
    # The high row scores best everywhere; within the low row, yaws near 0 score best.
    scores = np.where(grid[:, 2] > 0, 1.0, 0.0) - np.abs(np.sin(grid[:, 3] / 2))
    seeds, held = _seeds(grid, heights, scores, scores, keep=2, in_cell=True)
    low = seeds[grid[seeds, 2] < 0]
    assert len(low) == PER_HEIGHT_YAWS and held[grid[seeds, 2] < 0].all()
    low_yaws = np.sort(np.degrees(grid[low, 3]))
    gaps = np.diff(np.r_[low_yaws, low_yaws[0] + 360.0])
    assert (gaps > 60.0).all() and 0.0 in low_yaws
    alone, held_alone = _seeds(grid, heights, scores, scores, keep=2, in_cell=False)
    assert len(alone) == 2 and not held_alone.any()


def test_an_arm_whose_column_stands_in_the_table_is_not_chosen() -> None:
    """The final judging keeps the candidates an arm can stand at: one floating over the
    middle of the table (its column in the table block) loses to one beside the table, even
    ranked first by the search and keeping as many poses."""
    box = trimesh.creation.box((300.0, 300.0, 50.0))
    box.apply_translation((0.0, 0.0, 25.0))
    part = part_from_mesh(box, "box")
    obstacles = obstacles_for(part, Cell.around(part), clearance_mm=20.0)
    traj = _raster(200.0, 3, n=20, height_mm=200.0)
    tcp = parse_pose_arg(TCP)
    T_part_flange = traj.poses @ np.linalg.inv(tcp)
    centre = T_part_flange[:, :2, 3].mean(axis=0)
    # (x, y, z, yaw): the path's centre under the base 300 mm below it; and 650 mm out.
    rows = np.array([[200.0, 0.0, -500.0, 0.0], [650.0, 0.0, -100.0, 0.0]])
    clear = column_clear(
        get_robot("ur5e"), placement_poses(rows, centre), obstacles.table_block, 20.0
    )
    assert list(clear) == [False, True]
    T, _ = _best_judged(
        traj, get_robot("ur5e"), tcp, T_part_flange, rows, np.array([1.0, 0.5]), centre,
        obstacles,
    )  # fmt: skip
    assert column_clear(get_robot("ur5e"), T[None], obstacles.table_block, 20.0)[0]
    assert np.allclose(T, _as_printed(placement_poses(rows[1:], centre)[0]))


def _two_views(light_passes: int, light_n: int, heavy_n: int, apart_mm: float) -> Trajectory:
    """Two views far apart: a light one of `light_passes` passes of `light_n` poses and a
    heavy one of a pass of `heavy_n`, their poses' centre at the origin."""
    light = _raster(200.0, light_passes, n=light_n)
    heavy = _raster(200.0, 1, n=heavy_n)
    n_light, n_heavy = len(light), len(heavy)
    light.poses[:, 0, 3] -= apart_mm * n_heavy / (n_light + n_heavy)
    heavy.poses[:, 0, 3] += apart_mm * n_light / (n_light + n_heavy)
    blocks = [(0, light_passes - 1), (light_passes, light_passes)]
    views = [
        {"index": k, "axis": [0.0, 0.0, -1.0], "first_swath": a, "last_swath": b}
        for k, (a, b) in enumerate(blocks)
    ]
    return Trajectory(
        np.concatenate([light.poses, heavy.poses]),
        np.r_[light.swath, np.full(n_heavy, light_passes)],
        np.ones(n_light + n_heavy, bool),
        meta={"views": views},
    )


def test_view_worths_split_what_views_share():
    held = [np.array([1, 1, 1, 1, 0, 0], bool), np.array([0, 0, 1, 1, 1, 0], bool)]
    worths = view_worths(held)
    assert np.allclose(worths, [3 / 6, 2 / 6]) and np.isclose(worths.sum(), 5 / 6)


def test_weighted_placement_reaches_the_view_that_holds_most_surface():
    """No placement of a UR3e reaches both views: by the count of poses it reaches the view
    of many poses; with the poses weighted by what their view holds, the view of few poses
    that holds most of the surface."""
    traj = _two_views(2, 30, 30, 1200.0)
    heavy = traj.swath == 2
    tcp = parse_pose_arg(TCP)
    weights = pose_weights(traj, np.array([0.1, 0.9]))
    assert np.isclose(weights[heavy].sum(), 0.9) and np.isclose(weights.sum(), 1.0)
    flange = traj.poses @ np.linalg.inv(tcp)

    def reached(result):
        report = check_reach(result.T_base_part @ flange, "ur3e", swath=traj.swath)
        good = ~np.isnan(report.joints).any(axis=1)
        return good[~heavy].mean(), good[heavy].mean()

    by_count = reached(place(traj, "ur3e", tcp=tcp))
    by_worth = reached(place(traj, "ur3e", tcp=tcp, weights=weights))
    assert by_count[0] > 0.9 and by_count[1] < 0.1, by_count
    assert by_worth[1] > 0.9, by_worth
    with pytest.raises(ValueError, match="weights"):
        place(traj, "ur3e", tcp=tcp, weights=np.ones(3))


def test_weighted_sample_adds_the_views_it_misses_and_keeps_the_weight():
    """A sample of the light view alone gets poses of the heavy one, and its poses' weights
    add up to the whole plan's, the heavy view's mostly on its own poses."""
    traj = _two_views(2, 30, 30, 1200.0)
    heavy = traj.swath == 2
    weights = pose_weights(traj, np.array([0.1, 0.9]))
    sample, sampled = weighted_sample(traj, weights, np.array([0, 30, 59]), per_view=2)
    assert heavy[sample].sum() == 2 and len(sample) == 5
    assert np.isclose(sampled.sum(), weights.sum())
    assert np.isclose(sampled[heavy[sample]].sum(), 0.9)  # none of the light view's
    assert weighted_sample(traj, None, np.array([0, 30]), per_view=2)[1] is None


def test_the_table_tops_height_only_adds_its_own_seeds() -> None:
    """Placements standing the arm on the table's top are searched from their own best yaws
    (held at that height), and do not displace the best of the other heights."""
    heights = np.array([-400.0, -37.0, 0.0])
    yaws = np.radians(np.arange(0.0, 360.0, 30.0))
    grid = np.array([[300.0, 0.0, z, a] for z in heights for a in yaws])
    scores = np.where(grid[:, 2] == -37.0, 5.0, 0.0) + np.cos(grid[:, 3])  # the top scores best
    seeds, held = _seeds(grid, heights, scores, scores, 2, True, on_table=-37.0)
    on_top = grid[seeds, 2] == -37.0
    assert on_top.sum() == PER_HEIGHT_YAWS and held[on_top].all()
    best = seeds[~held]
    assert len(best) == 2 and (grid[best, 2] != -37.0).all()
    assert (np.cos(grid[best, 3]) == 1.0).all()  # the others' best yaw, at both heights
    without, held_without = _seeds(grid, heights, scores, scores, 2, True)
    assert (grid[without[~held_without], 2] == -37.0).all()  # else the top's are the best


def test_an_arm_does_not_stand_on_the_table_under_a_wide_part() -> None:
    """An arch 1.2 m wide resting on the table on its two feet: an arm standing on the
    table's top under its span has its axis over the part's footprint and its column
    within the part's height. It may stand level with the table's top beside it, not under
    the arch; without the part's bounds (as before) both read as clear."""
    feet = [trimesh.creation.box((100.0, 600.0, 300.0)) for _ in range(2)]
    feet[0].apply_translation((-550.0, 0.0, 150.0))
    feet[1].apply_translation((550.0, 0.0, 150.0))
    roof = trimesh.creation.box((1200.0, 600.0, 20.0))
    roof.apply_translation((0.0, 0.0, 310.0))
    part = part_from_mesh(trimesh.util.concatenate([*feet, roof]), "arch")
    obstacles = obstacles_for(part, Cell.around(part), clearance_mm=20.0)
    block = obstacles.table_block
    assert block is not None
    arm = get_robot("kr6-r900")
    on_top = float(block[1][2]) + 1.0  # the base 1 mm above the table's top
    # Standing at the arch's middle, under the roof; and beside the table, 450 mm out in y.
    T_under = np.linalg.inv(parse_pose_arg(f"0,0,{on_top},0,0,0"))
    T_beside = np.linalg.inv(parse_pose_arg(f"0,-750,{on_top},0,0,0"))
    T = np.stack([T_under, T_beside])
    assert list(column_clear(arm, T, block, 20.0)) == [True, True]
    assert list(column_clear(arm, T, block, 20.0, obstacles.part_bounds)) == [False, True]
