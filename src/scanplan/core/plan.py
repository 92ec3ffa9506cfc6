"""The plan record: a trajectory and everything it was made under (the part, sensor and
ScanSpec in its context, the views, the arm), typed and read once. Every job takes a `Plan`,
so a count, a tool or a cycle time means the same thing in every command.
"""

from __future__ import annotations

import os
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Annotated, Any

import numpy as np
from pydantic import AfterValidator, BaseModel, ConfigDict, Field, ValidationError

from scanplan.core.context import PlanContext, recorded
from scanplan.core.limits import POSITION_MM
from scanplan.core.plan_file import read_trajectory
from scanplan.core.quantities import ScanSpec
from scanplan.core.trajectory import Trajectory
from scanplan.core.validation import error_line

Finite = Annotated[float, Field(allow_inf_nan=False)]


def _rigid(rows: list[list[float]]) -> list[list[float]]:
    """A 4x4 rigid transform (mm): a rotation, a translation within `POSITION_MM`, and
    the row (0, 0, 0, 1)."""
    T = np.asarray(rows, dtype=np.float64)
    for c, x in zip("xyz", T[:3, 3], strict=True):
        POSITION_MM.check(float(x), f"translation {c}")
    R = T[:3, :3]
    # Entries past ±1 first: the product of a 1e200 with itself overflows.
    if not (np.abs(R).max() <= 1.0 + 1e-6 and np.allclose(R.T @ R, np.eye(3), atol=1e-6)):
        raise ValueError("its 3x3 block is not a rotation")
    if np.linalg.det(R) < 0:
        raise ValueError("its 3x3 block is a reflection, not a rotation")
    if not np.array_equal(T[3], [0.0, 0.0, 0.0, 1.0]):
        raise ValueError(f"its last row is {T[3].tolist()}, not [0, 0, 0, 1]")
    return rows


Matrix4 = Annotated[
    list[Annotated[list[Finite], Field(min_length=4, max_length=4)]],
    Field(min_length=4, max_length=4),
    AfterValidator(_rigid),
]


@dataclass(frozen=True)
class ViewRecord:
    """One view of a plan: where the sensor looks along (`axis`, unit, part frame), its
    block of pass indices `first_swath..last_swath`, the passes planned in it, and (where
    recorded) its pass lines, which a closed loop steers along."""

    index: int
    axis: tuple[float, float, float]
    first_swath: int
    last_swath: int
    passes: int
    record: dict[str, Any] = field(default_factory=dict)  # as the file holds it

    @classmethod
    def of(cls, data: dict[str, Any]) -> ViewRecord:
        """From a record the file reader has validated (`plan_file`)."""
        first, last = int(data["first_swath"]), int(data["last_swath"])
        axis = tuple(float(c) for c in data["axis"])
        return cls(
            int(data["index"]),
            (axis[0], axis[1], axis[2]),
            first,
            last,
            int(data.get("passes", last - first + 1)),
            dict(data),
        )

    def holds(self, swath: np.ndarray) -> np.ndarray:
        """(n,) bool: the poses of passes `swath` that belong to this view."""
        return (swath >= self.first_swath) & (swath <= self.last_swath)


def view_records(traj: Trajectory) -> tuple[ViewRecord, ...]:
    """The views `traj` records (none for a plan of one raster without a record)."""
    return tuple(ViewRecord.of(v) for v in traj.meta.get("views") or ())


def view_of_pose(traj: Trajectory) -> np.ndarray:
    """(n,) the index (into `view_records`) of the view each pose belongs to (0 without)."""
    out = np.zeros(len(traj), dtype=int)
    for k, view in enumerate(view_records(traj)):
        out[view.holds(traj.swath)] = k
    return out


PoseIndex = Annotated[str, Field(pattern=r"^\d{1,9}$")]
Joints6 = Annotated[list[Finite], Field(min_length=6, max_length=6)]


class _ArmJson(BaseModel):
    """What a plan file must hold of its arm; the rest (what fitting gave up) is free."""

    model_config = ConfigDict(extra="allow", strict=True)
    robot: str = Field(min_length=1)
    T_base_part: Matrix4
    T_flange_sensor: Matrix4
    # Where each pass is entered (a pose index) and the arm's joints there (deg): the
    # configuration it is flown on.
    pass_entry_joints_deg: dict[PoseIndex, Joints6] | None = None


@dataclass(frozen=True)
class ArmRecord:
    """The arm a plan was made for: its name (a preset or a file), the part's pose in its
    base frame, the sensor on its flange (mm), and what fitting the plan to it cost
    (`record`, as the file holds it: poses given up, in-spec coverage with and without)."""

    robot: str
    T_base_part: np.ndarray
    T_flange_sensor: np.ndarray
    record: dict[str, Any]

    @classmethod
    def of(cls, data: object, where: str) -> ArmRecord:
        """From a file's `robot` record; ValueError naming `where` and the field."""
        try:
            model = _ArmJson.model_validate(data)
        except ValidationError as exc:
            raise ValueError(error_line(f"{where}: robot", exc)) from None
        return cls(
            model.robot,
            np.asarray(model.T_base_part, dtype=np.float64),
            np.asarray(model.T_flange_sensor, dtype=np.float64),
            dict(data),  # type: ignore[call-overload]
        )

    def entry_joints(
        self, robot: str, T_base_part: np.ndarray, T_flange_sensor: np.ndarray
    ) -> dict[int, np.ndarray] | None:
        """The joints (rad) the fit entered each pass with, by the pose it is entered at
        (`trajectory.pass_entries`): the configurations chosen, for this arm standing where
        the plan put it and holding the sensor as planned; None for another arm, pose or TCP
        (their own choice), or a file that records none."""
        entries = self.record.get("pass_entry_joints_deg")
        if (
            entries is None
            or robot != self.robot
            or not np.allclose(T_base_part, self.T_base_part, atol=1e-6)
            or not np.allclose(T_flange_sensor, self.T_flange_sensor, atol=1e-6)
        ):
            return None
        return {int(i): np.radians(np.asarray(q, dtype=np.float64)) for i, q in entries.items()}

    @property
    def flyable(self) -> bool:
        """Whether fitting left a plan the arm flies (the plan's own verdict)."""
        return bool(self.record.get("flyable", self.record.get("reachable", True)))

    @property
    def coverage(self) -> tuple[float, float] | None:
        """`free_and_flown` of this arm's record."""
        return free_and_flown(self.record)


def free_and_flown(record: Mapping[str, Any]) -> tuple[float, float] | None:
    """(free, flown) in-spec coverage of an arm's record, as the planner estimated them: the
    plan made without the arm where one was made (views chosen for the arm), else the same
    views before fitting; and what the arm flies. None where the record has neither."""
    free = record.get("in_spec_free_plan", record.get("in_spec_without_robot"))
    flown = record.get("in_spec")
    if not isinstance(free, int | float) or not isinstance(flown, int | float):
        return None
    return float(free), float(flown)


@dataclass(frozen=True)
class Plan:
    """A trajectory and what it was made under. `where`: the file (or job) it came from,
    for messages; `assumed`: what was taken for a record an older file lacks, in words."""

    traj: Trajectory
    context: PlanContext
    views: tuple[ViewRecord, ...] = ()
    arm: ArmRecord | None = None
    where: str = "plan"
    assumed: tuple[str, ...] = ()

    @classmethod
    def of(cls, traj: Trajectory, where: str = "plan") -> Plan:
        """The plan `traj` records in its `meta` (as read from a file, or as planned)."""
        assumed: list[str] = []
        if traj.meta.get("context") is None:
            context = recorded(traj, ScanSpec())
            assumed.append(
                f"{where} records no context (an older or foreign file): assumed the default "
                f"sensor and tolerances and the {context.surface} surface"
            )
        else:
            context = PlanContext.from_json_dict(traj.meta["context"], where)
            if not context.part_digest:
                assumed.append(
                    f"{where} records no digest of its part (planned before plans did): the "
                    "part given is taken to be the one planned, unchecked"
                )
        views = view_records(traj)
        arm = None
        if (data := traj.meta.get("robot")) is not None:
            arm = ArmRecord.of(data, where)
        return cls(traj, context, views, arm, where, tuple(assumed))

    @property
    def records_context(self) -> bool:
        """Whether the file recorded what the plan was made under (else defaults assumed)."""
        return self.traj.meta.get("context") is not None

    @property
    def spec(self) -> ScanSpec:
        return self.context.spec

    @property
    def planner(self) -> str:
        return self.traj.planner or self.context.planner

    def views_flown(self) -> list[int]:
        """The indices (into `views`) of the views with a scanning pose: the views a
        program flies; [0] for a plan without view records."""
        if not self.views:
            return [0] if self.traj.scanning.any() else []
        scanning = self.traj.scanning
        return [k for k, v in enumerate(self.views) if (v.holds(self.traj.swath) & scanning).any()]

    def passes_flown(self) -> int:
        """The passes flown: the pass indices with a scanning pose, as the cycle time counts
        them (a pass the arm splits at a flip is two; one cut where poses were dropped is
        one pass of several runs)."""
        return len(np.unique(self.traj.swath[self.traj.scanning]))

    def counts(self) -> str:
        """'3 views, 12 passes, 4015 profiles': the one way every output counts a plan."""
        n_views, n_passes = len(self.views_flown()), self.passes_flown()
        return (
            f"{n_views} view{'s' * (n_views != 1)}, {n_passes} pass{'es' * (n_passes != 1)}, "
            f"{int(self.traj.scanning.sum())} profiles"
        )

    @property
    def cycle_time_s(self) -> float | None:
        """The cycle time `plan` printed and recorded (None: a file without it)."""
        value = self.traj.meta.get("cycle_time_s")
        return None if value is None else float(value)


def read_plan(path: str | os.PathLike) -> Plan:
    """The plan a CSV or JSON file holds; ValueError (one line) naming the file and field."""
    return Plan.of(read_trajectory(path), f"plan {os.fspath(path)}")
