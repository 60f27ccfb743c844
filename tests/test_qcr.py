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


# -- the plain (no-QCR) problem with its mean direction eliminated ----------------------------


def _plain(m=120, n=8, k=3, seed=4):
    from spslidar.patterns import DensePatterns

    rng = np.random.default_rng(seed)
    phi = np.clip(0.5 + 0.25 * rng.standard_normal((m, n * n)), 0, 1)
    return DensePatterns(phi), phi, rng.standard_normal((m, k)) + 40.0


def test_mean_eliminated_is_exact_variable_projection():
    """For every z, the reduced residual equals the plain residual at the best constant:
    ||A (z + c(z) 1) - C|| = ||B z - (I - vv^T) C||, and no constant does better."""
    from spslidar.qcr import MeanEliminated

    op, phi, corr = _plain()
    b = MeanEliminated(op)
    z = np.random.default_rng(1).standard_normal((phi.shape[1], corr.shape[1]))
    p = b.recover(z, corr)
    lhs = np.linalg.norm(phi @ p - corr, axis=0)
    rhs = np.linalg.norm(b.matvec(z) - b.data(corr), axis=0)
    np.testing.assert_allclose(lhs, rhs, rtol=1e-10)
    for dc in (-1e-3, 1e-3):
        assert np.all(np.linalg.norm(phi @ (p + dc) - corr, axis=0) > lhs)
    # the constant image is the eliminated direction
    assert np.abs(b.matvec(np.ones((phi.shape[1], 1)))).max() < 1e-9


def test_mean_eliminated_conditioning():
    """The plain operator's largest singular value is ~2 sqrt(Q) times its next; the reduced
    operator's is of the order of the rest."""
    from spslidar.qcr import MeanEliminated

    op, phi, _ = _plain(m=400, n=16)
    s_plain = np.linalg.svd(phi, compute_uv=False)
    s_red = np.linalg.svd(MeanEliminated(op).todense(), compute_uv=False)
    assert s_plain[0] / s_plain[1] > 5
    assert s_red[0] < 1.01 * s_plain[1]


def test_plain_tv_problem_converges_within_the_default_budget():
    """Without QCR the default 60 FISTA iterations give the depth map of a long solve (before
    the elimination 60 iterations gave 0.25 m of RMSE where 1500 gave 0.12 m at 64x64), and a
    longer code lowers the depth error (Fig. 4j)."""
    from spslidar import pipeline

    rmse = {}
    for length in (1023, 16383):
        meas = pipeline.measure(size=32, code_length=length, seed=0)
        short = pipeline.reconstruct(meas, qcr=False)
        long_ = pipeline.reconstruct(meas, qcr=False, iterations=250)
        assert short.metrics["config"]["nonneg"] is False
        # the same depth map up to a pixel or two that the MRF may settle either way (at
        # 16383 bits one such pixel, 0.5 m off, is 0.009 m of RMSE): the share of pixels
        # off by > 5 cm within 1 % of the image, the median error within 1 mm
        truth, valid = meas.scene.depth, meas.scene.valid
        # (a pixel without a return, NaN, counts as off)
        err = [np.abs(np.asarray(r.depth) - truth)[valid] for r in (short, long_)]
        off = [np.mean(~(e <= 0.05)) for e in err]
        assert off[0] == pytest.approx(off[1], abs=0.01)
        assert np.nanmedian(err[0]) == pytest.approx(np.nanmedian(err[1]), abs=1e-3)
        assert not any("not converged" in w for w in short.metrics["warnings"])
        rmse[length] = long_.metrics["depth_rmse_m"]
    assert rmse[16383] < 0.5 * rmse[1023]
