"""The device kernels of the chain's stages: what :mod:`spslidar.pipeline.chain` runs on a
backend's device when the stage choice has one (``--backend torch|cupy|array-api-strict``).

There is one chain, :func:`spslidar.pipeline.chain.measure` and ``reconstruct``; for each
stage it asks :func:`simulates_on_device` / :func:`reconstructs_on_device` whether this
backend has a device kernel for the configured choice, and otherwise runs the stage's NumPy
implementation on the host, on the arrays brought back (:func:`spslidar.backends.patterns.
host_patterns`), so every stage choice runs on every backend through the same path. The
kernels here are written against the array API (:mod:`spslidar.backends.kernels`):

* :func:`simulate` - expected counts, Poisson counts and the matched filter of a block of
  patterns at a time (eq. 4-6), for the ``linear`` detector;
* :func:`problem` - the centred QCR problem (eq. 11-18) with the noise probe of the
  regularisation default and ``max |A^T y|``;
* :func:`solve` - FISTA with the TV prox (a CUDA graph on PyTorch + CUDA);
* :func:`argmax_depth` - the argmax estimator's peaks (eq. 2-3), only the peaks come back.

Nothing here imports the pipeline: the chain hands each kernel what it needs.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from . import DEVICE_KERNELS
from .kernels import TVProx, argmax_peaks, centre, fista_tv, scalars, simulate_block
from .rng import Stream

__all__ = ["DEVICE_BLOCK_BINS", "argmax_depth", "noise_per_bin", "problem",
           "reconstructs_on_device", "simulate", "simulates_on_device", "solve"]

#: most TDC bins (patterns x code period) per simulated block on a device stream (fixed, so the
#: counts depend only on the seed and the shape): 2^27 float32 bins = 512 MB
DEVICE_BLOCK_BINS = 1 << 27
#: replay FISTA's iterations from a CUDA graph with PyTorch on CUDA (``torch_graph``)
USE_CUDA_GRAPHS = True


def simulates_on_device(cfg: Any, patterns: Any) -> bool:
    """Whether the simulation stage has a device kernel for this run: the ``linear``
    detector (another detector's counts are drawn by its NumPy kernel on the host) and
    patterns shown as they are (differential patterns, shown as two exposures, are
    simulated on the host)."""
    host = getattr(patterns, "host", None)
    return (cfg.detector in DEVICE_KERNELS["detector"]
            and not getattr(host, "differential", False))


def reconstructs_on_device(cfg: Any) -> bool:
    """Whether the QCR problem and the solve have device kernels for this configuration
    (:data:`spslidar.backends.DEVICE_KERNELS`): the centred QCR form and plain FISTA with a TV
    (``--restart`` and ``--monotone`` are solved on the host)."""
    from ..config import chosen_stage_options

    k = DEVICE_KERNELS
    return (bool(cfg.qcr) and cfg.qcr_form in k["qcr_form"] and cfg.solver in k["solver"]
            and cfg.regulariser in k["regulariser"]
            and not any(chosen_stage_options(cfg, "solver").values()))


def noise_per_bin(be: Any, noise: Any, patterns: Any, refl: np.ndarray,
                  bin_width: float) -> np.ndarray:
    """:meth:`spslidar.detectors.counting.NoiseModel.per_bin` with the patterns' products
    with the reflectivity (the modulated ambient light) taken on the device."""
    mod = None
    if noise.ambient != "paper":
        a = be.asarray(np.asarray(refl, dtype=np.float64).reshape(-1, 1))
        mod = be.to_numpy(patterns.rows_apply(0, patterns.shape[0], a))[:, 0]
    return noise.per_bin(patterns, refl, bin_width, modulation=mod)


def simulate(be: Any, patterns: Any, acq: Any, ulags: np.ndarray, noise: Any, detector: Any,
             shifts: np.ndarray, weights: np.ndarray, refl: np.ndarray, seq_counts: Any,
             noiseless: bool, block_rows: int) -> dict[str, Any]:
    """The simulation stage on the device: eq. (4) per block of patterns, the detector's
    counts (:class:`~spslidar.backends.rng.Stream`), the matched filter (eq. 5-6).

    Parameters
    ----------
    be : Backend
        The array backend the stage runs on.
    patterns : DevicePatterns
        The DMD patterns, on the device.
    acq : Acquisition
        The code, the bin width and the periods per pattern.
    ulags : ndarray of int
        The gated lags (whole bins) at which the matched filter is evaluated.
    noise, detector : NoiseModel, DetectorModel
        The background model and the detector (the linear counter on this path).
    shifts, weights : ndarray
        Each pixel's returns per occupied delay (:func:`spslidar.instrument.
        instrument_weights`, host-side).
    refl : ndarray, shape (Q,)
        The scene's reflectivity per pixel.
    seq_counts : numpy.random.SeedSequence
        The counts' seed, read through a :class:`~spslidar.backends.rng.Stream` (the NumPy
        path's blocks and streams on a host stream).
    noiseless : bool
        Use the expected counts themselves (no Poisson draw).
    block_rows : int
        Patterns per block on a host stream (the NumPy path's ``BLOCK``, so the streams are
        split as it splits them).

    Returns
    -------
    dict
        The simulation record of :func:`spslidar.pipeline.simulate.simulate_correlations`,
        ``corr`` on the device.
    """
    from ..correlate import (
        FFT_LAGS,
        check_noise_scale,
        correlation_gain,
        make_replica,
        noise_sigma_from_totals,
        replica_matrix,
    )
    from ..detectors.counting import MAX_MEAN, check_means
    from ..forward import shifted_codes

    xp = be.xp
    m = patterns.shape[0]
    noise_bin = noise_per_bin(be, noise, patterns, refl, acq.bin_width)
    replica = make_replica(acq.code, acq.replica)
    gain = correlation_gain(acq.code, replica) * acq.n_periods * acq.signal_per_pulse
    check_noise_scale(noise_bin, acq, gain)  # (the device ran such signals: an audit)
    w_dev = be.asarray(weights)
    codes = be.asarray(shifted_codes(acq.code, shifts))
    period = int(acq.code.size)
    if ulags.size <= FFT_LAGS:  # the NumPy path's matched filter: a bank of shifted replicas
        bank, rep_f, take = be.asarray(replica_matrix(replica, ulags)), None, None
    else:  # ... or the FFT in float64 for many lags (the dense bank was L x K floats three
        # times over, 2.65 GB past a 0.6 GB cap at 16x16 through a 0-200 m gate, unpriced)
        bank = None
        rep_f = xp.conj(xp.fft.rfft(be.asarray(np.asarray(replica, dtype=np.float64))))
        take = be.asarray(np.mod(np.asarray(ulags, dtype=np.int64), period))
    noise_dev = be.asarray(noise_bin)
    counts_stream = Stream(be, seq_counts)
    if counts_stream.host:  # the NumPy path's blocks and streams
        n_blocks = max(1, int(np.ceil(m / block_rows)))
    else:
        n_blocks = max(1, int(np.ceil(m * acq.period / DEVICE_BLOCK_BINS)))
    edges = np.linspace(0, m, n_blocks + 1).astype(int)
    children = counts_stream.children(n_blocks)
    corr_parts, tot_parts, amp_parts = [], [], []
    for b in range(n_blocks):
        a, e = int(edges[b]), int(edges[b + 1])
        amp, lam = simulate_block(xp, patterns.rows_apply(a, e, w_dev), codes, noise_dev[a:e],
                                  acq.signal_per_pulse, acq.n_periods)
        if noiseless:
            counts, totals = lam, xp.sum(lam, axis=1, dtype=xp.float64)
        else:
            # the NumPy path's bound on exact float32 counts, read off the device only where
            # the block's ceiling passes it (it ran 1e8 photons per bin to a map: an audit)
            ceiling = acq.n_periods * (acq.signal_per_pulse * float(
                scalars(be, xp.max(xp.sum(xp.abs(amp), axis=1)))[0])
                + float(np.max(np.abs(noise_bin[a:e]), initial=0.0)))
            if not ceiling <= MAX_MEAN * 0.99:
                check_means(np.asarray(scalars(be, xp.min(lam), xp.max(lam))))
            counts, totals = counts_stream.poisson(lam, children[b], detector, acq.n_periods)
        del lam
        if bank is not None:
            corr_parts.append((counts @ bank) / float(gain))
        else:
            full = xp.fft.irfft(xp.fft.rfft(xp.astype(counts, xp.float64), axis=1)
                                * rep_f[None, :], n=period, axis=1)
            corr_parts.append(xp.astype(xp.take(full, take, axis=1) / float(gain), xp.float32))
            del full
        tot_parts.append(totals)
        amp_parts.append(xp.sum(amp, axis=1))
    corr = corr_parts[0] if n_blocks == 1 else xp.concat(corr_parts, axis=0)
    totals = be.to_numpy(xp.concat(tot_parts) if n_blocks > 1 else tot_parts[0])
    amp_sum = be.to_numpy(xp.concat(amp_parts) if n_blocks > 1 else amp_parts[0])
    n_pulses = float(acq.code.sum()) * acq.n_periods
    if noiseless:  # (the host's check of its float32 rounding: a review found it missing here)
        from ..correlate import noiseless_roundoff

        noiseless_roundoff(noise_bin, amp_sum, acq, patterns.shape[1])
    return {"corr": corr, "sigma": noise_sigma_from_totals(totals, replica, gain),
            "counts": totals, "signal_counts": acq.signal_per_pulse * n_pulses * amp_sum,
            "noise_per_bin": noise_bin}


def problem(be: Any, patterns: Any, corr: Any, sigma: np.ndarray, probe_seed: Any,
            dtype: Any) -> tuple[Any, Any, float, float]:
    """The centred QCR problem of eq. (18) on the device (:func:`spslidar.qcr.qcr_problem`),
    the regularisation default's noise level (:func:`spslidar.pipeline.weights.noise_level`,
    its probe drawn on the host stream of the NumPy path) and ``max |A^T y|``.

    Returns
    -------
    A, y : device operator and array
    sigma_eff, lam_max : float
    """
    xp = be.xp
    m = patterns.shape[0]
    norm = float(np.sqrt(m))
    A = patterns.centred(norm, dtype)
    y = xp.astype(centre(xp, xp.astype(corr, xp.float64)) / norm, dtype)
    e = np.random.default_rng(probe_seed).standard_normal((m, 4)) * sigma[:, None]
    ey = (e - e.mean(axis=0, keepdims=True)) / np.sqrt(m)
    z = A.rmatvec(xp.astype(be.asarray(ey), dtype))
    sigma_eff = float(np.sqrt(scalars(be, xp.mean(xp.astype(z, xp.float64) ** 2))[0]))
    lam_max = float(scalars(be, xp.max(xp.abs(xp.astype(A.rmatvec(y), xp.float64))))[0])
    return A, y, sigma_eff, lam_max


def solve(be: Any, A: Any, y: Any, shape: tuple[int, int], nonneg: bool, lam: float,
          iterations: int, tol: float, inner: int, isotropic: bool = True) -> tuple[Any, Any]:
    """FISTA + TV on the device (:class:`spslidar.solvers.fista.FISTA` with
    :class:`spslidar.solvers.regularisers.TV`, iterate for iterate); a CUDA graph replays the
    iterations with PyTorch on CUDA; ``isotropic`` False: the anisotropic TV of
    ``--regulariser tv-aniso``. Returns ``(x, FistaInfo)``."""
    reg = TVProx(be.xp, shape, nonneg=nonneg, max_inner=inner, be=be, isotropic=isotropic)
    run = fista_tv
    if USE_CUDA_GRAPHS and be.name == "torch" and be.device.type == "cuda":
        from .torch_graph import fista_tv_graphed as run
    return run(be, A, y, reg, lam, iterations, tol)


def argmax_depth(be: Any, slices: Any) -> tuple[np.ndarray, ...]:
    """The argmax estimator's peaks found on the device; only ``(idx, peak, below, above)``
    (one value per pixel) come back to the host."""
    return tuple(be.to_numpy(a) for a in argmax_peaks(be.xp, slices))


def scatter_columns(be: Any, full: Any, x: Any, cols: np.ndarray) -> Any:
    """``full[:, cols] = x`` (the array API has no integer-array assignment: one column at a
    time through basic indexing)."""
    for j, c in enumerate(np.asarray(cols).tolist()):
        full[:, c] = x[:, j]
    return full
