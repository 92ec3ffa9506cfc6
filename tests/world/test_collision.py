"""The sensor body vs the part (SPEC §3b): distances and depths against analytic answers,
plans that keep clear (checked with FCL built here, not through the checker), and a post
planted beside a plate that the transitions must go over."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from helpers import fcl_distance
from scanplan.core.quantities import ScanSpec
from scanplan.core.sensor_spec import SensorSpec
from scanplan.judging import evaluate
from scanplan.planning.pass_path import plan_path
from scanplan.planning.swaths import plan_swaths
from scanplan.rl.planners import make_planner
from scanplan.world.collision import CollisionChecker
from scanplan.world.part import Part

SPEC = ScanSpec()
CUBE = SensorSpec(body_min_mm=(-10.0, -10.0, -10.0), body_max_mm=(10.0, 10.0, 10.0))


def plate_part(thickness: float = 20.0) -> Part:
    """400 x 400 plate, top face at z = 0."""
    mesh = trimesh.creation.box((400.0, 400.0, thickness))
    mesh.apply_translation((0.0, 0.0, -thickness / 2))
    return Part(mesh, name="plate")


def at(x: float, y: float, z: float) -> np.ndarray:
    pose = np.eye(4)
    pose[:3, 3] = (x, y, z)
    return pose


def test_a_box_far_from_the_part_is_clear_at_the_right_distance():
    checker = CollisionChecker(plate_part(), CUBE)
    poses = np.stack([at(0, 0, 60.0), at(0, 0, 10.0 + 7.25), at(230.0, 0, 30.0)])
    report = checker.check(poses, clearance_mm=5.0, exact=True)
    # Box bottom 10 below its centre; the last is off the plate's edge by 20 in x and
    # 20 above its top: diagonal distance.
    want = [50.0, 7.25, float(np.hypot(20.0, 20.0))]
    np.testing.assert_allclose(report.distance_mm, want, atol=1e-6)
    assert not report.colliding.any() and report.exact.all()
    # Without exact: the first and the last are cleared by the prefilters, still >= clearance.
    quick = checker.check(poses, clearance_mm=5.0)
    assert not quick.colliding.any()
    assert np.all(quick.distance_mm <= np.array(want) + 1e-9)
    assert quick.distance_mm[1] == pytest.approx(7.25, abs=1e-6)


def test_poses_cleared_by_a_neighbour_agree_with_measuring_each():
    """A dense wavy path over, near and into a plate with a post, turning as it goes: the
    poses cleared by the one measured before them are exactly those measuring every pose
    finds clear, and their distance is a lower bound of the measured one."""
    post = trimesh.creation.box((40.0, 40.0, 120.0))
    post.apply_translation((60.0, 0.0, 60.0))
    plate = trimesh.creation.box((400.0, 400.0, 100.0))
    plate.apply_translation((0.0, 0.0, -50.0))
    checker = CollisionChecker(Part(trimesh.util.concatenate([plate, post]), name="post"), CUBE)
    t = np.linspace(0.0, 1.0, 4000)
    poses = np.stack([at(-180.0 + 360.0 * s, 30.0 * np.sin(9 * s), 0.0) for s in t])
    poses[:, 2, 3] = 5.0 + 60.0 * (1 + np.sin(23 * t))  # from 5 (into the plate) to 125
    angle = 0.6 * np.sin(17 * t)
    poses[:, 0, 0] = poses[:, 2, 2] = np.cos(angle)
    poses[:, 0, 2], poses[:, 2, 0] = np.sin(angle), -np.sin(angle)
    quick = checker.check(poses, clearance_mm=20.0)
    every = checker.check(poses, clearance_mm=20.0, exact=True)
    assert every.colliding.any() and (~every.colliding).sum() > 1000
    assert every.touching.any()
    np.testing.assert_array_equal(quick.colliding, every.colliding)
    np.testing.assert_array_equal(quick.touching, every.touching)
    assert np.all(quick.distance_mm <= every.distance_mm + 1e-6)
    # Most clear poses ride on a neighbour's measurement.
    clear = ~every.colliding
    assert quick.exact[clear].sum() < 0.1 * clear.sum()


def test_a_pass_hovering_at_the_clearance_collides_yes_or_no_where_measuring_says():
    """A pass along a post's wall whose lateral distance wavers about the clearance, turning
    as it goes (so edges and corners of the body come nearest too): the yes/no test agrees
    with measuring every pose, a body deep inside a closed block included."""
    post = trimesh.creation.box((40.0, 400.0, 200.0))
    post.apply_translation((0.0, 0.0, 100.0))
    checker = CollisionChecker(Part(post, name="post"), CUBE)
    t = np.linspace(0.0, 1.0, 1500)
    poses = np.stack(
        [at(20.0 + 10.0 + 20.37 + 1.5 * np.sin(40 * s), -150 + 300 * s, 100.0) for s in t]
    )
    angle = 0.3 * np.sin(13 * t)
    poses[:, 0, 0] = poses[:, 1, 1] = np.cos(angle)
    poses[:, 0, 1], poses[:, 1, 0] = -np.sin(angle), np.sin(angle)
    every = checker.check(poses, clearance_mm=20.0, exact=True)
    assert 200 < every.colliding.sum() < 1300  # both sides of the clearance
    np.testing.assert_array_equal(checker.colliding(poses, 20.0), every.colliding)
    np.testing.assert_array_equal(checker.colliding(poses, 0.0), every.touching)
    # Deep inside a closed block: no face within the clearance, colliding all the same.
    block = CollisionChecker(plate_part(thickness=100.0), CUBE)
    assert block.colliding(at(0.0, 0.0, -50.0)[None], 20.0).all()
    assert not block.colliding(at(0.0, 0.0, 200.0)[None], 20.0).any()


def test_a_box_pressed_into_a_plate_collides_by_its_depth():
    checker = CollisionChecker(plate_part(thickness=20.0), CUBE)
    depths = np.array([0.5, 3.0, 7.5])
    poses = np.stack([at(0, 0, 10.0 - d) for d in depths])
    report = checker.check(poses, clearance_mm=20.0)
    assert report.colliding.all() and report.touching.all()
    np.testing.assert_allclose(report.penetration_mm, depths, atol=1e-6)
    assert report.worst_penetration_mm == pytest.approx(7.5, abs=1e-6)
    assert report.colliding.sum() == 3 and report.touching.sum() == 3


def test_within_the_clearance_is_colliding_but_not_touching():
    checker = CollisionChecker(plate_part(), CUBE)
    report = checker.check(np.stack([at(0, 0, 10.0 + 4.0)]), clearance_mm=20.0)
    assert report.colliding[0] and not report.touching[0]
    assert report.distance_mm[0] == pytest.approx(4.0, abs=1e-6)
    assert report.penetration_mm[0] == 0.0


def test_a_body_wholly_inside_a_closed_part_collides():
    checker = CollisionChecker(plate_part(thickness=100.0), CUBE)
    report = checker.check(np.stack([at(0, 0, -50.0)]), clearance_mm=0.0)
    assert report.touching[0]
    assert report.penetration_mm[0] == pytest.approx(40.0, abs=1e-6)  # corners 40 deep


@pytest.mark.slow
@pytest.mark.parametrize("part_name", ["door", "drone"])
@pytest.mark.parametrize("planner", ["fixed", "geometric"])
def test_default_plans_keep_the_body_clear(part_name, planner, request):
    plans = request.getfixturevalue(f"{part_name}_plans")  # door_plans, drone_plans
    part, traj = plans.part, plans.plan(planner, roll=False)
    assert traj.meta["collisions_dropped"] == 0
    report = CollisionChecker(part, SPEC.sensor).check(traj.poses, 0.0)
    assert not report.touching.any()
    # Independently: FCL objects built here, a sample of poses with every transition pose.
    rng = np.random.default_rng(0)
    moving = np.flatnonzero(~traj.scanning)
    sample = np.concatenate([moving, rng.choice(len(traj), 20, replace=False)])
    for i in sample[::3]:
        assert fcl_distance(part, SPEC.sensor, traj.poses[i]) > 0


# ---- a post planted beside a plate --------------------------------------------------------


def plate_and_post() -> tuple[Part, Part]:
    """A 600 x 700 plate (top at 0) and, just past its +x end between the two passes, a
    60 x 60 post 600 mm tall: what the old 50 mm lift would have crossed through."""
    plate = trimesh.creation.box((600.0, 700.0, 10.0))
    plate.apply_translation((0.0, 0.0, -5.0))
    post = trimesh.creation.box((60.0, 60.0, 600.0))
    post.apply_translation((330.0, 0.0, 300.0))
    return Part(plate, name="plate"), Part(trimesh.util.concatenate([plate, post]), name="post")


POST_TOP = 600.0


def test_transitions_go_over_a_post_beside_the_part():
    plate, part = plate_and_post()
    swaths = plan_swaths(plate, SPEC.sensor, "x")  # the post is a fixture: not scanned
    assert len(swaths) == 2
    traj = plan_path(part, SPEC, make_planner("fixed"), swaths)
    moving = ~traj.scanning
    assert moving.sum() > 3
    assert traj.meta["collisions_dropped"] == 0
    # The old straight 50 mm lift across would hit the post.
    end0 = traj.poses[np.flatnonzero(traj.swath == 0)[-1]]
    old_height = end0[2, 3] + 50.0
    ys = np.linspace(end0[1, 3], -end0[1, 3], 41)
    old = np.stack([at(end0[0, 3], y, old_height) for y in ys])
    old[:, :3, :3] = end0[:3, :3]
    assert min(fcl_distance(part, SPEC.sensor, p) for p in old) <= 0
    # The planned one goes over it, clear at 0 mm for every pose (checked here with FCL).
    for pose in traj.poses[moving]:
        assert fcl_distance(part, SPEC.sensor, pose) > 0
    checker = CollisionChecker(part, SPEC.sensor)
    height = traj.poses[moving, 2, 3]
    crossing = traj.poses[moving][height > height.max() - 1e-6]
    assert len(crossing) > 3
    # The whole body, not just the emitter, passes above the post's top by the clearance.
    assert checker.body_corners_part(crossing)[..., 2].min() >= POST_TOP + SPEC.clearance_mm - 1e-6
    report = checker.check(traj.poses, SPEC.clearance_mm)
    assert not report.colliding.any()


def test_a_scanning_pose_inside_the_post_is_dropped_and_counted():
    _, part = plate_and_post()

    class Planner:
        """A straight pass whose middle poses run through the post."""

        name = "through"
        roll = False

        def plan(self, part_, swath, spec):
            from scanplan.core.trajectory import Trajectory

            s = np.arange(0.0, swath.length_mm, 10.0)
            poses = swath.poses(s, np.zeros_like(s), np.zeros_like(s))
            return Trajectory(poses, np.full(len(s), swath.index), np.ones(len(s), bool))

    from scanplan.planning.swaths import Swath

    u, v = np.array([0.0, 1.0, 0.0]), np.array([-1.0, 0.0, 0.0])
    # Along y through the post at x = 330 with the emitter at z = 300 (inside the post).
    swath = Swath(0, np.array([330.0, -400.0, 300.0]), np.array([330.0, 400.0, 300.0]), u, v)
    traj = plan_path(part, SPEC, Planner(), [swath])
    dropped = traj.meta["collisions_dropped"]
    checker = CollisionChecker(part, SPEC.sensor)
    planned = Planner().plan(part, swath, SPEC)
    assert dropped == int(checker.check(planned.poses, SPEC.clearance_mm).colliding.sum()) > 0
    assert traj.scanning.sum() == len(planned) - dropped
    # What is left, and the move around the post, is clear.
    assert not checker.check(traj.poses, SPEC.clearance_mm).colliding.any()
    assert (~traj.scanning).any()


def test_evaluate_reports_collisions_of_a_trajectory_through_the_post():
    from scanplan.core.trajectory import Trajectory

    plate, part = plate_and_post()
    (swath, _) = plan_swaths(plate, SPEC.sensor, "x")
    good = plan_path(part, SPEC, make_planner("fixed"), [swath])
    bad_pose = at(330.0, 0.0, 300.0)
    bad_pose[:3, :3] = good.poses[0, :3, :3]
    poses = np.concatenate([good.poses, bad_pose[None]])
    traj = Trajectory(poses, np.zeros(len(poses), int), np.r_[good.scanning, False])
    data = evaluate(part, SPEC, traj, points_per_profile=64).to_json_dict()
    assert data["collisions"]["count"] == 1 and data["collisions"]["count_touching"] == 1
    assert data["collisions"]["worst_penetration_mm"] > 0
    assert data["collisions"]["clearance_mm"] == SPEC.clearance_mm
    assert data["move_length_mm"] + data["scan_length_mm"] == pytest.approx(data["path_length_mm"])
    assert data["scan_time_s"] + data["move_time_s"] == pytest.approx(data["cycle_time_s"])
