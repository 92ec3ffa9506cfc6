"""Views named by the direction the sensor looks from ("from +X, 10° up"), and grouped by it
so that a legend of a plan with a hundred views stays short: one entry for the views from
above, one for each side (±X, ±Y).
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

# A view within this many degrees of vertical is "from above".
ABOVE_DEG = 60.0
SIDES = ("+X", "+Y", "-X", "-Y")


def elevation_deg(axis: Sequence[float]) -> float:
    """Degrees above the horizontal of a view's axis (the part towards the sensor)."""
    a = np.asarray(axis, dtype=float)
    return math.degrees(math.asin(float(np.clip(a[2] / np.linalg.norm(a), -1.0, 1.0))))


def side(axis: Sequence[float]) -> str:
    """The side (+X, +Y, -X, -Y) a view looks from, or "above"."""
    if elevation_deg(axis) >= ABOVE_DEG:
        return "above"
    azimuth = math.degrees(math.atan2(axis[1], axis[0])) % 360.0
    return SIDES[int(((azimuth + 45.0) % 360.0) // 90.0)]


def view_name(axis: Sequence[float]) -> str:
    """E.g. 'from +X, 10° up' or 'from above'."""
    where = side(axis)
    if where == "above":
        return "from above"
    return f"from {where}, {elevation_deg(axis):.0f}° up"


def groups(axes: Sequence[Sequence[float]]) -> dict[str, list[int]]:
    """View indices by side, in the order of SIDES after "above"."""
    by_side: dict[str, list[int]] = {}
    for k, axis in enumerate(axes):
        by_side.setdefault(side(axis), []).append(k)
    order = ("above", *SIDES)
    return {s: by_side[s] for s in order if s in by_side}


def group_label(where: str, axes: Sequence[Sequence[float]], members: Sequence[int]) -> str:
    """The legend entry of one side's views: 'from +X, 12-35° up (7 views)'."""
    n = len(members)
    count = f" ({n} views)" if n > 1 else ""
    if where == "above":
        return f"from above{count}"
    ups = [elevation_deg(axes[k]) for k in members]
    lo, hi = round(min(ups)), round(max(ups))
    span = f"{lo}°" if lo == hi else f"{lo}-{hi}°"
    return f"from {where}, {span} up{count}"
