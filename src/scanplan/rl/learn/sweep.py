"""Sweeps: seeds x hyperparameter grids as tasks on Dask distributed, each a `train(config)`
into its own directory followed by the evaluation of the trained policy (or of an untrained
planner) on parts it never saw, collected into one table (CSV + Markdown).
"""

from __future__ import annotations

import csv
import itertools
import json
import logging
import math
import os
import re
import time
from collections.abc import Callable, Iterable, Iterator, Mapping, Sequence
from contextlib import contextmanager
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import Any

from scanplan.core.limits import MAX_RUNS, check_count
from scanplan.core.quantities import ScanSpec
from scanplan.core.run import scheduler_client
from scanplan.judging import evaluate
from scanplan.planning.pass_path import plan_scan
from scanplan.rl.learn.config import TrainConfig, env_options, typed_field
from scanplan.rl.learn.train import train
from scanplan.rl.planners import make_planner
from scanplan.world.part import load_part
from scanplan.world.part_list import parse_part
from scanplan.world.parts import PART_NAMES

CLUSTER_HINT = "scanplan sweep needs the cluster extra: pip install 'scanplan[cluster]'"
METRICS = (
    "reward_mean",
    "in_spec_coverage",
    "distance_error_mean_abs_mm",
    "orientation_error_mean_deg",
)
COLUMNS = (
    "label",
    "env",
    "seed",
    "params",
    "part",
    *METRICS,
    "timesteps",
    "train_wall_s",
    "train_cpu_s",
    "eval_s",
    "policy_dir",
)


@dataclass(frozen=True)
class EvalPart:
    """A part to evaluate on: a built-in name or a mesh file, with its units."""

    name: str
    source: str
    units: str = "mm"

    @classmethod
    def parse(cls, text: str) -> EvalPart:
        """`door`, `drone` or `PATH[:UNITS]` (units mm, m or in; default mm)."""
        ref = parse_part(text)
        return cls(Path(ref.source).stem, ref.source, ref.units_or("mm"))

    def check(self) -> EvalPart:
        """Self, or a ValueError if it is neither a built-in part nor a file (checked before
        any training, which would otherwise end on it)."""
        if self.source not in PART_NAMES and not Path(self.source).is_file():
            raise ValueError(
                f"--part {self.source!r} is neither a file nor a built-in part "
                f"({', '.join(PART_NAMES)})"
            )
        return self


@dataclass(frozen=True)
class SweepTask:
    """One row of a sweep: train `config` (None: no training) and evaluate `planner` (`rl`
    loads the trained policy) on every part. `roll` applies to the untrained planners; an
    `rl` planner rolls if its policy is a v1 one."""

    label: str
    config: TrainConfig | None = None
    planner: str = "rl"
    roll: bool = False
    params: Mapping[str, Any] = field(default_factory=dict)

    @property
    def env(self) -> str:
        if self.config is not None:
            return "v1" if self.config.env.get("roll") else "v0"
        return "v1" if self.roll else "v0"

    @property
    def seed(self) -> int | None:
        return None if self.config is None else self.config.seed


def slug(text: str) -> str:
    return re.sub(r"[^a-z0-9]+", "-", text.lower()).strip("-") or "task"


def _with_param(config: TrainConfig, key: str, value: Any) -> TrainConfig:
    """`key` a TrainConfig field, or `env.NAME` for an environment option."""
    if key.startswith("env."):
        env = {**config.env, key[4:]: value}
        env_options(env)  # the policy file's schema: types and ranges, before any worker
        return replace(config, env=env)
    if key not in TrainConfig.__dataclass_fields__ or key in _NOT_SWEPT:
        raise ValueError(f"sweep grid: {key!r} is no TrainConfig field (nor env.NAME)")
    try:
        # The field's type, then its range (TrainConfig checks it when made).
        return replace(config, **{key: typed_field(key, value)})
    except ValueError as exc:
        raise ValueError(f"sweep grid: {str(exc).removeprefix('training config: ')}") from None


def grid_tasks(
    label: str,
    base: TrainConfig,
    out_dir: str | os.PathLike[str],
    seeds: Iterable[int] = (0,),
    grid: Mapping[str, Sequence[Any]] | None = None,
) -> list[SweepTask]:
    """seeds x the cartesian product of `grid` (TrainConfig field -> values), each task
    training into `out_dir/<label>[-key=value...]-s<seed>`."""
    grid = dict(grid or {})
    seeds = list(seeds)
    runs = len(seeds) * math.prod(len(v) for v in grid.values())
    check_count(runs, MAX_RUNS, "sweep: runs (seeds x grid)")
    tasks = []
    for values in itertools.product(*grid.values()):
        params = dict(zip(grid, values, strict=True))
        config = base
        for key, value in params.items():
            config = _with_param(config, key, value)
        name = "-".join([slug(label), *(slug(f"{k}={v}") for k, v in params.items())])
        for seed in seeds:
            run_dir = Path(out_dir) / f"{name}-s{seed}"
            tasks.append(
                SweepTask(
                    label,
                    replace(config, seed=int(seed), output_dir=str(run_dir), progress_bar=False),
                    params=params,
                )
            )
    return tasks


# Set per run by the sweep itself.
_NOT_SWEPT = ("output_dir", "seed", "resume", "progress_bar", "command")
_DONE = "sweep_train.json"
_EVALUATED = "sweep_eval.json"


def _config_record(config: TrainConfig) -> dict[str, Any]:
    record = {k: v for k, v in asdict(config).items() if k not in ("command", "progress_bar")}
    return json.loads(json.dumps(record))  # tuples as lists, as read back


def train_once(config: TrainConfig, reuse: bool = False) -> tuple[int, float, float]:
    """`train(config)` -> (timesteps, wall s, CPU s of this process). reuse: a directory that
    already holds a finished run of exactly this config is not trained again."""
    done = Path(config.output_dir) / _DONE
    if reuse and done.is_file():
        record = json.loads(done.read_text())
        if record["config"] == _config_record(config):
            return int(record["timesteps"]), float(record["wall_s"]), float(record["cpu_s"])
    (Path(config.output_dir) / _EVALUATED).unlink(missing_ok=True)
    cpu = time.process_time()
    result = train(config)
    cpu = time.process_time() - cpu
    record = {
        "config": _config_record(config),
        "timesteps": result.timesteps,
        "wall_s": result.wall_time_s,
        "cpu_s": cpu,
    }
    done.write_text(json.dumps(record, indent=1))
    return result.timesteps, result.wall_time_s, cpu


def run_task(
    task: SweepTask, parts: Sequence[EvalPart], reuse: bool = False
) -> list[dict[str, Any]]:
    """Train (if the task does) and evaluate on each part; one row per part. Runs in a Dask
    worker, so everything it needs comes in its arguments. CPU s counts this process only
    (torch runs on one thread while training)."""
    timesteps, wall, cpu, policy_dir = 0, 0.0, 0.0, ""
    if task.config is not None:
        timesteps, wall, cpu = train_once(task.config, reuse)
        policy_dir = task.config.output_dir
        planner = make_planner("rl", policy=policy_dir)
    else:
        planner = make_planner(task.planner, roll=task.roll)
    spec = ScanSpec()
    # A trained run's evaluations are kept beside it (dropped when it is trained again).
    cache_path = Path(policy_dir) / _EVALUATED if policy_dir else None
    cache: dict[str, Any] = {}
    if reuse and cache_path is not None and cache_path.is_file():
        cache = json.loads(cache_path.read_text())
    rows = []
    for p in parts:
        key = f"{p.source}:{p.units}"
        if key not in cache:
            start = time.perf_counter()
            part = load_part(p.source, p.units)
            _, traj = plan_scan(part, spec, planner)
            m = evaluate(part, spec, traj, points_per_profile=512)
            cache[key] = {k: float(getattr(m, k)) for k in METRICS}
            cache[key]["eval_s"] = round(time.perf_counter() - start, 1)
            if cache_path is not None:
                cache_path.write_text(json.dumps(cache, indent=1))
        row: dict[str, Any] = {
            "label": task.label,
            "env": task.env,
            "seed": "" if task.seed is None else task.seed,
            "params": json.dumps(dict(task.params), sort_keys=True) if task.params else "",
            "part": p.name,
            **{k: cache[key][k] for k in METRICS},
            "timesteps": timesteps,
            "train_wall_s": round(wall, 1),
            "train_cpu_s": round(cpu, 1),
            "eval_s": cache[key]["eval_s"],
            "policy_dir": policy_dir,
        }
        rows.append(row)
    return rows


def _client_class() -> Any:
    try:
        from dask.distributed import Client
    except ImportError:
        raise ImportError(CLUSTER_HINT) from None
    return Client


@contextmanager
def connect(scheduler: str | None = None, n_workers: int | None = None) -> Iterator[Any]:
    """A Dask client on the scheduler at `scheduler` (tcp://HOST:8786), else on a
    LocalCluster over loopback with one single-threaded worker process per core (training
    runs torch on one thread); a LocalCluster is closed afterwards."""
    client_class = _client_class()
    if scheduler is not None:
        with scheduler_client(scheduler) as client:
            yield client
        return
    from dask.distributed import LocalCluster

    with (
        LocalCluster(
            n_workers=n_workers or os.cpu_count() or 1,
            threads_per_worker=1,
            processes=True,
            # The workers' log (start, stop, a lost worker) stays out of the user's terminal:
            # the sweep reports what matters itself.
            silence_logs=logging.CRITICAL,
            host="127.0.0.1",
            dashboard_address=":0",
        ) as cluster,
        client_class(cluster) as client,
    ):
        yield client


def run_sweep(
    tasks: Sequence[SweepTask],
    parts: Sequence[EvalPart],
    client: Any,
    on_done: Callable[[list[dict[str, Any]]], None] | None = None,
    reuse: bool = False,
) -> list[dict[str, Any]]:
    """Every task on the cluster (the longest-training first); rows in task order. reuse:
    runs already finished with the same config are evaluated, not trained again."""
    from dask.distributed import as_completed

    if not tasks:
        raise ValueError("sweep: no task")
    if not parts:
        raise ValueError("sweep: no part to evaluate on")

    def cost(task: SweepTask) -> int:
        return -1 if task.config is None else task.config.total_timesteps + task.config.bc_samples

    order = sorted(range(len(tasks)), key=lambda i: -cost(tasks[i]))
    futures = {client.submit(run_task, tasks[i], list(parts), reuse, pure=False): i for i in order}
    results: dict[int, list[dict[str, Any]]] = {}
    for future in as_completed(futures):
        rows = future.result()
        results[futures[future]] = rows
        if on_done is not None:
            on_done(rows)
    return [row for i in range(len(tasks)) for row in results[i]]


def write_csv(rows: Sequence[Mapping[str, Any]], path: str | os.PathLike[str]) -> Path:
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_suffix(path.suffix + ".tmp")
    with tmp.open("w", newline="") as f:
        writer = csv.DictWriter(f, COLUMNS, extrasaction="ignore")
        writer.writeheader()
        writer.writerows(rows)
    os.replace(tmp, path)
    return path


def read_csv(path: str | os.PathLike[str]) -> list[dict[str, Any]]:
    with Path(path).open(newline="") as f:
        rows: list[dict[str, Any]] = list(csv.DictReader(f))
    for row in rows:
        for key in (*METRICS, "train_wall_s", "train_cpu_s", "eval_s"):
            row[key] = float(row[key])
        row["timesteps"] = int(row["timesteps"])
    return rows


def _mean_sd(values: Sequence[float]) -> tuple[float, float]:
    n = len(values)
    mean = sum(values) / n
    sd = math.sqrt(sum((v - mean) ** 2 for v in values) / (n - 1)) if n > 1 else 0.0
    return mean, sd


@dataclass(frozen=True)
class Summary:
    """One (row label, env, params, part) over its seeds: mean and sample sd per metric."""

    label: str
    env: str
    params: str
    part: str
    seeds: int
    mean: dict[str, float]
    sd: dict[str, float]
    train_wall_s: float  # mean over seeds
    train_cpu_s: float  # mean over seeds
    timesteps: int


def summarize(rows: Sequence[Mapping[str, Any]]) -> list[Summary]:
    """Group the rows by (label, env, params, part), in first-seen order."""
    groups: dict[tuple[str, str, str, str], list[Mapping[str, Any]]] = {}
    for row in rows:
        key = (str(row["label"]), str(row["env"]), str(row["params"]), str(row["part"]))
        groups.setdefault(key, []).append(row)
    out = []
    for (label, env, params, part), group in groups.items():
        stats = {k: _mean_sd([float(r[k]) for r in group]) for k in METRICS}
        out.append(
            Summary(
                label,
                env,
                params,
                part,
                len(group),
                {k: v[0] for k, v in stats.items()},
                {k: v[1] for k, v in stats.items()},
                _mean_sd([float(r["train_wall_s"]) for r in group])[0],
                _mean_sd([float(r.get("train_cpu_s", 0.0)) for r in group])[0],
                int(group[0]["timesteps"]),
            )
        )
    return out


def _cell(mean: float, sd: float, seeds: int, digits: int) -> str:
    return f"{mean:.{digits}f} ± {sd:.{digits}f}" if seeds > 1 else f"{mean:.{digits}f}"


def markdown_table(rows: Sequence[Mapping[str, Any]]) -> str:
    """Mean ± sd over seeds (sample sd; a single run shows its value)."""
    lines = [
        "| env | row | part | seeds | mean reward | in-spec coverage | \\|dist err\\| mm "
        "| orient. err ° | PPO steps | train wall s | train CPU s |",
        "|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for s in summarize(rows):
        label = s.label + (f" {s.params}" if s.params else "")
        trained = bool(s.timesteps or s.train_wall_s)
        wall = f"{s.train_wall_s:.0f}" if trained else "-"
        cpu = f"{s.train_cpu_s:.0f}" if trained else "-"
        steps = f"{s.timesteps}" if trained else "-"
        lines.append(
            f"| {s.env} | {label} | {s.part} | {s.seeds} "
            f"| {_cell(s.mean['reward_mean'], s.sd['reward_mean'], s.seeds, 4)} "
            f"| {_cell(s.mean['in_spec_coverage'], s.sd['in_spec_coverage'], s.seeds, 3)} "
            f"| {_cell(s.mean['distance_error_mean_abs_mm'], s.sd['distance_error_mean_abs_mm'], s.seeds, 2)} "  # noqa: E501
            f"| {_cell(s.mean['orientation_error_mean_deg'], s.sd['orientation_error_mean_deg'], s.seeds, 2)} "  # noqa: E501
            f"| {steps} | {wall} | {cpu} |"
        )
    return "\n".join(lines) + "\n"


def write_tables(
    rows: Sequence[Mapping[str, Any]], out_dir: str | os.PathLike[str], stem: str = "sweep"
) -> tuple[Path, Path]:
    """`<stem>.csv` (one row per task and part) and `<stem>.md` (mean ± sd over seeds)."""
    csv_path = write_csv(rows, Path(out_dir) / f"{stem}.csv")
    md_path = Path(out_dir) / f"{stem}.md"
    md_path.write_text(markdown_table(rows))
    return csv_path, md_path
