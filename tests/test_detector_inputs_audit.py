"""An outside audit of the detector models' Python API: the GMAPD's ``expected``,
``detection_probability`` and ``variance``, its pile-up correction, the noise model and the
linear counter took impossible inputs (negative or NaN means, 0 or -1 code periods, text for
numbers) that ``GMAPD.detect`` refuses, and answered with wrong numbers after seconds of work,
a ZeroDivisionError or a NumPy error naming no argument. Each is now one
:class:`~spslidar.errors.ConfigError` naming the argument, before any work."""

import numpy as np
import pytest

from spslidar.detectors.counting import NoiseModel
from spslidar.detectors.gmapd import GMAPD
from spslidar.detectors.linear import LinearDetector
from spslidar.detectors.pileup import coates_correction
from spslidar.errors import ConfigError

#: a 10-bin dead time at a flux the renewal model solves in milliseconds
LAM = np.full((2, 31), 0.5)


def _gmapd(**kw) -> GMAPD:
    return GMAPD(dead_time=1e-9, bin_width=1e-10, **kw)


@pytest.mark.parametrize("method", ["expected", "detection_probability", "variance"])
@pytest.mark.parametrize("bad", [-1.0, np.nan, np.inf])
def test_gmapd_model_refuses_impossible_means(method, bad):
    lam = LAM.copy()
    lam[1, 7] = bad
    with pytest.raises(ConfigError, match=r"^lam .*finite and non-negative"):
        getattr(_gmapd(), method)(lam, 20)
    with pytest.raises(ConfigError, match=r"^lam .*finite and non-negative"):
        getattr(_gmapd(), method)(-LAM, 20)


@pytest.mark.parametrize("method", ["expected", "detection_probability", "variance",
                                    "check_flux"])
@pytest.mark.parametrize("periods", [-1, 0, np.nan, np.inf, "20", True, None])
def test_gmapd_model_refuses_what_detect_refuses_as_n_periods(method, periods):
    g = _gmapd()
    with pytest.raises(ConfigError, match=r"^n_periods must be a positive number"):
        g.detect(LAM, np.random.default_rng(0), n_periods=periods)
    with pytest.raises(ConfigError, match=r"^n_periods must be a positive number"):
        getattr(g, method)(LAM, n_periods=periods)


def test_gmapd_model_takes_numpy_numbers_and_one_row_as_before():
    g = _gmapd()
    want = g.expected(LAM, 20)
    np.testing.assert_array_equal(g.expected(LAM, np.int64(20)), want)
    np.testing.assert_array_equal(g.expected(LAM.astype(np.float32), np.float64(20)), want)
    np.testing.assert_array_equal(g.expected(LAM[0], 20), want[:1])
    with pytest.raises(ConfigError, match=r"^lam must be \(B, L\) means"):
        g.expected(LAM[None], 20)  # (3-D: "too many values to unpack")


@pytest.mark.parametrize("correction", [True, False])
def test_gmapd_correct_refuses_impossible_counts_and_periods(correction):
    g = _gmapd(correction=correction)
    counts, _ = g.detect(LAM * 40, np.random.default_rng(5), n_periods=40)
    np.testing.assert_array_equal(g.correct(counts, np.int64(40)), g.correct(counts, 40))
    with pytest.raises(ConfigError, match=r"^counts .*finite and non-negative"):
        g.correct(-counts - 1.0, 40)  # (corrected to zeros)
    with pytest.raises(ConfigError, match=r"^counts .*finite and non-negative"):
        g.correct(np.where(counts > 0, np.nan, counts), 40)
    for periods in (-5, 0, np.nan, "40"):  # (-5 taken, 0 a ZeroDivisionError)
        with pytest.raises(ConfigError, match=r"^n_periods must be a positive number"):
            g.correct(counts, periods)


def test_coates_correction_refuses_impossible_arguments():
    hist = np.random.default_rng(2).poisson(3.0, 31).astype(float)
    np.testing.assert_array_equal(coates_correction(hist, np.int64(10), np.float64(4.0)),
                                  coates_correction(hist, 10, 4.0))
    bad = [
        ({"dead_time_bins": np.nan}, "^dead_time_bins must be 0 or"),  # (cannot convert NaN)
        ({"dead_time_bins": np.inf}, "^dead_time_bins must be 0 or"),
        ({"dead_time_bins": 0.5}, "^dead_time_bins must be 0 or"),
        ({"dead_time_bins": "4"}, "^dead_time_bins must be a number"),
        ({"n_periods": 0}, "^n_periods must be a positive number"),
        ({"n_periods": -5}, "^n_periods must be a positive number"),
        ({"hist": -hist}, r"^hist .*finite and non-negative"),
        ({"afterpulse_prob": 1.0}, r"^afterpulse_prob must be in \[0, 1\)"),
        ({"afterpulse_prob": 0.1}, "^afterpulse_delay_bins must be"),
        ({"oversample": 0}, "^oversample must be None or a whole number"),
        ({"oversample": True}, "^oversample must be a number"),
        ({"profile": "cubic"}, "^unknown sub-bin profile 'cubic'"),
    ]
    for change, msg in bad:
        kw = {"hist": hist, "n_periods": 10, "dead_time_bins": 4.0, **change}
        with pytest.raises(ConfigError, match=msg):
            coates_correction(**kw)


@pytest.mark.parametrize("key", ["background_rate", "dark_count_rate"])
@pytest.mark.parametrize("bad", [np.nan, np.inf, -1.0, "1e3", True])
def test_noise_model_refuses_impossible_rates(key, bad):
    with pytest.raises(ConfigError, match=f"^{key} must be"):
        NoiseModel(**{key: bad})


@pytest.mark.parametrize("bad", [-1e-3, 0.0, np.nan, np.inf, "1e-10"])
def test_noise_per_bin_refuses_an_impossible_bin_width(bad):
    noise = NoiseModel(m_n=2.0, background_rate=1e6)
    pats, refl = np.ones((3, 4)), np.ones(4)
    np.testing.assert_array_equal(noise.per_bin(pats, refl, np.float64(1e-10)),
                                  noise.per_bin(pats, refl, 1e-10))
    with pytest.raises(ConfigError, match="^bin_width must be"):
        noise.per_bin(pats, refl, bin_width=bad)  # (-1e-3: -1000 counts per bin)


def test_noise_model_refuses_text_and_bools_for_numbers():
    assert NoiseModel(m_n=np.int64(2)).per_bin(np.ones((1, 4)), np.ones(4), 1e-10)[0] == 8.0
    for bad in ("1", True):
        with pytest.raises(ConfigError, match=r"^noise \(m_n\) must be a number"):
            NoiseModel(m_n=bad)
    with pytest.raises(ConfigError, match="^noise_split must be a number"):
        NoiseModel(split=("0.5", "0.5", "0"))
    with pytest.raises(ConfigError, match="^noise_split must be three"):
        NoiseModel(split=(0.5, 0.5))


def test_gmapd_correction_takes_a_bool_or_the_documented_words_only():
    assert _gmapd(correction=True).correction is True
    assert _gmapd(correction=np.bool_(False)).correction == np.bool_(False)
    assert _gmapd(correction="off").correction is False
    assert _gmapd(correction="ON").correction is True
    assert _gmapd(correction="false").correction is False
    for bad in ("no", "", "0", 0, 1, None):  # ("no" is truthy: the correction stayed on)
        with pytest.raises(ConfigError, match="^correction must be True or False"):
            _gmapd(correction=bad)


@pytest.mark.parametrize("periods", [0, -1, np.nan, "2", True])
def test_linear_detector_refuses_what_the_gmapd_refuses_as_n_periods(periods):
    det = LinearDetector()
    with pytest.raises(ConfigError, match=r"^n_periods must be a positive number"):
        det.detect(LAM, np.random.default_rng(0), n_periods=periods)
    with pytest.raises(ConfigError, match=r"^n_periods must be a positive number"):
        det.expected(LAM, n_periods=periods)


def test_linear_detector_takes_numpy_periods_and_half_a_period_as_before():
    det = LinearDetector()
    want, tot = det.detect(LAM, np.random.default_rng(4), n_periods=2)
    for periods in (np.int64(2), np.float64(0.5), 0.5):
        got, got_tot = det.detect(LAM, np.random.default_rng(4), n_periods=periods)
        np.testing.assert_array_equal(got, want)
        np.testing.assert_array_equal(got_tot, tot)
    with pytest.raises(ConfigError, match="^n_periods"):
        det.detect(LAM, np.random.default_rng(4), n_periods=0)


@pytest.mark.parametrize("dtype", [np.float64, np.float32])
def test_linear_expected_is_a_new_array_at_unit_efficiency(dtype):
    lam = LAM.astype(dtype)
    out = LinearDetector(efficiency=1.0).expected(lam)
    assert out is not lam and not np.shares_memory(out, lam)
    assert out.dtype == lam.dtype
    np.testing.assert_array_equal(out, lam)
    out[0, 0] = 99.0  # a caller editing the result does not edit its means
    assert lam[0, 0] == 0.5


def test_detectors_refuse_text_and_bools_for_numbers_by_name():
    bad = [
        (lambda: LinearDetector(efficiency="0.5"), "^efficiency must be a number"),
        (lambda: LinearDetector(efficiency=True), "^efficiency must be a number"),
        (lambda: LinearDetector(dead_time="5e-8"), "^dead_time must be a number"),
        (lambda: GMAPD(bin_width="1e-10"), "^bin_width must be a number"),
        (lambda: GMAPD(dead_time="5e-8"), "^dead_time must be a number"),
        (lambda: GMAPD(efficiency=True), "^efficiency must be a number"),
        (lambda: GMAPD(jitter="0"), "^jitter must be a number"),
        (lambda: GMAPD(oversample=True), "^oversample must be a number"),
        (lambda: _gmapd().detect(LAM, np.random.default_rng(0), n_periods="2"),
         "^n_periods must be a positive number"),
    ]
    for make, msg in bad:
        with pytest.raises(ConfigError, match=msg):
            make()
    # numbers as NumPy scalars or 0-d arrays stay numbers
    assert LinearDetector(efficiency=np.float32(0.5)).expected(LAM)[0, 0] == 0.25
    assert GMAPD(dead_time=np.float64(1e-9), bin_width=np.array(1e-10)).dead_bins == 10.0
