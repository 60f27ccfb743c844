"""QCR (eq. 11-17): Delta is the covariance; H is cov(Phi, Phi); the DC part drops out."""

import numpy as np
import pytest

from spslidar.operators import dottest
from spslidar.qcr import CovarianceOperator, centre, centred_patterns, qcr_delta, qcr_problem


@pytest.fixture
def data():
    rng = np.random.default_rng(0)
    phi = np.clip(0.5 + 0.25 * rng.standard_normal((40, 25)), 0, 1)
    corr = rng.standard_normal((40, 3)) + 7.0
    return phi, corr


def test_delta_equals_explicit_covariance(data):
    phi, corr = data
    d = qcr_delta(phi, corr)
    for k in range(corr.shape[1]):
        for j in range(phi.shape[1]):
            explicit = np.cov(corr[:, k], phi[:, j], bias=True)[0, 1]
            assert d[j, k] == pytest.approx(explicit, rel=1e-10, abs=1e-12)
    # eq. (11): <C Phi> - <C><Phi>
    eq11 = (phi.T @ corr) / 40 - np.outer(phi.mean(0), corr.mean(0))
    np.testing.assert_allclose(d, eq11, atol=1e-12)


def test_covariance_operator_is_cov_matrix(data):
    phi, _ = data
    h = CovarianceOperator(phi, dtype=np.float64)
    np.testing.assert_allclose(h.todense(), np.cov(phi.T, bias=True), atol=1e-12)
    dottest(h, 3)


def test_dc_common_to_all_patterns_drops_out(data):
    phi, corr = data
    np.testing.assert_allclose(qcr_delta(phi, corr + 100.0), qcr_delta(phi, corr), atol=1e-10)


def test_centred_form_gradient_is_h_p_minus_delta(data):
    phi, corr = data
    p = np.random.default_rng(1).standard_normal((25, 3))
    a, y = qcr_problem(phi, corr, "centred", dtype=np.float64)
    grad = a.rmatvec(a.matvec(p) - y)
    h = CovarianceOperator(phi, dtype=np.float64)
    np.testing.assert_allclose(grad, h.matvec(p) - qcr_delta(phi, corr), atol=1e-10)
    a2, y2 = qcr_problem(phi, corr, "covariance", dtype=np.float64)
    np.testing.assert_allclose(y2, qcr_delta(phi, corr))
    np.testing.assert_allclose(centre(corr).mean(axis=0), 0, atol=1e-12)


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
@pytest.mark.parametrize("m", [7, 300])  # one block of rows, several blocks
def test_centred_patterns_equal_float64_centring(m, dtype):
    phi = np.clip(0.5 + 0.25 * np.random.default_rng(m).standard_normal((m, 33)), 0, 1)
    for src in (phi.astype(np.float32), phi):
        expect = (centre(np.asarray(src, dtype=np.float64)) / np.sqrt(m)).astype(dtype)
        got = centred_patterns(src, np.sqrt(m), dtype=dtype)
        assert got.dtype == dtype
        np.testing.assert_array_equal(got, expect)
    np.testing.assert_array_equal(centred_patterns(phi, dtype=np.float64), centre(phi))
