"""The cell around the part: the table it rests on and the fixtures that hold it, in part
coordinates. Nothing of the sensor may come within the clearance of them, scanning or moving.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from scanplan.core.context import LOWEST, PlanContext
from scanplan.core.limits import MAX_FIXTURES, check_count
from scanplan.core.quantities import UP
from scanplan.world.part import Part, load_part

TABLE_HELP = (
    "the table the part rests on: its height Z in part coordinates (mm), or none for a part "
    "held in the air; default: the part's lowest point"
)
# `--table` when none is given: the part rests on a table at its lowest point.
# The table an arm must keep clear of: a block under the part's footprint grown by this
# margin on every side (where the table surely is), this deep (its top and what holds it).
# The sensor keeps above the whole plane; the arm stands beside the block.
TABLE_MARGIN_MM = 150.0
TABLE_DEPTH_MM = 1000.0
# A table further than this from the part is a typo (metres for millimetres), not a cell.
MAX_TABLE_GAP_MM = 10_000.0


@dataclass(frozen=True)
class Table:
    """The plane {x : normal·x = offset_mm}; the free side is normal·x > offset_mm."""

    normal: np.ndarray
    offset_mm: float

    def height_mm(self, points: np.ndarray) -> np.ndarray:
        """(...,) signed height of points (..., 3) above the plane, mm."""
        return np.asarray(points) @ self.normal - self.offset_mm

    def rotated(self, R: np.ndarray) -> Table:
        """The same plane in a frame rotated by R (4, 4) about the origin."""
        return Table(R[:3, :3] @ self.normal, self.offset_mm)


@dataclass(frozen=True)
class Disk:
    """A turntable the part lies on, in part coordinates (it turns with the part): the
    centre of its top, its radius, and how far its body reaches down from the top (mm)."""

    top_mm: tuple[float, float, float]
    radius_mm: float
    height_mm: float


@dataclass(frozen=True)
class Cell:
    """The table (None: the part is held in the air) at the height `table_z_mm` of the part
    frame, the fixtures (each a Part, in part coordinates), and the turntable's disk the
    part lies on, if any (an obstacle the arm keeps clear of, as of the table block)."""

    table: Table | None = None
    fixtures: tuple[Part, ...] = ()
    table_z_mm: float | None = None
    disk: Disk | None = None

    @classmethod
    def around(
        cls,
        part: Part,
        table: str | float | None = None,
        fixtures: Sequence[str] = (),
        units: str = "mm",
        where: str = "--fixture",
    ) -> Cell:
        """The cell of `part`: `table` a height in part coordinates, 'none' (held in the air)
        or 'lowest'/None (resting on a table at its lowest point); `fixtures` mesh files in
        part coordinates and `units`, counted before any is read. Raises ValueError naming
        the option (`where`: the fixtures' own, --fixture or a plan file's field)."""
        check_count(len(fixtures), MAX_FIXTURES, where, "a cell holds a few clamps")
        z = _table_height(part, table)
        loaded = tuple(load_part(f, units, "fixture file") for f in fixtures)
        return cls(None if z is None else Table(np.array(UP), z), loaded, z)

    def table_block(self, part: Part) -> tuple[np.ndarray, np.ndarray] | None:
        """(lo, hi) corners in part coordinates of the table block an arm must keep clear of,
        under the part and its fixtures (None: no table); the table is level in the part
        frame."""
        if self.table_z_mm is None:
            return None
        bounds = np.array([part.bounds, *(f.bounds for f in self.fixtures)], dtype=np.float64)
        lo, hi = bounds[:, 0].min(axis=0), bounds[:, 1].max(axis=0)
        lo[:2] -= TABLE_MARGIN_MM
        hi[:2] += TABLE_MARGIN_MM
        lo[2], hi[2] = self.table_z_mm - TABLE_DEPTH_MM, self.table_z_mm
        return lo, hi

    def rotated(self, R: np.ndarray) -> Cell:
        """The cell in a view's frame (rotated by R, as `views.View.part` turns the part)."""
        fixtures = []
        for fixture in self.fixtures:
            mesh = fixture.mesh.copy()
            mesh.apply_transform(R)
            fixtures.append(Part(mesh, name=fixture.name, source=fixture.source))
        table = None if self.table is None else self.table.rotated(R)
        # The disk is what the arm's links keep clear of, in the part frame only (a view's
        # frame may tilt; the sensor keeps clear of the table plane, over the disk too).
        return Cell(table, tuple(fixtures), self.table_z_mm)

    def occluding(self, part: Part) -> Part:
        """`part` as rays meet it in this cell: its fixtures hide it from the laser and the
        camera (`Part.among`); the table does not (the part rests on it). A part already
        among occluders was put in its cell by the caller and is returned as it is."""
        if part.occluders:
            return part
        return part.among([f.mesh for f in self.fixtures])


def _table_height(part: Part, table: str | float | None) -> float | None:
    lowest = float(part.bounds[0, 2])
    if table is None or (isinstance(table, str) and table.strip() in ("", LOWEST)):
        return lowest
    if isinstance(table, str) and table.strip().lower() == "none":
        return None
    try:
        z = float(table)
    except ValueError:
        raise ValueError(f"--table {table!r}: expected a height in mm or none") from None
    if not math.isfinite(z):
        raise ValueError(f"--table {table!r}: expected a finite height in mm or none")
    if z > lowest + 1e-6:
        raise ValueError(
            f"--table {z:g} mm is above the part's lowest point ({lowest:g} mm): the table "
            "would cut through the part"
        )
    if lowest - z > MAX_TABLE_GAP_MM:
        raise ValueError(
            f"--table {z:g} mm is {lowest - z:g} mm below the part: more than "
            f"{MAX_TABLE_GAP_MM:g} mm (a height in metres?)"
        )
    return z


def planned_cell(context: PlanContext, part: Part, where: str = "the plan's fixtures") -> Cell:
    """The cell a plan was made in, around `part` (its fixtures read from their files);
    `where` its fixtures come from, for messages."""
    return Cell.around(part, context.table, context.fixtures, context.fixture_units, where)


def part_in_cell(context: PlanContext, part: Part) -> Part:
    """`part` as the rays of a plan made under `context` meet it: among the fixtures of its
    cell (`Cell.occluding`). Their files are read only if there are some and `part` is not
    among occluders already (the planner's part, judged while planning)."""
    if not context.fixtures or part.occluders:
        return part
    return planned_cell(context, part).occluding(part)
