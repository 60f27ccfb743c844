"""Photon counting: Poisson statistics, the three noise terms, pile-up flag."""

import numpy as np
import pytest

from spslidar.detectors import counting as det
from spslidar.errors import ConfigError


@pytest.mark.parametrize("lam", [0.3, 5.0, 4000.0])
def test_poisson_mean_equals_variance(lam):
    counts = det.poisson_counts(np.full((64, 4000), lam), np.random.default_rng(3))
    n = counts.size
    mean, var = counts.mean(dtype=np.float64), counts.var(dtype=np.float64)
    assert abs(mean - lam) < 5 * np.sqrt(lam / n)
    # variance of the sample variance of a Poisson ~ (lam + 2 lam^2) / n
    assert abs(var - lam) < 5 * np.sqrt((lam + 2 * lam**2) / n)
    assert np.all(counts == np.round(counts))


def test_poisson_depends_on_seed_not_threads(monkeypatch):
    lam = np.full((40, 300), 7.0)
    a = det.poisson_counts(lam, 11)
    monkeypatch.setattr(det, "_threads", lambda: 1)
    b = det.poisson_counts(lam, 11)
    c = det.poisson_counts(lam, 12)
    np.testing.assert_array_equal(a, b)
    assert not np.array_equal(a, c)


def test_poisson_rejects_bad_means():
    with pytest.raises(ValueError, match="Poisson means must be finite and non-negative"):
        det.poisson_counts(np.array([[1.0, -1.0]]), 0)
    with pytest.raises(ValueError, match="Poisson means must be finite and non-negative"):
        det.poisson_counts(np.array([[np.nan]]), 0)
    for bad in ([[1.0, np.inf]], [[-np.inf, 1.0]], [[2.0**24, 1.0]], [[np.nan, -1.0]]):
        with pytest.raises(ValueError):
            det.check_means(np.array(bad, dtype=np.float32))
    det.check_means(np.zeros((0, 3)))
    det.check_means(np.array([[0.0, 2.0**23]], dtype=np.float32))


@pytest.mark.parametrize("rows", [3, 8, 64, 101])
def test_poisson_rows_draws_the_counts_of_poisson_counts(rows):
    """The pipeline's kernel: the same random streams as poisson_counts, in float32 in place,
    with exact integer totals per row."""
    lam = np.random.default_rng(0).uniform(0, 50000, (rows, 300)).astype(np.float32)
    ref = det.poisson_counts(lam, np.random.default_rng(5))
    out = lam.copy()
    tot = det.poisson_rows(out, np.random.default_rng(5), out)
    np.testing.assert_array_equal(out, ref)
    assert tot.dtype == np.int64
    np.testing.assert_array_equal(tot, ref.sum(axis=1, dtype=np.float64))
    # the streams: blocks of rows drawn from children of the generator, whatever the thread count
    a = det.poisson_rows(lam, np.random.default_rng(6), np.empty_like(lam))
    b = det.poisson_rows(lam, np.random.default_rng(7), np.empty_like(lam))
    assert not np.array_equal(a, b)


def test_detection_efficiency_scales_the_means():
    d = det.PhotonCountingDetector(efficiency=0.25)
    lam = np.full((2, 3), 8.0, dtype=np.float32)
    np.testing.assert_allclose(d.detected_means(lam), 2.0)
    assert det.PhotonCountingDetector().detected_means(lam) is lam


def test_noise_model_paper_and_modulated():
    rng = np.random.default_rng(0)
    phi = rng.random((5, 16))
    alpha = rng.random(16)
    paper = det.NoiseModel(10.0, (0.5, 0.25, 0.25), "paper")
    np.testing.assert_allclose(paper.per_bin(phi, alpha, 1e-10), 16 * 10.0)
    mod = det.NoiseModel(10.0, (0.5, 0.25, 0.25), "modulated")
    expect = 16 * 10.0 * 0.5 + 10.0 * 0.5 * phi @ alpha
    np.testing.assert_allclose(mod.per_bin(phi, alpha, 1e-10), expect)
    phys = det.NoiseModel(0.0, background_rate=1e6, dark_count_rate=1e5)
    np.testing.assert_allclose(phys.per_bin(phi, alpha, 1e-9), 1.1e6 * 1e-9)


@pytest.mark.parametrize(
    "kw",
    [{"m_n": -1.0}, {"split": (0.5, 0.5, 0.5)}, {"split": (1.0, 0.0)}, {"ambient": "x"},
     {"background_rate": -1.0}],
)
def test_noise_model_bad_input(kw):
    with pytest.raises(ConfigError):
        det.NoiseModel(**kw)


def test_pileup_flag():
    d = det.PhotonCountingDetector(dead_time=50e-9)
    low = d.pileup_report(counts_per_period=1.0, period_s=1e-3)
    high = d.pileup_report(counts_per_period=1e6, period_s=1.6e-6)
    assert not low["gmapd_saturated"] and high["gmapd_saturated"]
    assert high["counts_per_dead_time"] == pytest.approx(1e6 / 1.6e-6 * 50e-9)
    assert "note" not in low
    # 0.135 per dead time was called saturating (an audit): a GMAPD loses 12 % there, said
    # so; it saturates past the 10 it works at with its pile-up corrected
    mid = d.pileup_report(counts_per_period=0.135 * 1.6e-6 / 50e-9, period_s=1.6e-6)
    assert not mid["gmapd_saturated"] and "would lose 12 %" in mid["note"]
    edge = d.pileup_report(counts_per_period=9.9 * 1.6e-6 / 50e-9, period_s=1.6e-6)
    assert not edge["gmapd_saturated"] and "would lose 91 %" in edge["note"]
    over = d.pileup_report(counts_per_period=10.1 * 1.6e-6 / 50e-9, period_s=1.6e-6)
    assert over["gmapd_saturated"] and "would saturate" in over["note"]


def test_linear_saturation_is_said_once_in_the_metrics():
    """The paper's photon levels saturate a real GMAPD on every run: a note in metrics.json's
    detector report, not a warning on every run (issue 24, item 7)."""
    from spslidar import pipeline

    r = pipeline.run(size=16, code_length=127, seed=0)
    assert r.metrics["detector"]["gmapd_saturated"]
    assert "would saturate" in r.metrics["detector"]["note"]
    assert not any("saturate" in w for w in r.warnings)
