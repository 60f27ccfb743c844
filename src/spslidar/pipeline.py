"""One simulated acquisition and reconstruction, end to end: ``run(config) -> Result``.

scene -> code + patterns -> expected counts (forward) -> Poisson counts (detector) -> matched
filter over the range gate (correlate) -> QCR -> compressive reconstruction of all range slices
at once (solvers) -> ML depth -> metrics. The command-line tool is a thin layer over
:func:`run`.

Random streams: one ``np.random.SeedSequence(seed)`` is split into independent children for the
code, the patterns, the photon counts and the noise probe of the regularisation default, so
changing e.g. the noise level does not change the patterns.
"""

from __future__ import annotations

import importlib
import json
import os
import threading
import time
from collections import OrderedDict
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from . import __version__
from .codes import make_code
from .config import Config
from .constants import SPEED_OF_LIGHT
from .correlate import (
    correlation_gain,
    gate_lags,
    make_replica,
    matched_filter,
    noise_sigma_from_totals,
    replica_matrix,
)
from .depth import ml_depth
from .detector import (
    MAX_MEAN,
    NoiseModel,
    PhotonCountingDetector,
    check_means,
    poisson_rows,
)
from .errors import ConfigError
from .forward import depth_to_delay, expected_counts, return_weights, shifted_codes
from .metrics import depth_errors, edge_agreement, sobel_edges
from .outdir import write_result_dir
from .patterns import make_patterns, n_patterns_for
from .qcr import centre, plain_problem, qcr_problem
from .scenes import load_scene

#: multiplies the data-derived noise level to give the default regularisation weight, per
#: solver (calibrated by ``benchmarks/lambda_sweep.py`` on the built-in scenes).
DEFAULT_LAM_SCALE = {"fista": 0.3, "twist": 0.3, "tval3": 0.3, "gpsr": 0.3}
#: default iteration caps per solver (GPSR: nonmonotone GPSR-BB reaches in 120 iterations the
#: objective that the monotone variant needed 200 for, see :class:`spslidar.solvers.GPSR`)
DEFAULT_ITERATIONS = {"fista": 60, "twist": 60, "tval3": 100, "gpsr": 120}
#: inner (dual) iterations of the warm-started TV prox per outer iteration: the prox's dual is
#: carried over between outer iterations, so a few suffice (measured: the same depth RMSE
#: with 3, 5, 10 or 20 on the default problem, and on the motorcycle with FISTA and TwIST)
TV_INNER = 3
#: rows of patterns per random stream: block ``b`` draws its counts from the ``b``-th child of
#: the counts generator, so the results depend only on the seed (not on threads or chunking)
BLOCK = 64
#: most threads simulating blocks at once (memory: ~ 20 * BLOCK * L bytes per thread)
MAX_THREADS = 8
#: implementations of :func:`simulate_correlations`
SIMULATE_METHODS = ("fast", "reference")
#: range-gate padding, in bins, around the scene's depth window
GATE_PAD_BINS = 3
#: with auto_gate unset, gates with more distinct slices than this are pruned automatically
AUTO_GATE_MIN_SLICES = 256
#: detection threshold of the automatic range gate, in standard deviations of the
#: pattern-averaged matched-filter output
AUTO_GATE_SIGMAS = 5.0
#: bins kept on each side of every occupied delay
AUTO_GATE_DILATE = 2


@dataclass
class Acquisition:
    """What the temporal part of the instrument is: its code, timing and photon scaling."""

    lidar: str
    code: np.ndarray  # unipolar bits over one period (TDC bins)
    bin_width: float  # s
    n_periods: int  # code periods accumulated per pattern
    signal_per_pulse: float  # m_s for this instrument (fairness rule applied)
    replica: str
    description: str

    @property
    def period(self) -> int:
        return int(self.code.size)

    @property
    def unambiguous_range(self) -> float:
        return SPEED_OF_LIGHT * self.period * self.bin_width / 2.0

    @property
    def acquisition_time(self) -> float:
        return self.period * self.n_periods * self.bin_width


@dataclass
class Result:
    """Everything one run produced. ``metrics`` is what ``metrics.json`` holds."""

    config: Config
    scene: Any
    depth: np.ndarray
    slices: np.ndarray
    lags: np.ndarray
    corr: np.ndarray
    metrics: dict[str, Any]
    timing: dict[str, float]
    warnings: list[str] = field(default_factory=list)

    @property
    def truth(self) -> np.ndarray:
        return self.scene.depth

    @property
    def depth_rmse(self) -> float:
        return self.metrics["depth_rmse_m"]

    def summary(self) -> str:
        """Two lines: what was run and what came out."""
        c, m = self.config, self.metrics
        what = (f"{c.lidar} {m['code_description']}, scene {self.scene.name} {c.size}x{c.size}, "
                f"{m['n_patterns']} {c.patterns} patterns ({100 * c.compression:g}%), "
                f"{'QCR' if c.qcr else 'no QCR'}, {c.solver}")
        t = self.timing
        out = (f"depth RMSE {m['depth_rmse_m']:.4f} m ({m['depth_rmse_m'] / m['bin_depth_m']:.2f} "
               f"bins), {100 * m['missing_fraction']:.1f}% pixels without return; "
               f"{t['total']:.2f} s (simulate {t['simulate']:.2f}, solve {t['solve']:.2f})")
        return f"{what}\n{out}"

    def save(self, out_dir: str | os.PathLike, figure: bool = True,
             overwrite: bool = False) -> Path:
        """Write ``metrics.json``, ``depth.npy``, ``truth.npy``, ``valid.npy`` and
        ``depth.png`` into ``out_dir``, all or nothing (see :mod:`spslidar.outdir`).

        ``out_dir`` must not exist, be empty, or (with ``overwrite=True``) hold a previous
        spslidar result; anything else is refused before a file is written, so a user's
        files are never touched.
        """

        def fill(tmp: Path) -> None:
            t0 = time.perf_counter()
            np.save(tmp / "depth.npy", self.depth)
            np.save(tmp / "truth.npy", self.truth)
            np.save(tmp / "valid.npy", np.asarray(self.scene.valid, dtype=bool))
            if figure:
                from .figures import depth_figure

                depth_figure(self, tmp / "depth.png")
            self.timing["write"] = time.perf_counter() - t0
            self.metrics["timing_s"] = dict(self.timing)
            with open(tmp / "metrics.json", "w") as fh:
                json.dump(_jsonable(self.metrics), fh, indent=2, allow_nan=True)

        return write_result_dir(out_dir, fill, overwrite=overwrite)


def _jsonable(obj):
    if isinstance(obj, dict):
        return {str(k): _jsonable(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_jsonable(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return _jsonable(obj.tolist())
    if isinstance(obj, (np.floating, np.integer, np.bool_)):
        return obj.item()
    return obj


# -- building blocks ---------------------------------------------------------------------------


def default_gate(scene, bin_width: float) -> tuple[float, float]:
    """The scene's depth window padded by a few bins (the operator's prior on the range)."""
    pad = GATE_PAD_BINS * SPEED_OF_LIGHT * bin_width / 2.0
    return (max(0.0, scene.depth_min - pad), scene.depth_max + pad)


def make_acquisition(cfg: Config, gate: tuple[float, float], rng_code) -> Acquisition:
    """The temporal code and photon scaling of the PSST or the conventional lidar.

    The conventional lidar fires one pulse per repetition period ``P`` bins and histograms
    ``n = floor(L / P)`` periods, ``L`` being the PSST code length, so both spend the same
    acquisition time per pattern. ``fairness='energy'`` keeps the PSST pulse energy
    (``m_s`` per pulse, the paper's premise of no excess laser power); ``'power'`` gives the
    conventional lidar the same average power (its pulses carry ``m_s * ones / n``).
    """
    bin_width = 1.0 / cfg.bit_rate
    # Gold family members 0 and 1 are the preferred pair's m-sequences themselves; the first
    # true Gold code is member 2, the default.
    index = cfg.code_index if cfg.code_index is not None else (2 if cfg.code == "gold" else 0)
    psst_code = make_code(cfg.code, cfg.code_length, cfg.ones_ratio, rng=rng_code,
                          index=index).astype(np.uint8)
    if cfg.lidar == "psst":
        replica = "bipolar" if cfg.replica == "auto" else cfg.replica
        name = {"mseq": "m-sequence", "gold": "Gold code", "random": "Bernoulli code"}[cfg.code]
        desc = f"{name} of {cfg.code_length} bits"
        if cfg.code == "random":
            desc += f" (ones ratio {cfg.ones_ratio:g})"
        return Acquisition("psst", psst_code, bin_width, 1, cfg.signal, replica, desc)
    # conventional periodic-pulse lidar
    if cfg.rep_rate is None:
        period = int(np.ceil(gate[1] * 2.0 / (SPEED_OF_LIGHT * bin_width))) + 1
    else:
        period = int(round(cfg.bit_rate / cfg.rep_rate))
    if period < 2:
        raise ConfigError(f"--rep-rate {cfg.rep_rate:g} Hz is too fast for --bit-rate "
                          f"{cfg.bit_rate:g} Hz: the period must be at least 2 TDC bins")
    if period > cfg.code_length:
        raise ConfigError(
            f"repetition period of {period} bins exceeds the acquisition time of "
            f"{cfg.code_length} bins per pattern: use a faster --rep-rate or a longer "
            f"--code-length")
    n = cfg.code_length // period
    code = np.zeros(period, dtype=np.uint8)
    code[0] = 1
    per_pulse = cfg.signal
    if cfg.fairness == "power":
        per_pulse = cfg.signal * float(psst_code.sum()) / n
    replica = "unipolar" if cfg.replica == "auto" else cfg.replica
    rep = cfg.bit_rate / period
    desc = f"single pulse at {rep / 1e6:.3g} MHz x {n} shots"
    return Acquisition("conventional", code, bin_width, n, per_pulse, replica, desc)


def build_regulariser(cfg: Config, shape: tuple[int, int]):
    from .operators import Wavelet2D
    from .solvers.regularisers import L1, TV

    kind = cfg.regulariser
    if kind == "auto":
        kind = "wavelet" if cfg.solver == "gpsr" else "tv"
    if kind == "tv":
        return TV(shape, nonneg=cfg.nonneg, max_inner=TV_INNER)
    if kind == "l1":
        return L1(None, nonneg=cfg.nonneg)
    # the prox of a wavelet l1 norm under a non-negativity constraint has no closed form:
    # --nonneg applies to the TV and pixel-l1 regularisers only
    return L1(Wavelet2D(shape, "haar"))


def load_solver(name: str):
    """Import the solver's module (which registers it) and return its class."""
    from .solvers import get_solver

    importlib.import_module(f"spslidar.solvers.{name}")
    return get_solver(name)


def simulate_correlations(
    patterns: np.ndarray,
    scene,
    acq: Acquisition,
    lags: np.ndarray,
    noise: NoiseModel,
    detector: PhotonCountingDetector,
    pulse_width: float,
    rng_counts: np.random.Generator,
    noiseless: bool = False,
    method: str = "fast",
    threads: int | None = None,
) -> dict[str, np.ndarray]:
    """Expected counts -> Poisson counts -> matched filter, streamed over blocks of patterns.

    Parameters
    ----------
    patterns : ndarray, shape (M, Q)
    scene : Scene
        Depth and reflectivity per pixel.
    acq : Acquisition
    lags : ndarray of int, shape (K,)
        Delays (bins) at which the matched filter is evaluated.
    noise : NoiseModel
    detector : PhotonCountingDetector
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
    threads : int, optional
        Threads (default: the CPUs available); the result does not depend on it.

    Returns
    -------
    dict with ``corr`` (M, K) normalised matched-filter outputs at ``lags``, ``sigma`` (M,)
    their estimated noise standard deviations, ``counts`` (M,) total counts per pattern,
    ``signal_counts`` (M,) expected signal counts per pattern and ``noise_per_bin`` (M,).

    Notes
    -----
    Both methods draw every TDC bin from its own Poisson distribution, so they give the same
    distribution of the gated outputs (``tests/test_pipeline.py`` checks their means, variances
    and covariances against each other and against the exact moments); the fast path computes
    the means in float32 (relative error ~1e-7, far below the Poisson fluctuations). Why no
    cheaper sampling scheme is exact is explained in :mod:`spslidar.detector`.
    """
    if method not in SIMULATE_METHODS:
        raise ConfigError(f"unknown simulation method {method!r}; choose fast or reference")
    m = patterns.shape[0]
    lags = np.asarray(lags, dtype=np.int64)
    delay = depth_to_delay(scene.depth.ravel(), acq.bin_width)
    refl = scene.reflectivity.ravel()
    # the return amplitudes of pattern block b are patterns[b] @ weights (eq. 4 without the code)
    shifts, weights = return_weights(refl, delay, pulse_width, acq.period)
    noise_bin = noise.per_bin(patterns, refl, acq.bin_width)
    replica = make_replica(acq.code, acq.replica)
    gain = correlation_gain(acq.code, replica) * acq.n_periods * acq.signal_per_pulse
    n_blocks = max(1, int(np.ceil(m / BLOCK)))
    edges = np.linspace(0, m, n_blocks + 1).astype(int)
    children = rng_counts.spawn(n_blocks)
    args = (patterns, weights, shifts, noise_bin, acq, detector, replica, lags, gain, edges,
            children, noiseless)
    if method == "fast":
        corr, totals, amp_sum = _simulate_fast(*args, threads=threads)
    else:
        corr, totals, amp_sum = _simulate_reference(*args)
    n_pulses = float(acq.code.sum()) * acq.n_periods
    signal_counts = acq.signal_per_pulse * n_pulses * amp_sum
    sigma = noise_sigma_from_totals(totals, replica, gain)
    return {"corr": corr, "sigma": sigma, "counts": totals, "signal_counts": signal_counts,
            "noise_per_bin": noise_bin}


def single_threaded_blas():
    """A context in which BLAS runs on one thread, or ``None`` without ``threadpoolctl``.

    The simulation's own threads each run BLAS products; BLAS's threads on top of them would
    oversubscribe the cores (OpenBLAS's busy-wait after each product: measured on 2 cores, the
    simulation ~10-20 % slower, and up to 10x when the machine is loaded).

    Returns
    -------
    context manager or None
        ``threadpoolctl.threadpool_limits(1, user_api='blas')``; the previous limits come back
        on exit.
    """
    try:
        from threadpoolctl import threadpool_limits
    except ImportError:  # pragma: no cover - threadpoolctl is optional
        return None
    return threadpool_limits(limits=1, user_api="blas")


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
                   edges, children, noiseless, threads=None):
    """The streamed simulation of :func:`simulate_correlations` (``method='fast'``)."""
    m = patterns.shape[0]
    n_blocks = edges.size - 1
    bank = replica_matrix(replica, lags) if lags.size <= 256 else None
    code_matrix = shifted_codes(acq.code, shifts)
    corr = np.empty((m, lags.size), dtype=np.float32)
    totals = np.empty(m)
    amp_sum = np.empty(m)
    # every bin's mean is at most n_periods * (m_s * sum_s |amp_s| + |noise|) (efficiency <= 1):
    # only a block whose bound reaches float32's exact integer range is scanned (NumPy's sampler
    # itself rejects negative or NaN means)

    def block(b):
        rows = slice(edges[b], edges[b + 1])
        amp = np.asarray(patterns[rows], dtype=np.float64) @ weights
        amp_sum[rows] = amp.sum(axis=1)
        lam = expected_counts(amp, shifts, acq.code, acq.signal_per_pulse, noise_bin[rows],
                              acq.n_periods, code_matrix=code_matrix)
        lam = detector.detected_means(lam)
        if noiseless:
            totals[rows] = lam.sum(axis=1, dtype=np.float64)
        else:
            ceiling = acq.n_periods * (acq.signal_per_pulse * np.abs(amp).sum(axis=1)
                                       + np.abs(noise_bin[rows]))
            if not np.all(ceiling <= MAX_MEAN * 0.99):
                check_means(lam)
            # the counts overwrite their own means (NumPy draws from a float64 copy)
            totals[rows] = poisson_rows(lam, children[b], lam)
        corr[rows] = matched_filter(lam, replica, lags, gain, bank=bank)

    workers = min(simulation_threads(threads), n_blocks)
    blas_limit = single_threaded_blas() if workers > 1 else None
    if blas_limit is None:
        for b in range(n_blocks):
            block(b)
    else:
        with blas_limit, ThreadPoolExecutor(workers) as pool:
            list(pool.map(block, range(n_blocks)))
    return corr, totals, amp_sum


def _simulate_reference(patterns, weights, shifts, noise_bin, acq, detector, replica, lags, gain,
                        edges, children, noiseless):
    """Brute-force :func:`simulate_correlations` (``method='reference'``): slow, for tests."""
    m = patterns.shape[0]
    period = acq.period
    amp = np.asarray(patterns, dtype=np.float64) @ weights
    code_f = np.fft.rfft(np.asarray(acq.code, dtype=np.float64))
    rep_f = np.conj(np.fft.rfft(np.asarray(replica, dtype=np.float64)))
    corr = np.empty((m, lags.size), dtype=np.float32)
    totals = np.empty(m)
    for b in range(edges.size - 1):
        rows = slice(edges[b], edges[b + 1])
        # eq. (4): each pattern's return amplitude per delay bin, circularly convolved with the
        # code by FFT (its round-off, where the signal is exactly 0, set to 0)
        profile = np.zeros((rows.stop - rows.start, period))
        profile[:, shifts] = amp[rows]
        signal = np.fft.irfft(np.fft.rfft(profile, axis=1) * code_f, n=period, axis=1)
        signal[np.abs(signal) <= 1e-9 * np.abs(amp[rows]).sum(axis=1, keepdims=True)] = 0.0
        lam = acq.n_periods * (acq.signal_per_pulse * signal + noise_bin[rows, None])
        lam = detector.detected_means(lam)
        if not noiseless:
            check_means(lam)
        hist = lam if noiseless else children[b].poisson(lam).astype(np.float64)
        # C(tau) = sum_t h(t) f(t - tau) at every tau (eq. 5-6), then the gated lags
        full = np.fft.irfft(np.fft.rfft(hist, axis=1) * rep_f, n=period, axis=1)
        corr[edges[b]:edges[b + 1]] = full[:, np.mod(lags, period)] / gain
        totals[edges[b]:edges[b + 1]] = hist.sum(axis=1)
    return corr, totals, amp.sum(axis=1)


def noise_level(A, patterns: np.ndarray, sigma: np.ndarray, cfg: Config, rng) -> float:
    """RMS of ``A^H e_y`` for measurement noise ``e`` of the estimated per-pattern level,
    pushed through the same data preparation (centring / covariance) as the data.

    This is the noise that reaches the regulariser's prox in a gradient step; the default
    regularisation weight is a fixed multiple of it. It uses the measurements only (through
    ``sigma``), never the truth.
    """
    m = patterns.shape[0]
    e = rng.standard_normal((m, 4)) * sigma[:, None]
    if cfg.qcr and cfg.qcr_form == "centred":
        ey = centre(e) / np.sqrt(m)
    elif cfg.qcr:
        ey = centre(np.asarray(patterns, dtype=np.float64)).T @ centre(e) / m
    else:
        ey = e
    z = A.rmatvec(ey.astype(A.dtype))
    return float(np.sqrt(np.mean(np.asarray(z, dtype=np.float64) ** 2)))


def occupied_lags(corr: np.ndarray, sigma: np.ndarray, n_sigmas: float = AUTO_GATE_SIGMAS,
                  dilate: int = AUTO_GATE_DILATE) -> np.ndarray:
    """Automatic range gate: which delays hold a return, found before any reconstruction.

    The matched-filter output averaged over the patterns is ``mean_i C_i(tau) =
    sum_j mean(Phi_j) alpha_j w_j(tau)``: the scene's reflectivity-weighted depth histogram
    (plus a constant background). Delays where it rises more than ``n_sigmas`` standard
    deviations (of that mean, ``sqrt(mean sigma_i^2 / M)``) above its median are occupied; each
    is widened by ``dilate`` bins. Returns a boolean mask over the columns of ``corr``.
    """
    profile = np.asarray(corr, dtype=np.float64).mean(axis=0)
    noise = float(np.sqrt(np.mean(np.asarray(sigma) ** 2) / corr.shape[0]))
    base = float(np.median(profile))
    hit = profile - base > n_sigmas * max(noise, 1e-300)
    if not hit.any():
        hit[np.argmax(profile)] = True
    keep = hit.copy()
    for d in range(1, dilate + 1):
        keep[d:] |= hit[:-d]
        keep[:-d] |= hit[d:]
    return keep


def unique_lags(lags: np.ndarray, period: int) -> tuple[np.ndarray, np.ndarray]:
    """Distinct delays modulo the code period, and the map back to the gate's lags."""
    u, inv = np.unique(np.mod(lags, period), return_inverse=True)
    return u, inv


# -- the run -------------------------------------------------------------------------------------


#: config keys that change only the processing, not the simulated measurement
PROCESSING_KEYS = frozenset({
    "auto_gate", "qcr", "qcr_form", "solver", "regulariser", "lam", "lam_scale", "iterations",
    "tol", "subbin", "nonneg",
})


@dataclass
class Measurement:
    """A simulated acquisition: the matched-filter outputs of every pattern over the gate,
    and everything needed to reconstruct them (see :func:`measure`, :func:`reconstruct`)."""

    config: Config
    scene: Any
    acq: Acquisition
    gate: tuple[float, float]
    lags: np.ndarray  # absolute gated delays (bins)
    ulags: np.ndarray  # distinct delays modulo the code period
    inverse: np.ndarray  # lags -> index into ulags
    patterns: np.ndarray
    sim: dict[str, np.ndarray]
    probe_seed: np.random.SeedSequence
    warnings: list[str]
    timing: dict[str, float]


def _resolve(config, overrides) -> Config:
    if config is None:
        cfg = Config.from_dict(overrides)
    elif isinstance(config, Config):
        cfg = config.replace(**overrides) if overrides else config
    else:
        cfg = Config.from_dict({**dict(config), **overrides})
    cfg.validate()
    return cfg


def measure(config: Config | dict | None = None, **overrides) -> Measurement:
    """Simulate one acquisition: scene, code, patterns, photon counts and matched filter.

    The result can be reconstructed several times (other solvers, weights, with and without
    QCR) by :func:`reconstruct` without simulating again.
    """
    cfg = _resolve(config, overrides)
    timing: dict[str, float] = {}
    warns: list[str] = []

    t0 = time.perf_counter()
    scene = load_scene(cfg.scene, cfg.size, cfg.depth_min, cfg.depth_max)
    timing["scene"] = time.perf_counter() - t0

    t0 = time.perf_counter()
    ss = np.random.SeedSequence(cfg.seed)
    seq_code, seq_pat, seq_counts, seq_probe = ss.spawn(4)
    bin_width = 1.0 / cfg.bit_rate
    gate = cfg.range_gate if cfg.range_gate is not None else default_gate(scene, bin_width)
    acq = make_acquisition(cfg, gate, np.random.default_rng(seq_code))
    lags = gate_lags(gate, bin_width)
    ulags, inverse = unique_lags(lags, acq.period)
    if lags.size > acq.period:
        warns.append(
            f"range gate {gate[0]:g}-{gate[1]:g} m is longer than the "
            f"{acq.unambiguous_range:.3g} m unambiguous range of the {acq.description}: returns "
            f"at d and d + {acq.unambiguous_range:.3g} m are indistinguishable and the estimate "
            f"takes the nearest alias inside the gate")
    outside = (scene.depth < gate[0]) | (scene.depth > gate[1])
    if np.any(outside & scene.valid):
        warns.append(f"{int((outside & scene.valid).sum())} pixels lie outside the range gate "
                     f"{gate[0]:g}-{gate[1]:g} m: their returns alias into the gate or are lost")
    q = cfg.size * cfg.size
    m = n_patterns_for(cfg.compression, q)
    dtype = np.float32 if cfg.dtype == "float32" else np.float64
    patterns = make_patterns(cfg.patterns, m, q, np.random.default_rng(seq_pat),
                             sigma=cfg.pattern_sigma, dtype=dtype)
    timing["setup"] = time.perf_counter() - t0

    t0 = time.perf_counter()
    noise = NoiseModel(cfg.noise, tuple(cfg.noise_split), cfg.ambient, cfg.background_rate,
                       cfg.dark_count_rate)
    detector = PhotonCountingDetector(dead_time=cfg.dead_time)
    sim = simulate_correlations(patterns, scene, acq, ulags, noise, detector, cfg.pulse_width,
                                np.random.default_rng(seq_counts), noiseless=cfg.noiseless)
    pile = detector.pileup_report(float(np.mean(sim["counts"])) / acq.n_periods,
                                  acq.period * bin_width)
    sim["pileup"] = pile
    if pile["gmapd_saturated"]:
        warns.append(
            f"flux of {pile['counts_per_dead_time']:.3g} counts per {cfg.dead_time * 1e9:g} ns "
            f"dead time: a real GMAPD would saturate (the paper's linear counting model is "
            f"used)")
    timing["simulate"] = time.perf_counter() - t0
    return Measurement(cfg, scene, acq, gate, lags, ulags, inverse, patterns, sim, seq_probe,
                       warns, timing)


def reconstruct(meas: Measurement, **processing) -> Result:
    """Range gate, QCR, compressive reconstruction, ML depth and metrics of a measurement.

    Parameters
    ----------
    meas : Measurement
    **processing
        Processing keys to change from the measurement's config (``solver``, ``lam``,
        ``lam_scale``, ``qcr``, ``qcr_form``, ``regulariser``, ``iterations``, ``tol``,
        ``subbin``, ``nonneg``, ``auto_gate``); anything else would need a new simulation and
        is an error.
    """
    bad = set(k.replace("-", "_") for k in processing) - PROCESSING_KEYS
    if bad:
        raise ConfigError(f"reconstruct() cannot change {', '.join(sorted(bad))}: "
                          f"simulate again with measure()")
    cfg = meas.config.replace(**processing) if processing else meas.config
    timing = dict(meas.timing)
    warns = list(meas.warnings)
    scene, acq, sim, patterns = meas.scene, meas.acq, meas.sim, meas.patterns
    ulags, lags = meas.ulags, meas.lags
    bin_width = acq.bin_width
    bin_depth = SPEED_OF_LIGHT * bin_width / 2.0
    q = cfg.size * cfg.size
    dtype = np.float32 if cfg.dtype == "float32" else np.float64

    t0 = time.perf_counter()
    corr = sim["corr"]
    auto = cfg.auto_gate if cfg.auto_gate is not None else ulags.size > AUTO_GATE_MIN_SLICES
    keep = occupied_lags(corr, sim["sigma"]) if auto else np.ones(ulags.size, dtype=bool)
    corr = corr[:, keep]
    if cfg.qcr:
        A, y = qcr_problem(patterns, corr, cfg.qcr_form, dtype=dtype)
    else:
        A, y = plain_problem(patterns, corr, dtype=dtype)
    sigma_eff = noise_level(A, patterns, sim["sigma"], cfg, np.random.default_rng(meas.probe_seed))
    lam_scale = cfg.lam_scale if cfg.lam_scale is not None else DEFAULT_LAM_SCALE[cfg.solver]
    lam = cfg.lam if cfg.lam is not None else lam_scale * sigma_eff
    timing["qcr"] = time.perf_counter() - t0

    t0 = time.perf_counter()
    from .solvers import StopRule

    reg = build_regulariser(cfg, (cfg.size, cfg.size))
    solver_cls = load_solver(cfg.solver)
    stop = StopRule(max_iter=cfg.iterations or DEFAULT_ITERATIONS[cfg.solver], rtol=cfg.tol)
    x, info = solver_cls(stop=stop).solve(A, y, reg, lam)
    timing["solve"] = time.perf_counter() - t0
    if not cfg.qcr and info.stop_reason == "max_iter":
        warns.append(
            f"without QCR the problem is ill-conditioned (the patterns' mean dominates its "
            f"operator) and {cfg.solver} stopped at its cap of {stop.max_iter} iterations: the "
            f"estimate is not converged (FISTA needs ~1000-2000 at 64x64; --iterations)")

    t0 = time.perf_counter()
    full = np.zeros((q, ulags.size), dtype=np.asarray(x).dtype)
    full[:, keep] = x
    slices = full[:, meas.inverse]
    depth, _ = ml_depth(slices, lags, bin_width, cfg.pulse_width, subbin=cfg.subbin)
    depth = depth.reshape(cfg.size, cfg.size)
    timing["depth"] = time.perf_counter() - t0

    t0 = time.perf_counter()
    err = depth_errors(depth, scene.depth, scene.valid)
    edge_corr = edge_agreement(sobel_edges(depth), sobel_edges(scene.depth))
    timing["metrics"] = time.perf_counter() - t0
    timing["total"] = sum(timing.values())

    metrics: dict[str, Any] = {
        **err,
        "depth_rmse_bins": err["depth_rmse_m"] / bin_depth,
        "edge_correlation": edge_corr,
        "bin_depth_m": bin_depth,
        "unambiguous_range_m": acq.unambiguous_range,
        "range_gate_m": list(meas.gate),
        "n_slices": int(lags.size),
        "n_slices_solved": int(keep.sum()),
        "auto_gate": bool(auto),
        "n_patterns": int(patterns.shape[0]),
        "code_description": acq.description,
        "code_period_bins": acq.period,
        "code_ones": int(acq.code.sum()),
        "n_periods": acq.n_periods,
        "acquisition_time_per_pattern_s": acq.acquisition_time,
        "signal_per_pulse": acq.signal_per_pulse,
        "replica": acq.replica,
        "mean_signal_counts_per_pattern": float(np.mean(sim["signal_counts"])),
        "mean_noise_counts_per_pattern": float(np.mean(sim["noise_per_bin"]) * acq.period
                                               * acq.n_periods),
        "correlation_noise_sigma": float(np.sqrt(np.mean(sim["sigma"] ** 2))),
        "lam": lam,
        "lam_scale": lam_scale if cfg.lam is None else None,
        "noise_level": sigma_eff,
        "solver_info": dict(info.as_dict()),
        "detector": sim["pileup"],
        "warnings": warns,
        "timing_s": dict(timing),
        "config": cfg.to_dict(),
        "seed": cfg.seed,
        "version": __version__,
    }
    return Result(cfg, scene, depth, slices, lags, corr, metrics, timing, warns)


def run(config: Config | dict | None = None, **overrides) -> Result:
    """Simulate one acquisition and reconstruct it: ``reconstruct(measure(config))``.

    Parameters
    ----------
    config : Config or dict, optional
        The run's configuration (defaults: the paper's default experiment).
    **overrides
        Config keys to change, e.g. ``run(noise=5, solver='twist')``.

    Returns
    -------
    Result
    """
    return reconstruct(measure(config, **overrides))


#: measurements kept per process by :func:`run_shared` (most recently used first out last)
SHARED_MEASUREMENTS = 2
#: a measurement larger than this (patterns and correlations) is not kept
SHARED_MAX_BYTES = 256 * 2**20

_shared: OrderedDict[str, Measurement] = OrderedDict()
_shared_lock = threading.Lock()


def simulation_key(cfg: Config) -> str:
    """What identifies a simulated measurement: the config without its processing keys."""
    d = cfg.to_dict()
    for k in PROCESSING_KEYS:
        d.pop(k, None)
    return json.dumps(d, sort_keys=True, default=repr)


def _measurement_bytes(meas: Measurement) -> int:
    arrays = [meas.patterns, *(v for v in meas.sim.values() if isinstance(v, np.ndarray))]
    return int(sum(a.nbytes for a in arrays))


def run_shared(config: Config | dict | None = None, **overrides) -> Result:
    """:func:`run`, reusing this process's last measurements when only processing differs.

    Sweeps and reproductions compare solvers, weights or QCR on the same simulated data (a
    paired comparison: points that differ only in :data:`PROCESSING_KEYS` get the same seed
    there). The last :data:`SHARED_MEASUREMENTS` measurements are kept (thread-safe), so such
    points simulate once. The result is identical to ``run(config)``; its ``timing`` keeps the
    simulation time measured when the data were simulated, and ``metrics['measurement_reused']``
    says whether they were.
    """
    cfg = _resolve(config, overrides)
    key = simulation_key(cfg)
    with _shared_lock:
        meas = _shared.get(key)
        if meas is not None:
            _shared.move_to_end(key)
    reused = meas is not None
    if meas is None:
        meas = measure(cfg)
        if _measurement_bytes(meas) <= SHARED_MAX_BYTES:
            with _shared_lock:
                _shared[key] = meas
                while len(_shared) > SHARED_MEASUREMENTS:
                    _shared.popitem(last=False)
    result = reconstruct(meas, **{k: getattr(cfg, k) for k in PROCESSING_KEYS})
    result.metrics["measurement_reused"] = reused
    return result


def clear_shared() -> None:
    """Forget the measurements kept by :func:`run_shared`."""
    with _shared_lock:
        _shared.clear()


def run_metrics(params: dict) -> dict:
    """``run`` for sweeps (through :func:`run_shared`): a flat dict of the main metrics (no
    arrays)."""
    r = run_shared(params)
    m = r.metrics
    keep = ("depth_rmse_m", "depth_mae_m", "depth_bias_m", "missing_fraction",
            "edge_correlation", "n_patterns", "n_slices", "lam", "noise_level")
    out = {k: m[k] for k in keep}
    out["time_total_s"] = r.timing["total"]
    out["time_solve_s"] = r.timing["solve"]
    out["iterations"] = m["solver_info"]["iterations"]
    return out
