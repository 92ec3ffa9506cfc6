"""The training curves: the log's vocabulary (the paper's quantity names and the SB3 logger
keys they are recorded under), reading a log of either format, and the paper's figures.
"""

from __future__ import annotations

import csv
import math
import warnings
from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np

PROGRESS_CSV = "progress.csv"  # what SB3's CSV logger writes
# The paper's quantities (as columns of the old `training_log.csv`) -> SB3 logger keys.
# `scanplan/*` are recorded by `learn.callbacks.PaperQuantities`, the rest by SB3 itself.
LOG_KEYS: dict[str, str] = {
    "update": "scanplan/update",
    "timesteps": "time/total_timesteps",
    "episodes": "scanplan/episodes",
    "wall_time_s": "scanplan/wall_time_s",
    "ep_rew_mean": "rollout/ep_rew_mean",
    "ep_len_mean": "rollout/ep_len_mean",
    "reward_per_step": "scanplan/reward_per_step",
    "r_d": "scanplan/r_d",
    "r_alpha": "scanplan/r_alpha",
    "r_delta_s": "scanplan/r_delta_s",
    "lost_episodes": "scanplan/lost_episodes",
}
LOG_COLUMNS = tuple(LOG_KEYS)
CURVES = ("ep_rew_mean", "ep_len_mean", "reward_per_step", "r_d", "r_alpha", "r_delta_s")


def _number(text: str | None) -> float:
    return float(text) if text not in (None, "") else math.nan


def read_log(path: str | Path) -> dict[str, np.ndarray]:
    """A training log as {paper name: one value per update} (`LOG_COLUMNS`, NaN where a value
    was not logged, e.g. no episode finished yet): SB3's `progress.csv` or the old
    `training_log.csv` with the paper's names as columns (the shipped policy's)."""
    path = Path(path)
    with path.open(newline="") as f:
        reader = csv.DictReader(f)
        header = set(reader.fieldnames or ())
        rows = list(reader)
    if LOG_KEYS["timesteps"] in header:
        keys = LOG_KEYS
    elif "timesteps" in header:
        keys = {c: c for c in LOG_COLUMNS}
    else:
        raise ValueError(f"training log {path}: neither SB3's progress.csv nor a training_log.csv")
    try:
        return {c: np.array([_number(r.get(k)) for r in rows]) for c, k in keys.items()}
    except ValueError as exc:
        raise ValueError(f"training log {path}: {exc}") from None


def final_metrics(log: dict[str, np.ndarray], updates: int = 5) -> dict[str, float]:
    """The mean of each curve over the last `updates` updates (NaN entries skipped)."""
    final = {}
    for key in CURVES:
        tail = log[key][-updates:]
        tail = tail[np.isfinite(tail)]
        final[key] = float(tail.mean()) if tail.size else math.nan
    return final


def plot_training_curves(log_csv: str | Path, out_dir: str | Path) -> tuple[Path, ...]:
    """The paper's training figures: (a) mean episodic reward, (b) mean episode length,
    (c) normalized reward (per step); and the overall reward against R_D, R_α, R_Δs."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    log = read_log(log_csv)
    out = Path(out_dir)
    t = log["timesteps"]
    fig, axes = plt.subplots(1, 3, figsize=(13, 3.6))
    for ax, key, title in zip(
        axes,
        ("ep_rew_mean", "ep_len_mean", "reward_per_step"),
        ("(a) mean episodic reward", "(b) mean episode length", "(c) normalized reward"),
        strict=True,
    ):
        ax.plot(t, log[key], lw=1.2)
        ax.set_title(title)
        ax.set_xlabel("timesteps")
        ax.grid(alpha=0.3)
    fig.tight_layout()
    metrics_png = out / "training_metrics.png"
    fig.savefig(metrics_png, dpi=110)
    plt.close(fig)

    fig, ax = plt.subplots(figsize=(7, 4))
    labels = {"reward_per_step": "R", "r_d": "R_D", "r_alpha": "R_α", "r_delta_s": "R_Δs"}
    for key, label in labels.items():
        ax.plot(t, log[key], lw=1.4 if key == "reward_per_step" else 1.0, label=label)
    ax.set_xlabel("timesteps")
    ax.set_ylabel("mean reward per step")
    ax.set_title("overall and partial rewards during training")
    ax.grid(alpha=0.3)
    ax.legend()
    fig.tight_layout()
    rewards_png = out / "training_rewards.png"
    fig.savefig(rewards_png, dpi=110)
    plt.close(fig)
    return metrics_png, rewards_png


COMPARISON_PANELS = (
    ("ep_rew_mean", "(a) mean episodic reward"),
    ("ep_len_mean", "(b) mean episode length"),
    ("reward_per_step", "(c) normalized reward (per step)"),
    ("r_d", "R_D (distance)"),
    ("r_alpha", "R_α (orientation)"),
    ("r_delta_s", "R_Δs (spacing)"),
)


def _seed_band(logs: list[dict[str, np.ndarray]], key: str) -> tuple[np.ndarray, ...]:
    """(timesteps, mean, sd) of `key` over runs of one recipe, on the updates all of them
    logged (the same n_steps: the same timesteps); NaN where none has a value."""
    n = min(len(log["timesteps"]) for log in logs)
    values = np.stack([log[key][:n] for log in logs])
    seen = np.isfinite(values).any(axis=0)
    with np.errstate(invalid="ignore"), warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # an update no run logged: NaN
        mean, sd = np.nanmean(values, axis=0), np.nanstd(values, axis=0)
    return logs[0]["timesteps"][:n][seen], mean[seen], sd[seen]


def plot_training_comparison(
    logs: Mapping[str, str | Path | Sequence[str | Path]], out_png: str | Path
) -> Path:
    """The paper's training figures for several runs side by side: one panel per quantity
    (`COMPARISON_PANELS`), one line per run ({label: progress.csv or training_log.csv}),
    against PPO timesteps. A label given several logs (seeds of one recipe) is drawn as
    their mean with ±1 sd shaded."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.ticker import FuncFormatter

    if not logs:
        raise ValueError("plot_training_comparison: no log")
    read = {
        label: [read_log(p) for p in ([path] if isinstance(path, str | Path) else path)]
        for label, path in logs.items()
    }
    fig, axes = plt.subplots(2, 3, figsize=(14, 7.2))
    for ax, (key, title) in zip(axes.flat, COMPARISON_PANELS, strict=True):
        for label, runs in read.items():
            t, mean, sd = _seed_band(runs, key)
            (line,) = ax.plot(t, mean, lw=1.2, label=label)
            if len(runs) > 1:
                ax.fill_between(t, mean - sd, mean + sd, color=line.get_color(), alpha=0.2, lw=0)
        ax.set_title(title)
        ax.set_xlabel("PPO timesteps")
        ax.xaxis.set_major_formatter(FuncFormatter(lambda x, _: f"{x / 1000:g}k"))
        ax.grid(alpha=0.3)
    handles, labels = axes.flat[0].get_legend_handles_labels()
    fig.legend(handles, labels, loc="lower center", ncol=min(len(labels), 2), fontsize=9)
    fig.tight_layout(rect=(0, 0.04 + 0.03 * ((len(labels) - 1) // 2), 1, 1))
    out = Path(out_png)
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=110)
    plt.close(fig)
    return out
