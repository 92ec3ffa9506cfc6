"""Training for the perturbed world (`scanplan train --perturb`, beyond the paper): each
episode measures the part as built and where its draw puts it, on the CAD's pass; sensors
placed apart on one part are measured together as they would be one by one."""

from __future__ import annotations

import math

import numpy as np
import pytest

from helpers import plate_swath
from scanplan.core.quantities import ScanSpec
from scanplan.rl.env import SwathScanEnv
from scanplan.rl.learn.config import recipe_config
from scanplan.rl.policy import EnvOptions
from scanplan.sensor.placed import PlacedProfilometer, measure_together
from scanplan.sensor.profilometer import LineProfilometer
from scanplan.world.part import Part

WD = 400.0


def placed(tz: float = 0.0, tilt_deg: float = 0.0) -> np.ndarray:
    """A placement: lifted by tz and turned by tilt_deg about x."""
    c, s = math.cos(math.radians(tilt_deg)), math.sin(math.radians(tilt_deg))
    T = np.eye(4)
    T[1:3, 1:3] = [[c, -s], [s, c]]
    T[2, 3] = tz
    return T


def test_sensors_placed_apart_on_one_part_measure_together_as_one_by_one(plate):
    sensor = ScanSpec().sensor.with_points(32).without_noise()
    sims = [
        LineProfilometer(plate, sensor),
        PlacedProfilometer(plate, sensor, placed(5.0)),
        PlacedProfilometer(plate, sensor, placed(-3.0, 2.0)),
    ]
    poses = plate_swath().poses(np.array([100.0, 300.0, 500.0]), np.zeros(3), np.zeros(3))
    together = measure_together(sims, poses)
    for i, sim in enumerate(sims):
        alone = sim.measure_many(poses[i : i + 1])
        for field in ("z_sensor", "points_part", "normals_part"):
            assert np.array_equal(
                getattr(together, field)[i], getattr(alone, field)[0], equal_nan=True
            ), field
    # What each sees: the plate's top (z = 0) lifted 5 mm reads 5 mm nearer; turned 2° about
    # x, its normals turn with it, in the CAD's frame.
    hit = together.valid[1]
    assert together.true_z_sensor[1][hit] == pytest.approx(WD - 5.0, abs=1e-4)  # float32 rays
    # The measured points, quantized in depth as the sensor's are: within a few µm.
    assert together.points_part[1][hit, 2] == pytest.approx(5.0, abs=0.01)
    normal = together.normals_part[2][together.valid[2]].mean(axis=0)
    assert math.degrees(math.atan2(-normal[1], normal[2])) == pytest.approx(2.0, abs=1e-4)
    other = LineProfilometer(Part(plate.mesh.copy()), sensor)
    with pytest.raises(ValueError, match="different parts"):
        measure_together([sims[0], other], poses[:2])


def plate_env(plate: Part, perturb: str | None) -> SwathScanEnv:
    return SwathScanEnv(
        parts=[plate], swaths=[plate_swath()], noise=False, segment_mm=None, perturb=perturb
    )


def test_each_episode_measures_the_part_where_its_own_draw_puts_it(plate):
    env = plate_env(plate, "place:±5mm,0deg")
    lifts = []
    for seed in range(8):
        env.reset(seed=seed)
        sim = env.dynamics.sim
        assert isinstance(sim, PlacedProfilometer) and sim.part is plate  # the pool's engine
        T = sim.T_part_placed
        assert np.array_equal(T[:3, :3], np.eye(3)) and np.abs(T[:3, 3]).max() <= 5.0
        # The start is aligned on the part as it lies (as a closed loop starts on the cell);
        # its points are where the plate really is, in the CAD's frame.
        assert env.dynamics.d_mm == pytest.approx(WD, abs=1e-3)
        points = env.dynamics.profile.points_part[env.dynamics.profile.valid]
        assert points[:, 2] == pytest.approx(T[2, 3], abs=0.01)
        lifts.append(T[2, 3])
    assert np.ptp(lifts) > 3.0  # drawn afresh each episode
    again = plate_env(plate, "place:±5mm,0deg")
    again.reset(seed=7)
    assert again.dynamics.sim.T_part_placed[2, 3] == lifts[-1]  # seeded


def test_a_warped_episode_measures_its_own_mesh_and_leaves_the_cad_alone(plate):
    before = np.asarray(plate.mesh.vertices).copy()
    env = plate_env(plate, "warp:1mm@200mm")
    env.reset(seed=1)
    built = env.dynamics.sim.part
    assert built is not plate and env.dynamics.part is plate  # the pass stays the CAD's
    moved = np.linalg.norm(np.asarray(built.mesh.vertices) - before, axis=1)
    assert moved.max() > 0.1 and np.array_equal(plate.mesh.vertices, before)


def test_unperturbed_episodes_draw_what_they_always_drew(plate):
    plain, zero = plate_env(plate, None), plate_env(plate, "place:0mm,0deg")
    plain.reset(seed=4)
    zero.reset(seed=4)
    # A perturbation of zero is none: the pool's own sensor, and no draw for it.
    assert zero.perturbation is None and zero.dynamics.sim is zero._pool[0][2]
    assert type(zero.dynamics.sim) is LineProfilometer
    assert plain.np_random.random() == zero.np_random.random()


def test_the_trainer_records_the_perturbation_and_refuses_a_path_error():
    config = recipe_config("/tmp/x", perturb="place:5mm,2deg", noise=True)
    assert config.env["perturb"] == "place:5mm,2deg;warp:0mm@200mm;scale:0%;path:0mm,0deg"
    assert config.env["noise"] is True
    assert EnvOptions.model_validate(config.env).perturb == config.env["perturb"]
    assert "perturb" not in recipe_config("/tmp/x").env
    with pytest.raises(ValueError, match="path error"):
        recipe_config("/tmp/x", perturb="place:5mm,2deg;path:0.1mm,0deg")
    with pytest.raises(ValueError, match="perturb"):
        EnvOptions.model_validate({**config.env, "perturb": "place:5 parsecs"})


def test_train_refuses_a_bad_perturbation_before_training(tmp_path):
    from typer.testing import CliRunner

    from scanplan.cli import app

    out = tmp_path / "pol"
    for value in ("path:0.1mm,0deg", "wobble:3mm"):
        result = CliRunner().invoke(app, ["train", "-o", str(out), "--perturb", value, "-q"])
        assert result.exit_code != 0
        assert "--perturb" in result.stderr and "Traceback" not in result.output
        assert not out.exists()
