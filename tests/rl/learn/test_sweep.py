"""Sweeps on a Dask LocalCluster over loopback: tasks train into their own directories, are
evaluated on an unseen part and land in one table; same seed on two workers, same weights."""

from __future__ import annotations

import csv
import importlib.util
import json
import shlex
import sys

import pytest
import torch
import trimesh
from safetensors.torch import load_file

from helpers import tcp_server
from scanplan.rl.learn.config import TrainConfig
from scanplan.rl.learn.sweep import (
    COLUMNS,
    EvalPart,
    SweepTask,
    connect,
    grid_tasks,
    markdown_table,
    read_csv,
    run_sweep,
    run_task,
    summarize,
    write_tables,
)

needs_dask = pytest.mark.skipif(
    importlib.util.find_spec("distributed") is None, reason="dask distributed not installed"
)


def tiny_config(**kw) -> TrainConfig:
    base = {
        "total_timesteps": 256,
        "n_envs": 2,
        "n_steps": 64,
        "batch_size": 32,
        "n_epochs": 2,
        "checkpoint_every_updates": 1,
        "progress_bar": False,
        "command": "pytest sweep",
        "env": {"fan_points": 32, "noise": False, "segment_mm": (20.0, 40.0)},
        "bc_samples": 128,
    }
    return TrainConfig(**(base | kw))


@pytest.fixture(scope="module")
def client():
    distributed = pytest.importorskip("dask.distributed")
    cluster = distributed.LocalCluster(
        n_workers=2, threads_per_worker=1, processes=True, host="127.0.0.1", dashboard_address=":0"
    )
    with distributed.Client(cluster) as c:
        yield c
    cluster.close()


@pytest.fixture
def small_plate(tmp_path) -> EvalPart:
    """A 200 x 100 mm plate (an unseen part, quick to scan)."""
    box = trimesh.creation.box((200.0, 100.0, 10.0))
    box.apply_translation((0.0, 0.0, 5.0))
    path = tmp_path / "small_plate.stl"
    box.export(path)
    return EvalPart.parse(f"{path}:mm")


def test_eval_part_parses_units():
    assert EvalPart.parse("door") == EvalPart("door", "door", "mm")
    assert EvalPart.parse("/x/car.obj:m") == EvalPart("car", "/x/car.obj", "m")
    assert EvalPart.parse("/x/block.stl") == EvalPart("block", "/x/block.stl", "mm")


def test_grid_tasks_cross_seeds_and_values(tmp_path):
    tasks = grid_tasks(
        "PPO", tiny_config(), tmp_path, seeds=(0, 1), grid={"learning_rate": [1e-3, 3e-4]}
    )
    assert [(t.config.seed, t.config.learning_rate) for t in tasks] == [
        (0, 1e-3),
        (1, 1e-3),
        (0, 3e-4),
        (1, 3e-4),
    ]
    assert len({t.config.output_dir for t in tasks}) == 4
    with pytest.raises(ValueError, match="no TrainConfig field"):
        grid_tasks("x", tiny_config(), tmp_path, grid={"bogus": [1]})
    env = grid_tasks("x", tiny_config(), tmp_path, grid={"env.lookahead": [True]})
    assert env[0].config.env["lookahead"] is True


@needs_dask
@pytest.mark.slow
def test_sweep_on_a_local_cluster_trains_evaluates_and_tabulates(tmp_path, client, small_plate):
    tasks = [
        *grid_tasks("tiny", tiny_config(), tmp_path / "runs", seeds=(0, 1)),
        SweepTask("feedback", planner="feedback"),
    ]
    rows = run_sweep(tasks, [small_plate], client)
    assert [(r["label"], r["seed"]) for r in rows] == [("tiny", 0), ("tiny", 1), ("feedback", "")]
    for row in rows[:2]:
        assert row["timesteps"] == 256 and row["train_wall_s"] > 0
        assert row["part"] == "small_plate"
        assert -1.0 <= row["reward_mean"] <= 0.0 and 0.0 <= row["in_spec_coverage"] <= 1.0
    assert rows[0]["policy_dir"] != rows[1]["policy_dir"]

    csv_path, md_path = write_tables(rows, tmp_path)
    with csv_path.open() as f:
        assert tuple(next(csv.reader(f))) == COLUMNS
    back = read_csv(csv_path)
    assert [r["reward_mean"] for r in back] == [r["reward_mean"] for r in rows]
    (tiny,) = [s for s in summarize(back) if s.label == "tiny"]
    assert tiny.seeds == 2
    md = md_path.read_text()
    assert md == markdown_table(back)
    assert "| v0 | tiny | small_plate | 2 |" in md and "| v0 | feedback | small_plate | 1 |" in md


@needs_dask
@pytest.mark.slow
def test_same_seed_on_two_workers_trains_identical_weights(tmp_path, client, small_plate):
    # Two sweep tasks, same config and seed, pinned to the two worker processes.
    workers = sorted(client.scheduler_info()["workers"])
    assert len(workers) == 2
    tasks = [SweepTask(name, tiny_config(output_dir=str(tmp_path / name), seed=3)) for name in "ab"]
    futures = [
        client.submit(run_task, t, [small_plate], workers=[w], pure=False)
        for t, w in zip(tasks, workers, strict=True)
    ]
    (row_a,), (row_b,) = (f.result() for f in futures)
    a, b = (load_file(tmp_path / d / "policy.safetensors") for d in "ab")
    assert a.keys() == b.keys()
    for key in a:
        assert torch.equal(a[key], b[key]), key
    assert row_a["reward_mean"] == row_b["reward_mean"]


def test_sweep_without_dask_is_one_line_and_exit_2(tmp_path, monkeypatch):
    from typer.testing import CliRunner

    from scanplan.cli import app

    monkeypatch.setitem(sys.modules, "dask", None)
    monkeypatch.setitem(sys.modules, "dask.distributed", None)
    result = CliRunner().invoke(app, ["sweep", "-o", str(tmp_path / "s"), "--timesteps", "64"])
    assert result.exit_code == 2
    assert result.output.strip().splitlines() == [
        "error: scanplan sweep needs the cluster extra: pip install 'scanplan[cluster]'"
    ]
    assert not (tmp_path / "s").exists()


@pytest.mark.slow
def test_reuse_neither_retrains_nor_reevaluates_a_finished_run(tmp_path, small_plate):
    task = SweepTask("tiny", tiny_config(output_dir=str(tmp_path / "run")))
    (first,) = run_task(task, [small_plate], reuse=True)
    weights = tmp_path / "run" / "policy.safetensors"
    stamp = weights.stat().st_mtime_ns
    (again,) = run_task(task, [small_plate], reuse=True)
    assert again == first and weights.stat().st_mtime_ns == stamp
    # Another config in the same directory is trained (and evaluated) afresh.
    other = SweepTask("tiny", tiny_config(output_dir=str(tmp_path / "run"), seed=5))
    (third,) = run_task(other, [small_plate], reuse=True)
    assert weights.stat().st_mtime_ns != stamp and third["seed"] == 5


@needs_dask
@pytest.mark.slow
def test_sweep_cli_writes_and_prints_the_table(tmp_path, small_plate, monkeypatch):
    from typer.testing import CliRunner

    from scanplan.cli import app

    out = tmp_path / "s"
    args = ["sweep", "-o", str(out), "--seeds", "0", "--timesteps", "64", "--n-envs", "2"]
    args += ["--fan-points", "32", "--workers", "1", "--baseline", "feedback", "--label", "tiny"]
    args += ["--part", f"{small_plate.source}:mm"]
    # The command line recorded is the process's own (CliRunner leaves sys.argv as it is).
    monkeypatch.setattr(sys, "argv", ["/usr/bin/scanplan", *args])
    result = CliRunner().invoke(app, args)
    assert result.exit_code == 0, result.output
    assert "| v0 | tiny | small_plate | 1 |" in result.output
    assert "| v0 | feedback | small_plate | 1 |" in result.output
    rows = read_csv(out / "sweep.csv")
    assert [r["label"] for r in rows] == ["tiny", "feedback"]
    meta = json.loads((out / "runs" / "tiny-s0" / "policy.json").read_text())
    assert meta["training"]["command"] == shlex.join(["scanplan", *args])
    bad = CliRunner().invoke(app, ["sweep", "-o", str(out), "--baseline", "rl"])
    assert bad.exit_code == 2 and "--baseline 'rl'" in bad.output


@needs_dask
def test_connect_refuses_a_port_that_is_no_scheduler_in_one_line():
    with tcp_server(lambda conn: conn.close()) as address:
        with pytest.raises(ValueError, match=f"^--scheduler {address}: what answers there is not"):
            with connect(address):
                pass
