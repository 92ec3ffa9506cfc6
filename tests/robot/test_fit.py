"""A plan fitted to an arm: what the arm cannot fly is given up or split, never hidden."""

from __future__ import annotations

import json
import pickle
from dataclasses import replace

import numpy as np
from typer.testing import CliRunner

import scanplan.robot.fit as fit_module
import scanplan.robot.pass_repairs as repairs
from scanplan.cli import app
from scanplan.core.context import PlanContext
from scanplan.core.plan import Plan
from scanplan.core.plan_file import read_json
from scanplan.core.quantities import ScanSpec
from scanplan.core.trajectory import Trajectory, lead_tops
from scanplan.planning.pipeline import _not_flown
from scanplan.planning.swaths import Swath
from scanplan.planning.views import View, ViewPlan
from scanplan.robot import check_reach
from scanplan.robot.base import pose_arg
from scanplan.robot.export import ExportOptions, parse_pose_arg, parse_program
from scanplan.robot.export.common import plan_motion
from scanplan.robot.fit import fit_to_robot
from scanplan.robot.flown_poses import HALF_TURN
from scanplan.robot.hints import facing, what_would_help, why_not
from scanplan.robot.placed_arm import PlacedArm
from scanplan.robot.program import arm_joints
from scanplan.robot.reach import pass_starts
from scanplan.robot.ur import forward_kinematics

TCP = parse_pose_arg("0,0,90,0,0,0")


def _two_views(length_mm: float, n: int = 80) -> Trajectory:
    """Two one-pass 'views' along x at 150 mm: a plan the arm reaches only part of once the
    part is placed far out along x."""
    poses, swath = [], []
    for k, y in enumerate((-30.0, 30.0)):
        a, b = np.array([-length_mm / 2, y, 150.0]), np.array([length_mm / 2, y, 150.0])
        sw = Swath(k, a, b, np.array([1.0, 0, 0]), np.array([0, 1.0, 0]))
        poses.append(sw.poses(np.linspace(0, length_mm, n), np.zeros(n), np.zeros(n)))
        swath.append(np.full(n, k))
    views = [
        {"index": k, "axis": [0.0, 0.0, 1.0], "first_swath": k, "last_swath": k, "passes": 1}
        for k in range(2)
    ]
    return Trajectory(
        np.concatenate(poses),
        np.concatenate(swath),
        np.ones(2 * n, bool),
        planner="t",
        meta={"views": views},
    )


def test_unreachable_poses_are_given_up_and_the_rest_is_flyable():
    traj = _two_views(900.0)
    # The part's centre 450 mm out along x: a UR3e (reach 500 mm) loses the far end.
    T_base_part = parse_pose_arg("450,0,-200,0,0,0")
    before = check_reach(
        T_base_part @ traj.poses @ np.linalg.inv(TCP),
        "ur3e",
        swath=traj.swath,
        scanning=traj.scanning,
    )
    assert len(before.unreachable) > 0
    fit = fit_to_robot(traj, "ur3e", TCP, T_base_part)
    assert fit.report.reachable
    assert 0 < len(fit.traj) < len(traj)
    assert sum(fit.given_up.values()) == len(traj) - len(fit.traj)
    assert set(fit.given_up) <= {0, 1}
    # Checked afresh, as export does: nothing unreachable, no flip within a pass.
    again = check_reach(
        T_base_part @ fit.traj.poses @ np.linalg.inv(TCP),
        "ur3e",
        swath=fit.traj.swath,
        scanning=fit.traj.scanning,
    )
    assert again.reachable
    # The views' swath blocks follow the renumbered passes, in order and without gaps.
    blocks = [(v["first_swath"], v["last_swath"]) for v in fit.traj.meta["views"]]
    assert blocks[0][0] == int(fit.traj.swath.min())
    assert all(a[1] + 1 == b[0] for a, b in zip(blocks[:-1], blocks[1:], strict=True))
    assert np.all(np.diff(fit.traj.swath) >= 0)
    record = fit.record(TCP)
    assert record["robot"] == "ur3e" and record["reachable"]
    assert np.allclose(parse_pose_arg(record["part_pose"]), T_base_part, atol=1e-3)
    assert pose_arg(TCP) == "0,0,90,0,0,0"


def test_plan_for_an_arm_then_export_with_what_the_plan_records(tmp_path):
    runner = CliRunner()
    plan = tmp_path / "plan.json"
    result = runner.invoke(
        app,
        ["plan", "drone", "--planner", "fixed", "--robot", "ur3e", "--tcp", "0,0,90,0,0,0",
         "-q", "-o", str(plan)],
    )  # fmt: skip
    assert result.exit_code == 0, result.output
    assert "ur3e at --part-pose" in result.output and "in-spec coverage" in result.output
    recorded = json.loads(plan.read_text())["robot"]
    assert recorded["robot"] == "ur3e" and recorded["reachable"]
    assert 0.0 <= recorded["in_spec"] <= recorded["in_spec_without_robot"] + 1e-9
    # The configuration each pass is entered with is recorded, and every reader follows it.
    planned = read_json(plan)
    arm = Plan.of(planned).arm
    assert arm is not None
    entries = arm.entry_joints("ur3e", arm.T_base_part, arm.T_flange_sensor)
    starts = np.flatnonzero(pass_starts(planned.swath, planned.scanning))
    assert entries is not None and set(starts) <= set(entries)
    joints = arm_joints(Plan.of(planned))
    assert joints is not None
    np.testing.assert_allclose(joints[starts], [entries[i] for i in starts], atol=1e-7)
    moved = arm.T_base_part @ parse_pose_arg("0,0,10,0,0,0")
    assert arm.entry_joints("ur5e", arm.T_base_part, arm.T_flange_sensor) is None
    assert arm.entry_joints("ur3e", moved, arm.T_flange_sensor) is None  # another placement
    out = tmp_path / "scan.script"
    result = runner.invoke(app, ["export", str(plan), "-o", str(out)])
    assert result.exit_code == 0, result.output
    assert "--robot ur3e (the plan's)" in result.output and out.exists()
    assert "0 unreachable, 0 beyond joint limits" in result.output + result.stderr
    # The program's first target and every pass are entered by a joint move into its
    # configuration, then flown linearly: the program parses back to the thinned targets.
    text = out.read_text()
    passes = len(np.unique(planned.swath[planned.scanning]))
    assert text.count("movej([") == passes + int(not planned.scanning[0])
    poses, _ = parse_program(text, "urscript")
    assert len(poses) == len(plan_motion(planned, ExportOptions()).poses) < len(planned)
    # `place` judges the plan's own placement first, as export did: the same answer, no
    # search; with another TCP it searches.
    result = runner.invoke(app, ["place", str(plan), "--robot", "ur3e"])
    assert result.exit_code == 0, result.output
    assert "--tcp 0,0,90,0,0,0 (the plan's)" in result.output
    assert f"--part-pose {recorded['part_pose']}\n" in result.output
    assert "(the plan's own placement, not searched)" in result.output
    result = runner.invoke(app, ["place", str(plan), "--robot", "ur3e", "--tcp", "0,0,80,0,0,0"])
    assert "placements in" in result.output and "plan's own" not in result.output
    # An option needs the arm it refers to.
    result = runner.invoke(app, ["plan", "drone", "--tcp", "0,0,90,0,0,0", "-o", str(plan)])
    assert result.exit_code == 2 and "--tcp needs --robot" in result.stderr


def test_a_pass_the_wrist_reaches_only_turned_is_turned_not_given_up() -> None:
    from dataclasses import replace

    from scanplan.robot import get_robot

    # A KR 6 whose A4 turns only over 30..120° and A6 ±60°: as planned the pass needs A4
    # near -80° (or, wrist flipped, A6 near 180°), turned half a turn about its beam A4 near
    # +80° and A6 near 0.
    base = get_robot("kr6-r900")
    a4, a6 = np.radians([30.0, 120.0]), np.radians([-60.0, 60.0])
    arm = replace(base, limits=(*base.limits[:3], tuple(a4), base.limits[4], tuple(a6)))
    traj = _two_views(200.0)
    T = parse_pose_arg("500,0,0,0,0,0")
    turn = np.diag([-1.0, -1, 1, 1])
    reached = [
        (~np.isnan(check_reach(T @ p @ np.linalg.inv(TCP), arm).joints).any(axis=1)).sum()
        for p in (traj.poses, traj.poses @ turn)
    ]
    assert reached[0] <= len(traj) / 2 and reached[1] == len(traj)  # the premise
    fit = fit_to_robot(traj, arm, TCP, T)
    assert fit.report.reachable and fit.given_up == {} and fit.turned >= 1
    flown = fit.traj.poses
    assert np.allclose(flown[:, :3, 2], traj.poses[:, :3, 2])  # the same beam
    assert np.allclose(flown[:, :3, 3], traj.poses[:, :3, 3])  # from the same place


def test_a_pass_whose_move_turned_would_bring_the_body_into_the_cell_turns_without_it(
    monkeypatch,
):
    """The move into a pass turns with it, unless turned it puts the sensor body into the
    cell where it was clear as planned: two passes both kept better turned, the second's
    move in spoils, so it is flown as planned and the second pass turns alone (the arm
    turns the sensor in its joint move into the pass). A move inside a pass that would
    spoil keeps the whole pass as planned."""
    swath = np.array([0, 0, 0, 1, 1, 1])
    scanning = np.array([True, True, True, False, True, True])  # pose 3: the move into pass 1
    traj = Trajectory(np.tile(np.eye(4), (6, 1, 1)), swath, scanning)
    planned = np.array([False, False, False, True, False, False])
    turned = np.ones(6, bool)
    sensor_planned, sensor_turned = np.ones(6, bool), np.ones(6, bool)
    sensor_turned[3] = False
    monkeypatch.setattr(
        fit_module,
        "flyable_poses",
        lambda *a, **k: (planned & sensor_planned, turned & sensor_turned),
    )
    monkeypatch.setattr(
        fit_module, "sensor_clear_both", lambda poses, obs: (sensor_planned, sensor_turned)
    )
    out, count = fit_module._turned(traj, None, np.eye(4), np.eye(4), object())  # type: ignore[arg-type]
    assert count == 2
    assert np.allclose(out.poses[[0, 1, 2, 4, 5]], HALF_TURN)
    assert np.allclose(out.poses[3], np.eye(4))  # the move into pass 1, as planned
    # Without a cell there is no body to keep clear: both passes turn, the move with them.
    monkeypatch.setattr(fit_module, "flyable_poses", lambda *a, **k: (planned, turned))
    out, count = fit_module._turned(traj, None, np.eye(4), np.eye(4), None)  # type: ignore[arg-type]
    assert count == 2 and np.allclose(out.poses, HALF_TURN)
    # The spoiling move inside pass 1 (after its first scanning pose): pass 1 stays as planned.
    inside = Trajectory(traj.poses, swath, np.array([True, True, True, True, False, True]))
    planned_inside = np.array([False, False, False, False, True, False])
    sensor_turned[:] = True
    sensor_turned[4] = False
    monkeypatch.setattr(
        fit_module,
        "flyable_poses",
        lambda *a, **k: (planned_inside & sensor_planned, turned & sensor_turned),
    )
    out, count = fit_module._turned(inside, None, np.eye(4), np.eye(4), object())  # type: ignore[arg-type]
    assert count == 1
    assert np.allclose(out.poses[:3], HALF_TURN) and np.allclose(out.poses[3:], np.eye(4))


def test_a_half_turn_of_the_sensor_between_two_poses_is_made_by_a_joint_move() -> None:
    """Pass 0 turned about its beam, the move after it not: the move's first pose is
    entered by a joint move (as every pass's first pose is), not reached by a linear one."""
    poses = np.tile(np.eye(4), (5, 1, 1))
    poses[:2] = HALF_TURN
    traj = Trajectory(poses, np.array([0, 0, 1, 1, 1]), np.array([True, True, False, True, True]))
    entry = fit_module.entries_of(traj, np.zeros(5, bool))
    np.testing.assert_array_equal(np.flatnonzero(entry), [0, 2, 3])


def test_fit_says_why_each_pose_was_given_up_and_what_would_help():
    traj = _two_views(900.0)
    fit = fit_to_robot(traj, "ur3e", TCP, parse_pose_arg("450,0,-200,0,0,0"))
    record = fit.record(TCP)
    by_cause = record["given_up_by_cause"]
    # Every pose given up is counted under a cause, view by view.
    assert {k: sum(v.values()) for k, v in by_cause.items()} == record["scanning_poses_given_up"]
    assert set().union(*by_cause.values()) <= set(repairs.CAUSES)
    assert "reach" in set().union(*by_cause.values())
    # The far end lies beyond the UR3e's reach: the hint says by how much.
    assert record["beyond_reach_mm"] > 0
    hints = what_would_help(record)
    assert f"{record['beyond_reach_mm']:.0f} mm beyond the arm's horizontal reach" in hints[0]
    assert "a linear track" in hints[0] and "a turntable" in hints[0]
    # An axis the cell has is not suggested again.
    with_axes = record | {"external_axes": {"track": {"length_mm": 2000.0}, "turntable": None}}
    hint = what_would_help(with_axes)[0]
    assert "a longer track" in hint and "a linear track" not in hint and "turntable" in hint
    with_axes["external_axes"] = {"turntable": {"radius_mm": 500.0}}
    assert "turntable" not in what_would_help(with_axes)[0]


def test_the_arm_judging_a_view_keeps_only_what_it_flies(plate):
    traj = _two_views(900.0)
    T_base_part = parse_pose_arg("450,0,-200,0,0,0")
    arm = PlacedArm("ur3e", TCP, T_base_part, PlanContext(ScanSpec()))
    flown = arm.flown(plate, traj)
    assert 0 < flown.scanning.sum() < traj.scanning.sum()
    # What it keeps (each pass as planned or turned about the beam) the arm reaches.
    reach = check_reach(
        T_base_part @ flown.poses @ np.linalg.inv(TCP),
        "ur3e",
        swath=flown.swath,
        scanning=flown.scanning,
    )
    assert not np.isnan(reach.joints[flown.scanning]).any()
    # Picklable for the view workers, without the cell's obstacles (built where needed).
    copy = pickle.loads(pickle.dumps(arm))
    assert copy._obstacles is None
    np.testing.assert_array_equal(copy.flown(plate, traj).poses, flown.poses)
    # Given the cell's obstacles the caller built (as the plan's pipeline does), it judges
    # with them, the same; for another part it builds its own.
    given = PlacedArm("ur3e", TCP, T_base_part, PlanContext(ScanSpec()))
    given.among(plate, arm.obstacles(plate))
    assert given.obstacles(plate) is arm.obstacles(plate)
    np.testing.assert_array_equal(given.flown(plate, traj).poses, flown.poses)
    other = replace(plate, name="other")
    assert given.obstacles(other) is not arm.obstacles(plate)


def test_a_pass_is_entered_on_the_branch_that_flies_it_whole():
    # A straight path whose q5 crosses 0 on the branch the move before it ends on: followed
    # from there it flips the wrist mid-pass; entered on another branch it flies whole.
    s = np.linspace(0, 1, 200)[:, None]
    q0 = np.array([0.3, -1.4, 1.6, -1.7, 0.35, 0.4])
    q1 = np.array([0.5, -1.2, 1.4, -1.5, -0.35, 0.2])
    poses = forward_kinematics(np.vstack([q0[None], q0 + s * (q1 - q0)]))
    swath = np.r_[0, np.ones(200, int)]
    scanning = np.r_[False, np.ones(200, bool)]
    pinned = check_reach(poses[1:], "ur5e", q_start=q0)
    assert len(pinned.config_flips) == 1
    report = check_reach(poses, "ur5e", q_start=q0, swath=swath, scanning=scanning)
    assert report.reachable and len(report.config_flips) == 0 and len(report.pass_jumps) == 0
    np.testing.assert_allclose(report.joints[0], q0, atol=1e-8)  # the move: as given


def test_a_pass_whose_joint_move_in_hits_the_cell_is_flown_the_other_way_then_given_up():
    # Pass 0 (poses 0-4), the move into pass 1 (pose 5), pass 1 (poses 6-10): the joint move
    # into pose 6 sweeps a link into the cell.
    swath = np.array([0] * 5 + [1] * 6)
    scanning = np.array([True] * 5 + [False] + [True] * 5)
    poses = np.tile(np.eye(4), (11, 1, 1))
    poses[:, 0, 3] = np.arange(11.0)  # told apart by x
    traj = Trajectory(poses, swath, scanning)
    index, flipped = np.arange(11), np.zeros(11, bool)
    why = np.full(11, -1)
    out, reversed_now = repairs.flown_back(traj, traj, index, {6: (0, 0)}, why, flipped)
    # Entered from its other end; the move that led to its old start is given up.
    assert reversed_now
    np.testing.assert_array_equal(out.poses[:, 0, 3], [0, 1, 2, 3, 4, 5, 10, 9, 8, 7, 6])
    assert why[5] == repairs.CAUSES.index("joint move into a pass")
    assert (why[:5] == -1).all() and (why[6:] == -1).all()
    # Its move in hits the cell that way too: now it is given up.
    why = np.full(11, -1)
    again, reversed_now = repairs.flown_back(out, out, index, {6: (0, 0)}, why, flipped)
    assert not reversed_now and again is out
    assert (why[5:] == repairs.CAUSES.index("joint move into a pass")).all()
    # After the reversing rounds a pass is given up at once, never reversed.
    why, fresh = np.full(11, -1), np.zeros(11, bool)
    late, reversed_now = repairs.flown_back(traj, traj, index, {6: (0, 0)}, why, fresh, False)
    assert not reversed_now and late is traj and not fresh.any()
    assert (why[5:] == repairs.CAUSES.index("joint move into a pass")).all()


def test_a_reversed_pass_takes_its_external_axis_values_along():
    swath = np.array([0] * 5 + [1] * 6)
    scanning = np.array([True] * 5 + [False] + [True] * 5)
    poses = np.tile(np.eye(4), (11, 1, 1))
    external = np.arange(11.0)[:, None]
    traj = Trajectory(poses, swath, scanning, external=external)
    index, flipped, why = np.arange(11), np.zeros(11, bool), np.full(11, -1)
    out, _ = repairs.flown_back(traj, traj, index, {6: (0, 0)}, why, flipped)
    assert out.external is not None
    np.testing.assert_array_equal(out.external[:, 0], [0, 1, 2, 3, 4, 5, 10, 9, 8, 7, 6])


def test_a_pass_whose_move_in_hits_the_cell_is_entered_at_the_top_of_its_move_first():
    # Pass 0 (poses 0-4), the move into pass 1 (poses 5-6, up and over), pass 1 (7-10).
    swath = np.array([0] * 5 + [1] * 6)
    scanning = np.array([True] * 5 + [False] * 2 + [True] * 4)
    poses = np.tile(np.eye(4), (11, 1, 1))
    poses[:, 0, 3] = np.arange(11.0)
    poses[5:7, 2, 3] = 100.0
    traj = Trajectory(poses, swath, scanning)
    index, raised = np.arange(11), np.zeros(11, bool)
    assert np.flatnonzero(fit_module.entries_of(traj, raised)).tolist() == [0, 7]
    # The joint move into pass 1's first pose hits: the pass is entered at its top instead.
    low = np.zeros(11, bool)
    left, lifted = repairs.lifted(traj, index, {7: (0, 0)}, raised, low)
    assert lifted and left == {} and np.flatnonzero(raised).tolist() == [7]
    top = int(lead_tops(traj)[7])
    assert top in (5, 6)
    assert np.flatnonzero(fit_module.entries_of(traj, raised)).tolist() == [0, top]
    # Its move in hits from the top too: left to be flown the other way or given up.
    left, lifted = repairs.lifted(traj, index, {top: (0, 0)}, raised, low)
    assert not lifted and left == {top: (0, 0)}


def test_a_pass_whose_move_down_from_the_top_flips_is_entered_beside_the_surface_again():
    # Pass 0, the move into pass 1 (its swath index), pass 1 entered at the top of it, and
    # the move into pass 2 (not raised). A flip on the move down into pass 1 lowers it for
    # good; flips in a pass, or on a move into a pass entered at its first pose, do not.
    swath = np.array([0, 0, 0, 1, 1, 1, 1, 1, 1, 2, 2, 2, 2])
    scanning = np.array([1, 1, 1, 0, 0, 0, 1, 1, 1, 0, 0, 1, 1], bool)
    traj = Trajectory(np.tile(np.eye(4), (13, 1, 1)), swath, scanning)
    index = np.arange(13) + 100  # the kept poses of a longer plan
    raised, low = np.zeros(113, bool), np.zeros(113, bool)
    raised[106] = True
    flips = np.array([1, 4, 7, 10])
    left, lowered = repairs.lowered(traj, index, flips, raised, low)
    assert left.tolist() == [1, 7, 10] and lowered
    assert not raised.any() and np.flatnonzero(low).tolist() == [106]
    # Lowered for good: its joint move in is not raised again.
    left, lifted = repairs.lifted(traj, index, {6: (0, 1)}, raised, low)
    assert left == {6: (0, 1)} and not lifted and not raised.any()


def test_views_the_arm_flies_none_of_are_said_with_why_and_what_would_help():
    """A view of the plan without the arm whose surface the arm's plan misses is named with
    its side, its share and why the arm cannot fly it; one it holds is not named."""
    traj = _two_views(900.0)
    fit = fit_to_robot(traj, "ur3e", TCP, parse_pose_arg("450,0,-200,0,0,0"))
    near = View.looking_along(np.array([0.0, 0.0, 1.0]), 0)
    far = View.looking_along(np.array([0.0, 0.98, 0.17]), 1)
    # The far view: its passes 2 m out along x, beyond any UR3e; the near one: flown.
    out = traj.subset(traj.swath == 0)
    out = replace(out, poses=out.poses.copy())
    out.poses[:, 0, 3] += 2000.0
    held = np.r_[np.ones(50, bool), np.zeros(50, bool)]
    near_set, far_set = held.copy(), ~held
    far_set[:10] = True  # a few samples both hold
    views = [(ViewPlan(near, traj, 2), near_set), (ViewPlan(far, out, 1), far_set)]
    said, share = _not_flown(views, held, "ur3e", TCP, fit)
    assert share == 0.5 and len(said) == 1
    (view,) = said
    assert view["in_spec_lost"] == 0.5 and view["out_of_reach"] == view["scanning_poses"] > 0
    assert view["beyond_reach_mm"] > 1000
    assert facing(view["axis"]) == "+y" and "out of reach, the farthest" in why_not(view)
    hint = what_would_help({"free_views_not_flown": said, "in_spec_not_flown": share})[0]
    assert hint.startswith("0.500 of the surface is seen only from +y") and "turntable" in hint
    # A turntable in the cell: not suggested again.
    with_axes = {"free_views_not_flown": said, "in_spec_not_flown": share}
    with_axes["external_axes"] = {"turntable": {"radius_mm": 500.0}}
    assert "turntable" not in what_would_help(with_axes)[0]
    # Judged on other samples: nothing is compared, nothing said.
    assert _not_flown(views, held[:10], "ur3e", TCP, fit) == ([], 0.0)
    assert facing([0.0, 0.0, 1.0]) == "up" and facing([-0.7, 0.1, 0.7]) == "-x (44° up)"


def test_passes_given_up_for_the_sensor_on_their_joint_move_get_their_own_hint():
    record = {"given_up_by_cause": {"0": {"sensor on a joint move": 466}}}
    (hint,) = what_would_help(record)
    assert hint.startswith("466 poses on passes whose joint move in swings the sensor body")
    assert "--part-pose" in hint
