"""A catalogue: every part of a folder, or of a list file (`PATH [UNITS]` a line), planned
with the same options, each on its own core or Dask worker, one plan file a part.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import replace
from pathlib import Path

from scanplan.core.run import counted, task_runner
from scanplan.jobs.plan import PlanJob, Planned, run_plan_job
from scanplan.world.part_list import folder_parts, is_part_group, read_part_list


def is_catalogue(part: str) -> bool:
    """Whether `plan`'s PART names a catalogue (a folder or a list file), not one part."""
    return is_part_group(part)


def plan_one_of_catalogue(job: PlanJob) -> tuple[Planned, str | None]:
    """In a worker: the lines of one part's plan, or the one-line reason it has none (a bad
    part is that part's failure, not the catalogue's)."""
    try:
        return run_plan_job(job), None
    except (ValueError, OSError) as exc:
        return Planned([]), str(exc).splitlines()[0] if str(exc) else type(exc).__name__


def catalogue_jobs(job: PlanJob) -> list[tuple[str, PlanJob]]:
    """(the part's name as listed, its job) for every part of the catalogue `job.part`,
    each planned into the folder `job.output` as NAME.json (the folder made here)."""
    output = job.output
    if output.suffix and not output.is_dir():
        raise ValueError(
            f"-o {output}: with a catalogue of parts, -o is the folder the plans go to"
        )
    source = Path(job.part)
    parts = folder_parts(source) if source.is_dir() else read_part_list(source)
    if output.exists() and not output.is_dir():
        raise ValueError(f"-o {output} is a file: give a folder for the plans")
    output.mkdir(parents=True, exist_ok=True)
    # A list line's units win over --units, for that part.
    return [
        (
            ref.name,
            replace(
                job,
                part=ref.source,
                units=ref.units_or(job.units),
                output=output / f"{ref.stem}.json",
            ),
        )
        for ref in parts
    ]


def plan_catalogue(
    jobs: list[tuple[str, PlanJob]],
    scheduler: str | None,
    progress: Callable[[int, int], None] | None = None,
) -> list[tuple[str, Planned, str | None]]:
    """Plan every job: on the cores here, or on the Dask scheduler; per part its name, its
    lines and its error (None when planned)."""
    with task_runner(scheduler, len(jobs)) as run:
        results = list(counted(run, progress)(plan_one_of_catalogue, [j for _, j in jobs]))
    return [(name, done, error) for (name, _), (done, error) in zip(jobs, results, strict=True)]
