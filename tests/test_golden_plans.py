"""The plans of every planner on the door and the drone are those recorded before the
foundation refactor (tests/data/make_golden_plans.py): a change of structure, not of result."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from data.make_golden_plans import PARTS, PLANNERS, golden_plans

GOLDEN = Path(__file__).parent / "data" / "golden_plans.npz"


@pytest.fixture(scope="module")
def plans():
    return golden_plans()


@pytest.mark.slow
@pytest.mark.parametrize("part", PARTS)
@pytest.mark.parametrize("planner", PLANNERS)
def test_plan_matches_the_recorded_one(plans, part, planner):
    recorded = np.load(GOLDEN)
    key = f"{part}/{planner}"
    np.testing.assert_array_equal(plans[f"{key}/n"], recorded[f"{key}/n"])
    np.testing.assert_array_equal(plans[f"{key}/swath"], recorded[f"{key}/swath"])
    got, want = plans[f"{key}/poses"], recorded[f"{key}/poses"]
    np.testing.assert_allclose(got[:, :3, 3], want[:, :3, 3], rtol=0, atol=1e-9)
    np.testing.assert_allclose(got[:, :3, :3], want[:, :3, :3], rtol=0, atol=1e-12)
