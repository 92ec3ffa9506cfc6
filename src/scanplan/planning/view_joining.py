"""The views of a plan put in one order and joined into one trajectory: a short tour
between them (`order_views`), then clear moves around the part from each view to the next,
with the record of each view's swaths (`join_views`).
"""

from __future__ import annotations

from dataclasses import replace

import networkx as nx
import numpy as np

from scanplan.core.plan_records import region_record
from scanplan.core.quantities import ScanSpec
from scanplan.core.trajectory import Trajectory
from scanplan.planning.motion import view_transition
from scanplan.planning.swaths import swath_record
from scanplan.planning.views import ViewPlan
from scanplan.world.cell import Cell
from scanplan.world.collision import checker_for
from scanplan.world.part import Part


def order_views(plans: list[ViewPlan]) -> list[ViewPlan]:
    """The views in an order that keeps the moves between them short: the first (the top
    view) stays first, the rest follow a travelling-salesman tour (networkx's threshold
    accepting from a greedy tour, seeded) over the distance from one view's last pose to
    the next one's first (averaged both ways: the tour is symmetric)."""
    if len(plans) <= 2:
        return list(plans)
    first = np.stack([vp.traj.poses[0, :3, 3] for vp in plans])
    last = np.stack([vp.traj.poses[-1, :3, 3] for vp in plans])
    gap = np.linalg.norm(last[:, None] - first[None], axis=-1)
    graph = nx.Graph()
    for i in range(len(plans)):
        for j in range(i + 1, len(plans)):
            graph.add_edge(i, j, weight=0.5 * float(gap[i, j] + gap[j, i]))
    tour = nx.approximation.threshold_accepting_tsp(graph, "greedy", seed=0)[:-1]
    start = tour.index(0)
    order = tour[start:] + tour[:start]
    # Either direction around the tour: the one with the shorter directed moves.
    reverse = [0] + order[1:][::-1]
    cost = [sum(gap[a, b] for a, b in zip(o[:-1], o[1:], strict=True)) for o in (order, reverse)]
    return [plans[i] for i in (order if cost[0] <= cost[1] else reverse)]


def join_views(
    part: Part, plans: list[ViewPlan], spec: ScanSpec, cell: Cell | None = None
) -> tuple[list[ViewPlan], Trajectory]:
    """One trajectory: each view's swaths renumbered into a block of its own (view k's
    swaths follow view k−1's), joined by `view_transition`s clear of the part and its cell
    by `spec.clearance_mm`. `meta["views"]` records, per view, its axis and its swath block
    (first, last), which is how a CSV reader tells the views apart: a view is the block of
    consecutive swaths whose scanning poses look along its axis; and, where the view's plan
    carries them (`meta["swaths"]`), its pass lines (`swaths.swath_record`, view frame). A
    view no clear move reaches is left out and counted (`meta["views_unreachable"]`).
    Returns the views kept, renumbered, and the trajectory."""
    checker = checker_for(part, spec.sensor, cell)
    centre = 0.5 * (part.bounds[0] + part.bounds[1])
    # Clear of the part's bounding sphere, and no nearer than the farthest scanning pose.
    reach = max(float(np.linalg.norm(vp.traj.positions_mm - centre, axis=1).max()) for vp in plans)
    radius = max(0.5 * float(np.linalg.norm(part.extents)) + spec.clearance_mm, reach)
    pieces: list[Trajectory] = []
    views: list[dict] = []
    kept: list[ViewPlan] = []
    unreachable = 0
    first = 0
    prev_axis = plans[0].view.axis
    for vp in plans:
        traj = vp.traj
        swath = traj.swath - traj.swath.min() + first
        if pieces:
            try:
                moves = view_transition(
                    checker,
                    pieces[-1].poses[-1],
                    prev_axis,
                    traj.poses[0],
                    vp.view.axis,
                    centre,
                    radius,
                    spec.clearance_mm,
                )[:-1]  # without the next view's first pose, which its trajectory holds
            except ValueError:  # no clear way in: the scan goes on without this view
                unreachable += 1
                continue
            pieces.append(Trajectory(moves, np.full(len(moves), first), np.zeros(len(moves), bool)))
        pieces.append(replace(traj, swath=swath))
        kept.append(replace(vp, view=replace(vp.view, index=len(kept))))
        prev_axis = vp.view.axis
        record = {
            "index": len(views),
            "axis": [float(c) for c in vp.view.axis],
            "first_swath": int(swath.min()),
            "last_swath": int(swath.max()),
            "passes": vp.passes,
        }
        if vp.view.faces is not None:
            # The faces it looks at: a closed loop flies it on them, as it was planned.
            record["region"] = region_record(vp.view.faces, len(part.mesh.faces))
        if lines := traj.meta.get("swaths"):
            # The pass lines (in the view's frame) numbered as the trajectory's swaths: what
            # a controller steers along when the plan is run in closed loop (`trials`).
            offset = first - int(traj.swath.min())
            record["swaths"] = [swath_record(sw, sw.index + offset) for sw in lines]
        views.append(record)
        first = int(swath.max()) + 1
    out = Trajectory.concatenate(pieces)
    meta = dict(out.meta)
    meta["views"] = views
    if unreachable:
        meta["views_unreachable"] = unreachable
    return kept, replace(out, meta=meta)
