"""The matched filter (eq. 5-6): peak at the true delay, sidelobes, noise estimate."""

import numpy as np
import pytest

from spslidar.codes import make_code
from spslidar.correlate import (
    correlation_gain,
    correlation_noise_sigma,
    gate_lags,
    make_replica,
    matched_filter,
    noise_sigma_from_totals,
    replica_matrix,
)
from spslidar.errors import ConfigError


def test_bipolar_mseq_peak_and_zero_sidelobes():
    code = make_code("mseq", 1023)
    f = make_replica(code, "bipolar")
    k = 417
    hist = np.roll(code.astype(float), k)[None, :] * 3.0 + 5.0  # return + constant background
    c = matched_filter(hist, f, np.arange(1023), gain=correlation_gain(code, f),
                       out_dtype=np.float64)[0]
    assert np.argmax(c) == k
    assert c[k] == pytest.approx(3.0 + 5.0 * f.sum() / correlation_gain(code, f))
    side = np.delete(c, k)
    # m-sequence, bipolar replica: flat sidelobes; the constant background adds sum(f) = -1 each
    np.testing.assert_allclose(side, side[0], atol=1e-6)


def test_unipolar_replica_keeps_background_as_dc():
    code = make_code("mseq", 127)
    f = make_replica(code, "unipolar")
    hist = np.full((1, 127), 2.0)
    c = matched_filter(hist, f, np.arange(127), out_dtype=np.float64)[0]
    np.testing.assert_allclose(c, 2.0 * 64)  # every lag sees the 64 ones of the code


def test_fft_path_equals_matrix_path():
    rng = np.random.default_rng(0)
    code = make_code("random", 600, 0.3, rng=1)
    f = make_replica(code, "bipolar")
    hist = rng.poisson(3.0, (4, 600)).astype(float)
    lags = np.arange(-5, 700)  # > 256 lags: FFT path, wrapping
    a = matched_filter(hist, f, lags, out_dtype=np.float64)
    b = matched_filter(hist, f, lags[:200], out_dtype=np.float64)
    np.testing.assert_allclose(a[:, :200], b, rtol=1e-5, atol=1e-3)
    np.testing.assert_allclose(a[:, 5 + 600], a[:, 5], rtol=1e-9)  # lag 600 == lag 0


def test_noise_sigma_estimate_matches_monte_carlo():
    rng = np.random.default_rng(4)
    code = make_code("mseq", 255)
    f = make_replica(code, "bipolar")
    lam = np.roll(code * 2.0, 30) + 6.0
    hists = rng.poisson(lam, (3000, 255)).astype(float)
    c = matched_filter(hists, f, np.array([30, 100]), out_dtype=np.float64)
    est = correlation_noise_sigma(hists, f)
    assert np.std(c[:, 1]) == pytest.approx(np.mean(est), rel=0.05)
    assert np.std(c[:, 0]) == pytest.approx(np.mean(est), rel=0.05)


def test_gate_lags():
    lags = gate_lags((0.0, 0.15), 1e-10)  # 15 cm = 10 bins of 1.5 cm
    assert lags[0] == 0 and lags[-1] == 11  # 0.15 m is 10.007 bins: ceil
    with pytest.raises(ConfigError):
        gate_lags((5.0, 1.0), 1e-10)
    with pytest.raises(ConfigError):
        make_replica(np.ones(3), "tripolar")


def test_replica_matrix_matches_modular_indexing():
    code = make_code("mseq", 63)
    f = make_replica(code, "bipolar")
    lags = np.array([-70, -1, 0, 1, 17, 62, 63, 200])  # negative and beyond one period
    t = np.arange(63)
    expect = f[(t[:, None] - lags[None, :]) % 63]
    bank = replica_matrix(f, lags)
    assert bank.dtype == np.float32 and bank.flags.c_contiguous
    np.testing.assert_array_equal(bank, expect)
    assert replica_matrix(f, np.array([], dtype=int)).shape == (63, 0)


def test_noise_sigma_from_totals():
    code = make_code("mseq", 127)
    hist = np.random.default_rng(1).poisson(9.0, (5, 127)).astype(float)
    for kind in ("bipolar", "unipolar"):
        f = make_replica(code, kind)
        np.testing.assert_allclose(noise_sigma_from_totals(hist.sum(axis=1), f, 3.0),
                                   correlation_noise_sigma(hist, f, 3.0))
    f = make_replica(code, "unipolar")
    np.testing.assert_allclose(noise_sigma_from_totals(np.array([64.0 * 4]), f, 2.0),
                               np.sqrt(64.0 * 4 * 64 / 127) / 2.0)


def test_the_zero_mean_replica_cancels_a_constant_for_any_code():
    """``s - mean(s)`` sums to zero, so a constant background correlates to 0 at every lag,
    whatever the ones ratio; ``2s - 1`` does only for a balanced code."""
    from spslidar.correlate import auto_replica, make_replica

    rng = np.random.default_rng(3)
    for ratio in (0.1, 0.3, 0.5):
        code = (rng.random(4096) < ratio).astype(np.uint8)
        assert abs(make_replica(code, "zero-mean").sum()) < 1e-9
        expected_bipolar = 2 * int(code.sum()) - code.size
        assert make_replica(code, "bipolar").sum() == pytest.approx(expected_bipolar)
    mseq = make_code("mseq", 1023)
    assert auto_replica(mseq) == "bipolar"  # 512 ones of 1023: exact flat sidelobes
    assert auto_replica((rng.random(4096) < 0.1).astype(np.uint8)) == "zero-mean"


def test_an_unbalanced_code_is_recovered_noiselessly_with_the_default_replica():
    """A Bernoulli code of ones ratio 0.1 through ``2s - 1`` put a negative pedestal under
    every slice: noiseless RMSE 0.21 m with 37 % of the pixels without a return."""
    import spslidar

    common = dict(size=16, code="random", code_length=4096, ones_ratio=0.1, noiseless=True,
                  noise=0.0)
    auto = spslidar.run(**common)
    assert auto.metrics["config"]["replica"] == "zero-mean"
    assert auto.depth_rmse < 0.02 and auto.metrics["missing_fraction"] == 0
    assert spslidar.run(**common, replica="bipolar").depth_rmse > 0.1


def test_a_unipolar_replicas_plateau_is_taken_away(tmp_path):
    """An m-sequence's unipolar replica leaves every return on a plateau of half its peak
    ((T + 1) / 4 against (T + 1) / 2): --replica unipolar read a reflectivity of 0.3 as 0.604
    and called a 4.7 mm map "mostly noise" (an outside physics audit). The plateau is read
    from each profile and taken away: the reflectivity and the noise verdict read as the
    bipolar replica's do, the depths as before."""
    from spslidar.codes import make_code
    from spslidar.correlate import remove_plateau, replica_plateau
    from spslidar.pipeline import run

    code = make_code("mseq", 1023)
    assert replica_plateau(code, "unipolar") == pytest.approx(0.5, abs=1e-12)
    assert replica_plateau(code, "bipolar") == pytest.approx(0.0, abs=1e-12)
    assert abs(replica_plateau(code, "zero-mean")) < 2.0 / code.size
    pulse = np.zeros(64, np.uint8)
    pulse[0] = 1
    assert replica_plateau(pulse, "unipolar") == 0.0  # the conventional lidar's pulse
    for k in (1, 2, 3, 20):  # a return of 0.3 on its plateau of 0.15, gates of k slices
        profile = np.full((1, k), 0.5 * 0.3)
        profile[0, 0] = 0.3
        assert np.allclose(remove_plateau(profile, 0.5)[0, 0], 0.3)
        assert np.allclose(remove_plateau(profile, 0.5)[0, 1:], 0.0)
    # a return spread over 8 of 16 slices, and two returns: their strengths, their sum
    # (a median over the gate read half of them: a review)
    spread = np.full((1, 16), 0.5 * 0.3)
    spread[0, 4:12] += 0.5 * 0.3 / 8
    assert np.allclose(remove_plateau(spread, 0.5)[0, 4:12].sum(), 0.3)
    two = np.full((1, 16), 0.5 * (0.3 + 0.2))
    two[0, 3] += 0.5 * 0.3
    two[0, 9] += 0.5 * 0.2
    assert np.allclose(remove_plateau(two, 0.5)[0, [3, 9]], [0.3, 0.2])
    with pytest.raises(ValueError, match="all ones"):
        remove_plateau(two, 1.0)

    depth = np.full((16, 16), 12.0)
    depth[:, 8:] = 12.3
    scene = str(tmp_path / "planes.npz")
    np.savez(scene, depth=depth, reflectivity=np.full((16, 16), 0.3))
    common = dict(size=16, code_length=1023, compression=1.0, noise=0.01, signal=5.0)
    uni = run(scene=scene, replica="unipolar", **common)
    bi = run(scene=scene, replica="bipolar", **common)
    refl = np.nanmedian(uni.reflectivity)
    assert refl == pytest.approx(0.3, rel=0.05)  # (0.295 measured; 0.604 before)
    assert not any("mostly noise" in w for w in uni.warnings)
    assert uni.metrics["peak_to_noise_p90"] > uni.metrics["peak_to_noise_floor"]
    assert uni.metrics["depth_rmse_m"] == pytest.approx(bi.metrics["depth_rmse_m"], abs=1e-3)
