"""The GMAPD's renewal model (:func:`~spslidar.detectors.pileup.renewal_detection`) against
an independent reference: the dense Markov chain of each detection's bin modulo the period
(:mod:`spslidar.detectors.markov`, Rapp et al. 2019), for dead times shorter and far longer
than the code's period."""

from __future__ import annotations

import numpy as np
import pytest
from _warn_filters import ours_as_errors

from spslidar.codes.sequences import make_code
from spslidar.detectors.markov import chain_detection
from spslidar.detectors.pileup import renewal_detection


def _flux(per_dead: float, dead: int, n_bits: int = 255) -> np.ndarray:
    """Two rows of a code at two delays and levels, ``per_dead`` photons per dead time."""
    code = make_code("mseq", n_bits, 0.5, np.random.default_rng(1)).astype(float) + 0.1
    mu = np.stack([code, 2.0 * np.roll(code, 7)])
    return mu / mu.mean(axis=1, keepdims=True) * per_dead / dead


@pytest.mark.parametrize("dead,per_dead", [(1, 0.5), (37, 3.0), (100, 30.0), (600, 3.0),
                                           (2000, 3.0), (5000, 0.3)])
def test_renewal_model_is_the_markov_chains_stationary_law(dead, per_dead):
    """Both describe the same process (re-arming at the detection's time within the bin a dead
    time later): the histograms must agree to the fixed point's tolerance, from a dead time of
    one bin to twenty periods of the code, at 0.3-30 photons per dead time. The sweeps of
    several periods (a dead time over 255 bins) are held to the chain as the one-period sweeps
    are. (1e-9 of the largest bin: the fixed point stops at a change of 1e-10 a sweep; measured
    5e-14 to 8e-11.)"""
    mu = _flux(per_dead, dead)
    ref = chain_detection(mu, dead)
    with ours_as_errors():
        h = renewal_detection(mu, float(dead))
    np.testing.assert_allclose(h, ref, rtol=0, atol=1e-9 * ref.max())
    # and the chain itself: the constant-flux rate mu / (1 + mu D), to the code's modulation,
    # where a bin's flux is small (at 0.5 photon per bin the bins' own saturation counts)
    if mu.max() < 0.05:
        rate = mu[0].sum() / (1 + dead * mu[0].mean())
        assert ref[0].sum() == pytest.approx(rate, rel=0.1)


def test_chain_of_a_constant_flux_is_the_closed_form():
    """At a constant flux of 1e-4 photons per bin the chain's rate per bin is ``mu / (1 + mu
    D)`` to first order in ``mu``: within 1e-4 of it, the same in every bin."""
    mu = np.full(64, 1e-4)
    h = chain_detection(mu, 3000)
    np.testing.assert_allclose(h, 1e-4 / (1 + 0.3), rtol=1e-4)
    assert np.ptp(h) < 1e-12 * h.max()  # no bin is special


@pytest.mark.parametrize("mu,dead,said", [
    (np.full(8, 0.1), 2.5, "whole number"),
    (np.full(8, 0.1), 0, "whole number"),
    (np.zeros(8), 3, "flux in every row"),
    (np.full(8, np.nan), 3, "finite"),
    (-np.ones(8), 3, "non-negative"),
])
def test_chain_refuses_what_it_cannot_model(mu, dead, said):
    with pytest.raises(ValueError, match=said):
        chain_detection(mu, dead)


@pytest.mark.parametrize("dead,peak", [(600, 800.0), (509, 20.0), (1000, 50.0)])
def test_a_detector_locked_into_a_cycle_of_periods(dead, peak):
    """A bright bin fires at nearly every re-arming, so the detector locks into a cycle of as
    many periods as the dead time spans (600 bins over 255: one detection every third period,
    1/3 a period). The sweeps of several periods had a fixed point for each phase of the cycle
    and stopped at one, "converged", without a word: 0.42 detections a period, 27 % high (at
    20 photons and 509 bins, 2.3 % low; an outside audit of stop 68). The model is the chain's
    again: the mean of a sweep's periods is the one-period map's fixed point."""
    mu = np.full(255, 1e-4)
    mu[17] = peak
    ref = chain_detection(mu, dead)
    with ours_as_errors():
        h = renewal_detection(mu, float(dead))
    np.testing.assert_allclose(h, ref, rtol=0, atol=1e-9 * ref.max())
    # one detection a cycle in the bright bin (the background's few elsewhere)
    assert h[17] == pytest.approx(1 / -(-(dead + 1) // 255), rel=3e-2)


def test_sweeps_of_one_period_where_those_of_several_stall():
    """Three bins at 800 photons a period (absurd for a GMAPD, but not refused where the
    mean flux is low) over a dead time of 2.9 periods: the detector nearly locks into cycles
    among them, and the sweeps of three periods each never converged (27 398 sweeps, 32 % off);
    from the start again one period a sweep, the model is the chain's (the mixing, restarted
    from the best such sweep instead, stalled there without a word)."""
    mu = np.random.default_rng(1).random(146) * 1e-2
    mu[[71, 82, 141]] += 800.0
    ref = chain_detection(mu, 424)
    with ours_as_errors():
        h, info = renewal_detection(mu, 424.0, return_info=True)
    np.testing.assert_allclose(h, ref, rtol=0, atol=1e-3 * ref.max())  # (measured 3.8e-5)
    assert info["sweeps"] < 300
