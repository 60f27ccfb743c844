"""Defects an outside plugin author's audit found in the registries, the stage options and the
conformance kit (``spslidar check``): each test fails without its fix."""

from __future__ import annotations

import pytest

from spslidar.depth import ESTIMATORS
from spslidar.depth.argmax import ArgmaxDepth
from spslidar.registry import Option

WINDOW = Option("window", 1, "median window", kind=int, lo=1, hi=15)


class MedArgmax(ArgmaxDepth):
    """The paper's argmax, with an option of its own (unused: the runs must only reach it)."""

    name = "medargmax"

    def __init__(self, window: int = 1, **kw):
        super().__init__(**kw)
        self.window = window


@pytest.fixture
def medargmax():
    ESTIMATORS.add("medargmax", MedArgmax, "med argmax", "argmax with a window",
                   options=(WINDOW,))
    try:
        yield "medargmax"
    finally:
        ESTIMATORS.remove("medargmax")


# -- 1. reproduce: a plugin estimator's option is processing, as sweep reads it -------------

_ROWS: list = []


def _exp_window(ctx):
    """An experiment plugin's points: one estimator, two of its windows."""
    from spslidar.experiments.reproduce.context import base_params, run_points

    points = [base_params(ctx, code_length=255, compression=0.1, depth="medargmax", window=w)
              for w in (1, 3)]
    _ROWS[:] = run_points(ctx, points)
    return "## Window\n\nTwo windows.\n", []


@pytest.mark.parametrize("max_time", [None, 600])
def test_reproduce_reads_a_plugin_estimators_option_as_processing(medargmax, tmp_path,
                                                                  monkeypatch, max_time):
    """``base_params(ctx, depth="medargmax", window=w)``: the batch's time check dropped
    ``depth`` but kept ``window`` ("--window is an option of --depth medargmax, not of --depth
    mrf", exit 2), and the two windows drew two measurements (an unpaired comparison)."""
    from spslidar.experiments import reproduce
    from spslidar.experiments.reproduce import reproduce_main
    from spslidar.experiments.sweep import ERROR_KEY

    reg = reproduce.EXPERIMENT_REGISTRY
    monkeypatch.setattr(reg, "_entries", dict(reg._entries))
    reg.add("window", _exp_window, "Window", "two windows", in_all=False)
    assert reproduce_main("window", tmp_path, quick=True, progress=False,
                          max_time=max_time) == 0
    assert len(_ROWS) == 2 and not any(ERROR_KEY in row for row in _ROWS)
    assert _ROWS[0]["seed"] == _ROWS[1]["seed"]  # one measurement, two processings
