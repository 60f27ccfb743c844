"""Tests for spslidar.codes: m-sequences, Gold codes, Bernoulli codes and their correlations."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.signal import max_len_seq

from spslidar.codes import (
    GOLD_DEGREES,
    MSEQ_DEGREES,
    canonical_kind,
    gold_bound,
    gold_family,
    make_code,
    periodic_xcorr,
    preferred_pair,
    unambiguous_range,
    valid_lengths,
)
from spslidar.constants import SPEED_OF_LIGHT
from spslidar.errors import ConfigError


def _naive_xcorr(a, b):
    a = 2 * a.astype(np.int64) - 1
    b = 2 * b.astype(np.int64) - 1
    return np.array([np.dot(a, np.roll(b, -k)) for k in range(a.size)])


# ---------------------------------------------------------------------------------------------
# periodic_xcorr, gold_bound, valid_lengths, unambiguous_range


def test_periodic_xcorr_matches_direct_sum():
    rng = np.random.default_rng(0)
    a = rng.integers(0, 2, 37).astype(np.uint8)
    b = rng.integers(0, 2, 37).astype(np.uint8)
    r = periodic_xcorr(a, b)
    assert r.dtype == np.int64
    np.testing.assert_array_equal(r, _naive_xcorr(a, b))
    # unipolar: plain sums of products
    ru = periodic_xcorr(a, b, bipolar=False)
    direct = [int(np.dot(a.astype(int), np.roll(b.astype(int), -k))) for k in range(37)]
    np.testing.assert_array_equal(ru, direct)


def test_periodic_xcorr_shift_convention():
    a = make_code("mseq", 127)
    b = np.roll(a, 5)  # b[t + 5] = a[t], so the peak is at k = 5
    r = periodic_xcorr(a, b)
    assert int(np.argmax(r)) == 5 and r[5] == 127


def test_periodic_xcorr_rejects_mismatched_lengths():
    with pytest.raises(ConfigError, match="same length"):
        periodic_xcorr(np.ones(7), np.ones(8))


def test_gold_bound_values():
    assert [gold_bound(n) for n in (5, 6, 7, 9, 10, 11)] == [9, 17, 17, 33, 65, 65]


def test_valid_lengths():
    m = valid_lengths("mseq")
    assert m[0] == 7 and m[-1] == 2**20 - 1 and len(m) == len(MSEQ_DEGREES)
    g = valid_lengths("gold", max_n=12)
    assert g == [7, 31, 63, 127, 511, 1023, 2047]
    assert all(((v + 1).bit_length() - 1) % 4 != 0 for v in valid_lengths("gold"))
    assert valid_lengths("m-sequence", max_n=5) == [7, 15, 31]


def test_unambiguous_range():
    assert unambiguous_range(1023, 10e9) == pytest.approx(15.334, abs=1e-3)
    assert unambiguous_range(16383, 10e9) == pytest.approx(SPEED_OF_LIGHT * 16383 / 2e10)
    with pytest.raises(ConfigError, match="bit rate"):
        unambiguous_range(1023, 0.0)


# ---------------------------------------------------------------------------------------------
# m-sequences


@pytest.mark.parametrize("n", [3, 4, 5, 7, 8, 10, 12, 14])
def test_mseq_autocorrelation_two_valued(n):
    period = 2**n - 1
    code = make_code("mseq", period)
    assert code.dtype == np.uint8 and code.shape == (period,)
    assert set(np.unique(code).tolist()) == {0, 1}
    assert int(code.sum()) == (period + 1) // 2
    r = periodic_xcorr(code, code)
    assert r[0] == period
    assert np.all(r[1:] == -1)


def test_mseq_all_supported_degrees_are_maximal():
    # every SciPy default polynomial used must be primitive: (T+1)/2 ones and an impulse-like
    # periodic autocorrelation (checked here for all degrees up to 20, cheap with the FFT)
    for n in MSEQ_DEGREES:
        period = 2**n - 1
        code = make_code("mseq", period)
        assert int(code.sum()) == (period + 1) // 2, n
        r = periodic_xcorr(code, code)
        assert r[0] == period and r[1:].min() == -1 and r[1:].max() == -1, n


def test_mseq_index_is_cyclic_shift():
    base = make_code("mseq", 63)
    shifted = make_code("m-sequence", 63, index=10)
    np.testing.assert_array_equal(shifted, np.roll(base, -10))
    with pytest.raises(ConfigError, match="cyclic shift 0..62"):
        make_code("mseq", 63, index=63)


def test_mseq_ignores_ones_ratio_and_rng():
    a = make_code("mseq", 255, ones_ratio=0.1, rng=1)
    b = make_code("msequence", 255, ones_ratio=0.9, rng=2)
    np.testing.assert_array_equal(a, b)


def test_make_code_returns_independent_copies():
    a = make_code("mseq", 31)
    a[:] = 0
    assert make_code("mseq", 31).sum() == 16
    g = make_code("gold", 31, index=0)
    g[:] = 0
    assert make_code("gold", 31, index=0).sum() == 16


# ---------------------------------------------------------------------------------------------
# Gold codes


@pytest.mark.parametrize("n", GOLD_DEGREES)
def test_preferred_pairs_three_valued(n):
    taps_u, taps_v = preferred_pair(n)
    u = max_len_seq(n, taps=list(taps_u))[0]
    v = max_len_seq(n, taps=list(taps_v))[0]
    period = 2**n - 1
    assert u.sum() == v.sum() == (period + 1) // 2  # both are m-sequences
    t = gold_bound(n)
    values = set(np.unique(periodic_xcorr(u, v)).tolist())
    assert values == {-t, -1, t - 2}


@pytest.mark.parametrize("n", [5, 6, 7, 9, 10])
def test_gold_family_correlations(n):
    period = 2**n - 1
    fam = gold_family(n)
    assert fam.shape == (period + 2, period) and fam.dtype == np.uint8
    t = gold_bound(n)
    allowed = {-t, -1, t - 2}
    rng = np.random.default_rng(n)
    members = [0, 1, 2, 3, period + 1] + rng.choice(period + 2, 6, replace=False).tolist()
    members = sorted(set(members))
    bip = 2.0 * fam[members].astype(np.float64) - 1.0
    spec = np.fft.rfft(bip, axis=1)
    for i, a in enumerate(members):
        auto = periodic_xcorr(fam[a], fam[a])
        assert auto[0] == period
        assert np.abs(auto[1:]).max() <= t
        assert set(np.unique(auto[1:]).tolist()) <= allowed
        cross = np.rint(np.fft.irfft(np.conj(spec[i]) * spec[i + 1 :], n=period, axis=1))
        assert set(np.unique(cross).tolist()) <= allowed, (a, members[i + 1 :])
    # the family members are distinct codes
    assert np.unique(fam, axis=0).shape[0] == period + 2


def test_gold_make_code_matches_family():
    fam = gold_family(7)
    for idx in (0, 1, 2, 50, 128):
        np.testing.assert_array_equal(make_code("gold", 127, index=idx), fam[idx])
    with pytest.raises(ConfigError, match="family member 0..128"):
        make_code("gold", 127, index=129)


def test_gold_large_degree_single_member():
    code = make_code("gold", 2**14 - 1, index=3)
    u = make_code("gold", 2**14 - 1, index=0)
    r = periodic_xcorr(code, u)
    t = gold_bound(14)
    assert set(np.unique(r).tolist()) <= {-t, -1, t - 2}
    with pytest.raises(ConfigError, match="too large"):
        gold_family(15)


# ---------------------------------------------------------------------------------------------
# Bernoulli codes


@pytest.mark.parametrize("ratio", [0.1, 0.3])
def test_random_ones_ratio_within_4_sigma(ratio):
    length = 16383
    code = make_code("random", length, ones_ratio=ratio, rng=123)
    assert code.dtype == np.uint8 and code.shape == (length,)
    sigma = np.sqrt(length * ratio * (1 - ratio))
    assert abs(int(code.sum()) - length * ratio) < 4 * sigma


def test_random_seeded_reproducibility():
    a = make_code("random", 1000, ones_ratio=0.3, rng=7)
    b = make_code("bernoulli", 1000, ones_ratio=0.3, rng=np.random.default_rng(7))
    c = make_code("random", 1000, ones_ratio=0.3, rng=8)
    np.testing.assert_array_equal(a, b)
    assert not np.array_equal(a, c)


def test_random_has_at_least_one_one():
    for seed in range(20):
        code = make_code("random", 2, ones_ratio=1e-6, rng=seed)
        assert code.sum() >= 1


def test_random_any_length():
    assert make_code("random", 2048, ones_ratio=0.1, rng=0).shape == (2048,)


# ---------------------------------------------------------------------------------------------
# bad input


def test_bad_mseq_length_names_nearest():
    with pytest.raises(ConfigError, match="nearest 16383 or 32767") as info:
        make_code("mseq", 16384)
    assert "\n" not in str(info.value)
    with pytest.raises(ConfigError, match="nearest 7$"):
        make_code("mseq", 3)


@pytest.mark.parametrize("length, near", [(255, "127 or 511"), (4095, "2047 or 8191")])
def test_bad_gold_length_divisible_by_4(length, near):
    with pytest.raises(ConfigError, match="divisible by 4") as info:
        make_code("gold", length)
    assert near in str(info.value)
    with pytest.raises(ConfigError, match="divisible by 4"):
        preferred_pair(8)


def test_bad_gold_length_not_power_of_two_minus_one():
    with pytest.raises(ConfigError, match="Gold code.*nearest 1023 or 2047"):
        make_code("gold", 2000)


@pytest.mark.parametrize("ratio", [0.0, 1.0, 1.5, -0.2, float("nan")])
def test_bad_ones_ratio(ratio):
    with pytest.raises(ConfigError, match="ones_ratio"):
        make_code("random", 100, ones_ratio=ratio, rng=0)


def test_unknown_kind():
    with pytest.raises(ConfigError, match="unknown code kind 'barker'.*'mseq'.*'gold'.*'random'"):
        make_code("barker", 13)
    with pytest.raises(ConfigError, match="unknown code kind"):
        canonical_kind(None)


@pytest.mark.parametrize("length", [1, 0, -5])
def test_too_short_random(length):
    with pytest.raises(ConfigError, match="length >= 2"):
        make_code("random", length, ones_ratio=0.3, rng=0)


def test_non_integer_length_and_random_index():
    with pytest.raises(ConfigError, match="integer"):
        make_code("mseq", 31.5)
    with pytest.raises(ConfigError, match="integer"):
        make_code("mseq", True)
    with pytest.raises(ConfigError, match="random codes"):
        make_code("random", 31, index=2, rng=0)
