"""In-spec coverage over perturbed parts (metrics.robustness): zero perturbation is the
nominal figure exactly, seeded runs repeat exactly, a Dask cluster gives the local numbers."""

from __future__ import annotations

import importlib.util
from concurrent.futures import ProcessPoolExecutor

import numpy as np
import pytest
import trimesh

from helpers import fixture_files, loopback_cluster, straight
from scanplan.core.context import PlanContext
from scanplan.core.quantities import ScanSpec
from scanplan.core.sensor_spec import SensorSpec
from scanplan.judging import evaluate, robustness, trial_tasks
from scanplan.judging.robustness import trial_world
from scanplan.sensor.perturb import Perturbation
from scanplan.world.part import load_part, part_from_mesh

SPEC = ScanSpec(SensorSpec())
POINTS = 128
# A short pass over the middle of the 600 x 300 plate: part of its top in spec, edges not.
TRAJ = straight(np.arange(150.0, 450.0, 0.5))


def _run(part, text, trials=2, seed=0, run=map):
    tasks = trial_tasks(part, SPEC, TRAJ, Perturbation.parse(text), trials, seed, POINTS)
    return robustness(tasks, run)


def test_zero_perturbation_is_the_nominal_figure_exactly(plate):
    nominal = evaluate(plate, SPEC, TRAJ, points_per_profile=POINTS, ceiling=False)
    r = _run(plate, "place:0mm,0deg;warp:0mm@200mm;scale:0%;path:0mm,0deg")
    assert 0.1 < nominal.in_spec_coverage < 0.9
    assert list(r.per_trial) == [nominal.in_spec_coverage] * 2
    in_spec = nominal.coverage_map.state == 2
    assert np.array_equal(r.in_spec_share, in_spec.astype(float))
    assert r.fragile_fraction == 0.0


def test_seeded_runs_repeat_and_perturbations_cost_coverage(plate):
    text = "place:30mm,2deg;path:0.5mm"
    a, b = _run(plate, text, seed=4), _run(plate, text, seed=4)
    assert np.array_equal(a.per_trial, b.per_trial)
    assert np.array_equal(a.in_spec_share, b.in_spec_share)
    nominal = _run(plate, "path:0mm").mean
    assert a.worst < nominal and a.per_trial[0] != a.per_trial[1]
    data = a.to_json_dict()
    assert data["trials"] == 2 and data["spec"] == Perturbation.parse(text).text()
    assert data["worst"] <= data["p5"] <= data["mean"]


def test_trials_in_worker_processes_give_the_serial_numbers(plate):
    text = "place:10mm,1deg;warp:2mm@100mm"
    with ProcessPoolExecutor(2) as pool:
        parallel = _run(plate, text, run=pool.map)
    assert np.array_equal(parallel.per_trial, _run(plate, text).per_trial)


@pytest.mark.skipif(
    importlib.util.find_spec("distributed") is None, reason="dask distributed not installed"
)
def test_a_loopback_dask_cluster_gives_the_local_numbers(plate):
    from scanplan.core.run import task_runner as trial_runner  # what evaluate --scheduler runs

    text = "place:10mm,1deg;path:0.2mm"
    with (
        loopback_cluster() as cluster,
        trial_runner(cluster.scheduler_address, 2) as run,
    ):
        on_dask = _run(plate, text, run=run)
    assert np.array_equal(on_dask.per_trial, _run(plate, text).per_trial)


def test_a_warped_part_is_judged_on_the_nominal_samples_it_lies_over():
    # 2 mm RMS of warp is twice the in-spec radius: points left on the as-built surface
    # would miss the nominal samples; carried back per face they find them.
    box = trimesh.creation.box((600.0, 300.0, 10.0))
    box.apply_translation((0, 0, -5.0))
    v, f = trimesh.remesh.subdivide_to_size(box.vertices, box.faces, 20.0)
    fine = part_from_mesh(trimesh.Trimesh(v, f), "fine plate")
    nominal = _run(fine, "path:0mm", trials=1).mean
    warped = _run(fine, "warp:2mm@150mm", trials=1).mean
    assert warped == pytest.approx(nominal, abs=0.01)


def test_a_displaced_part_moves_among_fixtures_that_stay_where_the_cell_holds_them(plate, tmp_path):
    lid = fixture_files(tmp_path, plate)[0]
    context = PlanContext(SPEC, fixtures=(lid,))
    model = Perturbation.parse("place:20mm,2deg")
    task = trial_tasks(plate, SPEC, TRAJ, model, 1, 3, POINTS, context=context)[0]
    world = trial_world(task)
    assert not np.allclose(world.T_part_placed, np.eye(4), atol=1e-3)
    # The part is measured in its own frame: there the lid is where the cell holds it, seen
    # from the part as placed.
    (seen_from_part,) = world.part.occluders
    R, t = world.T_part_placed[:3, :3], world.T_part_placed[:3, 3]
    in_cell = load_part(lid).mesh.vertices
    assert np.allclose(seen_from_part.vertices @ R.T + t, in_cell, atol=1e-9)
