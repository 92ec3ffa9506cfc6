"""The training environments: `TrainConfig.env` turned into `SwathScanEnv` arguments (the one
place that does it), the batched vector env that measures many passes in one simulator call,
and `make_vec_env`, which wraps either vector env in SB3's episode monitor.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping, Sequence
from functools import partial
from typing import Any

import gymnasium as gym
import numpy as np
from stable_baselines3.common.vec_env import VecEnv, VecMonitor
from stable_baselines3.common.vec_env.base_vec_env import (
    VecEnvIndices,
    VecEnvObs,
    VecEnvStepReturn,
)

from scanplan.core.quantities import StepLimits
from scanplan.planning.dynamics import PassDynamics
from scanplan.rl.env import SwathScanEnv, random_part
from scanplan.rl.learn.config import TrainConfig
from scanplan.sensor.placed import measure_together
from scanplan.world.part import Part, load_part

_LIMIT_FIELDS = tuple(f.name for f in dataclasses.fields(StepLimits))


def swath_env_kwargs(env: Mapping[str, Any]) -> dict[str, Any]:
    """`TrainConfig.env` (as recorded in policy.json: step limits as numbers) as
    `SwathScanEnv` keyword arguments: the limits become one `StepLimits`, `segment_mm` a
    tuple (JSON gives a list)."""
    kwargs = {k: v for k, v in env.items() if k not in _LIMIT_FIELDS}
    limits = {k: env[k] for k in _LIMIT_FIELDS if env.get(k) is not None}
    if limits:
        kwargs["limits"] = StepLimits(**limits)
    if kwargs.get("segment_mm") is not None:
        kwargs["segment_mm"] = tuple(kwargs["segment_mm"])
    return kwargs


def make_env(parts: Sequence[str | Part], env: Mapping[str, Any]) -> SwathScanEnv:
    """One training env over `parts` (built-in names or mesh paths are loaded here)."""
    loaded = [load_part(p) if isinstance(p, str) else p for p in parts]
    return SwathScanEnv(parts=loaded, **swath_env_kwargs(env))


def _worker_env(parts: Sequence[str | Part], env: Mapping[str, Any]) -> SwathScanEnv:
    import torch

    torch.set_num_threads(1)  # per worker process: SB3's default here runs several times slower
    return make_env(parts, env)


def _shape(space: gym.Space[Any]) -> tuple[int, ...]:
    if space.shape is None:
        raise ValueError(f"{space} has no shape")
    return space.shape


class BatchedVecEnv(VecEnv):
    """n `SwathScanEnv`s stepped together in one process: the poses of all envs on the same
    part are measured in one `measure_many` call, so the simulator's per-call overhead is paid
    once per batch instead of once per env (several times faster than one env per process
    here). Action and observation shapes are the envs' own (v0 and v1 alike). Episode
    statistics are SB3's `VecMonitor`'s (see `make_vec_env`)."""

    def __init__(self, envs: Sequence[SwathScanEnv]) -> None:
        if not envs:
            raise ValueError("BatchedVecEnv needs at least one env")
        self.envs = list(envs)
        super().__init__(len(self.envs), self.envs[0].observation_space, envs[0].action_space)
        self.action_shape = _shape(self.action_space)
        self.obs_shape = _shape(self.observation_space)
        self._actions = np.zeros((self.num_envs, *self.action_shape), np.float32)

    def reset(self) -> VecEnvObs:
        obs = []
        for i, env in enumerate(self.envs):
            o, self.reset_infos[i] = env.reset(seed=self._seeds[i], options=self._options[i])
            obs.append(o)
        self._reset_seeds()
        self._reset_options()
        return np.stack(obs)

    def step_async(self, actions: np.ndarray) -> None:
        self._actions = np.asarray(actions)

    def step_wait(self) -> VecEnvStepReturn:
        groups: dict[int, list[int]] = {}
        proposed = []
        for i, (env, a) in enumerate(zip(self.envs, self._actions, strict=True)):
            proposed.append(env.dynamics.propose(a))
            # One ray engine per part measured (as built: perturbed episodes place it apart).
            groups.setdefault(id(env.dynamics.sim.part), []).append(i)
        terms: dict[str, np.ndarray] = {}
        for idx in groups.values():
            # The envs on one part as arrays: their poses, one measurement, D, α, Δs and the
            # reward terms in one call each (per-env numpy calls cost more than the rays).
            first = self.envs[idx[0]]
            dyns = [self.envs[i].dynamics for i in idx]
            steps = [proposed[i] for i in idx]
            scan = measure_together(
                [d.sim for d in dyns],
                PassDynamics.poses_of(dyns, [p.state for p in steps]),
                first.np_random,
            )
            PassDynamics.accept_many(dyns, steps, scan)
            for key, values in first.reward_terms(dyns).items():
                terms.setdefault(key, np.zeros(self.num_envs))[idx] = values
        obs = np.zeros((self.num_envs, *self.obs_shape), np.float32)
        rewards = np.zeros(self.num_envs, np.float32)
        dones = np.zeros(self.num_envs, bool)
        infos = []
        for i, env in enumerate(self.envs):
            mine = {key: values[i] for key, values in terms.items()}
            o, r, term, trunc, info = env.step_accepted(proposed[i], mine)
            if term or trunc:
                info["terminal_observation"] = o
                info["TimeLimit.truncated"] = trunc and not term
                o, self.reset_infos[i] = env.reset()
            obs[i], rewards[i], dones[i] = o, r, term or trunc
            infos.append(info)
        return obs, rewards, dones, infos

    def close(self) -> None:
        pass

    def get_attr(self, attr_name: str, indices: VecEnvIndices = None) -> list[Any]:
        return [getattr(self.envs[i], attr_name) for i in self._get_indices(indices)]

    def set_attr(self, attr_name: str, value: Any, indices: VecEnvIndices = None) -> None:
        for i in self._get_indices(indices):
            setattr(self.envs[i], attr_name, value)

    def env_method(
        self, method_name: str, *method_args: Any, indices: VecEnvIndices = None, **kwargs: Any
    ) -> list[Any]:
        return [
            getattr(self.envs[i], method_name)(*method_args, **kwargs)
            for i in self._get_indices(indices)
        ]

    def env_is_wrapped(
        self, wrapper_class: type[gym.Wrapper], indices: VecEnvIndices = None
    ) -> list[bool]:
        return [False for _ in self._get_indices(indices)]


def make_vec_env(config: TrainConfig) -> VecEnv:
    """`vec_env="batched"`: n_envs passes stepped together in this process (default, fastest
    here), in SB3's `VecMonitor`; `"subproc"`: one env per worker process (SB3's
    `make_vec_env`, which puts each env in SB3's `Monitor`: a `VecMonitor` on top would only
    overwrite the same statistics, with a warning)."""
    env = dict(config.env)
    if config.vec_env == "batched":
        # Parts are loaded and procedural parts drawn once and shared by all envs, so the
        # batch measures all envs on one part together.
        n_random = int(env.pop("procedural_parts", 0) or 0)
        parts = (
            *(load_part(p) if isinstance(p, str) else p for p in config.parts),
            *(random_part(np.random.default_rng([config.seed, k])) for k in range(n_random)),
        )
        vec: VecEnv = VecMonitor(
            BatchedVecEnv([make_env(parts, env) for _ in range(config.n_envs)])
        )
        vec.seed(config.seed)
        return vec
    from stable_baselines3.common.env_util import make_vec_env as sb3_make_vec_env
    from stable_baselines3.common.vec_env import DummyVecEnv, SubprocVecEnv

    return sb3_make_vec_env(
        partial(_worker_env, config.parts, env),
        n_envs=config.n_envs,
        seed=config.seed,
        vec_env_cls=SubprocVecEnv if config.n_envs > 1 else DummyVecEnv,
    )
