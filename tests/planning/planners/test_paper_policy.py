"""The shipped from-scratch policy (`--policy paper`, issue 22): made by `scanplan train`
without behaviour cloning, it loads by name and plans a procedural part it never saw within the
in-spec distance tolerance."""

from __future__ import annotations

import json

import numpy as np
from typer.testing import CliRunner

from scanplan.cli import app
from scanplan.core.plan_file import read_trajectory
from scanplan.core.quantities import ScanSpec
from scanplan.judging import evaluate
from scanplan.rl.env import random_part
from scanplan.rl.planner import SHIPPED_POLICIES

SPEC = ScanSpec()


def test_paper_policy_is_pure_ppo_made_by_scanplan_train():
    meta = json.loads((SHIPPED_POLICIES["paper"] / "policy.json").read_text())
    training = meta["training"]
    assert training["command"].startswith("scanplan train")
    assert "--bc-samples" not in training["command"]
    assert training["config"]["bc_samples"] == 0 and training["behaviour_cloning_mse"] is None
    assert f"--seed {training['seed']}" in training["command"]
    assert meta["env"]["reward_distance_scale_mm"] == 12.5  # its deviation, recorded
    # Its pitch pivot, recorded (and read by the planner, which steps the policy so).
    assert meta["env"]["pitch_pivot"] == "footprint"
    assert "--pitch-pivot footprint" in training["command"]


def test_policy_paper_plans_a_procedural_part_within_the_distance_tolerance(tmp_path):
    part = random_part(np.random.default_rng(25))  # 596 x 100 mm, 70 mm of relief: one pass
    stl = tmp_path / "strip.stl"
    part.mesh.export(stl)
    out = tmp_path / "paper.csv"
    args = ["plan", str(stl), "--planner", "rl", "--policy", "paper", "-o", str(out), "-q"]
    result = CliRunner().invoke(app, args)
    assert result.exit_code == 0, result.output
    traj = read_trajectory(out)
    assert traj.scanning.sum() > 1000  # the whole ~600 mm pass at ~0.5 mm a profile
    m = evaluate(part, SPEC, traj, points_per_profile=64)
    # It follows the relief in depth (3.8 mm here; the fixed line 3.6 mm on this strip),
    # well inside the in-spec tolerance.
    assert m.distance_error_mean_abs_mm < SPEC.tolerance_mm / 2
    assert m.in_spec_coverage > 0.5
