"""The contracts of the chain's stages other than solvers: code families, pattern kinds,
detector models, depth estimators and scene kinds (:mod:`spslidar.testing`).

Each ``check_*`` function takes a registered name, builds the stage as the pipeline builds it
(the options it declares at their defaults) and raises :class:`AssertionError` naming the
contract that failed; it returns the list of the contracts it checked.

* code family: the length asked for, 0/1 bits, reproducible from the generator, about as many
  ones as zeros (what the bipolar replica of eq. 5-6 needs), a periodic correlation with a
  single peak, ``index + 1`` refused (``ConfigError``) or another code, and the same code in
  a fresh process (:mod:`.process`: not drawn from ``hash()`` or the time);
* pattern kind: the adjoint (dot) test for one and several columns, the dtype asked for (of
  both products), mirror states in [0, 1] as the DMD shows them, no side effect on the input,
  the same patterns from the same seed, and what QCR reads: the mean pattern, the centred
  operator and the cast, against the dense patterns;
* detector model: counts finite and non-negative in every bin, the mean of ``detect`` is
  ``expected`` (Monte Carlo, 5 standard errors, bin by bin and in total), ``correct`` undoes
  the model's non-linearity at low flux (the identity for a linear model);
* depth estimator: noiseless recovery of a step, a slanted plane and a one-pixel pole,
  confidence in [0, 1], no depth where no pixel has a return (all of them, or a few among
  pixels that have one), and with ``subbin`` a two-bin return read monotonically within half
  a bin;
* scene kind: loads at the probe's size as a valid scene, the same twice, rescaled into a
  window given, both ends, in two windows of other spans (a flat scene at its own depth or the
  nearer end), and the same scene in a fresh process.

A stage that needs other probe settings declares them where it is registered:
``check={"code_length": 131}`` for a code family, ``check={"size": 16}`` for a pattern kind
(``"compression"`` too) or a scene kind; a scene kind with an argument is loaded with its
``example=`` (default ``0``).
"""

from __future__ import annotations

import numpy as np

from ..config import chosen_stage_options
from ..constants import SPEED_OF_LIGHT
from ..errors import ConfigError
from . import config_for
from .probes import _fail, _probe, probe_code, scene_size, scene_spec

__all__ = ["check_code_family", "check_depth_estimator", "check_detector",
           "check_pattern_kind", "check_scene_kind"]


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
    make, index, length = probe_code(name)
    code, again = make(index), make(index)
    what = f"code family {name!r} at {length} bits"
    if code.shape != (length,):  # (against the length asked for: code.size passed any)
        raise _fail(what, f"shape {code.shape}: {code.size} bits, not the {length} asked for")
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
    try:  # another member: refused (a family of one code per length) or another code
        other = make(index + 1)
    except (ConfigError, ValueError):
        other = None
    if other is not None and np.array_equal(other, code):
        raise _fail(what, f"index {index + 1} gives the same code as index {index}: refuse "
                          f"an index the family does not have (ConfigError), or honour it")
    return ["length", "bits", "reproducible", "balanced", "single correlation peak",
            "index selects", *_same_in_a_fresh_process("code", name, what, (code,))]


def _same_in_a_fresh_process(kind: str, name: str, what: str, arrays) -> list[str]:
    """The contract of :mod:`.process` (said skipped where the stage cannot be built
    afresh), on the probe output ``arrays`` this process built."""
    from . import SKIPPED, registry_of
    from .process import digest, fresh_digest

    there = fresh_digest(kind, name)
    if there is None:
        origin = registry_of(kind).get(name).origin or "this process"
        return [f"{SKIPPED}the same in a fresh process (registered by {origin}, which a new "
                f"interpreter does not import: load it with --plugin or SPSLIDAR_PLUGINS)"]
    if set(there) != {digest(arrays)}:
        raise _fail(what, "another output in a fresh process (another PYTHONHASHSEED): a "
                          "sweep's workers would each get their own; draw from the rng given "
                          "or from the arguments, not from hash(), the time or a global state")
    return ["the same in a fresh process"]


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

    cfg = config_for("patterns", name, **{"size": 8, "compression": 0.5,
                                       **_probe("patterns", name)})
    options = chosen_stage_options(cfg, "patterns")
    n = cfg.size
    m = max(2, int(round(cfg.compression * n * n)))
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
        back = np.asarray(op.rmatvec(np.ones((m, 1), dtype=dtype)))
        if back.dtype != np.dtype(dtype):
            raise _fail(what, f"rmatvec gave {back.dtype}")
        # what QCR reads (eq. 11): the mean pattern, the centred operator and the cast, each
        # against the dense patterns (round-off of the dtype, relative to the row sums)
        tol = (1e-5 if np.dtype(dtype) == np.float32 else 1e-10) * n * n
        mean = np.asarray(op.mean_pattern(), np.float64)
        if mean.shape != (n * n,) or np.abs(mean - shown.mean(axis=0)).max() > tol / m:
            raise _fail(what, "mean_pattern() is not the patterns' mean over M (eq. 11)")
        centred = np.asarray(op.centred(2.0, dtype=np.float64).matvec(
            x.astype(np.float64)), np.float64)
        want = (shown - shown.mean(axis=0)) @ x.astype(np.float64) / 2.0
        if np.abs(centred - want).max() > tol:
            raise _fail(what, "centred(norm) is not (Phi - mean pattern) / norm")
        cast = op.as_dtype(np.float64)
        if np.abs(np.asarray(cast.matvec(x.astype(np.float64))) - shown @ x).max() > tol:
            raise _fail(what, "as_dtype(float64) is not the same patterns")
    return ["shape", "adjoint", "no side effect", "dtype", "same seed, same patterns",
            "mirror states in [0, 1]", "mean pattern, centred and cast (QCR)"]


def _detector(name: str):
    from ..detectors import build_detector
    from ..pipeline.chain import detector_options

    return build_detector(name, **detector_options(config_for("detector", name)))


def check_detector(name: str) -> list[str]:
    """The contract of a detector model (see the module docstring).

    ``detect``'s mean over 200 rows of 5 000 periods (one call, as the simulation draws a
    block of patterns) against ``expected``, bin by bin within 5 standard errors and in total
    within 5 standard errors (a fraction of a percent here: a model whose ``expected`` is 1-2 %
    off fails); and
    ``correct(expected(lam))`` linear in ``lam`` at low flux (the non-linearity, pile-up,
    removed; an efficiency and dark counts, which ``correct`` leaves, may remain), the
    identity for a model that says it is ``linear``.

    Returns
    -------
    list of str
        The contracts checked.
    """
    what = f"detector {name!r}"
    det = _detector(name)
    rng = np.random.default_rng(7)
    period, n_periods, reps = 64, 5000, 200
    lam = np.full((reps, period), 0.02 * n_periods)
    lam[:, 10] = 0.3 * n_periods  # a return over a background
    counts, totals = det.detect(lam.copy(), rng, n_periods)
    for got, label in ((counts, "counts"), (totals, "totals")):
        if np.asarray(got).dtype.kind not in "biuf":  # (complex counts passed, their
            # imaginary part cast away with a warning, an outside audit of plugins)
            raise _fail(what, f"detect gave {label} of dtype {np.asarray(got).dtype}: counts "
                              f"are real numbers")
    c = np.asarray(counts, np.float64)
    totals = np.asarray(totals, np.float64)
    if c.shape != lam.shape or totals.shape != (reps,):
        raise _fail(what, f"detect gave counts of shape {c.shape} and totals {totals.shape} "
                          f"for {lam.shape} rows")
    # finite and >= 0 in every bin, here and at low flux (no light, then 0.01 photons per
    # bin), where a count is mostly 0 (poisson(mean) - 1, its expected alike, passed the
    # other contracts, an audit of plugins)
    low = np.full((4, period), 0.01)
    low[0] = 0.0
    for flux, got in (("", c), (" at low flux", det.detect(low, rng, 10)[0])):
        got = np.asarray(got, np.float64)
        bad = ~np.isfinite(got) | (got < 0)
        if bad.any():
            r, b = (int(v) for v in np.argwhere(bad)[0])
            raise _fail(what, f"detect gave negative or non-finite counts{flux} "
                              f"({int(bad.sum())} of {got.size} bins, e.g. {got[r, b]:g} in "
                              f"bin {b} of row {r}): a count is a number of detections")
    if not np.allclose(totals, c.sum(axis=1), rtol=1e-6, atol=1e-6):
        raise _fail(what, "detect's totals are not its counts' row sums")
    mean = c.mean(axis=0)
    expected = np.asarray(det.expected(lam[:1], n_periods), np.float64)[0]
    se_total = c.sum(axis=1).std() / np.sqrt(reps)
    if abs(mean.sum() - expected.sum()) > 5 * se_total + 1e-9:
        raise _fail(what, f"mean of {reps} detections' totals {mean.sum():.5g}, expected "
                          f"{expected.sum():.5g} ({100 * (mean.sum() / expected.sum() - 1):+.2g}"
                          f" %; 5 standard errors: {5 * se_total:.2g})")
    se = np.sqrt(np.maximum(c.var(axis=0), 1e-12) / reps)
    off = np.abs(mean - expected) - 5 * se
    if np.any(off > 1e-9):
        b = int(np.argmax(off))
        raise _fail(what, f"mean of {reps} detections {mean[b]:.5g} in bin {b}, expected "
                          f"{expected[b]:.5g} (5 standard errors: {5 * se[b]:.2g})")
    n_periods = 100
    lam = np.full((2, 128), 1e-4 * n_periods)
    lam[:, 20] = 5e-3 * n_periods
    lam[1] *= 3
    out = np.asarray(det.expected(lam, n_periods), np.float64)
    back = np.asarray(det.correct(out.copy(), n_periods), np.float64)
    if back.shape != lam.shape:
        raise _fail(what, f"correct gave shape {back.shape} for {lam.shape}")
    if getattr(det, "linear", True):
        if not np.allclose(back, out, rtol=1e-12, atol=0):
            raise _fail(what, "a linear model's correct() changed its histogram")
    else:
        # at 0.1 % of the flux per dead time pile-up is a per-mille effect: what correct
        # leaves must be linear in lam (an efficiency a, dark counts b), to 1e-4
        design = np.stack([lam.ravel(), np.ones(lam.size)], axis=1)
        coef, *_ = np.linalg.lstsq(design, back.ravel(), rcond=None)
        fit = design @ coef
        if not (coef[0] > 0 and np.allclose(back.ravel(), fit, rtol=1e-4, atol=0)):
            raise _fail(what, "correct(expected(lam)) is not linear in lam at low flux (rtol "
                              "1e-4): it does not undo the model's pile-up")
    done = ["counts finite and non-negative", "detect's totals", "mean of detect is expected",
            "correct undoes the non-linearity"]
    if not getattr(det, "linear", True):
        # (the matched filter's noise level is built from them: a plugin's negative or
        # mis-shaped ones passed here and ended a run in a traceback, an outside audit)
        from ..errors import ConfigError
        from ..pipeline.simulate import checked_noise_totals

        fixed = np.asarray(det.correct(c.copy(), 5000), np.float64)
        try:
            checked_noise_totals(det, c, c.sum(axis=1), 5000, fixed)
        except ConfigError as exc:
            raise AssertionError(str(exc)) from None  # (it names the model)
        done.append("noise totals: one variance per row")
    return done


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
    options = chosen_stage_options(config_for("depth", name), "depth")
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
    empty = [5, 40, 77]  # pixels without a return among pixels with one
    holed = slices.copy()
    holed[empty] = 0.0
    est = ESTIMATORS.load(name)(**options).estimate(holed, ctx)
    got = np.asarray(est.depth, np.float64)
    if not np.all(np.isnan(got[empty])) or np.any(np.asarray(est.confidence)[empty] != 0):
        raise _fail(what, f"pixels {empty} hold no return, among pixels that do, and were "
                          f"given depths {got[empty]} (NaN and confidence 0 expected)")
    _check_subbin(name, options, ctx, what)
    return ["no side effect", "noiseless recovery (step, slanted plane, one-pixel pole)",
            "confidence in [0, 1]", "no depth without returns",
            "sub-bin returns (subbin on): monotone, within half a bin"]


def _check_subbin(name: str, options: dict, ctx, what: str) -> None:
    """With ``subbin``, a return shared between bins ``t`` and ``t + 1`` as ``(1 - f, f)``
    reads as a depth that grows with ``f`` and lies within half a bin of ``t + f`` (read
    at the pulse's middle, eq. 2-3); an estimator without sub-bin refinement reads ``t`` or
    ``t + 1``, which passes too."""
    from dataclasses import replace

    from ..depth import ESTIMATORS

    share = np.linspace(0.05, 0.95, 12)
    t = 20
    slices = np.zeros((share.size, ctx.lags.size))
    slices[:, t], slices[:, t + 1] = 1.0 - share, share
    fine = replace(ctx, shape=(1, share.size), subbin=True)
    est = ESTIMATORS.load(name)(**options).estimate(slices, fine)
    d_bin = SPEED_OF_LIGHT * ctx.bin_width / 2
    got = np.asarray(est.depth, np.float64) / d_bin - ctx.lags[0]
    want = t + share + 0.5 - ctx.pulse_width / 2
    if not np.all(np.isfinite(got)):
        raise _fail(what, "a two-bin return read as no return (subbin on)")
    if np.any(np.diff(got) < -1e-6):
        raise _fail(what, f"with subbin on, a return moving from bin {t} to {t + 1} reads "
                          f"depths that go back (in bins: {np.round(got, 3).tolist()})")
    if np.any(np.abs(got - want) > 0.5 + 1e-6):
        k = int(np.argmax(np.abs(got - want)))
        raise _fail(what, f"with subbin on, a return shared {1 - share[k]:.2f} / "
                          f"{share[k]:.2f} between bins {t} and {t + 1} reads at bin "
                          f"{got[k]:.3f}, more than half a bin from {want[k]:.3f}")


def check_scene_kind(name: str) -> list[str]:
    """The contract of a scene kind (see the module docstring), at 16 x 16 pixels (or the
    ``size`` its entry's ``check=`` declares), with the argument its entry's ``example=``
    gives (default ``0``). A flat scene keeps its depth where the window holds it and goes to
    the window's nearer end where not, as ``load_scene`` does with a file.

    Returns
    -------
    list of str
        The contracts checked.
    """
    from ..scenes import load_scene

    spec = scene_spec(name)
    size = scene_size(name)
    what = f"scene {spec!r}"
    a, b = load_scene(spec, size), load_scene(spec, size)
    if not a.depth.shape == a.reflectivity.shape == a.valid.shape == (size, size):
        raise _fail(what, f"depth, reflectivity and valid are not all {size} x {size}")
    if not (a.valid.any() and np.all(np.isfinite(a.depth)) and a.depth.min() >= 0):
        raise _fail(what, "no valid pixel, or a negative or non-finite depth")
    if not (0 <= a.reflectivity.min() and a.reflectivity.max() <= 1):
        raise _fail(what, "reflectivity outside [0, 1]")
    if not (np.array_equal(a.depth, b.depth) and np.array_equal(a.reflectivity, b.reflectivity)
            and np.array_equal(a.valid, b.valid)):
        raise _fail(what, "not the same scene twice (depth, reflectivity and valid)")
    flat = float(np.ptp(a.depth[a.valid])) == 0.0
    own = float(a.depth[a.valid][0])
    # the window is filled to round-off (a linear remap in float64); a flat scene keeps its
    # depth or goes to the nearer end; two windows of other spans (one alone passed a scene
    # that read only its near bound and kept its own 1 m span, a known limit of stop 51)
    for near, far in ((7.0, 8.0), (3.0, 5.5)):
        w = load_scene(spec, size, near, far)
        d = w.depth[w.valid]
        lo, hi = (near, far) if not flat else (min(max(own, near), far),) * 2
        if abs(d.min() - lo) > 1e-9 or abs(d.max() - hi) > 1e-9:
            raise _fail(what, f"rescaled into [{near:g}, {far:g}] m it spans "
                              f"[{d.min():.9g}, {d.max():.9g}]")
    return ["shape", "valid values", "deterministic", "rescaled into a window",
            *_same_in_a_fresh_process("scene", name, what,
                                      (a.depth, a.reflectivity, a.valid))]
