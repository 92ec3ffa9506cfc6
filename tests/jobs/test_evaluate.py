"""`evaluate -o DIR` with trials: the report and the fragility map are one folder, swapped in
whole; a run stopped while writing it leaves the previous folder as it was."""

from __future__ import annotations

import errno

import numpy as np
import trimesh

from helpers import listing, run_cli
from scanplan.core.plan_file import write_csv
from scanplan.core.trajectory import Trajectory
from scanplan.planning.swaths import Swath


def test_the_fragility_map_is_in_the_folder_and_a_failed_write_keeps_the_last(
    tmp_path, monkeypatch
):
    from scanplan.judging.report import maps

    plate = trimesh.creation.box((300, 200, 10))
    plate.apply_translation((0, 0, -5))
    plate.export(tmp_path / "plate.stl")
    sw = Swath(0, np.array([-50.0, 0, 400]), np.array([50.0, 0, 400]), np.eye(3)[0], np.eye(3)[1])
    poses = sw.poses(np.linspace(0, 100, 21), np.zeros(21), np.zeros(21))
    write_csv(Trajectory(poses, np.zeros(21, int), np.ones(21, bool)), tmp_path / "t.csv")
    out = tmp_path / "report"
    args = ["evaluate", str(tmp_path / "plate.stl"), str(tmp_path / "t.csv"), "-q", "-o", str(out)]
    first = run_cli(*args, "--perturb", "place:1mm", "--trials", "1")
    assert first.exit_code == 0, first.output
    written = {p.name: p.read_bytes() for p in out.iterdir()}
    assert {"fragility.csv", "fragility.png", "metrics.json"} <= set(written)
    assert written["fragility.csv"].startswith(b"x_mm,y_mm,z_mm,in_spec_share\n")

    def full(*args, **kwargs):
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(maps, "plot_fragility_map", full)
    again = run_cli(*args, "--perturb", "place:2mm", "--trials", "1")
    assert again.exit_code == 2 and again.stderr == "error: No space left on device\n"
    assert {p.name: p.read_bytes() for p in out.iterdir()} == written
    assert listing(tmp_path) == ["plate.stl", "report", "t.csv"]
