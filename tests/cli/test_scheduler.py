"""--scheduler on every command that takes it (plan, a catalogue, evaluate, defects, sweep):
a port that is no Dask scheduler is one line and exit 2 before any work, nothing written; a
scheduler without workers is waited for a stated time, and Ctrl-C during that wait is one
more line ("interrupted"), exit 130."""

from __future__ import annotations

import importlib.util
import os
import signal
import subprocess
import sys
import time

import pytest
import trimesh

from helpers import ROOT, run_cli, tcp_server

pytestmark = pytest.mark.skipif(
    importlib.util.find_spec("distributed") is None, reason="dask distributed not installed"
)


def garbage(conn):
    conn.sendall(b"\xff" * 8 + b"not dask")


@pytest.fixture()
def catalogue(tmp_path):
    folder = tmp_path / "cad"
    folder.mkdir()
    trimesh.creation.box((200.0, 100.0, 10.0)).export(folder / "block.stl")
    return folder


def test_a_port_that_is_no_scheduler_is_one_line_before_any_work(
    catalogue, plate_and_trajectory, tmp_path
):
    plate, traj = (str(p) for p in plate_and_trajectory)
    out = tmp_path / "out"
    with tcp_server(garbage) as address:
        commands = {
            "catalogue": ["plan", str(catalogue), "-o", str(out)],
            "plan": ["plan", str(catalogue / "block.stl"), "-o", str(out / "p.json")],
            "evaluate": ["evaluate", plate, traj, "--perturb", "path:1mm", "-o", str(out)],
            "defects": ["defects", plate, traj, "-o", str(out)],
            "sweep": ["sweep", "-o", str(out), "--timesteps", "64"],
        }
        for name, args in commands.items():
            start = time.monotonic()
            result = run_cli(*args, "--scheduler", address)
            assert result.exit_code == 2, (name, result.output)
            assert result.stderr == (
                f"error: --scheduler {address}: what answers there is not a Dask scheduler\n"
            ), name
            assert not out.exists(), name
            assert time.monotonic() - start < 20, name


def test_ctrl_c_while_waiting_for_a_worker_is_two_lines_and_exit_130(catalogue, tmp_path):
    from dask.distributed import LocalCluster

    out = tmp_path / "plans"
    with LocalCluster(
        n_workers=0, processes=False, protocol="tcp", host="127.0.0.1", dashboard_address=":0"
    ) as cluster:
        address = cluster.scheduler_address
        env = {**os.environ, "PYTHONPATH": str(ROOT / "src")}
        args = ["plan", str(catalogue), "-o", str(out), "--scheduler", address, "-q"]
        with subprocess.Popen(
            [sys.executable, "-m", "scanplan", *args],
            env=env,
            stderr=subprocess.PIPE,
            stdout=subprocess.DEVNULL,
            text=True,
            start_new_session=True,
        ) as proc:
            assert proc.stderr is not None
            first = proc.stderr.readline()  # said before the wait
            os.killpg(proc.pid, signal.SIGINT)  # Ctrl-C: the terminal signals the group
            rest = proc.stderr.read()
            code = proc.wait(timeout=30)
    said = f"--scheduler {address}: no worker yet; waiting 30 s\n"
    assert (first, rest, code) == (said, "interrupted\n", 130)
    assert not out.exists()
