"""Training logs and curves (report.training): the shipped log reads unchanged, a CSV that is no
training log is refused, the comparison plots every run in every panel."""

from __future__ import annotations

import csv

import numpy as np
import pytest

from scanplan.judging.report.training import LOG_COLUMNS, read_log


def test_read_log_reads_the_shipped_old_format_log_unchanged():
    from scanplan.rl.planner import DEFAULT_POLICY

    path = DEFAULT_POLICY / "training_log.csv"
    log = read_log(path)
    rows = list(csv.DictReader(path.open()))
    assert tuple(log) == LOG_COLUMNS and len(log["timesteps"]) == len(rows) == 30
    for column in LOG_COLUMNS:
        assert log[column].tolist() == [float(r[column]) for r in rows], column


def test_read_log_refuses_a_csv_that_is_no_training_log(tmp_path):
    path = tmp_path / "x.csv"
    path.write_text("a,b\n1,2\n")
    with pytest.raises(ValueError, match="x.csv: neither SB3's progress.csv"):
        read_log(path)


def test_training_comparison_plots_every_run_in_every_panel(tmp_path, monkeypatch):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from scanplan.judging.report.training import COMPARISON_PANELS, plot_training_comparison
    from scanplan.rl.planner import DEFAULT_POLICY

    shipped = DEFAULT_POLICY / "training_log.csv"
    other = tmp_path / "other.csv"  # the same log at half the reward, as a second run
    rows = list(csv.DictReader(shipped.open()))
    with other.open("w", newline="") as f:
        writer = csv.DictWriter(f, list(rows[0]))
        writer.writeheader()
        for r in rows:
            writer.writerow(r | {"ep_rew_mean": str(float(r["ep_rew_mean"]) / 2)})
    figures = []
    monkeypatch.setattr(plt, "close", lambda fig: figures.append(fig))
    out = plot_training_comparison({"shipped": shipped, "half": other}, tmp_path / "c.png")
    assert out.is_file() and out.stat().st_size > 10_000
    (fig,) = figures
    assert [ax.get_title() for ax in fig.axes] == [t for _, t in COMPARISON_PANELS]
    reward = fig.axes[0].get_lines()
    assert len(reward) == 2 and all(len(ax.get_lines()) == 2 for ax in fig.axes)
    ys = read_log(shipped)["ep_rew_mean"]
    np.testing.assert_allclose(reward[0].get_ydata(), ys)
    np.testing.assert_allclose(reward[1].get_ydata(), ys / 2)
    with pytest.raises(ValueError, match="no log"):
        plot_training_comparison({}, tmp_path / "none.png")


def test_seeds_of_one_recipe_are_drawn_as_their_mean_with_the_sd_shaded(tmp_path, monkeypatch):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.collections import PolyCollection

    from scanplan.judging.report.training import plot_training_comparison
    from scanplan.rl.planner import DEFAULT_POLICY

    shipped = DEFAULT_POLICY / "training_log.csv"
    rows = list(csv.DictReader(shipped.open()))
    seeds = []
    for k, scale in enumerate((1.0, 3.0)):
        path = tmp_path / f"seed{k}.csv"
        with path.open("w", newline="") as f:
            writer = csv.DictWriter(f, list(rows[0]))
            writer.writeheader()
            for r in rows:
                writer.writerow(r | {"ep_rew_mean": str(float(r["ep_rew_mean"]) * scale)})
        seeds.append(path)
    figures = []
    monkeypatch.setattr(plt, "close", lambda fig: figures.append(fig))
    plot_training_comparison({"two seeds": seeds, "one": shipped}, tmp_path / "s.png")
    (fig,) = figures
    ax = fig.axes[0]
    ys = read_log(shipped)["ep_rew_mean"]
    mean, one = ax.get_lines()
    np.testing.assert_allclose(mean.get_ydata(), 2 * ys)  # the mean of 1x and 3x
    np.testing.assert_allclose(one.get_ydata(), ys)
    (band,) = [c for c in ax.collections if isinstance(c, PolyCollection)]  # one band: the pair
    lo, hi = band.get_paths()[0].vertices[:, 1].min(), band.get_paths()[0].vertices[:, 1].max()
    assert lo == pytest.approx(np.nanmin(2 * ys - np.abs(ys))) and hi == pytest.approx(
        np.nanmax(2 * ys + np.abs(ys))
    )
