"""`train(TrainConfig)`: PPO (stable-baselines3) over the training vector env, the paper's
curves through SB3's logger, checkpoints and resuming (no pickle), and the actor exported as
a policy file (`scanplan.rl.policy`: safetensors + validated JSON).
"""

from __future__ import annotations

import csv
import math
import os
import shutil
import time
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np

from scanplan.core.context import scan_spec_record
from scanplan.core.files import atomic_directory
from scanplan.core.quantities import ScanSpec
from scanplan.judging.report.training import (
    CURVES,
    PROGRESS_CSV,
    final_metrics,
    plot_training_curves,
    read_log,
)
from scanplan.rl.learn.checkpoint import (
    CHECKPOINT_DIR,
    latest_checkpoint,
    load_checkpoint,
    restore,
    resumed_config,
    save_checkpoint,
)
from scanplan.rl.learn.config import TrainConfig, env_options
from scanplan.rl.policy import FORMAT as POLICY_FORMAT
from scanplan.rl.policy import (
    POLICY_JSON,
    WEIGHTS,
    Architecture,
    PolicyMeta,
    TrainingRecord,
    save_policy,
)

_STATS_WINDOW = 50  # episodes in SB3's rollout/ep_*_mean (the old log's window)


@dataclass(frozen=True)
class TrainResult:
    output_dir: Path
    policy_json: Path
    weights: Path
    log_csv: Path  # SB3's progress.csv: read it with `report.training.read_log`
    plots: tuple[Path, ...]
    timesteps: int
    wall_time_s: float
    final: dict[str, float]


def actor_state_dict(model: Any) -> dict[str, Any]:
    """The deterministic actor of an SB3 PPO MlpPolicy as `nn.Sequential` weights:
    hidden Linear layers (keys `<2i>.weight/bias`) then the action head."""
    linears = [m for m in model.policy.mlp_extractor.policy_net if hasattr(m, "weight")]
    linears.append(model.policy.action_net)
    state = {}
    for i, layer in enumerate(linears):
        state[f"{2 * i}.weight"] = layer.weight.detach().cpu().clone()
        state[f"{2 * i}.bias"] = layer.bias.detach().cpu().clone()
    return state


def policy_meta(model: Any, config: TrainConfig, training: dict[str, Any]) -> PolicyMeta:
    """The policy.json of a trained model (validated: see `scanplan.rl.policy`)."""
    return PolicyMeta(
        format=POLICY_FORMAT,
        weights=WEIGHTS,
        architecture=Architecture(
            obs_dim=int(model.observation_space.shape[0]),
            hidden=tuple(config.net_arch),
            activation=config.activation,  # type: ignore[arg-type]
            action_dim=int(model.action_space.shape[0]),
        ),
        env=env_options(config.env),
        training=TrainingRecord.model_validate(training),
        # The training env's: every run trains with the default sensor and parameters.
        scan_spec=scan_spec_record(ScanSpec()),
    )


def build_ppo(config: TrainConfig, vec: Any) -> Any:
    """PPO with the config's hyperparameters (SB3's names), on the CPU. A resumed run builds
    it exactly so, then loads the checkpoint."""
    import torch
    from stable_baselines3 import PPO

    activation = {"relu": torch.nn.ReLU, "tanh": torch.nn.Tanh}[config.activation]
    return PPO(
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
            "activation_fn": activation,
            # SB3's Adam (eps 1e-5) stepping all tensors at once: the same arithmetic (the same
            # weights bit for bit), a tenth less time per update than one tensor at a time.
            "optimizer_kwargs": {"eps": 1e-5, "foreach": True},
        },
        stats_window_size=_STATS_WINDOW,
        seed=config.seed,
        device="cpu",
        verbose=0,
    )


def _init_actor(model: Any, config: TrainConfig) -> None:
    import torch

    with torch.no_grad():
        # Per-action initial spread: a 1° pitch jump moves the footprint by W_d·Δθ ≈ 7 mm, so
        # exploring Δθ as widely as Δy ruins every Δs reward (capped at −1, no gradient).
        model.policy.log_std[:] = torch.as_tensor(config.log_std_init)
        # Start from the nominal advance: a policy that starts at Δy ≈ 0 first learns that
        # standing still at a flat start beats meeting the ramps ahead.
        if config.init_advance is not None:
            model.policy.action_net.bias[0] = config.init_advance


def _read_rows(path: Path) -> tuple[list[str], list[dict[str, str]]]:
    if not path.is_file():
        return [], []
    with path.open(newline="") as f:
        reader = csv.DictReader(f)
        return list(reader.fieldnames or ()), list(reader)


def _prepend_rows(path: Path, before: tuple[list[str], list[dict[str, str]]]) -> None:
    """SB3's CSV logger starts its file afresh: put the resumed run's earlier rows first."""
    old_keys, old_rows = before
    if not old_rows:
        return
    keys, rows = _read_rows(path)
    columns = old_keys + [k for k in keys if k not in old_keys]
    tmp = path.with_suffix(".csv.tmp")
    with tmp.open("w", newline="") as f:
        writer = csv.DictWriter(f, columns, restval="")
        writer.writeheader()
        writer.writerows(old_rows + rows)
    os.replace(tmp, path)


def _last(log: dict[str, np.ndarray], key: str) -> float:
    values = log[key][np.isfinite(log[key])]
    return float(values[-1]) if len(values) else 0.0


def train(config: TrainConfig) -> TrainResult:
    """Train PPO and write in `config.output_dir`: policy.json + policy.safetensors,
    progress.csv (SB3's logger; the paper's quantities under `report.training.LOG_KEYS`),
    the curve PNGs, and checkpoints/ (safetensors + JSON, for resuming only). Resuming takes
    the model's and envs' config from the checkpoint (`resumed_config`) and continues the
    count, the log and the checkpoints. Torch runs on one thread while training. The folder
    is replaced whole at the end; a failed run leaves the one there untouched (a new folder
    keeps its checkpoints, to resume from)."""
    ckpt = None
    if config.resume:
        ckpt = load_checkpoint(latest_checkpoint(config.resume))
        config = resumed_config(ckpt, config)
    env_options(config.env)  # fail before training, not when saving
    out = Path(config.output_dir)
    # Everything is written in a temporary sibling swapped in at the end: an interrupted run,
    # or a second run into the same folder, never leaves a policy beside another's log.
    with atomic_directory(out, replaceable=is_run_directory) as work:
        try:
            result = _train_into(config, ckpt, work, out)
        except BaseException:
            _keep_checkpoints(work, out)
            raise
    return result


def is_run_directory(path: Path) -> bool:
    """Whether `path` holds a training run's output (a policy, a log or checkpoints), so that
    a new run may replace it."""
    return any((path / name).exists() for name in (POLICY_JSON, PROGRESS_CSV, CHECKPOINT_DIR))


def _keep_checkpoints(work: Path, out: Path) -> None:
    """After a failed or interrupted run into a new folder, the folder with its checkpoints
    (to --resume from); a previous run's folder is left as it was."""
    if not out.exists() and any((work / CHECKPOINT_DIR).glob("*.json")):
        os.chmod(work, 0o777 & ~_umask())  # mkdtemp makes it private
        try:
            os.rename(work, out)
        except OSError:  # another run got there first: its folder stays as it is
            pass


def _umask() -> int:
    umask = os.umask(0)
    os.umask(umask)
    return umask


def _train_into(config: TrainConfig, ckpt: Any, work: Path, out: Path) -> TrainResult:
    """Train in `work`; the result names the files as they will be in `out`."""
    # Deferred: torch's threads are set, and stable-baselines3 loads, only when a run trains.
    import torch

    from scanplan.rl.learn.callbacks import PaperQuantities, make_logger
    from scanplan.rl.learn.teacher import behaviour_clone
    from scanplan.rl.learn.vec_env import make_vec_env

    log_csv = work / PROGRESS_CSV
    before: tuple[list[str], list[dict[str, str]]] = ([], [])
    wall_before, episodes_before = 0.0, 0
    if config.resume:
        resumed = Path(config.resume)
        previous = resumed / PROGRESS_CSV
        before = _read_rows(previous)
        if before[1]:
            log = read_log(previous)
            wall_before, episodes_before = _last(log, "wall_time_s"), int(_last(log, "episodes"))
        if resumed.resolve() == out.resolve() and (resumed / CHECKPOINT_DIR).is_dir():
            # The swap replaces the folder: its checkpoints carry over.
            shutil.copytree(resumed / CHECKPOINT_DIR, work / CHECKPOINT_DIR)
    threads = torch.get_num_threads()
    torch.set_num_threads(1)  # several times faster here than torch's default for a 64x64 MLP
    # The policy's Normal checks its arguments at every minibatch: the checks change no
    # number, and cost several percent of an update.
    validate = torch.distributions.Distribution._validate_args
    torch.distributions.Distribution.set_default_validate_args(False)
    start = time.perf_counter()
    bc_mse = math.nan
    vec = make_vec_env(config)
    try:
        model = build_ppo(config, vec)
        if ckpt is not None:
            restore(model, ckpt)
            vec.seed(config.seed + model.num_timesteps)
        else:
            _init_actor(model, config)
            if config.bc_samples > 0:
                bc_mse = behaviour_clone(model, vec, config.bc_samples, config.seed)
        remaining = config.total_timesteps - model.num_timesteps
        if remaining > 0:
            model.set_logger(make_logger(work))
            callback = PaperQuantities(config, work, start, wall_before, episodes_before)
            try:
                model.learn(
                    remaining,
                    callback=callback,
                    progress_bar=config.progress_bar,
                    reset_num_timesteps=False,
                )
            finally:
                model.logger.close()
                _prepend_rows(log_csv, before)
            save_checkpoint(model, config, work)
        elif before[1]:
            _prepend_rows(log_csv, before)  # nothing new: the log is the resumed one
    finally:
        vec.close()
        torch.set_num_threads(threads)
        torch.distributions.Distribution.set_default_validate_args(validate)
    wall = time.perf_counter() - start + wall_before
    final = (
        final_metrics(read_log(log_csv)) if log_csv.is_file() else dict.fromkeys(CURVES, math.nan)
    )
    cfg = {k: v for k, v in asdict(config).items() if k not in ("command", "resume")}
    training = {
        "command": config.command,
        "seed": config.seed,
        "timesteps": int(model.num_timesteps),
        "wall_time_s": round(wall, 1),
        "final_metrics_last5_updates": final,
        "behaviour_cloning_mse": bc_mse,
        "config": cfg,
        "machine_cores": os.cpu_count(),
    }
    meta = policy_meta(model, config, training)
    policy_json = save_policy(actor_state_dict(model), meta, work)
    plots = plot_training_curves(log_csv, work) if log_csv.is_file() else ()
    return TrainResult(
        output_dir=out,
        policy_json=out / policy_json.name,
        weights=out / meta.weights,
        log_csv=out / PROGRESS_CSV,
        plots=tuple(out / p.name for p in plots),
        timesteps=int(model.num_timesteps),
        wall_time_s=wall,
        final=final,
    )
