"""The contracts of the chain's stages other than solvers: code families, pattern kinds,
detector models, depth estimators and scene kinds (:mod:`spslidar.testing`).

Each ``check_*`` function takes a registered name, builds the stage as the pipeline builds it
(the options it declares at their defaults) and raises :class:`AssertionError` naming the
contract that failed; it returns the list of the contracts it checked.

* code family: the length asked for, 0/1 bits, reproducible from the generator, about as many
  ones as zeros (what the bipolar replica of eq. 5-6 needs), a periodic correlation with a
  single peak;
* pattern kind: the adjoint (dot) test for one and several columns, the dtype asked for,
  mirror states in [0, 1] as the DMD shows them, no side effect on the input, the same
  patterns from the same seed;
* detector model: the mean of ``detect`` is ``expected`` (Monte Carlo, 5 standard errors),
  ``correct`` inverts ``expected`` at low flux;
* depth estimator: noiseless recovery of a step, a slanted plane and a one-pixel pole,
  confidence in [0, 1], no depth where no pixel has a return;
* scene kind: loads at any size as a valid scene, the same twice, rescaled into a window
  given.
"""

from __future__ import annotations

import numpy as np

from ..config import Config, chosen_stage_options
from ..constants import SPEED_OF_LIGHT
from ..errors import ConfigError

__all__ = ["check_code_family", "check_depth_estimator", "check_detector",
           "check_pattern_kind", "check_scene_kind"]

#: candidate code lengths; the first one a family accepts is used
CODE_LENGTHS = (127, 255, 511, 1023, 128)


def _fail(what: str, why: str) -> AssertionError:
    return AssertionError(f"{what}: {why}")


def _config(option: str, name: str, **more) -> Config:
    """The config choosing ``name`` in registry ``option``, the entry's hook passed."""
    from ..config import registries

    cfg = Config.from_dict({option: name, **more})
    registries()[option].get(name).check(cfg)
    return cfg


def _code_config(name: str) -> Config:
    for length in CODE_LENGTHS:
        try:
            return _config("code", name, code_length=length)
        except ConfigError:
            continue
    raise _fail(f"code family {name!r}", f"accepts none of the lengths {CODE_LENGTHS}")


def check_code_family(name: str) -> list[str]:
    """The contract of a code family (see the module docstring).

    Parameters
    ----------
    name : str
        A name in :data:`spslidar.codes.CODES`.

    Returns
    -------
    list of str
        The contracts checked.
    """
    from ..codes import CODES

    cfg = _code_config(name)
    entry = CODES.get(name)
    index = entry.defaults.get("index", 0)
    options = chosen_stage_options(cfg, "code")
    length = cfg.code_length

    def make():
        return np.asarray(entry.load()(name, length, 0.5, rng=np.random.default_rng(1),
                                       index=index, **options))

    what = f"code family {name!r} at {length} bits"
    code, again = make(), make()
    if code.shape != (length,):
        raise _fail(what, f"shape {code.shape}, not ({length},)")
    if not set(np.unique(code).tolist()) <= {0, 1}:
        raise _fail(what, "bits other than 0 and 1")
    if not np.array_equal(code, again):
        raise _fail(what, "not reproducible from the same generator")
    ones = int(code.sum())
    # the m-sequence and Gold families have (L + 1) / 2 ones; a Bernoulli code's share is
    # within 5 binomial standard deviations of one half
    if abs(ones - length / 2) > max(1.0, 5 * np.sqrt(length / 4)):
        raise _fail(what, f"{ones} ones, not about half (the bipolar replica needs balance)")
    b = 2.0 * code - 1.0
    corr = np.fft.ifft(np.fft.fft(b) * np.conj(np.fft.fft(b))).real
    if np.max(np.abs(corr[1:])) > corr[0] / 2:
        raise _fail(what, f"a periodic sidelobe of {np.max(np.abs(corr[1:])):.0f} against a "
                          f"peak of {corr[0]:.0f}: more than half of it")
    return ["length", "bits", "reproducible", "balanced", "single correlation peak"]


def check_pattern_kind(name: str, dtypes=(np.float32, np.float64)) -> list[str]:
    """The contract of a pattern kind (see the module docstring), on 8 x 8 pixels and 32
    patterns, in each of ``dtypes``.

    Returns
    -------
    list of str
        The contracts checked.
    """
    from ..operators import dottest
    from ..patterns import build_patterns

    cfg = _config("patterns", name, size=8, compression=0.5)
    options = chosen_stage_options(cfg, "patterns")
    m, n = 32, cfg.size
    for dtype in dtypes:
        what = f"pattern kind {name!r} ({np.dtype(dtype).name})"

        def build(dtype=dtype):
            return build_patterns(name, m, n, np.random.default_rng(3), dtype=dtype,
                                  sigma=cfg.pattern_sigma, order=cfg.hadamard_order,
                                  realisation=cfg.hadamard_realisation, **options)

        op, same = build(), build()
        if tuple(op.shape) != (m, n * n):
            raise _fail(what, f"shape {tuple(op.shape)}, not {(m, n * n)}")
        try:  # the adjoint: dottest's tolerances are the dtype's (1e-4 / 1e-10)
            dottest(op, n_cols=1, rng=0)
            dottest(op, n_cols=3, rng=1)
        except AssertionError as err:
            raise _fail(what, f"adjoint test: {err}") from None
        x = np.random.default_rng(4).standard_normal((n * n, 2)).astype(dtype)
        x0 = x.copy()
        y = np.asarray(op.matvec(x))
        if not np.array_equal(x, x0):
            raise _fail(what, "matvec changed its input")
        if y.dtype != np.dtype(dtype):
            raise _fail(what, f"matvec gave {y.dtype}")
        if not np.array_equal(y, np.asarray(same.matvec(x))):
            raise _fail(what, "not the same patterns from the same seed")
        shown = np.asarray(op.apply_rows(slice(0, m), np.eye(n * n, dtype=dtype)))
        # mirror states in [0, 1] (grey levels allowed), row by row equal to the operator's
        # products (float32 round-off: 1e-5 of the row sums)
        if shown.min() < -1e-6 or shown.max() > 1 + 1e-6:
            raise _fail(what, f"mirror states in [{shown.min():g}, {shown.max():g}], not "
                              f"[0, 1]")
        err = np.abs(shown @ x[:, 0].astype(np.float64) - y[:, 0])
        if np.any(err > 1e-5 * (np.abs(y[:, 0]) + n * n)):
            raise _fail(what, f"apply_rows and matvec differ by {err.max():.3g}")
    return ["shape", "adjoint", "no side effect", "dtype", "same seed, same patterns",
            "mirror states in [0, 1]"]


def _detector(name: str):
    from ..detectors import build_detector
    from ..pipeline.chain import detector_options

    return build_detector(name, **detector_options(_config("detector", name)))


def check_detector(name: str) -> list[str]:
    """The contract of a detector model (see the module docstring).

    Returns
    -------
    list of str
        The contracts checked.
    """
    what = f"detector {name!r}"
    det = _detector(name)
    rng = np.random.default_rng(7)
    period, n_periods, reps = 64, 50, 400
    lam = np.full((1, period), 0.002 * n_periods)
    lam[0, 10] = 0.05 * n_periods  # a return over a low background
    mean, sq = np.zeros(period), np.zeros(period)
    for _ in range(reps):
        counts, totals = det.detect(lam.copy(), rng, n_periods)
        c = np.asarray(counts, np.float64)[0]
        if not np.isclose(float(np.asarray(totals)[0]), c.sum(), rtol=1e-6):
            raise _fail(what, f"detect's total {np.asarray(totals)[0]} is not its counts' sum "
                              f"{c.sum()}")
        mean += c
        sq += c * c
    mean /= reps
    se = np.sqrt(np.maximum(sq / reps - mean**2, 1e-12) / reps)
    expected = np.asarray(det.expected(lam, n_periods), np.float64)[0]
    # the total over the bins too, where a loss spread thin over every bin shows (its
    # variance the sum of the bins': exact for Poisson counts, an upper bound where a dead
    # time anti-correlates the bins)
    total_se = np.sqrt(max(float(np.sum(sq / reps - mean**2)), 1e-12) / reps)
    if abs(mean.sum() - expected.sum()) > 5 * total_se + 1e-9:
        raise _fail(what, f"mean of {reps} detections' totals {mean.sum():.5g}, expected "
                          f"{expected.sum():.5g} (5 standard errors: {5 * total_se:.2g})")
    off = np.abs(mean - expected) - 5 * se
    if np.any(off > 1e-9):
        b = int(np.argmax(off))
        raise _fail(what, f"mean of {reps} detections {mean[b]:.5g} in bin {b}, expected "
                          f"{expected[b]:.5g} (5 standard errors: {5 * se[b]:.2g})")
    # at 0.1 % of the flux per dead time pile-up is a per-mille effect: correct removes it
    n_periods = 100
    lam = np.full((2, 128), 1e-4 * n_periods)
    lam[:, 20] = 5e-3 * n_periods
    back = np.asarray(det.correct(np.asarray(det.expected(lam, n_periods)), n_periods))
    if back.shape != lam.shape or not np.allclose(back, lam, rtol=1e-4, atol=0):
        raise _fail(what, "correct(expected(lam)) is not lam at low flux (rtol 1e-4)")
    return ["detect's totals", "mean of detect is expected", "correct inverts expected"]


def depth_problem(n: int = 12, bins: int = 40):
    """Noiseless slices of a step, a slanted plane and a one-pixel pole: one unit return
    per pixel at its true lag, zero elsewhere.

    Returns
    -------
    slices : ndarray, shape (n * n, bins)
    ctx : DepthContext
    depth : ndarray, shape (n, n)
        The true depths (eq. 2-3: a half-bin pulse inside bin ``t`` is read at its middle,
        ``t + 1/2 - pulse_width / 2``).
    """
    from ..depth import DepthContext

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
    depth = (lag0 + true + 0.5 - ctx.pulse_width / 2) * d_bin
    return slices, ctx, depth


def check_depth_estimator(name: str) -> list[str]:
    """The contract of a depth estimator (see the module docstring).

    Returns
    -------
    list of str
        The contracts checked.
    """
    from ..depth import ESTIMATORS

    what = f"depth estimator {name!r}"
    options = chosen_stage_options(_config("depth", name), "depth")
    slices, ctx, depth = depth_problem()
    keep = slices.copy()
    est = ESTIMATORS.load(name)(**options).estimate(slices, ctx)
    if not np.array_equal(slices, keep):
        raise _fail(what, "estimate changed the slices it was given")
    got = np.asarray(est.depth, np.float64).reshape(depth.shape)
    # exact to a hundredth of a bin (a centroid of a one-bin return is the bin itself)
    tol = 0.01 * SPEED_OF_LIGHT * ctx.bin_width / 2
    err = np.abs(got - depth)
    if not np.all(err <= tol):
        bad = np.argwhere(~(err <= tol))
        r, c = (int(v) for v in bad[0])
        raise _fail(what, f"noiseless recovery: {len(bad)} of {depth.size} pixels wrong, "
                          f"e.g. ({r}, {c}) at {got[r, c]:.4f} m, true {depth[r, c]:.4f} m")
    conf = np.asarray(est.confidence)
    if conf.shape != (depth.size,) or not np.all((conf >= 0) & (conf <= 1)):
        raise _fail(what, "confidence not one value in [0, 1] per pixel")
    if np.asarray(est.low_confidence).dtype != bool:
        raise _fail(what, "low_confidence is not boolean")
    est = ESTIMATORS.load(name)(**options).estimate(np.zeros_like(slices), ctx)
    if not np.all(np.isnan(est.depth)) or not np.all(np.asarray(est.confidence) == 0):
        raise _fail(what, "a depth or a confidence where no pixel has a return")
    return ["no side effect", "noiseless recovery (step, slanted plane, one-pixel pole)",
            "confidence in [0, 1]", "no depth without returns"]


def scene_spec(name: str) -> str:
    """A loadable spec of scene kind ``name`` (``kind:EXAMPLE`` where it takes an argument)."""
    from ..scenes import SCENES

    entry = SCENES.get(name)
    if entry.defaults.get("argument"):
        return f"{name}:{entry.defaults.get('example', '0')}"
    return name


def check_scene_kind(name: str) -> list[str]:
    """The contract of a scene kind (see the module docstring), at 16 x 16 pixels.

    Returns
    -------
    list of str
        The contracts checked.
    """
    from ..scenes import load_scene

    spec = scene_spec(name)
    what = f"scene {spec!r}"
    a, b = load_scene(spec, 16), load_scene(spec, 16)
    if not a.depth.shape == a.reflectivity.shape == a.valid.shape == (16, 16):
        raise _fail(what, "depth, reflectivity and valid are not all 16 x 16")
    if not (a.valid.any() and np.all(np.isfinite(a.depth)) and a.depth.min() >= 0):
        raise _fail(what, "no valid pixel, or a negative or non-finite depth")
    if not (0 <= a.reflectivity.min() and a.reflectivity.max() <= 1):
        raise _fail(what, "reflectivity outside [0, 1]")
    if not np.array_equal(a.depth, b.depth):
        raise _fail(what, "not the same scene twice")
    w = load_scene(spec, 16, 7.0, 8.0)
    d = w.depth[w.valid]
    # the window is filled to round-off (a linear remap in float64)
    if abs(d.min() - 7.0) > 1e-9 or abs(d.max() - 8.0) > 1e-9:
        raise _fail(what, f"rescaled into [7, 8] m it spans [{d.min():.9g}, {d.max():.9g}]")
    return ["shape", "valid values", "deterministic", "rescaled into a window"]
