"""Issue 26: every number checked at the edge, every size bounded, every run interruptible.
Each case ends in exit != 0, at most two lines on stderr, no traceback, nothing left behind.
"""

from __future__ import annotations

from pathlib import Path

import pytest
from typer.testing import CliRunner

from scanplan.cli import app

runner = CliRunner()


def assert_quiet_failure(result, *fragments: str, code: int | None = None) -> None:
    assert result.exit_code != 0, (result.stdout, result.stderr)
    if code is not None:
        assert result.exit_code == code, (result.exit_code, result.stderr)
    assert len(result.stderr.splitlines()) <= 2, result.stderr
    assert "Traceback" not in result.output and "internal error" not in result.stderr
    for fragment in fragments:
        assert fragment in result.stderr, result.stderr


def tree(path: Path) -> dict[str, bytes]:
    return {str(p.relative_to(path)): p.read_bytes() for p in path.rglob("*") if p.is_file()}


# ---- train -o: written aside, swapped in at the end -----------------------------------------
@pytest.fixture()
def previous_run(tmp_path) -> Path:
    """A folder holding an earlier run's policy and log."""
    out = tmp_path / "policy"
    (out / "checkpoints").mkdir(parents=True)
    (out / "policy.json").write_text('{"old": true}')
    (out / "policy.safetensors").write_bytes(b"old weights")
    (out / "progress.csv").write_text("time/total_timesteps\n128\n")
    (out / "checkpoints" / "ppo_128.json").write_text("{}")
    return out


def fake_training(monkeypatch, fail: type[BaseException] | None):
    """train's inner loop replaced: writes a log and a checkpoint, then fails or finishes."""
    import scanplan.learn.train as train_module

    def train_into(config, ckpt, work, out):
        (work / "checkpoints").mkdir()
        (work / "checkpoints" / "ppo_64.json").write_text("{}")
        (work / "progress.csv").write_text("time/total_timesteps\n64\n")
        if fail is not None:
            raise fail
        (work / "policy.json").write_text('{"new": true}')
        return train_module.TrainResult(
            out,
            out / "policy.json",
            out / "policy.safetensors",
            out / "progress.csv",
            (),
            64,
            1.0,
            {"reward_per_step": 0.0, "r_d": 0.0, "r_alpha": 0.0, "r_delta_s": 0.0},
        )

    monkeypatch.setattr(train_module, "_train_into", train_into)


@pytest.mark.parametrize("fail, code", [(KeyboardInterrupt, 130), (RuntimeError("boom"), 1)])
def test_interrupted_train_leaves_the_previous_policy_whole(previous_run, monkeypatch, fail, code):
    before = tree(previous_run)
    fake_training(monkeypatch, fail)
    result = runner.invoke(app, ["train", "-o", str(previous_run), "--timesteps", "64"])
    assert result.exit_code == code and len(result.stderr.splitlines()) <= 2
    assert "Traceback" not in result.output
    assert tree(previous_run) == before
    assert [p.name for p in previous_run.parent.iterdir()] == ["policy"]  # no temporary left


def test_a_finished_train_replaces_the_folder_whole(previous_run, monkeypatch):
    fake_training(monkeypatch, None)
    result = runner.invoke(app, ["train", "-o", str(previous_run), "--timesteps", "64"])
    assert result.exit_code == 0, result.stderr
    # The old run's log and checkpoints are gone with it: never mixed with the new ones.
    assert sorted(tree(previous_run)) == ["checkpoints/ppo_64.json", "policy.json", "progress.csv"]
    assert [p.name for p in previous_run.parent.iterdir()] == ["policy"]


def test_an_interrupted_new_train_keeps_its_checkpoints_to_resume(tmp_path, monkeypatch):
    fake_training(monkeypatch, KeyboardInterrupt)
    out = tmp_path / "new"
    result = runner.invoke(app, ["train", "-o", str(out), "--timesteps", "64"])
    assert result.exit_code == 130
    assert (out / "checkpoints" / "ppo_64.json").is_file()
    assert [p.name for p in tmp_path.iterdir()] == ["new"]


def test_train_refuses_to_replace_a_folder_of_something_else(tmp_path, monkeypatch):
    fake_training(monkeypatch, None)
    mine = tmp_path / "mine"
    mine.mkdir()
    (mine / "notes.txt").write_text("keep")
    result = runner.invoke(app, ["train", "-o", str(mine), "--timesteps", "64"])
    assert_quiet_failure(result, "not empty", code=2)
    assert tree(mine) == {"notes.txt": b"keep"}


# ---- sweep: everything checked before a worker starts ---------------------------------------
SWEEP_CASES = [
    (["--grid", "total_timesteps=abc"], "total_timesteps 'abc'"),
    (["--grid", "learning_rate=[1,2]"], "learning_rate"),
    (["--grid", "gamma=0.5,2"], "gamma 2"),
    (["--grid", "env.fan_points=1"], "fan_points"),
    (["--grid", "output_dir=x"], "output_dir"),
    (["--seeds", "inf"], "--seeds 'inf'"),
    (["--seeds", "1,1"], "given twice"),
    (["--seeds", "99999999999"], "99999999999 is not in"),
    (["--part", "nosuch.stl"], "nosuch.stl"),
    (["--scheduler", "localhost"], "--scheduler"),
    (["--timesteps", "-1"], "--timesteps"),
]


@pytest.mark.parametrize("args, fragment", SWEEP_CASES, ids=[" ".join(a) for a, _ in SWEEP_CASES])
def test_sweep_fails_early_and_quietly(tmp_path, monkeypatch, args, fragment):
    pytest.importorskip("dask.distributed")
    import scanplan.learn.sweep as sweep

    def no_cluster(*a, **kw):
        raise AssertionError("a worker started")

    monkeypatch.setattr(sweep, "connect", no_cluster)
    out = tmp_path / "a" / "sweep"
    result = runner.invoke(app, ["sweep", "-o", str(out), *args])
    assert_quiet_failure(result, fragment, code=2)
    assert list(tmp_path.iterdir()) == []


# ---- huge or ill-typed numbers: refused at the edge, naming the option and the range -------
@pytest.fixture(scope="module")
def cell_files(tmp_path_factory) -> Path:
    """A 600 mm plate, a 21-pose plan over it, a robot TOML and the default policy's copy."""
    import shutil

    import numpy as np
    import trimesh

    from scanplan.swaths import Swath
    from scanplan.trajectory import Trajectory, write_csv

    d = tmp_path_factory.mktemp("limits")
    plate = trimesh.creation.box((600, 600, 10))
    plate.apply_translation((0, 0, -5))
    plate.export(d / "plate.stl")
    sw = Swath(0, np.array([-50.0, 0, 400]), np.array([50.0, 0, 400]), np.eye(3)[0], np.eye(3)[1])
    poses = sw.poses(np.linspace(0, 100, 21), np.zeros(21), np.zeros(21))
    write_csv(Trajectory(poses, np.zeros(21, int), np.ones(21, bool)), d / "t.csv")
    shutil.copytree(Path(__file__).parents[2] / "src/scanplan/policies/default", d / "pol")
    return d


def robot_toml(directory: Path, **edits: str) -> Path:
    text = {
        "a1": "25", "a2": "-35", "c1": "400", "c2": "455", "c3": "420", "c4": "80",
        "offsets_deg": "[0, -90, 0, 0, 0, 0]", "sign": "[-1, 1, 1, -1, 1, -1]",
        "limits_deg": "[[-170, 170], [-190, 45], [-120, 156], [-185, 185], [-120, 120], "
        "[-350, 350]]",
    } | edits  # fmt: skip
    path = directory / f"arm-{abs(hash(tuple(edits.items())))}.toml"
    path.write_text("".join(f"{k} = {v}\n" for k, v in text.items()))
    return path


HUGE_CASES = [
    (["evaluate", "{d}/plate.stl", "{d}/t.csv", "--tolerance", "1e308,90"], "--tolerance"),
    (["plan", "{d}/plate.stl", "-o", "{o}/x.csv", "--tolerance", "1e-300,15"], "--tolerance"),
    (["train", "-o", "{o}/pol", "--init-advance", "1e308"], "--init-advance"),
    (["train", "-o", "{o}/pol", "--init-advance", "-7"], "--init-advance"),
    (["train", "-o", "{o}/pol", "--timesteps", "100000000000000"], "--timesteps"),
    (
        [
            "export",
            "{d}/t.csv",
            "-o",
            "{o}/p.script",
            "--robot",
            "none",
            "--profile-rate",
            "1e308",
            "--spacing",
            "1e308",
        ],
        "--profile-rate",
    ),  # fmt: skip
    (
        [
            "export",
            "{d}/t.csv",
            "-o",
            "{o}/p.script",
            "--robot",
            "none",
            "--profile-rate",
            "20000",
            "--spacing",
            "1",
        ],
        "scan speed of 20000 mm/s",
    ),  # fmt: skip
    (
        ["export", "{d}/t.csv", "-o", "{o}/p.script", "--robot", "none", "--travel-speed", "1e300"],
        "--travel-speed",
    ),  # fmt: skip
    (
        ["export", "{d}/t.csv", "-o", "{o}/p.script", "--robot", "none", "--chord-tol", "1e-300"],
        "--chord-tol",
    ),  # fmt: skip
    (
        ["place", "{d}/t.csv", "--part", "{d}/plate.stl", "--robot", "ur5e", "--yaw-step", "1e-9"],
        "candidate placements",
    ),  # fmt: skip
    (
        ["place", "{d}/t.csv", "--part", "{d}/plate.stl", "--robot", "ur5e", "--yaw-step", "0.001"],
        "candidate placements",
    ),  # fmt: skip
    (
        [
            "place",
            "{d}/t.csv",
            "--part",
            "{d}/plate.stl",
            "--robot",
            "ur5e",
            "--height-range",
            "-1e308,1e308",
        ],
        "--height-range",
    ),  # fmt: skip
    (
        [
            "plan",
            "{d}/plate.stl",
            "-o",
            "{o}/x.csv",
            "--raster",
            "nominal",
            "--overlap",
            "0.999999999999",
        ],
        "passes of one view",
    ),  # fmt: skip
    (
        ["plan", "{d}/plate.stl", "-o", "{o}/x.csv", "--raster", "nominal", "--overlap", "0.99999"],
        "passes of one view",
    ),  # fmt: skip
]


@pytest.mark.parametrize(
    "args, fragment", HUGE_CASES, ids=[" ".join(a[:1] + a[-2:]) for a, _ in HUGE_CASES]
)
def test_huge_numbers_are_refused_naming_the_option(cell_files, tmp_path, args, fragment):
    out = tmp_path / "out"
    out.mkdir()
    args = [a.format(d=cell_files, o=out) for a in args]
    assert_quiet_failure(runner.invoke(app, args), fragment, code=2)
    assert list(out.iterdir()) == []


@pytest.mark.parametrize(
    "edits, field",
    [
        ({"c2": "inf"}, "c2"),
        ({"c2": "1e-300"}, "c2"),
        ({"a2": "1e308"}, "a2"),
        ({"c4": "1e300"}, "c4"),
        ({"b": "-inf"}, "b"),
        ({"base": "[1e308, 0, 0, 0, 0, 0]"}, "base"),
        ({"offsets_deg": "[0, 1e300, 0, 0, 0, 0]"}, "offsets_deg"),
        ({"speed_mm_s": "1e308"}, "speed_mm_s"),
    ],
)
def test_a_robot_file_with_impossible_lengths_is_refused(cell_files, tmp_path, edits, field):
    arm = robot_toml(tmp_path, **edits)
    out = tmp_path / "p.script"
    result = runner.invoke(app, ["export", str(cell_files / "t.csv"), "-o", str(out), "--robot",
                                 str(arm)])  # fmt: skip
    assert_quiet_failure(result, field, code=2)
    assert not out.exists()


@pytest.mark.parametrize(
    "key, value", [("dy_max_mm", 1e-300), ("dz_max_mm", 1e300), ("segment_mm", [1e-300, 1e300])]
)
def test_a_policy_with_impossible_steps_is_refused(cell_files, tmp_path, key, value):
    import json
    import shutil

    pol = tmp_path / "pol"
    shutil.copytree(cell_files / "pol", pol)
    meta = json.loads((pol / "policy.json").read_text())
    meta["env"][key] = value
    (pol / "policy.json").write_text(json.dumps(meta))
    out = tmp_path / "x.csv"
    args = ["plan", str(cell_files / "plate.stl"), "-o", str(out), "--planner", "rl"]
    assert_quiet_failure(runner.invoke(app, [*args, "--policy", str(pol)]), key, code=2)
    assert not out.exists()
