"""Monte-Carlo measurement of the output SNR of equation (10), with its standard error.

:func:`snr_simulated` counts Poisson photons of one binary pattern over ``trials`` code periods
(one summed draw per period, or full TDC histograms from the library's forward model and
matched filter) and correlates them with the **unipolar** replica, the definition eq. (10)
uses; the interval comes from the delta method or a bootstrap. Where the trials cannot
resolve the SNR (``trials x SNR < 4``, or no variance in their counts) the ratio simulated /
theory is NaN and a RuntimeWarning says what to change.
"""

from __future__ import annotations

import math
import warnings
from typing import TYPE_CHECKING, Any

from spslidar.snr.theory import (
    MAX_TRIALS,
    SNR_INTERVALS,
    SNR_METHODS,
    as_integer,
    as_nonneg,
    as_number,
    check_choice,
    check_size,
    check_trials,
    chosen_code_options,
    code_family,
    config_error,
    default_code_index,
    eq10,
    make_code_checked,
    mirrors_on,
    realised_far,
)

if TYPE_CHECKING:  # pragma: no cover
    import numpy as np

__all__ = ["snr_simulated"]

# Largest total mean count per period the 'sum' path draws (NumPy's Poisson sampler refuses
# means near 2^63; far below that, float64 still resolves the variance of the counts).
_MAX_TOTAL_MEAN = 1e17
#: above this mean the 'sum' path draws the Gaussian limit of the Poisson law, rounded:
#: NumPy's Poisson sampler gets the variance wrong there (var / mean 1.016 at 3e13, 1.096 at
#: 3e14, 1.37 at 1e16 over 20 000 draws: the simulated SNR read 0.60 of eq. (10) at 1e17,
#: 44 sigmas off; an audit of 2026-11-30), where the Gaussian's relative error in any
#: moment is below 1e-6
POISSON_EXACT_MEAN = 1e12
# Bins drawn at once by the 'histogram' path (trials are processed in chunks of this size).
_HIST_CHUNK_BINS = 4_000_000
#: seconds per simulated TDC bin of the 'histogram' path (Poisson draw and matched filter of
#: each bin): 4.9e-8 measured on the 2-core machine (2000 periods of 16383 bins in 1.6 s),
#: rounded up
SECONDS_PER_HIST_BIN = 6e-8
#: seconds per trial of the 'sum' path (one Poisson draw)
SECONDS_PER_SUM_TRIAL = 1e-7
#: seconds per trial drawn into a bootstrap resample (10^6 trials x 2000 resamples took 16 s
#: on a 2-core machine, 2026-11-28)
SECONDS_PER_BOOT_DRAW = 1e-8
#: fewest trials a bootstrap interval is drawn from: from 2 trials every resample with a
#: variance gave the same SNR, and the interval came out as +- 0
MIN_BOOT_TRIALS = 10
#: least ``trials x SNR`` (eq. 10) a simulation resolves. The simulated mean count exceeds the
#: noise mean by ``sqrt(trials x SNR)`` of its standard errors in expectation, so below 4 the
#: signal is under two standard errors of the mean, the estimate's relative spread
#: ``2 / sqrt(trials x SNR)`` passes 100 % and its floor (about ``1 / trials``, what noise alone
#: gives) more than a quarter of the SNR: simulated / theory then measures the floor, not eq. (10)
#: (``--signal 1e-12`` gave 2.3e16). With no noise it is the signal photons expected over all
#: the trials.
MIN_TRIALS_X_SNR = 4.0
#: longest code a simulation takes (``run``'s ``--code-length`` limit, 2^24 bits: a random
#: code of 10^9 bits asked for 7.45 GiB before anything was checked)
MAX_SIM_CODE_LENGTH = 2**24


def estimate_seconds(period: int, trials: int, method: str, n_boot: int = 0) -> float:
    """The time a simulation of ``trials`` periods of ``period`` bins takes, with ``n_boot``
    bootstrap resamples of the trials, estimated from its parameters as
    :mod:`spslidar.pipeline.budget` estimates a run's."""
    boot = float(n_boot) * trials * SECONDS_PER_BOOT_DRAW
    if method == "histogram":
        return float(trials) * period * SECONDS_PER_HIST_BIN + boot
    return float(trials) * SECONDS_PER_SUM_TRIAL + boot


def _counts_sum(ones: int, per_bit: float, trials: int, rng) -> np.ndarray:
    """``C`` for each trial as one Poisson draw with the summed mean of the 'on' bins."""
    total = ones * per_bit
    if total > _MAX_TOTAL_MEAN:
        raise config_error(
            f"mean counts per period {total:.3g} are too large to simulate (limit "
            f"{_MAX_TOTAL_MEAN:.0e}): lower the photon numbers, size or code length"
        )
    if total > POISSON_EXACT_MEAN:
        return rng.normal(total, math.sqrt(total), size=trials).round()
    return rng.poisson(total, size=trials).astype("float64")


def _counts_histogram(
    code, m2: int, n: int, a: float, m_s: float, m_n: float, delay: int, trials: int, rng
) -> np.ndarray:
    """``C`` for each trial from full Poisson histograms and the library's matched filter."""
    import numpy as np

    from ..correlate import make_replica, matched_filter, replica_matrix
    from ..detectors.counting import NoiseModel, poisson_counts
    from ..forward import expected_counts, return_amplitudes

    period = code.size
    q = n * n
    from ..machine import available_memory

    # the pixel arrays (pattern, reflectivity, delays, the (Q, 2) shifts and amplitudes and
    # their temporaries: 160 bytes per pixel at the peak, measured from N = 1024 to 2048) and
    # one chunk of histograms with its correlation (~3 float64 per bin)
    need = 160.0 * q + 3 * 8.0 * _HIST_CHUNK_BINS + 150e6
    if need > available_memory():
        raise config_error(
            f"--method histogram at --size {n} needs ~{need / 1e9:.0f} GB of memory, more than "
            f"the {available_memory() / 1e9:.1f} GB available: use --method sum (the same "
            f"statistic without per-pixel arrays) or a smaller --size")
    pattern = np.zeros((1, q))
    pattern[0, rng.choice(q, size=m2, replace=False)] = 1.0
    alpha = np.full(q, a)
    # every pixel returns after exactly `delay` bins; a full-bin pulse lands in one TDC bin
    shifts, amp = return_amplitudes(pattern, alpha, np.full(q, float(delay)), 1.0, period)
    noise_bin = NoiseModel(m_n=m_n).per_bin(pattern, alpha, bin_width=1e-10)
    lam = expected_counts(amp, shifts, code, m_s, noise_bin)  # (1, T): eq. (4) in expectation
    replica = make_replica(code, "unipolar")
    lags = np.array([delay])
    bank = replica_matrix(replica, lags, np.float64)  # float64: exact sums of counts
    chunk = max(1, _HIST_CHUNK_BINS // period)
    out = np.empty(trials)
    for start in range(0, trials, chunk):
        rows = min(chunk, trials - start)
        try:
            hist = poisson_counts(np.broadcast_to(lam, (rows, period)), rng)
        except ValueError as exc:
            # (one code period a row: snr has no --periods to lower, an audit)
            raise config_error(f"cannot simulate the histogram: "
                               f"{str(exc).replace(', --noise or --periods', ' or --noise')}"
                               ) from None
        c = matched_filter(hist, replica, lags, out_dtype=np.float64, bank=bank)
        out[start : start + rows] = c[:, 0]
    return out


def _t95(k: int) -> float:
    """Student's two-sided 95 % quantile for ``k`` trials (``k - 1`` degrees of freedom): the
    delta method's interval with the standard error estimated from the trials themselves."""
    from scipy import stats

    return float(stats.t.ppf(0.975, max(1, k - 1)))


def _delta_stderr(c: np.ndarray, noise_mean: float) -> tuple[float, float]:
    """SNR estimate and its delta-method standard error from the trials ``c``."""
    import numpy as np

    k = c.size
    m = float(c.mean())
    dev = c - m
    v = float(dev @ dev) / (k - 1)
    if v <= 0.0:
        return math.inf if m != noise_mean else math.nan, math.nan
    d = m - noise_mean
    g = d * d / v
    m3 = float(np.mean(dev**3))
    m4 = float(np.mean(dev**4))
    var_m = v / k
    var_v = max(m4 - v * v * (k - 3) / (k - 1), 0.0) / k
    cov_mv = m3 / k
    gm = 2.0 * d / v
    gv = -d * d / (v * v)
    var_g = gm * gm * var_m + gv * gv * var_v + 2.0 * gm * gv * cov_mv
    return g, math.sqrt(max(var_g, 0.0))


def _bootstrap(c: np.ndarray, noise_mean: float, n_boot: int, rng) -> tuple[float, float, float]:
    """Bootstrap standard error and 95 % percentile interval of the SNR estimate."""
    import numpy as np

    k = c.size
    reps = np.empty(n_boot)
    block = max(1, 2_000_000 // k)
    for start in range(0, n_boot, block):
        rows = min(block, n_boot - start)
        s = c[rng.integers(0, k, size=(rows, k))]
        mean = s.mean(axis=1)
        var = s.var(axis=1, ddof=1)
        with np.errstate(divide="ignore", invalid="ignore"):
            reps[start : start + rows] = (mean - noise_mean) ** 2 / var
    finite = reps[np.isfinite(reps)]
    if finite.size < max(2, n_boot // 2):  # most resamples without a variance: no interval
        return math.nan, math.nan, math.nan
    lo, hi = np.percentile(finite, [2.5, 97.5])
    return float(finite.std(ddof=1)), float(lo), float(hi)


def _positive(value: Any, flag: str, hi: float) -> float:
    """``value`` in ``(0, hi]`` (``(0, inf)`` for an infinite ``hi``), or ConfigError worded as
    ``run`` words its ranges (``--signal must be in (0, inf), got 0.0``): at 0 there is no
    signal, eq. (10) is 0 and the simulation has nothing to be compared with."""
    x = as_number(value, flag)
    if not 0.0 < x <= hi:
        span = "(0, inf)" if math.isinf(hi) else f"(0, {hi:g}]"
        why = (": with no signal photons eq. (10) is 0 and there is no SNR to simulate"
               if x == 0.0 else "")
        raise config_error(f"{flag} must be in {span}, got {x}{why}")
    return x


#: the fewest periods whose counts' variance the SNR is read from (2 and 3 gave ratios of 0.23
#: and 6.9 where eq. (10) holds to 1 %; the t quantile of 10 is 2.26)
MIN_TRIALS = 10


def _unresolved(c: np.ndarray, theory: float, noise: float, interval: tuple[float, ...]
                ) -> str | None:
    """Why the trials ``c`` cannot estimate the SNR that eq. (10) puts at ``theory``, as one
    sentence saying what to change; None when they can.

    Three reasons: ``trials x theory`` below ``MIN_TRIALS_X_SNR`` (the signal is within
    the estimate's noise floor), no sample variance (every trial counted the same; the
    estimate is 0/0 or infinite) and no finite standard error or interval (``interval``:
    ``simulated, stderr, ci_low, ci_high``).
    """
    k = int(c.size)
    rho = k * theory
    reasons = []
    advice = ""
    if not rho >= MIN_TRIALS_X_SNR:
        what = " signal photons expected over all of them" if noise == 0 else ""
        reasons.append(f"eq. (10) gives {theory:.3g}, below the {MIN_TRIALS_X_SNR / k:.3g} "
                       f"that {k} periods resolve (trials x SNR = {rho:.3g}{what}, under "
                       f"{MIN_TRIALS_X_SNR:g})")
        lower = ", or lower --noise" if noise > 0 else ""
        need = MIN_TRIALS_X_SNR / theory if theory > 0 else math.inf
        if need <= MAX_TRIALS:
            need_k = math.ceil(need)
            if need_k * theory < MIN_TRIALS_X_SNR:  # (rounding)
                need_k += 1
            advice = f"use --trials {need_k} or more, or raise --signal or --code-length{lower}"
        else:
            advice = (f"no --trials up to {MAX_TRIALS:.0e} resolves it: raise --signal, "
                      f"--reflectivity or --code-length{lower}")
    if float(c.min()) == float(c.max()):
        reasons.append(f"all {k} periods counted {float(c[0]):.6g} photons, so their variance "
                       f"is 0 and the SNR estimate is {'0/0' if c[0] == 0 else 'infinite'}")
        advice = advice or "use more --trials"
    elif not all(math.isfinite(x) for x in interval):
        # (a bootstrap whose resamples mostly have no variance; with a variance in the counts
        # at most 1/e of them miss every differing count, so this is a safeguard)
        reasons.append("the estimate has no finite standard error or interval")
        advice = advice or "use more --trials or --interval delta"
    elif k < MIN_TRIALS:
        # (3 trials printed simulated/theory = 6.87 from an interval of 0 to 1.4e6, 2 trials
        # 0.226, neither flagged: an outside audit of 2026-12-03)
        reasons.append(f"a variance from {k} periods is no estimate (its 95 % interval "
                       f"{interval[2]:.3g} to {interval[3]:.3g})")
        advice = advice or f"use --trials {MIN_TRIALS} or more"
    if not reasons:
        return None
    return (f"the simulation cannot resolve this SNR, so simulated/theory is left out: "
            f"{'; and '.join(reasons)}: {advice}")


def snr_simulated(
    code: str,
    code_length: int,
    ones_ratio: float,
    signal: float,
    noise: float,
    size: int,
    on_fraction: float,
    reflectivity: float = 1.0,
    trials: int = 200,
    rng: np.random.Generator | int | None = None,
    *,
    method: str = "sum",
    interval: str = "delta",
    code_index: int | None = None,
    delay: int | None = None,
    n_boot: int = 2000,
    max_time: float | None = 3600.0,
    code_options: dict[str, Any] | None = None,
) -> dict[str, Any]:
    """Measure the output SNR of eq. (10) by Monte Carlo, with its standard error.

    ``trials`` independent code periods of one binary pattern with ``M_2`` mirrors on, all
    returning at the same integer delay ``k``, are counted and correlated with the unipolar
    replica at lag ``k``.

    Parameters
    ----------
    code : {'mseq', 'gold', 'random'}
        Code kind (aliases as in :func:`spslidar.codes.make_code`).
    code_length : int
        Code length ``T`` in bits.
    ones_ratio : float
        Share of '1' bits of a random code, in (0, 1) (checked but unused for mseq/gold).
    signal : float
        ``m_s``: mean signal photons per laser pulse per DMD pixel (mirror on, reflectivity 1),
        positive (at 0 eq. (10) is 0 and there is nothing to compare; as ``run``, which
        refuses ``--signal 0``).
    noise : float
        ``m_n``: mean noise counts per TDC bin per pixel.
    size : int
        Pixels per side ``N``.
    on_fraction : float
        Share ``F`` of mirrors on, in (0, 1]; ``M_2 = round(F N^2)``.
    reflectivity : float, optional
        Reflectivity ``a`` of every pixel, in (0, 1] (default 1; 0 is no signal, as
        ``signal=0``).
    trials : int, optional
        Independent code periods simulated (>= 2; default 200). The relative standard error of
        the SNR estimate is about ``sqrt(2 / trials)``.
    rng : numpy.random.Generator or int or None, optional
        Random generator or seed (``np.random.default_rng(rng)``); it draws the random code,
        the pattern, the counts and the bootstrap resamples.
    method : {'sum', 'histogram'}, optional
        ``'sum'`` (default): one Poisson draw per trial for ``C``, whose mean is the sum of the
        means of the bins the replica selects. ``'histogram'``: the full histogram of ``T``
        bins per trial from the library's forward model (:func:`spslidar.forward.
        expected_counts` with an actual ``N x N`` binary pattern), Poisson counts
        (:func:`spslidar.detectors.counting.poisson_counts`) and matched filter
        (:func:`spslidar.correlate.matched_filter`, unipolar replica).
    interval : {'delta', 'bootstrap'}, optional
        Standard error and 95 % interval from the delta method (default; interval
        ``estimate +- t se``, clipped at 0, with ``t`` Student's 97.5 % quantile at ``K - 1``
        degrees of freedom: 1.97 at 200 trials, 12.7 at 2, where 1.96 gave an interval of
        0 .. 9.7e6 around a theory of 1.7e7) or a percentile bootstrap of the trials.
    code_index : int or None, optional
        Member of the Gold family / cyclic shift of the m-sequence (default None: ``run``'s
        default, member 2 for Gold codes, the first true Gold code, as members 0 and 1 are
        the preferred pair's m-sequences; shift 0 for m-sequences).
    delay : int, optional
        Round-trip delay ``k`` in bins (default ``T // 3``); the result does not depend on it.
    n_boot : int, optional
        Bootstrap resamples (default 2000; ``interval='bootstrap'`` only).
    max_time : float or None, optional
        Refuse (SpslidarError) a simulation estimated (:func:`estimate_seconds`) to take longer
        than this many seconds, before any draw; one over 30 s says its estimate on stderr
        first (default 3600; None: no limit).
    code_options : dict, optional
        The options the code family declares (a plugin family's, as ``run``'s flags give
        them), each checked by its declaration; the family's defaults where not given.

    Returns
    -------
    dict
        ``theory`` (eq. 10 with the generated code's number of ones), ``simulated``,
        ``stderr``, ``ci_low``, ``ci_high`` (95 %), ``ratio`` (simulated / theory; NaN, with
        a RuntimeWarning, where the trials cannot resolve the SNR: see Notes); the counts'
        ``mean_counts`` and ``var_counts`` over the trials and their theoretical
        ``signal_mean`` (eq. 8), ``noise_mean`` and ``variance`` (eq. 9); and every parameter:
        ``code``, ``code_length``, ``code_index``, ``code_options`` (the family's declared
        options as the code was made), ``ones_ratio`` (the requested share for
        random codes, the code's share for mseq/gold), ``ones``, ``ones_ratio_actual``,
        ``signal``, ``noise``, ``size``, ``on_fraction``, ``mirrors_on``, ``reflectivity``,
        ``trials``, ``method``, ``interval``, ``replica`` (``'unipolar'``), ``delay``.

    Raises
    ------
    ConfigError
        On invalid parameters (see :func:`~spslidar.snr.snr_theory`), a signal or a
        reflectivity of 0, ``trials < 2``, an unknown method or interval, or photon numbers
        too large to draw.

    Warns
    -----
    RuntimeWarning
        Where the trials cannot resolve the SNR (``ratio`` is then NaN), saying why and what
        to change: ``trials x theory`` below ``MIN_TRIALS_X_SNR`` (4), every trial with the
        same count (no sample variance: the estimate is 0/0 or infinite), or no finite
        standard error or interval.

    Notes
    -----
    The mean counts in TDC bin ``t`` are ``m_s M_2 a s(t - k) + N^2 m_n`` (eq. 4 with one
    delay) and the matched filter is ``C = sum_t h(t) s(t - k)`` (eq. 5-6, unipolar replica),
    so ``C`` sums the ``R_a T`` bins where the code is on: it is Poisson with mean
    ``R_a T (M_2 a m_s + N^2 m_n)``, which is what ``method='sum'`` draws directly. The SNR
    of eq. (10) is estimated as

        SNR_sim = (mean(C) - E[C_n])^2 / var(C),   E[C_n] = R_a T N^2 m_n,

    with ``var`` the unbiased sample variance. The noise mean ``E[C_n]`` is the known input of
    the simulation, not estimated from noise-only trials: it is exact, whereas an estimate
    would add its own variance to the numerator (and a bias of ``Var[C_n] / trials``) without
    testing anything eq. (10) states. The plug-in estimator has a relative bias of about
    ``2 / trials`` (from ``1 / var``), far below its standard error ``~ sqrt(2 / trials)``.
    The delta-method variance uses the sample central moments ``m3``, ``m4``:
    ``Var(mean) = v / K``, ``Var(v) = (m4 - v^2 (K - 3) / (K - 1)) / K``,
    ``Cov(mean, v) = m3 / K``.
    The estimate has a floor: ``E[(mean(C) - E[C_n])^2] = (E[C_s])^2 + var(C) / K``, so with
    no signal at all it averages ``1 / K`` (``chi^2_1 / K``). The trials resolve the SNR only
    where ``K x SNR`` (the squared number of standard errors of ``mean(C)`` the signal mean
    spans; with no noise, the signal photons expected over all trials) reaches
    ``MIN_TRIALS_X_SNR`` = 4: below it the floor exceeds a quarter of the SNR and the
    estimate's relative spread ``2 / sqrt(K SNR)`` exceeds 100 %, and simulated / theory
    measured the floor (2.3e16 at ``signal=1e-12``). There ``ratio`` is NaN and a
    RuntimeWarning names the ``trials`` that would resolve it; ``simulated`` and its interval
    are kept (they bound the SNR from above).
    The delta interval is asymptotic: its coverage of eq. (10) was measured at 94.4 % for 200
    trials and 89 % for 20 (4000 repetitions each, m-sequence of 1023 bits), so use ``trials``
    of 100 or more, or ``interval='bootstrap'``, when the interval matters.
    """

    kind = code_family(code)
    m_s = _positive(signal, "--signal", math.inf)
    m_n = as_nonneg(noise, "noise m_n")
    a = _positive(reflectivity, "--reflectivity", 1.0)
    m2 = mirrors_on(on_fraction, size)
    n = check_size(size)
    k = check_trials(trials)
    method = check_choice(method, SNR_METHODS, "method")
    interval = check_choice(interval, SNR_INTERVALS, "interval")
    if interval == "bootstrap":
        n_boot = as_integer(n_boot, "n_boot")
        if n_boot < 100:
            raise config_error(f"n_boot must be at least 100, got {n_boot}")
        if k < MIN_BOOT_TRIALS:
            raise config_error(f"a bootstrap interval needs at least {MIN_BOOT_TRIALS} trials "
                               f"to resample, got {k} (use more --trials or the delta method)")
    if as_integer(code_length, "code length") > MAX_SIM_CODE_LENGTH:  # before the code exists
        raise config_error(f"code length {code_length} is more than the {MAX_SIM_CODE_LENGTH} "
                           f"bits a simulation takes (as run's --code-length); eq. (10) itself "
                           f"(spslidar.snr.snr_theory) has no such limit")
    from ..randomness import as_generator

    gen = as_generator(rng)
    code_index = default_code_index(kind, code_index)
    code_options = chosen_code_options(kind, code_options)  # (the result says them)
    bits = make_code_checked(kind, code_length, ones_ratio, gen, code_index,
                             options=code_options)
    period = int(bits.size)
    ones = int(bits.sum())
    if kind == "random" and ones_ratio is not None and realised_far(
            ones, float(ones_ratio) * period):
        # (--ones-ratio 1e-10 over 100 bits drew a code of share 0.01, and 0.01 over 2 bits
        # one of 0.5, unsaid: an outside audit of 2026-12-01)
        warnings.warn(f"--ones-ratio {float(ones_ratio):g} drew a {period}-bit code with "
                      f"{ones} one{'' if ones == 1 else 's'} (share {ones / period:.3g}), "
                      f"which the simulation and its eq. (10) use", UserWarning, stacklevel=2)
    from ..pipeline.budget import check_time  # refuses beyond max_time, says over 30 s

    check_time(estimate_seconds(period, k, method,
                                n_boot if interval == "bootstrap" else 0),
               max_time, "this SNR simulation",
               reduce="--trials or --code-length" + (
                   ", use --method sum" if method != "sum" else "") + (
                   ", use --interval delta" if interval == "bootstrap" else ""))
    lag = period // 3 if delay is None else as_integer(delay, "delay") % period
    sig_bit = m2 * a * m_s
    noise_bin = n * n * m_n
    theory = eq10(ones, m2, a, m_s, n, m_n)

    if method == "sum":
        c = _counts_sum(ones, sig_bit + noise_bin, k, gen)
    else:
        c = _counts_histogram(bits, m2, n, a, m_s, m_n, lag, k, gen)
    noise_mean = ones * noise_bin
    simulated, se = _delta_stderr(c, noise_mean)
    if interval == "delta":
        z = _t95(k)
        lo, hi = max(simulated - z * se, 0.0), simulated + z * se
    else:
        se, lo, hi = _bootstrap(c, noise_mean, n_boot, gen)
    why = _unresolved(c, theory, m_n, (simulated, se, lo, hi))
    if why is not None:
        warnings.warn(why, RuntimeWarning, stacklevel=2)
    ratio = simulated / theory if why is None else math.nan
    return {
        "code": kind,
        "code_length": period,
        "code_index": int(code_index),
        # the family's declared options as the code was made (a plugin's; {} for the
        # built-ins): the --json params left them out, a review
        "code_options": code_options,
        "ones_ratio": float(ones_ratio) if kind == "random" else ones / period,
        "ones": ones,
        "ones_ratio_actual": ones / period,
        "signal": m_s,
        "noise": m_n,
        "size": n,
        "on_fraction": float(on_fraction),
        "mirrors_on": m2,
        "reflectivity": a,
        "trials": k,
        "method": method,
        "interval": interval,
        "replica": "unipolar",
        "delay": int(lag),
        "theory": float(theory),
        "simulated": float(simulated),
        "stderr": float(se),
        "ci_low": float(lo),
        "ci_high": float(hi),
        "ratio": float(ratio),
        "mean_counts": float(c.mean()),
        "var_counts": float(c.var(ddof=1)),
        "signal_mean": float(ones * sig_bit),
        "noise_mean": float(noise_mean),
        "variance": float(ones * (sig_bit + noise_bin)),
    }
