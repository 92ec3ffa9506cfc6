"""Scan-quality metrics of a trajectory: simulate its scan (`evaluate`), summarize the errors,
spacing, coverage and in-spec coverage of the surface to inspect (`Metrics`).
"""

from scanplan.metrics.evaluation import coverage_spacing_mm, evaluate, in_spec_radius_mm
from scanplan.metrics.summary import (
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
    "SurfaceState",
    "coverage_spacing_mm",
    "evaluate",
    "in_spec_radius_mm",
]
