"""The arm's links in the cell: capsules that follow the kinematics, checked against the part,
the fixtures and the table block; the quick voxel test never clears what FCL finds."""

from __future__ import annotations

import fcl
import numpy as np
import pytest
import trimesh
from scipy.spatial import cKDTree

import scanplan.robot.links as links_module
from scanplan.robot import ROBOT_NAMES, get_robot
from scanplan.robot.links import (
    LinkClearance,
    check_links,
    column_clear,
    obstacles_for,
    on_table_z,
)
from scanplan.world.capsule_collision import CellObstacles, _DistanceField, _SurfaceProxy
from scanplan.world.cell import TABLE_MARGIN_MM, Cell
from scanplan.world.part import part_from_mesh

CLEARANCE = 20.0  # the plan clearance the links keep, as the sensor body does

RNG = np.random.default_rng(7)


def _box_part(extents, centre):
    box = trimesh.creation.box(extents)
    box.apply_translation(centre)
    return part_from_mesh(box, "box")


@pytest.mark.parametrize("name", ROBOT_NAMES)
def test_capsules_follow_the_chain_to_the_flange(name) -> None:
    arm = get_robot(name)
    q = RNG.uniform(-1.5, 1.5, (20, 6))
    ends, radii, names = arm.link_capsules(q)
    assert ends.shape == (20, len(names), 2, 3) and radii.shape == (len(names),)
    assert (radii > 20).all() and (radii < 250).all()
    # The last link ends at the flange, wherever the joints put it.
    assert np.allclose(ends[:, -1, 1], arm.forward(q)[:, :3, 3], atol=1e-6)
    # Rigid links: each capsule keeps its length whatever the joints.
    length = np.linalg.norm(ends[..., 1, :] - ends[..., 0, :], axis=-1)
    assert np.allclose(length, length[0], atol=1e-6)


def test_a_box_in_the_forearms_way_is_named() -> None:
    arm = get_robot("kr6-r900")
    q = np.zeros((1, 6))  # arm stretched out along +x at 435 mm
    ends, _, names = arm.link_capsules(q)
    forearm = 0.5 * (ends[0, 4, 0] + ends[0, 4, 1])
    part = _box_part((40, 40, 40), forearm + (0, 0, 80))  # just above the forearm
    obstacles = obstacles_for(part, Cell())
    report = check_links(arm, q, obstacles, np.eye(4))
    assert report.colliding[0] and names[report.link[0]] in ("elbow", "forearm")
    assert "part" in report.describe(0)
    # Moved 300 mm higher, it is clear.
    far = obstacles_for(_box_part((40, 40, 40), forearm + (0, 0, 380)), Cell())
    assert check_links(arm, q, far, np.eye(4)).clear


def test_the_table_block_and_the_arm_beside_it() -> None:
    arm = get_robot("ur5e")
    part = _box_part((200, 200, 50), (0, 0, 25))
    cell = Cell.around(part)  # resting on a table at z = 0
    lo, hi = cell.table_block(part)
    assert np.allclose(lo[:2], -100 - TABLE_MARGIN_MM) and hi[2] == 0.0
    T = np.eye(4)
    # The base 300 mm from the part's centre, below the table top: the column is in the block.
    T[:3, 3] = (-300.0, 0.0, 200.0)
    assert not column_clear(arm, T[None], (lo, hi), CLEARANCE)[0]
    # On the table top (the table below the column): clear; far beside it: clear.
    T[:3, 3] = (-300.0, 0.0, -1.0)
    assert column_clear(arm, T[None], (lo, hi), CLEARANCE)[0]
    T[:3, 3] = (-700.0, 0.0, 200.0)
    assert column_clear(arm, T[None], (lo, hi), CLEARANCE)[0]


def test_a_joint_move_through_the_part_is_caught() -> None:
    arm = get_robot("kr6-r900")
    # Joint 1 swings the stretched arm from -60° to +60°: a post at 0° is in the way.
    q = np.zeros((2, 6))
    q[0, 0], q[1, 0] = np.radians(-60), np.radians(60)
    post = _box_part((60, 60, 600), (700.0, 0.0, 300.0))
    obstacles = obstacles_for(post, Cell())
    report = check_links(arm, q, obstacles, np.eye(4), pass_start=np.array([False, True]))
    assert not report.colliding.any()  # neither end touches the post
    assert 1 in report.moves and not report.clear
    assert "joint move" in report.describe(1)


def test_the_voxel_test_never_clears_what_fcl_finds() -> None:
    # A curved part: every capsule the quick test clears keeps its clearance from the mesh.
    mesh = trimesh.creation.icosphere(subdivisions=3, radius=120.0)
    part = part_from_mesh(mesh, "sphere")
    obstacles = CellObstacles(part, Cell(), CLEARANCE)
    rng = np.random.default_rng(11)  # its own draws, whatever ran before it
    centre = rng.uniform(-250, 250, (400, 3))
    axis = rng.normal(size=(400, 3))
    axis = 60.0 * axis / np.linalg.norm(axis, axis=1, keepdims=True)
    ends = np.stack([centre - axis, centre + axis], axis=1)[:, None]
    radii = np.full(1, 30.0)
    hit = obstacles.capsules_hit(ends, radii, CLEARANCE)[:, 0]
    bvh = fcl.BVHModel()
    bvh.beginModel(len(mesh.vertices), len(mesh.faces))
    bvh.addSubModel(np.asarray(mesh.vertices), np.asarray(mesh.faces, np.int32))
    bvh.endModel()
    sphere = fcl.CollisionObject(bvh, fcl.Transform())
    for (a, b), h in zip(ends[:, 0], hit, strict=True):
        segment = fcl.CollisionObject(
            fcl.Capsule(30.0, float(np.linalg.norm(b - a))),
            fcl.Transform(_z_to(b - a), 0.5 * (a + b)),
        )
        d = fcl.distance(segment, sphere, fcl.DistanceRequest(), fcl.DistanceResult())
        assert (h == 0) == (d < CLEARANCE), (d, h)
    assert 50 < (hit == 0).sum() < 350  # both verdicts are exercised
    # Without FCL the verdict is cautious: every capsule FCL finds hitting still hits.
    quick = obstacles.capsules_hit(ends, radii, CLEARANCE, exact=False)[:, 0]
    assert (quick[hit == 0] == 0).all() and (quick == 0).sum() <= (hit == 0).sum() + 15


def _z_to(d: np.ndarray) -> np.ndarray:
    from scipy.spatial.transform import Rotation

    d = d / np.linalg.norm(d)
    rot, _ = Rotation.align_vectors([d], [[0.0, 0.0, 1.0]])
    return rot.as_matrix()


def test_an_arm_over_the_table_stands_on_it_not_in_the_air() -> None:
    arm = get_robot("kr6-r900")
    part = _box_part((200, 200, 50), (0, 0, 25))
    block = Cell.around(part).table_block(part)
    T = np.eye(4)
    T[:3, 3] = (-200.0, 0.0, -30.0)  # over the table, on a 30 mm plate: fine
    assert column_clear(arm, T[None], block, CLEARANCE)[0]
    T[:3, 3] = (-200.0, 0.0, -250.0)  # over the table on a 250 mm riser nothing models
    assert not column_clear(arm, T[None], block, CLEARANCE)[0]


def test_a_turn_about_the_beam_is_checked_for_the_sensor_body() -> None:
    # The body is not symmetric about the beam: a tilted pose clear of the table may put the
    # body into it once turned half a turn, and the cell check says so.
    from scipy.spatial.transform import Rotation

    from scanplan.core.sensor_spec import DEFAULT_SENSOR, PRESETS
    from scanplan.robot.flown_poses import HALF_TURN

    part = _box_part((300, 300, 20), (0, 0, 10))
    obstacles = obstacles_for(part, Cell.around(part), PRESETS[DEFAULT_SENSOR], 20.0)
    rng = np.random.default_rng(3)
    poses = np.tile(np.eye(4), (2000, 1, 1))
    tilt = rng.uniform(-1.4, 1.4, (2000, 2))
    down = Rotation.from_euler("x", np.pi)  # the beam (z_s) pointing down
    poses[:, :3, :3] = (Rotation.from_euler("xy", tilt) * down).as_matrix()
    poses[:, :3, 3] = rng.uniform((-150, -150, 20), (150, 150, 400), (2000, 3))
    planned, turned = obstacles.sensor_clear(poses), obstacles.sensor_clear(poses @ HALF_TURN)
    assert (planned & ~turned).any() and (turned & ~planned).any()
    # Without the sensor, only the links are checked: every pose passes this test.
    assert obstacles_for(part, Cell.around(part)).sensor_clear(poses @ HALF_TURN).all()


def test_the_table_block_is_measured_as_fcl_measures_a_capsule_against_a_box() -> None:
    from scanplan.world.capsule_collision import segment_box_distance

    lo, hi = np.array([-300.0, -200.0, -40.0]), np.array([300.0, 200.0, 0.0])
    box = fcl.CollisionObject(fcl.Box(*(hi - lo)), fcl.Transform(0.5 * (lo + hi)))
    rng = np.random.default_rng(4)
    ends = rng.uniform([-500, -400, -200], [500, 400, 300], (300, 2, 3))
    far = segment_box_distance(ends, lo, hi)
    radius = 20.0
    for (a, b), d in zip(ends, far, strict=True):
        capsule = fcl.CollisionObject(
            fcl.Capsule(radius, float(np.linalg.norm(b - a))),
            fcl.Transform(_z_to(b - a), 0.5 * (a + b)),
        )
        result = fcl.DistanceResult()
        measured = fcl.distance(capsule, box, fcl.DistanceRequest(), result)
        if measured > 1e-6:  # apart: the same distance
            assert d - radius == pytest.approx(measured, abs=1e-3)
        else:  # touching or inside: within the radius
            assert d <= radius + 1e-6
    assert (far == 0).any() and (far > 50).any()


def test_a_pass_that_could_not_gain_by_turning_is_not_checked_turned_and_chosen_alike() -> None:
    # Passes over a plate, tilted pass by pass, a UR5e placed beside it: the per-pass choice
    # between planned and turned is the same whether the turned poses of passes that cannot
    # gain are checked or not, and some are not.
    from scipy.spatial.transform import Rotation

    from scanplan.core.sensor_spec import DEFAULT_SENSOR, PRESETS
    from scanplan.core.trajectory import Trajectory
    from scanplan.robot.flown_poses import flyable_poses, kept_by_pass, turned_passes

    part = _box_part((400, 400, 20), (0, 0, 10))
    obstacles = obstacles_for(part, Cell.around(part), PRESETS[DEFAULT_SENSOR], 20.0)
    rng = np.random.default_rng(5)
    blocks, swath, scanning = [], [], []
    for k in range(10):
        tilt = rng.uniform(-0.6, 0.6, 2)
        # Every other pass flown with the sensor turned the other way about the vertical.
        yaw = Rotation.from_euler("z", np.pi * (k % 2))
        R = (yaw * Rotation.from_euler("xy", tilt) * Rotation.from_euler("x", np.pi)).as_matrix()
        T = np.tile(np.eye(4), (30, 1, 1))
        T[:, :3, :3] = R
        T[:, 0, 3] = np.linspace(-180, 180, 30)
        T[:, 1, 3] = -180 + 40 * k
        T[:, 2, 3] = 300.0
        blocks.append(T)
        swath += [k] * 30
        scanning += [True] * 30
    traj = Trajectory(np.concatenate(blocks), np.array(swath), np.array(scanning))
    arm = get_robot("ur5e")
    tcp = np.eye(4)
    tcp[:3, 3] = 120.0, 0.0, 90.0  # a bracket off to the side: turned, the flange moves
    T_base_part = np.eye(4)
    T_base_part[:3, 3] = 600.0, 0.0, -200.0  # the far passes at the edge of the reach
    inv_tcp = np.linalg.inv(tcp)
    full = flyable_poses(traj, arm, T_base_part, inv_tcp, obstacles, exact=False)
    every = np.ones(len(traj), bool)
    both = flyable_poses(traj, arm, T_base_part, inv_tcp, obstacles, exact=False, choosing=every)
    np.testing.assert_array_equal(both[0], full[0])
    np.testing.assert_array_equal(kept_by_pass(traj.swath, *both), kept_by_pass(traj.swath, *full))
    scan = flyable_poses(
        traj, arm, T_base_part, inv_tcp, obstacles, exact=False, choosing=traj.scanning
    )
    np.testing.assert_array_equal(
        turned_passes(traj.swath, *scan), turned_passes(traj.swath, *full)
    )
    assert len(turned_passes(traj.swath, *full))  # some passes are better turned
    assert (full[1] & ~both[1]).any()  # and some turned poses were left unchecked


@pytest.mark.parametrize("subdivisions", [1, 5])
def test_the_surface_cloud_holds_every_point_of_a_coarse_or_fine_mesh_within_its_bound(
    subdivisions,
) -> None:
    # A coarse sphere gets a grid on each triangle; a fine one (every edge shorter than the
    # spacing) is its vertices alone. Either way each surface point lies within 2 spacings.
    from scipy.spatial import cKDTree

    from scanplan.world.capsule_collision import _surface_points

    mesh = trimesh.creation.icosphere(subdivisions=subdivisions, radius=20.0)
    spacing = 1.0
    edges = np.linalg.norm(np.diff(mesh.vertices[mesh.edges_unique], axis=1)[:, 0], axis=1)
    assert (edges.max() > spacing) == (subdivisions == 1)
    cloud = _surface_points(mesh, spacing)
    if subdivisions == 5:
        assert len(cloud) == len(mesh.vertices)
    probe, _ = trimesh.sample.sample_surface(mesh, 5000, seed=1)
    assert cKDTree(cloud).query(probe)[0].max() <= 2 * spacing


@pytest.mark.parametrize("name", ROBOT_NAMES)
def test_the_on_table_height_stands_the_arm_on_the_tables_top(name) -> None:
    """At `on_table_z` an upright arm over the table block stands on its top (column_clear
    says so); 400 mm lower its column is in the table, 60 mm higher it floats over it; an
    arm it gives no height for stands on the top at none."""
    arm = get_robot(name)
    block = (np.array([-300.0, -300.0, -1000.0]), np.array([300.0, 300.0, 0.0]))
    z = on_table_z(arm, block, 20.0)

    def at(height: float) -> np.ndarray:
        T = np.eye(4)
        T[:3, 3] = 0.0, 200.0, height  # the base over the block, 200 mm from its middle
        return T

    if z is None:  # its column reaches too far below its base frame: no height stands it
        assert not any(column_clear(arm, at(-h), block, 20.0)[0] for h in range(-400, 400, 5))
        return
    assert column_clear(arm, at(z), block, 20.0).all()
    assert not column_clear(arm, at(z + 400.0), block, 20.0).any()
    assert not column_clear(arm, at(z - 60.0), block, 20.0).any()


def test_a_memo_gives_the_same_report_and_asks_the_cell_only_for_what_is_new(monkeypatch) -> None:
    arm = get_robot("kr6-r900")
    # The arm sweeping joints 1 and 2 past a post: some poses hit it, some clear it.
    q = np.zeros((120, 6))
    q[:, 0] = np.linspace(-0.8, 0.8, 120)
    q[:, 1] = np.linspace(-0.3, 0.3, 120)
    obstacles = obstacles_for(_box_part((60, 60, 600), (700.0, 0.0, 300.0)), Cell())
    starts = np.zeros(120, bool)
    starts[60] = True
    alone = [check_links(arm, q[:n], obstacles, np.eye(4), starts[:n]) for n in (120, 90)]
    assert alone[0].colliding.any() and not alone[0].colliding.all()
    asked: list[int] = []
    real = CellObstacles.capsules_hit

    def counting(self, ends, radii, clearance_mm, exact=True):
        asked.append(len(ends))
        return real(self, ends, radii, clearance_mm, exact)

    monkeypatch.setattr(CellObstacles, "capsules_hit", counting)
    memo: dict = {}
    first = check_links(arm, q, obstacles, np.eye(4), starts, memo=memo)
    asked_first, asked[:] = sum(asked), []
    again = check_links(arm, q[:90], obstacles, np.eye(4), starts[:90], memo=memo)
    for report, fresh in zip((first, again), alone, strict=True):
        assert np.array_equal(report.link, fresh.link)
        assert np.array_equal(report.obstacle, fresh.obstacle)
        assert report.moves == fresh.moves
    # The second path is the first's start: only its last checked pose, which stands for
    # fewer poses now, is new to the cell.
    assert asked_first > 5 and sum(asked) <= 1


def test_a_checked_pose_stands_for_poses_whose_capsules_its_grown_ones_hold() -> None:
    arm = get_robot("ur5e")
    rng = np.random.default_rng(5)
    # Passes of small steps, a jump between them, and a pose standing still for a while.
    q = np.cumsum(rng.normal(0.0, 0.004, (600, 6)), axis=0)
    q[300:] += 0.5
    q[400:480] = q[400]
    ends, radii, _ = arm.link_capsules(q)
    first, group, grown = links_module._stride_groups(ends, radii)
    assert first[0] == 0 and np.array_equal(first, np.flatnonzero(np.diff(np.r_[-1, group])))
    assert 300 in first  # the jump starts a group
    assert np.diff(np.r_[first, len(q)]).max() <= links_module._MAX_SPAN
    assert 1 < len(q) / len(first) < 64  # a checked pose stands for several
    moved = np.linalg.norm(ends - ends[first][group], axis=-1).max(axis=-1)  # (m, k)
    assert (moved <= links_module.LINK_STRIDE_MM + 1e-9).all()
    assert (moved <= grown[group] - radii + 1e-12).all()
    assert np.allclose(grown.max(axis=0), radii + moved.max(axis=0))


def test_a_path_asked_again_is_answered_from_the_memo(monkeypatch) -> None:
    # The reach check's choice asks the quick check along each pass's branches; the fit's
    # rounds ask again about passes left as they were: answered without the links checked.
    arm = get_robot("kr6-r900")
    q = np.zeros((120, 2, 6))
    q[:, :, 0] = np.linspace(-0.8, 0.8, 120)[:, None]
    q[:, 1, 1] = 0.4  # the second branch leans towards the post
    obstacles = obstacles_for(_box_part((60, 60, 600), (700.0, 0.0, 300.0)), Cell())
    fresh = LinkClearance(arm, obstacles, np.eye(4)).clear_along(0, q)
    assert fresh.any() and not fresh.all()
    memo: dict = {}
    first = LinkClearance(arm, obstacles, np.eye(4), memo).clear_along(0, q)
    checked: list[int] = []
    real = links_module.check_links

    def counting(*args, **kwargs):
        checked.append(1)
        return real(*args, **kwargs)

    monkeypatch.setattr(links_module, "check_links", counting)
    again = LinkClearance(arm, obstacles, np.eye(4), memo).clear_along(0, q)
    assert checked == [] and np.array_equal(again, fresh) and np.array_equal(first, fresh)
    moved = LinkClearance(arm, obstacles, np.eye(4), memo).clear_along(0, q[:100])
    assert len(checked) == 2 and np.array_equal(moved, fresh[:100])  # a new path: checked
    # A joint move asked again, too.
    move = (0, q[0, 0], 119, q[119, 1])
    told = LinkClearance(arm, obstacles, np.eye(4)).clear_move(*move)
    assert LinkClearance(arm, obstacles, np.eye(4), memo).clear_move(*move) is told
    asked = len(checked)
    assert LinkClearance(arm, obstacles, np.eye(4), memo).clear_move(*move) is told
    assert len(checked) == asked


def test_the_distance_field_bounds_the_distance_to_the_nearest_cloud_point() -> None:
    rng = np.random.default_rng(3)
    # A curved sheet of points, as a surface cloud is.
    u, v = rng.uniform(0, 200, (2, 20_000))
    cloud = np.stack([u, v, 30 * np.sin(u / 40)], axis=1)
    field = _DistanceField(cloud, cell=4.0)
    points = rng.uniform(-150, 350, (20_000, 3))
    lo, hi = field.bounds(points)
    d, _ = cKDTree(cloud).query(points)
    assert (lo <= d).all() and (d <= hi).all()
    inside = np.isfinite(hi)
    assert inside.mean() > 0.2 and (hi[inside] - lo[inside] < 14.0).all()  # two diagonals
    assert (lo[~inside] == 0).all()  # outside its grid it knows nothing


def test_the_surface_proxy_says_what_the_exact_distances_of_a_capsules_axis_points_say():
    # What `within` decides from the distance field's bounds, and the k-d tree only where
    # they straddle, is what every axis point's exact nearest cloud point says.
    part = part_from_mesh(trimesh.creation.icosphere(3, radius=30.0), "ball")
    proxy = _SurfaceProxy(part)
    assert proxy._cloud is not None
    cloud = cKDTree(proxy._cloud.copy())
    rng = np.random.default_rng(5)
    m = 2000
    a = rng.uniform(-80, 80, (m, 3))
    step = rng.normal(size=(m, 3))
    step *= rng.uniform(0, 80, (m, 1)) / np.linalg.norm(step, axis=1, keepdims=True)
    segments = np.stack([a, a + step], axis=1)
    radii = rng.uniform(2.0, 25.0, m)
    maybe, surely = proxy.within(segments, radii)
    reach = radii + proxy.bound_mm + 0.5 * proxy.pitch
    count = np.ceil(np.linalg.norm(step, axis=1) / proxy.pitch).astype(int) + 1
    owner = np.repeat(np.arange(m), count)
    t = np.concatenate([np.linspace(0.0, 1.0, c) for c in count])
    d = cloud.query(a[owner] + t[:, None] * step[owner], distance_upper_bound=200.0)[0]
    nearest = np.full(m, np.inf)
    np.minimum.at(nearest, owner, d)
    np.testing.assert_array_equal(surely, nearest <= radii)
    np.testing.assert_array_equal(maybe, nearest <= reach)
    assert 0.1 < surely.mean() and surely.sum() < maybe.sum() < m  # all three verdicts occur
