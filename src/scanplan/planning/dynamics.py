"""The pass step model (SPEC §4, §5): a sensor on a Swath, and how an action becomes its next
pose under the per-step limits and the paper's action limitation.

State (s, h, θ): advance along u and height above the swath's start (mm), pitch about x_s
(rad). A step (Δy, Δz, Δθ) moves Δy along u and Δz along the beam z_s = −sinθ·u − cosθ·w of
the pose it starts from, then pitches by Δθ. With roll (beyond the paper, env v1) the state is
(s, h, θ, φ, l) — roll about the scan direction u (applied before the pitch, so it is the
roll about y_s of SPEC §1 when θ = 0) and the sensor's lateral offset along v — and a step
(Δy, Δz, Δθ, Δφ) also rolls by Δφ, about the point W_d along the beam (the line's centre at
the working distance, where a robot's TCP would be set), so the footprint stays on the pass
while the line tilts; pitch keeps the paper's pivot, the sensor origin.

The Gymnasium environment is a thin wrapper over `PassDynamics`; the rl and feedback planners
drive the same object with a controller, and the geometric planner uses the inverse
(`steps_between`) and the tracker (`track`) to choose poses directly.
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
from scanplan.planning.swaths import Swath, frame_poses
from scanplan.sensor.profilometer import LineProfilometer, Profile, Scan
from scanplan.world.part import Part

# Where a pitch step turns (`scanplan train --pitch-pivot`): the sensor's origin (the default,
# v0 as it always was) or the footprint, W_d along the beam (a robot TCP set there), so that
# a pitch step does not swing the footprint by W_d·Δθ.
DEFAULT_PITCH_PIVOT = "sensor"
PITCH_PIVOTS = (DEFAULT_PITCH_PIVOT, "footprint")


def check_pitch_pivot(pivot: str, roll: bool = False, name: str = "pitch_pivot") -> str:
    """`pivot` if it is one of `PITCH_PIVOTS` and allowed (a rolling step model, env v1,
    keeps the sensor's); ValueError (one line, naming the option `name`) otherwise."""
    if pivot not in PITCH_PIVOTS or (roll and pivot != DEFAULT_PITCH_PIVOT):
        raise ValueError(
            f"{name} {pivot!r}: one of {', '.join(PITCH_PIVOTS)}, and {DEFAULT_PITCH_PIVOT} "
            "with roll (env v1)"
        )
    return pivot


def pitch_pivot_mm(pivot: str, spec: ScanSpec) -> float:
    """The distance along the beam a pitch step turns about (`PITCH_PIVOTS`)."""
    check_pitch_pivot(pivot)
    return spec.working_distance_mm if pivot == "footprint" else 0.0


def _towards(value: float, limit: float) -> tuple[float, float]:
    """The paper's sign limitation: only towards the target (0 width when it is unknown)."""
    if not math.isfinite(value):
        return 0.0, 0.0
    return (0.0, float(limit)) if value >= 0 else (-float(limit), 0.0)


def limit_action(
    action: np.ndarray,
    d_mm: float,
    alpha_rad: float,
    limits: StepLimits,
    wd_mm: float,
    beta_rad: float = math.nan,
) -> np.ndarray:
    """An action in [−1, 1]³ scaled to (Δy mm, Δz mm, Δθ rad), with the paper's dynamic action
    limitation from the current D and α (eqs. clipActionD/N): Δz only towards W_d, Δθ only
    towards alignment. With no valid point D and α are unknown: Δz and Δθ are held at 0.
    An action in [−1, 1]⁴ (roll) adds Δφ, limited by the sign of β as Δθ is by α's."""
    roll = len(action) == 4
    lim = limits.array_roll if roll else limits.array
    step = np.clip(np.asarray(action, dtype=np.float64), -1.0, 1.0) * lim
    # Scalar clips as min/max: np.clip's result, at a fraction of its cost per training step.
    lo, hi = _towards(d_mm - wd_mm, lim[1])
    step[1] = min(max(float(step[1]), lo), hi)
    lo, hi = _towards(alpha_rad, lim[2])
    step[2] = min(max(float(step[2]), lo), hi)
    if roll:
        lo, hi = _towards(beta_rad, lim[3])
        step[3] = min(max(float(step[3]), lo), hi)
    return step


def _rolled_step(
    s: float,
    h: float,
    th: float,
    phi: float,
    lat: float,
    dy: float,
    dz: float,
    dth: float,
    dphi: float,
    pivot_mm: float,
) -> tuple[float, float, float, float, float]:
    """The rolled step of `apply_step` on plain floats (the tracker's recurrence calls it
    per station)."""
    ct = math.cos(th)
    s, h, lat = (
        s + dy - dz * math.sin(th),
        h - dz * ct * math.cos(phi),
        lat + dz * ct * math.sin(phi),
    )
    th, phi2 = th + dth, phi + dphi
    # Rolling about the pivot moves the sensor by W_d (z_s(θ', φ) − z_s(θ', φ')).
    ct2 = pivot_mm * math.cos(th)
    h -= ct2 * (math.cos(phi) - math.cos(phi2))
    lat += ct2 * (math.sin(phi) - math.sin(phi2))
    return s, h, th, phi2, lat


def apply_step(
    state: np.ndarray,
    step: np.ndarray,
    pivot_mm: float | None = None,
    pitch_pivot_mm: float = 0.0,
) -> np.ndarray:
    """(s, h, θ) after the step (Δy, Δz, Δθ) in mm and rad; (s, h, θ, φ, l) after
    (Δy, Δz, Δθ, Δφ), the roll about the point `pivot_mm` (W_d) along the beam. The beam is
    z_s = −sinθ·u + cosθ·(sinφ·v − cosφ·w) (`Swath.poses`). Pitch turns about the point
    `pitch_pivot_mm` along the beam: 0 is the sensor's origin (the default), W_d the
    footprint (`PITCH_PIVOTS`; the rolled step keeps the origin)."""
    if len(state) == 5:
        if pivot_mm is None:
            raise ValueError("a rolled step needs its pivot distance (W_d)")
        s, h, th, phi, lat = (float(x) for x in state)
        dy, dz, dth, dphi = (float(x) for x in step)
        return np.array(_rolled_step(s, h, th, phi, lat, dy, dz, dth, dphi, pivot_mm))
    s, h, th = state
    dy, dz, dth = step
    s, h, th2 = s + dy - dz * math.sin(th), h - dz * math.cos(th), th + dth
    if pitch_pivot_mm:
        # The pivot p·z_s(θ) stays put: the origin moves by p·(z_s(θ) − z_s(θ + Δθ)).
        s += pitch_pivot_mm * (math.sin(th2) - math.sin(th))
        h += pitch_pivot_mm * (math.cos(th2) - math.cos(th))
    return np.array([s, h, th2])


def steps_between(s_mm: np.ndarray, h_mm: np.ndarray, pitch_rad: np.ndarray) -> np.ndarray:
    """The inverse of `apply_step`: (Δy, Δz, Δθ) of each step between consecutive stations
    (s, h, θ) of a pass, (n−1, 3)."""
    ds, dh, dth = np.diff(s_mm), np.diff(h_mm), np.diff(pitch_rad)
    th = pitch_rad[:-1]
    dz = -dh / np.cos(th)
    dy = ds + dz * np.sin(th)
    return np.stack([dy, dz, dth], axis=1)


def track(
    s_mm: np.ndarray, h_mm: np.ndarray, pitch_rad: np.ndarray, limits: StepLimits
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Follow the stations with steps clipped to the limits' magnitudes (for planners that
    choose poses directly; the sign limitation is a training aid that forbids anticipation)."""
    acts = steps_between(s_mm, h_mm, pitch_rad)
    lim = limits.array * (1 - 1e-9)
    if np.all(np.abs(acts) <= lim):
        return s_mm, h_mm, pitch_rad
    s, h, th = s_mm.copy(), h_mm.copy(), pitch_rad.copy()
    for i in range(1, len(s)):  # a recurrence over stations: each step starts where the last ended
        c, sn = math.cos(th[i - 1]), math.sin(th[i - 1])
        dz = min(max(-(h_mm[i] - h[i - 1]) / c, -lim[1]), lim[1])
        dy = min(max(s_mm[i] - s[i - 1] + dz * sn, -lim[0]), lim[0])
        dth = min(max(pitch_rad[i] - th[i - 1], -lim[2]), lim[2])
        s[i] = s[i - 1] + dy - dz * sn
        h[i] = h[i - 1] - dz * c
        th[i] = th[i - 1] + dth
    return s, h, th


def track_rolled(
    s_mm: np.ndarray,
    h_mm: np.ndarray,
    pitch_rad: np.ndarray,
    roll_rad: np.ndarray,
    lateral0_mm: float,
    limits: StepLimits,
    pivot_mm: float,
) -> np.ndarray:
    """`track` with roll: follow the stations' (s, h, θ, φ) with steps (Δy, Δz, Δθ, Δφ)
    clipped to the limits' magnitudes, through `apply_step` (so every pose is one the step
    model can reach); the lateral offset l follows. Returns the states, (n, 5)."""
    lim = limits.array_roll * (1 - 1e-9)
    lim_y, lim_z, lim_th, lim_phi = (float(x) for x in lim)
    targets = np.stack([np.asarray(a, dtype=np.float64) for a in (s_mm, h_mm, pitch_rad, roll_rad)])
    n = targets.shape[1]
    out = np.empty((n, 5))
    out[:, :4] = targets.T
    out[0, 4] = lateral0_mm
    # On the stations, a step reaches the next one exactly (the recurrence's Δz puts h on
    # it): only where that step breaks a limit is the recurrence needed, until a step
    # within the limits brings it back (0.4 % of the door's stations).
    s, h, th, phi = targets
    dz = -(np.diff(h) + pivot_mm * np.cos(th[1:]) * (np.cos(phi[:-1]) - np.cos(phi[1:]))) / (
        np.cos(th[:-1]) * np.cos(phi[:-1])
    )
    dy = np.diff(s) + dz * np.sin(th[:-1])
    steep = np.flatnonzero(
        (np.abs(np.stack([dy, dz, np.diff(th), np.diff(phi)])) > lim[:, None]).any(axis=0)
    )  # step j: from station j to j + 1
    dlat = dz * np.cos(th[:-1]) * np.sin(phi[:-1]) + pivot_mm * np.cos(th[1:]) * (
        np.sin(phi[:-1]) - np.sin(phi[1:])
    )
    s_t, h_t, th_t, phi_t = targets.tolist()  # plain floats in the recurrence: ~10x faster
    i = 1  # station i - 1 is on the stations
    while i < n:
        k = int(np.searchsorted(steep, i - 1))
        j = int(steep[k]) if k < len(steep) else n - 1  # on the stations up to j
        out[i : j + 1, 4] = out[i - 1, 4] + np.cumsum(dlat[i - 1 : j])
        state = tuple(out[j].tolist())
        for i in range(j + 1, n):  # a recurrence: each step starts where the last ended
            s_i, h_i, th_i, phi_i, lat_i = state
            dphi = min(max(phi_t[i] - phi_i, -lim_phi), lim_phi)
            dth = min(max(th_t[i] - th_i, -lim_th), lim_th)
            pivot_h = pivot_mm * math.cos(th_i + dth) * (math.cos(phi_i) - math.cos(phi_i + dphi))
            raw_z = -(h_t[i] - h_i + pivot_h) / (math.cos(th_i) * math.cos(phi_i))
            step_z = min(max(raw_z, -lim_z), lim_z)
            raw_y = s_t[i] - s_i + step_z * math.sin(th_i)
            step_y = min(max(raw_y, -lim_y), lim_y)
            state = _rolled_step(s_i, h_i, th_i, phi_i, lat_i, step_y, step_z, dth, dphi, pivot_mm)
            out[i] = state
            if (step_y, step_z, dth, dphi) == (raw_y, raw_z, th_t[i] - th_i, phi_t[i] - phi_i):
                break  # back on station i
        else:
            break
        i += 1
    return out


def progress_mm(state: np.ndarray, wd_mm: float) -> float:
    """Advance of the scan along u: where the beam meets the working distance (a pitched sensor
    looks W_d·sinθ behind itself; ending on the sensor's own advance would leave the end of the
    pass unscanned)."""
    return float(state[0] - wd_mm * math.sin(state[2]))  # with roll too: z_s·u = −sinθ


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
        raise ValueError(
            f"pass {swath.index} sees no surface of part {part.name}: "
            "the part is outside the sensor's reach"
        )
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
    pitch_pivot: where a pitch step turns (`PITCH_PIVOTS`, v0 only).
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
