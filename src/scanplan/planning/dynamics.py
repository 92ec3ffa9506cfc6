"""A sensor on one pass (SPEC §4, §5): `PassDynamics` holds its state on a Swath and the
profile it measured there, and takes an action to its next pose through the step model
(`step_model`); where a pass sees the part, and how many steps it gets.

The Gymnasium environment is a thin wrapper over `PassDynamics`; the rl and feedback planners
drive the same object with a controller.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from scanplan.core.quantities import (
    ScanSpec,
    StepLimits,
    advance,
    mean_distance,
    profile_angles,
    signed_alpha,
    signed_beta,
)
from scanplan.planning.step_model import (
    DEFAULT_PITCH_PIVOT,
    apply_step,
    check_pitch_pivot,
    limit_action,
    pitch_pivot_mm,
    progress_mm,
)
from scanplan.planning.swaths import Swath, frame_poses
from scanplan.sensor.profilometer import LineProfilometer, Profile, Scan
from scanplan.world.part import Part


@dataclass(frozen=True)
class PassGeometry:
    """Where a pass sees the part: advances along u (mm, from `swath.start_mm`) of the first
    and last stations whose fan hits it."""

    s_first_mm: float
    s_last_mm: float


def pass_geometry(
    part: Part, swath: Swath, spec: ScanSpec, step_mm: float = 2.0, min_hits: float = 0.1
) -> PassGeometry:
    """First/last stations of a pass at its nominal height, pitch 0, where the fan hits the
    part with at least `min_hits` x the most columns any station hits (the run-in over empty
    space has nothing to align to). Raises ValueError if the pass never sees the part."""
    s = np.arange(0.0, max(swath.length_mm, step_mm) + 1e-9, step_mm)
    probe = LineProfilometer(part, spec.sensor.without_noise().with_points(64))
    scan = probe.measure_many(swath.poses(s, 0 * s, 0 * s))
    hits = np.isfinite(scan.true_z_sensor).sum(axis=1)
    if hits.max() == 0:
        raise swath.sees_nothing(part)
    seen = np.flatnonzero(hits >= max(1, min_hits * hits.max()))
    return PassGeometry(float(s[seen[0]]), float(s[seen[-1]]))


def step_budget(length_mm: float, spec: ScanSpec) -> tuple[int, int]:
    """(nominal steps, step limit) of a pass of `length_mm`: one step per Δs_opt, and three
    times that (+10) before an episode is truncated."""
    nominal = int(math.ceil(length_mm / spec.delta_s_opt_mm))
    return nominal, 3 * nominal + 10


# ---- the sensor on a pass -------------------------------------------------------------------


@dataclass(frozen=True)
class Step:
    """A proposed step: the limited action (Δy mm, Δz mm, Δθ rad) and the state it leads to."""

    action_mm_rad: np.ndarray
    state: np.ndarray


class PassDynamics:
    """A sensor on one Swath: its state (s, h, θ), the profile it measured there, and D, α,
    Δs of that profile (`quantities`). `propose` an action (nothing changes), measure the
    proposed pose (`measure`, or many dynamics' poses in one batch), then `accept` it.

    sim: the simulated sensor; None for a sensor online (`online.OnlinePass`), whose
    profiles come in through `begin` and `accept` (nothing is measured here).
    rng: the Generator the simulator's noise draws from (an env's `np_random`).
    roll: the state is (s, h, θ, φ, l) and actions are 4-D (env v1); β is tracked too.
    align_iterations, start_pitch_max_rad: see `aligned_start`.
    pitch_pivot: where a pitch step turns (`step_model.PITCH_PIVOTS`, v0 only).
    """

    def __init__(
        self,
        part: Part,
        swath: Swath,
        spec: ScanSpec,
        sim: LineProfilometer | None,
        limits: StepLimits | None = None,
        rng: np.random.Generator | None = None,
        roll: bool = False,
        align_iterations: int = 4,
        start_pitch_max_rad: float = math.radians(15.0),
        pitch_pivot: str = DEFAULT_PITCH_PIVOT,
    ) -> None:
        self.part, self.swath, self.spec, self._sim = part, swath, spec, sim
        self.roll = roll
        self.pitch_pivot_mm = pitch_pivot_mm(check_pitch_pivot(pitch_pivot, roll), spec)
        self.beta_rad = self.tilt_rad = math.nan
        self.limits = limits or StepLimits()
        self.rng = rng
        self.align_iterations = align_iterations
        self.start_pitch_max_rad = start_pitch_max_rad

    # ---- measuring ----------------------------------------------------------------------
    @property
    def sim(self) -> LineProfilometer:
        """The simulated sensor (RuntimeError for a pass run online: nothing to simulate)."""
        if self._sim is None:
            raise RuntimeError("this pass runs online: its profiles come from the sensor")
        return self._sim

    def pose(self, state: np.ndarray | None = None) -> np.ndarray:
        """T_part_sensor at `state` (default: the current one)."""
        return self.swath.pose(*(self.state if state is None else state))

    def measure(self, state: np.ndarray) -> Profile:
        """The profile the sensor takes at (s, h, θ) on this swath."""
        return self.sim.measure(self.swath.pose(*state), self.rng)

    @staticmethod
    def d_alpha(profile: Profile) -> tuple[float, float]:
        """D and signed α of a profile (NaN with no valid point)."""
        d = float(mean_distance(profile.z_sensor, profile.valid))
        a = float(signed_alpha(profile.normals_part, profile.valid, profile.T_part_sensor))
        return d, a

    @staticmethod
    def beta(profile: Profile) -> float:
        """Signed cross angle β of a profile (the roll that aligns; NaN with no valid point)."""
        return float(signed_beta(profile.normals_part, profile.valid, profile.T_part_sensor))

    def _take(self, profile: Profile) -> None:
        """D, α (and with roll β and the beam angle) of the profile the sensor is now at,
        from one mean normal (`profile_angles`; the same numbers as `d_alpha`, `beta`)."""
        self.d_mm = float(mean_distance(profile.z_sensor, profile.valid))
        normals, valid, pose = profile.normals_part, profile.valid, profile.T_part_sensor
        if self.roll:
            alpha, beta, tilt = profile_angles(normals, valid, pose)
            self.alpha_rad, self.beta_rad, self.tilt_rad = float(alpha), float(beta), float(tilt)
        else:
            self.alpha_rad = float(signed_alpha(normals, valid, pose))

    def advance_to(self, profile: Profile) -> float:
        """Δs from the current profile to `profile` (NaN if no column is valid in both)."""
        prev = self.profile
        return float(
            advance(prev.points_part, prev.valid, profile.points_part, profile.valid, self.swath.u)
        )

    # ---- the pass -------------------------------------------------------------------------
    def start(self, state: np.ndarray) -> None:
        """Put the sensor at `state` and measure there."""
        self.begin(state, self.measure(np.asarray(state, dtype=np.float64)))

    def begin(self, state: np.ndarray, profile: Profile) -> None:
        """Put the sensor at `state`, where `profile` was measured (no Δs yet)."""
        self.state = np.asarray(state, dtype=np.float64)
        self.profile = profile
        self._take(profile)
        self.delta_s_mm = float("nan")

    def propose(self, action: np.ndarray) -> Step:
        """The limited step of `action` in [−1, 1]³ and the state it leads to."""
        limited = limit_action(
            action,
            self.d_mm,
            self.alpha_rad,
            self.limits,
            self.spec.working_distance_mm,
            self.beta_rad,
        )
        wd = self.spec.working_distance_mm
        return Step(limited, apply_step(self.state, limited, wd, self.pitch_pivot_mm))

    def accept(self, step: Step, profile: Profile, delta_s_mm: float | None = None) -> None:
        """Move to `step.state`, where `profile` was measured; `delta_s_mm`: its
        `advance_to`, if the caller has it already."""
        self.delta_s_mm = self.advance_to(profile) if delta_s_mm is None else delta_s_mm
        self.state, self.profile = step.state, profile
        self._take(profile)

    @staticmethod
    def poses_of(dyns: Sequence[PassDynamics], states: Sequence[np.ndarray]) -> np.ndarray:
        """(k, 4, 4) T_part_sensor of each of k sensors at its state (on its own swath), in
        one `frame_poses` call: what `pose` gives one by one."""
        x = np.stack(states)
        rolled = x.shape[1] == 5
        return frame_poses(
            np.stack([d.swath.start_mm for d in dyns]),
            np.stack([d.swath.u for d in dyns]),
            np.stack([d.swath.v for d in dyns]),
            x[:, 0],
            x[:, 1],
            x[:, 2],
            x[:, 3] if rolled else None,
            x[:, 4] if rolled else None,
        )

    @staticmethod
    def accept_many(dyns: Sequence[PassDynamics], steps: Sequence[Step], scan: Scan) -> None:
        """`accept` of k sensors' proposed steps measured together: row i of `scan` is
        `steps[i].state` of `dyns[i]` (`measure_many` of `poses_of`). Δs, D and α (with roll
        β and the beam angle) of all rows in one array call each: the numbers `accept` gives
        one by one, without k sets of small numpy calls (a training batch's main cost)."""
        roll = dyns[0].roll
        if any(d.roll != roll for d in dyns):
            raise ValueError("accept_many: all dynamics must be rolled or none")
        valid = scan.valid
        prev_points = np.stack([d.profile.points_part for d in dyns])
        prev_valid = np.stack([d.profile.valid for d in dyns])
        u = np.stack([d.swath.u for d in dyns])
        delta_s = advance(prev_points, prev_valid, scan.points_part, valid, u).tolist()
        d_mm = mean_distance(scan.z_sensor, valid).tolist()
        if roll:
            alpha, beta, tilt = profile_angles(scan.normals_part, valid, scan.poses)
            beta_l, tilt_l = beta.tolist(), tilt.tolist()
        else:
            alpha = signed_alpha(scan.normals_part, valid, scan.poses)
        alpha_l = alpha.tolist()
        for i, dyn in enumerate(dyns):
            dyn.state, dyn.profile = steps[i].state, scan.profile(i)
            dyn.delta_s_mm, dyn.d_mm, dyn.alpha_rad = delta_s[i], d_mm[i], alpha_l[i]
            if roll:
                dyn.beta_rad, dyn.tilt_rad = beta_l[i], tilt_l[i]

    @property
    def progress_mm(self) -> float:
        return progress_mm(self.state, self.spec.working_distance_mm)

    def aligned_start(self, s0: float, tries: int = 30, step_mm: float = 2.0) -> np.ndarray:
        """A start at advance s0 with D = W_d and α = 0: pitch by α, then move along the beam by
        D − W_d, a few times. A station in a camera shadow (behind a step) is skipped: try
        `step_mm` further on."""
        for k in range(tries):
            state = self._align_at(s0 + k * step_mm)
            if self.measure(state).valid.any():
                return state
        return self._align_at(s0)

    def _align_at(self, s0: float) -> np.ndarray:
        """Pitch by α and put the sensor W_d from the surface along the new beam, keeping the
        beam on the surface at advance s0 (so the scan starts at P_ini, not W_d·sinθ later)."""
        if self.roll:
            return self._align_rolled_at(s0)
        s, h, th = s0, 0.0, 0.0
        wd = self.spec.working_distance_mm
        for _ in range(self.align_iterations):
            prof = self.measure(np.array([s, h, th]))
            d, a = self.d_alpha(prof)
            if not np.isfinite(d):  # out of the depth window: use the first hits
                hit = np.isfinite(prof.true_z_sensor)
                if not hit.any():
                    break
                d, a = float(prof.true_z_sensor[hit].mean()), 0.0
            surface_h = h - d * math.cos(th)
            # At a part's very end the mean normal is its end wall or nose: do not start
            # facing it (the pass scans the top; the controller pitches on from there).
            th = float(np.clip(th + a, -self.start_pitch_max_rad, self.start_pitch_max_rad))
            s, h = s0 + wd * math.sin(th), surface_h + wd * math.cos(th)
        return np.array([s, h, th])

    def _align_rolled_at(self, s0: float) -> np.ndarray:
        """`_align_at` with roll: pitch by α, roll by β, the beam through the footprint at
        advance s0 on the swath's centre line, W_d away."""
        s, h, th, phi, lat = s0, 0.0, 0.0, 0.0, 0.0
        wd = self.spec.working_distance_mm
        for _ in range(self.align_iterations):
            prof = self.measure(np.array([s, h, th, phi, lat]))
            d, a = self.d_alpha(prof)
            b = self.beta(prof)
            if not np.isfinite(d):
                hit = np.isfinite(prof.true_z_sensor)
                if not hit.any():
                    break
                d, a, b = float(prof.true_z_sensor[hit].mean()), 0.0, 0.0
            surface_h = h - d * math.cos(phi) * math.cos(th)
            th = float(np.clip(th + a, -self.start_pitch_max_rad, self.start_pitch_max_rad))
            phi = float(np.clip(phi + b, -self.start_pitch_max_rad, self.start_pitch_max_rad))
            s = s0 + wd * math.sin(th)
            h = surface_h + wd * math.cos(th) * math.cos(phi)
            lat = -wd * math.cos(th) * math.sin(phi)
        return np.array([s, h, th, phi, lat])
