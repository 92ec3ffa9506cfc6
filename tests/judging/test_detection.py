"""What a scan finds (metrics.detection, pod, detectability): on a flat plate scanned at the
working distance, a dent of ~12 σ over 5 profile spacings is found in every trial and one of
0.8 σ almost never; the defect-free plate makes no call; the POD fit recovers a known curve
and says plainly when the data allow none; the predicted a90 matches the measured one."""

from __future__ import annotations

import importlib.util
from dataclasses import replace

import numpy as np
import pytest
import trimesh

from helpers import fixture_files, loopback_cluster, straight
from scanplan.core.context import PlanContext
from scanplan.core.quantities import ScanSpec, norm_rows
from scanplan.judging.detection import (
    DefectTask,
    cos_incidence,
    defect_run,
    defect_tasks,
    detector_for,
    run_defect_trial,
    sigma_mm,
)
from scanplan.judging.evaluation import evaluate, surface_samples
from scanplan.judging.pod import fit_pod
from scanplan.judging.survey import DetectabilitySurvey, _pitch_and_noise, survey
from scanplan.sensor.defects import Defect
from scanplan.sensor.profilometer import LineProfilometer
from scanplan.world.part import part_from_mesh
from scanplan.world.surface import VisibleSurface

SPEC = ScanSpec()
SENSOR = SPEC.sensor
Z, X = np.array([0.0, 0.0, 1.0]), np.array([1.0, 0.0, 0.0])


def _plate(length: float = 400.0) -> trimesh.Trimesh:
    mesh = trimesh.creation.box((length, 300.0, 10.0))
    mesh.apply_translation((0, 0, -5.0))  # top face at z = 0, W_d below the pass
    return mesh


def _sigma_at_wd() -> float:
    """σ of a point on the plate at W_d, facing the sensor (noise and quantization)."""
    noise = SENSOR.noise.std_mm(np.array([SENSOR.working_distance_mm]), np.ones(1), 400.0)[0]
    return float(np.hypot(noise, SENSOR.z_resolution_mm / np.sqrt(12.0)))


def test_deep_wide_dent_always_found_shallow_almost_never():
    mesh = _plate()
    # A pass along x over x in [-60, 60]: profiles 0.5 mm apart, the line across the plate.
    traj = straight(np.arange(260.0, 380.0, 0.5))
    detector = detector_for(traj, SENSOR)
    sigma = _sigma_at_wd()
    spacing = 0.5
    width = 5 * spacing  # wider than 4 profile spacings
    rng = np.random.default_rng(7)
    found = {"deep": [], "shallow": []}
    for trial in range(6):
        xs = np.linspace(-45, 45, 4) + rng.uniform(-3, 3, 4)
        ys = np.array([-100.0, -35.0, 35.0, 100.0]) + rng.uniform(-3, 3, 4)
        defects = [
            Defect("dent", np.array([x, y, 0.0]), Z, X, depth, width)
            for x, y, depth in zip(xs, ys, [12 * sigma, 0.8 * sigma] * 2, strict=True)
        ]
        task = DefectTask("plate", mesh.vertices, mesh.faces, None, SENSOR, traj.poses,
                          tuple(defects), detector, noise_seed=trial)  # fmt: skip
        out = run_defect_trial(task)
        assert (out[:, 2] > 20).all()  # every defect under the scan, densely sampled
        found["deep"] += list(out[0::2, 0])
        found["shallow"] += list(out[1::2, 0])
    assert np.mean(found["deep"]) == 1.0
    assert np.mean(found["shallow"]) <= 1 / 12


def test_defect_free_plate_no_call_and_predicted_a90_matches_measured():
    mesh = _plate(160.0)
    part = part_from_mesh(mesh, "plate")
    traj = straight(np.arange(236.0, 404.0, 0.5))  # the whole plate under the line
    context = PlanContext(SPEC)
    surface = surface_samples(part, SENSOR, context, 0)
    tasks = defect_tasks(part, SPEC, traj, "dent", (0.02, 0.2), 8, 8, 0, context, None, surface)
    run = defect_run(tasks)
    assert run.fit.status == "fit"
    calls, detectability = survey(part, SENSOR, traj.poses, tasks[0].detector, surface)
    assert calls.count == 0
    assert calls.valid_points > 500_000
    predicted = detectability.predicted_a("dent", tasks[0].detector, 0.9)
    assert predicted is not None and run.fit.a90 is not None
    assert predicted == pytest.approx(run.fit.a90, rel=0.2)
    assert run.fit.a50 < run.fit.a90 < run.fit.a90_95


def test_pod_fit_recovers_a_known_curve():
    rng = np.random.default_rng(1)
    a = np.exp(rng.uniform(np.log(0.01), np.log(1.0), 2000))
    b0, b1 = 6.0, 3.0  # a50 = e^-2 = 0.135 mm
    hits = rng.uniform(size=len(a)) < 1 / (1 + np.exp(-(b0 + b1 * np.log(a))))
    fit = fit_pod(a, hits)
    assert fit.status == "fit"
    assert fit.a50 == pytest.approx(np.exp(-b0 / b1), rel=0.1)
    assert fit.a90 == pytest.approx(np.exp((np.log(9) - b0) / b1), rel=0.1)
    assert fit.a90 < fit.a90_95 < 1.3 * fit.a90


def test_pod_fit_degenerate_data_are_stated_not_nan():
    a = np.geomspace(0.1, 1.0, 10)
    every = fit_pod(a, np.ones(10, bool))
    assert every.status == "all_hit" and every.a90 is None and "below" in every.note
    none = fit_pod(a, np.zeros(10, bool))
    assert none.status == "all_miss" and none.a50 is None and "above" in none.note
    split = fit_pod(a, a > 0.4)
    assert split.status == "separated" and split.a90_95 is None
    assert split.a90 == pytest.approx(a[a > 0.4].min())
    for fit in (every, none, split):
        assert all(v is None or np.isfinite(v) for v in fit.to_json_dict().values()
                   if isinstance(v, float | type(None)))  # fmt: skip


@pytest.mark.skipif(
    importlib.util.find_spec("distributed") is None, reason="dask distributed not installed"
)
def test_trials_on_a_loopback_dask_cluster_repeat_the_serial_run():
    from scanplan.core.run import task_runner as trial_runner  # what defects --scheduler runs

    part = part_from_mesh(_plate(160.0), "plate")
    traj = straight(np.arange(300.0, 340.0, 0.5))
    context = PlanContext(SPEC)
    surface = surface_samples(part, SENSOR, context, 0)
    near = np.abs(surface.points[:, 0]) < 15  # under the short pass
    surface = VisibleSurface(surface.points[near], surface.area_mm2, surface.faces[near])
    tasks = defect_tasks(part, SPEC, traj, "pit", (0.05, 0.5), 2, 3, 1, context, None, surface)
    serial = defect_run(tasks)
    with (
        loopback_cluster() as cluster,
        trial_runner(cluster.scheduler_address, 2) as run,
    ):
        on_dask = defect_run(tasks, run)
    assert np.array_equal(on_dask.hits, serial.hits)
    assert np.array_equal(on_dask.flagged_points, serial.flagged_points)
    assert serial.landed_points.sum() > 0


def test_evaluate_predicts_the_full_fan_map_from_its_own_sub_sampled_scan():
    # The map evaluate draws from its 256-column scan (no second scan) against the survey of
    # the real 4096-column sensor: the real column pitch and the same predicted a90.
    part = part_from_mesh(_plate(160.0), "plate")
    traj = straight(np.arange(236.0, 404.0, 0.5))
    detector = detector_for(traj, SENSOR)
    surface = surface_samples(part, SENSOR, PlanContext(SPEC), 0)
    _, full = survey(part, SENSOR, traj.poses, detector, surface)
    acc = DetectabilitySurvey(SENSOR, detector, false_calls=False)
    evaluate(part, SPEC, traj, points_per_profile=256, observers=[acc])
    calls, fan = acc.finish()
    assert calls is None
    pitch = SENSOR.line_width_mm / (SENSOR.points_per_profile - 1)
    assert np.median(fan.column_mm[fan.seen]) == pytest.approx(pitch, rel=0.1)
    assert np.median(fan.spacing_mm[fan.seen]) == pytest.approx(0.5, rel=0.1)
    predicted = fan.predicted_a("dent", detector, 0.9)
    assert predicted == pytest.approx(full.predicted_a("dent", detector, 0.9), rel=0.1)


def test_the_map_is_the_depth_where_each_sample_reaches_its_share():
    # Per sample, the mapped depth is where its own POD crosses 90 %: found just above it,
    # not just below; and the sub-sampled scan's map agrees with its a90 in the median.
    part = part_from_mesh(_plate(160.0), "plate")
    traj = straight(np.arange(236.0, 404.0, 0.5))
    detector = detector_for(traj, SENSOR)
    acc = DetectabilitySurvey(SENSOR, detector, false_calls=False)
    evaluate(part, SPEC, traj, points_per_profile=256, observers=[acc])
    _, found = acc.finish()
    rows = found.sampled_rows(0)
    rows = np.arange(len(found.seen)) if rows is None else rows
    smallest = found.smallest_mm("dent", detector, 0.9, rows)
    mapped = np.isfinite(smallest)
    assert mapped.mean() > 0.9
    depth = np.where(mapped, smallest, 1.0)  # inf where none is found below 100 mm
    assert (found.pod_at("dent", depth * 1.001, detector, rows)[mapped] >= 0.9).all()
    assert (found.pod_at("dent", depth * 0.99, detector, rows)[mapped] < 0.9).mean() > 0.99
    a90 = found.predicted_a("dent", detector, 0.9)
    assert np.median(smallest[mapped]) == pytest.approx(a90, rel=0.15)


def test_a_defect_under_a_fixture_is_never_seen(tmp_path):
    """Defects placed on a plate 40 % of which a lid hides: no point lands on those under
    the lid, and those outside it are found, as many points on each as without it."""
    part = part_from_mesh(_plate(), "plate")
    lid, _ = fixture_files(tmp_path, part)  # over x < -40
    traj = straight(np.arange(120.0, 520.0, 0.5))  # the whole plate under the line
    lidded = PlanContext(SPEC, fixtures=(lid,))
    task = defect_tasks(part, SPEC, traj, "dent", (0.2, 0.3), 1, 8, 0, lidded)[0]
    assert len(task.occluders) == 1
    out = run_defect_trial(task)
    x = np.array([d.centre_mm[0] for d in task.defects])
    reach = np.array([d.radius_mm for d in task.defects])
    under, clear = x + reach < -40.0, x - reach > -40.0
    assert under.any() and clear.any()
    assert (out[under] == 0).all()
    # Found, and the points landed on each (its flagged points follow the noise drawn).
    bare = run_defect_trial(replace(task, occluders=()))
    assert out[clear, 0].all() and np.array_equal(out[clear][:, [0, 2]], bare[clear][:, [0, 2]])


def test_the_survey_asks_the_noise_and_pitch_of_the_points_a_sample_uses(plate):
    """Found at the asked points alone, the noise along the normal and the column pitch are
    those of the whole scan (`sigma_mm` · `cos_incidence`, the step to the next column)."""
    fan = ScanSpec().sensor.with_points(64)
    scan = LineProfilometer(plate, fan, seed=2).measure_many(
        straight(np.arange(300, 340, 4.0), 20.0, 0.1).poses
    )
    row, col = np.nonzero(scan.valid)
    assert len(row) > 200 and not scan.valid.all()  # some columns miss: NaN pitch there
    asked = np.arange(0, len(row), 3)
    pitch, noise = _pitch_and_noise(scan, fan, row, col, asked)
    want_noise = (sigma_mm(scan, fan) * cos_incidence(scan, fan))[row, col]
    step = np.full(scan.valid.shape, np.nan)
    step[:, :-1] = norm_rows(np.diff(scan.points_part, axis=1))
    step[:, :-1][~(scan.valid[:, 1:] & scan.valid[:, :-1])] = np.nan
    np.testing.assert_array_equal(noise[asked], want_noise[asked])  # one formula, the same bits
    np.testing.assert_array_equal(pitch[asked], step[row, col][asked])
    others = np.setdiff1d(np.arange(len(row)), asked)
    assert np.isnan(noise[others]).all() and np.isnan(pitch[others]).all()


def test_the_disc_crossing_and_found_share_are_numpys_own_to_the_bit():
    # Sorted lookups and counts by words: the same numbers as np.interp in the given order
    # and a row mean, ties and zeros included.
    from scanplan.judging import detectability as dt

    rng = np.random.default_rng(3)
    gap = rng.uniform(0.05, 3.0, 5000)
    col = np.r_[rng.uniform(0.05, 3.0, 4998), 0.0, 1.0]
    gap[-1] = gap[-2]  # a tie
    rho, sums = dt._profile_sums()
    need = 6 * col / (2.0 * gap)
    plain = np.empty((len(gap), dt.OFFSETS))
    for i in range(dt.OFFSETS):
        s = sums[:, i]
        first = int(np.searchsorted(s, 0.0, side="right")) - 1
        plain[:, i] = np.interp(need, s[first:], rho[first:], right=np.inf)
    plain = np.where(need[:, None] <= 0.0, 0.0, plain)
    crossing = dt._disc_crossing(gap, col, 6)
    assert np.array_equal(crossing, plain)
    ratio = rng.uniform(0.0, 5.0, len(gap))
    found = ratio[:, None] >= crossing
    assert np.array_equal(dt._share_of_offsets(found), found.mean(axis=1))
