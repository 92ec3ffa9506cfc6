"""Shared fixtures: analytic parts whose right answers are known, built once per session.

Property-based tests draw the same examples on every run, so CI is deterministic (a new
random example must not turn an unchanged tree red)."""

from __future__ import annotations

import math

import numpy as np
import pytest
import trimesh
from hypothesis import settings

from scanplan.part import Part, part_from_mesh
from scanplan.swaths import Swath
from scanplan.trajectory import Trajectory

settings.register_profile("deterministic", derandomize=True, database=None)
settings.load_profile("deterministic")

X, Y = np.eye(3)[0], np.eye(3)[1]


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
    length, width, height, slope_deg = 600.0, 400.0, 150.0, 60.0
    inset = height / math.tan(math.radians(slope_deg))
    lo = [(x, y, 0.0) for x in (-length / 2, length / 2) for y in (-width / 2, width / 2)]
    hi = [
        (x, y, height)
        for x in (-length / 2 + inset, length / 2 - inset)
        for y in (-width / 2 + inset, width / 2 - inset)
    ]
    return part_from_mesh(trimesh.Trimesh(lo + hi).convex_hull, "housing")
