"""A catalogue: every part of a folder, or of a list file, planned with the same options,
each on its own core or Dask worker, one plan file a part.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import replace
from pathlib import Path

from scanplan.core.paths import read_regular
from scanplan.core.run import counted, task_runner
from scanplan.jobs.plan import Lines, PlanJob, run_plan_job
from scanplan.world.mesh_files import MESH_SUFFIXES, STEP_SUFFIXES

# A catalogue listed in a text file rather than gathered in a folder: a .txt is no part file.
CATALOGUE_LIST_SUFFIX = ".txt"
# A list of parts, one path a line: tens of thousands of lines at most.
MAX_PART_LIST_BYTES = 16 * 1024**2


def is_catalogue(part: str) -> bool:
    """Whether `plan`'s PART names a catalogue (a folder or a list file), not one part."""
    return Path(part).is_dir() or Path(part).suffix.lower() == CATALOGUE_LIST_SUFFIX


def catalogue_parts(folder: Path) -> list[Path]:
    """The part files (meshes and STEP) directly in `folder`, sorted; each must have its own
    name, as its plan is named after it."""
    parts = sorted(
        p
        for p in folder.iterdir()
        if p.is_file() and p.suffix.lower() in MESH_SUFFIXES + STEP_SUFFIXES
    )
    if not parts:
        formats = ", ".join(MESH_SUFFIXES + STEP_SUFFIXES)
        raise ValueError(f"folder {folder} holds no part file ({formats})")
    stems = [p.stem for p in parts]
    if twice := sorted({s for s in stems if stems.count(s) > 1}):
        raise ValueError(f"folder {folder}: parts {', '.join(twice)} would share a plan name")
    return parts


def catalogue_list(listing: Path) -> list[tuple[str, str]]:
    """(the entry as written, the part to load) for each part a list file names: one a line,
    a path relative to the list's folder (or absolute, or a built-in part's name); blank
    lines and what follows a '#' are skipped. A missing or unreadable part is that part's
    failure, not the list's; the list itself must exist and name parts of distinct plan
    names."""
    data = read_regular(listing, "part list", MAX_PART_LIST_BYTES, "not a list of parts")
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise ValueError(f"part list {listing}: cannot read it ({exc})") from None
    entries = [e for line in text.splitlines() if (e := line.split("#", 1)[0].strip())]
    if not entries:
        raise ValueError(f"part list {listing} names no part (one path a line, # comments)")
    base = listing.parent
    # A name with no suffix that is no file next to the list is left to `load_part`: a
    # built-in part, or its one-line error.
    parts = [(e, str(base / e) if (base / e).exists() or Path(e).suffix else e) for e in entries]
    stems = [Path(e).stem for e in entries]
    if twice := sorted({s for s in stems if stems.count(s) > 1}):
        raise ValueError(f"part list {listing}: parts {', '.join(twice)} would share a plan name")
    return parts


def plan_one_of_catalogue(job: PlanJob) -> tuple[Lines, str | None]:
    """In a worker: the lines of one part's plan, or the one-line reason it has none (a bad
    part is that part's failure, not the catalogue's)."""
    try:
        return run_plan_job(job), None
    except (ValueError, OSError) as exc:
        return [], str(exc).splitlines()[0] if str(exc) else type(exc).__name__


def catalogue_jobs(job: PlanJob) -> list[tuple[str, PlanJob]]:
    """(the part's name as listed, its job) for every part of the catalogue `job.part`,
    each planned into the folder `job.output` as NAME.json (the folder made here)."""
    output = job.output
    if output.suffix and not output.is_dir():
        raise ValueError(
            f"-o {output}: with a catalogue of parts, -o is the folder the plans go to"
        )
    source = Path(job.part)
    if source.is_dir():
        parts = [(p.name, str(p)) for p in catalogue_parts(source)]
    else:
        parts = catalogue_list(source)
    if output.exists() and not output.is_dir():
        raise ValueError(f"-o {output} is a file: give a folder for the plans")
    output.mkdir(parents=True, exist_ok=True)
    return [
        (name, replace(job, part=p, output=output / f"{Path(p).stem}.json")) for name, p in parts
    ]


def plan_catalogue(
    jobs: list[tuple[str, PlanJob]],
    scheduler: str | None,
    progress: Callable[[int, int], None] | None = None,
) -> list[tuple[str, Lines, str | None]]:
    """Plan every job: on the cores here, or on the Dask scheduler; per part its name, its
    lines and its error (None when planned)."""
    with task_runner(scheduler, len(jobs)) as run:
        results = list(counted(run, progress)(plan_one_of_catalogue, [j for _, j in jobs]))
    return [(name, lines, error) for (name, _), (lines, error) in zip(jobs, results, strict=True)]
