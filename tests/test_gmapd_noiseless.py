"""The pile-up correction of a noiseless GMAPD run (its expected histograms).

An audit found ``spslidar run --detector gmapd --signal 1.5e-5 --noise 3e-5 --noiseless``
(one code period, 69 photons per 50 ns dead time) gave an empty depth map, while
``--pileup-correction off`` gave 0.0047 m: the correction capped every bin's flux at
``log(max(2 n (alpha + g), 1))``, half a count below the bin's ceiling, which at one period
and 0.19 armed is ``log 1 = 0``, so every bin of the corrected histogram read 0 photons. That
cap is a bound on counts; an expected histogram is inverted exactly (the README's claim).
"""

from __future__ import annotations

import numpy as np
import pytest

from spslidar import measure, reconstruct
from spslidar.detectors.gmapd import GMAPD
from spslidar.detectors.pileup import coates_correction


def _flux(rows: int = 3, period: int = 1023, per_bin: float = 0.009) -> np.ndarray:
    """Photons per bin over one period: a flat background and a coded return per row."""
    rng = np.random.default_rng(1)
    code = rng.random(period) < 0.5
    lam = np.full((rows, period), 0.8 * per_bin)
    lam += 0.4 * per_bin * np.roll(code, 37)[None, :] * np.linspace(0.5, 1.0, rows)[:, None]
    return lam


@pytest.mark.parametrize("n_periods", [1, 3])
def test_correction_inverts_the_expected_histogram_at_few_periods(n_periods):
    """The audit's flux per bin (4.3 photons per dead time here, 1023 bins of 100 ps, 500-bin
    dead time) at 1 and 3 periods: ``n (alpha + g)`` is 0.19 and 0.57, below and above
    the old cap's threshold of 1/2."""
    det = GMAPD()
    lam = _flux() * n_periods
    hist = det.expected(lam, n_periods)
    fixed = det.correct(hist, n_periods, expected=True)
    assert np.all(hist < 0.25 * lam)  # deep in pile-up: most photons are lost
    np.testing.assert_allclose(fixed, lam, rtol=1e-9)
    # the bound on counts no longer erases a histogram below one count per bin: flux under
    # log 2 per bin is read exactly even by a caller that does not say it is expected
    np.testing.assert_allclose(det.correct(hist, n_periods), lam, rtol=1e-9)


def test_expected_histogram_is_not_capped_where_counts_would_be():
    """A bright bin at one period: its flux (1.5 per bin) is above the counts' cap, which the
    expected histogram is not bound by."""
    lam = _flux(rows=1, period=200, per_bin=0.01)
    lam[0, 120] = 1.5
    hist = GMAPD(dead_time=10e-9, oversample=1).expected(lam, 1)
    exact = coates_correction(hist, 1, 100.0, expected=True)
    np.testing.assert_allclose(exact, lam, rtol=1e-9)
    capped = coates_correction(hist, 1, 100.0)
    assert capped[0, 120] < 0.8 * lam[0, 120]  # counts cannot resolve it: bounded


def test_noiseless_gmapd_run_keeps_its_returns():
    """The audit's command, small (16x16, 1023 bits): every pixel holds its return and the
    corrected depth is as good as the uncorrected (before: coverage 0, no depth)."""
    cfg = {"detector": "gmapd", "signal": 1.5e-5, "noise": 3e-5, "noiseless": True,
           "size": 16, "code_length": 1023, "seed": 0}
    on = reconstruct(measure(cfg))
    off = reconstruct(measure({**cfg, "pileup_correction": False}))
    assert on.metrics["coverage"] == 1.0
    assert on.depth_rmse <= off.depth_rmse + 1e-3


def test_no_run_is_told_the_correction_amplifies_its_noise():
    """At 69 incident photons per dead time (64x64; 17 at 32x32) a noiseless run was warned that
    the correction 'amplifies the counting noise' (it has none). That warning, measured on
    counts drawn bin by bin, was withdrawn once the counts held the dead time's correlations
    (the correction then helps at 30 and 100 photons per dead time): neither run is told it,
    and the flux is still read back."""
    cfg = {"detector": "gmapd", "signal": 1.5e-5, "noise": 3e-5, "size": 32, "seed": 0}
    noisy = measure(cfg)
    assert noisy.sim["pileup"]["incident_per_dead_time"] > 10
    quiet = measure({**cfg, "noiseless": True})
    for m in (noisy, quiet):
        assert not any("amplifies the counting noise" in w for w in m.warnings)
