"""The records a plan file carries beside its poses (context, robot, views, cycle_time_s),
checked the same way whether they come from a CSV's comment lines or a JSON's keys: types,
required fields, counts and ranges (`core.limits`). The context's and the arm's fields are
checked where they are typed (`context`, `plan`); a view's pass lines here, before any work.
"""

from __future__ import annotations

import base64
import binascii
import math
import zlib
from typing import Annotated, Any

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, ValidationError, model_validator

from scanplan.core.limits import (
    DURATION_S,
    MAX_PASSES,
    MAX_TRIANGLES,
    MAX_VIEWS,
    PASS_LENGTH_MM,
    POSITION_MM,
    SIGNED_LENGTH_MM,
    check_count,
    in_range,
)
from scanplan.core.trajectory import INT32
from scanplan.core.validation import error_line, field_line

# The records of `Trajectory.meta` a plan file carries (JSON-able values).
FILE_RECORDS = ("context", "views", "robot", "cycle_time_s")

FiniteFloat = Annotated[float, Field(allow_inf_nan=False)]
Index = Annotated[int, Field(ge=0, le=int(INT32.max))]
Point = Annotated[list[Annotated[float, in_range(POSITION_MM)]], Field(min_length=3, max_length=3)]
Vector = Annotated[list[FiniteFloat], Field(min_length=3, max_length=3)]
# A pass line's directions are unit (and u horizontal, v = up x u) to this.
_UNIT_TOL = 1e-6


class _SwathJson(BaseModel):
    """One pass line of a view (`swaths.swath_record`, in the view's frame): from `start_mm`
    along the unit, horizontal `u` (as far as `end_mm` lies along it), with `v` = up x u;
    `band_mm` the lateral band (lo <= hi) an adaptive pass aligns to."""

    model_config = ConfigDict(extra="allow", strict=True)
    index: Index
    start_mm: Point
    end_mm: Point
    u: Vector
    v: Vector
    band_mm: (
        Annotated[
            list[Annotated[float, in_range(SIGNED_LENGTH_MM)]], Field(min_length=2, max_length=2)
        ]
        | None
    ) = None

    @model_validator(mode="after")
    def _a_line_of_plausible_length(self) -> _SwathJson:
        u, v = np.array(self.u), np.array(self.v)
        if abs(math.hypot(*u) - 1.0) > _UNIT_TOL or abs(u[2]) > _UNIT_TOL:  # hypot: no overflow
            raise ValueError(f"u {self.u} is not a unit horizontal vector")
        if np.abs(v - np.cross((0.0, 0.0, 1.0), u)).max() > _UNIT_TOL:
            raise ValueError(f"v {self.v} is not up x u")
        # The length a pass is flown over (`Swath.length_mm`): what a closed loop steps along.
        PASS_LENGTH_MM.check(float((np.array(self.end_mm) - self.start_mm) @ u), "its length")
        if self.band_mm is not None and self.band_mm[0] > self.band_mm[1]:
            raise ValueError(f"band_mm {self.band_mm} runs backwards")
        return self


def region_record(faces: np.ndarray, n_faces: int) -> dict[str, Any]:
    """A view's region as its record holds it: the part's face count and the mask of its
    faces, one bit a face, deflated and in base64 (a connected region deflates to little)."""
    mask = np.zeros(n_faces, bool)
    mask[np.asarray(faces, dtype=np.int64)] = True
    packed = zlib.compress(np.packbits(mask).tobytes(), 9)
    return {"faces": int(n_faces), "mask": base64.b64encode(packed).decode("ascii")}


def region_faces(record: dict[str, Any], n_faces: int, where: str) -> np.ndarray:
    """(k,) the faces of a view's region record (`region_record`) on a part of `n_faces`
    faces; ValueError (one line, naming `where`) for a mask that does not decode to one
    bit a face of that part, or selects none."""
    if int(record["faces"]) != n_faces:
        raise ValueError(
            f"{where}: the view's region is of a part of {record['faces']} faces; this part "
            f"has {n_faces}"
        )
    try:
        return _mask_faces(str(record["mask"]), n_faces)
    except ValueError as exc:
        raise ValueError(f"{where}: {exc}") from None


def _mask_faces(mask: str, n_faces: int) -> np.ndarray:
    """The faces a region's mask selects; ValueError unless it is `n_faces` bits, some set."""
    size = (n_faces + 7) // 8
    try:
        inflate = zlib.decompressobj()
        packed = inflate.decompress(base64.b64decode(mask, validate=True), size)
        whole = inflate.eof and not inflate.unconsumed_tail and len(packed) == size
    except (binascii.Error, zlib.error):
        whole = False
    if not whole:
        raise ValueError(f"the view's region mask is not {n_faces} faces' bits")
    faces = np.flatnonzero(np.unpackbits(np.frombuffer(packed, np.uint8), count=n_faces))
    if not len(faces):
        raise ValueError("the view's region holds no face")
    return faces


class _RegionJson(BaseModel):
    """A view's region (`region_record`): the part's face count and its faces' mask."""

    model_config = ConfigDict(extra="forbid", strict=True)
    faces: Annotated[int, Field(ge=1, le=MAX_TRIANGLES)]
    # Base64 of at most one bit a face, deflated (deflate grows incompressible data little).
    mask: Annotated[str, Field(min_length=1, max_length=MAX_TRIANGLES // 4)]

    @model_validator(mode="after")
    def _decodes(self) -> _RegionJson:
        # Read as every command reads the file: a broken mask is refused here, not later.
        _mask_faces(self.mask, self.faces)
        return self


class _ViewJson(BaseModel):
    """One view's record (`views.join_views`): its axis, its block of swath indices, the
    passes planned in it and (where recorded) its pass lines and its region."""

    model_config = ConfigDict(extra="allow", strict=True)
    index: Index
    axis: Vector
    first_swath: int
    last_swath: int
    passes: Index = 0
    swaths: Annotated[list[_SwathJson], Field(max_length=MAX_PASSES)] | None = None
    region: _RegionJson | None = None  # a view of part of the surface: which part

    @model_validator(mode="after")
    def _unit_axis_and_a_block(self) -> _ViewJson:
        if not abs(math.hypot(*self.axis) - 1.0) <= 1e-3:
            raise ValueError(f"axis {self.axis} is not a unit vector")
        if not 0 <= self.first_swath <= self.last_swath <= INT32.max:
            raise ValueError(
                f"swaths {self.first_swath}..{self.last_swath} are not a block of pass indices"
            )
        return self


class _RecordsJson(BaseModel):
    # Strict: a cycle time of "fast" is a broken file, not a value to coerce. What a record
    # holds inside is checked where it is typed (context: PlanContext; robot: ArmRecord).
    model_config = ConfigDict(strict=True)
    context: dict[str, Any] | None = None
    robot: dict[str, Any] | None = None
    views: Annotated[list[_ViewJson], Field(max_length=MAX_VIEWS)] | None = None
    cycle_time_s: Annotated[float, in_range(DURATION_S)] | None = None


def validated_records(records: dict[str, Any], where: str) -> dict[str, Any]:
    """The FILE_RECORDS of `records` (a null one left out), checked; ValueError naming
    `where` (the file) and the first bad field (`views[2].swaths[0].u: ...`)."""
    if isinstance(views := records.get("views"), list):  # counted before each is checked
        check_count(len(views), MAX_VIEWS, f"{where}: views")
    try:
        model = _RecordsJson.model_validate({k: records.get(k) for k in FILE_RECORDS})
    except ValidationError as exc:
        raise ValueError(f"{where}: {field_line(exc)}") from None
    # The views as the file holds them: their free fields ride along, and no null is added.
    views = None if model.views is None else [v.model_dump(exclude_unset=True) for v in model.views]
    out = {
        "context": model.context,
        "views": views,
        "robot": model.robot,
        "cycle_time_s": model.cycle_time_s,
    }
    return {k: v for k, v in out.items() if v is not None}


def checked_swath_record(record: object, where: str) -> dict[str, Any]:
    """A pass line's record (`swaths.swath_record`) checked, as the file reader checks the
    views' lines; ValueError naming `where` and the field."""
    try:
        return _SwathJson.model_validate(record).model_dump(exclude_unset=True)
    except ValidationError as exc:
        raise ValueError(error_line(where, exc)) from None
