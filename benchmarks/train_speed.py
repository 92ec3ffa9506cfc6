"""Training steps/s of `scanplan train`'s configuration (the paper's PPO recipe, batched envs),
side by side with the same envs stepped bare (random actions, no policy, no update) in the
same run, and the wall time that projects for 1 M steps.

    python benchmarks/train_speed.py [--timesteps 20480] [--n-envs 16]

The steady rate is read from the run's log (wall time per update, first to last update), so
imports, building PPO and writing plots count once, in the projection's start-up term. CPU
seconds are printed too: on a shared machine they travel better than wall seconds.
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import numpy as np


def bare_env_rate(config, steps: int) -> tuple[float, float]:
    """(steps/s wall, steps/s CPU) of the training vec env alone."""
    from scanplan.rl.learn.vec_env import make_vec_env

    vec = make_vec_env(config)
    vec.reset()
    rng = np.random.default_rng(0)
    shape = (vec.num_envs, vec.action_space.shape[0])
    actions = [rng.uniform(-1.0, 1.0, shape).astype(np.float32) for _ in range(64)]
    for a in actions:
        a[:, 0] = np.abs(a[:, 0])  # advance, so that episodes end and reset as in training
    vec.step(actions[0])  # warm up
    n = max(steps // vec.num_envs, 1)
    wall, cpu = time.perf_counter(), time.process_time()
    for i in range(n):
        vec.step(actions[i % len(actions)])
    wall, cpu = time.perf_counter() - wall, time.process_time() - cpu
    vec.close()
    return n * vec.num_envs / wall, n * vec.num_envs / cpu


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--timesteps", type=int, default=20480)
    parser.add_argument("--n-envs", type=int, default=16)
    args = parser.parse_args()

    from scanplan.judging.report.training import read_log
    from scanplan.rl.learn.config import recipe_config
    from scanplan.rl.learn.train import train

    with tempfile.TemporaryDirectory() as tmp:
        config = recipe_config(
            str(Path(tmp) / "run"), timesteps=args.timesteps, n_envs=args.n_envs, progress_bar=False
        )
        env_wall, env_cpu = bare_env_rate(config, args.timesteps)
        wall, cpu = time.perf_counter(), time.process_time()
        result = train(config)
        wall, cpu = time.perf_counter() - wall, time.process_time() - cpu
        log = read_log(result.log_csv)
    steps, t = log["timesteps"], log["wall_time_s"]
    if len(steps) < 3:
        raise SystemExit("--timesteps: give at least 3 updates (3 x 2048 steps)")
    steady = (steps[-1] - steps[0]) / (t[-1] - t[0])  # from the end of the first update
    startup = wall - result.timesteps / steady
    train_cpu = result.timesteps / cpu  # start-up included: a lower bound of the steady rate
    per_update = config.n_envs * config.n_steps
    print(
        f"scanplan train's recipe: {config.n_envs} envs x n_steps {config.n_steps} = "
        f"{per_update} steps per update, batch {config.batch_size}, {config.n_epochs} epochs"
    )
    print(f"{'':30s} {'steps/s':>9s} {'x bare env':>11s}")
    print(f"{'bare batched env (wall)':30s} {env_wall:9.0f} {1.0:11.2f}")
    print(f"{'training, steady (wall)':30s} {steady:9.0f} {steady / env_wall:11.2f}")
    print(f"{'bare batched env (CPU)':30s} {env_cpu:9.0f} {1.0:11.2f}")
    print(f"{'training, with start-up (CPU)':30s} {train_cpu:9.0f} {train_cpu / env_cpu:11.2f}")
    projected = startup + 1_000_000 / steady
    print(
        f"{result.timesteps} steps in {wall:.1f} s wall ({cpu:.1f} s CPU), start-up "
        f"{startup:.1f} s; 1 M steps projected: {projected / 60:.1f} min wall"
    )


if __name__ == "__main__":
    main()
