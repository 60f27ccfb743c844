"""The reflectivity refitted with the depth held (``spslidar.refit``) and its edge-weighted
TV (``spslidar.solvers.weighted_tv``): the prox against the project's own anisotropic TV (an
independent banded implementation) and against separate images where an edge is cut, the
operator's adjoint and norm bound, exact recovery in the noiseless limit, another surface's
returns taken out of the data, and the pipeline's reflectivity on a scene of uniform
reflectivity."""

from __future__ import annotations

import numpy as np
import pytest

import spslidar
from spslidar.operators.base import MatrixOperator, dottest, power_norm
from spslidar.pipeline.weights import LAM_FLOOR
from spslidar.refit import (
    PlacedReturns,
    apart,
    depth_edges,
    refit_reflectivity,
    return_shapes,
)
from spslidar.solvers.regularisers import make_tv_aniso
from spslidar.solvers.weighted_tv import EdgeWeightedTV


def _ones(ny, nx):
    return np.ones((ny - 1, nx)), np.ones((ny, nx - 1))


@pytest.mark.parametrize("nonneg", [False, True])
def test_unit_weights_are_the_anisotropic_tv(nonneg):
    """Unit weights: the same prox as the banded FGP of ``--regulariser tv-aniso`` (both run
    to convergence, so they agree to round-off), and the same value."""
    rng = np.random.default_rng(0)
    v = rng.normal(size=(7 * 9, 3))
    ours = EdgeWeightedTV((7, 9), *_ones(7, 9), nonneg=nonneg, max_inner=3000)
    ref = make_tv_aniso((7, 9), nonneg=nonneg, max_inner=3000)
    ref.inner_tol = 0.0
    np.testing.assert_allclose(ours.prox(v, 0.3), ref.prox(v, 0.3), atol=1e-8)
    np.testing.assert_allclose(ours.values(v), ref.values(v), rtol=1e-12)


def test_a_cut_edge_splits_the_image():
    """Zero weights along a column boundary: the prox is each side's own prox, computed as a
    separate image by the unweighted TV; the value is the sides' values summed."""
    rng = np.random.default_rng(1)
    img = rng.normal(size=(6, 10))
    wy, wx = _ones(6, 10)
    wx[:, 3] = 0.0  # between columns 3 and 4
    ours = EdgeWeightedTV((6, 10), wy, wx, nonneg=True, max_inner=3000)
    got = ours.prox(img.ravel(), 0.4).reshape(6, 10)
    for part in (img[:, :4], img[:, 4:]):
        ref = make_tv_aniso(part.shape, nonneg=True, max_inner=3000)
        ref.inner_tol = 0.0
        want = ref.prox(part.ravel(), 0.4).reshape(part.shape)
        sl = slice(0, 4) if part.shape[1] == 4 else slice(4, 10)
        np.testing.assert_allclose(got[:, sl], want, atol=1e-8)
    whole = float(ours(img.ravel()))
    sides = sum(float(make_tv_aniso(p.shape)(p.ravel())) for p in (img[:, :4], img[:, 4:]))
    np.testing.assert_allclose(whole, sides, rtol=1e-12)


def test_weighted_prox_beats_its_neighbours():
    """The prox minimises ``1/2 ||z - v||^2 + t TV_w(z)`` over ``z >= 0``: no feasible
    perturbation of it does better (random weights in [0, 2], 200 perturbations)."""
    rng = np.random.default_rng(2)
    wy, wx = rng.uniform(0, 2, (4, 5)), rng.uniform(0, 2, (5, 4))
    reg = EdgeWeightedTV((5, 5), wy, wx, nonneg=True, max_inner=5000)
    v = rng.normal(size=25)
    z = reg.prox(v, 0.25)

    def f(x):
        return 0.5 * float(np.sum((x - v) ** 2)) + 0.25 * float(reg(x))

    best = f(z)
    for _ in range(200):
        trial = np.clip(z + 1e-3 * rng.normal(size=25), 0.0, None)
        assert f(trial) >= best - 1e-9
    assert (z >= 0).all()


@pytest.mark.parametrize("bad", [
    dict(weights_y=np.ones((3, 5)), weights_x=np.ones((5, 4))),  # y weights mis-shaped
    dict(weights_y=np.ones((4, 5)), weights_x=-np.ones((5, 4))),  # negative
    dict(weights_y=np.full((4, 5), np.nan), weights_x=np.ones((5, 4))),  # not finite
])
def test_weighted_tv_refuses_bad_weights(bad):
    with pytest.raises(ValueError, match="weights"):
        EdgeWeightedTV((5, 5), **bad)


def test_weighted_tv_refuses_columns_of_another_size():
    reg = EdgeWeightedTV((4, 5), *_ones(4, 5))
    with pytest.raises(ValueError, match="edge-weighted TV on 4x5 images applied to 21 rows"):
        reg.prox(np.ones(21), 0.1)


def _problem(rng, n=12, m=200, k=8):
    """A random pattern operator and a cube of one return per pixel: strengths ``r``
    (piecewise constant), delays ``centre`` in two planes, shapes over 2-3 delays."""
    q = n * n
    A = MatrixOperator(rng.uniform(0, 1, (m, q)) - 0.5)
    r = np.full((n, n), 0.8)
    r[:, n // 2:] = 0.3
    r[2:5, 2:5] = 1.0
    centre = np.where(np.arange(q) % n < n // 3, 2, 5)
    frac = rng.uniform(0, 0.4, q)
    cube = np.zeros((q, k))
    cube[np.arange(q), centre] = 1.0 - frac
    cube[np.arange(q), centre + 1] = frac
    have = np.ones(q, dtype=bool)
    return A, r.ravel(), centre, have, cube


def test_placed_returns_adjoint_and_norm():
    """``<B r, y> = <r, B^H y>``; the bound of ``||B||^2`` holds against a power iteration."""
    rng = np.random.default_rng(3)
    A, r, centre, have, cube = _problem(rng)
    B = PlacedReturns(A, return_shapes(cube, centre, have))
    assert dottest(B, n_cols=2) < 1e-10
    np.testing.assert_allclose(B @ r, (A @ (r[:, None] * cube)).ravel(), rtol=1e-12)
    assert B.lipschitz_bound(power_norm(A) ** 2) >= power_norm(B) ** 2 / 1.02


def test_return_shapes():
    """Each pixel's non-negative profile over its window, summing to 1; the centre alone where
    the window holds nothing; a row of zeros without a return or off the delays."""
    prof = np.array([[0.0, 1.0, 3.0, -2.0, 5.0],
                     [0.0, 0.0, 0.0, 0.0, 0.0],
                     [1.0, 1.0, 1.0, 1.0, 1.0],
                     [1.0, 1.0, 1.0, 1.0, 1.0]])
    h = return_shapes(prof, np.array([2, 2, 0, 9]), np.array([True, True, True, True]))
    np.testing.assert_allclose(h[0], [0, 0.25, 0.75, 0, 0])
    np.testing.assert_allclose(h[1], [0, 0, 1, 0, 0])
    np.testing.assert_allclose(h[2], [0.5, 0.5, 0, 0, 0])
    np.testing.assert_allclose(h[3], 0.0)
    h = return_shapes(prof, np.array([2, 2, 0, 9]), np.array([False, True, True, True]))
    np.testing.assert_allclose(h[0], 0.0)


def test_refit_recovers_strengths_noiseless():
    """Noiseless data of a cube of one return per pixel and an exact depth: the refit gives
    each pixel's strength (the weight is at its floor, 0.3 % of max |B^H y|: within 2 %)."""
    rng = np.random.default_rng(4)
    A, r, centre, have, cube = _problem(rng)
    y = A @ (r[:, None] * cube)
    est, info = refit_reflectivity(A, y, cube, cube, centre, have, (12, 12), sigma_eff=0.0,
                                   iterations=400, floor_share=LAM_FLOOR)
    np.testing.assert_allclose(est, r, rtol=0.02)
    assert info["iterations"] == 400 and info["weight"] > 0 and info["delays"] == 4


def test_refit_takes_another_surfaces_returns_out():
    """A second surface behind half the pixels, far from every window at its delay, is in
    the data: taken out as the solve placed it, the strengths are those of the first returns;
    left in (``apart`` reaching everything), they are not."""
    rng = np.random.default_rng(5)
    A, r, centre, have, cube = _problem(rng, m=120, k=10)
    first = r[:, None] * cube
    behind = np.zeros_like(first)
    # pixels at delay 2 (columns 0-3), a wall behind columns 0-1 at delay 5, where columns
    # 4-11 have their returns: three pixels or more from them
    left = (np.arange(144) % 12) < 2
    behind[left, 5] = 0.5
    y = A @ (first + behind)
    profiles = first + behind  # a perfect solve's cube
    est, _ = refit_reflectivity(A, y, profiles, profiles, centre, have, (12, 12),
                                sigma_eff=0.0, iterations=400, floor_share=LAM_FLOOR)
    np.testing.assert_allclose(est, r, rtol=0.02)
    assert apart(profiles, return_shapes(profiles, centre, have) > 0, (12, 12))[left, 5].min() \
        == 0.5
    import spslidar.refit as refit_module

    keep = refit_module.APART_PIXELS
    refit_module.APART_PIXELS = 12  # every value "near" a window: nothing taken out
    try:
        kept, _ = refit_reflectivity(A, y, profiles, profiles, centre, have, (12, 12),
                                     sigma_eff=0.0, iterations=400, floor_share=LAM_FLOOR)
    finally:
        refit_module.APART_PIXELS = keep
    assert np.max(np.abs(kept - r) / r) > 0.1


def test_depth_edges():
    """1 between neighbours within ``step`` delays of each other, 0 across a larger step and
    beside a pixel without a return."""
    c = np.array([[0, 1, 9], [0, 4, 9]])
    have = np.array([[True, True, True], [True, True, False]])
    wy, wx = depth_edges(c.ravel(), have.ravel(), (2, 3), step=3)
    np.testing.assert_array_equal(wy, [[1, 1, 0]])  # (a step of 3 is within)
    np.testing.assert_array_equal(wx, [[1, 0], [0, 0]])


def test_pipeline_reflectivity_of_a_uniform_scene():
    """The camera scene has reflectivity 1 everywhere: refitted, 90 % of its pixels read
    within 10 % of it (the window's sum: 0.52-1.19 over 5-95 % at this size, measured
    2026-12-01), and ``metrics.json`` says how it was read. No truth is read by the refit."""
    m = spslidar.measure(scene="camera", size=32, code_length=4095, noise=5, seed=0)
    r = spslidar.reconstruct(m)
    assert r.metrics["reflectivity_method"]["method"] == "refit"
    ratio = r.reflectivity[np.isfinite(r.reflectivity)]
    lo, hi = np.percentile(ratio, [5, 95])
    assert 0.9 < lo and hi < 1.1, (lo, hi)


def test_a_unipolar_replica_keeps_the_window():
    """Where the refit's model does not hold (a unipolar replica's plateau under every
    profile), the window's sum is kept and said (a calibrated instrument is refitted:
    tests/test_calibration.py)."""
    m = spslidar.measure(scene="steps", size=16, code_length=1023, noise=1, seed=0,
                         replica="unipolar")
    r = spslidar.reconstruct(m)
    assert r.metrics["reflectivity_method"] == {"method": "window"}


def test_an_aliased_gate_refits_every_return():
    """A gate longer than the code's period (127 bits: its delays taken modulo the period):
    each pixel's return is placed at its delay's column, so every pixel with a depth has a
    refitted reflectivity (they were all NaN when the gate's delays were read as the data's
    columns, a first version)."""
    m = spslidar.measure(size=16, code_length=127, seed=0)
    r = spslidar.reconstruct(m)
    assert np.asarray(m.ulags).size < 200  # (the unique delays: the period's)
    info = r.metrics["reflectivity_method"]
    assert info["method"] == "refit" and info["delays"] > 0
    found = np.isfinite(r.depth)
    assert found.any() and np.isfinite(r.reflectivity[found]).all()


def test_refit_columns_are_checked():
    rng = np.random.default_rng(6)
    A, r, centre, have, cube = _problem(rng)
    y = A @ (r[:, None] * cube)
    with pytest.raises(ValueError, match="columns"):
        refit_reflectivity(A, y, cube, cube, centre, have, (12, 12), sigma_eff=0.0,
                           columns=np.arange(cube.shape[1]) + 1)


def test_a_pixelwise_solve_keeps_its_light():
    """GPSR's wavelet solve spreads a return along its own delays, not into its neighbours:
    nothing is taken out of its data (the camera read a median 0.76 of its reflectivity of 1
    when its spread was taken for another surface's light, 0.97 without: an outside audit of
    2026-12-01)."""
    m = spslidar.measure(scene="camera", size=32, code_length=2047, seed=0)
    r = spslidar.reconstruct(m, solver="gpsr")
    assert r.metrics["reflectivity_method"]["method"] == "refit"
    assert 0.9 < np.median(r.reflectivity[np.isfinite(r.reflectivity)]) < 1.1


def test_an_empty_gate_refits_nothing():
    """A noiseless gate without the scene: an empty depth map, no reflectivity, and the record
    says the refit did not make it (it said "refit" with 65 delays, an outside audit)."""
    r = spslidar.run(scene="camera", size=16, code_length=1023, noiseless=True,
                     range_gate=(30.0, 31.0), seed=0)
    assert np.isnan(r.depth).all() and np.isnan(r.reflectivity).all()
    assert r.metrics["reflectivity_method"] == {"method": "window"}


def test_the_tv_is_cut_at_the_depths_steps():
    """Two surfaces 13 delays apart, reflectivities 1.0 and 0.2, 60 patterns over 144 pixels
    under a heavy weight: cut at the step, each keeps its own level (within 5 %); the
    unweighted TV of the same weight pulls them together (the dark one read 0.49)."""
    rng = np.random.default_rng(7)
    n, k = 12, 20
    q = n * n
    A = MatrixOperator(rng.uniform(0, 1, (60, q)) - 0.5)
    left = (np.arange(q) % n) < n // 2
    r = np.where(left, 1.0, 0.2)
    centre = np.where(left, 2, 15)
    cube = np.zeros((q, k))
    cube[np.arange(q), centre] = 1.0
    y = A @ (r[:, None] * cube)
    have = np.ones(q, dtype=bool)
    kw = dict(sigma_eff=1.0, scale=10.0, iterations=300)
    cut, _ = refit_reflectivity(A, y, cube, cube, centre, have, (n, n), **kw)
    np.testing.assert_allclose(cut, r, rtol=0.05)
    import spslidar.refit as refit_module

    keep = refit_module.EDGE_BINS
    refit_module.EDGE_BINS = 100  # no step is a step: the plain anisotropic TV
    try:
        joined, _ = refit_reflectivity(A, y, cube, cube, centre, have, (n, n), **kw)
    finally:
        refit_module.EDGE_BINS = keep
    assert np.median(joined[~left]) > 1.5 * 0.2  # (0.49 measured)
