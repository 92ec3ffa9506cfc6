"""The RL observation: what the agent sees of a sensor on a pass, normalized. One definition
for the environment that trains a policy and the rl planner that runs it, and the layout a
policy file's input size is checked against.
"""

from __future__ import annotations

import numpy as np

from scanplan.core.quantities import ScanSpec
from scanplan.planning.dynamics import PassDynamics
from scanplan.world.surface import aligning_angles

OBS_LIMIT = 10.0  # every normalized observation is clipped to [-OBS_LIMIT, OBS_LIMIT]
LOOKAHEAD_MM = (10.0, 30.0, 60.0, 120.0, 200.0)
_LOOKAHEAD_COLUMNS = 16
# The layout, in order: P relative to the pass start (if use_position); θ, D, α, Δs; φ, β
# (with roll, env v1); (Δh, pitch) at the footprint's distances ahead (if lookahead).
POSITION_FEATURES = 3
CORE_FEATURES = 4
ROLL_FEATURES = 2
LOOKAHEAD_FEATURES = 2 * len(LOOKAHEAD_MM)


def observation_size(use_position: bool, lookahead: bool, roll: bool = False) -> int:
    """Entries of the observation for these options (the layout above)."""
    return (
        (POSITION_FEATURES if use_position else 0)
        + CORE_FEATURES
        + (ROLL_FEATURES if roll else 0)
        + (LOOKAHEAD_FEATURES if lookahead else 0)
    )


def observe(
    dyn: PassDynamics,
    start_state: np.ndarray,
    use_position: bool,
    lookahead: bool,
    scale: ScanSpec | None = None,
) -> np.ndarray:
    """The normalized observation of a sensor on a pass (table in `env.SwathScanEnv`); φ and
    β are added when `dyn.roll`. scale: the ScanSpec whose Z range, α_max and Δs_opt
    normalize it (a policy's, as it was trained); None: the pass's own. The depth error is
    always to the pass's own working distance."""
    spec = dyn.spec if scale is None else scale
    half = spec.half_range_mm
    s, h, th = dyn.state[:3]
    d = (dyn.d_mm - dyn.spec.working_distance_mm) / half if np.isfinite(dyn.d_mm) else 0.0
    a = dyn.alpha_rad / spec.alpha_max_rad if np.isfinite(dyn.alpha_rad) else 0.0
    ds = dyn.delta_s_mm / spec.delta_s_opt_mm if np.isfinite(dyn.delta_s_mm) else 1.0
    obs = [th / spec.alpha_max_rad, d, a, ds]
    if dyn.roll:
        b = dyn.beta_rad / spec.alpha_max_rad if np.isfinite(dyn.beta_rad) else 0.0
        obs += [dyn.state[3] / spec.alpha_max_rad, b]
    if use_position:
        # The paper's P; its lateral entry is 0 by construction (a pass moves in the u-w plane).
        obs = [(s - start_state[0]) / 1000.0, 0.0, (h - start_state[1]) / half, *obs]
    if lookahead:
        obs += list(_lookahead_features(dyn, spec))
    return np.clip(np.asarray(obs, dtype=np.float32), -OBS_LIMIT, OBS_LIMIT)


def _lookahead_features(dyn: PassDynamics, scale: ScanSpec) -> np.ndarray:
    """From the CAD (planning is offline): mean surface height and the pitch that faces its
    mean normal under the line at the footprint and at `LOOKAHEAD_MM` ahead; returned
    relative to the footprint's height and to θ."""
    th = dyn.state[2]
    sw = dyn.swath
    half_line = dyn.spec.sensor.line_width_mm / 2
    foot = dyn.progress_mm  # the footprint's advance: where the beam meets W_d
    ahead = foot + np.array((0.0, *LOOKAHEAD_MM))
    lateral = np.linspace(-half_line, half_line, _LOOKAHEAD_COLUMNS)
    probe = sw.probe(dyn.part, ahead, lateral)
    hit = probe.hit
    z = np.where(hit, probe.z_mm, 0.0).sum(1) / np.maximum(hit.sum(1), 1)
    n_mean = probe.normals_up.sum(1)
    pitch, _ = aligning_angles(n_mean, sw.u, sw.v, roll=False)
    seen: np.ndarray = np.asarray(hit.any(axis=1))
    z = np.where(seen, z, z[0] if seen[0] else 0.0)
    pitch = np.where(seen, pitch, th)
    dh = (z[1:] - z[0]) / scale.half_range_mm if seen[0] else 0 * z[1:]
    dp = (pitch[1:] - th) / scale.alpha_max_rad
    return np.concatenate([dh, dp])
