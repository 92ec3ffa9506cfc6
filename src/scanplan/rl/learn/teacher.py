"""Behaviour cloning (beyond the paper): a warm start that fits the PPO actor's mean action to
the feedback controller (`planners.feedback.FeedbackController`) before PPO begins.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from stable_baselines3.common.vec_env import VecEnv

from scanplan.planning.planners.feedback import FeedbackController
from scanplan.rl.learn.vec_env import BatchedVecEnv

# Exploration noise around the teacher, in action units: Δy, Δz, then angles (Δθ[, Δφ]).
_NOISE_LINEAR, _NOISE_ANGLE = 0.1, 0.03


def _teacher_actions(controller: FeedbackController, batched: BatchedVecEnv) -> np.ndarray:
    """The controller's action for each env (4-D on a v1 env: it rolls by β too)."""
    n = batched.action_shape[0]
    out = np.zeros((batched.num_envs, n))
    for i, env in enumerate(batched.envs):
        a = np.asarray(controller(env.dynamics), dtype=np.float64)[:n]
        out[i, : a.size] = a
    return out


def behaviour_clone(
    model: Any, vec: VecEnv, samples: int, seed: int, epochs: int = 20, lr: float = 1e-3
) -> float:
    """Fit the actor's mean to the feedback controller on `samples` states visited by it with
    a little action noise (so the states around its path are seen too); returns the final
    MSE. `vec` must be (a wrapper of) a `BatchedVecEnv`: the teacher reads each env's
    dynamics."""
    import torch

    batched = vec.unwrapped
    if not isinstance(batched, BatchedVecEnv):
        raise ValueError("behaviour cloning needs the batched vector env (vec_env 'batched')")
    controller = FeedbackController()
    n_actions = batched.action_shape[0]
    noise = np.full(n_actions, _NOISE_ANGLE)
    noise[:2] = _NOISE_LINEAR
    rng = np.random.default_rng(seed)
    obs = vec.reset()
    xs: list[np.ndarray] = []
    ys: list[np.ndarray] = []
    while len(xs) * vec.num_envs < samples:
        expert = _teacher_actions(controller, batched)
        xs.append(np.asarray(obs))
        ys.append(expert)
        act = np.clip(expert + rng.normal(0.0, 1.0, expert.shape) * noise, -1.0, 1.0)
        obs, _, _, _ = vec.step(act.astype(np.float32))
    x = torch.as_tensor(np.concatenate(xs), dtype=torch.float32)
    y = torch.as_tensor(np.concatenate(ys), dtype=torch.float32)
    policy = model.policy
    params = [*policy.mlp_extractor.policy_net.parameters(), *policy.action_net.parameters()]
    opt = torch.optim.Adam(params, lr=lr)
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
