"""Fixtures on the command line hide what they cover (SPEC §3b, §7): a lid over part of a
plate takes that share out of the in-spec coverage `plan` plans for and `evaluate` judges,
in the scan `scan` simulates and in the perturbed trials; a fixture that hides nothing
changes neither the plan nor a figure."""

from __future__ import annotations

import json
import re
from pathlib import Path

import pytest
import trimesh

from helpers import fixture_files, run_cli
from scanplan.core.plan import read_plan
from scanplan.world.part import load_part

POINTS = ["--points", "128"]


def _judged(*args: str) -> dict:
    result = run_cli("evaluate", *args, "--json", *POINTS, "-q")
    assert result.exit_code == 0, result.output
    return json.loads(result.stdout)


def test_a_lid_takes_its_share_out_of_plan_and_evaluate_and_a_block_beside_nothing(
    plate_file: Path, tmp_path: Path
):
    lid, beside = fixture_files(tmp_path, load_part(str(plate_file)))  # over 40 % of it
    cells = {"bare": [], "lid": ["--fixture", lid], "beside": ["--fixture", beside]}
    plans = {name: tmp_path / f"{name}.json" for name in cells}
    for name, fixture in cells.items():
        result = run_cli(
            "plan", str(plate_file), "--views", "top", "-q", "-o", str(plans[name]), *fixture
        )
        assert result.exit_code == 0, result.output
    bare, lidded, by = (_judged(str(plate_file), str(plans[n])) for n in ("bare", "lid", "beside"))
    assert bare["in_spec_coverage"] > 0.97 and bare["visibility_ceiling"] == 1.0
    assert lidded["in_spec_coverage"] == pytest.approx(bare["in_spec_coverage"] - 0.4, abs=0.02)
    assert lidded["visibility_ceiling"] == pytest.approx(0.6, abs=0.01)
    assert lidded["surface"] == bare["surface"]  # the same surface to inspect: the plate's
    poses = [read_plan(plans[n]).traj.poses.tolist() for n in ("bare", "beside")]
    assert poses[0] == poses[1]
    assert by["in_spec_coverage"] == bare["in_spec_coverage"]
    assert by["visibility_ceiling"] == bare["visibility_ceiling"]
    # The plain plan judged in the lid's cell: the same share lost, said in one note.
    result = run_cli("evaluate", str(plate_file), str(plans["bare"]), *POINTS, "--fixture", lid)
    assert result.exit_code == 0, result.output
    assert f"fixtures ['{lid}'] (planned: table lowest, fixtures [])" in result.output
    shares = re.search(r"in-spec coverage ([\d.]+)%.* visibility ceiling ([\d.]+)%", result.stdout)
    assert shares is not None, result.stdout
    assert float(shares[1]) == pytest.approx(100 * lidded["in_spec_coverage"], abs=2.0)
    assert float(shares[2]) == pytest.approx(60.0, abs=1.0)


def test_scan_and_trials_hide_what_a_recorded_lid_covers(plate_file: Path, tmp_path: Path):
    lid, _ = fixture_files(tmp_path, load_part(str(plate_file)))
    plan = tmp_path / "plan.json"
    assert run_cli("plan", str(plate_file), "--views", "top", "-q", "-o", str(plan)).exit_code == 0
    record = json.loads(plan.read_text())
    record["context"]["fixtures"] = [lid]  # the plain passes, planned as if in the lid's cell
    lidded = tmp_path / "lidded.json"
    lidded.write_text(json.dumps(record))
    clouds = {}
    for name, path in (("bare", plan), ("lid", lidded)):
        clouds[name] = tmp_path / f"{name}.ply"
        result = run_cli("scan", str(plate_file), str(path), "-o", str(clouds[name]), *POINTS)
        assert result.exit_code == 0, result.output
    bare, hidden = (trimesh.load(clouds[n]).vertices for n in ("bare", "lid"))
    x0 = float(load_part(str(plate_file)).bounds[0, 0])
    lid_end = x0 + 0.4 * 2 * abs(x0)  # the lid covers the first 40 % of the plate's length
    assert (bare[:, 0] < lid_end - 1.0).mean() == pytest.approx(0.4, abs=0.02)
    assert not (hidden[:, 0] < lid_end - 1.0).any()
    assert len(hidden) == pytest.approx(0.6 * len(bare), rel=0.03)
    # Perturbed trials replay the plan among the same fixtures: at zero, the nominal figure.
    zero = ["--perturb", "place:0mm,0deg;warp:0mm@200mm;path:0mm", "--trials", "1"]
    data = _judged(str(plate_file), str(lidded), *zero)
    assert data["in_spec_coverage"] == pytest.approx(0.6, abs=0.02)
    assert data["robustness"]["per_trial"] == [data["in_spec_coverage"]]


def test_a_lid_over_the_whole_part_is_said_in_one_line(plate_file: Path, tmp_path: Path):
    """15 mm above the plate: above the planners' probes' usual start, below the sensor."""
    part = load_part(str(plate_file))
    cover = trimesh.creation.box((*(part.extents[:2] + 100.0), 10.0))
    cover.apply_translation((0.0, 0.0, part.bounds[1, 2] + 20.0))
    cover.export(tmp_path / "cover.stl")
    plan, out = tmp_path / "plan.json", tmp_path / "hidden.json"
    assert run_cli("plan", str(plate_file), "--views", "top", "-q", "-o", str(plan)).exit_code == 0
    hidden = ["--fixture", str(tmp_path / "cover.stl")]
    for args, message in [
        (["plan", str(plate_file), "--views", "top", "-o", str(out)],
         "the fixtures (--fixture) hide all the surface a top-down raster sees"),
        (["plan", str(plate_file), "--views", "top", "--raster", "nominal", "-o", str(out)],
         "sees no surface of part plate: the part is outside the sensor's reach or its fixtures"),
        (["evaluate", str(plate_file), str(plan)], "or hidden by its fixtures"),
    ]:  # fmt: skip
        result = run_cli(*args, *hidden, "-q")
        assert result.exit_code == 2 and message in result.output, result.output
        assert result.output.strip().count("\n") == 0 and not out.exists()
