"""Collision-check throughput on the door's trajectory vs bare FCL calls, in one run.

Trajectory: the fixed planner's plan of the built-in door (scanning and transition poses),
plus the same poses lowered 400 mm so the body meets the skin (every pose goes to FCL).
Prints poses/s of `CollisionChecker.check` (prefiltered, and exact=True) and of the yes/no
`CollisionChecker.colliding` (checked to agree with `check`) next to a bare `fcl.collide`
and `fcl.distance` per pose of the same body and BVH; the ratios are what travels between
machines.
Run: .venv/bin/python benchmarks/bench_collision.py
"""

from __future__ import annotations

import time

import fcl

from scanplan.core.quantities import ScanSpec
from scanplan.planning.pass_path import plan_path
from scanplan.planning.swaths import plan_swaths
from scanplan.rl.planners import make_planner
from scanplan.world.collision import CollisionChecker
from scanplan.world.part import load_part


def rate(fn, n: int) -> float:
    start = time.perf_counter()
    fn()
    return n / (time.perf_counter() - start)


def main() -> None:
    spec = ScanSpec()
    part = load_part("door")
    traj = plan_path(part, spec, make_planner("fixed"), plan_swaths(part, spec.sensor))
    start = time.perf_counter()
    checker = CollisionChecker(part, spec.sensor)
    print(f"door: {len(part.mesh.faces)} faces, BVH built in {time.perf_counter() - start:.2f} s")
    low = traj.poses.copy()
    low[:, 2, 3] -= 400.0  # the emitter on the skin: the body near or in the part
    lo, hi = spec.sensor.body_bounds_mm
    box = fcl.CollisionObject(fcl.Box(*(hi - lo)), fcl.Transform())
    centre = 0.5 * (lo + hi)
    part_obj = checker._part_obj  # the same BVH, for the bare reference

    def bare(poses, call):
        def run():
            for pose in poses:
                box.setTransform(fcl.Transform(pose[:3, :3], pose[:3, :3] @ centre + pose[:3, 3]))
                if call == "collide":
                    fcl.collide(box, part_obj, fcl.CollisionRequest(), fcl.CollisionResult())
                else:
                    fcl.distance(box, part_obj, fcl.DistanceRequest(), fcl.DistanceResult())

        return run

    # fcl.distance on a 350k-face BVH is slow: the exact rows use every 20th pose.
    for label, poses in (("as planned", traj.poses), ("lowered 400 mm", low)):
        n = len(poses)
        report = checker.check(poses, spec.clearance_mm)
        ours = rate(lambda p=poses: checker.check(p, spec.clearance_mm), n)
        few = poses[::20]
        exact = rate(lambda p=few: checker.check(p, spec.clearance_mm, exact=True), len(few))
        yes_no = rate(lambda p=poses: checker.colliding(p, spec.clearance_mm), n)
        agree = (checker.colliding(poses, spec.clearance_mm) == report.colliding).mean()
        collide = rate(bare(poses, "collide"), n)
        distance = rate(bare(few, "distance"), len(few))
        print(
            f"{label}: {n} poses, {int(report.exact.sum())} measured by FCL, "
            f"{int(report.colliding.sum())} colliding\n"
            f"  check            {ours:12.0f} poses/s  ({ours / collide:.2f} x bare collide)\n"
            f"  colliding        {yes_no:12.0f} poses/s  ({yes_no / collide:.2f} x bare collide;"
            f" agrees with check on {agree:.1%} of poses)\n"
            f"  check exact=True {exact:12.0f} poses/s  ({exact / distance:.2f} x bare distance)\n"
            f"  bare fcl.collide {collide:12.0f} poses/s\n"
            f"  bare fcl.distance{distance:12.0f} poses/s"
        )


if __name__ == "__main__":
    main()
