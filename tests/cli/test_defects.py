"""`scanplan defects`: bad sizes and types end in one line and exit 2 before any work; a run
prints valid JSON (the fit's statement, the false calls, the prediction) and writes its files,
as a whole folder: a run stopped while writing leaves the previous folder as it was."""

from __future__ import annotations

import errno
import json

import pytest

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


@pytest.mark.parametrize(
    "stop, code, said",
    [
        (OSError(errno.ENOSPC, "No space left on device"), 2, "No space left on device"),
        (KeyboardInterrupt(), 130, "interrupted"),
    ],
    ids=["full-disk", "ctrl-c"],
)
def test_defects_folder_stopped_while_written_keeps_the_previous_one(
    plate_and_trajectory, tmp_path, monkeypatch, stop, code, said
):
    # The folder is written aside and swapped in whole: stopped after pod.json and
    # defects.csv are written, before the plot, the previous run's folder stays as it was
    # and no half-written one is left beside it.
    from scanplan.judging.report import pod

    plate, traj = plate_and_trajectory
    out = tmp_path / "out"
    args = ["defects", str(plate), str(traj), "--trials", "1", "--per-trial", "2", "-q"]
    assert run_cli(*args, "--no-defect-free", "-o", str(out)).exit_code == 0
    before = {p.name: p.read_bytes() for p in out.iterdir()}
    assert "pod.png" in before and "detectability.csv" not in before

    def stopped(*a, **kw):
        raise stop

    monkeypatch.setattr(pod, "plot_pod", stopped)
    result = run_cli(*args, "--sizes", "0.1:0.2", "-o", str(out))
    assert result.exit_code == code, result.output
    assert said in result.stderr and len(result.stderr.splitlines()) == 1
    assert {p.name: p.read_bytes() for p in out.iterdir()} == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out", "plate.stl", "t.csv"]
