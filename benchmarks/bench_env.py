"""Environment steps/s: one SwathScanEnv, SB3's SubprocVecEnv over 2 processes, and the
batched in-process vector env used for training, side by side with the ratio to one env.

    python benchmarks/bench_env.py [--steps 3000]
"""

from __future__ import annotations

import argparse
import time

import numpy as np


def rate(step, n_envs: int, steps: int) -> float:
    step()  # warm up
    start = time.perf_counter()
    for _ in range(steps):
        step()
    return steps * n_envs / (time.perf_counter() - start)


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--steps", type=int, default=3000)
    args = parser.parse_args()

    from scanplan.rl.env import SwathScanEnv
    from scanplan.rl.learn.config import TrainConfig
    from scanplan.rl.learn.vec_env import make_vec_env

    action = np.array([0.5, 0.0, 0.0], np.float32)
    env = SwathScanEnv(noise=False)
    env.reset(seed=0)

    def single() -> None:
        _, _, term, trunc, _ = env.step(action)
        if term or trunc:
            env.reset()

    results = {"1 env": rate(single, 1, args.steps)}
    for name, vec_env, n in (("subproc x2", "subproc", 2), ("batched x16", "batched", 16)):
        vec = make_vec_env(TrainConfig(n_envs=n, vec_env=vec_env, env={"noise": False}))
        vec.reset()
        actions = np.tile(action, (n, 1))
        results[name] = rate(lambda v=vec, a=actions: v.step(a), n, max(args.steps // n, 50))
        vec.close()
    base = results["1 env"]
    print(f"{'environment':14s} {'steps/s':>9s} {'x 1 env':>8s}")
    for name, r in results.items():
        print(f"{name:14s} {r:9.0f} {r / base:8.2f}")


if __name__ == "__main__":
    main()
