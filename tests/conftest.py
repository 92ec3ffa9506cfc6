"""Shared fixtures, each built once per session: analytic parts whose right answers are known
(a flat plate, a plate tilted along the pass, a step, slopes across it), and the plans several
suites judge that take seconds each (the door and the drone per planner, the housing by views).

Property-based tests draw the same examples on every run, so CI is deterministic (a new
random example must not turn an unchanged tree red)."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
import trimesh
from hypothesis import settings

from helpers import PartPlans, sloped_housing
from scanplan.core.quantities import ScanSpec
from scanplan.core.trajectory import Trajectory
from scanplan.planning.pipeline import plan_views
from scanplan.planning.swaths import Swath
from scanplan.rl.planners import make_planner
from scanplan.world.part import Part, load_part, part_from_mesh

settings.register_profile("deterministic", derandomize=True, database=None)
settings.load_profile("deterministic")

X, Y = np.eye(3)[0], np.eye(3)[1]


@pytest.fixture(scope="session")
def plate() -> Part:
    """A flat plate 600 x 300 x 10 mm, top face at z = 0: a pass at W_d above it measures
    D = W_d, α = 0 on every profile (`helpers.plate_swath`, `helpers.straight`)."""
    mesh = trimesh.creation.box((600.0, 300.0, 10.0))
    mesh.apply_translation((0, 0, -5.0))  # top face at z = 0
    return part_from_mesh(mesh, "plate")


@pytest.fixture(scope="session")
def tilted_plate() -> Part:
    """A plate 300 x 100 x 10 mm tilted 20° about y, so that a pass along x runs down it: 20°
    off a vertical beam, beyond the 15° in-spec tolerance, on every point."""
    mesh = trimesh.creation.box((300.0, 100.0, 10.0))
    mesh.apply_transform(trimesh.transformations.rotation_matrix(math.radians(20.0), Y))
    return part_from_mesh(mesh, "tilted")


@pytest.fixture(scope="session")
def stepped_plate() -> Part:
    """A 600 x 200 plate (top at z = 0) with a block 40 mm high on its second half (x > 0): a
    step up across the whole width of a pass along x."""
    low = trimesh.creation.box((600.0, 200.0, 10.0))
    low.apply_translation((0.0, 0.0, -5.0))
    high = trimesh.creation.box((300.0, 200.0, 40.0))
    high.apply_translation((150.0, 0.0, 20.0))
    return part_from_mesh(trimesh.util.concatenate([low, high]), "step")


@pytest.fixture()
def plate_file(tmp_path) -> Path:
    """A 400 x 200 x 10 mm plate as an STL file, for the command line."""
    mesh = trimesh.creation.box((400.0, 200.0, 10.0))
    path = tmp_path / "plate.stl"
    mesh.export(path)
    return path


@pytest.fixture(scope="session")
def cross_slope_plate() -> Part:
    """A 600 x 300 plate tilted 20° about the x axis (the scan direction): a cross slope."""
    box = trimesh.creation.box((600.0, 300.0, 10.0))
    box.apply_transform(trimesh.transformations.rotation_matrix(math.radians(20.0), [1, 0, 0]))
    return part_from_mesh(box, "cross-slope")


@pytest.fixture(scope="session")
def tilted_strip() -> Part:
    """A strip 400 x 60 mm tilted 20° about the scan direction x: every point is 20° off a
    vertical beam, and the depth stays within ±11 mm of W_d across it."""
    mesh = trimesh.creation.box((400.0, 60.0, 1.0))
    mesh.apply_translation((0, 0, -0.5))
    mesh.apply_transform(trimesh.transformations.rotation_matrix(math.radians(20), X))
    return part_from_mesh(mesh, "tilted-strip")


@pytest.fixture(scope="session")
def straight_pass() -> Trajectory:
    """A straight pass along x at W_d above z = 0, pitch 0, a profile every 0.5 mm."""
    sw = Swath(0, np.array([-320.0, 0, 400.0]), np.array([320.0, 0, 400.0]), X, Y)
    s = np.arange(120.0, 520.0, 0.5)
    poses = sw.poses(s, 0 * s, 0 * s)
    return Trajectory(poses, np.zeros(len(s), int), np.ones(len(s), bool), planner="straight")


@pytest.fixture(scope="session")
def step_block() -> Part:
    """A plate 600 x 400 mm (top at z = 0) with a block 60 mm high along its +y edge
    (y from 100 to 200 mm); faces of at most 20 mm, so a box ROI selects them cleanly."""
    plate = trimesh.creation.box((600.0, 400.0, 10.0))
    plate.apply_translation((0, 0, -5.0))
    block = trimesh.creation.box((600.0, 100.0, 60.0))
    block.apply_translation((0, 150.0, 30.0))
    mesh = trimesh.util.concatenate([plate, block])
    vertices, faces = trimesh.remesh.subdivide_to_size(mesh.vertices, mesh.faces, 20.0)
    return part_from_mesh(trimesh.Trimesh(vertices, faces), "step-block")


@pytest.fixture(scope="session")
def housing() -> Part:
    """A housing 600 x 400 x 150 mm whose four side walls slope at 60°: a part of views."""
    return sloped_housing()


@pytest.fixture(scope="session")
def housing_views(housing):
    """The housing planned by views (`--views auto`, geometric planner): (views, trajectory)."""
    return plan_views(housing, ScanSpec(), make_planner("geometric"), "auto")


@pytest.fixture(scope="session")
def door() -> Part:
    return load_part("door")


@pytest.fixture(scope="session")
def door_plans(door) -> PartPlans:
    """The door planned once per planner (and roll setting), on first use: several suites
    judge the same plans, which take seconds each."""
    return PartPlans(door)


@pytest.fixture(scope="session")
def drone_plans() -> PartPlans:
    return PartPlans(load_part("drone"))
