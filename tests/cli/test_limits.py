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
