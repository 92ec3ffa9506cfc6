"""Headroom: how much in-spec coverage under perturbation can small corrections to a plan
buy at all? An offline optimizer picks, per pass, a height offset and a pitch offset (about
the line's centre at the working distance, so the footprint stays) for the plan's poses,
scored on the mean in-spec coverage over `--train` seeded perturbed trials; the corrected
plan and the plan as it is are then judged side by side on `--test` other trials (another
seed) and unperturbed. If the corrected plan holds no more on the held-out trials, there is
nothing for a learned open-loop correction to find.

A pass's samples are in spec by its own points only (the in-spec test and the density rule
look at one pass), so each pass's candidates are scanned once per trial and the plan's in-spec
set is the union of its passes' sets: the search costs candidates x trials plan scans.

    python benchmarks/headroom.py door PLAN.json [--perturb 'place:5mm,2deg'] [--points 256]
"""

from __future__ import annotations

import argparse
import math
import time
from dataclasses import replace
from itertools import product

import numpy as np

from scanplan.core.context import recorded
from scanplan.core.plan_file import read_trajectory
from scanplan.core.quantities import UP, ScanSpec
from scanplan.core.trajectory import Trajectory
from scanplan.judging import evaluate, robustness, run_trial, trial_tasks
from scanplan.judging.evaluation import scanning_steps
from scanplan.sensor.perturb import Perturbation, rotation_matrix
from scanplan.world.part import load_part

HEIGHTS_MM = (-4.0, 0.0, 4.0)
PITCHES_DEG = (-1.0, 0.0, 1.0)


def corrected(poses: np.ndarray, dh_mm: float, dpitch_deg: float, wd_mm: float) -> np.ndarray:
    """(n, 4, 4) poses raised by dh along +Z and pitched by dpitch about their x_s through
    the point W_d along the beam."""
    out = poses.copy()
    if dpitch_deg:
        x_s = poses[:, :3, 0]
        R = rotation_matrix(x_s * math.radians(dpitch_deg))
        foot = poses[:, :3, 3] + wd_mm * poses[:, :3, 2]
        out[:, :3, :3] = R @ poses[:, :3, :3]
        out[:, :3, 3] = foot - np.einsum("nij,nj->ni", R, foot - poses[:, :3, 3])
    out[:, :3, 3] += dh_mm * UP
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("part")
    parser.add_argument("plan")
    parser.add_argument("--perturb", default="place:5mm,2deg")
    parser.add_argument("--points", type=int, default=256)
    parser.add_argument("--train", type=int, default=6)
    parser.add_argument("--test", type=int, default=16)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--rounds", type=int, default=2)
    args = parser.parse_args()
    start = time.perf_counter()
    part = load_part(args.part)
    traj = read_trajectory(args.plan)
    context = recorded(traj, ScanSpec())
    spec = context.spec
    wd = spec.working_distance_mm
    model = Perturbation.parse(args.perturb)
    idx, has_prev = scanning_steps(traj)
    poses, swath = traj.poses[idx], traj.swath[idx]
    passes = [np.flatnonzero(swath == k) for k in np.unique(swath)]
    candidates = list(product(HEIGHTS_MM, PITCHES_DEG))
    # Training trials: seed + 1000, never the held-out ones (seed).
    train = trial_tasks(
        part, spec, traj, model, args.train, args.seed + 1000, args.points, context=context
    )
    sets = np.zeros((len(passes), len(candidates), args.train, len(train[0].surface.points)), bool)
    for p, rows in enumerate(passes):
        for c, (dh, dth) in enumerate(candidates):
            moved = corrected(poses[rows], dh, dth, wd)
            for t, task in enumerate(train):
                sets[p, c, t] = run_trial(replace(task, poses=moved, has_prev=has_prev[rows]))
        print(f"pass {p}: {len(candidates)} candidates x {args.train} trials scanned", flush=True)
    zero = candidates.index((0.0, 0.0))
    # The union is the whole plan's set but for the sensor noise (each scan draws its own).
    whole, union = run_trial(train[0]), sets[:, zero, 0].any(axis=0)
    print(
        f"trial 0, plan as it is: whole scan {whole.mean():.4f}, union of its passes "
        f"{union.mean():.4f} ({(whole != union).mean():.2%} of the samples differ)"
    )

    def score(choice: list[int]) -> float:
        held = np.zeros_like(sets[0, 0])
        for p, c in enumerate(choice):
            held |= sets[p, c]
        return float(held.mean(axis=1).mean())

    choice = [zero] * len(passes)
    best = score(choice)
    print(f"training mean in-spec, plan as it is: {best:.4f}")
    for _ in range(args.rounds):
        for p in range(len(passes)):
            for c in range(len(candidates)):
                trial_choice = choice[:p] + [c] + choice[p + 1 :]
                if (s := score(trial_choice)) > best + 1e-9:
                    best, choice = s, trial_choice
    print(f"training mean in-spec, corrected: {best:.4f}")
    print("per pass (height mm, pitch deg):", [candidates[c] for c in choice])
    moved = poses.copy()
    for p, rows in enumerate(passes):
        moved[rows] = corrected(poses[rows], *candidates[choice[p]], wd)
    fixed_traj = traj.poses.copy()
    fixed_traj[idx] = moved
    plan_c = Trajectory(fixed_traj, traj.swath, traj.scanning, planner=traj.planner, meta=traj.meta)
    print(f"held-out: {args.test} trials, seed {args.seed} ({model.text()}), {args.points} points")
    print("| plan | nominal | mean | p5 | worst |")
    print("|---|---|---|---|---|")
    for name, plan in (("as planned", traj), ("corrected", plan_c)):
        nominal = evaluate(part, spec, plan, args.seed, args.points, context=context)
        r = robustness(
            trial_tasks(part, spec, plan, model, args.test, args.seed, args.points, context=context)
        )
        print(
            f"| {name} | {nominal.in_spec_coverage:.3f} | {r.mean:.3f} | {r.p5:.3f} | "
            f"{r.worst:.3f} |",
            flush=True,
        )
    print(f"({time.perf_counter() - start:.0f} s)")


if __name__ == "__main__":
    main()
