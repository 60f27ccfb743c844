"""The depth estimators on cubes a user makes (an outside audit of 2026-11-29): noiseless
blocks, a NaN delay, a corrupt value, a flat window. Each test failed before its mend."""

from __future__ import annotations

import numpy as np
import pytest

from spslidar.depth import ESTIMATORS, DepthContext
from spslidar.errors import ConfigError

NAMES = ["argmax", "censor", "evidence", "guarded", "mrf"]
BIN = 1e-10 * 299792458 / 2  # metres per slice at 10 GHz


def _lags(depth):
    return np.round(np.asarray(depth) / BIN - 0.25, 2)  # pulse width 0.5: +0.25 bin


@pytest.mark.parametrize("name", NAMES)
def test_a_dim_pole_in_a_noiseless_block_keeps_its_only_return(name):
    """A pole at a tenth of the wall's strength, one return per pixel and exact zeros
    elsewhere: mrf and evidence gave it the wall (where its profiles hold 0; evidence also
    reported the pole's only return as a second surface), censor its ends two slices off.
    The noise scale of a noiseless block was the whole block's RMS, one pole's height."""
    n, k = 8, 60
    x = np.zeros((n, n, k))
    x[:, :, 40] = 1.0
    x[:, 4, 40] = 0.0
    x[:, 4, 10] = 0.1
    out = ESTIMATORS.load(name)().estimate(x.reshape(n * n, k),
                                           DepthContext(np.arange(k), 1e-10, 0.5, (n, n)))
    depth = _lags(out.depth).reshape(n, n)
    assert (depth[:, 4] == 10.0).all() and (np.delete(depth, 4, axis=1) == 40.0).all()
    if out.depth2 is not None:
        assert np.isnan(out.depth2).all()  # one return per pixel: no second surface


@pytest.mark.parametrize("name", NAMES)
def test_a_nan_delay_is_no_evidence_not_a_void_image(name):
    """One NaN column made every pixel "no return" (the whole profile was voided); a pixel
    with no finite value at all still has none."""
    x = np.zeros((64, 40))
    x[:, 10] = 1.0
    x[:, 30] = np.nan
    x[5] = np.nan
    out = ESTIMATORS.load(name)().estimate(x, DepthContext(np.arange(40), 1e-10, 0.5, (8, 8)))
    d = _lags(out.depth)
    assert np.isnan(d[5]) and out.confidence[5] == 0.0
    assert (np.delete(d, 5) == 10.0).all()


@pytest.mark.parametrize("hot", [3e38, 1e45])
def test_one_corrupt_value_is_refused_not_read(hot):
    """A value 3e38-1e45 times the rest: the rest underflowed the estimators' float32 (every
    MRF depth the first lag and NaN confidences, or 129 of 255 pixels NaN). One line; at
    1e36 the rest stays within float32 and is read right (below)."""
    rng = np.random.default_rng(0)
    y = np.maximum(0.05 * rng.standard_normal((256, 60)), 0)
    y[:, 30] += 1.0
    y[0, 10] = hot
    for name in ("argmax", "mrf"):
        with pytest.raises(ConfigError, match="decades.*is a value corrupt"):
            ESTIMATORS.load(name)().estimate(y, DepthContext(np.arange(60), 1e-10, 0.5,
                                                             (16, 16)))
    y[0, 10] = 1e36  # large, within what the estimators resolve: read, the wall at lag 30
    out = ESTIMATORS.load("mrf")().estimate(y, DepthContext(np.arange(60), 1e-10, 0.5, (16, 16)))
    assert (_lags(out.depth)[1:] == 30.0).all()


def test_a_nan_confidence_is_no_confidence_and_its_depth_is_flagged():
    """NaN confidences were written as they were; refused (an audit's first mend), a plugin
    whose confidence is a peak share (0/0 on an all-zero profile) was refused over pixels
    without a return, which an empty automatic gate makes of every pixel (a review)."""
    from spslidar.depth.base import DepthEstimate, _checked_estimate

    est = DepthEstimate(depth=np.array([0.0, 1.0, np.nan, 2.0]),
                        confidence=np.array([0.5, np.nan, np.nan, 0.0]),
                        peak=np.ones(4), low_confidence=np.zeros(4, bool))
    out = _checked_estimate(est, 4, "Mine")
    assert out.confidence.tolist() == [0.5, 0.0, 0.0, 0.0]
    assert out.low_confidence.tolist() == [False, True, False, False]
    est.confidence = np.array([0.5, 1.5, 0.0, 0.0])
    with pytest.raises(ConfigError, match="outside"):
        _checked_estimate(est, 4, "Mine")


def test_censor_keeps_its_candidate_where_the_window_is_flat():
    """A censored pixel whose window holds exact zeros took the window's first slice, two in
    front of its neighbours (3 cm towards the sensor, supported by nothing)."""
    rng = np.random.default_rng(1)
    n, k = 8, 80
    x = np.maximum(0.05 * rng.standard_normal((n * n, k)), 0)
    x[:, 40] += 1.0
    x[27] = np.maximum(0.05 * rng.standard_normal(k), 0)
    x[27, 34:47] = 0.0
    out = ESTIMATORS.load("censor")().estimate(x, DepthContext(np.arange(k), 1e-10, 0.5, (n, n)))
    assert out.info["censored_fraction"] > 0
    assert _lags(out.depth)[27] == 40.0


def test_censor_reads_a_straight_edge_and_a_pole_at_the_border_as_no_outliers():
    """The ROAD statistic is 0 on both sides of a straight edge and along a one-pixel pole,
    but at the image's border the pair along the edge is missing, and the pair across it
    alone read 10 slices (confidence 0.19 and flagged on a noiseless step; 0.036 at a pole's
    ends): the extrapolations now join the pairs there are."""
    from spslidar.depth.censor import road_linear

    step = np.where(np.arange(8)[None, :] < 4, 40.0, 20.0) * np.ones((8, 1))
    assert not road_linear(step).any()
    pole = np.full((8, 8), 40.0)
    pole[:, 4] = 10.0
    assert not road_linear(pole).any()
    spike = step.copy()
    spike[0, 1] = 55.0  # an outlier at the border is still one
    assert road_linear(spike)[0, 1] >= 15.0
    x = np.zeros((64, 60))
    x[np.arange(64), step.ravel().astype(int)] = 1.0
    out = ESTIMATORS.load("censor")().estimate(x, DepthContext(np.arange(60), 1e-10, 0.5, (8, 8)))
    assert out.confidence.min() == 1.0 and not out.low_confidence.any()


def test_a_sparse_cube_at_any_scale_is_read_not_refused():
    """The corrupt-value check read the median of all non-zero values, the dust of a sparse
    cube: one return of 2e19 per pixel over 1e-15 dust was refused, the same cube divided by
    1e5 read (a review). It reads the typical pixel's peak."""
    rng = np.random.default_rng(0)
    x = np.where(rng.random((64, 40)) < 0.9, 1e-15, 0.0)
    x[np.arange(64), 12] = 2e19
    x[:32, 12] = 0.0  # half the pixels hold dust alone: still read, at every scale
    for scale in (1.0, 1e-5, 2.0**70, 2.0**-70):
        out = ESTIMATORS.load("argmax")().estimate(x * scale, DepthContext(
            np.arange(40), 1e-10, 0.5, (8, 8)))
        assert (_lags(out.depth)[32:] == 12.0).all()
