"""What a training run records: the paper's training quantities per update, written through
SB3's logger (CSV, and TensorBoard when installed), and a checkpoint every k updates.
"""

from __future__ import annotations

import importlib.util
import time
from pathlib import Path

import numpy as np
from stable_baselines3.common.callbacks import BaseCallback
from stable_baselines3.common.logger import Logger, configure

from scanplan.judging.report.training import LOG_KEYS
from scanplan.rl.learn.checkpoint import save_checkpoint
from scanplan.rl.learn.config import TrainConfig


def make_logger(out_dir: str | Path) -> Logger:
    """SB3's logger into `out_dir`: `progress.csv`, plus TensorBoard event files if
    TensorBoard is installed (optional: `pip install 'scanplan[tensorboard]'`)."""
    tensorboard = importlib.util.find_spec("tensorboard") is not None
    return configure(str(out_dir), ["csv"] + (["tensorboard"] if tensorboard else []))


class PaperQuantities(BaseCallback):
    """Per update (PPO rollout), into the model's logger under `report.training.LOG_KEYS`:
    reward per step, the mean partial rewards R_D, R_α, R_Δs over the rollout's steps, the
    episodes that ended lost, the update number, the episode count and the wall time (both
    continued from `episodes_before`, `wall_before_s` on resume). Mean episodic reward and
    length are SB3's own `rollout/ep_*_mean` (from `VecMonitor` / `Monitor`). After every
    `config.checkpoint_every_updates` updates, a checkpoint (`learn.checkpoint`)."""

    def __init__(
        self,
        config: TrainConfig,
        out_dir: str | Path,
        start_time: float,
        wall_before_s: float = 0.0,
        episodes_before: int = 0,
    ) -> None:
        super().__init__()
        self.config, self.out_dir = config, Path(out_dir)
        self.start_time, self.wall_before_s = start_time, wall_before_s
        self.episodes = episodes_before
        self.sums = np.zeros(3)  # R_D, R_α, R_Δs
        self.steps = 0
        self.lost = 0
        self._checkpoint_due = False

    def _on_rollout_start(self) -> None:
        # Here, after `train()`, the parameters include the update the checkpoint is named by.
        if self._checkpoint_due:
            save_checkpoint(self.model, self.config, self.out_dir)
            self._checkpoint_due = False

    def _on_step(self) -> bool:
        for info in self.locals["infos"]:
            self.sums += (info["r_d"], info["r_alpha"], info["r_delta_s"])
            self.steps += 1
            if "episode" in info:
                self.episodes += 1
                self.lost += info.get("lost_penalty", 0.0) < 0
        return True

    def _on_rollout_end(self) -> None:
        update = self.num_timesteps // (self.config.n_steps * self.config.n_envs)
        means = self.sums / max(self.steps, 1)
        wall = time.perf_counter() - self.start_time + self.wall_before_s
        values = {
            "update": update,
            "episodes": self.episodes,
            "wall_time_s": round(wall, 2),
            "reward_per_step": float(self.locals["rollout_buffer"].rewards.mean()),
            "r_d": float(means[0]),
            "r_alpha": float(means[1]),
            "r_delta_s": float(means[2]),
            "lost_episodes": self.lost,
        }
        for name, value in values.items():
            self.logger.record(LOG_KEYS[name], value)
        self.sums[:] = 0.0
        self.steps, self.lost = 0, 0
        self._checkpoint_due = update % self.config.checkpoint_every_updates == 0
