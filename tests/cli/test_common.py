"""The command line's error contract (SPEC §8): a user mistake — an unknown option, a bad or
out-of-bounds value, a crafted input file — ends with one line on stderr naming the option or
file, exit code 2, no traceback and no partial output; long work shows progress on a terminal
only."""

from __future__ import annotations

import errno
import json
import os
import struct
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import trimesh
import typer
from hypothesis import HealthCheck, event, given, settings
from hypothesis import strategies as st
from typer.testing import CliRunner

from helpers import ROOT
from scanplan.cli import app
from scanplan.cli.common import progress_bar
from scanplan.core.plan_file import CSV_COLUMNS, write_csv
from scanplan.core.trajectory import Trajectory

runner = CliRunner()
SRC = ROOT / "src"


@pytest.fixture(scope="module")
def files(tmp_path_factory) -> Path:
    """A small plate (1 s to plan) and a 5-pose trajectory over it at the working distance."""
    d = tmp_path_factory.mktemp("cli")
    plate = trimesh.creation.box((120, 120, 10))
    plate.apply_translation((0, 0, -5))
    plate.export(d / "plate.stl")
    poses = np.tile(np.diag([1.0, -1.0, -1.0, 1.0]), (5, 1, 1))
    poses[:, :3, 3] = np.c_[np.linspace(-20, 20, 5), np.zeros(5), np.full(5, 400.0)]
    write_csv(Trajectory(poses, np.zeros(5, int), np.ones(5, bool)), d / "good.csv")
    return d


def assert_one_line_error(result, *fragments: str) -> None:
    assert result.exit_code == 2, (result.stdout, result.stderr, result.exception)
    lines = result.stderr.splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: "), result.stderr
    assert "Traceback" not in result.output and "╭" not in result.output
    for fragment in fragments:
        assert fragment in lines[0], lines[0]


# ---- options ------------------------------------------------------------------------------
USAGE_CASES = [
    (["plan"], "Missing argument 'part'"),
    (["plan", "door", "--bogus"], "No such option: --bogus"),
    (["frobnicate"], "No such command 'frobnicate'"),
    (["export", "t.csv"], "Missing option '-o'"),
    (["plan", "door", "-o"], "Option '-o' requires an argument"),
    (["evaluate", "door", "t.csv", "--points", "abc"], "--points: 'abc' is not a valid integer"),
    (["evaluate", "door", "t.csv", "--points", "1"], "--points: 1 is not in [2, 100000]"),
    (["demo", "--points", "100001"], "--points: 100001 is not in [2, 100000]"),
    (["scan", "p", "t", "-o", "c.ply", "--seed", "-1"], "--seed: -1 is not in [0, 4294967295]"),
    (["scan", "p", "t", "-o", "c.ply", "--seed", "1e3"], "--seed: '1e3' is not a valid integer"),
    (["train", "-o", "d", "--timesteps", "0"], "--timesteps: 0 is not in [1, 10000000000]"),
    (["train", "-o", "d", "--n-envs", "0"], "--n-envs: 0 is not in [1, 1024]"),
    (["train", "-o", "d", "--fan-points", "1"], "--fan-points: 1 is not in [2, 100000]"),
    (["train", "-o", "d", "--procedural", "-3"], "--procedural: -3 is not in [0, 1000]"),
    (["train", "-o", "d", "--bc-samples", "-1"], "--bc-samples: -1 is not in [0, 10000000]"),
    (["train", "-o", "d", "--init-advance", "inf"], "--init-advance: inf is not a finite number"),
    (["plan", "door", "-o", "x.csv", "--overlap", "1"], "--overlap: 1 is not in [0, 1)"),
    (["plan", "door", "-o", "x.csv", "--overlap", "nan"], "--overlap: nan is not a finite"),
    (["plan", "door", "-o", "x.csv", "--roll=yes"], "Option '--roll' does not take a value"),
    (["export", "t.csv", "-o", "p", "--spacing", "nan"], "--spacing: nan is not a finite number"),
    (["export", "t.csv", "-o", "p", "--spacing", "0"], "--spacing: 0 is not in [0.001, 1000]"),
    (["export", "t.csv", "-o", "p", "--profile-rate", "-5"], "--profile-rate: -5 is not in [0.1,"),
    (["export", "t.csv", "-o", "p", "--travel-speed", "inf"], "--travel-speed: inf is not a"),
    (["export", "t.csv", "-o", "p", "--tcp", "1,2"], "--tcp: pose '1,2': expected 6"),
    (["export", "t.csv", "-o", "p", "--part-pose", "0,0,0,0,0,nan"], "--part-pose: pose"),
    (["place", "t.csv", "--robot", "ur5e", "--yaw-step", "0"], "--yaw-step: 0 is not in (0, 360]"),
]


@pytest.mark.parametrize("args, fragment", USAGE_CASES, ids=lambda a: " ".join(a)[:40])
def test_usage_error_is_one_line_naming_the_option(tmp_path, monkeypatch, args, fragment):
    monkeypatch.chdir(tmp_path)
    assert_one_line_error(runner.invoke(app, args), fragment)
    assert list(tmp_path.iterdir()) == []


def test_value_errors_name_the_option(files, tmp_path):
    """Checked in the command (after parsing): still one line that names the option."""
    plate, good = files / "plate.stl", files / "good.csv"
    cases = [
        (["plan", str(plate), "-o", "x.csv", "--tolerance", "nan,15"], "--tolerance 'nan,15'"),
        (["place", str(good), "--robot", "ur5e", "--height-range", "1,inf"], "--height-range"),
        (["train", "-o", "d", "--log-std-init", "0,x"], "--log-std-init '0,x'"),
    ]
    for args, fragment in cases:
        assert_one_line_error(runner.invoke(app, args), fragment)


def test_entry_point_one_line_and_rich_help(tmp_path):
    """Through `python -m scanplan`, the way a user runs it, not only CliRunner."""
    env = {**os.environ, "PYTHONPATH": str(SRC), "COLUMNS": "100"}

    def run(*args: str) -> subprocess.CompletedProcess[str]:
        cmd = [sys.executable, "-m", "scanplan", *args]
        return subprocess.run(cmd, capture_output=True, text=True, env=env, cwd=tmp_path)

    bad = run("evaluate", "door", "t.csv", "--points", "abc")
    assert bad.returncode == 2 and bad.stdout == ""
    assert bad.stderr.splitlines() == [
        "error: --points: 'abc' is not a valid integer (see 'python -m scanplan evaluate --help')"
    ]
    unknown = run("plan", "door", "--frobnicate")
    assert unknown.returncode == 2 and len(unknown.stderr.splitlines()) == 1
    assert "No such option: --frobnicate" in unknown.stderr
    helped = run("plan", "--help")
    assert helped.returncode == 0 and helped.stderr == ""
    assert "╭─ Options" in helped.stdout and "--overlap" in helped.stdout
    assert list(tmp_path.iterdir()) == []


# ---- outputs ------------------------------------------------------------------------------
def test_train_leaves_no_output_directory_after_an_early_error(tmp_path):
    out = tmp_path / "runs" / "policy"
    result = runner.invoke(app, ["train", "-o", str(out), "--part", "teapot", "--timesteps", "8"])
    assert_one_line_error(result, "teapot")
    assert list(tmp_path.iterdir()) == []  # not even the parent it made
    kept = tmp_path / "mine"
    kept.mkdir()
    result = runner.invoke(app, ["train", "-o", str(kept), "--part", str(tmp_path / "no.stl")])
    assert_one_line_error(result, "no.stl")
    assert kept.is_dir()  # a directory the user had is left alone


def test_demo_leaves_no_output_directory_after_an_early_error(tmp_path):
    out = tmp_path / "a" / "demo"
    result = runner.invoke(app, ["demo", "-o", str(out), "--part", "teapot"])
    assert_one_line_error(result, "teapot")
    assert list(tmp_path.iterdir()) == []


def half_then_full_disk(monkeypatch) -> None:
    """Every file opened by the atomic writer takes half its bytes, then the disk is full."""
    real_fdopen = os.fdopen

    class HalfFile:
        def __init__(self, f):
            self.f = f

        def write(self, data):
            self.f.write(data[: len(data) // 2])
            self.f.flush()
            raise OSError(errno.ENOSPC, "No space left on device")

        def __enter__(self):
            return self

        def __exit__(self, *exc):
            self.f.close()

    monkeypatch.setattr(os, "fdopen", lambda fd, *a, **k: HalfFile(real_fdopen(fd, *a, **k)))


@pytest.mark.parametrize("command", ["plan", "scan", "export", "part"])
def test_interrupted_write_leaves_no_file(files, tmp_path, monkeypatch, command):
    plate, good = str(files / "plate.stl"), str(files / "good.csv")
    args = {
        "plan": ["plan", plate, "-o", str(tmp_path / "t.csv"), "--planner", "fixed"],
        "scan": ["scan", plate, good, "-o", str(tmp_path / "c.ply")],
        "export": ["export", good, "--robot", "none", "-o", str(tmp_path / "p.script")],
        "part": ["part", "training-piece", "-o", str(tmp_path / "tp.stl")],
    }[command]
    half_then_full_disk(monkeypatch)
    assert_one_line_error(runner.invoke(app, args), "No space left on device")
    assert list(tmp_path.iterdir()) == []


# ---- progress -----------------------------------------------------------------------------
def test_progress_is_reported_by_the_library_and_quiet_off_a_terminal(files, monkeypatch):
    from scanplan.core.plan_file import read_csv
    from scanplan.core.quantities import ScanSpec
    from scanplan.planning.pass_path import plan_scan
    from scanplan.rl.planners import make_planner
    from scanplan.sensor.cloud import simulate_cloud
    from scanplan.world.part import load_part

    part, spec = load_part(str(files / "plate.stl")), ScanSpec()
    calls: list[tuple[int, int]] = []
    swaths, traj = plan_scan(
        part, spec, make_planner("fixed"), "nominal", progress=lambda *a: calls.append(a)
    )
    assert calls == [(i + 1, len(swaths)) for i in range(len(swaths))]
    good = read_csv(files / "good.csv")
    calls.clear()
    simulate_cloud(part, spec.sensor, good, chunk_poses=2, progress=lambda *a: calls.append(a))
    assert calls == [(2, 5), (4, 5), (5, 5)]

    # On a terminal a bar is fed; off one (or with --quiet) nothing is drawn at all.
    with progress_bar("x", quiet=True) as update:
        assert update is None
    with progress_bar("x", quiet=False) as update:
        assert update is None  # pytest's stderr is not a terminal
    monkeypatch.setattr(sys.stderr, "isatty", lambda: True, raising=False)
    with progress_bar("x", quiet=False) as update:
        assert update is not None
        update(1, 2)
    result = runner.invoke(app, ["evaluate", str(files / "plate.stl"), str(files / "good.csv")])
    # No bar off a terminal; one line on what a plan file without a context was judged by.
    assert result.exit_code == 0
    assert result.stderr.splitlines() == [
        f"note: plan {files / 'good.csv'} records no context (an older or foreign file): "
        "assumed the default sensor and tolerances and the top surface"
    ]


def test_evaluate_progress_callback_signature(files):
    """metrics.evaluate calls progress(done, total)."""
    from scanplan.core.plan_file import read_csv
    from scanplan.core.quantities import ScanSpec
    from scanplan.judging import evaluate
    from scanplan.world.part import load_part

    calls: list[tuple[int, int]] = []
    part, good = load_part(str(files / "plate.stl")), read_csv(files / "good.csv")
    evaluate(part, ScanSpec(), good, points_per_profile=64, chunk_poses=2,
             progress=lambda *a: calls.append(a))  # fmt: skip
    assert calls == [(2, 5), (4, 5), (5, 5)]


# ---- crafted files run nothing --------------------------------------------------------------
# Covered elsewhere: YAML/TOML sensor files with python tags and arbitrary bytes, trajectory
# CSV/JSON of arbitrary values, meshes of arbitrary bytes (tests/test_loaders_hostile.py);
# pickled policies (tests/test_policy.py); SB3 .zip and pickled checkpoints (tests/test_train.py).
def _glb(doc: dict) -> bytes:
    j = json.dumps(doc).encode()
    j += b" " * (-len(j) % 4)
    return b"glTF" + struct.pack("<II", 2, 20 + len(j)) + struct.pack("<I", len(j)) + b"JSON" + j


@pytest.fixture()
def crafted(tmp_path) -> Path:
    d = tmp_path / "crafted"
    d.mkdir()
    pwned = d / "PWNED"
    (d / "secret.txt").write_text("x" * 36)
    files = {
        "robot.toml": f'name = "!!python/object/apply:os.system [\\"touch {pwned}\\"]"\n'
        "a1 = \"__import__('os').system('touch PWNED')\"\n",
        "deep.toml": "a = " + "[" * 5000 + "]" * 5000 + "\n",
        "huge_vertices.ply": (
            b"ply\nformat binary_little_endian 1.0\n"
            b"element vertex 4000000000\nproperty float x\nproperty float y\nproperty float z\n"
            b"element face 4000000000\nproperty list uchar int vertex_indices\nend_header\n"
        )
        + bytes(64),
        "huge_list.ply": b"ply\nformat binary_little_endian 1.0\nelement vertex 3\n"
        b"property float x\nproperty float y\nproperty float z\nelement face 1\n"
        b"property list uint int vertex_indices\nend_header\n"
        + struct.pack("<9f", 0, 0, 0, 1, 0, 0, 0, 1, 0)
        + struct.pack("<I", 4_000_000_000)
        + b"\0" * 12,
        "scripted.glb": _glb(
            {
                "asset": {"version": "2.0"},
                "extensionsUsed": ["KHR_draco_mesh_compression", "EXT_script"],
                "extensionsRequired": ["KHR_draco_mesh_compression", "EXT_script"],
                "extras": {"script": f"__import__('os').system('touch {pwned}')"},
                # A buffer outside the file: a GLB is read from memory, never from beside it.
                "buffers": [{"uri": "../crafted/secret.txt", "byteLength": 36}],
                "bufferViews": [{"buffer": 0, "byteLength": 36}],
                "accessors": [{"bufferView": 0, "componentType": 5126, "count": 3, "type": "VEC3"}],
                "meshes": [{"primitives": [{"attributes": {"POSITION": 0}}]}],
                "nodes": [{"mesh": 0}],
                "scenes": [{"nodes": [0]}],
                "scene": 0,
            }
        ),
    }
    for name, content in files.items():
        path = d / name
        path.write_bytes(content if isinstance(content, bytes) else content.encode())
    return d


@pytest.mark.parametrize(
    "args, fragment",
    [
        (["export", "{good}", "--robot", "{d}/robot.toml", "-o", "{out}/p.script"], "robot.toml"),
        (["export", "{good}", "--robot", "{d}/deep.toml", "-o", "{out}/p.script"], "deep.toml"),
        (["place", "{good}", "--robot", "{d}/robot.toml"], "robot.toml"),
        (["plan", "{d}/huge_vertices.ply", "-o", "{out}/t.csv"], "huge_vertices.ply"),
        (["plan", "{d}/huge_list.ply", "-o", "{out}/t.csv"], "huge_list.ply"),
        (["scan", "{d}/scripted.glb", "{good}", "-o", "{out}/c.ply"], "scripted.glb"),
    ],
    ids=lambda a: a[0] + "-" + Path(a[1 if a[0] != "export" else 3]).name,
)
def test_crafted_file_runs_nothing(files, crafted, tmp_path, args, fragment):
    out = tmp_path / "out"
    out.mkdir()
    argv = [a.format(d=crafted, good=files / "good.csv", out=out) for a in args]
    assert_one_line_error(runner.invoke(app, argv), fragment)
    assert not (crafted / "PWNED").exists() and not Path("PWNED").exists()
    assert list(out.iterdir()) == []


# ---- any argument list: exit 0 or one line and exit 2 ---------------------------------------
def _options() -> dict[str, list[tuple[str, bool]]]:
    """Each command's options from the real app: (name, is a flag)."""
    group = typer.main.get_command(app)
    table: dict[str, list[tuple[str, bool]]] = {}
    for name, command in group.commands.items():  # type: ignore[attr-defined]
        table[name] = [
            (opt, bool(getattr(p, "is_flag", False)))
            for p in command.params
            if p.param_type_name == "option"
            for opt in (*p.opts, *p.secondary_opts)
            if opt != "--help"
        ]
    return table


OPTIONS = _options()
ALL_OPTIONS = sorted({o for opts in OPTIONS.values() for o, _ in opts})
VALUES = [
    "", "abc", "nan", "-nan", "inf", "-inf", "-1", "0", "1", "2", "0.5", "1.5", "1e3", "1e400",
    "100001", "2,15", "0,0", "1,2,3", "1,2,3,4,5,6", "1,2,3,4,5,nan", "0,0,0,0,0,0", "x,y",
    "fixed", "geometric", "rl", "auto", "x", "nominal", "urscript", "krl", "csv", "none", "ur5e",
    "v1", "paper", "-", "--", "é", "a b", "{plate}", "{good}", "{out}/missing.stl", "{d}",
    "{out}/o.csv", "{out}/o.ply", "{out}/o.json", "{out}/o.script", "{out}/o.txt", "{out}/dir",
]  # fmt: skip
POSITIONAL = ["{plate}", "{good}", "teapot", "{d}/missing.csv", "{d}", "nan"]
# What each command needs to run (so most examples get past parsing into the command).
NEEDS = {
    "part": ["training-piece", "-o", "{out}/tp.stl"],
    "plan": ["{plate}", "-o", "{out}/t.csv"],
    "scan": ["{plate}", "{good}", "-o", "{out}/c.ply"],
    "evaluate": ["{plate}", "{good}"],
    "export": ["{good}", "-o", "{out}/p.script"],
    "place": ["{good}", "--robot", "ur5e"],
    "train": ["-o", "{out}/policy"],
    "demo": ["-o", "{out}/demo"],
    "sweep": ["-o", "{out}/sweep"],
    "view": ["{good}", "-o", "{out}/v.html"],
    "defects": ["{plate}", "{good}"],
    "compare": ["{plate}", "--points", "16"],
}


@st.composite
def argument_lists(draw) -> list[str]:
    command = draw(st.sampled_from(sorted(OPTIONS)))
    if draw(st.integers(0, 3)) > 0:
        args = list(NEEDS[command])
    else:
        args = draw(st.lists(st.sampled_from(POSITIONAL), max_size=3))
        if draw(st.booleans()):
            args += ["-o", draw(st.sampled_from(VALUES[-6:]))]
    own = OPTIONS[command]
    for _ in range(draw(st.integers(0, 3))):
        foreign = not own or draw(st.integers(0, 5)) == 0
        name, flag = (draw(st.sampled_from(ALL_OPTIONS)), False) if foreign else draw(
            st.sampled_from(own))  # fmt: skip
        option = [name]
        if not flag and draw(st.integers(0, 9)) > 0:
            option.append(draw(st.sampled_from(VALUES)))
        args += option
    return [command, *args]


def _stop(*args, **kwargs):
    raise typer.Exit(0)  # a run that got this far parsed its options: skip the long work


@pytest.mark.slow
@settings(
    max_examples=300,
    deadline=None,
    suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow],
)
@given(args=argument_lists())
def test_any_argument_list_exits_0_or_one_line_2(files, tmp_path_factory, args):
    # The jobs imported before patching: each binds the stage it calls at its import, and
    # is patched where it looks the stage up.
    import scanplan.jobs.compare
    import scanplan.jobs.defects
    import scanplan.jobs.demo
    import scanplan.jobs.place
    import scanplan.rl.learn.sweep
    import scanplan.rl.learn.train

    out = tmp_path_factory.mktemp("out")
    argv = [a.format(plate=files / "plate.stl", good=files / "good.csv", d=files, out=out)
            for a in args]  # fmt: skip
    with pytest.MonkeyPatch.context() as mp:
        mp.chdir(out)
        mp.setattr(scanplan.rl.learn.train, "train", _stop)
        mp.setattr(scanplan.jobs.demo, "run_demo", _stop)
        mp.setattr(scanplan.jobs.place, "place", _stop)
        mp.setattr(scanplan.rl.learn.sweep, "connect", _stop)  # no cluster, no training
        mp.setattr(scanplan.jobs.defects, "defect_tasks", _stop)  # no defect trials
        mp.setattr(scanplan.jobs.compare, "compare", _stop)  # no plans, no evaluations
        result = runner.invoke(app, argv)
    event(f"{args[0]} exit {result.exit_code}")
    assert result.exit_code in (0, 2), (argv, result.output, result.exception)
    assert "Traceback" not in result.output, argv
    if result.exit_code == 2:
        lines = result.stderr.splitlines()
        assert len(lines) == 1 and lines[0].startswith("error: "), (argv, result.stderr)
        assert list(out.iterdir()) == [], argv
    assert sorted(p.name for p in files.iterdir()) == ["good.csv", "plate.stl"], argv


# ---- hostile input files: one line, exit 2, no output of any kind ------------------------
@pytest.fixture(scope="module")
def hostile(tmp_path_factory):
    d = tmp_path_factory.mktemp("hostile")
    files = {
        "lying.stl": b"\0" * 80 + struct.pack("<I", 1000) + b"\0" * 50,
        "random.obj": os.urandom(200),
        "badidx.ply": b"ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\n"
        b"property float y\nproperty float z\nelement face 1\n"
        b"property list uchar int vertex_indices\nend_header\n0 0 0\n1 0 0\n0 1 0\n3 0 1 9\n",
        "huge.stl": b"\0" * 80
        + struct.pack("<I", 1)
        + struct.pack("<12f", 0, 0, 1, 0, 0, 0, 1e30, 0, 0, 0, 1e30, 0)
        + b"\0\0",
        "empty.step": b"",
        "bad.step": b"ISO-10303-21;\nnonsense\n",
        "deep.json": b"[" * 50_000 + b"]" * 50_000,
        "swath.csv": (",".join(CSV_COLUMNS) + "\n1e20,1,0,0,400,1,0,0,0\n").encode(),
        "nanq.json": json.dumps(
            {
                "poses": [
                    {
                        "swath": 0,
                        "scanning": True,
                        "position_mm": [0, 0, 400],
                        "quaternion_wxyz": [0, 0, 0, 0],
                    }
                ]
            }
        ).encode(),
        "metres.toml": b"working_distance_mm = 0.4\nz_range_mm = 0.25\nfov_deg = 63.5\n"
        b"points_per_profile = 64\nz_resolution_um = 3.8\ntriangulation_angle_deg = 30\n",
        "tag.yaml": b"!!python/object/apply:os.system ['touch "
        + str(d / "PWNED").encode()
        + b"']\n",
    }
    for name, content in files.items():
        (d / name).write_bytes(content)
    plate = d / "plate.stl"
    import trimesh

    box = trimesh.creation.box((300, 300, 10))
    box.export(plate)
    poses = np.tile(np.diag([1.0, -1.0, -1.0, 1.0]), (5, 1, 1))
    poses[:, :3, 3] = np.c_[np.linspace(-20, 20, 5), np.zeros(5), np.full(5, 405.0)]
    write_csv(Trajectory(poses, np.zeros(5, int), np.ones(5, bool)), d / "good.csv")
    return d


CLI_CASES = [
    ("plan", "{d}/lying.stl", "-o", "{out}.csv"),
    ("plan", "{d}/random.obj", "-o", "{out}.csv"),
    ("plan", "{d}/badidx.ply", "-o", "{out}.csv"),
    ("plan", "{d}/huge.stl", "-o", "{out}.csv"),
    ("plan", "{d}/empty.step", "-o", "{out}.csv"),
    ("plan", "{d}/bad.step", "-o", "{out}.json"),
    ("plan", "{d}/plate.stl", "--sensor", "{d}/metres.toml", "-o", "{out}.csv"),
    ("plan", "{d}/plate.stl", "--sensor", "{d}/tag.yaml", "-o", "{out}.csv"),
    ("plan", "{d}", "-o", "{out}.csv"),
    ("evaluate", "{d}/plate.stl", "{d}/deep.json", "-o", "{out}"),
    ("evaluate", "{d}/plate.stl", "{d}/swath.csv", "--json"),
    ("scan", "{d}/plate.stl", "{d}/nanq.json", "-o", "{out}.ply"),
    ("scan", "{d}/huge.stl", "{d}/good.csv", "-o", "{out}.ply"),
    ("export", "{d}/swath.csv", "--format", "urscript", "-o", "{out}.script"),
    ("export", "{d}/deep.json", "--format", "krl", "-o", "{out}.src"),
]


@pytest.mark.parametrize("args", CLI_CASES, ids=lambda a: "-".join(Path(x).name for x in a[:3]))
def test_cli_hostile_input_is_one_line_exit_2_no_output(hostile, tmp_path, args):
    out = tmp_path / "out"
    argv = [a.format(d=hostile, out=out) for a in args]
    result = runner.invoke(app, argv)
    assert result.exit_code == 2, (result.stdout, result.stderr, result.exception)
    lines = result.stderr.splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: "), result.stderr
    assert "Traceback" not in result.output and "Warning" not in result.output
    assert list(tmp_path.iterdir()) == []  # no partial output of any kind
    assert not (hostile / "PWNED").exists()


# ---- the net at the top: a bug is one line, a signal cleans up -----------------------------
def test_an_internal_error_is_one_line_naming_it_a_bug(tmp_path, monkeypatch):
    import scanplan.jobs.plan

    def broken(*args, **kwargs):
        raise TypeError("unsupported operand")

    monkeypatch.setattr(scanplan.jobs.plan, "plan_views", broken)
    out = tmp_path / "t.csv"
    result = runner.invoke(app, ["plan", "drone", "-q", "-o", str(out)])
    assert result.exit_code == 1 and not out.exists()
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and "internal error, a bug" in lines[0]
    assert "TypeError: unsupported operand" in lines[0] and "SCANPLAN_DEBUG=1" in lines[0]
    assert "Traceback" not in result.output
    monkeypatch.setenv("SCANPLAN_DEBUG", "1")
    result = runner.invoke(app, ["plan", "drone", "-q", "-o", str(out)])
    assert isinstance(result.exception, TypeError)  # the traceback, for the bug report


def test_sigterm_exits_143_and_leaves_no_output(tmp_path, monkeypatch):
    import os
    import signal

    import scanplan.jobs.plan

    def killed(*args, **kwargs):
        os.kill(os.getpid(), signal.SIGTERM)
        raise AssertionError("the signal did not interrupt the command")

    monkeypatch.setattr(scanplan.jobs.plan, "plan_views", killed)
    before = signal.getsignal(signal.SIGTERM)
    out = tmp_path / "t.csv"
    result = runner.invoke(app, ["plan", "drone", "-q", "-o", str(out)])
    assert result.exit_code == 143 and result.stderr.strip() == "terminated"
    assert list(tmp_path.iterdir()) == []
    assert signal.getsignal(signal.SIGTERM) is before  # the handler is put back
