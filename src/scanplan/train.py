"""PPO training of the pass agent (SPEC §5) with stable-baselines3, and the policy files.

`train(TrainConfig)` runs PPO over vectorized `SwathScanEnv`s (one process per core, torch on
one thread each), logs the paper's training curves per update (CSV + PNG), checkpoints, can
resume (`scanplan.learn.checkpoint`, no pickle), and exports the actor as a policy file
(`scanplan.policy.save_policy`: safetensors + JSON) that loads without unpickling anything.
"""

from __future__ import annotations

import csv
import math
import time
from collections import deque
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from scanplan.learn.checkpoint import (
    latest_checkpoint,
    load_checkpoint,
    restore,
    resumed_config,
    save_checkpoint,
)
from scanplan.policy import FORMAT as POLICY_FORMAT
from scanplan.policy import (
    WEIGHTS,
    Architecture,
    EnvOptions,
    PolicyMeta,
    TrainingRecord,
    save_policy,
)

LOG_CSV = "training_log.csv"
LOG_COLUMNS = (
    "update",
    "timesteps",
    "episodes",
    "wall_time_s",
    "ep_rew_mean",
    "ep_len_mean",
    "reward_per_step",
    "r_d",
    "r_alpha",
    "r_delta_s",
    "lost_episodes",
)


@dataclass
class TrainConfig:
    """Everything a training run needs. PPO fields keep stable-baselines3's names; their
    defaults are the paper's table. SB3's `n_steps` counts steps per env: 16 batched envs x
    128 = the paper's update every 2048 steps. `env` holds `SwathScanEnv` keyword arguments."""

    output_dir: str = "policy"
    parts: tuple[str, ...] = ("training-piece",)
    total_timesteps: int = 1_000_000
    seed: int = 0
    n_envs: int = 16
    vec_env: str = "batched"
    learning_rate: float = 3e-4
    n_steps: int = 128
    batch_size: int = 64
    gamma: float = 0.99
    clip_range: float = 0.2
    n_epochs: int = 10
    net_arch: tuple[int, ...] = (64, 64)
    activation: str = "relu"
    log_std_init: float | tuple[float, ...] = 0.0  # one per action: (Δy, Δz, Δθ)
    init_advance: float | None = None  # initial mean Δy action (0.5 = Δs_opt at Δy_max 1 mm)
    bc_samples: int = 0  # > 0: behaviour-clone the feedback controller on this many states first
    env: dict[str, Any] = field(
        default_factory=lambda: {
            "fan_points": 128,
            "noise": False,  # µm-scale noise does not move mm-scale D, α, Δs; 20 % faster
            "use_position": True,
            "lookahead": False,
            "segment_mm": (100.0, 400.0),
            "procedural_parts": 0,
        }
    )
    checkpoint_every_updates: int = 10
    resume: str | None = None
    progress_bar: bool = True
    command: str = ""


@dataclass(frozen=True)
class TrainResult:
    output_dir: Path
    policy_json: Path
    weights: Path
    log_csv: Path
    plots: tuple[Path, ...]
    timesteps: int
    wall_time_s: float
    final: dict[str, float]


# ---- environments -------------------------------------------------------------------------


def _make_env(parts: tuple[Any, ...], env_kwargs: dict[str, Any]):
    """A picklable factory for one worker process: torch on one thread (SB3's default on
    this machine runs several times slower), parts (names or `Part`s) loaded in the worker."""

    def factory():
        import torch

        from scanplan.env import SwathScanEnv
        from scanplan.part import load_part

        torch.set_num_threads(1)
        kwargs = dict(env_kwargs)
        if kwargs.get("segment_mm") is not None:
            kwargs["segment_mm"] = tuple(kwargs["segment_mm"])
        loaded = [load_part(p) if isinstance(p, str) else p for p in parts]
        return SwathScanEnv(parts=loaded, **kwargs)

    return factory


def _batched_class():
    from stable_baselines3.common.vec_env import VecEnv

    class BatchedSwathScanEnv(VecEnv):
        """n `SwathScanEnv`s stepped together in one process: the poses of all envs on the
        same part are measured in one `measure_many` call, so the simulator's per-call
        overhead is paid once per batch instead of once per env (several times faster than
        one env per process here). Adds SB3 Monitor's `episode` info itself."""

        def __init__(self, envs):
            self.envs = envs
            super().__init__(len(envs), envs[0].observation_space, envs[0].action_space)
            self._actions = np.zeros((len(envs), 3))
            self._ret = np.zeros(len(envs))
            self._len = np.zeros(len(envs), dtype=int)
            self._t0 = time.perf_counter()

        def reset(self):
            obs = []
            for i, env in enumerate(self.envs):
                o, self.reset_infos[i] = env.reset(seed=self._seeds[i], options=self._options[i])
                obs.append(o)
            self._reset_seeds()
            self._reset_options()
            self._ret[:], self._len[:] = 0.0, 0
            return np.stack(obs)

        def step_async(self, actions):
            self._actions = np.asarray(actions)

        def step_wait(self):
            groups: dict[int, list[int]] = {}
            proposed = []
            for i, (env, a) in enumerate(zip(self.envs, self._actions, strict=True)):
                proposed.append(env.dynamics.propose(a))
                groups.setdefault(id(env.dynamics.part), []).append(i)  # one sim per part
            profiles: list[Any] = [None] * self.num_envs
            for idx in groups.values():
                first = self.envs[idx[0]]
                poses = np.stack([self.envs[i].dynamics.pose(proposed[i].state) for i in idx])
                scan = first.dynamics.sim.measure_many(poses, first.np_random)
                for k, i in enumerate(idx):
                    profiles[i] = scan.profile(k)
            obs = np.zeros((self.num_envs, *self.observation_space.shape), np.float32)
            rewards = np.zeros(self.num_envs, np.float32)
            dones = np.zeros(self.num_envs, bool)
            infos = []
            for i, env in enumerate(self.envs):
                o, r, term, trunc, info = env.step_measured(proposed[i], profiles[i])
                self._ret[i] += r
                self._len[i] += 1
                if term or trunc:
                    info["terminal_observation"] = o
                    info["TimeLimit.truncated"] = trunc and not term
                    info["episode"] = {
                        "r": float(self._ret[i]),
                        "l": int(self._len[i]),
                        "t": round(time.perf_counter() - self._t0, 3),
                    }
                    self._ret[i], self._len[i] = 0.0, 0
                    o, self.reset_infos[i] = env.reset()
                obs[i], rewards[i], dones[i] = o, r, term or trunc
                infos.append(info)
            return obs, rewards, dones, infos

        def close(self):
            pass

        def get_attr(self, attr_name, indices=None):
            return [getattr(self.envs[i], attr_name) for i in self._get_indices(indices)]

        def set_attr(self, attr_name, value, indices=None):
            for i in self._get_indices(indices):
                setattr(self.envs[i], attr_name, value)

        def env_method(self, method_name, *args, indices=None, **kwargs):
            return [
                getattr(self.envs[i], method_name)(*args, **kwargs)
                for i in self._get_indices(indices)
            ]

        def env_is_wrapped(self, wrapper_class, indices=None):
            return [False for _ in self._get_indices(indices)]

    return BatchedSwathScanEnv


def make_vec_env(config: TrainConfig):
    """`vec_env="batched"`: n_envs passes stepped together in this process (default, fastest
    here); `"subproc"`: one env per worker process (SB3 SubprocVecEnv, Monitor-wrapped)."""
    if config.vec_env == "batched":
        # Procedural parts are drawn once and shared, so the batch still measures per part.
        from scanplan.env import random_part

        env_kwargs = dict(config.env)
        n_random = int(env_kwargs.pop("procedural_parts", 0) or 0)
        parts = (
            *config.parts,
            *(random_part(np.random.default_rng([config.seed, k])) for k in range(n_random)),
        )
        envs = [_make_env(parts, env_kwargs)() for _ in range(config.n_envs)]
        vec = _batched_class()(envs)
        vec.seed(config.seed)
        return vec
    from stable_baselines3.common.env_util import make_vec_env as sb3_make_vec_env
    from stable_baselines3.common.vec_env import DummyVecEnv, SubprocVecEnv

    return sb3_make_vec_env(
        _make_env(config.parts, config.env),
        n_envs=config.n_envs,
        seed=config.seed,
        vec_env_cls=SubprocVecEnv if config.n_envs > 1 else DummyVecEnv,
    )


# ---- logging ------------------------------------------------------------------------------


def _callback_class():
    from stable_baselines3.common.callbacks import BaseCallback

    class TrainingLog(BaseCallback):
        """Per update: the paper's curves (CSV); every k updates: a checkpoint."""

        def __init__(
            self, out: Path, every: int, start_time: float, wall_offset: float, config: TrainConfig
        ):
            super().__init__()
            self.out, self.every, self.config = out, every, config
            self.start_time, self.wall_offset = start_time, wall_offset
            self.episodes: deque[tuple[float, int]] = deque(maxlen=50)
            self.n_episodes, self.lost = 0, 0
            self.sums = np.zeros(4)
            self.count = 0
            self.update = 0

        def _on_training_start(self) -> None:
            path = self.out / LOG_CSV
            if path.exists():
                rows = list(csv.DictReader(path.open()))
                if rows:
                    self.update = int(rows[-1]["update"])
                    self.n_episodes = int(rows[-1]["episodes"])
            else:
                path.write_text(",".join(LOG_COLUMNS) + "\n")

        def _on_step(self) -> bool:
            for info in self.locals["infos"]:
                self.sums += [info["r_d"], info["r_alpha"], info["r_delta_s"], 1.0]
                self.count += 1
                if "episode" in info:  # from SB3's Monitor wrapper
                    self.episodes.append((info["episode"]["r"], info["episode"]["l"]))
                    self.n_episodes += 1
                    self.lost += info["lost_penalty"] < 0
            return True

        def _on_rollout_end(self) -> None:
            self.update += 1
            rew = self.locals["rollout_buffer"].rewards
            eps = np.array(self.episodes) if self.episodes else np.full((1, 2), np.nan)
            row = {
                "update": self.update,
                "timesteps": self.num_timesteps,
                "episodes": self.n_episodes,
                "wall_time_s": round(time.perf_counter() - self.start_time + self.wall_offset, 2),
                "ep_rew_mean": float(eps[:, 0].mean()),
                "ep_len_mean": float(eps[:, 1].mean()),
                "reward_per_step": float(rew.mean()),
                "r_d": self.sums[0] / max(self.count, 1),
                "r_alpha": self.sums[1] / max(self.count, 1),
                "r_delta_s": self.sums[2] / max(self.count, 1),
                "lost_episodes": self.lost,
            }
            with (self.out / LOG_CSV).open("a") as f:
                f.write(
                    ",".join(
                        f"{row[c]:.6g}" if isinstance(row[c], float) else str(row[c])
                        for c in LOG_COLUMNS
                    )
                    + "\n"
                )
            for key in ("reward_per_step", "r_d", "r_alpha", "r_delta_s"):
                self.logger.record(f"scanplan/{key}", row[key])  # TensorBoard, if installed
            self.sums[:] = 0
            self.count, self.lost = 0, 0
            if self.update % self.every == 0:
                save_checkpoint(self.model, self.config, self.out)

    return TrainingLog


def _tensorboard_dir(out: Path) -> str | None:
    """`out/tensorboard` if TensorBoard is installed (optional: `pip install tensorboard`)."""
    import importlib.util

    return str(out / "tensorboard") if importlib.util.find_spec("tensorboard") else None


def read_log(path: str | Path) -> dict[str, np.ndarray]:
    rows = list(csv.DictReader(Path(path).open()))
    return {c: np.array([float(r[c]) for r in rows]) for c in LOG_COLUMNS}


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


# ---- policy files -------------------------------------------------------------------------


def actor_state_dict(model) -> dict[str, Any]:
    """The deterministic actor of an SB3 PPO MlpPolicy as `nn.Sequential` weights:
    hidden Linear layers (keys `<2i>.weight/bias`) then the action head."""
    linears = [m for m in model.policy.mlp_extractor.policy_net if hasattr(m, "weight")]
    linears.append(model.policy.action_net)
    state = {}
    for i, layer in enumerate(linears):
        state[f"{2 * i}.weight"] = layer.weight.detach().cpu().clone()
        state[f"{2 * i}.bias"] = layer.bias.detach().cpu().clone()
    return state


def policy_meta(model, config: TrainConfig, training: dict[str, Any]) -> PolicyMeta:
    """The policy.json of a trained model (validated: see `scanplan.policy`)."""
    return PolicyMeta(
        format=POLICY_FORMAT,
        weights=WEIGHTS,
        architecture=Architecture(
            obs_dim=int(model.observation_space.shape[0]),
            hidden=tuple(config.net_arch),
            activation=config.activation,  # type: ignore[arg-type]
            action_dim=int(model.action_space.shape[0]),
        ),
        env=EnvOptions.from_env_kwargs(config.env),
        training=TrainingRecord.model_validate(training),
    )


# ---- behaviour-cloning warm start (beyond the paper) ---------------------------------------


def behaviour_clone(model, vec, samples: int, seed: int, epochs: int = 20) -> float:
    """Fit the actor's mean to the feedback controller (`planners.feedback`) on states visited
    by it with a little action noise (so the states around its path are seen too); returns
    the final MSE."""
    import torch

    from scanplan.planners.feedback import FeedbackController

    expert_action = FeedbackController()

    rng = np.random.default_rng(seed)
    obs = vec.reset()
    xs: list[np.ndarray] = []
    ys: list[np.ndarray] = []
    noise = np.array([0.1, 0.1, 0.03])
    while len(xs) * vec.num_envs < samples:
        expert = np.stack([expert_action(env.dynamics) for env in vec.envs])
        xs.append(obs)
        ys.append(expert)
        act = np.clip(expert + rng.normal(0.0, 1.0, expert.shape) * noise, -1.0, 1.0)
        obs, _, _, _ = vec.step(act.astype(np.float32))
    x = torch.as_tensor(np.concatenate(xs), dtype=torch.float32)
    y = torch.as_tensor(np.concatenate(ys), dtype=torch.float32)
    policy = model.policy
    params = [*policy.mlp_extractor.policy_net.parameters(), *policy.action_net.parameters()]
    opt = torch.optim.Adam(params, lr=1e-3)
    gen = torch.Generator().manual_seed(seed)
    loss = torch.tensor(0.0)
    for _ in range(epochs):
        for idx in torch.randperm(len(x), generator=gen).split(256):
            mean = policy.action_net(policy.mlp_extractor.forward_actor(x[idx]))
            loss = torch.nn.functional.mse_loss(mean, y[idx])
            opt.zero_grad()
            loss.backward()
            opt.step()
    model._last_obs = None  # SB3 resets the envs at learn()
    return float(loss.detach())


# ---- training -----------------------------------------------------------------------------


def train(config: TrainConfig) -> TrainResult:
    """Train PPO and write: policy.json + weights, training_log.csv, the curve PNGs,
    checkpoints/ (safetensors + JSON, for resuming only) in `config.output_dir`. Resuming
    takes the model's and envs' config from the checkpoint (`resumed_config`)."""
    import torch
    from stable_baselines3 import PPO

    if config.total_timesteps <= 0:
        raise ValueError(f"total timesteps must be > 0, got {config.total_timesteps}")
    if config.n_envs < 1:
        raise ValueError(f"n_envs must be >= 1, got {config.n_envs}")
    ckpt = None
    if config.resume:
        ckpt = load_checkpoint(latest_checkpoint(config.resume))
        config = resumed_config(ckpt, config)
    EnvOptions.from_env_kwargs(config.env)  # fail before training, not when saving
    torch.set_num_threads(1)
    out = Path(config.output_dir)
    out.mkdir(parents=True, exist_ok=True)
    (out / "checkpoints").mkdir(exist_ok=True)
    start = time.perf_counter()
    wall_offset = 0.0
    bc_mse = math.nan
    vec = make_vec_env(config)
    try:
        # A resumed run builds PPO exactly as a new one does, then loads the checkpoint.
        model = PPO(
            "MlpPolicy",
            vec,
            learning_rate=config.learning_rate,
            n_steps=config.n_steps,
            batch_size=config.batch_size,
            gamma=config.gamma,
            clip_range=config.clip_range,
            n_epochs=config.n_epochs,
            policy_kwargs={
                "net_arch": {"pi": list(config.net_arch), "vf": list(config.net_arch)},
                "activation_fn": {"relu": torch.nn.ReLU, "tanh": torch.nn.Tanh}[config.activation],
            },
            seed=config.seed,
            device="cpu",
            verbose=0,
            tensorboard_log=_tensorboard_dir(out),
        )
        if ckpt is not None:
            assert config.resume is not None
            resume = Path(config.resume)
            restore(model, ckpt)
            if resume.resolve() != out.resolve() and (resume / LOG_CSV).exists():
                (out / LOG_CSV).write_text((resume / LOG_CSV).read_text())
            if (out / LOG_CSV).exists():
                log = read_log(out / LOG_CSV)
                if len(log["wall_time_s"]):
                    wall_offset = float(log["wall_time_s"][-1])
            vec.seed(config.seed + model.num_timesteps)
        else:
            (out / LOG_CSV).unlink(missing_ok=True)
            # Per-action initial spread: a 1° pitch jump moves the footprint by W_d·Δθ ≈ 7 mm,
            # so exploring Δθ as widely as Δy ruins every Δs reward (capped at −1, no gradient).
            with torch.no_grad():
                model.policy.log_std[:] = torch.as_tensor(config.log_std_init)
                # Start from the nominal advance: a policy that starts at Δy ≈ 0 first learns
                # that standing still at a flat start beats meeting the ramps ahead.
                if config.init_advance is not None:
                    model.policy.action_net.bias[0] = config.init_advance  # type: ignore[operator]
            if config.bc_samples > 0:
                if config.vec_env != "batched":
                    raise ValueError("behaviour cloning needs the batched vector env")
                bc_mse = behaviour_clone(model, vec, config.bc_samples, config.seed)
        remaining = config.total_timesteps - model.num_timesteps
        if remaining > 0:
            callback = _callback_class()(
                out, config.checkpoint_every_updates, start, wall_offset, config
            )
            model.learn(
                remaining,
                callback=callback,
                progress_bar=config.progress_bar,
                reset_num_timesteps=False,
            )
            save_checkpoint(model, config, out)
    finally:
        vec.close()
    wall = time.perf_counter() - start + wall_offset
    log = read_log(out / LOG_CSV)
    tail = slice(-5, None)
    final = {
        k: float(np.mean(v[np.isfinite(v)])) if np.isfinite(v := log[k][tail]).any() else math.nan
        for k in ("ep_rew_mean", "ep_len_mean", "reward_per_step", "r_d", "r_alpha", "r_delta_s")
    }
    cfg = {k: v for k, v in asdict(config).items() if k not in ("command", "resume")}
    training = {
        "command": config.command,
        "seed": config.seed,
        "timesteps": int(model.num_timesteps),
        "wall_time_s": round(wall, 1),
        "final_metrics_last5_updates": final,
        "behaviour_cloning_mse": bc_mse,
        "config": cfg,
        "machine_cores": __import__("os").cpu_count(),
    }
    meta = policy_meta(model, config, training)
    policy_json = save_policy(actor_state_dict(model), meta, out)
    plots = plot_training_curves(out / LOG_CSV, out)
    return TrainResult(
        output_dir=out,
        policy_json=policy_json,
        weights=out / meta.weights,
        log_csv=out / LOG_CSV,
        plots=plots,
        timesteps=int(model.num_timesteps),
        wall_time_s=wall,
        final=final,
    )
