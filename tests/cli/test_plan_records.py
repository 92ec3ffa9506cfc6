"""Issue 46 (A, B, G) as a user meets it: a plan file whose record has the wrong JSON type,
lacks a field, or holds a number out of the range the same value has as an option ends in
one line naming the file and the field, exit 2, nothing written, in every command that reads
plans; before the part is loaded or any work is done."""

from __future__ import annotations

import copy
from dataclasses import replace
from pathlib import Path

import pytest

from helpers import recorded_trajectory, run_cli
from scanplan.core.plan_file import write_csv, write_json

# Each command as a user runs it on plan file {plan}, writing under {out}.
COMMANDS = {
    "evaluate": ("evaluate", "door", "{plan}", "-o", "{out}/report"),
    "export": ("export", "{plan}", "-o", "{out}/p.script"),
    "defects": ("defects", "door", "{plan}", "-o", "{out}/defects"),
    "place": ("place", "{plan}", "--robot", "ur10e"),
    "view": ("view", "{plan}", "-o", "{out}/page.html"),
    "scan": ("scan", "door", "{plan}", "-o", "{out}/cloud.ply"),
    "closed loop": (
        "evaluate", "door", "{plan}", "--perturb", "place:1mm", "--closed-loop", "--json",
    ),
}  # fmt: skip

# (what, the field the line names, how the record is broken); a CSV or a JSON in turn.
OBJECT = "expected a JSON object"
CASES = [
    ("context list", f"context: {OBJECT}", lambda m: m | {"context": [1, 2]}),
    ("context string", f"context: {OBJECT}", lambda m: m | {"context": "top"}),
    ("robot number", f"robot: {OBJECT}", lambda m: m | {"robot": 3}),
    ("robot unnamed", "robot.robot: Field required", lambda m: m | {"robot": unnamed(m)}),
    ("views string", "views: Input should be a valid list", lambda m: m | {"views": "top"}),
    ("cycle list", "cycle_time_s: Input should be", lambda m: m | {"cycle_time_s": [1]}),
    (
        "tolerance",
        "scan_spec.tolerance_mm: 1e+200 is not in",
        lambda m: spec(m, tolerance_mm=1e200),
    ),
    ("spacing", "scan_spec.delta_s_opt_mm: 1e-06 is not", lambda m: spec(m, delta_s_opt_mm=1e-6)),
    (
        "clearance",
        "scan_spec.clearance_mm: 1e+300 is not in",
        lambda m: spec(m, clearance_mm=1e300),
    ),
    ("10 km pass", "views[0].swaths[0].end_mm[0]: 10000000 is", lambda m: line(m, [1e7, 0, 400])),
    ("1e300 pass", "views[0].swaths[0].end_mm[0]: 1e+300 is", lambda m: line(m, [1e300, 0, 400])),
]


def unnamed(meta: dict) -> dict:
    return {k: v for k, v in meta["robot"].items() if k != "robot"}


def spec(meta: dict, **change: float) -> dict:
    meta = copy.deepcopy(meta)
    meta["context"]["scan_spec"].update(change)
    return meta


def line(meta: dict, end_mm: list[float]) -> dict:
    meta = copy.deepcopy(meta)
    meta["views"][0]["swaths"][0]["end_mm"] = end_mm
    return meta


@pytest.fixture(scope="module")
def plans(tmp_path_factory) -> dict[str, Path]:
    """Each broken plan, as a CSV (even cases) or a JSON (odd ones)."""
    d = tmp_path_factory.mktemp("plans")
    traj = recorded_trajectory()
    out = {}
    for i, (name, _, broken) in enumerate(CASES):
        path = d / f"{name.replace(' ', '_')}.{'json' if i % 2 else 'csv'}"
        meta = broken(copy.deepcopy(traj.meta))
        if path.suffix == ".csv":
            write_csv(replace(traj, meta=meta), path)
        else:
            write_json(replace(traj, meta=meta), path)
        out[name] = path
    return out


@pytest.mark.parametrize("command", sorted(COMMANDS))
@pytest.mark.parametrize(
    ("name", "field"), [(c[0], c[1]) for c in CASES], ids=[c[0] for c in CASES]
)
def test_a_broken_plan_record_is_one_line_in_every_command(plans, tmp_path, command, name, field):
    plan = plans[name]
    args = [a.format(plan=plan, out=tmp_path) for a in COMMANDS[command]]
    result = run_cli(*args)
    assert result.exit_code == 2, (result.stdout, result.stderr)
    lines = result.stderr.splitlines()
    assert len(lines) == 1, result.stderr
    assert lines[0].startswith(("error: plan ", "error: trajectory file ")), lines[0]
    assert str(plan) in lines[0] and field in lines[0], lines[0]
    assert list(tmp_path.iterdir()) == []
