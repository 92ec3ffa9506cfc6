"""External axes in the cell: a turntable the part sits on, and a linear track the arm rides.

Frames (mm). The plan stays in the part frame; an external axis changes where the part is
in the arm's base frame, pose by pose. With the turntable at θ (degrees) about its axis
through `axis_point_mm` along `axis_direction` (both in the part frame, the part as it lies
at θ = 0):

    T_base_part(θ) = T_base_axis · R(axis, θ) · T_axis_part,

T_base_axis = T_base_part0 · Translate(p), T_axis_part = Translate(-p): the turntable turns
the part (and its fixtures, and the disk it lies on) about the axis. With the arm at s (mm)
along a track of unit direction d (base frame at s = 0), the base moves by d·s, so the
part moves by -d·s in the base frame:

    T_base_part(θ, s) = Translate(-d·s) · T_base_part(θ).

`T_base_part0` is the placement the plan records (`--part-pose`), the part at θ = 0, s = 0.
A plan's external axis values are one column each (`Trajectory.external`), in the order
`ExternalAxes.names`: the turntable's first, then the track's.
"""

from __future__ import annotations

import tomllib
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Annotated, Any, Literal

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, ValidationError, model_validator

from scanplan.core.cycle import trapezoid_time_s
from scanplan.core.paths import read_regular
from scanplan.core.validation import error_line
from scanplan.world.cell import Cell, Disk

Finite = Annotated[float, Field(allow_inf_nan=False)]
Positive = Annotated[float, Field(gt=0, allow_inf_nan=False)]
Vector = Annotated[list[Finite], Field(min_length=3, max_length=3)]

MAX_POSITIONER_FILE_BYTES = 64 * 1024
# A track or turntable beyond these is a typo (metres for millimetres, a unit slip).
MAX_TRACK_MM = 20_000.0
MAX_TURN_DEG = 720.0


class Turntable(BaseModel):
    """A 1-axis turntable the part lies on: its axis (part frame; the point None: through
    the centre of the part's footprint, placed by the tool), the angles it may take, its
    speed and acceleration, and its disk (the radius, and how far the top stands above the
    floor's pedestal: drawn, and kept clear of by the arm)."""

    model_config = ConfigDict(extra="forbid", strict=True)
    axis_point_mm: Vector | None = None
    axis_direction: Vector = [0.0, 0.0, 1.0]
    limits_deg: Annotated[list[Finite], Field(min_length=2, max_length=2)] = [-180.0, 180.0]
    speed_deg_s: Positive = 60.0
    accel_deg_s2: Positive = 120.0
    radius_mm: Positive = 500.0
    height_mm: Positive = 300.0

    @model_validator(mode="after")
    def _sane(self) -> Turntable:
        lo, hi = self.limits_deg
        if not -MAX_TURN_DEG <= lo < hi <= MAX_TURN_DEG:
            raise ValueError(f"limits_deg {self.limits_deg}: expected LO < HI within ±720")
        if not 0.5 < float(np.linalg.norm(self.axis_direction)) < 2.0:
            raise ValueError(f"axis_direction {self.axis_direction} is not a unit vector")
        return self


class Track(BaseModel):
    """A linear track the arm's base rides: its unit direction in the base frame (None:
    chosen by the tool), its travel `length_mm` (the arm from -length/2 to +length/2 about
    the placement), its speed and acceleration, and how it is mounted (None: chosen by the
    tool): on the floor beside the table, the arm standing on its carriage, or overhead
    (a gantry over the table), the arm hanging from its carriage upside down."""

    model_config = ConfigDict(extra="forbid", strict=True)
    direction: Vector | None = None
    mount: Literal["floor", "overhead"] | None = None
    length_mm: Annotated[float, Field(gt=0, le=MAX_TRACK_MM, allow_inf_nan=False)]
    speed_mm_s: Positive = 500.0
    accel_mm_s2: Positive = 1000.0

    @model_validator(mode="after")
    def _unit(self) -> Track:
        if self.direction is not None and not 0.5 < float(np.linalg.norm(self.direction)) < 2.0:
            raise ValueError(f"direction {self.direction} is not a unit vector")
        return self


class _AxesFile(BaseModel):
    model_config = ConfigDict(extra="forbid", strict=True)
    turntable: Turntable | None = None
    track: Track | None = None


def _unit(v: list[float] | np.ndarray) -> np.ndarray:
    u = np.asarray(v, dtype=np.float64)
    return u / np.linalg.norm(u)


def rotation_about(axis: np.ndarray, angle_rad: np.ndarray) -> np.ndarray:
    """(n, 3, 3) rotations by `angle_rad` (n,) about the unit `axis` (Rodrigues)."""
    a = np.asarray(angle_rad, dtype=np.float64).reshape(-1)
    x, y, z = axis
    K = np.array([[0.0, -z, y], [z, 0.0, -x], [-y, x, 0.0]])
    s, c = np.sin(a)[:, None, None], np.cos(a)[:, None, None]
    return np.eye(3) + s * K + (1.0 - c) * (K @ K)


@dataclass(frozen=True)
class ExternalAxes:
    """The external axes of a cell: a turntable, a track, or both (not neither)."""

    turntable: Turntable | None = None
    track: Track | None = None

    def __post_init__(self) -> None:
        if self.turntable is None and self.track is None:
            raise ValueError("external axes: give a turntable, a track or both")

    @property
    def names(self) -> tuple[str, ...]:
        """The axes' names, in the order of their values: turntable_deg, track_mm."""
        return (("turntable_deg",) if self.turntable else ()) + (
            ("track_mm",) if self.track else ()
        )

    @property
    def labels(self) -> tuple[str, ...]:
        """The axes' names with their units, for a program's header: 'turntable (deg)'."""
        return tuple(f"{n.rsplit('_', 1)[0]} ({n.rsplit('_', 1)[1]})" for n in self.names)

    @property
    def rotary(self) -> np.ndarray:
        """(k,) bool: which axes turn (degrees) rather than slide (mm)."""
        return np.array([n.endswith("_deg") for n in self.names])

    @property
    def limits(self) -> np.ndarray:
        """(k, 2) each axis's range (degrees or mm)."""
        out = []
        if self.turntable is not None:
            out.append(self.turntable.limits_deg)
        if self.track is not None:
            out.append([-self.track.length_mm / 2, self.track.length_mm / 2])
        return np.array(out, dtype=np.float64)

    @property
    def speeds(self) -> np.ndarray:
        """(k,) deg/s or mm/s."""
        out = [self.turntable.speed_deg_s] if self.turntable else []
        return np.array(out + ([self.track.speed_mm_s] if self.track else []))

    @property
    def accels(self) -> np.ndarray:
        """(k,) deg/s² or mm/s²."""
        out = [self.turntable.accel_deg_s2] if self.turntable else []
        return np.array(out + ([self.track.accel_mm_s2] if self.track else []))

    @property
    def resolved(self) -> bool:
        """Whether what the tool chooses and the axes' motion needs (the turntable's point,
        the track's direction) is set; the track's mount follows from the placement."""
        return (self.turntable is None or self.turntable.axis_point_mm is not None) and (
            self.track is None or self.track.direction is not None
        )

    @property
    def overhead(self) -> bool:
        """Whether the arm hangs upside down from an overhead track."""
        return self.track is not None and self.track.mount == "overhead"

    def base_part(self, T_base_part0: np.ndarray, values: np.ndarray) -> np.ndarray:
        """(n, 4, 4) `T_base_part` with the axes at `values` (n, k) (module docstring)."""
        if not self.resolved:
            raise ValueError("external axes: the turntable's point or the track's direction unset")
        values = np.asarray(values, dtype=np.float64).reshape(-1, len(self.names))
        n = len(values)
        T = np.broadcast_to(np.asarray(T_base_part0, dtype=np.float64), (n, 4, 4)).copy()
        col = 0
        if self.turntable is not None:
            assert self.turntable.axis_point_mm is not None
            p = np.asarray(self.turntable.axis_point_mm, dtype=np.float64)
            R = rotation_about(_unit(self.turntable.axis_direction), np.radians(values[:, 0]))
            M = np.tile(np.eye(4), (n, 1, 1))
            M[:, :3, :3] = R
            M[:, :3, 3] = p - R @ p  # Translate(p) · R · Translate(-p)
            T = T @ M
            col = 1
        if self.track is not None:
            assert self.track.direction is not None
            T[:, :3, 3] -= values[:, col, None] * _unit(self.track.direction)
        return T

    def with_choices(
        self,
        axis_point_mm: np.ndarray | None = None,
        direction: np.ndarray | None = None,
        mount: str | None = None,
    ) -> ExternalAxes:
        """These axes with what the tool chose filled in where the user left it open."""
        turntable, track = self.turntable, self.track
        if turntable is not None and turntable.axis_point_mm is None and axis_point_mm is not None:
            point = [float(v) for v in axis_point_mm]
            turntable = turntable.model_copy(update={"axis_point_mm": point})
        if track is not None and track.direction is None and direction is not None:
            track = track.model_copy(update={"direction": [float(v) for v in _unit(direction)]})
        if track is not None and track.mount is None and mount is not None:
            track = track.model_copy(update={"mount": mount})
        return ExternalAxes(turntable, track)

    def record(self) -> dict[str, Any]:
        """What a plan file records of the axes (`of_record` reads it back)."""
        out: dict[str, Any] = {"names": list(self.names)}
        if self.turntable is not None:
            out["turntable"] = self.turntable.model_dump()
        if self.track is not None:
            out["track"] = self.track.model_dump()
        return out

    @classmethod
    def of_record(cls, data: object, where: str) -> ExternalAxes:
        """From a plan's record (`record`); ValueError naming `where` and the field."""
        if not isinstance(data, dict):
            raise ValueError(f"{where}: expected a JSON object")
        fields = {k: v for k, v in data.items() if k not in ("names", "travel")}
        try:
            model = _AxesFile.model_validate(fields)
            axes = cls(model.turntable, model.track)
        except ValidationError as exc:
            raise ValueError(error_line(where, exc)) from None
        if data.get("names", list(axes.names)) != list(axes.names):
            raise ValueError(f"{where}.names: expected {list(axes.names)}")
        return axes

    def describe(self) -> str:
        """One line: 'turntable ±180° at 60°/s, track 2000 mm at 500 mm/s'."""
        said = []
        if (t := self.turntable) is not None:
            lo, hi = t.limits_deg
            said.append(f"turntable {lo:g}..{hi:g} deg at {t.speed_deg_s:g} deg/s")
        if (k := self.track) is not None:
            mount = "" if k.mount is None else f" {k.mount}"
            said.append(f"track {k.length_mm:g} mm{mount} at {k.speed_mm_s:g} mm/s")
        return ", ".join(said)


# Presets: a 1 m-class turntable (a 500 mm disk radius, 60°/s), the part centred on it.
POSITIONERS: dict[str, ExternalAxes] = {
    "turntable": ExternalAxes(turntable=Turntable()),
}


def load_positioner(arg: str | Path) -> ExternalAxes:
    """`--positioner`: a preset name (`POSITIONERS`) or a TOML file with a [turntable]
    and/or [track] table; ValueError (one line) naming the file and field."""
    key = str(arg).strip().lower()
    if key in POSITIONERS:
        return POSITIONERS[key]
    if not key.endswith(".toml"):
        raise ValueError(
            f"--positioner {str(arg)!r}: choose {', '.join(POSITIONERS)} or a .toml file"
        )
    path = Path(arg)
    content = read_regular(path, "positioner file", MAX_POSITIONER_FILE_BYTES, "not a positioner")
    try:
        data = tomllib.loads(content.decode())
    except (UnicodeDecodeError, tomllib.TOMLDecodeError, RecursionError) as exc:
        first = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        raise ValueError(f"positioner file {path} cannot be parsed: {first}") from None
    try:
        model = _AxesFile.model_validate(data)
    except ValidationError as exc:
        raise ValueError(error_line(f"positioner file {path}", exc)) from None
    if model.turntable is None and model.track is None:
        raise ValueError(f"positioner file {path}: give a [turntable] or a [track] table")
    return ExternalAxes(model.turntable, model.track)


def track_of(length_mm: float) -> Track:
    """`--track LENGTH_MM`: a track of that travel, its direction and mount chosen by the
    tool."""
    try:
        return Track(length_mm=float(length_mm))
    except ValidationError:
        raise ValueError(
            f"--track {length_mm!r}: expected a travel in mm, > 0 and at most {MAX_TRACK_MM:g}"
        ) from None


def combined(positioner: ExternalAxes | None, track: Track | None) -> ExternalAxes | None:
    """The cell's axes from `--positioner` and `--track` (None: the arm alone)."""
    if positioner is None and track is None:
        return None
    if positioner is not None and positioner.track is not None and track is not None:
        raise ValueError("--track and a positioner file with a [track]: give the track once")
    return ExternalAxes(
        None if positioner is None else positioner.turntable,
        track if track is not None else (None if positioner is None else positioner.track),
    )


def part_poses(T_base_part0: np.ndarray, external: np.ndarray | None, axes: ExternalAxes | None):
    """`T_base_part` for each pose whose external axis values are `external` (n, k): (n, 4, 4)
    with axes, else `T_base_part0` (4, 4) itself, which stands for every pose."""
    if axes is None or external is None:
        return np.asarray(T_base_part0, dtype=np.float64)
    return axes.base_part(T_base_part0, external)


def kept(T_base_part: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """The part poses of the poses `mask` selects: (4, 4) as it is, (n, 4, 4) those rows."""
    T = np.asarray(T_base_part)
    return T if T.ndim == 2 else T[mask]


def plan_axes(record: dict[str, Any] | None, external: np.ndarray | None, where: str):
    """The external axes of a plan's arm `record` (its `external_axes`), checked against the
    plan's values per pose (`Trajectory.external`); None for a plan of the arm alone.
    ValueError (one line, naming `where`) where they disagree or a value is out of range."""
    data = None if record is None else record.get("external_axes")
    if data is None:
        if external is not None:
            raise ValueError(f"{where}: external axis values per pose but no external_axes record")
        return None
    axes = ExternalAxes.of_record(data, f"{where}: robot.external_axes")
    if external is None:
        raise ValueError(f"{where}: robot.external_axes without their values per pose")
    if external.shape[1] != len(axes.names):
        raise ValueError(
            f"{where}: {external.shape[1]} external axis values per pose, "
            f"{len(axes.names)} axes ({', '.join(axes.names)})"
        )
    lo, hi = axes.limits.T
    bad = np.flatnonzero(((external < lo - 1e-6) | (external > hi + 1e-6)).any(axis=1))
    if len(bad):
        j = int(np.argmax((external[bad[0]] < lo - 1e-6) | (external[bad[0]] > hi + 1e-6)))
        raise ValueError(
            f"{where}: pose {bad[0]}: {axes.names[j]} {external[bad[0], j]:g} beyond its "
            f"range {lo[j]:g}..{hi[j]:g}"
        )
    if not axes.resolved:
        raise ValueError(
            f"{where}: robot.external_axes: the turntable's point or track's direction unset"
        )
    return axes


def axes_seconds(traj, axes: ExternalAxes, spec, scan_speed_mm_s: float) -> float:
    """s the arm waits on the external axes over `traj` (its values `traj.external`): each
    turn of the turntable between views in full (the arm stands while it indexes: a
    trapezoid at its speed and acceleration), and where the track must move faster than
    its speed to follow the sensor, the time it takes beyond the arm's own (the TCP at the
    scan speed in a pass, at the travel speed elsewhere)."""
    if traj.external is None:
        return 0.0
    delta = np.abs(np.diff(traj.external, axis=0))
    total = 0.0
    col = 0
    if axes.turntable is not None:
        turns = delta[:, 0][delta[:, 0] > 1e-9]
        t = axes.turntable
        total += float(trapezoid_time_s(turns, t.speed_deg_s, t.accel_deg_s2).sum())
        col = 1
    if axes.track is not None:
        tcp = (traj.poses @ spec.T_sensor_line)[:, :3, 3]
        step = np.linalg.norm(np.diff(tcp, axis=0), axis=1)
        in_pass = traj.scanning[1:] & traj.scanning[:-1] & (traj.swath[1:] == traj.swath[:-1])
        arm_s = step / np.where(in_pass, scan_speed_mm_s, spec.travel_speed_mm_s)
        track_s = delta[:, col] / axes.track.speed_mm_s
        total += float(np.maximum(track_s - arm_s, 0.0).sum())
    return total


def with_disk(cell: Cell, axes: ExternalAxes | None) -> Cell:
    """`cell` with the turntable's disk (and body below it) the part lies on, as an obstacle
    of the arm's links; as it is without a turntable (or one whose point is not set)."""
    if axes is None or (t := axes.turntable) is None or t.axis_point_mm is None:
        return cell
    top = (float(t.axis_point_mm[0]), float(t.axis_point_mm[1]), float(t.axis_point_mm[2]))
    return replace(cell, disk=Disk(top, t.radius_mm, t.height_mm))


def axis_steps(traj, axes: ExternalAxes | None) -> np.ndarray:
    """(n,) bool: the poses of `traj` where the turntable takes a new angle (the program
    reaches them by a joint move on which it turns), none without a turntable."""
    step = np.zeros(len(traj), bool)
    if axes is not None and axes.turntable is not None and traj.external is not None:
        step[1:] = np.abs(np.diff(traj.external[:, 0])) > 1e-9
    return step
