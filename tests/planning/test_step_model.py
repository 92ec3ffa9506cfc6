"""The pass step model with roll φ (beyond the paper, SPEC §1): a roll turns the beam about the
scan direction and keeps the footprint, is limited by β as pitch is by α, and tracked
stations stay reachable."""

from __future__ import annotations

import math

import numpy as np
import pytest

from scanplan.core.quantities import StepLimits
from scanplan.planning.step_model import apply_step, limit_action, progress_mm, track_rolled
from scanplan.planning.swaths import Swath

WD = 400.0


def swath_x() -> Swath:
    u, v = np.array([1.0, 0.0, 0.0]), np.array([0.0, 1.0, 0.0])
    return Swath(0, np.array([-300.0, 0.0, WD]), np.array([300.0, 0.0, WD]), u, v)


def test_roll_turns_the_beam_about_the_scan_direction_and_keeps_the_footprint():
    sw = swath_x()
    phi = math.radians(20.0)
    state = np.array([0.0, 0.0, 0.0, 0.0, 0.0])
    after = apply_step(state, np.array([0.0, 0.0, 0.0, phi]), WD)
    pose0, pose1 = sw.pose(*state), sw.pose(*after)
    foot0 = pose0[:3, 3] + WD * pose0[:3, 2]
    foot1 = pose1[:3, 3] + WD * pose1[:3, 2]
    np.testing.assert_allclose(foot1, foot0, atol=1e-9)  # rolled about the W_d point
    # z_s tilts towards +x_s = +v for φ > 0; y_s (the scan direction) does not move.
    assert pose1[1, 2] == pytest.approx(math.sin(phi))
    np.testing.assert_allclose(pose1[:3, 1], pose0[:3, 1], atol=1e-12)
    assert progress_mm(after, WD) == pytest.approx(0.0, abs=1e-9)


def test_roll_limitation_follows_beta_as_pitch_follows_alpha():
    lim = StepLimits()
    got = limit_action(np.array([0.5, 0.0, 0.0, -1.0]), WD, 0.0, lim, WD, beta_rad=0.1)
    assert got[3] == 0.0  # β > 0: only positive Δφ
    got = limit_action(np.array([0.5, 0.0, 0.0, -1.0]), WD, 0.0, lim, WD, beta_rad=-0.1)
    assert got[3] == pytest.approx(-lim.dphi_max_rad)
    got = limit_action(np.array([0.5, 0.0, 0.0, 1.0]), WD, 0.0, lim, WD, beta_rad=math.nan)
    assert got[3] == 0.0  # unknown: hold


def test_tracked_rolled_stations_are_reachable_by_the_step_model():
    n = 200
    s = np.arange(n) * 0.5
    h = 3.0 * np.sin(s / 20.0)
    th = np.radians(5.0) * np.sin(s / 30.0)
    phi = np.radians(np.linspace(0.0, 30.0, n))  # 0.15°/step: within Δφ_max
    states = track_rolled(s, h, th, phi, 0.0, StepLimits(), WD)
    lim = StepLimits().array_roll
    for i in range(1, n):  # every state follows from the previous one by a step in limits
        prev = states[i - 1]
        dth, dphi = states[i, 2] - prev[2], states[i, 3] - prev[3]
        assert abs(dth) <= lim[2] + 1e-12 and abs(dphi) <= lim[3] + 1e-12
    np.testing.assert_allclose(states[:, 3], phi, atol=1e-12)
    np.testing.assert_allclose(states[:, 1], h, atol=1e-6)


def tracked_at_every_station(s, h, th, phi, lateral0, limits, pivot):
    """`track_rolled`'s recurrence run at every station, through `apply_step`."""
    lim = limits.array_roll * (1 - 1e-9)
    states = [np.array([s[0], h[0], th[0], phi[0], lateral0])]
    for i in range(1, len(s)):
        s0, h0, th0, phi0, _ = states[-1]
        dphi = float(np.clip(phi[i] - phi0, -lim[3], lim[3]))
        dth = float(np.clip(th[i] - th0, -lim[2], lim[2]))
        pivot_h = pivot * math.cos(th0 + dth) * (math.cos(phi0) - math.cos(phi0 + dphi))
        dz = float(
            np.clip(-(h[i] - h0 + pivot_h) / (math.cos(th0) * math.cos(phi0)), -lim[1], lim[1])
        )
        dy = float(np.clip(s[i] - s0 + dz * math.sin(th0), -lim[0], lim[0]))
        states.append(apply_step(states[-1], np.array([dy, dz, dth, dphi]), pivot))
    return np.array(states)


def test_tracking_skips_only_what_the_recurrence_would_not_change():
    """Stations mostly within the limits, with steps in height, pitch and roll that the
    tracker must ramp through: the same states as the recurrence at every station."""
    rng = np.random.default_rng(5)
    n = 400
    s = np.arange(n) * 0.5
    h = 2.0 * np.sin(s / 25.0)
    th = np.radians(4.0) * np.sin(s / 40.0)
    phi = np.radians(3.0) * np.cos(s / 35.0)
    for k in rng.integers(0, n, 6):  # steps the limits cannot follow at once
        h[k:] += rng.normal(0.0, 6.0)
        th[k:] += rng.normal(0.0, 0.1)
        phi[k:] += rng.normal(0.0, 0.1)
    want = tracked_at_every_station(s, h, th, phi, 0.7, StepLimits(), WD)
    got = track_rolled(s, h, th, phi, 0.7, StepLimits(), WD)
    np.testing.assert_allclose(got, want, rtol=0, atol=1e-9)
    on_stations = np.isclose(got[:, 1], h, atol=1e-9) & np.isclose(got[:, 2], th, atol=1e-12)
    assert 0.3 < on_stations.mean() < 0.99  # both stretches were exercised
