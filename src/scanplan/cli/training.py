"""`scanplan train` and `sweep`: PPO training of the pass agent, one run or seeds x a grid of
configs on Dask. Both build the trainer's config from the same options, in one place.
"""

from __future__ import annotations

import json
import re
import shlex
import sys
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Any

import typer

from scanplan.cli.common import removed_on_error, user_errors
from scanplan.cli.options import (
    SEED_CHECK,
    BcSamplesOpt,
    EnvVersionOpt,
    FanPointsOpt,
    InitAdvanceOpt,
    LogStdInitOpt,
    NEnvsOpt,
    PitchPivotOpt,
    ProceduralOpt,
    RewardDistanceScaleOpt,
    StartOffsetOpt,
    StateOpt,
    TrainNoiseOpt,
    TrainPerturbOpt,
    bounded,
    parse_floats,
)
from scanplan.core.limits import MAX_SEED, MAX_TIMESTEPS
from scanplan.core.run import check_scheduler

if TYPE_CHECKING:
    from scanplan.rl.learn.config import TrainConfig
    from scanplan.rl.learn.sweep import EvalPart, SweepTask


def training_config(ctx: typer.Context, **own: Any) -> TrainConfig:
    """The trainer's config from the options train and sweep share (read by name from the
    parsed command line: -o, --timesteps and the training group of cli.options) and the
    command's `own` fields."""
    # Deferred: learn loads torch and stable-baselines3.
    from scanplan.rl.learn.config import recipe_config

    shared = ctx.params
    return recipe_config(
        str(shared["output"]),
        timesteps=shared["timesteps"],
        n_envs=shared["n_envs"],
        state=shared["state"],
        env_version=shared["env_version"],
        procedural=shared["procedural"],
        fan_points=shared["fan_points"],
        log_std_init=parse_floats(shared["log_std_init"], "--log-std-init"),
        init_advance=shared["init_advance"],
        start_offset=parse_floats(shared["start_offset"], "--start-offset"),
        reward_distance_scale=shared["reward_distance_scale"],
        pitch_pivot=shared["pitch_pivot"],
        bc_samples=shared["bc_samples"],
        perturb=shared["perturb"],
        noise=shared["noise"],
        command=shlex.join(["scanplan", *sys.argv[1:]]),
        **own,
    )


# ---- train --------------------------------------------------------------------------------
PolicyDirOpt = Annotated[
    Path,
    typer.Option(
        "-o",
        "--output",
        metavar="FOLDER",
        help="output folder: the policy, its log and checkpoints",
    ),
]
TrainPartsOpt = Annotated[
    list[str] | None, typer.Option("--part", help="training part(s): built-in name or mesh")
]
# Not shared with sweep: a total here, per run there, where 0 means behaviour cloning only.
TrainTimestepsOpt = Annotated[
    int,
    typer.Option(help="total PPO timesteps, >= 1", callback=bounded(1, MAX_TIMESTEPS)),
]
TrainSeedOpt = Annotated[
    int, typer.Option(help="seed of PPO and the environments, >= 0", callback=SEED_CHECK)
]
VecOpt = Annotated[str, typer.Option(help="batched (envs stepped together, one process) | subproc")]
ResumeOpt = Annotated[Path | None, typer.Option(help="continue from the latest checkpoint in DIR")]
NoProgressOpt = Annotated[
    bool, typer.Option("--no-progress", "--quiet", "-q", help="no progress bar")
]


@user_errors
def train_cmd(
    ctx: typer.Context,
    output: PolicyDirOpt,
    part: TrainPartsOpt = None,
    timesteps: TrainTimestepsOpt = 1_000_000,
    seed: TrainSeedOpt = 0,
    n_envs: NEnvsOpt = 16,
    vec: VecOpt = "batched",
    resume: ResumeOpt = None,
    state: StateOpt = "paper",
    env_version: EnvVersionOpt = "v0",
    procedural: ProceduralOpt = 0,
    fan_points: FanPointsOpt = None,
    log_std_init: LogStdInitOpt = "0",
    init_advance: InitAdvanceOpt = None,
    start_offset: StartOffsetOpt = "0,0",
    reward_distance_scale: RewardDistanceScaleOpt = None,
    pitch_pivot: PitchPivotOpt = None,
    bc_samples: BcSamplesOpt = 0,
    perturb: TrainPerturbOpt = None,
    noise: TrainNoiseOpt = False,
    no_progress: NoProgressOpt = False,
):
    """Train the pass agent with PPO (the paper's hyperparameters) and write a policy.

    With no options this is the paper's recipe from scratch, which on the training piece does
    not learn to follow a surface (its policy does not beat the fixed line on the door; why:
    scanplan/policies/default/README.md); the shipped default policy is warm-started
    (--bc-samples). --reward-distance-scale 12.5 (a deviation from the paper's reward) makes
    it learn the depth from scratch, and --pitch-pivot footprint (a pitch step that does not
    swing the footprint) the pitch: the shipped --policy paper, whose command is in its
    policy.json."""
    # Deferred: learn loads torch and stable-baselines3.
    from scanplan.rl.learn.checkpoint import CHECKPOINT_DIR
    from scanplan.rl.learn.train import train

    if resume is not None and not resume.is_dir():
        raise ValueError(f"--resume {resume} is not a directory")
    # The training group and --timesteps reach the config through ctx.params.
    config = training_config(
        ctx,
        parts=tuple(part or ["training-piece"]),
        seed=seed,
        vec_env=vec,
        resume=str(resume) if resume else None,
        progress_bar=not no_progress,
    )

    def has_checkpoint(out: Path) -> bool:
        return any((out / CHECKPOINT_DIR).glob("*.json"))

    with removed_on_error(output, keep=has_checkpoint):
        result = train(config)
    f = result.final
    typer.echo(
        f"{result.timesteps} timesteps in {result.wall_time_s:.0f} s | reward/step "
        f"{f['reward_per_step']:.4f} (R_D {f['r_d']:.4f}, R_α {f['r_alpha']:.4f}, "
        f"R_Δs {f['r_delta_s']:.4f}) -> {result.policy_json}"
    )


# ---- sweep --------------------------------------------------------------------------------
def parse_grid(items: list[str]) -> dict[str, list[Any]]:
    """--grid KEY=V1,V2 (values as JSON where they parse, e.g. [-2,-2,-4], else strings)."""
    grid: dict[str, list[Any]] = {}
    for item in items:
        key, sep, values = item.partition("=")
        if not sep or not key or not values:
            raise ValueError(f"--grid {item!r}: expected KEY=V1,V2,...")
        parsed = []
        for text in re.split(r",(?![^\[]*\])", values):
            try:
                value = json.loads(text)
            except json.JSONDecodeError:
                value = text
            parsed.append(tuple(value) if isinstance(value, list) else value)
        grid[key.strip()] = parsed
    return grid


def parse_seeds(text: str) -> list[int]:
    """--seeds 0,1,2: whole numbers in [0, MAX_SEED], each once."""
    seeds = []
    for item in text.split(","):
        try:
            seed = int(item.strip())
        except ValueError:
            raise ValueError(f"--seeds {text!r}: expected whole numbers, e.g. 0,1,2") from None
        if not 0 <= seed <= MAX_SEED:
            raise ValueError(f"--seeds {text!r}: {seed} is not in [0, {MAX_SEED}]")
        if seed in seeds:
            raise ValueError(f"--seeds {text!r}: {seed} given twice")
        seeds.append(seed)
    return seeds


def check_cluster(scheduler: str | None, workers: int | None) -> None:
    """--scheduler and --workers, refused before any work: the scheduler must answer as one
    and have a worker within a stated time (`open_scheduler`), which it says it waits for."""
    if workers is not None and workers < 1:
        raise ValueError(f"--workers: {workers} must be >= 1")
    if scheduler is not None:
        check_scheduler(scheduler, waiting=lambda text: typer.echo(text, err=True))


def run_on_cluster(
    tasks: list[SweepTask],
    parts: list[EvalPart],
    output: Path,
    scheduler: str | None,
    workers: int | None,
) -> tuple[Path, Path]:
    """Run the sweep's tasks on Dask and write its tables in `output`: (csv, md)."""
    # Deferred: the sweep loads dask, torch and stable-baselines3.
    from scanplan.rl.learn.sweep import connect, run_sweep, write_tables

    def has_runs(directory: Path) -> bool:  # finished runs are reused by a rerun: keep them
        return any((directory / "runs").glob("**/policy.json"))

    with removed_on_error(output, keep=has_runs):
        output.mkdir(parents=True, exist_ok=True)
        try:
            with connect(scheduler, workers) as client:
                rows = run_sweep(
                    tasks,
                    parts,
                    client,
                    on_done=lambda done: typer.echo(
                        f"done: {done[0]['label']} seed {done[0]['seed']}", err=True
                    ),
                )
        except (OSError, TimeoutError) as exc:  # no scheduler there, or it went away
            raise ValueError(f"--scheduler {scheduler}: {exc}".splitlines()[0]) from None
        return write_tables(rows, output)


SweepDirOpt = Annotated[
    Path,
    typer.Option(
        "-o",
        "--output",
        metavar="FOLDER",
        help="output folder: one folder a run, sweep.csv, sweep.md",
    ),
]
EvalPartsOpt = Annotated[
    list[str] | None,
    typer.Option("--part", help="unseen part(s) to evaluate on: name or PATH[:UNITS]"),
]
SeedsOpt = Annotated[str, typer.Option(help="training seeds, e.g. 0,1,2")]
GridOpt = Annotated[
    list[str] | None,
    typer.Option("--grid", help="KEY=V1,V2: a TrainConfig field (or env.NAME) and its values"),
]
LabelOpt = Annotated[str, typer.Option(help="row label of the trained runs")]
BaselineOpt = Annotated[
    list[str] | None,
    typer.Option("--baseline", help="also evaluate an untrained planner: feedback, geometric"),
]
SchedulerOpt = Annotated[
    str | None, typer.Option(help="Dask scheduler tcp://HOST:8786 (default: a LocalCluster)")
]
WorkersOpt = Annotated[
    int | None, typer.Option(help="LocalCluster workers (default: one per core)")
]
SweepTimestepsOpt = Annotated[
    int,
    typer.Option(help="PPO timesteps per run (0: BC only)", callback=bounded(0, MAX_TIMESTEPS)),
]


@user_errors
def sweep_cmd(
    ctx: typer.Context,
    output: SweepDirOpt,
    part: EvalPartsOpt = None,
    seeds: SeedsOpt = "0,1,2",
    grid: GridOpt = None,
    label: LabelOpt = "rl",
    baseline: BaselineOpt = None,
    scheduler: SchedulerOpt = None,
    workers: WorkersOpt = None,
    timesteps: SweepTimestepsOpt = 61_440,
    state: StateOpt = "paper",
    env_version: EnvVersionOpt = "v0",
    procedural: ProceduralOpt = 0,
    fan_points: FanPointsOpt = None,
    log_std_init: LogStdInitOpt = "0",
    init_advance: InitAdvanceOpt = None,
    start_offset: StartOffsetOpt = "0,0",
    reward_distance_scale: RewardDistanceScaleOpt = None,
    pitch_pivot: PitchPivotOpt = None,
    bc_samples: BcSamplesOpt = 0,
    perturb: TrainPerturbOpt = None,
    noise: TrainNoiseOpt = False,
    n_envs: NEnvsOpt = 16,
):
    """Train seeds x a grid of configs as Dask tasks, evaluate each policy on unseen parts,
    and write sweep.csv (per run and part) and sweep.md (mean ± sd over seeds)."""
    # Deferred: the sweep loads dask, torch and stable-baselines3.
    from scanplan.rl.learn.sweep import CLUSTER_HINT

    try:
        import dask.distributed  # noqa: F401
    except ImportError:
        raise ValueError(CLUSTER_HINT) from None
    from scanplan.rl.learn.sweep import EvalPart, SweepTask, grid_tasks

    # Everything is checked before a worker starts: a mistake never costs a training run.
    seed_list = parse_seeds(seeds)
    base = training_config(ctx, progress_bar=False)  # the training group, via ctx.params
    tasks = grid_tasks(label, base, output / "runs", seed_list, parse_grid(grid or []))
    roll = env_version == "v1"
    for name in baseline or []:
        if name not in ("fixed", "feedback", "geometric"):
            raise ValueError(f"--baseline {name!r}: use fixed, feedback or geometric")
    tasks += [SweepTask(name, planner=name, roll=roll) for name in baseline or []]
    parts = [EvalPart.parse(p).check() for p in part or ["door", "drone"]]
    check_cluster(scheduler, workers)  # last: the scheduler may take seconds to answer
    csv_path, md_path = run_on_cluster(tasks, parts, output, scheduler, workers)
    typer.echo(md_path.read_text(), nl=False)
    typer.echo(f"-> {csv_path}, {md_path}")
