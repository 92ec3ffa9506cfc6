"""`scan`: the point cloud a plan's scan measures of its part, with each point's errors."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

from scanplan.core.plan import Plan
from scanplan.core.sensor_spec import SensorSpec
from scanplan.sensor.cloud import PointCloud, ply_size_bytes, simulate_cloud, write_ply
from scanplan.world.cell import part_in_cell
from scanplan.world.part import Part


def scan_size_line(plan: Plan, sensor: SensorSpec, max_points: int | None) -> str:
    """How large the cloud may be, said before scanning: a cloud of GB is better cut now than
    found on the disk."""
    profiles = int(plan.traj.scanning.sum())
    most = profiles * sensor.points_per_profile
    kept = most if max_points is None else min(most, max_points)
    return (
        f"scan: {profiles} profiles x {sensor.points_per_profile} columns: up to {most:,} points"
        f" (~{megabytes(ply_size_bytes(most))} as PLY)"
        + (f", at most {kept:,} kept (~{megabytes(ply_size_bytes(kept))})" if kept < most else "")
        + ("" if kept < most or most <= 1_000_000 else "; --max-points N writes fewer")
    )


def scan_plan(
    plan: Plan,
    part: Part,
    sensor: SensorSpec,
    output: Path,
    seed: int = 0,
    max_points: int | None = None,
    progress: Callable[[int, int], None] | None = None,
) -> PointCloud:
    """Simulate the plan's scan of `part` with `sensor` and write the cloud as PLY; the
    fixtures the plan records hide what they cover (no point of them or behind them)."""
    if not plan.traj.scanning.any():
        raise ValueError(f"{plan.where} has no scanning pose")
    part = part_in_cell(plan.context, part)
    cloud = simulate_cloud(
        part, sensor, plan.traj, seed=seed, progress=progress, max_points=max_points
    )
    if len(cloud.points_part) == 0:
        raise ValueError(
            f"no valid point: part {part.name} is outside the sensor's reach along {plan.where}"
        )
    write_ply(cloud, output)
    return cloud


def megabytes(size_bytes: int) -> str:
    return f"{size_bytes / 1e6:.1f} MB"
