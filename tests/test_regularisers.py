"""Regularisers and their proxes: TV (FGP) against scikit-image and PyProximal, L1, Zero."""

from __future__ import annotations

import numpy as np
import pytest

from spslidar.operators import Gradient2D, Wavelet2D
from spslidar.solvers.regularisers import L1, TV, Zero


def _piecewise_image(ny: int, nx: int, rng: np.random.Generator, sigma: float = 0.2):
    img = np.zeros((ny, nx))
    img[ny // 4 : 3 * ny // 4, nx // 5 : 3 * nx // 5] = 1.0
    img[:, 4 * nx // 5 :] = 0.5
    img[ny // 2 :, : nx // 6] = -0.3
    return img + sigma * rng.standard_normal((ny, nx))


def _prox_objective(reg, z, v, t):
    return 0.5 * float(np.sum((z - v) ** 2)) + t * reg(z)


def _duality_gap(reg: TV, v: np.ndarray, t: float) -> tuple[float, float]:
    """Primal-dual gap of the TV prox at its final dual iterate ``reg.dual``.

    Dual of min_z 1/2||z - v||^2 + t TV(z) [+ i_{z>=0}]: with w = v - t G^T p,
    D(p) = 1/2||P_C(w) - w||^2 + 1/2||v||^2 - 1/2||w||^2 for p in the unit balls/boxes.
    """
    g = Gradient2D(reg.image_shape)
    p = reg.dual.reshape(-1, v.shape[1])
    w = v - t * (g.H @ p)
    z = np.maximum(w, 0) if reg.nonneg else w
    primal = _prox_objective(reg, z, v, t)
    dual = 0.5 * np.sum((z - w) ** 2) + 0.5 * np.sum(v**2) - 0.5 * np.sum(w**2)
    return primal, primal - dual


def test_tv_value_matches_gradient2d():
    rng = np.random.default_rng(0)
    ny, nx, k = 7, 9, 3
    x = rng.standard_normal((ny * nx, k))
    g = (Gradient2D((ny, nx)) @ x).reshape(2, ny * nx, k)
    iso = np.sqrt(g[0] ** 2 + g[1] ** 2).sum(axis=0)
    aniso = np.abs(g).sum(axis=(0, 1))
    reg = TV((ny, nx))
    np.testing.assert_allclose(reg.values(x), iso, rtol=1e-12)
    assert reg(x) == pytest.approx(iso.sum(), rel=1e-12)
    assert TV((ny, nx), isotropic=False)(x) == pytest.approx(aniso.sum(), rel=1e-12)
    assert reg(x[:, 0]) == pytest.approx(iso[0], rel=1e-12)
    # attributes used by other solvers
    assert reg.image_shape == (ny, nx) and reg.isotropic and not reg.nonneg
    assert isinstance(reg.gradient, Gradient2D) and reg.gradient.image_shape == (ny, nx)
    assert (reg.gradient @ x.astype(np.float32)).dtype == np.float32
    assert (reg.gradient @ x).dtype == np.float64


def test_tv_value_matches_pyproximal():
    import pyproximal
    rng = np.random.default_rng(1)
    img = rng.standard_normal((6, 8))
    ours = TV(img.shape)(img.ravel())
    theirs = pyproximal.TV(dims=img.shape, sigma=1.0)(img.ravel())
    assert ours == pytest.approx(theirs, rel=1e-12)


def test_tv_prox_vs_skimage():
    from skimage.restoration import denoise_tv_chambolle

    rng = np.random.default_rng(2)
    f = _piecewise_image(24, 28, rng)
    t = 0.15
    reg = TV(f.shape, max_inner=3000, inner_tol=1e-7, warm_start=False)
    z = reg.prox(f.ravel(), t)
    # skimage minimises sum |grad u| + 1/(2 weight) ||u - f||^2, i.e. weight = t in our
    # 1/2||z - v||^2 + t TV(z), with the same forward differences / Neumann boundary
    s = denoise_tv_chambolle(f, weight=t, eps=1e-7, max_num_iter=5000)
    ours = _prox_objective(reg, z, f.ravel(), t)
    theirs = _prox_objective(reg, s.ravel(), f.ravel(), t)
    assert ours <= theirs * (1 + 1e-3)
    assert theirs <= ours * (1 + 1e-3)  # both converged to the same minimum
    np.testing.assert_allclose(z, s.ravel(), atol=2e-2)


def test_tv_prox_vs_pyproximal():
    import pyproximal
    rng = np.random.default_rng(3)
    f = _piecewise_image(16, 20, rng)
    t = 0.2
    reg = TV(f.shape, max_inner=3000, inner_tol=1e-7, warm_start=False)
    z = reg.prox(f.ravel(), t)
    # pyproximal's TV(sigma).prox(x, tau) = argmin 1/2||z - x||^2 + sigma tau TV(z)
    zp = pyproximal.TV(dims=f.shape, sigma=1.0, niter=2000, rtol=1e-12).prox(f.ravel(), t)
    ours = _prox_objective(reg, z, f.ravel(), t)
    theirs = _prox_objective(reg, zp, f.ravel(), t)
    assert ours <= theirs * (1 + 1e-3)
    assert theirs <= ours * (1 + 1e-3)


@pytest.mark.parametrize("isotropic", [True, False])
@pytest.mark.parametrize("nonneg", [False, True])
def test_tv_prox_duality_gap(isotropic, nonneg):
    rng = np.random.default_rng(4)
    v = np.stack([_piecewise_image(12, 10, rng).ravel() for _ in range(3)], axis=1)
    t = 0.3
    reg = TV((12, 10), isotropic=isotropic, nonneg=nonneg, max_inner=5000, inner_tol=1e-9)
    z = reg.prox(v, t)
    primal, gap = _duality_gap(reg, v, t)
    assert gap >= -1e-9 * primal
    assert gap <= 1e-4 * primal
    assert _prox_objective(reg, z, v, t) == pytest.approx(primal, rel=1e-6)
    if nonneg:
        assert z.min() >= 0
    # the prox beats random feasible perturbations
    for _ in range(5):
        zz = z + 1e-3 * rng.standard_normal(z.shape)
        if nonneg:
            zz = np.maximum(zz, 0)
        assert _prox_objective(reg, zz, v, t) >= _prox_objective(reg, z, v, t) - 1e-9


def test_tv_prox_batched_equals_separate():
    rng = np.random.default_rng(5)
    k = 4
    v = np.stack([_piecewise_image(10, 14, rng, sigma=0.1 * (i + 1)).ravel() for i in range(k)], 1)
    t = 0.25
    batched = TV((10, 14), max_inner=3000, inner_tol=1e-8, warm_start=False).prox(v, t)
    for i in range(k):
        single = TV((10, 14), max_inner=3000, inner_tol=1e-8, warm_start=False).prox(v[:, i], t)
        np.testing.assert_allclose(batched[:, i], single, atol=1e-5)


def test_tv_prox_warm_start():
    rng = np.random.default_rng(6)
    v = np.stack([_piecewise_image(20, 20, rng).ravel() for _ in range(5)], 1)
    t = 0.2
    reg = TV((20, 20), max_inner=2000, inner_tol=1e-5)
    reg.prox(v, t)
    cold_iters = reg.last_inner_iterations
    v2 = v + 1e-3 * rng.standard_normal(v.shape)
    z_warm = reg.prox(v2, t)
    warm_iters = reg.last_inner_iterations
    assert warm_iters < cold_iters / 2
    z_cold = TV((20, 20), max_inner=2000, inner_tol=1e-5, warm_start=False).prox(v2, t)
    obj = TV((20, 20))
    assert _prox_objective(obj, z_warm, v2, t) == pytest.approx(
        _prox_objective(obj, z_cold, v2, t), rel=1e-4
    )
    assert reg.dual.shape == (2, 20, 20, 5) and np.all(np.hypot(*reg.dual) <= 1 + 1e-12)
    # a threshold change rescales the warm start; a shape change falls back to a cold start
    z_t = reg.prox(v2, 2 * t)
    z_t_cold = TV((20, 20), max_inner=2000, inner_tol=1e-5, warm_start=False).prox(v2, 2 * t)
    np.testing.assert_allclose(z_t, z_t_cold, atol=1e-3)
    reg.prox(v2[:, :2], t)
    assert reg.dual.shape == (2, 20, 20, 2)
    reg.reset()
    assert reg.dual is None


def test_tv_prox_dtype_shape_and_trivial_cases():
    rng = np.random.default_rng(7)
    v = rng.standard_normal((8 * 6, 3)).astype(np.float32)
    reg = TV((8, 6))
    z = reg.prox(v, 0.1)
    assert z.dtype == np.float32 and z.shape == v.shape
    assert reg.prox(v[:, 0], 0.1).shape == (48,)
    np.testing.assert_array_equal(reg.prox(v, 0.0), v)
    np.testing.assert_array_equal(TV((8, 6), nonneg=True).prox(v, 0.0), np.maximum(v, 0))
    # a huge threshold flattens each image to its mean (TV of the mean image is 0)
    zz = TV((8, 6), max_inner=5000, inner_tol=1e-10).prox(v.astype(np.float64), 1e3)
    np.testing.assert_allclose(zz, np.broadcast_to(v.mean(0), v.shape), atol=1e-4)
    with pytest.raises(ValueError):
        reg.prox(v, -1.0)
    with pytest.raises(ValueError):
        reg.prox(np.zeros((10, 2)), 0.1)


def test_l1_prox_is_soft_thresholding():
    rng = np.random.default_rng(8)
    v = rng.standard_normal((50, 4))
    t = 0.4
    expected = np.sign(v) * np.maximum(np.abs(v) - t, 0)
    reg = L1()
    np.testing.assert_array_equal(reg.prox(v, t), expected)
    np.testing.assert_array_equal(reg.prox(v[:, 1], t), expected[:, 1])
    np.testing.assert_array_equal(L1(nonneg=True).prox(v, t), np.maximum(v - t, 0))
    assert reg(v) == pytest.approx(np.abs(v).sum())
    np.testing.assert_allclose(reg.values(v), np.abs(v).sum(0))
    assert reg.prox(v.astype(np.float32), t).dtype == np.float32
    assert reg.basis is None


def test_l1_prox_matches_pyproximal():
    import pyproximal
    rng = np.random.default_rng(9)
    v = rng.standard_normal(40)
    np.testing.assert_allclose(L1().prox(v, 0.3), pyproximal.L1(sigma=1.0).prox(v, 0.3))


def test_l1_wavelet_prox():
    rng = np.random.default_rng(10)
    shape = (16, 8)
    w = Wavelet2D(shape, "db2")
    v = rng.standard_normal((16 * 8, 3))
    t = 0.5
    reg = L1(basis=w)
    assert reg.basis is w
    c = w @ v
    expected = w.H @ (np.sign(c) * np.maximum(np.abs(c) - t, 0))
    z = reg.prox(v, t)
    np.testing.assert_allclose(z, expected, atol=1e-12)
    assert reg(v) == pytest.approx(np.abs(c).sum())
    # it is the minimiser: random perturbations do not decrease the prox objective
    base = _prox_objective(reg, z, v, t)
    for _ in range(5):
        assert _prox_objective(reg, z + 1e-3 * rng.standard_normal(z.shape), v, t) >= base
    with pytest.raises(ValueError):
        L1(basis=w, nonneg=True)


def test_zero_regulariser():
    rng = np.random.default_rng(11)
    v = rng.standard_normal((10, 2))
    assert Zero()(v) == 0.0
    np.testing.assert_array_equal(Zero().prox(v, 5.0), v)
    np.testing.assert_array_equal(Zero(nonneg=True).prox(v, 5.0), np.maximum(v, 0))


# -- performance paths: row bands, threads, float32 sums, fast Haar ---------------------------


def _large_tv_input(k=33, seed=12):
    """A block of (64 x 64, k) images big enough for the two-band FGP loop."""
    rng = np.random.default_rng(seed)
    v = np.stack([_piecewise_image(64, 64, rng).ravel() for _ in range(k)], 1)
    return v.astype(np.float32)


@pytest.mark.parametrize("isotropic", [True, False])
@pytest.mark.parametrize("nonneg", [False, True])
def test_tv_prox_row_bands_and_threads_do_not_change_the_result(isotropic, nonneg, monkeypatch):
    v = _large_tv_input()
    kw = dict(isotropic=isotropic, nonneg=nonneg, max_inner=7, inner_tol=0.0)
    assert len(TV((64, 64))._bands((64, 64, v.shape[1]))) == 2
    # reference: one band (the split threshold raised above the block size)
    monkeypatch.setattr(TV, "SPLIT_MIN_SIZE", 1 << 40)
    one = TV((64, 64), **kw)
    z1 = [one.prox(v, 0.2), one.prox(v * 1.01, 0.2)]  # second call warm-started
    monkeypatch.undo()
    for threads in (1, 2):
        reg = TV((64, 64), threads=threads, **kw)
        z = [reg.prox(v, 0.2), reg.prox(v * 1.01, 0.2)]
        for a, b in zip(z, z1, strict=True):
            np.testing.assert_array_equal(a, b)
        np.testing.assert_array_equal(reg.dual, one.dual)
        assert reg.last_inner_iterations == 7


def test_tv_prox_in_a_parallel_context_and_stop_test():
    from spslidar.operators.parallel import parallel

    v = _large_tv_input(k=40)
    ref = TV((64, 64), max_inner=300, inner_tol=5e-3, threads=1)
    z_ref = ref.prox(v, 0.1)
    with parallel(2) as ctx:
        reg = TV((64, 64), max_inner=300, inner_tol=5e-3)
        assert reg._n_threads(2)[0] == (ctx.threads if ctx is not None else 1)
        z = reg.prox(v, 0.1)
    np.testing.assert_array_equal(z, z_ref)
    # the stop test fired in both, at the same iteration
    assert reg.last_inner_iterations == ref.last_inner_iterations < 300


def test_tv_prox_error_in_a_band_thread_is_raised(monkeypatch):
    v = _large_tv_input()
    reg = TV((64, 64), threads=2, max_inner=5)
    orig = TV._fgp_band
    calls = []

    def failing(self, vt, rr, P, Q, R, a, e, *args):
        calls.append(a)
        if a > 0 and len(calls) > 3:
            raise FloatingPointError("boom")
        return orig(self, vt, rr, P, Q, R, a, e, *args)

    monkeypatch.setattr(TV, "_fgp_band", failing)
    with pytest.raises(FloatingPointError, match="boom"):
        reg.prox(v, 0.1)


def test_tv_values_float32_accuracy_and_column_subsets():
    rng = np.random.default_rng(13)
    x = rng.standard_normal((64 * 64, 9)).astype(np.float32)
    reg = TV((64, 64))
    ref = TV((64, 64)).values(x.astype(np.float64))
    np.testing.assert_allclose(reg.values(x), ref, rtol=1e-5)
    # subsets of varying width reuse the scratch and stay exact
    for cols in ([0, 3], [1, 2, 4, 5, 8], [7]):
        np.testing.assert_allclose(reg.values(x[:, cols]), ref[cols], rtol=1e-5)
    reg.prox(x, 0.1)  # with the prox's buffers in place
    np.testing.assert_allclose(reg.values(x), ref, rtol=1e-5)


@pytest.mark.parametrize("shape,level", [((64, 64), None), ((16, 8), None), ((32, 48), 2),
                                         ((8, 8), 1)])
@pytest.mark.parametrize("dtype", [np.float64, np.float32])
def test_fast_haar_matches_pywavelets(shape, level, dtype):
    import pywt

    rng = np.random.default_rng(14)
    w = Wavelet2D(shape, "haar", level=level)
    x = rng.standard_normal((shape[0] * shape[1], 3)).astype(dtype)
    c = w.matvec(x)
    assert c.dtype == dtype
    ref = np.stack([
        pywt.coeffs_to_array(pywt.wavedec2(x[:, j].reshape(shape), "haar",
                                           mode="periodization", level=w.level))[0].ravel()
        for j in range(3)
    ], axis=1)
    tol = 1e-12 if dtype == np.float64 else 2e-6
    np.testing.assert_allclose(c, ref, atol=tol * np.abs(ref).max())
    np.testing.assert_allclose(w.rmatvec(c), x, atol=tol * np.abs(x).max())
    # the adjoint is the inverse, also on data that did not come from the forward transform
    d = rng.standard_normal(c.shape).astype(dtype)
    lhs, rhs = float(np.vdot(w.matvec(x), d)), float(np.vdot(x, w.rmatvec(d)))
    assert lhs == pytest.approx(rhs, rel=1e-10 if dtype == np.float64 else 1e-4)


@pytest.mark.parametrize("isotropic", [True, False])
@pytest.mark.parametrize("ny", [64, 65])
def test_tv_values_in_row_bands_match_gradient2d(isotropic, ny):
    # a block large enough to be valued in two row bands (concurrently in a parallel context)
    from spslidar.operators.parallel import parallel, row_bands

    rng = np.random.default_rng(14)
    nx, k = 48, 48
    x = rng.standard_normal((ny * nx, k))
    assert len(row_bands(ny, x.size)) == 2
    g = (Gradient2D((ny, nx)) @ x).reshape(2, ny * nx, k)
    ref = np.sqrt(g[0] ** 2 + g[1] ** 2).sum(axis=0) if isotropic else np.abs(g).sum(axis=(0, 1))
    reg = TV((ny, nx), isotropic=isotropic)
    serial = reg.values(x)
    np.testing.assert_allclose(serial, ref, rtol=1e-12)
    with parallel(2):
        np.testing.assert_array_equal(reg.values(x), serial)
