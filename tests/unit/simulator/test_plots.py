"""The run's figures draw without a warning however little the run recorded: a single
instant since Step 5 (the COM observer's plot then spans one instant), or only the final
instant."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import pytest

from simulator.inprocess import run_inprocess
from simulator.plots import _com_rows, plot_com_observer, write_plots
from simulator.scenario import load_scenario
from tests.helpers.paths import PAPER


@pytest.fixture(scope="module")
def sparse_run():
    """The paper's run recording its first and final instants only."""
    return run_inprocess(load_scenario(PAPER), record_every=100_000)


@pytest.mark.filterwarnings("error")
def test_the_com_observer_plot_of_one_instant_warns_of_nothing(sparse_run, tmp_path: Path):
    assert len(_com_rows(sparse_run)) == 1  # z_C estimated at the final instant only
    path = plot_com_observer(sparse_run, tmp_path / "com_observer.png")
    assert path.stat().st_size > 10_000


@pytest.mark.filterwarnings("error")
def test_every_figure_of_a_run_recorded_at_its_final_instant_only(sparse_run, tmp_path: Path):
    run = dataclasses.replace(sparse_run, history=[sparse_run.final])
    for path in write_plots(run, tmp_path):
        assert path.stat().st_size > 10_000, path
