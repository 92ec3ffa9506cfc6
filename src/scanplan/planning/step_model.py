"""The pass step model's arithmetic (SPEC §4, §5): how a limited action moves a sensor's state
on a swath, the step between two states (its inverse), and trackers that follow stations with
steps within the limits. Plain numbers: nothing here measures.

State (s, h, θ): advance along u and height above the swath's start (mm), pitch about x_s
(rad). A step (Δy, Δz, Δθ) moves Δy along u and Δz along the beam z_s = −sinθ·u − cosθ·w of
the pose it starts from, then pitches by Δθ. With roll (beyond the paper, env v1) the state is
(s, h, θ, φ, l) — roll about the scan direction u (applied before the pitch, so it is the
roll about y_s of SPEC §1 when θ = 0) and the sensor's lateral offset along v — and a step
(Δy, Δz, Δθ, Δφ) also rolls by Δφ, about the point W_d along the beam (the line's centre at
the working distance, where a robot's TCP would be set), so the footprint stays on the pass
while the line tilts; pitch keeps the paper's pivot, the sensor origin.

`dynamics.PassDynamics` steps a sensor with it; the geometric planner uses the inverse
(`steps_between`) and the trackers (`track`, `track_rolled`) to choose poses directly.
"""

from __future__ import annotations

import math

import numpy as np

from scanplan.core.quantities import ScanSpec, StepLimits

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
