"""Issue 13's ablation: does the agent learn more than its teacher? Rows (each trained row
over several seeds, as Dask tasks of `scanplan.rl.learn.sweep`), evaluated on parts never used
in training (door, drone and the real car door and quadrotor when present):

  feedback        the proportional controller as a planner (the BC teacher), no training
  BC only         behaviour cloning of that controller, 0 PPO steps
  BC + PPO        the shipped recipe (`policies/default/policy.json`)
  pure PPO        the paper's state and SB3's defaults, on the training piece only, at
                  budgets that fit this machine (the paper's 1M-3M steps do not)
  geometric       the model-based planner (sees the CAD), no training
  shipped policy  the policy file in the repository (seed 0 of BC + PPO, trained earlier)

for env v0 (the paper's) and v1 (with roll). Prints the Markdown table and writes
`ablation.csv` / `ablation.md` into --out; --readme writes the table into the shipped
policy's README between its ablation markers.

Run: nice -n 10 .venv/bin/python benchmarks/ablation.py --out /tmp/ablation [--seeds 0,1,2]
       [--long] [--bc-only-v1] [--variant lookahead|more-ppo] [--workers 2] [--scheduler tcp://HOST:8786]
       [--readme] [--figure docs/training_comparison.png]
"""

from __future__ import annotations

import argparse
import shlex
import sys
from pathlib import Path
from typing import Any

from scanplan.judging.report.training import plot_training_comparison
from scanplan.rl.learn.config import recipe_config
from scanplan.rl.learn.sweep import (
    EvalPart,
    SweepTask,
    connect,
    grid_tasks,
    markdown_table,
    run_sweep,
    summarize,
    write_tables,
)

REAL_PARTS = {  # file in ../shared/parts -> units
    "vito_left_car_door.obj": "m",
    "tum_ardrone_quadrotor_4.stl": "m",
}
SHIPPED = {  # the shipped recipe (policies/default/policy.json)
    "state": "no-position",
    "procedural": 8,
    "bc_samples": 60_000,
    "timesteps": 61_440,
    "log_std_init": (-2.0, -2.0, -4.0),
}
PAPER = {"state": "paper"}  # the paper's state, SB3's defaults, the training piece
VARIANTS = {"lookahead": "BC + PPO, look-ahead state", "more-ppo": "BC + PPO 205k"}
README = Path(__file__).resolve().parents[1] / "src/scanplan/policies/default/README.md"
FIGURE_SHIPPED = (
    "shipped: BC warm start (not in the x axis) + PPO, no-position state, procedural parts, seed 0"
)
FIGURE_FAITHFUL = (
    "faithful: pure PPO, the paper's state and SB3 defaults, training piece only, seed 0"
)
BEGIN, END = "<!-- ablation:begin -->", "<!-- ablation:end -->"


def train_options(recipe: dict[str, Any], env: str) -> str:
    """The `scanplan train` options of a recipe (what a row's runs are)."""
    words = [f"--env {env}"] if env == "v1" else []
    for key, value in recipe.items():
        flag = "--" + key.replace("_", "-")
        if isinstance(value, tuple):
            words.append(f"{flag}={','.join(f'{v:g}' for v in value)}")
        else:
            words.append(f"{flag} {value}")
    return " ".join(words)


def rows(args: argparse.Namespace) -> tuple[list[SweepTask], list[tuple[str, str, str]]]:
    """The tasks, and (env, row, train options) for the table's legend."""
    seeds = [int(s) for s in args.seeds.split(",")]
    runs = Path(args.out) / "runs"
    tasks: list[SweepTask] = []
    legend: list[tuple[str, str, str]] = []

    def trained(label: str, env: str, recipe: dict[str, Any]) -> None:
        recipe = dict(recipe)
        if env == "v1" and "log_std_init" in recipe:
            recipe["log_std_init"] = (*recipe["log_std_init"], recipe["log_std_init"][-1])
        base = recipe_config(str(runs), env_version=env, progress_bar=False, **recipe)
        tasks.extend(grid_tasks(f"{label}", base, runs / env, seeds))
        legend.append((env, label, train_options(recipe, env)))

    for env in ("v0", "v1"):
        roll = env == "v1"
        tasks.append(SweepTask("feedback", planner="feedback", roll=roll))
        if env == "v0" or args.bc_only_v1:
            trained("BC only", env, SHIPPED | {"timesteps": 0})
        trained("BC + PPO", env, SHIPPED)
        if env == "v0":
            tasks.append(SweepTask("shipped policy", planner="rl"))
            trained("pure PPO 61k, paper's state", env, PAPER | {"timesteps": 61_440})
            if args.long:
                trained("pure PPO 205k, paper's state", env, PAPER | {"timesteps": 204_800})
            if args.variant == "lookahead":
                trained(VARIANTS["lookahead"], env, SHIPPED | {"state": "lookahead"})
            elif args.variant == "more-ppo":
                trained(VARIANTS["more-ppo"], env, SHIPPED | {"timesteps": 204_800})
        tasks.append(SweepTask("geometric", planner="geometric", roll=roll))
    return tasks, legend


def eval_parts(shared: Path) -> tuple[list[EvalPart], list[str]]:
    parts = [EvalPart.parse("door"), EvalPart.parse("drone")]
    missing = []
    for name, units in REAL_PARTS.items():
        path = shared / name
        if path.is_file():
            parts.append(EvalPart(path.stem, str(path), units))
        else:
            missing.append(str(path))
    return parts, missing


def verdict(table_rows: list[dict[str, Any]], env: str, row: str) -> list[str]:
    """Per part: does `row` beat feedback and geometric on mean reward by more than its seed
    spread (mean − sd above the baseline)?"""
    by = {(s.env, s.label, s.part): s for s in summarize(table_rows)}
    lines = []
    for (e, label, part), s in by.items():
        if e != env or label != row:
            continue
        out = []
        for baseline in ("feedback", "geometric"):
            b = by.get((env, baseline, part))
            if b is None:
                continue
            m, sd = s.mean["reward_mean"], s.sd["reward_mean"]
            d = m - b.mean["reward_mean"]
            if d > sd:
                word = "beats"
            elif d < -sd:
                word = "is behind (beyond the seed sd)"
            else:
                word = f"does not beat ({'ahead' if d > 0 else 'behind'} within the seed sd)"
            out.append(f"{word} {baseline}: {d:+.4f}, seed sd {sd:.4f}")
        lines.append(f"- {env} {part}: {row} " + "; ".join(out))
    return lines


def write_readme(text: str) -> None:
    old = README.read_text()
    if BEGIN in old and END in old:
        head, rest = old.split(BEGIN, 1)
        tail = rest.split(END, 1)[1]
        new = f"{head}{BEGIN}\n{text}{END}{tail}"
    else:
        new = f"{old.rstrip()}\n\n{BEGIN}\n{text}{END}\n"
    README.write_text(new)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", default="/tmp/ablation")
    parser.add_argument("--seeds", default="0,1,2")
    parser.add_argument("--long", action="store_true", help="also pure PPO at 205k steps")
    parser.add_argument("--bc-only-v1", action="store_true", help="also BC only on v1")
    parser.add_argument("--variant", choices=("lookahead", "more-ppo"), default=None)
    parser.add_argument("--shared", default=str(Path(__file__).resolve().parents[2] / "shared"))
    parser.add_argument("--workers", type=int, default=None)
    parser.add_argument("--scheduler", default=None)
    parser.add_argument("--no-reuse", action="store_true", help="retrain finished runs")
    parser.add_argument("--readme", action="store_true", help="write the policy README table")
    parser.add_argument("--figure", default=None, help="PNG: shipped vs faithful training curves")
    args = parser.parse_args()

    tasks, legend = rows(args)
    parts, missing = eval_parts(Path(args.shared) / "parts")
    for path in missing:
        print(f"skipped (missing): {path}", file=sys.stderr)
    with connect(args.scheduler, args.workers) as client:
        done = run_sweep(
            tasks,
            parts,
            client,
            on_done=lambda r: print(
                f"done: {r[0]['env']} {r[0]['label']} seed {r[0]['seed']} "
                f"(train {r[0]['train_wall_s']:.0f} s wall, {r[0]['train_cpu_s']:.0f} s CPU)",
                file=sys.stderr,
                flush=True,
            ),
            reuse=not args.no_reuse,
        )
    write_tables(done, args.out, "ablation")
    command = shlex.join(["python", "benchmarks/ablation.py", *sys.argv[1:]])
    cpu_total = sum(float(r["train_cpu_s"]) for r in done if r["part"] == parts[0].name)
    text = [
        f"Produced by `{command}` (seeds {args.seeds} per trained row; {len(parts)} unseen "
        f"parts; `metrics.evaluate` at 512 columns; training CPU in all {cpu_total / 60:.1f} min).",
        "",
        "Rows (the `scanplan train` options of each trained row):",
        "",
        *(f"- {env} **{label}**: `{opts}`" for env, label, opts in legend),
        "",
        markdown_table(done),
        "Verdict per part, trained rows against the teacher (feedback) and the model-based "
        "planner (geometric) on mean reward (beats = mean − baseline > seed sd):",
        "",
        *verdict(done, "v0", "BC + PPO"),
        *verdict(done, "v1", "BC + PPO"),
        *(verdict(done, "v0", VARIANTS[args.variant]) if args.variant else []),
        "",
    ]
    report = "\n".join(text)
    print(report)
    if args.figure:
        faithful = sorted(Path(args.out, "runs", "v0").glob("pure-ppo-*-s0/progress.csv"))
        if faithful:  # the longest faithful run (205k with --long) beside the shipped one
            faithful.sort(key=lambda p: len(p.read_text().splitlines()))
            logs = {
                FIGURE_SHIPPED: README.parent / "training_log.csv",
                FIGURE_FAITHFUL: faithful[-1],
            }
            print(f"-> {plot_training_comparison(logs, args.figure)} ({faithful[-1].parent.name})")
    if args.readme:
        write_readme(report)


if __name__ == "__main__":
    main()
