"""How a fit enters a pass whose joint move in would sweep a link of the arm into the cell,
or flip it on the way down: at the top of the move leading into it (`lifted`), back beside
the surface for good if the move down from there flips (`lowered`), from its other end
(`flown_back`), or not at all (given up, with why).
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import replace

import numpy as np

from scanplan.core.trajectory import Trajectory, lead_tops, pass_bounds

# Why a pose is given up: out of the arm's reach, beyond its joint limits, an arm link
# within the clearance of the part, a fixture or the table (in `CellObstacles.NAMES`'
# order), on the joint move into its pass, or the sensor body in the cell on a joint move
# no lift clears (`joint_moves`).
CAUSES = (
    "reach",
    "joint limits",
    "link in the part",
    "link in a fixture",
    "link in the table",
    "joint move into a pass",
    "sensor on a joint move",
)


def lifted(
    current: Trajectory,
    index: np.ndarray,
    moves: dict[int, tuple[int, int]],
    raised: np.ndarray,
    low: np.ndarray,
) -> tuple[dict[int, tuple[int, int]], bool]:
    """The joint `moves` into passes of `current` (the kept poses of the fit's plan, at
    `index`) that sweep a link into the cell, less those of passes entered at their first
    pose with a move leading into them: those are entered at the top of it from now on
    (marked in `raised`, by their first pose), unless `low` marks them (that move down
    flips the arm). Returns the moves left, and whether any was lifted."""
    top = lead_tops(current)
    left = {}
    for i, hit in moves.items():
        if current.scanning[i] and top[i] != i and not (low | raised)[index[i]]:
            raised[index[i]] = True
        else:
            left[i] = hit
    return left, len(left) < len(moves)


def lowered(
    current: Trajectory, index: np.ndarray, flips: np.ndarray, raised: np.ndarray, low: np.ndarray
) -> tuple[np.ndarray, bool]:
    """Of the configuration `flips` (pose indices into `current`, the kept poses of the
    fit's plan at `index`), those on the move down into a pass entered at its top: no
    controller flips in a linear move, so that pass is entered at its first pose again
    and for good (`raised` cleared, `low` set, by its first pose). Returns the other
    flips (where the pass is cut) and whether any pass was lowered."""
    down = np.zeros(len(flips), bool)
    starts, _ = pass_bounds(current.scanning, current.swath)
    first = np.flatnonzero(starts)
    for k, f in enumerate(flips):
        if current.scanning[f]:
            continue
        after = first[first > f]
        if not len(after) or current.swath[after[0]] != current.swath[f]:
            continue
        s = index[after[0]]
        if raised[s]:
            raised[s], low[s], down[k] = False, True, True
    return flips[~down], bool(down.any())


def flown_back(
    traj: Trajectory,
    current: Trajectory,
    index: np.ndarray,
    moves: Iterable[int],
    why: np.ndarray,
    flipped: np.ndarray,
    reverse: bool = True,
) -> tuple[Trajectory, bool]:
    """Passes of `current` (the kept poses of `traj`, at `index`) whose joint move in
    (`moves`: their first poses) sweeps a link into the cell, flown the other way: entered
    from their other end, the moves that led to their first pose given up (the arm makes
    a joint move instead); a pass already flown so, or any with `reverse` off, is given up
    (in `why`). `flipped` marks the poses reversed. Returns `traj` with those passes
    reversed, and whether any was."""
    poses, external = traj.poses, traj.external
    reversed_any = False
    for i in moves:
        in_pass = current.swath == current.swath[i]
        piece = np.flatnonzero(in_pass & current.scanning)
        slots = index[piece]
        if not reverse or flipped[slots].any() or len(slots) < 2:
            why[in_pass] = CAUSES.index("joint move into a pass")
            continue
        if not reversed_any:
            poses = poses.copy()
            external = None if external is None else external.copy()
        poses[slots] = poses[slots[::-1]]
        if external is not None:  # the axes' values go with their poses
            external[slots] = external[slots[::-1]]
        flipped[slots] = True
        why[in_pass & ~current.scanning] = CAUSES.index("joint move into a pass")
        reversed_any = True
    if not reversed_any:
        return traj, False
    return replace(traj, poses=poses, external=external), True
