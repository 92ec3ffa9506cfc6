"""What the paper's reward pays in the training env, per action source: the untrained PPO
policy (SB3's N(0, 1) around 0), a narrow spread around 0, `fixed`, `feedback`, those two
with N(0, 1) noise, and `feedback` holding the pitch (Δθ = 0: depth following alone). Per
source: mean per-step R_D, R_α, R_Δs and reward, episode length against the nominal steps,
the undiscounted return and the discounted return from the start G0 (γ 0.99), the fractions
truncated and lost, mean |D − W_d| and |α| (issue 22's evidence).

    python benchmarks/reward_sources.py [--episodes 24] [--start-offset 100,20]
        [--reward-distance-scale MM]

The env is `scanplan train`'s (the paper's recipe: training piece, 100-400 mm segments),
stepped one env at a time; episodes use reset seeds 1000, 1001, ... for every source.
"""

from __future__ import annotations

import argparse
import math

import numpy as np


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--episodes", type=int, default=24)
    ap.add_argument("--start-offset", default="0,0", help="MM,DEG as scanplan train's")
    ap.add_argument("--reward-distance-scale", type=float, default=None, help="MM, as train's")
    args = ap.parse_args()
    import torch

    from scanplan.planning.planners.feedback import FeedbackController
    from scanplan.rl.learn.config import recipe_config
    from scanplan.rl.learn.vec_env import make_env

    torch.set_num_threads(1)
    offset = tuple(float(v) for v in args.start_offset.split(","))
    cfg = recipe_config(
        "unused", start_offset=offset, reward_distance_scale=args.reward_distance_scale
    )
    env = make_env(cfg.parts, cfg.env)
    feedback = FeedbackController()
    rng = np.random.default_rng(0)
    narrow = np.exp([-2.0, -2.0, -4.0])

    def noise() -> np.ndarray:
        return rng.normal(0.0, 1.0, 3)

    sources = {
        "initial policy N(0,1)": lambda: np.clip(noise(), -1, 1),
        "mean 0, log_std -2,-2,-4": lambda: np.clip(noise() * narrow, -1, 1),
        "fixed": lambda: np.array([0.5, 0.0, 0.0]),
        "fixed + N(0,1)": lambda: np.clip(np.array([0.5, 0.0, 0.0]) + noise(), -1, 1),
        "feedback": lambda: feedback(env.dynamics),
        "feedback + N(0,1)": lambda: np.clip(feedback(env.dynamics) + noise(), -1, 1),
        "feedback, depth only": lambda: feedback(env.dynamics) * np.array([1.0, 1.0, 0.0]),
    }
    head = "R_D R_alpha R_ds R/step len nominal return G0 trunc lost |dD|mm |alpha|deg"
    print(f"{'source':26s} " + " ".join(f"{h:>8s}" for h in head.split()))
    for name, act in sources.items():
        rows = []
        for ep in range(args.episodes):
            env.reset(seed=1000 + ep)
            terms, rewards, dd, aa = [], [], [], []
            done = trunc = False
            info: dict = {}
            while not done:
                _, r, term, trunc, info = env.step(np.asarray(act(), dtype=np.float32))
                terms.append((info["r_d"], info["r_alpha"], info["r_delta_s"]))
                rewards.append(r)
                if np.isfinite(info["d_mm"]):
                    dd.append(abs(info["d_mm"] - env.scan_spec.working_distance_mm))
                    aa.append(abs(math.degrees(info["alpha_rad"])))
                done = term or trunc
            rew = np.array(rewards)
            rows.append(
                [
                    *np.mean(terms, axis=0),
                    rew.mean(),
                    len(rew),
                    env.nominal_steps,
                    rew.sum(),
                    float(np.sum(rew * 0.99 ** np.arange(len(rew)))),
                    float(trunc),
                    float(info["lost_penalty"] < 0),
                    np.mean(dd) if dd else np.nan,
                    np.mean(aa) if aa else np.nan,
                ]
            )
        m = np.nanmean(np.array(rows, dtype=float), axis=0)
        print(f"{name:26s} " + " ".join(f"{v:8.3f}" for v in m), flush=True)


if __name__ == "__main__":
    main()
