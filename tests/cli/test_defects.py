"""`scanplan defects`: bad sizes and types end in one line and exit 2 before any work; a run
prints valid JSON (the fit's statement, the false calls, the prediction) and writes its files."""

from __future__ import annotations

import json

from helpers import run_cli


def test_defects_refuses_bad_input_in_one_line(plate_and_trajectory, tmp_path):
    plate, traj = plate_and_trajectory
    out = tmp_path / "out"
    for args, message in (
        (["--sizes", "0.5:0.1"], "LO must be <= HI"),
        (["--sizes", "0:1"], "--sizes LO 0 is not in"),
        (["--sizes", "a:b"], "expected LO:HI"),
        (["--type", "crack"], "--type 'crack'"),
    ):
        result = run_cli("defects", str(plate), str(traj), *args, "-o", str(out))
        assert result.exit_code == 2, result.output
        assert message in result.output
        assert len(result.output.strip().splitlines()) == 1
        assert not out.exists()


def test_defects_json_and_files(plate_and_trajectory, tmp_path):
    plate, traj = plate_and_trajectory
    out = tmp_path / "out"
    result = run_cli(
        "defects", str(plate), str(traj), "--trials", "1", "--per-trial", "4",
        "--sizes", "0.05:0.5", "--json", "-q", "-o", str(out),
    )  # fmt: skip
    assert result.exit_code == 0, result.output
    data = json.loads(result.stdout)
    assert data["type"] == "dent" and len(data["defects"]) == 4
    assert data["pod"]["status"] in ("fit", "all_hit", "all_miss", "separated", "flat")
    assert data["false_calls"]["count"] == 0
    assert data["predicted"]["samples"] > 0
    # Only part of the plate lies under the 100 mm of poses: the prediction never reaches 90 %.
    assert data["predicted"]["a90_mm"] is None
    for name in ("pod.json", "pod.png", "defects.csv", "detectability.csv", "detectability.png"):
        assert (out / name).stat().st_size > 0
