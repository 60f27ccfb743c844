"""Conformance suites over the stage registries, discovered: every registered code family,
pattern kind, detector model and depth estimator is tested by the same contract, so a new
entry is tested without touching this file (and fails here if it breaks the contract).
Solvers and regularisers have theirs in ``test_solver_conformance.py``.

* codes: the length asked for, 0/1 bits, reproducible from the generator, a share of ones the
  family promises, and a periodic correlation with a single peak (what the matched filter of
  eq. 5-6 needs);
* pattern operators: the adjoint (dot) test for single and batched columns, the dtype asked
  for, mirror states in [0, 1] as the DMD shows them, no side effect on the input, the same
  patterns from the same seed;
* detectors: the mean of ``detect`` is ``expected`` (Monte Carlo, 5 standard errors), and
  ``correct`` inverts ``expected`` at low flux;
* depth estimators: noiseless recovery of a depth map with a one-pixel pole, a step and a
  slanted plane, confidence in [0, 1], no depth where no pixel has a return.
"""

from __future__ import annotations

import numpy as np
import pytest

from spslidar.codes import CODES
from spslidar.config import Config
from spslidar.constants import SPEED_OF_LIGHT
from spslidar.depth import ESTIMATORS, DepthContext
from spslidar.detectors import DETECTORS, build_detector
from spslidar.errors import ConfigError
from spslidar.patterns import PATTERNS, build_patterns
from spslidar.pipeline.chain import detector_options

#: candidate code lengths, the first one a family accepts is used
_LENGTHS = (127, 255, 511, 1023, 128)


def _code_length(name: str) -> int:
    for length in _LENGTHS:
        try:
            CODES.get(name).check(Config.from_dict({"code": name, "code_length": length}))
        except ConfigError:
            continue
        return length
    pytest.fail(f"code family {name!r} accepts none of the lengths {_LENGTHS}")


@pytest.mark.parametrize("name", CODES.names())
def test_code_family_contract(name):
    length = _code_length(name)
    index = CODES.get(name).defaults.get("index", 0)
    make = CODES.load(name)
    code = np.asarray(make(name, length, 0.5, np.random.default_rng(1), index))
    again = np.asarray(make(name, length, 0.5, np.random.default_rng(1), index))
    assert code.shape == (length,)
    assert set(np.unique(code)) <= {0, 1}
    np.testing.assert_array_equal(code, again)  # reproducible from the generator
    ones = int(code.sum())
    # the m-sequence and Gold families have (L + 1) / 2 ones; a Bernoulli code's share is
    # within 5 binomial standard deviations of the one asked for
    assert abs(ones - length / 2) <= max(1, 5 * np.sqrt(length / 4)), ones
    # the bipolar periodic correlation has its peak at lag 0 only, at least twice any sidelobe
    b = 2.0 * code - 1.0
    corr = np.fft.ifft(np.fft.fft(b) * np.conj(np.fft.fft(b))).real
    assert corr[0] == pytest.approx(length, rel=1e-9)
    assert np.max(np.abs(corr[1:])) <= corr[0] / 2


def _pattern_cfg(name: str) -> Config:
    return Config.from_dict({"patterns": name, "size": 8, "compression": 0.5})


@pytest.mark.parametrize("name", PATTERNS.names())
@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_pattern_operator_contract(name, dtype):
    from spslidar.operators import dottest

    cfg = _pattern_cfg(name)
    PATTERNS.get(name).check(cfg)
    m, n = 32, cfg.size
    op = build_patterns(name, m, n, np.random.default_rng(3), dtype=dtype)
    same = build_patterns(name, m, n, np.random.default_rng(3), dtype=dtype)
    assert op.shape == (m, n * n)
    # the adjoint: the default tolerances of dottest are the dtypes' (1e-4 / 1e-10)
    dottest(op, n_cols=1, rng=0)
    dottest(op, n_cols=3, rng=1)
    x = np.random.default_rng(4).standard_normal((n * n, 2)).astype(dtype)
    x0 = x.copy()
    y = np.asarray(op.matvec(x))
    np.testing.assert_array_equal(x, x0)  # no side effect on the input
    assert y.dtype == np.dtype(dtype)
    np.testing.assert_array_equal(y, np.asarray(same.matvec(x)))  # same seed, same patterns
    shown = np.asarray(op.apply_rows(slice(0, m), np.eye(n * n, dtype=dtype)))
    # as the DMD shows them: mirror states in [0, 1] (grey levels allowed), row by row equal
    # to the operator's own products (float32 round-off: 1e-5 of the row sums)
    assert shown.min() >= -1e-6 and shown.max() <= 1 + 1e-6
    np.testing.assert_allclose(shown @ x[:, 0].astype(np.float64), y[:, 0],
                               rtol=1e-5, atol=1e-5 * n * n)


def _detector(name: str):
    cfg = Config.from_dict({"detector": name})
    DETECTORS.get(name).check(cfg)
    return build_detector(name, **detector_options(cfg))


@pytest.mark.parametrize("name", DETECTORS.names())
def test_detector_mean_is_expected(name):
    """Mean of many detections = ``expected``, bin by bin, within 5 standard errors."""
    det = _detector(name)
    rng = np.random.default_rng(7)
    period, n_periods, reps = 64, 50, 400
    lam = np.full((1, period), 0.002 * n_periods)
    lam[0, 10] = 0.05 * n_periods  # a return over a low background
    mean = np.zeros(period)
    sq = np.zeros(period)
    for _ in range(reps):
        counts, totals = det.detect(lam.copy(), rng, n_periods)
        c = np.asarray(counts, np.float64)[0]
        assert totals[0] == pytest.approx(c.sum())
        mean += c
        sq += c * c
    mean /= reps
    se = np.sqrt(np.maximum(sq / reps - mean**2, 1e-12) / reps)
    expected = np.asarray(det.expected(lam, n_periods), np.float64)[0]
    assert np.all(np.abs(mean - expected) <= 5 * se + 1e-9)


@pytest.mark.parametrize("name", DETECTORS.names())
def test_detector_correct_inverts_at_low_flux(name):
    """``correct(expected(lam))`` gives ``lam`` back at low flux (0.1 % of the flux per dead
    time: pile-up is a per-mille effect, and the inverse must remove it)."""
    det = _detector(name)
    n_periods = 100
    lam = np.full((2, 128), 1e-4 * n_periods)
    lam[:, 20] = 5e-3 * n_periods
    back = np.asarray(det.correct(np.asarray(det.expected(lam, n_periods)), n_periods))
    np.testing.assert_allclose(back, lam, rtol=1e-4)


def _depth_problem(n: int = 12, bins: int = 40):
    """Noiseless slices of a scene with a step, a slanted plane and a one-pixel pole: one
    unit return per pixel at its true lag, zero elsewhere."""
    bin_w = 1e-10
    d_bin = SPEED_OF_LIGHT * bin_w / 2
    lag0 = 1000
    true = np.full((n, n), 30)
    true[:, n // 2:] = 20  # a step
    true[: n // 3, :] = 8 + np.arange(n)[None, :]  # a slanted plane (one bin per column)
    true[n // 2, 2] = 36  # a one-pixel pole in front of nothing like it
    slices = np.zeros((n * n, bins))
    slices[np.arange(n * n), true.ravel()] = 1.0
    ctx = DepthContext(np.arange(lag0, lag0 + bins), bin_w, 0.5, (n, n), False)
    # a half-bin pulse inside bin t starts anywhere in [t, t + 1/2): eq. 2-3 read it at the
    # middle, t + 1/2 - pulse_width / 2
    depth = (lag0 + true + 0.5 - ctx.pulse_width / 2) * d_bin
    return slices, ctx, depth


@pytest.mark.parametrize("name", ESTIMATORS.names())
def test_depth_estimator_noiseless_recovery(name):
    slices, ctx, depth = _depth_problem()
    est = ESTIMATORS.load(name)().estimate(slices.copy(), ctx)
    got = np.asarray(est.depth).reshape(depth.shape)
    # exact to a hundredth of a bin (a centroid of a one-bin return is the bin itself)
    np.testing.assert_allclose(got, depth, atol=0.01 * SPEED_OF_LIGHT * ctx.bin_width / 2)
    conf = np.asarray(est.confidence)
    assert conf.shape == (depth.size,) and np.all((conf >= 0) & (conf <= 1))
    assert np.asarray(est.low_confidence).dtype == bool


@pytest.mark.parametrize("name", ESTIMATORS.names())
def test_depth_estimator_without_returns(name):
    """No return anywhere: no depth anywhere (NaN), confidence 0."""
    slices, ctx, depth = _depth_problem()
    est = ESTIMATORS.load(name)().estimate(np.zeros_like(slices), ctx)
    assert np.all(np.isnan(est.depth))
    assert np.all(np.asarray(est.confidence) == 0)


def _scene_specs():
    from spslidar.scenes import SCENES

    for e in SCENES:
        arg = e.defaults.get("argument")
        yield f"{e.name}:{e.defaults.get('example', '0')}" if arg else e.name


@pytest.mark.parametrize("spec", list(_scene_specs()))
def test_scene_kind_contract(spec):
    """Every registered scene kind loads by name at any size, as a valid :class:`Scene`
    inside its depth window, the same twice, and rescales into a window given."""
    from spslidar.scenes import load_scene

    a, b = load_scene(spec, 16), load_scene(spec, 16)
    assert a.depth.shape == a.reflectivity.shape == a.valid.shape == (16, 16)
    assert a.valid.any() and np.all(np.isfinite(a.depth)) and a.depth.min() >= 0
    assert 0 <= a.reflectivity.min() and a.reflectivity.max() <= 1
    np.testing.assert_array_equal(a.depth, b.depth)
    w = load_scene(spec, 16, 7.0, 8.0)
    d = w.depth[w.valid]
    # the window is filled to round-off (a linear remap in float64)
    assert d.min() == pytest.approx(7.0, abs=1e-9) and d.max() == pytest.approx(8.0, abs=1e-9)
