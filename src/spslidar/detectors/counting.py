"""The photon-counting detector: a Geiger-mode APD with a TDC, and the paper's noise terms.

Noise (eq. 4, 9): three additive Poisson processes per TDC bin,

* ``B1`` ambient light reflected by the scene. The paper adds it unmodulated as
  ``N^2 m_n^(1)`` per bin (``ambient='paper'``); physically it passes the DMD, so
  ``ambient='modulated'`` gives ``m_n^(1) sum_j Phi_ij alpha_j`` instead (it is then
  correlated with the patterns and QCR no longer removes it).
* ``B2`` sunlight / stray light reaching the detector, pattern-independent: ``N^2 m_n^(2)``.
* ``B3`` detector noise (dark counts): ``N^2 m_n^(3)``.

``m_n = m_n^(1) + m_n^(2) + m_n^(3)`` is the paper's single noise number, read (see
``docs/reading.md``) as mean noise counts per TDC bin *per pixel*, each term too, so that the
total per bin is ``N^2 m_n`` (eq. (9)-(10) as written put ``N^2`` on ``m_n^(1)`` alone: a
reading, not the paper's letter); ``noise_split`` divides it among the three terms. Physical rates
can be added on top: ``background_rate`` and ``dark_count_rate`` in counts per second.

The counting itself is the paper's linear model (no dead time): counts ~ Poisson(lambda) per
bin. A real GMAPD counts at most one photon per dead time, so :func:`pileup_report` flags runs
whose flux is far beyond what such a detector could record. The Poisson sampler is NumPy's; the
detector is written here because no library models a TDC histogram with these noise terms.
:func:`poisson_counts` draws in a fixed number of row blocks, each from its own child generator,
on a thread pool, so results depend only on the seed, not on the number of threads;
:func:`poisson_rows` is the single-block kernel the pipeline runs on its own thread pool.

Every TDC bin gets its own Poisson draw: no cheaper sampler is exact. The pipeline needs the
joint distribution of the matched-filter outputs at all gated lags (and of each pattern's total
count); bin ``t`` enters them with the weight vector ``(f(t - tau_1), ..., f(t - tau_K), 1)``,
and for an m-sequence of degree ``n`` every window of ``K >= n`` consecutive replica values
occurs once per period, so no two bins share a weight vector and no group of bins can be merged
into one Poisson draw. Nor are there signal-free bins to shortcut: with more than ``n``
consecutive occupied delay bins, every bin holds some return (an m-sequence has no run of
``n`` zeros). Drawing one lag's output as the difference of two Poisson totals is exact for that
lag alone, but not jointly (it loses the ``-lambda`` covariance between lags and the
correlation with the total count), so it is not used.
"""

from __future__ import annotations

import os
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..arrays import real_scalar
from ..constants import MAX_COUNT_MEAN
from ..errors import ConfigError

AMBIENT_MODELS = ("paper", "modulated")
#: row blocks for the Poisson draws (fixed, so results do not depend on the thread count)
N_BLOCKS = 8
#: largest mean counts per bin: counts are returned as float32, exact integers up to 2^24
MAX_MEAN = MAX_COUNT_MEAN
#: photons per dead time beyond which a GMAPD, even with its pile-up corrected, no longer
#: works (the README's 1-10): the linear counter's report calls such a flux saturating
GMAPD_WORKING_FLUX = 10.0


@dataclass
class NoiseModel:
    """The paper's three noise terms (eq. 4, 9).

    Parameters
    ----------
    m_n : float
        Total mean noise counts per TDC bin per pixel (the paper's ``m_n``).
    split : tuple of 3 floats
        Shares of ``m_n`` for ambient (B1), background (B2) and dark counts (B3); sums to 1.
    ambient : {'paper', 'modulated'}
        How B1 enters (see module docstring).
    background_rate, dark_count_rate : float
        Extra background and dark counts in counts per second (physical units), added on top;
        finite and non-negative.

    Raises
    ------
    ConfigError
        For a value that is not a number (text, a bool), or is out of its range, naming it.
    """

    m_n: float = 10.0
    split: tuple[float, float, float] = (1 / 3, 1 / 3, 1 / 3)
    ambient: str = "paper"
    background_rate: float = 0.0
    dark_count_rate: float = 0.0

    def __post_init__(self):
        # (m_n="1" failed in np.isfinite, naming nothing; NaN and infinite rates were taken:
        # an outside audit of the Python API)
        if not np.isfinite(real_scalar(self.m_n, "noise (m_n)")) or self.m_n < 0:
            raise ConfigError(f"noise (m_n) must be a non-negative number, got {self.m_n}")
        if np.ndim(self.split) != 1 or np.size(self.split) != 3:
            raise ConfigError(f"noise_split must be three non-negative shares summing to 1, "
                              f"got {self.split!r}")
        s = np.array([real_scalar(v, "noise_split") for v in self.split], dtype=float)
        if np.any(s < 0) or not np.isclose(s.sum(), 1.0):
            raise ConfigError(f"noise_split must be three non-negative shares summing to 1, "
                              f"got {list(self.split)}")
        if self.ambient not in AMBIENT_MODELS:
            raise ConfigError(f"unknown ambient model {self.ambient!r}; choose paper or modulated")
        for key in ("background_rate", "dark_count_rate"):
            rate = real_scalar(getattr(self, key), key)
            if not (np.isfinite(rate) and rate >= 0):
                raise ConfigError(f"{key} must be a finite, non-negative number of counts per "
                                  f"second, got {getattr(self, key)!r}")

    def per_bin(self, patterns: Any, reflectivity: np.ndarray,
                bin_width: float, modulation: np.ndarray | None = None) -> np.ndarray:
        """Noise counts per TDC bin for each pattern (one code period), shape ``(M,)``.

        ``patterns``: the ``(M, Q)`` pattern operator or matrix. ``modulation``: the
        patterns' products with the reflectivity, ``Phi alpha`` (``(M,)``), where the caller
        computes them (patterns on a device); default computed here. Only the ``modulated``
        ambient light uses them.

        Notes
        -----
        Eq. (9): ``N^2 m_n^(1) + m_n^(2) + m_n^(3)`` with each term per pixel (so x N^2).

        Raises
        ------
        ConfigError
            For a ``bin_width`` that is not a positive finite number of seconds (-1e-3 gave
            -1000 counts per bin at 1e6 counts per second: an outside audit).
        """
        width = real_scalar(bin_width, "bin_width")
        if not (np.isfinite(width) and width > 0):
            raise ConfigError(f"bin_width must be a positive time in seconds, got {bin_width!r}")
        m, q = patterns.shape
        f1, f2, f3 = (float(v) for v in self.split)
        base = q * self.m_n * (f2 + f3) + (self.background_rate + self.dark_count_rate) * bin_width
        if self.ambient == "paper":
            return np.full(m, base + q * self.m_n * f1)
        if modulation is None:
            from ..patterns import as_patterns

            a = np.asarray(reflectivity, dtype=np.float64).ravel()
            modulation = as_patterns(patterns, copy=False).apply_rows(slice(0, m), a[:, None])[:, 0]
        return base + self.m_n * f1 * modulation


def _threads() -> int:
    return max(1, min(N_BLOCKS, os.cpu_count() or 1))


def too_many_counts(per_bin: float) -> str:
    """The one-line refusal of a run whose expected counts per TDC bin exceed what a float32
    count holds exactly (:data:`MAX_MEAN`)."""
    return (f"about {per_bin:.3g} expected photons per TDC bin exceed the {MAX_MEAN:.3g} a "
            f"count holds exactly: lower --signal, --noise or --periods (a real detector "
            f"saturates at about one count per dead time)")


def check_rates(lam, what: str = "lam (a detector's expected photons per bin)") -> None:
    """A detector's expected photons per bin (or its counts): finite and non-negative, or one
    :class:`~spslidar.errors.ConfigError` (a ``ValueError``) naming ``what`` (NaN read "lam
    value too large" from NumPy's sampler, and a GMAPD took negative means: an audit of
    2026-11-29; its ``expected`` took 13-30 s to return negative or NaN means: an audit of
    the Python API). Two reductions, as :func:`check_means` reads its means (whose bound on
    float32 counts a GMAPD's flux does not have)."""
    a = np.asarray(lam)
    # NaN fails every comparison, so the two reductions check finiteness and sign at once
    if a.size and not (a.min() >= 0 and a.max() < np.inf):
        raise ConfigError(f"{what} must be finite and non-negative")


def check_means(lam: np.ndarray) -> None:
    """Raise ``ValueError`` unless all Poisson means are finite, non-negative and small enough
    for float32 counts (exact integers up to 2^24 per bin; a
    :class:`~spslidar.errors.ConfigError`, one line for the user, when too large).

    Parameters
    ----------
    lam : ndarray
        Means per bin (any shape and float dtype).
    """
    lam = np.asarray(lam)
    if not lam.size:
        return
    lo, hi = lam.min(), lam.max()
    # NaN fails every comparison, so two reductions check finiteness and sign at once
    if hi == np.inf and lo >= 0:  # finite inputs whose product overflowed: too many counts
        raise ConfigError(too_many_counts(float(hi)))
    if not (lo >= 0 and hi < np.inf):
        raise ValueError("Poisson means must be finite and non-negative")
    if hi > MAX_MEAN:
        raise ConfigError(too_many_counts(float(hi)))


def _streams(rng: np.random.Generator, n_rows: int) -> list[tuple[slice, np.random.Generator]]:
    """The fixed split of ``n_rows`` rows into random streams: ``N_BLOCKS`` children of
    ``rng`` (or ``rng`` itself for fewer rows), whatever the number of threads."""
    if n_rows < N_BLOCKS:
        return [(slice(0, n_rows), rng)]
    children = rng.spawn(N_BLOCKS)
    edges = np.linspace(0, n_rows, N_BLOCKS + 1).astype(int)
    return [(slice(edges[b], edges[b + 1]), children[b]) for b in range(N_BLOCKS)]


def poisson_rows(lam: np.ndarray, rng: np.random.Generator, out: np.ndarray) -> np.ndarray:
    """Draw ``Poisson(lam)`` per bin into ``out``; return each row's exact total count.

    The same counts as ``poisson_counts(lam, rng)`` (the same split into random streams), in
    the calling thread.

    Parameters
    ----------
    lam : ndarray, shape (B, L)
        Means (float32 or float64; NumPy's sampler works on a float64 copy either way, so
        ``out`` may be ``lam`` itself). Not checked: see :func:`check_means`.
    rng : numpy.random.Generator
    out : ndarray, shape (B, L)
        Receives the counts (float32 is exact below 2^24).

    Returns
    -------
    ndarray of int64, shape (B,)
        ``sum_t counts[b, t]``.

    Notes
    -----
    The kernel that :func:`spslidar.pipeline.simulate_correlations` runs on its thread pool
    (NumPy's Poisson sampler releases the GIL).
    """
    totals = np.empty(lam.shape[0], dtype=np.int64)
    for sl, gen in _streams(rng, lam.shape[0]):
        counts = gen.poisson(lam[sl])
        out[sl] = counts
        totals[sl] = counts.sum(axis=1)
    return totals


def poisson_counts(lam: np.ndarray, rng: np.random.Generator | int | None,
                   parallel: bool = True) -> np.ndarray:
    """Draw Poisson counts with means ``lam`` (any shape, rows split in fixed blocks): the
    photon counts of the detected rate of eq. (4).

    Returns float32 counts (exact integers up to 2^24 per bin; a bin with more raises).
    """
    from ..randomness import as_generator

    rng = as_generator(rng)
    lam = np.asarray(lam, dtype=np.float64)
    check_means(lam)
    out = np.empty(lam.shape, dtype=np.float32)
    if lam.ndim == 0:
        out[...] = rng.poisson(lam)
        return out
    streams = _streams(rng, lam.shape[0])

    def work(b):
        sl, gen = streams[b]
        out[sl] = gen.poisson(lam[sl])

    if parallel and len(streams) > 1 and _threads() > 1:
        with ThreadPoolExecutor(_threads()) as ex:
            list(ex.map(work, range(len(streams))))
    else:
        for b in range(len(streams)):
            work(b)
    return out


@dataclass
class PhotonCountingDetector:
    """GMAPD + TDC in the paper's linear (no dead time) photon-counting model.

    Parameters
    ----------
    dead_time : float
        Dead time in seconds, used only to flag pile-up (:meth:`pileup_report`).
    efficiency : float
        Photon detection efficiency in (0, 1]; scales the mean counts (1: the paper's model,
        which folds all losses into ``m_s``).
    """

    dead_time: float = 50e-9
    efficiency: float = 1.0

    def __post_init__(self):
        # (efficiency="0.5" failed in a comparison naming nothing: an outside audit)
        if not np.isfinite(real_scalar(self.dead_time, "dead_time")) or not self.dead_time >= 0:
            raise ConfigError(f"dead_time must be a finite, non-negative time in seconds, got "
                              f"{self.dead_time!r}")
        if not 0 < real_scalar(self.efficiency, "efficiency") <= 1:
            raise ConfigError(f"efficiency must be in (0, 1], got {self.efficiency!r}")

    def count(self, lam: np.ndarray, rng, parallel: bool = True) -> np.ndarray:
        """Photon counts per bin: Poisson(efficiency * lam)."""
        return poisson_counts(self.detected_means(lam), rng, parallel=parallel)

    def detected_means(self, lam: np.ndarray) -> np.ndarray:
        """Mean counts per bin after the detection efficiency.

        Parameters
        ----------
        lam : ndarray
            Mean photons per bin reaching the detector.

        Returns
        -------
        ndarray
            ``efficiency * lam`` (``lam`` itself when the efficiency is 1).
        """
        check_rates(lam)
        if self.efficiency != 1.0:
            lam = self.efficiency * np.asarray(lam)
        return lam

    def pileup_report(self, counts_per_period: float, period_s: float) -> dict:
        """Mean detections per dead time, and whether a real GMAPD would saturate.

        Parameters
        ----------
        counts_per_period : float
            Mean total counts per pattern per code period.
        period_s : float
            Code period in seconds.

        Notes
        -----
        The linear model is the paper's, and at its photon levels a real GMAPD would almost
        always saturate, so this is said once, in ``metrics.json`` (``note``), not as a
        warning on every run; ``--detector gmapd`` models the dead time.
        """
        rate = counts_per_period / period_s
        per_dead = rate * self.dead_time
        report = {
            "count_rate_hz": float(rate),
            "counts_per_dead_time": float(per_dead),
            # (past the 1-10 photons per dead time a GMAPD works at with its pile-up
            # corrected; it fired at 0.1, where one loses about a tenth of its counts: an
            # outside physics audit)
            "gmapd_saturated": bool(per_dead > GMAPD_WORKING_FLUX),
        }
        if report["gmapd_saturated"]:
            report["note"] = (
                f"flux of {per_dead:.3g} counts per {self.dead_time * 1e9:g} ns dead time: a "
                f"real GMAPD would saturate, recording at most one per dead time (it works "
                f"at 1-{GMAPD_WORKING_FLUX:g} with its pile-up corrected; the paper's linear "
                f"counting model is used; --detector gmapd models the dead time)")
        elif per_dead > 0.1:
            report["note"] = (
                f"flux of {per_dead:.3g} counts per {self.dead_time * 1e9:g} ns dead time: a "
                f"real GMAPD would lose {100 * per_dead / (1 + per_dead):.0f} % of them to "
                f"its dead time, which the linear counting model leaves out (--detector "
                f"gmapd models it)")
        return report
