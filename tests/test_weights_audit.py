"""The regularisation weight and the memory limit as a researcher sweeping them meets them
(an audit of pattern kinds, budgets and solvers, 2026-11-28)."""

from __future__ import annotations

import argparse

import pytest

import spslidar
from spslidar.cli import _memory


def test_a_lam_scale_the_floor_overrides_is_said():
    """Three --lam-scale values 0.01-0.3 at 64x64 Hadamard gave one weight (the floor,
    3e-3 max|A^T y|) and one RMSE, without a word but ``lam_floored`` in metrics.json."""
    low = spslidar.run(size=16, lam_scale=0.01)
    lower = spslidar.run(size=16, lam_scale=0.001)
    assert low.metrics["lam_floored"] and low.metrics["lam"] == lower.metrics["lam"]
    said = [w for w in low.warnings if w.startswith("--lam-scale 0.01 gives a weight below")]
    assert len(said) == 1 and "with 5 times" in said[0]
    default = spslidar.run(size=16)  # not floored at the paper's noise: nothing said
    assert not default.metrics["lam_floored"]
    assert not any("--lam-scale" in w for w in default.warnings)


def test_a_lam_scale_whose_weight_wins_outright_is_said():
    """``--lam 1e5`` warned that the regulariser wins outright; ``--lam-scale 1e6``, whose
    weight is as large, said nothing (RMSE 0.26 m either way)."""
    r = spslidar.run(size=16, lam_scale=1e6)
    assert any("the regulariser wins outright" in w and "--lam-scale 1e+06" in w
               for w in r.warnings)


@pytest.mark.parametrize("text, gb", [("2", 2.0), ("2GB", 2.0), ("500MB", 0.5),
                                      ("500 M", 0.5), ("1.5GiB", 1.5 * 2**30 / 1e9),
                                      ("0.25g", 0.25)])
def test_max_memory_takes_units(text, gb):
    assert _memory(text) == pytest.approx(gb, rel=1e-12)


@pytest.mark.parametrize("text", ["2 parsecs", "GB", "1..2GB", ""])
def test_max_memory_refuses_what_is_not_a_size(text):
    with pytest.raises(argparse.ArgumentTypeError, match="not a memory size"):
        _memory(text)


def test_a_floored_solve_is_priced_again_before_it_runs(monkeypatch):
    """The time estimate counts 100 iterations before the weight is known; at the weight's
    floor the cap is five times the solver's (FISTA: 300), and a 256x256 Hadamard run
    priced at 8.1 s ran 24 s past --max-time 15 (an audit of 2026-11-28). Once the weight is
    known, a floored solve is priced again and refused before it runs."""
    from spslidar.errors import SpslidarError
    from spslidar.pipeline import budget

    m = spslidar.measure(size=16, patterns="hadamard", lam_scale=0.01, max_time=1000)
    monkeypatch.setattr(budget, "FAST_SECONDS_PER_ENTRY", 1.0)  # each entry a second
    with pytest.raises(SpslidarError, match=r"at the weight's floor \(300 iterations\)"):
        spslidar.reconstruct(m)
    monkeypatch.undo()
    assert spslidar.reconstruct(m).metrics["solver_info"]["iterations"] <= 300
