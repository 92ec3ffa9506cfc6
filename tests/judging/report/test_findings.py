"""What a report tells in words: the program and its arm, robustness, verdicts."""

from __future__ import annotations

import numpy as np

from scanplan.judging.report.findings import (
    Program,
    arm_finding,
    robustness_finding,
    verdict_finding,
)
from scanplan.judging.robustness import Robustness
from scanplan.judging.verdict import judge, parse_requirements

RECORD = {
    "part_pose": "900,0,-300,0,0,0",
    "in_spec_without_robot": 0.9,
    "in_spec": 0.75,
    "scanning_poses_given_up": {"0": 10, "1": 5},
    "moves_given_up": 2,
    "passes_split": 1,
    "passes_turned": 0,
}


def test_the_arm_finding_names_the_program_placement_and_the_cost():
    found = arm_finding("kr6-r900", RECORD, Program("scan.src", "KRL", 120, 61.25), "0,0,90,0,0,0")
    text = " ".join(found.lines)
    assert found.title == "Robot program and arm (kr6-r900)"
    assert "Program scan.src (KRL), 120 targets, cycle time 61.2 s." in text
    assert "the part at 900,0,-300,0,0,0 in the arm's base frame" in text
    assert "in-spec coverage 90.0% without it, 75.0% with it (15.0 points lost)" in text
    assert "gave up 15 scanning poses and 2 move poses" in text
    assert "<li>" in found.to_html() and "&#x27;" in found.to_html()  # escaped


def test_robustness_and_verdicts_are_told_only_when_run():
    assert robustness_finding(None, 0.9) is None and verdict_finding([]) is None
    robust = Robustness(
        "place:1mm", 3, np.array([0.8, 0.9, 0.7]), np.zeros((4, 3)), np.array([1, 0.5, 0, 1])
    )
    text = " ".join(robustness_finding(robust, 0.92).lines)
    assert "over 3 perturbed trials mean 80.0%" in text and "worst 70.0%" in text
    assert "25.0% of the surface is fragile" in text
    verdicts = judge(parse_requirements("p5>=0.8"), {"p5": robust.p5})
    found = verdict_finding(verdicts)
    assert found is not None and found.title == "Verdict: FAIL (1 of 1)"
