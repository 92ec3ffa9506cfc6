"""The rl planner: loads the shipped policy without unpickling code and plans sound passes;
the shipped v1 policy rolls a cross slope into spec."""

from __future__ import annotations

import json
import shutil
from dataclasses import replace

import numpy as np
import pytest
import torch
from safetensors.torch import load_file
from typer.testing import CliRunner

from helpers import plate_swath
from scanplan.cli import app
from scanplan.core.context import scan_spec_record
from scanplan.core.quantities import ScanSpec, advance, mean_distance, signed_alpha
from scanplan.core.sensor_spec import SensorSpec
from scanplan.judging import evaluate
from scanplan.planning.pass_path import plan_path
from scanplan.planning.planners.closed_loop import Guards
from scanplan.planning.swaths import plan_swaths
from scanplan.rl.planner import DEFAULT_POLICY, RLPlanner
from scanplan.rl.policy import load_policy
from scanplan.sensor.profilometer import LineProfilometer


def test_shipped_policy_files_are_weights_and_json():
    meta = json.loads((DEFAULT_POLICY / "policy.json").read_text())
    assert meta["format"] == "scanplan-policy/2" and meta["weights"] == "policy.safetensors"
    weights = DEFAULT_POLICY / meta["weights"]
    assert weights.stat().st_size < 100_000  # a [64, 64] MLP: a few tens of KB at most
    for key in ("command", "seed", "wall_time_s", "final_metrics_last5_updates"):
        assert key in meta["training"]
    assert meta["training"]["command"].startswith("scanplan train")
    assert "--seed 0" in meta["training"]["command"] and meta["training"]["seed"] == 0
    # Plain tensors in a safetensors file, no pickle anywhere in the directory.
    state = load_file(weights)
    assert all(isinstance(v, torch.Tensor) for v in state.values())
    assert not list(DEFAULT_POLICY.glob("*.pt")) and not list(DEFAULT_POLICY.glob("*.pkl"))
    policy = load_policy(DEFAULT_POLICY)
    for name, tensor in policy.actor.state_dict().items():
        assert torch.equal(tensor, state[name])


def test_default_policy_follows_a_flat_plate(plate):
    """No backward step, spacing near Δs_opt, D near W_d, aligned, over a whole pass."""
    sensor = SensorSpec().without_noise()
    swath = plate_swath()
    traj = RLPlanner.from_file(None).plan(plate, swath, ScanSpec(sensor))
    assert traj.scanning.all() and (traj.swath == swath.index).all()
    assert np.all(np.diff(traj.positions_mm[:, 0]) > 0)
    scan = LineProfilometer(plate, sensor.with_points(256)).measure_many(traj.poses)
    d = mean_distance(scan.z_sensor, scan.valid)
    a = signed_alpha(scan.normals_part, scan.valid, traj.poses)
    ds = advance(
        scan.points_part[:-1], scan.valid[:-1], scan.points_part[1:], scan.valid[1:], swath.u
    )
    assert np.isfinite(ds).mean() > 0.99  # the last station may look past the plate's end
    ds, d, a = ds[np.isfinite(ds)], d[np.isfinite(d)], a[np.isfinite(a)]
    assert np.all(ds > 0)
    assert abs(ds.mean() - 0.5) < 0.1 and ds.std() / ds.mean() < 0.25
    assert np.abs(d - 400.0).mean() < 2.0
    assert np.degrees(np.abs(a)).mean() < 2.0
    assert 500 < len(traj) < 2000  # the plate is ~600 mm long: ~1200 stations


def test_missing_or_unsafe_policy_is_a_value_error(tmp_path):
    with pytest.raises(ValueError, match="no policy.json"):
        RLPlanner.from_file(tmp_path / "nowhere")
    bad = tmp_path / "bad"
    shutil.copytree(DEFAULT_POLICY, bad)
    meta = json.loads((bad / "policy.json").read_text())
    # A pickled object (not plain tensors) must be refused, never executed.
    torch.save({"0.weight": np.dtype}, bad / meta["weights"])
    with pytest.raises(ValueError, match="not a safetensors file"):
        RLPlanner.from_file(bad)


class _PitchSwing(RLPlanner):
    """Scripted actions: pitch the beam forward for 10 steps, then back at full rate with no
    Δy — the back swing moves the footprint ~7 mm backwards per step."""

    def act(self, obs: np.ndarray) -> np.ndarray:
        self.calls = getattr(self, "calls", 0) + 1
        phase = (self.calls - 1) // 10 % 2
        return np.array([0.5, 0.0, -1.0 if phase == 0 else 1.0])


def _plate_advances(plate, swath, traj):
    scan = LineProfilometer(plate, SensorSpec().without_noise().with_points(256)).measure_many(
        traj.poses
    )
    ds = advance(
        scan.points_part[:-1], scan.valid[:-1], scan.points_part[1:], scan.valid[1:], swath.u
    )
    return ds[np.isfinite(ds)]


def test_forward_only_guard_removes_backward_steps(plate):
    sensor = SensorSpec().without_noise()
    swath = plate_swath()
    shipped = RLPlanner.from_file(None)
    off = Guards(stall_window=0, min_advance=None)
    unguarded = _PitchSwing(shipped.actor, shipped.config, guards=off)
    ds_free = _plate_advances(plate, swath, unguarded.plan(plate, swath, ScanSpec(sensor)))
    assert (ds_free < 0).sum() > 10  # the scripted swing does go backwards

    guarded = _PitchSwing(shipped.actor, shipped.config, guards=Guards(stall_window=0))
    traj = guarded.plan(plate, swath, ScanSpec(sensor))
    ds = _plate_advances(plate, swath, traj)
    assert np.all(ds > 0)
    assert traj.meta["backward_overrides"] > 10


def test_the_policy_normalizes_by_its_training_spec_and_refuses_a_sensor_it_never_saw(tmp_path):
    planner = RLPlanner.from_file(None)
    # The shipped policy records the ScanSpec it was trained under: the default one.
    assert scan_spec_record(planner.trained_spec) == scan_spec_record(ScanSpec())
    sensor = ScanSpec().sensor
    with pytest.raises(ValueError, match="Z range of 250 mm; sensor wide has 400 mm"):
        planner.check_sensor(ScanSpec(replace(sensor, name="wide", z_range_mm=400.0)))
    with pytest.raises(ValueError, match="working distance of 400 mm; sensor near works at 300"):
        planner.check_sensor(ScanSpec(replace(sensor, name="near", working_distance_mm=300.0)))
    planner.check_sensor(ScanSpec(replace(sensor, z_range_mm=200.0)))  # inside what it saw
    wide = tmp_path / "wide.toml"
    wide.write_text(
        'name = "wide"\nworking_distance_mm = 400\nz_range_mm = 400\nfov_deg = 63.5\n'
        "points_per_profile = 512\nz_resolution_um = 4\ntriangulation_angle_deg = 30\n"
    )
    out = tmp_path / "plan.csv"
    result = CliRunner().invoke(
        app, ["plan", "training-piece", "--planner", "rl", "--sensor", str(wide), "-o", str(out)]
    )
    assert result.exit_code == 2 and not out.exists()
    assert len(result.stderr.strip().splitlines()) == 1 and "Z range" in result.stderr


SPEC = ScanSpec()


def test_shipped_v1_policy_rolls_a_cross_slope_into_spec(cross_slope_plate):
    from scanplan.rl.planner import RLPlanner

    planner = RLPlanner.from_file("v1")
    assert planner.roll and planner.config["training"]["command"].startswith("scanplan train")
    part = cross_slope_plate
    swaths = plan_swaths(part, SPEC.sensor, "x")
    m = evaluate(part, SPEC, plan_path(part, SPEC, planner, swaths), points_per_profile=256)
    assert m.in_spec_coverage >= 0.9
