"""The cell around the part: the table (and fixtures) in the collision world, the `--table`
option read with clear errors, and plans that keep the sensor body clear of both."""

from __future__ import annotations

import json

import numpy as np
import pytest
import trimesh
from typer.testing import CliRunner

from scanplan.cli import app
from scanplan.core.limits import TooLarge
from scanplan.core.sensor_spec import SensorSpec
from scanplan.world.cell import Cell
from scanplan.world.collision import checker_for
from scanplan.world.part import part_from_mesh

CUBE = SensorSpec(body_min_mm=(-10.0, -10.0, -10.0), body_max_mm=(10.0, 10.0, 10.0))


@pytest.fixture(scope="module")
def block():
    """A 100 mm cube standing on z = 0."""
    mesh = trimesh.creation.box((100.0, 100.0, 100.0))
    mesh.apply_translation((0, 0, 50.0))
    return part_from_mesh(mesh, "block")


def at(x: float, y: float, z: float) -> np.ndarray:
    T = np.eye(4)
    T[:3, 3] = x, y, z
    return T


def test_fixtures_are_counted_before_any_is_read(block, tmp_path):
    missing = [str(tmp_path / f"clamp{i}.stl") for i in range(101)]
    with pytest.raises(TooLarge, match=r"^--fixture: 101 is more than the 100 allowed"):
        Cell.around(block, fixtures=missing)
    with pytest.raises(TooLarge, match=r"^plan p.json: context: fixtures: 10,000 is more"):
        Cell.around(block, fixtures=["clamp.stl"] * 10_000, where="plan p.json: context: fixtures")
    with pytest.raises(ValueError, match=f"^fixture file {missing[0]} does not exist"):
        Cell.around(block, fixtures=missing[:100])


def test_the_table_option_reads_heights_none_and_refuses_the_rest(block):
    assert Cell.around(block).table_z_mm == 0.0  # resting on its lowest point
    assert Cell.around(block, "-25").table_z_mm == -25.0
    held = Cell.around(block, "none")
    assert held.table is None and held.table_z_mm is None
    for bad, fragment in (("abc", "expected a height"), ("nan", "finite"), ("10", "above")):
        with pytest.raises(ValueError, match=fragment):
            Cell.around(block, bad)
    with pytest.raises(ValueError, match="metres"):
        Cell.around(block, "-20000")


def test_the_body_is_checked_against_the_table_and_the_fixtures(block, tmp_path):
    fixture = trimesh.creation.box((20.0, 20.0, 20.0))
    fixture.apply_translation((200.0, 0, 10.0))
    path = tmp_path / "fixture.stl"
    fixture.export(path)
    cell = Cell.around(block, fixtures=[str(path)])
    checker = checker_for(block, CUBE, cell)
    poses = np.stack(
        [
            at(-200.0, 0, 100.0),  # 90 mm above the table, far from both: clear
            at(-200.0, 0, 25.0),  # its bottom 15 mm above the table: within 20 mm
            at(-200.0, 0, 5.0),  # its bottom 5 mm into the table
            at(200.0, 0, 45.0),  # 15 mm above the fixture
        ]
    )
    report = checker.check(poses, clearance_mm=20.0)
    assert report.colliding.tolist() == [False, True, True, True]
    assert report.colliding_with("table").tolist() == [False, True, True, False]
    assert report.colliding_with("fixtures").tolist() == [False, False, False, True]
    np.testing.assert_allclose(report.by_obstacle["table"][:3], [90.0, 15.0, -5.0], atol=1e-9)
    assert report.touching.tolist() == [False, False, True, False]
    # Yes or no, without measuring: the same answers, at the clearance and touching.
    assert checker.colliding(poses, 20.0).tolist() == [False, True, True, True]
    assert checker.colliding(poses, 0.0).tolist() == [False, False, True, False]
    # Without a cell, only the part counts.
    alone = checker_for(block, CUBE).check(poses, clearance_mm=20.0)
    assert not alone.colliding.any()
    # A cell turned with a view keeps the same plane in the view's frame.
    R = np.eye(4)
    R[:3, :3] = trimesh.transformations.rotation_matrix(0.3, [1, 0, 0])[:3, :3]
    turned = cell.rotated(R)
    assert turned.table is not None
    point = np.array([10.0, 20.0, 30.0])
    assert turned.table.height_mm(R[:3, :3] @ point) == pytest.approx(30.0)


def test_a_plan_keeps_clear_of_the_table_and_evaluate_counts_it(block, tmp_path):
    part = tmp_path / "block.stl"
    block.mesh.export(part)
    plan = tmp_path / "plan.json"
    runner = CliRunner()
    result = runner.invoke(app, ["plan", str(part), "--views", "auto", "-q", "-o", str(plan)])
    assert result.exit_code == 0, result.output
    context = json.loads(plan.read_text())["context"]
    assert context["table"] == "lowest" and context["fixtures"] == []
    result = runner.invoke(app, ["evaluate", str(part), str(plan), "--json", "--points", "96"])
    assert result.exit_code == 0, result.output
    collisions = json.loads(result.stdout)["collisions"]
    assert collisions["count"] == 0 and collisions["table"] == 0
    # Judged in another cell than it was planned in: said in one line.
    result = runner.invoke(
        app, ["evaluate", str(part), str(plan), "--json", "--points", "96", "--table", "none"]
    )
    assert result.exit_code == 0
    note = result.stderr.strip().splitlines()
    assert len(note) == 1 and "table none" in note[0] and "planned: table lowest" in note[0]
