"""A designer comparing codes, patterns and detectors (an outside audit of 2026-11-29): what
the run does must be what it says. Each test failed before its mend."""

from __future__ import annotations

import numpy as np

import spslidar
from spslidar.cli import main

SMALL = dict(size=16, code_length=1023, range_gate=(19.9, 20.9), seed=0)


def test_a_dead_time_detector_with_half_period_frames_is_refused(tmp_path, capsys):
    """Differential Hadamard frames last half the dwell; the GMAPD draws whole periods, so at
    --periods 1 it drew none (exit 0, an empty map, a count rate of 0) and at 3 a third too
    few. One line, exit 2, nothing written; an even --periods runs."""
    args = ["run", "--size", "16", "--code-length", "1023", "--range-gate", "19.9", "20.9",
            "--no-figure", "--detector", "gmapd", "--signal", "0.0005", "--noise", "0.00002",
            "--patterns", "hadamard", "--hadamard-realisation", "differential"]
    for periods in ("1", "3"):
        out = tmp_path / f"o{periods}"
        assert main([*args, "--periods", periods, "--out", str(out)]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and "give an even --periods" in err[0] and "gmapd" in err[0]
        assert not out.exists()
    assert main([*args, "--periods", "2", "--out", str(tmp_path / "o2")]) == 0
    r = spslidar.run(**SMALL, detector="gmapd", signal=0.0005, noise=0.00002,
                     patterns="hadamard", hadamard_realisation="differential", periods=2)
    assert r.metrics["detector"]["count_rate_hz"] > 0 and np.isfinite(r.depth).all()


def test_the_realisation_of_scrambled_hadamard_rows_is_not_said_to_be_ignored():
    """It was said to be ignored while it was applied (the noise sigma doubled)."""
    kw = dict(SMALL, patterns="scrambled-hadamard", periods=2)
    shifted = spslidar.run(**kw)
    diff = spslidar.run(**kw, hadamard_realisation="differential")
    assert not any("is ignored" in w for w in diff.warnings)
    assert diff.metrics["correlation_noise_sigma"] > 1.5 * shifted.metrics[
        "correlation_noise_sigma"]
    gauss = spslidar.run(**SMALL, hadamard_realisation="differential")  # still ignored there
    assert any(w.startswith("--hadamard-realisation differential is ignored")
               for w in gauss.warnings)


def test_a_noise_split_is_said_to_be_ignored_under_the_papers_ambient_light():
    """Under --ambient paper the shares add up to m_n per bin: the depth maps were identical
    whatever the split, without a word; under --ambient modulated they differ."""
    a = spslidar.run(**SMALL, noise_split=(1.0, 0.0, 0.0))
    b = spslidar.run(**SMALL)
    np.testing.assert_array_equal(a.depth, b.depth)
    assert sum("--noise-split 1 0 0 is ignored" in w for w in a.warnings) == 1
    m = spslidar.run(**SMALL, noise_split=(1.0, 0.0, 0.0), ambient="modulated")
    assert not any("--noise-split" in w for w in m.warnings)
    assert not np.array_equal(m.depth, b.depth)
