"""A designer comparing codes, patterns and detectors (an outside audit of 2026-11-29): what
the run does must be what it says. Each test failed before its mend."""

from __future__ import annotations

import numpy as np
import pytest

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
    kw = dict(SMALL, detector="gmapd", signal=0.0005, noise=0.00002, patterns="hadamard",
              hadamard_realisation="differential")
    r = spslidar.run(**kw, periods=2)
    assert r.metrics["detector"]["count_rate_hz"] > 0 and np.isfinite(r.depth).all()
    # with the plan, so that a sweep's check refuses it before any run (a review)
    from spslidar.config import Config
    from spslidar.errors import ConfigError
    from spslidar.pipeline import preflight

    with pytest.raises(ConfigError, match="give an even --periods"):
        preflight(Config(**kw))
    # without a dead time the counts are Poisson over any dwell: it runs (it was refused)
    assert np.isfinite(spslidar.run(**kw, dead_time=0.0).depth).any()
    # the conventional lidar's pulses, not --periods, are what must be even
    with pytest.raises(ConfigError, match=r"even number of pulses per pattern \(3 now"):
        preflight(Config(**dict(kw, lidar="conventional", periods=2, rep_rate=10e9 / 682)))


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


def test_the_afterpulse_correction_is_unbiased_on_low_count_histograms():
    """About one count per bin: the bins without a count kept their share of the expected
    afterpulses (clipped at 0), so the corrected photons read +14 % at P = 0.3 without dead
    time and +8 % at P = 0.1 with 20 ns (200 bins); the signed estimate is unbiased without
    dead time (40 histograms of 100 periods: 1.002 +- 0.004) and within the dead time's
    own finite-count bias with it (1.023 +- 0.010, against 1.013 without afterpulses)."""
    from spslidar.codes import make_code
    from spslidar.detectors.gmapd import GMAPD

    code = make_code("mseq", 1023).astype(float)
    lam = np.repeat((0.02 * np.roll(code, 300) + 5e-4)[None, :], 40, axis=0)
    for dead, prob, most in ((0.0, 0.3, 0.02), (20e-9, 0.1, 0.05)):
        g = GMAPD(dead_time=dead, afterpulse_prob=prob, afterpulse_delay=2e-9, bin_width=1e-10)
        counts, _ = g.detect(lam * 100, np.random.default_rng(7), n_periods=100)
        ratio = g.correct(counts, 100).sum(axis=1) / (100 * lam[0].sum())
        assert abs(ratio.mean() - 1.0) < most, (dead, prob, ratio.mean())


def test_the_signed_afterpulse_correction_stays_bounded_inside_a_bright_return():
    """Inside a bright return the detector is dead after its first detection: the bins' armed
    share vanishes, and continuing a slightly negative count through that slope read
    -1.6e13 photons (a mean reflectivity of 3.7e12 through run, a review). A bin armed less
    than one period's worth reads 0 there."""
    from spslidar.detectors.gmapd import GMAPD

    det = GMAPD(dead_time=5e-9, afterpulse_prob=0.1, afterpulse_delay=1e-9)
    n = 100
    lam = np.full((32, 1023), 0.002 * n)
    lam[:, 100:103] += 3.0 * n
    counts, _ = det.detect(lam.copy(), np.random.default_rng(0), n)
    fixed = det.correct(counts, n)
    assert fixed.min() > -10.0 and np.isfinite(fixed).all()  # a few counts at the most
    r = spslidar.run(size=16, code_length=1023, range_gate=(19.5, 21.5), detector="gmapd",
                     afterpulse_prob=0.3, afterpulse_delay=1e-9, dead_time=2e-9, noise=1e-4,
                     periods=10, signal=0.01, seed=0)
    assert r.metrics["mean_reflectivity"] < 10.0  # 1.7 (3.7e12 before)


def test_an_option_is_not_taken_for_a_prefix_of_another(tmp_path, capsys):
    """``reconstruct --lam 0.1`` (it had no --lam) was read as --lam-scale 0.1, a weight 134
    times smaller than asked, with exit 0 (it has --lam now: --iter is the prefix here)."""
    for args, said in ((["run", "--siz", "16"], "--siz 16"),
                       (["reconstruct", "--ptu", "x.ptu", "--patterns", "p.npy", "--code",
                         "c.npy", "--bit-rate", "10e9", "--range-gate", "1", "2", "--iter",
                         "5"], "--iter 5")):
        with pytest.raises(SystemExit) as stop:
            main([*args, "--out", str(tmp_path / "o")])
        assert stop.value.code == 2
        assert f"unrecognized arguments: {said}" in capsys.readouterr().err
        assert not (tmp_path / "o").exists()


def test_tval3_is_told_to_raise_a_weight_too_small_for_it(tmp_path, capsys):
    """A diverged TVAL3 solve at --lam 1e-45 was told to lower --lam: its data term is
    1/(2 lam) ||A x - y||^2, so the weight must rise."""
    assert main(["run", "--size", "16", "--solver", "tval3", "--lam", "1e-45", "--no-figure",
                 "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert "raise --lam" in err and "lower --lam" not in err
