"""The paper's RL environment (SPEC §5): one Boustrophedon pass per episode, PPO-ready.

`SwathScanEnv` owns the pass dynamics (Δy along u, Δz along the beam, Δθ about x_s, with the
paper's dynamic action limitation) and the observation; D, α, Δs and the reward come from
`quantities` and `reward`, the same functions as the planners' and the metrics'.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from scanplan.part import Part, part_from_mesh
from scanplan.quantities import advance, mean_distance, signed_alpha
from scanplan.reward import RewardConfig, reward_terms
from scanplan.sensor import LineProfilometer, Profile, SensorSpec
from scanplan.swaths import UP, Swath, plan_swaths

ENV_ID = "scanplan/SwathScan-v0"
OBS_LIMIT = 10.0  # every normalized observation is clipped to [-OBS_LIMIT, OBS_LIMIT]
LOOKAHEAD_MM = (10.0, 30.0, 60.0, 120.0, 200.0)
_LOOKAHEAD_COLUMNS = 16


@dataclass(frozen=True)
class PassGeometry:
    """Where a pass sees the part: advances along u (mm, from `swath.start_mm`) of the first
    and last stations whose fan hits it, and the height that puts the surface at W_d there."""

    s_first_mm: float
    s_last_mm: float


def pass_geometry(
    part: Part, swath: Swath, sensor: SensorSpec, step_mm: float = 2.0, min_hits: float = 0.1
) -> PassGeometry:
    """First/last stations of a pass at its nominal height, pitch 0, where the fan hits the
    part with at least `min_hits` x the most columns any station hits (the run-in over empty
    space has nothing to align to). Raises ValueError if the pass never sees the part."""
    s = np.arange(0.0, max(swath.length_mm, step_mm) + 1e-9, step_mm)
    probe = LineProfilometer(part, sensor.without_noise().with_points(64))
    scan = probe.measure_many(swath.poses(s, 0 * s, 0 * s))
    hits = np.isfinite(scan.true_z_sensor).sum(axis=1)
    if hits.max() == 0:
        raise ValueError(
            f"pass {swath.index} sees no surface of part {part.name}: "
            "the part is outside the sensor's reach"
        )
    seen = np.flatnonzero(hits >= max(1, min_hits * hits.max()))
    return PassGeometry(float(s[seen[0]]), float(s[seen[-1]]))


def random_part(rng: np.random.Generator) -> Part:
    """A procedural training part (beyond the paper): a heightfield strip of random flats,
    ramps (5-50°), steps, bumps and dips, with a random cross slope and waviness."""
    from scanplan.parts import heightfield_solid

    length = float(rng.uniform(500.0, 1100.0))
    width = float(rng.uniform(100.0, 400.0))
    xs = np.linspace(-length / 2, length / 2, int(length / 2) + 1)
    z = np.full_like(xs, 60.0)
    x = -length / 2 + 40.0
    while x < length / 2 - 40.0:
        seg = float(rng.uniform(40.0, 160.0))
        kind = rng.integers(4)
        after = xs >= x
        if kind == 0:  # ramp up or down to a new level
            dz = float(rng.uniform(5.0, 30.0) * rng.choice([-1, 1]))
            run = abs(dz) / math.tan(math.radians(rng.uniform(5.0, 50.0)))
            z += np.where(after, dz * np.clip((xs - x) / run, 0.0, 1.0), 0.0)
        elif kind == 1:  # step
            z += np.where(after, float(rng.uniform(-25.0, 25.0)), 0.0)
        elif kind == 2:  # bump or dip of half-width seg/2
            t = np.clip((xs - x) / seg, 0.0, 1.0)
            z += float(rng.uniform(-20.0, 20.0)) * np.sin(np.pi * t) ** 2
        x += seg
    z += float(rng.uniform(0.0, 8.0)) * np.sin(xs / float(rng.uniform(40.0, 200.0)))
    z = np.clip(z - z.min() + 10.0, 10.0, None)
    ys = np.linspace(-width / 2, width / 2, 9)
    cross = math.tan(math.radians(rng.uniform(-10.0, 10.0)))
    z_top = z[None, :] + cross * ys[:, None]
    z_top += 10.0 - z_top.min()
    return part_from_mesh(heightfield_solid(xs, ys, z_top), name="random")


class SwathScanEnv(gym.Env):
    """Optimize one Boustrophedon pass of a line profilometer, step by step (the paper's MDP).

    The sensor starts at the first station of the pass that sees the part, at the working
    distance and aligned (D = W_d, α = 0), and advances along the pass direction u.

    ## Action space

    `Box(-1, 1, (3,), float32)`, scaled by (Δy_max, Δz_max, Δθ_max), default (1 mm, 1 mm, 1°):

    | index | action | meaning                          | limitation (paper eqs. clipActionD/N) |
    |-------|--------|----------------------------------|---------------------------------------|
    | 0     | Δy     | along u                          | none                                  |
    | 1     | Δz     | along z_s, + = towards the part  | [0, max] if D ≥ W_d else [−max, 0]    |
    | 2     | Δθ     | pitch about x_s                  | [0, max] if α ≥ 0 else [−max, 0]      |

    Where the profile has no valid point, D and α are unknown: Δz and Δθ are held at 0.

    ## Observation space

    `Box(-10, 10, (k,), float32)`, every entry clipped to ±10:

    | entries        | observation                                  | normalization        |
    |----------------|----------------------------------------------|----------------------|
    | 3 if P         | P = (s, 0, h): advance, lateral, height of   | s / 1000 mm, 0,      |
    |                | the sensor from the episode's start (swath)  | h / (Z_r/2)          |
    | 1              | θ pitch                                      | θ / α_max            |
    | 1              | D mean profile distance                      | (D − W_d) / (Z_r/2)  |
    | 1              | α signed angle to the mean normal            | α / α_max            |
    | 1              | Δs advance since the previous profile        | Δs / Δs_opt          |
    | 10 if lookahead| CAD surface at 10/30/60/120/200 mm ahead:    | Δh / (Z_r/2),        |
    |                | height change, pitch that aligns minus θ     | Δθ / α_max           |

    No valid point: D and α read 0 (nominal), Δs reads 1. The paper's state is
    `use_position=True, lookahead=False` (k = 7).

    ## Reward

    `reward.reward_terms(D, α, Δs)`: R = w_D·R_D + w_α·R_α + w_Δs·R_Δs, each term in [−1, 0];
    the terms are in `info` (`r_d`, `r_alpha`, `r_delta_s`) with `d_mm`, `alpha_rad`,
    `delta_s_mm`. A pass that loses the surface for good (`lost_patience` consecutive profiles
    without a valid point) ends and is charged −1 for each of its remaining nominal steps
    (remaining length / Δs_opt, at most the steps left before truncation), in
    `info["lost_penalty"]`: ending early is never cheaper than finishing.

    ## Starting state

    A pass drawn from `parts` (the training piece by default) with a random lateral offset of
    up to ±`lateral_jitter_mm` and a random direction (±u); with `procedural_parts > 0`, a pool
    of that many `random_part`s joins the draw. With `segment_mm = (lo, hi)` the episode covers
    a random sub-segment of the pass of length U(lo, hi) mm starting at a random station: a
    whole pass is ~2000 steps at Δs_opt = 0.5 mm, so training on sub-segments gives PPO many
    more, shorter episodes per update. `segment_mm=None` runs whole passes (planning).

    ## Episode end

    Terminated when the scan's advance along u (the beam at W_d, `progress_mm`) passes the
    segment's end P_fin, or when the surface is lost for good; truncated after
    `max_episode_steps` (default 3 x nominal steps).

    ## Version history

    | version | change |
    |---------|--------|
    | v0      | the paper's state, action, reward; options: look-ahead, no-P state,    |
    |         | sub-segments of passes, procedural parts                                |
    """

    metadata: dict[str, Any] = {"render_modes": []}

    def __init__(
        self,
        parts: Sequence[Part] | None = None,
        swaths: Sequence[Swath] | None = None,
        sensor: SensorSpec | None = None,
        fan_points: int = 128,
        noise: bool = True,
        reward_config: RewardConfig | None = None,
        dy_max_mm: float = 1.0,
        dz_max_mm: float = 1.0,
        dtheta_max_rad: float = math.radians(1.0),
        use_position: bool = True,
        lookahead: bool = False,
        segment_mm: tuple[float, float] | None = (100.0, 400.0),
        lateral_jitter_mm: float = 150.0,
        random_direction: bool = True,
        procedural_parts: int = 0,
        lost_patience: int | None = 150,
        max_episode_steps: int | None = None,
        align_iterations: int = 4,
        start_pitch_max_rad: float = math.radians(15.0),
    ) -> None:
        """parts: parts to draw passes over (default: the training piece). swaths: fixed
        passes over `parts[0]` instead of drawn ones (planning; no jitter, no reversal)."""
        super().__init__()
        spec = sensor or SensorSpec()
        spec = spec.with_points(fan_points) if fan_points else spec
        self.sensor = spec if noise else spec.without_noise()
        wd = self.sensor.working_distance_mm
        self.reward_config = reward_config or RewardConfig(
            working_distance_mm=wd, z_range_mm=self.sensor.z_range_mm
        )
        self._fixed_parts = list(parts) if parts is not None else None
        self._fixed_swaths = list(swaths) if swaths is not None else None
        self.limits = np.array([dy_max_mm, dz_max_mm, dtheta_max_rad])
        self.use_position = use_position
        self.lookahead = lookahead
        self.segment_mm = segment_mm
        self.lateral_jitter_mm = lateral_jitter_mm
        self.random_direction = random_direction
        self.procedural_parts = procedural_parts
        self.lost_patience = lost_patience
        self.max_episode_steps = max_episode_steps
        self.align_iterations = align_iterations
        self.start_pitch_max_rad = start_pitch_max_rad
        n_obs = (3 if use_position else 0) + 4 + (2 * len(LOOKAHEAD_MM) if lookahead else 0)
        self.action_space = spaces.Box(-1.0, 1.0, (3,), np.float32)
        self.observation_space = spaces.Box(-OBS_LIMIT, OBS_LIMIT, (n_obs,), np.float32)
        self._pool: list[tuple[Part, list[Swath], LineProfilometer]] | None = None

    # ---- episode set-up -------------------------------------------------------------------
    def _build_pool(self) -> list[tuple[Part, list[Swath], LineProfilometer]]:
        if self._fixed_parts is not None:
            parts = self._fixed_parts
        else:
            from scanplan.part import load_part

            parts = [load_part("training-piece")]
        if self._fixed_swaths is not None:
            parts = parts[:1]
        else:
            parts = parts + [random_part(self.np_random) for _ in range(self.procedural_parts)]
        pool = []
        for i, part in enumerate(parts):
            swaths = (
                self._fixed_swaths
                if self._fixed_swaths is not None and i == 0
                else plan_swaths(part, self.sensor)
            )
            pool.append((part, list(swaths), LineProfilometer(part, self.sensor)))
        return pool

    def _draw_swath(self) -> tuple[Part, Swath, LineProfilometer]:
        assert self._pool is not None
        rng = self.np_random
        part, swaths, sim = self._pool[int(rng.integers(len(self._pool)))]
        swath = swaths[int(rng.integers(len(swaths)))]
        if self._fixed_swaths is not None:
            return part, swath, sim
        shift = float(rng.uniform(-1.0, 1.0)) * self.lateral_jitter_mm * swath.v
        start, end = swath.start_mm + shift, swath.end_mm + shift
        if self.random_direction and rng.random() < 0.5:
            return part, Swath(swath.index, end, start, -swath.u, -swath.v), sim
        return part, Swath(swath.index, start, end, swath.u, swath.v), sim

    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[np.ndarray, dict[str, Any]]:
        """options: {"swath": i} picks a fixed pass (planning) instead of a random one."""
        super().reset(seed=seed)
        if self._pool is None:
            self._pool = self._build_pool()
        if options and "swath" in options:
            part, swaths, sim = self._pool[0]
            self.part, self.swath, self.sim = part, swaths[int(options["swath"])], sim
        else:
            self.part, self.swath, self.sim = self._draw_swath()
        geo = pass_geometry(self.part, self.swath, self.sensor)
        s0, s1 = geo.s_first_mm, geo.s_last_mm
        if self.segment_mm is not None and s1 - s0 > self.segment_mm[0]:
            length = min(float(self.np_random.uniform(*self.segment_mm)), s1 - s0)
            s0 = float(self.np_random.uniform(s0, s1 - length))
            s1 = s0 + length
        self.s_end_mm = s1
        self.nominal_steps = int(math.ceil((s1 - s0) / self.reward_config.delta_s_opt_mm))
        self.step_limit = self.max_episode_steps or 3 * self.nominal_steps + 10
        self.state = self._aligned_start(s0)  # (s, h, theta)
        self.start_state = self.state.copy()
        self.profile = self.measure_at(self.state)
        self.d_mm, self.alpha_rad = self._d_alpha(self.profile)
        self.delta_s_mm = float("nan")
        self.steps = 0
        self.invalid_run = 0
        return self._observation(), {"d_mm": self.d_mm, "alpha_rad": self.alpha_rad}

    def measure_at(self, state: np.ndarray) -> Profile:
        """The profile the sensor takes at (s, h, θ) on the current swath."""
        return self.sim.measure(self.swath.pose(*state), self.np_random)

    def _d_alpha(self, profile: Profile) -> tuple[float, float]:
        d = float(mean_distance(profile.z_sensor, profile.valid))
        a = float(signed_alpha(profile.normals_part, profile.valid, profile.T_part_sensor))
        return d, a

    def _aligned_start(self, s0: float, tries: int = 30, step_mm: float = 2.0) -> np.ndarray:
        """Pitch by α, then move along the beam by D − W_d, a few times: D = W_d, α = 0. A
        station in a camera shadow (behind a step) is skipped: try `step_mm` further on."""
        for k in range(tries):
            state = self._align_at(s0 + k * step_mm)
            if self.measure_at(state).valid.any():
                return state
        return self._align_at(s0)

    def _align_at(self, s0: float) -> np.ndarray:
        """Pitch by α and put the sensor W_d from the surface along the new beam, keeping the
        beam on the surface at advance s0 (so the scan starts at P_ini, not W_d·sinθ later)."""
        s, h, th = s0, 0.0, 0.0
        wd = self.sensor.working_distance_mm
        for _ in range(self.align_iterations):
            prof = self.measure_at(np.array([s, h, th]))
            d, a = self._d_alpha(prof)
            if not np.isfinite(d):  # out of the depth window: use the first hits
                hit = np.isfinite(prof.true_z_sensor)
                if not hit.any():
                    break
                d, a = float(prof.true_z_sensor[hit].mean()), 0.0
            surface_h = h - d * math.cos(th)
            # At a part's very end the mean normal is its end wall or nose: do not start
            # facing it (the pass scans the top; the agent pitches on from there).
            th = float(np.clip(th + a, -self.start_pitch_max_rad, self.start_pitch_max_rad))
            s, h = s0 + wd * math.sin(th), surface_h + wd * math.cos(th)
        return np.array([s, h, th])

    # ---- dynamics -------------------------------------------------------------------------
    def limit_action(self, action: np.ndarray) -> np.ndarray:
        """Scale an action in [-1, 1]^3 to (Δy mm, Δz mm, Δθ rad) and apply the paper's
        dynamic action limitation from the current D and α (eqs. clipActionD/N)."""
        dy, dz, dth = np.clip(np.asarray(action, dtype=np.float64), -1.0, 1.0) * self.limits
        wd = self.sensor.working_distance_mm
        # No valid point: D and α are unknown, so neither sign is known to be safe: hold.
        lo_z, hi_z = (
            (0.0, 0.0)
            if not np.isfinite(self.d_mm)
            else ((0.0, self.limits[1]) if self.d_mm >= wd else (-self.limits[1], 0.0))
        )
        lo_t, hi_t = (
            (0.0, 0.0)
            if not np.isfinite(self.alpha_rad)
            else ((0.0, self.limits[2]) if self.alpha_rad >= 0 else (-self.limits[2], 0.0))
        )
        dz, dth = float(np.clip(dz, lo_z, hi_z)), float(np.clip(dth, lo_t, hi_t))
        return np.array([dy, dz, dth])

    @property
    def progress_mm(self) -> float:
        """Advance of the scan along u: where the beam meets the working distance (a pitched
        sensor looks W_d·sinθ behind itself; ending on the sensor's own advance would leave
        the end of the pass unscanned)."""
        s, _, th = self.state
        return float(s - self.sensor.working_distance_mm * math.sin(th))

    @staticmethod
    def apply_step(state: np.ndarray, step: np.ndarray) -> np.ndarray:
        """(s, h, θ) after moving Δy along u and Δz along the beam z_s = −sinθ u − cosθ w of
        the current pose, then pitching by Δθ (as `planners.geometric.step_actions`)."""
        s, h, th = state
        dy, dz, dth = step
        return np.array([s + dy - dz * math.sin(th), h - dz * math.cos(th), th + dth])

    def step(self, action: np.ndarray) -> tuple[np.ndarray, float, bool, bool, dict[str, Any]]:
        return self.finish_step(self.measure_at(self.begin_step(action)))

    def begin_step(self, action: np.ndarray) -> np.ndarray:
        """First half of `step`: apply the limited action; returns the new (s, h, θ).
        `BatchedSwathScanEnv` measures many envs' poses in one call between the halves."""
        self.limited = self.limit_action(action)
        self.state = self.apply_step(self.state, self.limited)
        return self.state

    def finish_step(self, profile: Profile) -> tuple[np.ndarray, float, bool, bool, dict[str, Any]]:
        """Second half of `step`, from the profile measured at the new pose."""
        prev, self.profile = self.profile, profile
        valid = profile.valid
        self.d_mm, self.alpha_rad = self._d_alpha(profile)
        self.delta_s_mm = float(
            advance(prev.points_part, prev.valid, profile.points_part, valid, self.swath.u)
        )
        terms = reward_terms(self.d_mm, self.alpha_rad, self.delta_s_mm, self.reward_config)
        reward = float(terms["reward"])
        self.steps += 1
        self.invalid_run = 0 if valid.any() else self.invalid_run + 1
        terminated = bool(self.progress_mm >= self.s_end_mm)
        truncated = self.steps >= self.step_limit
        lost_penalty = 0.0
        if (
            not terminated
            and self.lost_patience is not None
            and self.invalid_run >= self.lost_patience
        ):
            remaining = (self.s_end_mm - self.progress_mm) / self.reward_config.delta_s_opt_mm
            lost_penalty = -float(min(max(math.ceil(remaining), 0), self.step_limit - self.steps))
            terminated, truncated = True, False
        info = {
            "d_mm": self.d_mm,
            "alpha_rad": self.alpha_rad,
            "delta_s_mm": self.delta_s_mm,
            "r_d": float(terms["r_d"]),
            "r_alpha": float(terms["r_alpha"]),
            "r_delta_s": float(terms["r_delta_s"]),
            "lost_penalty": lost_penalty,
            "action_mm_rad": self.limited,
        }
        return self._observation(), reward + lost_penalty, terminated, truncated, info

    # ---- observation ----------------------------------------------------------------------
    def _observation(self) -> np.ndarray:
        cfg, half = self.reward_config, self.sensor.z_range_mm / 2
        s, h, th = self.state
        d = (self.d_mm - self.sensor.working_distance_mm) / half if np.isfinite(self.d_mm) else 0.0
        a = self.alpha_rad / cfg.alpha_max_rad if np.isfinite(self.alpha_rad) else 0.0
        ds = self.delta_s_mm / cfg.delta_s_opt_mm if np.isfinite(self.delta_s_mm) else 1.0
        obs = [th / cfg.alpha_max_rad, d, a, ds]
        if self.use_position:
            obs = [
                (s - self.start_state[0]) / 1000.0,
                0.0,
                (h - self.start_state[1]) / half,
                *obs,
            ]
        if self.lookahead:
            obs += list(self._lookahead_features())
        return np.clip(np.asarray(obs, dtype=np.float32), -OBS_LIMIT, OBS_LIMIT)

    def _lookahead_features(self) -> np.ndarray:
        """From the CAD (planning is offline): mean surface height and the pitch that faces
        its mean normal under the line at the footprint and at `LOOKAHEAD_MM` ahead, by
        vertical rays; returned relative to the footprint's height and to θ."""
        s, _, th = self.state
        sw = self.swath
        half_line = self.sensor.line_width_mm / 2
        foot = s - self.sensor.working_distance_mm * math.sin(th)
        ahead = foot + np.array((0.0, *LOOKAHEAD_MM))
        lateral = np.linspace(-half_line, half_line, _LOOKAHEAD_COLUMNS)
        top = float(self.part.bounds[1, 2]) + 10.0
        origins = sw.start_mm + ahead[:, None, None] * sw.u + lateral[None, :, None] * sw.v
        origins = origins.reshape(-1, 3)
        origins[:, 2] = top
        t, face = self.part.ray_engine.first_hit(origins, np.tile(-UP, (len(origins), 1)))
        hit = (face >= 0).reshape(len(ahead), -1)
        z = np.where(hit, top - t.reshape(hit.shape), 0.0).sum(1) / np.maximum(hit.sum(1), 1)
        n = np.zeros((len(origins), 3))
        n[face >= 0] = self.part.ray_engine.face_normals[face[face >= 0]]
        n *= np.where(n[:, 2:3] < 0, -1.0, 1.0)
        n_mean = n.reshape(*hit.shape, 3).sum(1)
        pitch = np.arctan2(n_mean @ sw.u, np.maximum(n_mean[:, 2], 1e-9))
        seen: np.ndarray = np.asarray(hit.any(axis=1))
        z = np.where(seen, z, z[0] if seen[0] else 0.0)
        pitch = np.where(seen, pitch, th)
        dh = (z[1:] - z[0]) / (self.sensor.z_range_mm / 2) if seen[0] else 0 * z[1:]
        dp = (pitch[1:] - th) / self.reward_config.alpha_max_rad
        return np.concatenate([dh, dp])


def register() -> None:
    if ENV_ID not in gym.registry:
        gym.register(id=ENV_ID, entry_point="scanplan.env:SwathScanEnv")


register()
