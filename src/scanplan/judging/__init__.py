"""Scan-quality metrics of a trajectory: simulate its scan (`evaluate`), summarize the errors,
spacing, coverage and in-spec coverage of the surface to inspect (`Metrics`), and how that
coverage holds on seeded perturbed parts (`robustness`).
"""

from scanplan.judging.evaluation import (
    coverage_spacing_mm,
    evaluate,
    in_spec_radius_mm,
    in_spec_samples,
)
from scanplan.judging.robustness import Robustness, TrialTask, robustness, run_trial, trial_tasks
from scanplan.judging.summary import (
    COVERAGE_DEFINITION,
    IN_SPEC_COVERAGE_DEFINITION,
    VISIBILITY_CEILING_DEFINITION,
    CoverageMap,
    Metrics,
    SurfaceState,
)

__all__ = [
    "COVERAGE_DEFINITION",
    "IN_SPEC_COVERAGE_DEFINITION",
    "VISIBILITY_CEILING_DEFINITION",
    "CoverageMap",
    "Metrics",
    "Robustness",
    "SurfaceState",
    "TrialTask",
    "coverage_spacing_mm",
    "evaluate",
    "in_spec_radius_mm",
    "in_spec_samples",
    "robustness",
    "run_trial",
    "trial_tasks",
]
