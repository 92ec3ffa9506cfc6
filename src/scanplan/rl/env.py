"""The paper's RL environment (SPEC §5): one Boustrophedon pass per episode, PPO-ready.

A thin `gym.Env` over the pass step model (`dynamics.PassDynamics`): this module adds what
makes it an MDP — which pass an episode runs, the observation (`observation.observe`, also
what the rl planner feeds its policy), the reward (`reward.reward_terms`) and when an episode ends.
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Sequence
from dataclasses import replace
from typing import Any

import gymnasium as gym
import numpy as np
import trimesh
from gymnasium import spaces

from scanplan.core.quantities import TRAINING_FAN_POINTS, ScanSpec, StepLimits
from scanplan.core.reward import reward_terms
from scanplan.planning.dynamics import PassDynamics, pass_geometry, step_budget
from scanplan.planning.dynamics import Step as PassStep
from scanplan.planning.observation import OBS_LIMIT, observation_size, observe
from scanplan.planning.step_model import DEFAULT_PITCH_PIVOT, check_pitch_pivot
from scanplan.planning.swaths import Swath, plan_swaths
from scanplan.sensor.perturb import Perturbation, bounds_centre
from scanplan.sensor.placed import PlacedProfilometer
from scanplan.sensor.profilometer import LineProfilometer, Profile
from scanplan.world.part import Part, load_part, part_from_mesh
from scanplan.world.parts import heightfield_solid

ENV_ID = "scanplan/SwathScan-v0"
ENV_ID_ROLL = "scanplan/SwathScan-v1"
# The trainer's (learn.config) default too: 100-400 mm sub-segments of passes.
TRAINING_SEGMENT_MM = (100.0, 400.0)


def random_part(rng: np.random.Generator) -> Part:
    """A procedural training part (beyond the paper): a heightfield strip of random flats,
    ramps (5-50°), steps, bumps and dips, with a random cross slope and waviness."""
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
    distance and aligned (D = W_d, α = 0), and advances along the pass direction u. The step
    model is `self.dynamics` (`dynamics.PassDynamics`); this class adds the MDP around it.
    `roll=True` is env v1 (`scanplan/SwathScan-v1`, beyond the paper; rows marked v1 below).

    ## Action space

    `Box(-1, 1, (3,), float32)`, scaled by (Δy_max, Δz_max, Δθ_max), default (1 mm, 1 mm, 1°):

    | index | action | meaning                          | limitation (paper eqs. clipActionD/N) |
    |-------|--------|----------------------------------|---------------------------------------|
    | 0     | Δy     | along u                          | none                                  |
    | 1     | Δz     | along z_s, + = towards the part  | [0, max] if D ≥ W_d else [−max, 0]    |
    | 2     | Δθ     | pitch about x_s (`pitch_pivot`)  | [0, max] if α ≥ 0 else [−max, 0]      |
    | 3 (v1)| Δφ     | roll about u (≈ y_s), pivot W_d  | [0, max] if β ≥ 0 else [−max, 0]      |

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
    | 2 if v1        | φ roll; β the roll that aligns (SPEC §5)     | φ / α_max, β / α_max |
    | 10 if lookahead| CAD surface at 10/30/60/120/200 mm ahead:    | Δh / (Z_r/2),        |
    |                | height change, pitch that aligns minus θ     | Δθ / α_max           |

    No valid point: D and α read 0 (nominal), Δs reads 1. The paper's state is
    `use_position=True, lookahead=False` (k = 7).

    ## Reward

    `reward.reward_terms(D, α, Δs)`: R = w_D·R_D + w_α·R_α + w_Δs·R_Δs, each term in [−1, 0]
    (v1: R_α of the full angle between beam and mean normal instead of α);
    the terms are in `info` (`r_d`, `r_alpha`, `r_delta_s`) with `d_mm`, `alpha_rad`,
    `delta_s_mm`. A pass that loses the surface for good (`lost_patience` consecutive profiles
    without a valid point) ends and is charged −1 for each of its remaining nominal steps
    (remaining length / Δs_opt, at most the steps left before truncation), in
    `info["lost_penalty"]`: ending early is never cheaper than finishing.
    `reward_distance_scale_mm` (training, a deviation from the paper) sets the depth error at
    which R_D reaches −1 instead of the paper's Z_r/2.
    `pitch_pivot="footprint"` (beyond the paper, which does not say where the sensor frame's
    origin is) turns Δθ about the point W_d along the beam instead of the sensor's origin.

    ## Starting state

    A pass drawn from `parts` (the training piece by default) with a random lateral offset of
    up to ±`lateral_jitter_mm` and a random direction (±u); with `procedural_parts > 0`, a pool
    of that many `random_part`s joins the draw. With `segment_mm = (lo, hi)` the episode covers
    a random sub-segment of the pass of length U(lo, hi) mm starting at a random station: a
    whole pass is ~2000 steps at Δs_opt = 0.5 mm, so training on sub-segments gives PPO many
    more, shorter episodes per update. `segment_mm=None` runs whole passes (planning).
    The sensor starts aligned at W_d (the paper's start); with `start_offset_mm` /
    `start_pitch_deg` (training, beyond the paper) off it by a random depth and pitch error.
    With `perturb` (training, beyond the paper) the part each episode measures is drawn
    from that perturbation: as built and where it lies (the start aligned on it, as a
    closed loop starts on a cell), while the pass and any look-ahead are the CAD's.

    ## Episode end

    Terminated when the scan's advance along u (the beam at W_d, `progress_mm`) passes the
    segment's end P_fin, or when the surface is lost for good; truncated after
    `max_episode_steps` (default 3 x nominal steps).

    ## Version history

    | version | change |
    |---------|--------|
    | v0      | the paper's state, action, reward; options: look-ahead, no-P state,    |
    |         | sub-segments of passes, procedural parts, start offsets, R_D's scale,   |
    |         | the pitch pivot, perturbed parts                                        |
    | v1      | roll: Δφ (about the point W_d along the beam), φ and β observed,        |
    |         | orientation reward on the full angle; v0 unchanged                      |
    """

    metadata: dict[str, Any] = {"render_modes": []}

    def __init__(
        self,
        parts: Sequence[Part] | None = None,
        swaths: Sequence[Swath] | None = None,
        scan_spec: ScanSpec | None = None,
        fan_points: int = TRAINING_FAN_POINTS,
        noise: bool = True,
        limits: StepLimits | None = None,
        use_position: bool = True,
        lookahead: bool = False,
        segment_mm: tuple[float, float] | None = TRAINING_SEGMENT_MM,
        lateral_jitter_mm: float = 150.0,
        random_direction: bool = True,
        procedural_parts: int = 0,
        lost_patience: int | None = 150,
        max_episode_steps: int | None = None,
        roll: bool = False,
        start_offset_mm: float = 0.0,
        start_pitch_deg: float = 0.0,
        reward_distance_scale_mm: float | None = None,
        pitch_pivot: str = DEFAULT_PITCH_PIVOT,
        perturb: str | None = None,
    ) -> None:
        """parts: parts to draw passes over (default: the training piece). swaths: fixed
        passes over `parts[0]` instead of drawn ones (planning; no jitter, no reversal).
        scan_spec: the scan's parameters (sensor, Δs_opt, α_max, weights; `env.spec` is
        Gymnasium's); its sensor is sub-sampled to `fan_points` columns (0 = all) and made
        noiseless unless `noise`. roll: env v1 (4-D action with Δφ, φ and β observed,
        the orientation reward on the full angle between beam and mean normal).
        start_offset_mm, start_pitch_deg: an episode starts off the aligned pose by a depth
        error U(−a, a) mm along the beam and a pitch error U(−b, b)° about the footprint
        (beyond the paper, which is silent on the start; 0 = the aligned start, v0 only).
        reward_distance_scale_mm: R_D's scale (`ScanSpec.reward_distance_scale_mm`; None keeps
        the scan spec's, by default the paper's Z_r/2). pitch_pivot: where Δθ turns,
        "sensor" (its origin) or "footprint" (W_d along the beam; v0 only). perturb: the
        real part is not the CAD (training, beyond the paper): a `Perturbation` spec
        (placement, warp, scale; `training_perturbation`) drawn afresh each episode; the
        pass is the CAD's, every profile is measured on the part as built and placed."""
        super().__init__()
        self.perturbation = training_perturbation(perturb)
        if (start_offset_mm or start_pitch_deg) and roll:
            raise ValueError("start_offset_mm / start_pitch_deg: env v0 only")
        if not (0.0 <= start_offset_mm < 1e4 and 0.0 <= start_pitch_deg <= 60.0):
            raise ValueError(
                f"start offsets: depth {start_offset_mm} mm not in [0, 1e4) or pitch "
                f"{start_pitch_deg}° not in [0, 60]"
            )
        self.start_offset_mm = float(start_offset_mm)
        self.start_pitch_deg = float(start_pitch_deg)
        spec = scan_spec or ScanSpec()
        sensor = spec.sensor.with_points(fan_points) if fan_points else spec.sensor
        self.scan_spec = spec.with_sensor(sensor if noise else sensor.without_noise())
        if reward_distance_scale_mm is not None:
            self.scan_spec = replace(
                self.scan_spec, reward_distance_scale_mm=float(reward_distance_scale_mm)
            )
        self.limits = limits or StepLimits()
        self._fixed_parts = list(parts) if parts is not None else None
        self._fixed_swaths = list(swaths) if swaths is not None else None
        self.use_position = use_position
        self.lookahead = lookahead
        self.segment_mm = segment_mm
        self.lateral_jitter_mm = lateral_jitter_mm
        self.random_direction = random_direction
        self.procedural_parts = procedural_parts
        self.lost_patience = lost_patience
        self.max_episode_steps = max_episode_steps
        self.roll = roll
        self.pitch_pivot = check_pitch_pivot(pitch_pivot, roll)
        n_obs = observation_size(use_position, lookahead, roll)
        self.action_space = spaces.Box(-1.0, 1.0, (4 if roll else 3,), np.float32)
        self.observation_space = spaces.Box(-OBS_LIMIT, OBS_LIMIT, (n_obs,), np.float32)
        self._pool: list[tuple[Part, list[Swath], LineProfilometer]] | None = None

    # ---- episode set-up -------------------------------------------------------------------
    def _build_pool(self) -> list[tuple[Part, list[Swath], LineProfilometer]]:
        if self._fixed_parts is not None:
            parts = self._fixed_parts
        else:
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
                else plan_swaths(part, self.scan_spec.sensor)
            )
            pool.append((part, list(swaths), LineProfilometer(part, self.scan_spec.sensor)))
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
            swath = swaths[int(options["swath"])]
        else:
            part, swath, sim = self._draw_swath()
        sim = self._perturbed(part, sim)
        self.dynamics = dyn = PassDynamics(
            part,
            swath,
            self.scan_spec,
            sim,
            self.limits,
            self.np_random,
            roll=self.roll,
            pitch_pivot=self.pitch_pivot,
        )
        geo = pass_geometry(part, swath, self.scan_spec)
        s0, s1 = geo.s_first_mm, geo.s_last_mm
        if self.segment_mm is not None and s1 - s0 > self.segment_mm[0]:
            length = min(float(self.np_random.uniform(*self.segment_mm)), s1 - s0)
            s0 = float(self.np_random.uniform(s0, s1 - length))
            s1 = s0 + length
        self.s_end_mm = s1
        self.nominal_steps, limit = step_budget(s1 - s0, self.scan_spec)
        self.step_limit = self.max_episode_steps or limit
        dyn.start(self._offset_start(dyn, dyn.aligned_start(s0)))
        self.start_state = dyn.state.copy()
        self.steps = 0
        self.invalid_run = 0
        return self._observation(), {"d_mm": dyn.d_mm, "alpha_rad": dyn.alpha_rad}

    def _perturbed(self, part: Part, sim: LineProfilometer) -> LineProfilometer:
        """The sensor of this episode: on `part` as built, lying where this episode's draw
        of the perturbation puts it (`sim` itself without one). A part only placed keeps its
        ray engine (the batched env measures every episode on it in one call)."""
        if self.perturbation is None:
            return sim
        trial = self.perturbation.trial(int(self.np_random.integers(2**63)), 0)
        mesh = part.mesh
        vertices = np.asarray(mesh.vertices)
        centre = bounds_centre(vertices)
        built = part
        if self.perturbation.warp_mm or trial.scale:
            shape = trial.as_built(vertices, np.asarray(mesh.vertex_normals), centre)
            built = Part(
                trimesh.Trimesh(shape, mesh.faces, process=False),
                name=part.name,
                source=part.source,
            )
        return PlacedProfilometer(built, self.scan_spec.sensor, trial.T_part_placed(centre))

    def _offset_start(self, dyn: PassDynamics, aligned: np.ndarray) -> np.ndarray:
        """The aligned start moved by the random start offsets (if any): pitched about the
        footprint (W_d along the beam), then moved along the new beam; the aligned start
        itself where the offset pose sees nothing. No draw when both offsets are 0."""
        if not (self.start_offset_mm or self.start_pitch_deg):
            return aligned
        rng = self.np_random
        dz = float(rng.uniform(-1.0, 1.0)) * self.start_offset_mm
        dth = math.radians(float(rng.uniform(-1.0, 1.0)) * self.start_pitch_deg)
        s, h, th = (float(x) for x in aligned)
        wd = self.scan_spec.working_distance_mm
        foot_s, foot_h = s - wd * math.sin(th), h - wd * math.cos(th)
        th2 = th + dth
        s2 = foot_s + (wd - dz) * math.sin(th2)  # dz > 0: towards the part (D < W_d)
        h2 = foot_h + (wd - dz) * math.cos(th2)
        state = np.array([s2, h2, th2])
        return state if dyn.measure(state).valid.any() else aligned

    # ---- steps ----------------------------------------------------------------------------
    def step(self, action: np.ndarray) -> tuple[np.ndarray, float, bool, bool, dict[str, Any]]:
        proposed = self.dynamics.propose(action)
        return self.step_measured(proposed, self.dynamics.measure(proposed.state))

    def step_measured(
        self, proposed: PassStep, profile: Profile
    ) -> tuple[np.ndarray, float, bool, bool, dict[str, Any]]:
        """`step` with the profile at `proposed.state` measured by the caller: the batched
        vector env measures many envs' proposed poses (`dynamics.propose`) in one call."""
        self.dynamics.accept(proposed, profile)
        return self.step_accepted(proposed, self.reward_terms())

    def reward_terms(self, dyns: Sequence[PassDynamics] | None = None) -> dict[str, Any]:
        """`reward.reward_terms` of the sensor where it stands, or as arrays of several
        (`dyns`: a batch of this env's kind); v1 charges the full angle between beam and mean
        normal (what pitch and roll fix)."""
        if dyns is None:
            dyn = self.dynamics
            orientation = dyn.tilt_rad if self.roll else dyn.alpha_rad
            return reward_terms(dyn.d_mm, orientation, dyn.delta_s_mm, self.scan_spec)
        return reward_terms(
            [d.d_mm for d in dyns],
            [d.tilt_rad if self.roll else d.alpha_rad for d in dyns],
            [d.delta_s_mm for d in dyns],
            self.scan_spec,
        )

    def step_accepted(
        self, proposed: PassStep, terms: dict[str, Any]
    ) -> tuple[np.ndarray, float, bool, bool, dict[str, Any]]:
        """The rest of `step` once `self.dynamics` has accepted `proposed`: `terms` are its
        `reward_terms` (scalars, or this env's entries of a batch's arrays)."""
        dyn = self.dynamics
        reward = float(terms["reward"])
        self.steps += 1
        self.invalid_run = 0 if dyn.profile.valid.any() else self.invalid_run + 1
        terminated = bool(dyn.progress_mm >= self.s_end_mm)
        truncated = self.steps >= self.step_limit
        lost_penalty = 0.0
        if (
            not terminated
            and self.lost_patience is not None
            and self.invalid_run >= self.lost_patience
        ):
            remaining = (self.s_end_mm - dyn.progress_mm) / self.scan_spec.delta_s_opt_mm
            lost_penalty = -float(min(max(math.ceil(remaining), 0), self.step_limit - self.steps))
            terminated, truncated = True, False
        info = {
            "d_mm": dyn.d_mm,
            "alpha_rad": dyn.alpha_rad,
            "delta_s_mm": dyn.delta_s_mm,
            "r_d": float(terms["r_d"]),
            "r_alpha": float(terms["r_alpha"]),
            "r_delta_s": float(terms["r_delta_s"]),
            "lost_penalty": lost_penalty,
            "action_mm_rad": proposed.action_mm_rad,
        }
        if self.roll:
            info["beta_rad"], info["tilt_rad"] = dyn.beta_rad, dyn.tilt_rad
        return self._observation(), reward + lost_penalty, terminated, truncated, info

    def _observation(self) -> np.ndarray:
        return observe(self.dynamics, self.start_state, self.use_position, self.lookahead)


def training_perturbation(text: str | None) -> Perturbation | None:
    """The perturbation an env trains under (None: the CAD); ValueError (one line) for a
    path error, which a controller never sees (the robot flies it after the policy acts)."""
    if text is None:
        return None
    model = Perturbation.parse(text)
    if model.path_mm.size or model.path_deg.size:
        raise ValueError(
            "--perturb: a robot's path error is not seen by the controller it trains; "
            "train with place, warp and scale"
        )
    return None if model.is_zero else model


def register() -> None:
    # v0 stays the paper's MDP on purpose; Gymnasium's "v0 is out of date" note is noise here.
    warnings.filterwarnings("ignore", message=r".*SwathScan-v0 is out of date.*")
    if ENV_ID not in gym.registry:
        gym.register(id=ENV_ID, entry_point="scanplan.rl.env:SwathScanEnv")
    if ENV_ID_ROLL not in gym.registry:
        gym.register(
            id=ENV_ID_ROLL, entry_point="scanplan.rl.env:SwathScanEnv", kwargs={"roll": True}
        )


register()
