"""--require: criteria parsed in their units, judged pass or fail, bad ones one line."""

from __future__ import annotations

import math

import pytest

from scanplan.judging.verdict import (
    FIGURES,
    check_available,
    judge,
    parse_requirements,
    verdict_lines,
)


def test_criteria_are_read_in_each_figure_s_units():
    got = parse_requirements("in-spec>=0.9, p5>=80%,cycle<=2min,a90<0.1mm, collisions<=0")
    assert [(c.figure.key, c.op) for c in got] == [
        ("in-spec", ">="), ("p5", ">="), ("cycle", "<="), ("a90", "<"), ("collisions", "<="),
    ]  # fmt: skip
    assert [c.limit for c in got] == pytest.approx([0.9, 0.8, 120.0, 0.1, 0.0])


@pytest.mark.parametrize(
    "text, message",
    [
        ("inspec>=0.9", "unknown figure 'inspec'"),
        ("in-spec=0.9", "expected NAME>=VALUE"),
        ("cycle<=2furlongs", "cycle takes the units 's', 'min', 'h'"),
        ("in-spec>=0.9s", "in-spec takes the units '%'"),
        ("cycle<=1e999", "not a finite number"),
        (" , ", "names no criterion"),
    ],
)
def test_a_bad_criterion_is_one_line_naming_it(text, message):
    with pytest.raises(ValueError, match=message) as info:
        parse_requirements(text)
    assert "\n" not in str(info.value)


def test_verdicts_pass_fail_and_a_figure_not_reached_fails():
    criteria = parse_requirements("in-spec>=0.9,cycle<=120s,a90<=0.1")
    verdicts = judge(criteria, {"in-spec": 0.95, "cycle": 130.0, "a90": None})
    assert [v.passed for v in verdicts] == [True, False, False]
    lines = verdict_lines(verdicts)
    assert lines[0] == "verdict: FAIL (2 of 3 criteria)"
    assert lines[1] == "  pass: in-spec coverage 95.0% (required >= 90.0%)"
    assert lines[2] == "  FAIL: cycle time 130.0 s (required <= 120.0 s)"
    assert "n/a" in lines[3]
    data = verdicts[1].to_json_dict()
    assert data == {
        "criterion": "cycle<=120s", "figure": "cycle", "op": "<=", "limit": 120.0,
        "value": 130.0, "pass": False,
    }  # fmt: skip
    assert not judge(criteria[:1], {"in-spec": math.nan})[0].passed
    assert verdict_lines(judge(criteria[:1], {"in-spec": 0.9})) == [
        "verdict: pass",
        "  pass: in-spec coverage 90.0% (required >= 90.0%)",
    ]


def test_a_figure_the_run_will_not_measure_is_refused_first():
    criteria = parse_requirements("p5>=0.8")
    check_available(criteria, {"a90": "never"})
    with pytest.raises(
        ValueError, match="'p5>=0.8': in-spec coverage under perturbation, p5 needs --perturb"
    ):
        check_available(criteria, {"p5": "needs --perturb"})
    assert all(f.key == k for k, f in FIGURES.items())
