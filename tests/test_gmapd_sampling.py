"""GMAPD counts drawn detection by detection (:mod:`spslidar.detectors.sampling`), against the
photon-by-photon reference :func:`~spslidar.detectors.events.simulate_events` (an audit of
2026-11-29: each bin drawn on its own gave the pile-up-corrected matched filter 4 times the
spread of a real detector's at 3.5 photons per dead time)."""

from __future__ import annotations

import numpy as np
import pytest

from spslidar.detectors import sampling
from spslidar.detectors.events import simulate_events
from spslidar.detectors.gmapd import GMAPD

L, DEAD = 200, 50  # bins per period; a 5 ns dead time in 100 ps bins


def _flux(per_dead: float) -> np.ndarray:
    """Photons per bin per period: a background and two returns."""
    mu = np.full(L, per_dead / DEAD)
    mu[60:63] += per_dead * 0.5
    mu[150] += per_dead * 0.3
    return mu


def _both(g: GMAPD, mu: np.ndarray, n: int, reps: int, seed: int):
    """``reps`` histograms from the reference and from ``detect`` (one call, ``reps`` rows)."""
    rng = np.random.default_rng(seed)
    ref = np.array([simulate_events(mu * n, n, g, rng, warmup_periods=5)[0]
                    for _ in range(reps)], dtype=np.float64)
    lam = np.repeat((mu * n)[None, :], reps, axis=0)
    got = np.asarray(g.detect(lam, rng, n)[0], dtype=np.float64)
    return ref, got


@pytest.mark.parametrize("per_dead,prob,jitter", [(3.0, 0.0, 0.0), (10.0, 0.2, 1.5e-10)])
def test_counts_have_the_reference_statistics(per_dead, prob, jitter):
    g = GMAPD(dead_time=DEAD * 1e-10, bin_width=1e-10, jitter=jitter, afterpulse_prob=prob,
              afterpulse_delay=2e-9 if prob else 0.0, dark_count_rate=1e6)
    reps, n = 1000, 100
    ref, got = _both(g, _flux(per_dead), n, reps, seed=3)
    mean = g.expected(_flux(per_dead)[None, :] * n, n)[0]
    # the mean histogram: chi^2 per bin about 1 (its standard deviation over 200 bins is 0.1)
    chi2 = np.mean((got.mean(0) - mean) ** 2 / np.maximum(got.var(0) / reps, 1e-12))
    assert chi2 < 1.4
    # the dead time's correlations: the total's variance (Fano factor far below 1) and that of
    # one dead time's window of counts agree with the reference's within 20 % (a variance
    # estimated from 1000 draws of these skewed small counts has a relative standard error of
    # about 5 %; of two, 7 %; measured on 4000 draws: 1 % and 6 % apart)
    for sl in (slice(None), slice(55, 55 + DEAD)):
        v_ref, v_got = ref[:, sl].sum(1).var(), got[:, sl].sum(1).var()
        assert abs(v_got / v_ref - 1) < 0.2, (sl, v_ref, v_got)
    assert got.sum(1).var() < 0.2 * got.sum(1).mean()  # binomial bins gave about 0.9


def test_at_most_one_detection_per_dead_time():
    """One period, bright: every window of ``DEAD`` consecutive bins holds at most one
    detection, for every row (bins drawn on their own held up to 5)."""
    g = GMAPD(dead_time=DEAD * 1e-10, bin_width=1e-10)
    lam = np.repeat(_flux(30.0)[None, :], 200, axis=0)
    counts = np.asarray(g.detect(lam, np.random.default_rng(0), 1)[0])
    windows = np.lib.stride_tricks.sliding_window_view(counts, DEAD, axis=1).sum(-1)
    assert windows.max() == 1 and counts.sum(1).min() >= L // (DEAD + 1)


def test_corrected_matched_filter_has_the_reference_spread():
    """The audit's case: 3.5 photons per dead time, 100 periods, pile-up corrected, matched
    filter of a 1023-bit m-sequence's return. Spread within 30 % of the reference's
    (independent bins gave 7 times it)."""
    from spslidar.codes.sequences import make_code

    code = np.asarray(make_code("mseq", 1023), dtype=np.float64)
    g = GMAPD(dead_time=50e-9, bin_width=1e-10)
    n, reps = 100, 150
    mu = 3.5 / 500 * 0.2 + np.roll(code, 40) * (3.5 / 500 * 0.8 * 2)
    rng = np.random.default_rng(5)
    f = 2 * code - 1
    replica = np.stack([np.roll(f, 40 + k) for k in (-3, 0, 3)], axis=1)
    ref = np.array([simulate_events(mu * n, n, g, rng)[0] for _ in range(reps)], float)
    got = np.asarray(g.detect(np.repeat((mu * n)[None, :], reps, 0), rng, n)[0], float)
    peaks = [np.asarray(g.correct(x, n)) @ replica for x in (ref, got)]
    sd_ref, sd_got = peaks[0][:, 1].std(), peaks[1][:, 1].std()
    assert abs(sd_got / sd_ref - 1) < 0.3, (sd_ref, sd_got)
    # and the same mean, within 4 standard errors
    assert abs(peaks[1][:, 1].mean() - peaks[0][:, 1].mean()) < 4 * sd_ref * np.sqrt(2 / reps)


def test_long_dwell_is_scaled_with_the_exact_statistics(monkeypatch):
    """Past EXACT_DETECTIONS the dwell is scaled from fewer periods: mean and the total's
    variance as the exact draw's (here forced at a tenth of the detections)."""
    g = GMAPD(dead_time=DEAD * 1e-10, bin_width=1e-10)
    n, reps = 300, 300
    lam = np.repeat((_flux(3.0) * n)[None, :], reps, axis=0)
    exact = np.asarray(g.detect(lam, np.random.default_rng(1), n)[0], float)
    monkeypatch.setattr(sampling, "EXACT_DETECTIONS", 90)
    scaled = np.asarray(g.detect(lam, np.random.default_rng(2), n)[0], float)
    assert np.all(scaled >= 0) and np.all(exact == np.rint(exact))
    se = exact.sum(1).std() / np.sqrt(reps)
    assert abs(scaled.sum(1).mean() - exact.sum(1).mean()) < 4 * np.sqrt(2) * se
    assert abs(scaled.sum(1).var() / exact.sum(1).var() - 1) < 0.3
    w = slice(55, 55 + DEAD)
    assert abs(scaled[:, w].sum(1).var() / exact[:, w].sum(1).var() - 1) < 0.3


def test_a_dim_row_beside_a_bright_one_is_drawn_exactly(monkeypatch):
    """Whether a row was drawn or scaled followed the brightest row of its block: a dim row
    beside a bright one came out on a lattice of 2 values per bin (an audit). Each row is
    drawn exactly where its own detections allow."""
    g = GMAPD(dead_time=DEAD * 1e-10, bin_width=1e-10)
    n = 300
    lam = np.stack([_flux(3.0) * n, _flux(0.01) * n])
    monkeypatch.setattr(sampling, "EXACT_DETECTIONS", 90)
    counts = np.asarray(g.detect(lam, np.random.default_rng(4), n)[0], np.float64)
    assert np.all(counts[1] == np.rint(counts[1]))  # the dim row: whole counts
    assert not np.all(counts[0] == np.rint(counts[0]))  # the bright row: scaled
