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
    import scanplan.rl.learn.train as train_module

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
    import scanplan.rl.learn.sweep as sweep

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

    from scanplan.core.plan_file import write_csv
    from scanplan.core.trajectory import Trajectory
    from scanplan.planning.swaths import Swath

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


# ---- held-back siblings (second pass): sensor, robot, policy and trajectory files ------------
def sensor_toml(directory: Path, top: str = "", noise: str = "", body: str = "") -> Path:
    """A small sensor file with `top` (a `key = value` line) replacing its key, and `noise`,
    `body` lines added to those tables."""
    fields = {
        "working_distance_mm": "300", "z_range_mm": "200", "fov_deg": "45",
        "points_per_profile": "64", "z_resolution_um": "2.5", "triangulation_angle_deg": "30",
    }  # fmt: skip
    if top:
        key, value = (p.strip() for p in top.split("="))
        fields[key] = value
    text = "".join(f"{k} = {v}\n" for k, v in fields.items())
    text += f"[noise]\n{noise or 'sigma0_um = 4'}\n" + (f"[body]\n{body}\n" if body else "")
    path = directory / f"s-{abs(hash((top, noise, body)))}.toml"
    path.write_text(text)
    return path


@pytest.mark.parametrize(
    "edit, fragment",
    [
        ({"noise": "speckle_scale_mm = 1e-300"}, "noise.speckle_scale_mm: 1e-300 is not in"),
        ({"noise": "speckle_amplitude_um = 1e300"}, "noise.speckle_amplitude_um: 1e+300 is not"),
        ({"noise": "seed = 99999999999999999999"}, "noise.seed"),
        ({"top": "fov_deg = 1e-300"}, "fov_deg: 1e-300 is not in [0.1, 170) deg"),
        ({"top": "z_resolution_um = 1e300"}, "z_resolution_um"),
        ({"top": "incidence_cutoff_deg = 1e-300"}, "incidence_cutoff_deg"),
        ({"body": "x_mm = [-1e308, 1e308]"}, "body.x_mm[0]: -1e+308 is not in [-5000, 5000] mm"),
        ({"body": "z_mm = [0, 1e-300]"}, "less than 1 mm wide"),
    ],
)
def test_a_sensor_file_with_implausible_values_is_refused(cell_files, tmp_path, edit, fragment):
    sensor = sensor_toml(tmp_path, **edit)
    out = tmp_path / "cloud.ply"
    args = ["scan", str(cell_files / "plate.stl"), str(cell_files / "t.csv"), "-o", str(out)]
    result = runner.invoke(app, [*args, "--sensor", str(sensor)])
    assert_quiet_failure(result, fragment, code=2)
    assert not out.exists()


@pytest.mark.parametrize(
    "edits, fragment",
    [
        ({"accel_mm_s2": "1e-300"}, "accel_mm_s2: 1e-300 is not in"),
        ({"angular_speed_deg_s": "1e308"}, "angular_speed_deg_s"),
        ({"joint_speed_deg_s": "[1e308, 1, 1, 1, 1, 1]"}, "joint_speed_deg_s.0"),
        ({"a2": "0", "c3": "1e-300"}, "the forearm's length hypot(a2, c3)"),
        ({"flange": "[0, 0, 0, 1e300, 0, 0]"}, "flange A,B,C 1e+300"),
        ({"limits_deg": "[[-1e308, 1], [0, 1], [0, 1], [0, 1], [0, 1], [0, 1]]"}, "limits_deg"),
    ],
)
def test_a_robot_file_with_implausible_motion_or_shape_is_refused(
    cell_files, tmp_path, edits, fragment
):
    arm = robot_toml(tmp_path, **edits)
    out = tmp_path / "p.script"
    args = ["export", str(cell_files / "t.csv"), "-o", str(out), "--robot", str(arm)]
    assert_quiet_failure(runner.invoke(app, [*args, "--part", str(cell_files / "plate.stl")]),
                         fragment, code=2)  # fmt: skip
    assert not out.exists()


def test_inverse_kinematics_of_a_singular_pose_is_nan_without_a_warning(tmp_path):
    import warnings

    import numpy as np

    from scanplan.robot import load_robot_file

    arm = load_robot_file(robot_toml(tmp_path, c4="1e-300", a1="0", b="0"))
    T = np.eye(4)[None].repeat(2, axis=0)
    T[1, :3, 3] = (600.0, 0.0, 400.0)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        q = arm.inverse(T)
    assert q.shape == (2, 8, 6)


def _edited_policy(cell_files, tmp_path, edit) -> Path:
    import json
    import shutil

    pol = tmp_path / "pol"
    shutil.copytree(cell_files / "pol", pol)
    meta = json.loads((pol / "policy.json").read_text())
    edit(meta, pol)
    (pol / "policy.json").write_text(json.dumps(meta))
    return pol


@pytest.mark.parametrize(
    "edit, fragment",
    [
        (lambda m, p: m["env"].update(dtheta_max_rad=1e-300), "env.dtheta_max_rad: 1e-300"),
        (
            lambda m, p: m["architecture"].update(hidden=[10**6, 10**6]),
            "the architecture's parameters",
        ),
        (
            lambda m, p: (p / "policy.safetensors").open("ab").write(b"\0" * (2 * 1024**2)),
            "more than the architecture's",
        ),
    ],
    ids=["dtheta", "hidden", "weights"],
)
def test_a_policy_too_large_or_too_fine_is_refused(cell_files, tmp_path, edit, fragment):
    pol = _edited_policy(cell_files, tmp_path, edit)
    out = tmp_path / "x.csv"
    args = ["plan", str(cell_files / "plate.stl"), "-o", str(out), "--planner", "rl"]
    assert_quiet_failure(runner.invoke(app, [*args, "--policy", str(pol)]), fragment, code=2)
    assert not out.exists()


def _json_plan(cell_files, tmp_path, **edits) -> Path:
    import json

    data = json.loads((cell_files / "t.csv").with_suffix(".json").read_text())
    for key, value in edits.items():
        if key == "position":
            data["poses"][3]["position_mm"] = value
        else:
            data[key] = value
    path = tmp_path / "t.json"
    path.write_text(json.dumps(data))
    return path


@pytest.fixture(scope="module")
def json_plan(cell_files):
    from scanplan.core.plan_file import read_csv, write_json

    write_json(read_csv(cell_files / "t.csv"), cell_files / "t.json")
    return cell_files / "t.json"


VIEW = {"index": 0, "axis": [0.0, 0.0, 1.0], "first_swath": 0, "last_swath": 0}


@pytest.mark.parametrize(
    "edits, fragment",
    [
        ({"position": [1e308, 0, 400]}, "poses[3].position_mm[0]: 1e+308 is not in"),
        ({"views": [VIEW] * 10_001}, "views: 10,001 is more than the 10,000 allowed"),
        ({"views": [VIEW | {"axis": [0, 0, 1e308]}]}, "views[0]: axis"),
        ({"views": [VIEW | {"first_swath": 5, "last_swath": 1}]}, "views[0]: swaths 5..1"),
    ],
)
def test_a_trajectory_out_of_range_or_too_long_is_refused(
    cell_files, json_plan, tmp_path, edits, fragment
):
    plan = _json_plan(cell_files, tmp_path, **edits)
    out = tmp_path / "ev"
    result = runner.invoke(
        app, ["evaluate", str(cell_files / "plate.stl"), str(plan), "-o", str(out)]
    )
    assert_quiet_failure(result, fragment, code=2)
    assert not out.exists()


def test_a_trajectory_csv_position_of_1e308_is_refused_naming_line_and_column(cell_files, tmp_path):
    plan = tmp_path / "t.csv"
    lines = (cell_files / "t.csv").read_text().splitlines()
    lines[3] = lines[3].replace("-40.000000", "1e308", 1)
    plan.write_text("\n".join(lines) + "\n")
    out = tmp_path / "p.script"
    result = runner.invoke(app, ["export", str(plan), "-o", str(out), "--robot", "none"])
    assert_quiet_failure(result, "line 4, column x_mm: 1e+308 is not in", code=2)
    assert not out.exists()


# ---- sizes checked before anything is read or allocated -------------------------------------
def test_units_of_a_built_in_part_are_checked_too(tmp_path):
    out = tmp_path / "x.csv"
    result = runner.invoke(app, ["plan", "door", "-o", str(out), "--units", "furlong"])
    assert_quiet_failure(result, "unknown units 'furlong'", code=2)
    assert not out.exists()


def test_a_binary_stl_announcing_too_many_triangles_is_not_read(tmp_path):
    from scanplan.core.limits import MAX_TRIANGLES

    stl = tmp_path / "huge.stl"
    count = MAX_TRIANGLES + 1
    with stl.open("wb") as f:  # sparse: the size its header announces, next to no disk
        f.write(b"\0" * 80 + count.to_bytes(4, "little"))
        f.truncate(84 + 50 * count)
    out = tmp_path / "x.csv"
    result = runner.invoke(app, ["plan", str(stl), "-o", str(out)])
    assert_quiet_failure(result, "triangles: 20,000,001 is more than", code=2)
    assert not out.exists()


@pytest.mark.parametrize(
    "module, name, fragment",
    [
        ("scanplan.sensor.profilometer", "MAX_RAYS", "rays to cast (21 poses x 4,096 points"),
        ("scanplan.sensor.cloud", "MAX_CLOUD_POINTS", "points the cloud would hold"),
    ],
)
def test_scan_counts_its_rays_and_points_before_measuring(
    cell_files, tmp_path, monkeypatch, module, name, fragment
):
    import importlib

    monkeypatch.setattr(importlib.import_module(module), name, 1000)
    out = tmp_path / "cloud.ply"
    args = ["scan", str(cell_files / "plate.stl"), str(cell_files / "t.csv"), "-o", str(out)]
    assert_quiet_failure(runner.invoke(app, args), fragment, code=2)
    assert not out.exists()


# ---- a stop that a library swallowed still stops, and writes nothing ------------------------
def test_a_swallowed_sigterm_still_ends_in_143_and_writes_nothing(
    cell_files, tmp_path, monkeypatch
):
    import signal

    import scanplan.core.files as files
    import scanplan.core.plan as plan_file

    read = plan_file.read_trajectory

    def read_then_swallow(path):  # as trimesh does around an optional import
        files.stopped_by = signal.SIGTERM
        return read(path)

    monkeypatch.setattr(plan_file, "read_trajectory", read_then_swallow)
    out = tmp_path / "out" / "p.script"
    args = ["export", str(cell_files / "t.csv"), "-o", str(out), "--robot", "none"]
    result = runner.invoke(app, args)
    assert_quiet_failure(result, "terminated", code=143)
    assert not out.parent.exists() or list(out.parent.iterdir()) == []  # no .p.script.*.tmp
    assert files.stopped_by is None or runner.invoke(app, ["part", "--help"]).exit_code == 0


def test_a_signal_while_the_modules_load_is_one_line(monkeypatch, capsys):
    import os
    import signal
    import sys
    import types

    import scanplan.__main__ as entry

    class Loading(types.ModuleType):
        def __getattr__(self, name):
            os.kill(os.getpid(), signal.SIGTERM)  # arrives while `from scanplan.cli import app`
            return lambda: None

    monkeypatch.setitem(sys.modules, "scanplan.cli", Loading("scanplan.cli"))
    monkeypatch.setattr(entry, "_received", [])
    before = signal.getsignal(signal.SIGTERM)
    with pytest.raises(SystemExit) as exit_:
        entry.main()
    assert exit_.value.code == 143
    assert capsys.readouterr().err == "terminated\n"
    assert signal.getsignal(signal.SIGTERM) is before
