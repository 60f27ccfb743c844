"""The dwell (``--periods``), the weight floor of the default regularisation weight, and
``reproduce pileup`` (depth against flux for the linear counter and the GMAPD)."""

from __future__ import annotations

import csv
import math

import numpy as np
import pytest

from spslidar.config import Config
from spslidar.errors import ConfigError
from spslidar.pipeline import measure, reconstruct
from spslidar.pipeline.chain import LAM_FLOOR, default_weight

SMALL = {"size": 16, "code_length": 4095, "depth": "argmax", "seed": 3}


@pytest.mark.parametrize("lidar", ["psst", "conventional"])
def test_periods_scale_the_photons_not_the_physics(lidar):
    """k periods of m_s, m_n give the expected correlations of one period of k m_s, k m_n:
    the dwell multiplies the photons and nothing else (noiseless, so exactly)."""
    k = 7
    # the conventional pulse period divides the code period, so the dwell holds k times the
    # pulses of one code period (in general floor(k L / P))
    base = {**SMALL, "lidar": lidar, "noiseless": True,
            **({"rep_rate": 10e9 / 4095} if lidar == "conventional" else {})}
    one = measure({**base, "signal": 7e-3, "noise": 7e-4})
    many = measure({**base, "signal": 1e-3, "noise": 1e-4, "periods": k})
    assert many.acq.n_periods == k * one.acq.n_periods
    assert many.acq.acquisition_time == pytest.approx(k * one.acq.acquisition_time)
    # float32 matched filter over a background-dominated histogram: round-off ~1e-4 of scale
    scale = float(np.abs(one.sim["corr"]).max())
    np.testing.assert_allclose(many.sim["corr"], one.sim["corr"], rtol=0, atol=3e-4 * scale)
    np.testing.assert_allclose(many.sim["counts"], one.sim["counts"], rtol=1e-6)


def test_periods_in_metrics_and_conventional_shots():
    """The conventional lidar fires through the whole dwell: floor(K L / P) pulses, so a
    repetition period longer than one code period fits once the dwell covers it."""
    r = reconstruct(measure({**SMALL, "lidar": "conventional", "periods": 3, "noise": 1.0}))
    shots, period = r.metrics["n_periods"], r.metrics["code_period_bins"]
    assert shots == (3 * 4095) // period and f"x {shots} shots" in r.metrics["code_description"]
    assert r.metrics["config"]["periods"] == 3
    slow = {**SMALL, "code_length": 1023, "lidar": "conventional", "noise": 1.0}
    with pytest.raises(ConfigError, match="more --periods"):
        measure(slow)  # the 1392-bin period exceeds one 1023-bit code period
    assert measure({**slow, "periods": 2}).acq.n_periods == 2046 // 1392


@pytest.mark.parametrize("bad", [0, -2, 2.5, "many", True])
def test_bad_periods(bad):
    with pytest.raises(ConfigError, match="periods"):
        Config(periods=bad)


def test_default_weight_floor():
    cfg = Config()
    lam, scale, floored = default_weight(cfg, sigma_eff=1.0, lam_max=10.0)
    assert (lam, floored) == (pytest.approx(scale * 1.0), False)
    lam, _, floored = default_weight(cfg, sigma_eff=1e-6, lam_max=10.0)
    assert floored and lam == pytest.approx(LAM_FLOOR * 10.0)
    lam, _, floored = default_weight(cfg.replace(lam=1e-9), sigma_eff=1e-6, lam_max=10.0)
    assert (lam, floored) == (1e-9, False)  # an explicit weight is never floored


def test_weight_floor_binds_only_at_high_snr():
    """At the paper's photon levels the noise term sets the weight; with a long dwell the
    noise term vanishes and the floor keeps the compressive problem regularised, which
    beats the vanishing weight (conventional lidar, noiseless, 25 %)."""
    paper = reconstruct(measure({"size": 32, "depth": "argmax"}))
    assert paper.metrics["lam_floored"] is False
    m = measure({"size": 32, "lidar": "conventional", "fairness": "power", "noiseless": True,
                 "signal": 1e-3, "noise": 1e-4, "periods": 10**5, "depth": "argmax"})
    floored = reconstruct(m)
    assert floored.metrics["lam_floored"] is True
    vanishing = reconstruct(m, lam=floored.metrics["noise_level"]
                            * floored.metrics["lam_scale"])
    assert floored.depth_rmse < 0.5 * vanishing.depth_rmse


def test_more_light_never_a_worse_map_at_the_floor():
    """At the floor's small weight FISTA's default 60 iterations stopped far from the
    minimum: the steps at m_s = 500 read 0.039 m against 0.0015 m at m_s = 50 (found by a
    sweep of unusual regimes). Where the floor sets the weight the default iteration count
    is multiplied by FLOORED_ITERATIONS; a count the user gives is kept."""
    from spslidar.pipeline.weights import FLOORED_ITERATIONS

    def its(result):
        return result.metrics["solver_info"]["iterations"]

    base = {"scene": "steps", "size": 16, "code_length": 1023, "seed": 0}
    dim = reconstruct(measure({**base, "signal": 50}))
    m = measure({**base, "signal": 500})
    bright = reconstruct(m)
    assert bright.metrics["lam_floored"] and not dim.metrics["lam_floored"]
    assert its(bright) == FLOORED_ITERATIONS * its(dim)
    bin_m = 0.015  # one TDC bin at 10 GHz
    assert dim.depth_rmse < bin_m and bright.depth_rmse <= dim.depth_rmse + 1e-6
    # the old count, given explicitly, is kept, and is what lost
    short = reconstruct(m, iterations=its(dim))
    assert its(short) == its(dim) and short.depth_rmse > 2 * bin_m


def test_noiseless_data_are_weighted_as_noiseless():
    """``--noiseless`` took the weight of the noisy run it stands for (its counts' Poisson
    level), so the noise-free case was no better than the noisy one (the room, 32x32: 0.16 m);
    no noise reaches the prox, so the floor sets its weight (and the floor's iterations)."""
    res = reconstruct(measure({"scene": "room", "size": 32, "seed": 0, "noiseless": True}))
    assert res.metrics["lam_floored"]
    assert res.metrics["noise_level"] > 0  # still reported: what the counts would carry
    assert res.depth_rmse < 0.015  # within a bin (0.0038 m measured)


def test_reproduce_pileup_quick(tmp_path):
    """Quick mode: the GMAPD counts follow n / (1 + n) (PSST flux is nearly flat in time),
    the PSST lidar is hardly hurt by pile-up while the conventional lidar's uncorrected
    histogram fails at the top flux, and the correction rescues part of it."""
    from spslidar.experiments.reproduce import reproduce_main
    from spslidar.experiments.reproduce.pileup import QUICK_FLUXES

    assert reproduce_main("pileup", tmp_path, quick=True, progress=False) == 0
    folder = tmp_path / "pileup"
    assert (folder / "pileup.png").is_file()
    rows = list(csv.DictReader(open(folder / "pileup.csv")))
    assert len(rows) == 2 * 3 * len(QUICK_FLUXES)
    by = {(r["lidar"], float(r["flux_per_dead_time"]), r["label"]): r for r in rows}
    for flux in QUICK_FLUXES:
        lin = float(by["psst", flux, "linear counter"]["counts_per_dead_time"])
        gm = float(by["psst", flux, "GMAPD uncorrected"]["counts_per_dead_time"])
        assert lin == pytest.approx(flux, rel=0.02)
        assert gm == pytest.approx(lin / (1 + lin), rel=0.02)
    top = max(QUICK_FLUXES)
    rmse = {k: float(v["depth_rmse_m"]) for k, v in by.items()}
    assert rmse["psst", top, "GMAPD uncorrected"] < 0.02
    assert rmse["conventional", top, "GMAPD uncorrected"] > 0.1
    assert rmse["conventional", top, "GMAPD corrected"] < rmse["conventional", top,
                                                              "GMAPD uncorrected"]
    text = (folder / "section.md").read_text()
    assert "operating point" in text and not math.isnan(rmse["psst", top, "linear counter"])
