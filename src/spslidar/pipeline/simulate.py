"""The simulation engine: expected counts (forward model, equation 4) -> detector model -> matched
filter (equations 5-6), streamed over blocks of patterns on a thread pool."""

from __future__ import annotations

import os
from concurrent.futures import ThreadPoolExecutor

import numpy as np

from ..arrays import whole_numbers
from ..capture import carried
from ..correlate import (
    FFT_LAGS,
    check_noise_scale,
    correlation_gain,
    make_replica,
    matched_filter,
    noise_sigma_from_totals,
    noiseless_roundoff,
    replica_matrix,
)
from ..detectors import DetectorModel
from ..detectors.base import checked_detect, model_words
from ..detectors.counting import MAX_MEAN, NoiseModel, check_means
from ..errors import ConfigError
from ..forward import expected_counts, shifted_codes
from ..patterns import PatternOperator, as_patterns
from .acquisition import Acquisition

#: rows of patterns per random stream: block ``b`` draws its counts from the ``b``-th child of
#: the counts generator, so the results depend only on the seed (not on threads or chunking)
BLOCK = 64
#: most threads simulating blocks at once (memory: ~ 20 * BLOCK * L bytes per thread)
MAX_THREADS = 8
#: implementations of :func:`simulate_correlations`
SIMULATE_METHODS = ("fast", "reference")


def simulate_correlations(
    patterns: PatternOperator,
    scene,
    acq: Acquisition,
    lags: np.ndarray,
    noise: NoiseModel,
    detector: DetectorModel,
    pulse_width: float,
    rng_counts: np.random.Generator,
    noiseless: bool = False,
    method: str = "fast",
    threads: int | None = None,
    instrument=None,
    max_time: float | None = None,
    max_memory: float | None = None,
) -> dict[str, np.ndarray]:
    """Expected counts -> Poisson counts -> matched filter, streamed over blocks of patterns.

    Parameters
    ----------
    patterns : PatternOperator or ndarray, shape (M, Q)
        The DMD patterns (only products of row blocks are used).
    scene : Scene
        Depth and reflectivity per pixel.
    acq : Acquisition
    lags : ndarray of int, shape (K,)
        Delays (whole bins) at which the matched filter is evaluated.
    noise : NoiseModel
    detector : DetectorModel
        Turns each block's expected photons per bin into detected counts (the stage's
        contract, :class:`spslidar.detectors.DetectorModel`).
    pulse_width : float
        Return pulse width in bins.
    rng_counts : numpy.random.Generator
        Source of the photon counts: block ``b`` of ``BLOCK`` patterns draws from the ``b``-th
        of ``rng_counts.spawn(n_blocks)``, so the counts depend only on the seed.
    noiseless : bool
        Use the expected counts themselves (no Poisson draw).
    method : {'fast', 'reference'}
        ``'fast'`` (default): the blocks run on a thread pool (NumPy's Poisson sampler and
        BLAS release the GIL; BLAS itself is held to one thread meanwhile, and without
        ``threadpoolctl`` the blocks run one after the other). Per block, the expected counts
        are one BLAS product of the return amplitudes with the matrix of codes shifted to
        each occupied delay, the counts one Poisson draw per TDC bin, and the matched filter
        one product with the bank of replicas shifted to each gated lag. ``'reference'``:
        brute force, kept for the tests: in float64, the return profile of each pattern
        circularly convolved with the code by FFT, per-bin Poisson draws, the full circular
        cross-correlation at every lag by FFT, then the gated lags picked out.
    instrument : object, optional
        Its ``system_delay`` (s) and ``irf`` (spec) are applied to every return
        (:func:`spslidar.instrument.instrument_weights`); default an ideal instrument.
    threads : int, optional
        Threads (default: the CPUs available); the result does not depend on it.
    max_time : float, optional
        For a detector model other than the linear counter, whose cost depends on the flux
        (a saturated GMAPD's dead-time fixed point takes thousands of sweeps), the first block
        of patterns is simulated alone and timed, and the rest estimated from it is refused
        beyond ``max_time`` seconds or said on stderr when over 30 s
        (:func:`spslidar.pipeline.budget.check_time`). None: not timed.
    max_memory : float, optional
        For such a model the first block's peak memory is measured too (the rise of the
        resident memory it causes: the run's estimate, made before the flux is known, leaves
        the model out), and the blocks
        run on as many threads as fit under ``max_memory`` GB (default: the memory
        available), one at a time if need be; where one does not fit, a one-line
        :class:`~spslidar.errors.ConfigError` (a GMAPD run peaked at 0.82 GB under a 0.3 GB
        ``--max-memory``, two blocks at a time: an audit of 2026-11-29).

    Returns
    -------
    dict with ``corr`` (M, K) normalised matched-filter outputs at ``lags``, ``sigma`` (M,)
    their estimated noise standard deviations, ``counts`` (M,) total counts per pattern,
    ``signal_counts`` (M,) expected signal counts per pattern, ``noise_per_bin`` (M,) and
    ``incident_counts`` (M,) the expected photons reaching the detector per pattern (signal
    and background, before the detector; the detector's report reads them).

    Notes
    -----
    Both methods draw every TDC bin from its own Poisson distribution, so they give the same
    distribution of the gated outputs (``tests/test_pipeline.py`` checks their means, variances
    and covariances against each other and against the exact moments); the fast path computes
    the means in float32 (relative error ~1e-7, far below the Poisson fluctuations). Why no
    cheaper sampling scheme is exact is explained in :mod:`spslidar.detectors.counting`.
    """
    if method not in SIMULATE_METHODS:
        raise ConfigError(f"unknown simulation method {method!r}; choose fast or reference")
    patterns = as_patterns(patterns, copy=False)
    m = patterns.shape[0]
    # (fractional lags were cast to the bin below without a word, where matched_filter and
    # the gate refused them: an audit of 2026-11-30)
    lags = whole_numbers(lags, "lags")
    refl = scene.reflectivity.ravel()
    # the return amplitudes of pattern block b are patterns[b] @ weights (eq. 4 without the
    # code), as the instrument records them (system delay and IRF; spslidar.instrument)
    from types import SimpleNamespace

    from ..instrument import instrument_weights

    shifts, weights = instrument_weights(scene, acq, SimpleNamespace(
        pulse_width=pulse_width, system_delay=getattr(instrument, "system_delay", 0.0),
        irf=getattr(instrument, "irf", None)))
    noise_bin = noise.per_bin(patterns, refl, acq.bin_width)
    replica = make_replica(acq.code, acq.replica)
    gain = correlation_gain(acq.code, replica) * acq.n_periods * acq.signal_per_pulse
    check_noise_scale(noise_bin, acq, gain)
    n_blocks = max(1, int(np.ceil(m / BLOCK)))
    edges = np.linspace(0, m, n_blocks + 1).astype(int)
    children = rng_counts.spawn(n_blocks)
    args = (patterns, weights, shifts, noise_bin, acq, detector, replica, lags, gain, edges,
            children, noiseless)
    if method == "fast":
        corr, totals, noise_tot, amp_sum, incident = _simulate_fast(
            *args, threads=threads, max_time=max_time, max_memory=max_memory)
    else:
        corr, totals, noise_tot, amp_sum, incident = _simulate_reference(*args)
    n_pulses = float(acq.code.sum()) * acq.n_periods
    signal_counts = acq.signal_per_pulse * n_pulses * amp_sum
    if noiseless:
        noiseless_roundoff(noise_bin, amp_sum, acq, patterns.shape[1])
    sigma = noise_sigma_from_totals(noise_tot, replica, gain)
    return {"corr": corr, "sigma": sigma, "counts": totals, "signal_counts": signal_counts,
            "noise_per_bin": noise_bin, "incident_counts": incident}


def single_threaded_blas():
    """A context in which BLAS runs on one thread, or ``None`` without ``threadpoolctl``.

    The simulation's own threads each run BLAS products; BLAS's threads on top of them would
    oversubscribe the cores (OpenBLAS's busy-wait after each product: measured on 2 cores, the
    simulation ~10-20 % slower, and up to 10x when the machine is loaded).

    Returns
    -------
    context manager or None
        The process-wide one-thread BLAS of :mod:`spslidar.operators.parallel`, whose limit
        the last thread inside gives back (this function set and restored its own, as that
        module did before its limits were shared: runs in a thread pool then left BLAS on one
        thread, an audit of 2026-11-29).
    """
    try:
        import threadpoolctl  # noqa: F401 - only whether it is there
    except ImportError:  # pragma: no cover - threadpoolctl is optional
        return None
    from ..operators.parallel import _blas_held

    return _blas_held()


def simulation_threads(threads: int | None = None) -> int:
    """Threads for the simulation.

    Parameters
    ----------
    threads : int, optional
        Requested number; default: the CPUs this process may use.

    Returns
    -------
    int
        Between 1 and ``MAX_THREADS``.
    """
    if threads is None:
        try:
            threads = len(os.sched_getaffinity(0))
        except AttributeError:  # pragma: no cover - not Linux
            threads = os.cpu_count() or 1
    return max(1, min(int(threads), MAX_THREADS))


def _simulate_fast(patterns, weights, shifts, noise_bin, acq, detector, replica, lags, gain,
                   edges, children, noiseless, threads=None, max_time=None, max_memory=None):
    """The streamed simulation of :func:`simulate_correlations` (``method='fast'``)."""
    m = patterns.shape[0]
    n_blocks = edges.size - 1
    bank = replica_matrix(replica, lags) if lags.size <= FFT_LAGS else None
    code_matrix = shifted_codes(acq.code, shifts)
    corr = np.empty((m, lags.size), dtype=np.float32)
    totals = np.empty(m)
    noise_tot = totals if detector.linear else np.empty(m)
    amp_sum = np.empty(m)
    incident = np.empty(m)  # photons reaching the detector, each pattern's (for its report)
    # every bin's mean is at most n_periods * (m_s * sum_s |amp_s| + |noise|) (efficiency <= 1):
    # only a block whose bound reaches float32's exact integer range is scanned (NumPy's sampler
    # itself rejects negative or NaN means)

    def block(b):
        rows = slice(edges[b], edges[b + 1])
        amp = patterns.apply_rows(rows, weights)
        amp_sum[rows] = amp.sum(axis=1)
        lam = expected_counts(amp, shifts, acq.code, acq.signal_per_pulse, noise_bin[rows],
                              acq.n_periods, code_matrix=code_matrix)
        incident[rows] = lam.sum(axis=1, dtype=np.float64)
        if noiseless:
            shape = lam.shape
            lam = detector.expected(lam, acq.n_periods)
            _check_counts(lam, shape, detector, "expected")
            # (the noise level's totals too: a non-linear model's are a separate array, left
            # unset here before, so a noiseless GMAPD run read uninitialised memory)
            totals[rows] = noise_tot[rows] = lam.sum(axis=1, dtype=np.float64)
            if not detector.linear:  # the correction is exact on expected histograms (it
                # was skipped: RMSE 0.022 m), said to be one (without the bounds on counts,
                # which at one period erased every bin: an empty depth map)
                lam = detector.correct(lam, acq.n_periods, expected=True)
        else:
            ceiling = acq.n_periods * (acq.signal_per_pulse * np.abs(amp).sum(axis=1)
                                       + np.abs(noise_bin[rows]))
            if not np.all(ceiling <= MAX_MEAN * 0.99):
                check_means(lam)
            # the counts overwrite their own means (NumPy draws from a float64 copy)
            shape = lam.shape
            lam, tot = checked_detect(detector, lam, children[b], acq.n_periods, out=lam)
            _check_counts(lam, shape, detector, totals=tot)  # (every model's: a plugin's)
            totals[rows] = tot
            if not detector.linear:
                fixed = detector.correct(lam, acq.n_periods)
                _check_counts(fixed, shape, detector, "correct")
                noise_tot[rows] = checked_noise_totals(detector, lam, totals[rows],
                                                       acq.n_periods, fixed)
                lam = fixed
        corr[rows] = matched_filter(lam, replica, lags, gain, bank=bank)

    first, fit = 0, None
    if not detector.linear and n_blocks > 1:
        # a flux-dependent detector model: time the first block, price the rest from it (each
        # block draws from its own stream, so the order does not change the result), and
        # measure its memory, which no estimate made before the flux holds
        import time

        from .budget import check_time

        t0 = time.perf_counter()
        fit = _measured_block(block, detector, max_memory)
        took = time.perf_counter() - t0
        first = 1
    if first:
        # priced as if the blocks ran one after another: a detector model's block is mostly
        # Python (the GMAPD's renewal model, its detection-by-detection draws, the Coates
        # correction), so the threads gain little (an audit of 2026-11-29 measured 25.7 s
        # where the rest had been priced at half its sequential time, 17 s; sequential, 27 s)
        rest = took * (n_blocks - 1)
        check_time(took + rest, max_time, f"the {detector.name} detector model's simulation",
                   reduce="--size, --compression, --code-length or the flux (--signal, "
                          "--noise)", basis="its first block of patterns")
    elif not detector.linear and m > 1:
        # one block: nothing was priced, so a 16x16 GMAPD run estimated at 0.13 s took 36 s
        # (noiseless 275 s) without a word (an audit of 2026-11-29); one pattern's model, on
        # a stream of its own (the run's draws are untouched), prices the block
        import time

        from .budget import check_time

        t0 = time.perf_counter()
        probed = _probe_row(patterns, weights, shifts, noise_bin, acq, detector, noiseless,
                            code_matrix)
        if probed:
            check_time(m * (time.perf_counter() - t0), max_time,
                       f"the {detector.name} detector model's simulation",
                       reduce="--size, --compression, --code-length or the flux (--signal, "
                              "--noise)", basis="one pattern's model")
    todo = range(first, n_blocks)
    workers = min(simulation_threads(threads), len(todo), fit or len(todo))
    blas_limit = single_threaded_blas() if workers > 1 else None
    if blas_limit is None:
        for b in todo:
            block(b)
    else:
        with blas_limit, ThreadPoolExecutor(workers) as pool:
            list(pool.map(carried(block), todo))
    return corr, totals, noise_tot, amp_sum, incident


def _probe_row(patterns, weights, shifts, noise_bin, acq, detector, noiseless: bool,
               code_matrix) -> bool:
    """A detector model's work for one pattern of median light alone, on a stream of its
    own: what :func:`_simulate_fast` times to price a run of one block. The first pattern
    was taken (a Hadamard order's all-on row, 1.9 times the mean light: a run of 2.3 s was
    priced at 6.6 s and refused under --max-time 5, a review). False, and nothing timed,
    where the model refuses the pattern: the block itself then refuses the run, with its
    brightest pattern's numbers (the probe's line gave the first pattern's, called the
    brightest)."""
    amp = patterns.apply_rows(slice(None), weights)
    light = np.abs(amp).sum(axis=1)

    def means(row: int) -> np.ndarray:
        return expected_counts(amp[row:row + 1], shifts, acq.code, acq.signal_per_pulse,
                               noise_bin[row:row + 1], acq.n_periods, code_matrix=code_matrix)

    row = int(np.argsort(light, kind="stable")[light.size // 2])
    try:
        # the brightest pattern's flux first, as the block checks it (a Hadamard run's
        # all-on row is refused: it was announced as '44 s' first, a review's case)
        detector.check_flux(means(int(np.argmax(light))), acq.n_periods)
        lam = means(row)
        if noiseless:
            detector.correct(detector.expected(lam, acq.n_periods), acq.n_periods,
                             expected=True)
            return True
        check_means(lam)
        counts, _ = checked_detect(detector, lam, np.random.default_rng(0), acq.n_periods, out=lam)
        detector.correct(counts, acq.n_periods)
    except ConfigError:
        return False
    return True


def _peak_growth(fn) -> float:
    """Run ``fn()`` and return how far the process's resident memory rose above where it
    started, sampled every 5 ms by a thread (``/proc/self/statm``; 0 where the system does
    not say). ``tracemalloc`` measured it exactly, but slowed the GMAPD's Python-heavy model
    by half (``reproduce pileup`` 80 -> 121 s) and its traces made joblib's workers restart."""
    import gc
    import threading

    from ..machine import resident_memory

    gc.collect()  # (garbage freed during the block would hide its rise)
    start = resident_memory()
    peak = [start]
    done = threading.Event()

    def watch() -> None:
        while not done.wait(0.005):
            peak[0] = max(peak[0], resident_memory())

    watcher = threading.Thread(target=watch, daemon=True)
    watcher.start()
    try:
        fn()
    finally:
        done.set()
        watcher.join()
    return max(peak[0], resident_memory()) - start


def _measured_block(block, detector, max_memory: float | None) -> int:
    """Run ``block(0)`` and return how many such blocks fit at once: in ``max_memory`` GB less
    what the process holds, or (no cap) in the memory available, which already leaves the
    process's own out (subtracting it too refused a 16 MB block with 1 GB free: a review).
    The block's peak is the rise of the resident memory it causes (:func:`_peak_growth`).
    None fitting is a one-line ConfigError."""
    from ..machine import _gb, available_memory, resident_memory

    need = max(1.0, _peak_growth(lambda: block(0)))
    if max_memory is None:
        limit, held, src = available_memory(), 0.0, "available"
    else:
        limit, held, src = float(max_memory) * 1e9, resident_memory(), "--max-memory"
    fit = int((limit - held) // need)
    if fit < 1:
        beside = f", beside the {_gb(held)} the run holds" if held else ""
        raise ConfigError(
            f"the {detector.name} detector model's simulation holds about {_gb(need)} per "
            f"block of patterns (measured on its first){beside}: more than the {_gb(limit)} "
            f"{src}; lower the flux (--signal, --noise), --periods, --size or --code-length"
            + ("" if max_memory is None else ", or raise --max-memory"))
    return fit


def _check_counts(counts, shape: tuple, detector, what: str = "detect",
                  totals=None) -> None:
    """A detector model's histograms as the matched filter takes them: ``shape``, finite and
    (but what :meth:`correct` makes) no bin below zero, with ``totals`` one finite total of
    0 or more per row where given; or a one-line ConfigError naming the model (a plugin's NaN
    counts were refused as a weight "beyond what float32 can hold"; histograms one bin short
    ended in a traceback in the matched filter; an audit of plugins). Every model's, every
    block: a plugin's linear ``poisson(mean) - 1`` ran with negative bins, or at a low flux
    ended in correlate.py's "totals holds a negative count" traceback (an outside audit of
    2026-11-30). Two reductions of the block (its min and max, which NaN reaches too), a
    fraction of its Poisson draws."""
    arr = np.asarray(counts)
    name = model_words(detector)
    if arr.dtype.kind not in "biuf":  # (complex counts ended in the matched filter's "hist
        # holds complex numbers", the model unnamed: an outside audit of plugins)
        raise ConfigError(f"the detector model {name} returned histograms of dtype "
                          f"{arr.dtype} from its {what}(): counts are real numbers")
    if arr.shape != shape:
        raise ConfigError(f"the detector model {name} returned histograms of shape "
                          f"{arr.shape} from its {what}() for {shape} (patterns x bins)")
    low, high = (float(arr.min()), float(arr.max())) if arr.size else (0.0, 0.0)
    if not (np.isfinite(low) and np.isfinite(high)):
        raise ConfigError(f"the detector model {name} returned histograms that are not "
                          f"finite from its {what}()")
    if low < 0 and what != "correct":  # (a correction may undershoot: its own concern)
        raise ConfigError(f"the detector model {name} returned negative counts (down to "
                          f"{low:g} in a bin) from its {what}(): a bin holds 0 or more")
    if totals is None:
        return
    tot = np.asarray(totals)
    if tot.shape != shape[:1]:
        raise ConfigError(f"the detector model {name} returned totals of shape {tot.shape} "
                          f"from its {what}() for {shape[0]} patterns (one per row)")
    if tot.size and not (np.isfinite(tot).all() and tot.min() >= 0):
        raise ConfigError(f"the detector model {name} returned totals that are negative or "
                          f"not finite from its {what}(): a row's total is 0 or more")


def checked_noise_totals(detector, counts, totals, n_periods: int, corrected) -> np.ndarray:
    """``detector.noise_totals(...)``: one finite, non-negative variance per row, or a
    one-line ConfigError naming the model (a plugin's negative or mis-shaped noise totals
    ended in a traceback from the matched filter's noise level, an outside audit of
    plugins)."""
    got = np.asarray(detector.noise_totals(counts, totals, n_periods, corrected=corrected))
    name = model_words(detector)
    rows = np.shape(totals)[:1]
    if got.dtype.kind not in "biuf" or got.shape != rows:
        raise ConfigError(f"the detector model {name} returned noise totals of shape "
                          f"{got.shape} and dtype {got.dtype} from its noise_totals() for "
                          f"{rows[0]} patterns (one real variance per row)")
    if got.size and not (np.isfinite(got).all() and got.min() >= 0):
        raise ConfigError(f"the detector model {name} returned noise totals that are "
                          f"negative or not finite from its noise_totals(): a variance is 0 "
                          f"or more")
    return got


def _simulate_reference(patterns, weights, shifts, noise_bin, acq, detector, replica, lags, gain,
                        edges, children, noiseless):
    """Brute-force :func:`simulate_correlations` (``method='reference'``): slow, for tests."""
    m = patterns.shape[0]
    period = acq.period
    amp = patterns.apply_rows(slice(0, m), weights)
    code_f = np.fft.rfft(np.asarray(acq.code, dtype=np.float64))
    rep_f = np.conj(np.fft.rfft(np.asarray(replica, dtype=np.float64)))
    corr = np.empty((m, lags.size), dtype=np.float32)
    totals = np.empty(m)
    noise_tot = np.empty(m)
    incident = np.empty(m)
    for b in range(edges.size - 1):
        rows = slice(edges[b], edges[b + 1])
        # eq. (4): each pattern's return amplitude per delay bin, circularly convolved with the
        # code by FFT (its round-off, where the signal is exactly 0, set to 0)
        profile = np.zeros((rows.stop - rows.start, period))
        profile[:, shifts] = amp[rows]
        signal = np.fft.irfft(np.fft.rfft(profile, axis=1) * code_f, n=period, axis=1)
        signal[np.abs(signal) <= 1e-9 * np.abs(amp[rows]).sum(axis=1, keepdims=True)] = 0.0
        lam = acq.n_periods * (acq.signal_per_pulse * signal + noise_bin[rows, None])
        incident[rows] = lam.sum(axis=1)
        if noiseless:
            hist = detector.expected(lam, acq.n_periods)
            _check_counts(hist, lam.shape, detector, "expected")
            totals[rows] = noise_tot[rows] = hist.sum(axis=1)
            # (a linear detector's: itself)
            hist = detector.correct(hist, acq.n_periods, expected=True)
        else:
            check_means(lam)
            hist, tot = checked_detect(detector, lam, children[b], acq.n_periods,
                                out=np.empty_like(lam))
            _check_counts(hist, lam.shape, detector, totals=tot)
            totals[rows] = tot
            fixed = detector.correct(hist, acq.n_periods)
            noise_tot[rows] = checked_noise_totals(detector, hist, totals[rows],
                                                   acq.n_periods, fixed)
            hist = fixed
        # C(tau) = sum_t h(t) f(t - tau) at every tau (eq. 5-6), then the gated lags
        full = np.fft.irfft(np.fft.rfft(hist, axis=1) * rep_f, n=period, axis=1)
        corr[rows] = full[:, np.mod(lags, period)] / gain
    return corr, totals, noise_tot, amp.sum(axis=1), incident
