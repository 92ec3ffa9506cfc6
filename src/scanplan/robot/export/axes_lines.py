"""External axes in a program: the header line that records them (read back by every
parser), and the targets written in the part's frame placed where the axes' values put it.
"""

from __future__ import annotations

import json
import re

import numpy as np

from scanplan.robot.axes import ExternalAxes
from scanplan.robot.export.common import Motion

# The header line that records a program's external axes (`axes_note`), read back by
# `read_axes` so a parser can place the targets written in the part's frame.
AXES_NOTE = re.compile(r"scanplan external axes: (\{.*\})\s*$", re.MULTILINE)


def axes_note(motion: Motion) -> str:
    """'scanplan external axes: {...}' (the axes' record as JSON), '' without axes."""
    if motion.axes is None:
        return ""
    return "scanplan external axes: " + json.dumps(motion.axes.record(), separators=(",", ":"))


# An arm hung from an overhead track stands upside down: the upright frame a controller
# calls its world is the arm's base frame turned half a turn about X (a ceiling mount).
HUNG_WORLD_BASE = np.diag([1.0, -1.0, -1.0, 1.0])


def world_base(axes: ExternalAxes | None) -> np.ndarray:
    """(4, 4) T_world_base: the upright world from the arm's base, turned half a turn about
    X for an arm hung from an overhead track, else the base itself."""
    return HUNG_WORLD_BASE if axes is not None and axes.overhead else np.eye(4)


def mount_note(motion: Motion) -> str:
    """'The arm hangs upside down ...' for an arm on an overhead track, '' otherwise."""
    if motion.axes is None or not motion.axes.overhead:
        return ""
    return (
        "The arm hangs upside down from an overhead track (a gantry over the table): "
        "configure it as ceiling-mounted"
    )


def read_axes(text: str) -> ExternalAxes | None:
    """The external axes a program's header records (`axes_note`), None when none."""
    m = AXES_NOTE.search(text)
    if m is None:
        return None
    try:
        data = json.loads(m.group(1))
    except ValueError:
        raise ValueError("the program's external axes line is not valid JSON") from None
    return ExternalAxes.of_record(data, "the program's external axes")


def on_axes(
    base: np.ndarray, poses_part: np.ndarray, external: np.ndarray | None, axes: ExternalAxes | None
) -> np.ndarray:
    """(n, 4, 4) `T_base_x` of targets `poses_part` written in the part frame, the part at
    `base` with every axis at 0 and the axes at `external` (n, k)."""
    if axes is None or external is None:
        return base @ poses_part
    if external.shape[1] != len(axes.names):
        raise ValueError(
            f"the program's targets hold {external.shape[1]} external axis values, its axes "
            f"{len(axes.names)}"
        )
    return axes.base_part(base, external) @ poses_part
