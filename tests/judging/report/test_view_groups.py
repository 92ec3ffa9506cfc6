"""Views named by the direction they look from, and grouped so a legend stays short."""

from __future__ import annotations

import math

import numpy as np

from scanplan.core.trajectory import Trajectory
from scanplan.judging.report import view_groups
from scanplan.judging.report.scene import passes_traces


def _axis(azimuth_deg: float, up_deg: float) -> list[float]:
    a, e = math.radians(azimuth_deg), math.radians(up_deg)
    return [math.cos(a) * math.cos(e), math.sin(a) * math.cos(e), math.sin(e)]


def test_a_view_is_named_by_the_side_and_height_it_looks_from():
    assert view_groups.view_name([0.0, 0.0, 1.0]) == "from above"
    assert view_groups.view_name(_axis(0, 10)) == "from +X, 10° up"
    assert view_groups.view_name(_axis(100, 35)) == "from +Y, 35° up"
    assert view_groups.view_name(_axis(-170, 20)) == "from -X, 20° up"
    assert view_groups.view_name(_axis(275, 59)) == "from -Y, 59° up"
    assert view_groups.view_name(_axis(275, 61)) == "from above"


def test_a_hundred_views_make_at_most_five_legend_entries():
    rng = np.random.default_rng(0)
    axes = [
        _axis(az, up)
        for az, up in zip(rng.uniform(0, 360, 116), rng.uniform(10, 90, 116), strict=True)
    ]
    n = 116 * 4
    poses = np.tile(np.eye(4), (n, 1, 1))
    poses[:, 0, 3] = np.arange(n)
    swath = np.repeat(np.arange(116), 4)
    views = [
        {"index": k, "axis": a, "first_swath": k, "last_swath": k, "passes": 1}
        for k, a in enumerate(axes)
    ]
    traj = Trajectory(poses, swath, np.ones(n, bool), meta={"views": views})
    traces = passes_traces(traj)
    in_legend = [t.name for t in traces if t.showlegend is not False]
    assert len(in_legend) <= 6, in_legend  # the moves and at most five sides
    assert len(traces) == 1 + 116  # every view drawn
    labels = [t.name for t in traces if t.showlegend is False]
    assert all(label.startswith("view ") and " from " in label for label in labels)
    groups = view_groups.groups(axes)
    assert sum(map(len, groups.values())) == 116 and set(groups) <= {"above", *view_groups.SIDES}
    assert any(f"({len(m)} views)" in name for m in groups.values() for name in in_legend)
