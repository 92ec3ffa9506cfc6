"""What every job on an existing plan shares: the part it was made for (checked by content,
never silently another), its cell, and the context it is judged by (the plan's, with what
the user's options override, said in one line).
"""

from __future__ import annotations

from collections.abc import Callable
from contextlib import AbstractContextManager, nullcontext
from dataclasses import replace
from pathlib import Path

from scanplan.core.context import VIEW_MODES, PlanContext
from scanplan.core.paths import not_regular
from scanplan.core.plan import Plan
from scanplan.core.sensor_files import load_sensor
from scanplan.world.cell import Cell, planned_cell
from scanplan.world.part import Part, geometry_digest, load_part

Say = Callable[[str], None]
# A progress bar by label, as the command line draws one: a context yielding progress(done,
# total), or None where nothing is drawn.
ProgressBar = Callable[[str], AbstractContextManager[Callable[[int, int], None] | None]]


def no_bar(_: str) -> AbstractContextManager[None]:
    """A `ProgressBar` that draws nothing."""
    return nullcontext(None)


def silent(_: str) -> None:
    """A `Say` that says nothing (a job run from a script, not the command line)."""


def planned_part(
    plan: Plan,
    part: str | None,
    units: str | None,
    needed_for: str = "the plan is judged on it",
    other_part: bool = False,
    say: Say = silent,
) -> Part:
    """The part `plan` was made for: `part` (else the one the plan records) in `units`
    (else the plan's). A part that is not the planned one (another file, or the same file
    in other units) is refused in one line naming both, unless `other_part` (then said)."""
    context = plan.context
    name = part or context.part
    if not name:
        raise ValueError(
            f"--part is required: {needed_for}, and {plan.where} records none (planned before "
            "plans named their part)"
        )
    recorded_units = context.fixture_units
    try:
        loaded = load_part(name, units or recorded_units)
    except ValueError as exc:
        if part or not_regular(name) is None:  # given, or there and not a part: as it said
            raise
        # Recorded as given when planned: a relative path is relative to where that was.
        raise ValueError(
            f"{exc}: {plan.where} records its part as given when it was planned; give the "
            "part's file before the plan"
        ) from None
    if not context.part_digest or geometry_digest(loaded) == context.part_digest:
        return loaded
    planned = f"{context.part or 'unnamed'} [{recorded_units}]"
    given = f"{name} [{units or recorded_units}]"
    same_file = context.part and _same_file(name, context.part)
    hint = (
        f"the plan was made with --units {recorded_units}"
        if same_file and units not in (None, recorded_units)
        else f"give the plan's part ({planned})"
    )
    if other_part:
        say(f"note: {given} is not the part {plan.where} was made for ({planned})")
        return loaded
    raise ValueError(
        f"part {given} is not the part {plan.where} was made for ({planned}): {hint}, or "
        "--other-part to use this one anyway"
    )


def _same_file(a: str, b: str) -> bool:
    try:
        return Path(a).resolve() == Path(b).resolve()
    except OSError:
        return a == b


def plan_cell(plan: Plan, part: Part, context: PlanContext | None = None) -> Cell:
    """The cell the plan was made in (its table and fixtures) around `part`, or that of
    `context` (the plan's with what options override); a message names the plan file for
    fixtures it records."""
    context = plan.context if context is None else context
    where = "--fixture"
    if context.fixtures == plan.context.fixtures:
        where = f"{plan.where}: context: fixtures"
    try:
        return planned_cell(context, part, where)
    except ValueError as exc:
        raise _recorded(exc, "--table", plan, context.table == plan.context.table) from None


def inspected(plan: Plan, part: Part, context: PlanContext | None = None) -> Part:
    """`part` kept to the region of interest of `context` (the plan's, else the one with
    what options override); a bad one the plan file records is named as the file's."""
    context = plan.context if context is None else context
    try:
        return part.with_roi(context.roi)
    except ValueError as exc:
        raise _recorded(exc, "--roi", plan, context.roi == plan.context.roi) from None


def _recorded(exc: ValueError, option: str, plan: Plan, from_plan: bool) -> ValueError:
    """`exc` (a message about `option`) naming the plan file's field instead where the
    value came `from_plan`, not from the option."""
    said = str(exc)
    if from_plan and said.startswith(option):
        field = option.removeprefix("--")
        return ValueError(f"{plan.where}: context: {field}{said.removeprefix(option)}")
    return exc


def judged_context(
    plan: Plan,
    sensor: str | None,
    tolerance: dict[str, float] | None,
    roi: str | None,
    views: str | None,
    table: str | None = None,
    fixtures: list[str] | None = None,
) -> tuple[PlanContext, str]:
    """The context to judge `plan` by: its own, with what the options override; and one
    line saying where that differs from the plan (or what an older file made us assume),
    '' if nowhere."""
    if views is not None and views not in VIEW_MODES:
        raise ValueError(f"unknown --views {views!r}; use top or auto")
    planned = plan.context
    spec = planned.spec
    if sensor is not None:
        spec = replace(spec, sensor=load_sensor(sensor))
    if tolerance:
        spec = replace(
            spec,
            tol_distance_mm=tolerance["tol_distance_mm"],
            tol_angle_rad=tolerance["tol_angle_rad"],
        )
    judged = planned.with_options(
        spec, roi, views, table, None if fixtures is None else tuple(fixtures)
    )
    notes = list(plan.assumed)
    if plan.records_context:  # else nothing recorded to differ from
        if changes := planned.differences(judged):
            notes.append("judged with " + "; ".join(changes))
    return judged, ("note: " + "; ".join(notes)) if notes else ""
