"""The deterministic forward model (eq. 4, 8)."""

import numpy as np
import pytest

from spslidar.constants import SPEED_OF_LIGHT
from spslidar.forward import (
    delay_to_depth,
    depth_to_delay,
    expected_counts,
    pulse_overlaps,
    return_amplitudes,
    shifted_codes,
)


def test_depth_delay_round_trip():
    d = np.array([0.0, 1.5, 20.37])
    bw = 1e-10
    np.testing.assert_allclose(delay_to_depth(depth_to_delay(d, bw), bw), d)
    # one bin of 100 ps is c * dt / 2 = 1.499 cm of depth
    assert delay_to_depth(1.0, bw) == pytest.approx(SPEED_OF_LIGHT * 1e-10 / 2)


@pytest.mark.parametrize("width", [0.25, 0.5, 1.0])
def test_pulse_overlaps_conserve_photons(width):
    delay = np.random.default_rng(0).uniform(0, 50, 200)
    bins, w = pulse_overlaps(delay, width)
    np.testing.assert_allclose(w.sum(axis=1), 1.0, atol=1e-12)
    assert np.all(w >= 0)
    # the photons' centroid is the pulse centre
    centroid = ((bins + 0.5) * w).sum(axis=1)
    np.testing.assert_allclose(centroid, delay + width / 2, atol=0.5)


def test_integer_delay_full_width_pulse_is_one_bin():
    bins, w = pulse_overlaps(np.array([7.0]), 1.0)
    assert bins[0, 0] == 7 and w[0, 0] == 1.0 and w[0, 1] == 0.0


def test_return_amplitudes_match_brute_force():
    rng = np.random.default_rng(1)
    m, q, period = 5, 12, 40
    phi = rng.random((m, q))
    alpha = rng.random(q)
    delay = rng.uniform(0, 90, q)  # beyond one period: wraps
    shifts, amp = return_amplitudes(phi, alpha, delay, 0.5, period)
    dense = np.zeros((m, period))
    bins, w = pulse_overlaps(delay, 0.5)
    for j in range(q):
        for p in range(2):
            dense[:, bins[j, p] % period] += phi[:, j] * alpha[j] * w[j, p]
    np.testing.assert_allclose(dense[:, shifts], amp, rtol=1e-12)
    others = np.setdiff1d(np.arange(period), shifts)
    assert np.all(dense[:, others] == 0)


def test_expected_counts_single_pixel_is_shifted_code():
    code = np.array([1, 0, 0, 1, 1, 0, 1], dtype=np.uint8)
    phi = np.ones((1, 1))
    shifts, amp = return_amplitudes(phi, np.array([1.0]), np.array([3.0]), 1.0, code.size)
    lam = expected_counts(amp, shifts, code, signal=2.0, noise_per_bin=0.5, n_periods=3)
    np.testing.assert_allclose(lam[0], 3 * (2.0 * np.roll(code, 3) + 0.5))
    np.testing.assert_array_equal(shifted_codes(code, [3])[0], np.roll(code, 3))


def test_total_signal_matches_eq8():
    """E[C_s] = T R_a M_2 alpha m_s for binary patterns with M_2 mirrors on (eq. 8)."""
    rng = np.random.default_rng(2)
    q, period = 64, 127
    code = (rng.random(period) < 0.3).astype(np.uint8)
    phi = (rng.random((3, q)) < 0.5).astype(float)
    alpha = np.full(q, 0.7)
    delay = rng.uniform(0, 40, q)
    shifts, amp = return_amplitudes(phi, alpha, delay, 0.5, period)
    lam = expected_counts(amp, shifts, code, signal=5.0, noise_per_bin=0.0)
    m2 = phi.sum(axis=1)
    np.testing.assert_allclose(lam.sum(axis=1), code.sum() * m2 * 0.7 * 5.0, rtol=1e-10)


def test_shifted_codes_matches_modular_indexing():
    rng = np.random.default_rng(3)
    code = (rng.random(31) < 0.5).astype(np.uint8)
    shifts = np.array([0, 5, 30, 31, 47, -3])
    t = np.arange(code.size)
    expect = code[(t[None, :] - shifts[:, None]) % code.size]
    got = shifted_codes(code, shifts)
    assert got.dtype == np.float32 and got.shape == (shifts.size, code.size)
    np.testing.assert_array_equal(got, expect)
    assert shifted_codes(code, shifts, np.float64).dtype == np.float64
    assert shifted_codes(code, np.array([], dtype=int)).shape == (0, code.size)
