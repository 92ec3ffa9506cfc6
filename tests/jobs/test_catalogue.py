"""A catalogue stopped by Ctrl-C or SIGTERM (`plan FOLDER`, its parts over worker processes
in `core.run.task_runner`) ends within seconds: the parts queued are dropped, the workers
stopped, one line said, the exit code the signal's."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from helpers import ROOT

needs_proc = pytest.mark.skipif(not Path("/proc/self/stat").exists(), reason="needs /proc")


def workers_of(pid: int) -> set[int]:
    """The live worker processes (spawned) whose parent is `pid`."""
    found = set()
    for entry in Path("/proc").iterdir():
        try:
            stat = (entry / "stat").read_text()
            command = (entry / "cmdline").read_bytes()
        except OSError:
            continue
        state, parent = stat.rsplit(")", 1)[1].split()[:2]
        if int(parent) == pid and state != "Z" and b"spawn_main" in command:
            found.add(int(entry.name))
    return found


def alive(pid: int) -> bool:
    try:
        return (Path("/proc") / str(pid) / "stat").read_text().rsplit(")", 1)[1].split()[0] != "Z"
    except OSError:
        return False


@needs_proc
@pytest.mark.skipif((os.cpu_count() or 1) < 2, reason="one core plans a catalogue in-process")
@pytest.mark.parametrize(
    "stop, code, said", [("SIGINT", 130, "interrupted"), ("SIGTERM", 143, "terminated")]
)
def test_a_catalogue_stops_within_seconds_of_a_signal(tmp_path, stop, code, said):
    # Three built-in parts of 10-20 s each on two workers: one queued behind them.
    listing = tmp_path / "parts.txt"
    listing.write_text("door\ndrone\ntraining-piece\n")
    out = tmp_path / "plans"
    env = {**os.environ, "PYTHONPATH": str(ROOT / "src")}
    with subprocess.Popen(
        [sys.executable, "-m", "scanplan", "plan", str(listing), "-o", str(out), "-q"],
        env=env,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        text=True,
        start_new_session=True,
    ) as proc:
        deadline = time.monotonic() + 60
        while len(workers := workers_of(proc.pid)) < 2:
            assert proc.poll() is None and time.monotonic() < deadline, "no workers started"
            time.sleep(0.1)
        time.sleep(1.0)  # the workers are planning
        start = time.monotonic()
        if stop == "SIGINT":  # Ctrl-C: the terminal signals the whole group
            os.killpg(proc.pid, signal.SIGINT)
        else:  # a service manager's stop: the process alone
            proc.send_signal(signal.SIGTERM)
        assert proc.stderr is not None
        stderr = proc.stderr.read()
        assert proc.wait(timeout=60) == code
        took = time.monotonic() - start
    assert stderr == f"{said}\n"
    assert took < 5.0
    time.sleep(0.5)
    assert not [pid for pid in workers if alive(pid)]
    assert not list(out.glob("*.json"))  # no part was finished
