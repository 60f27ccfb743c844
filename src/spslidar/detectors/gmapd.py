"""A free-running Geiger-mode APD: dead time, timing jitter, afterpulsing, dark counts.

:class:`GMAPD` implements the detector stage's contract
(:class:`~spslidar.detectors.base.DetectorModel`). Its fast path is the stationary renewal
(Markov-chain) model of Rapp, Ma, Dawson & Goyal, "Dead time compensation for high-flux
ranging", IEEE Trans. Signal Process. 67(13), 2019, for a periodic flux and a detector that
re-arms after its dead time regardless of code-period boundaries
(:func:`~spslidar.detectors.pileup.renewal_detection`; the equations are in that module's
docstring). :func:`~spslidar.detectors.events.simulate_events` is the photon-by-photon
reference it is tested against.

Counts (``detect``). Each row's detections are drawn one by one as the renewal process they
are (:func:`~spslidar.detectors.sampling.renewal_counts`: from each re-arming, the first
avalanche of the jittered periodic flux, afterpulses competing), so the counts carry the dead
time's correlations: at most one detection per dead time, a total-count Fano factor below 1.
Until 2026-11-29 each bin was drawn on its own as ``Binomial(n, q_t)``, which has the right
mean and per-bin variance but not those correlations, and the pile-up correction (D7), which
divides each bin by the armed fraction its preceding dead time's counts estimate, turned that
into a matched-filter peak 45 % high with 4 times the spread at 3.5 photons per dead time and
100 periods (against the photon-by-photon reference
:func:`~spslidar.detectors.events.simulate_events`; now within its spread). Long dwells are
scaled from fewer periods (see that module).

Written here because no maintained library models a free-running GMAPD under a periodic
flux (SciPy supplies the IRF's CDF and the FFT).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from ..arrays import real_array, real_scalar
from ..errors import ConfigError
from .base import DetectorModel, check_periods, means_block
from .counting import check_rates
from .jitter import convolve_periodic, jitter_kernel
from .pileup import auto_oversample, coates_correction, renewal_detection

__all__ = ["GMAPD"]

#: largest rows x bins x sub-bins solved at once (memory: ~15 float64 arrays of this size)
MAX_BLOCK = 2**21
#: float64 arrays of (dead time + period) bins per row the renewal model keeps (its history
#: and the Anderson acceleration's states; measured: 840 MB for 16 rows of 116 383 bins),
#: for its memory check
MODEL_ARRAYS = 48
#: mean incident photons per TDC bin and period (the brightest pattern's code period) above
#: which a simulation is refused, when that is also over :data:`SATURATED_PER_DEAD_TIME` per
#: dead time: the detector then fires in the first bin after nearly every re-arm, so its
#: histograms hold almost no timing information, and the renewal model, sub-binned 16-fold
#: and short of its fixed point after 200 sweeps, takes minutes to hours to say so (the paper's
#: defaults, 1.4e6 photons per 50 ns dead time: over 5 min for 16x16, 64 patterns; 2.9 photons
#: per bin: 37 s; 0.29: 3.7 s)
SATURATED_FLUX_PER_BIN = 1.0
#: the second condition of the refusal: a dead time of a few bins at a few photons per bin
#: is a synchronous detector's regime, which the Coates correction inverts
SATURATED_PER_DEAD_TIME = 100.0


#: the fields that are numbers (``oversample`` too, where it is not None)
_NUMBERS = ("dead_time", "bin_width", "efficiency", "dark_count_rate", "jitter", "jitter_tail",
            "jitter_tail_weight", "afterpulse_prob", "afterpulse_delay", "tol")
#: the words ``correction`` takes besides a bool (``--pileup-correction``'s)
_SWITCH = {"on": True, "true": True, "off": False, "false": False}


def _check(ok: bool, message: str) -> None:
    if not ok:
        raise ConfigError(message)


def _switch(value: Any, what: str) -> bool:
    """``value`` as a bool where it is one (Python's or NumPy's, kept as given) or one of the
    words ``on``, ``off``, ``true``, ``false`` in any case (the command line's
    ``--pileup-correction`` takes ``on`` / ``off``); else a one-line ConfigError naming
    ``what`` (``correction="no"`` was truthy, so the correction stayed on: an outside
    audit)."""
    if isinstance(value, bool | np.bool_):
        return value
    if isinstance(value, str) and value.lower() in _SWITCH:
        return _SWITCH[value.lower()]
    raise ConfigError(f"{what} must be True or False (or 'on' / 'off'), got {value!r}")


@dataclass
class GMAPD(DetectorModel):
    """Free-running, non-paralysable Geiger-mode APD with a TDC.

    Parameters
    ----------
    dead_time : float
        Non-paralysable dead time (s); 0 or at least ``bin_width``.
    bin_width : float
        TDC bin width (s).
    efficiency : float
        Photon detection efficiency, in (0, 1].
    dark_count_rate : float
        Dark counts per second (not jittered).
    jitter : float
        Standard deviation of the Gaussian timing jitter (s).
    jitter_tail, jitter_tail_weight : float
        Mean (s) and weight in [0, 1] of the IRF's exponential (diffusion) tail: with
        probability ``jitter_tail_weight`` a photon's jitter is Gaussian plus ``Exp(tail)``.
    afterpulse_prob : float
        Probability in [0, 1) that an avalanche fills a trap, which empties after an
        ``Exp(afterpulse_delay)`` delay counted from re-arming and causes an afterpulse if
        the detector is still armed (at low flux, ``afterpulse_prob`` is the fraction of
        detections followed by an afterpulse).
    afterpulse_delay : float
        Mean afterpulse delay after re-arming (s); > 0 when ``afterpulse_prob > 0``.
    oversample : int, optional
        Sub-bins per TDC bin for the renewal model (default: chosen from the largest flux
        per bin by :func:`~spslidar.detectors.pileup.auto_oversample`; 1 unless a bin gets
        more than 0.15 photon per period).
    tol : float
        Relative tolerance of the renewal fixed point.
    correction : bool or {'on', 'off', 'true', 'false'}
        Correct each histogram for pile-up before the matched filter (:meth:`correct`;
        ``--pileup-correction``); without it the distorted counts go on as measured. A word
        is read as ``--pileup-correction`` reads it, in any case; anything else is refused.

    Raises
    ------
    ConfigError
        For a parameter that is not a number (text, a bool), or is out of its range, naming
        it.

    Examples
    --------
    A 1 ns (10-bin) dead time under 0.5 photon per bin and period, over 100 periods:
    the detector fires about once per 10 + 2 bins, far below the 50 photons per bin.

    >>> import numpy as np
    >>> from spslidar.detectors.gmapd import GMAPD
    >>> det = GMAPD(dead_time=1e-9, bin_width=100e-12)
    >>> lam = np.full((4, 127), 50.0)  # photons per bin over the 100 periods
    >>> counts, totals = det.detect(lam, np.random.default_rng(0), n_periods=100)
    >>> counts.shape, counts.dtype
    ((4, 127), dtype('float32'))
    >>> expected = det.expected(lam, n_periods=100)
    >>> round(float(expected.mean()), 2)  # 100 periods / 12 bins
    8.33
    >>> bool(abs(counts.mean() / expected.mean() - 1) < 0.05)
    True
    """

    dead_time: float = 50e-9
    bin_width: float = 100e-12
    efficiency: float = 1.0
    dark_count_rate: float = 0.0
    jitter: float = 0.0
    jitter_tail: float = 0.0
    jitter_tail_weight: float = 0.0
    afterpulse_prob: float = 0.0
    afterpulse_delay: float = 0.0
    oversample: int | None = None
    tol: float = 1e-10
    correction: bool = True

    name = "gmapd"
    linear = False

    def __post_init__(self):
        # (bin_width="1e-10" failed in np.isfinite, naming nothing: an outside audit)
        for key in _NUMBERS + (("oversample",) if self.oversample is not None else ()):
            real_scalar(getattr(self, key), key)
        self.correction = _switch(self.correction, "correction")
        _check(np.isfinite(self.bin_width) and self.bin_width > 0,
               f"bin_width must be a positive time in seconds, got {self.bin_width}")
        _check(np.isfinite(self.dead_time) and self.dead_time >= 0,
               f"dead_time must be a non-negative time in seconds, got {self.dead_time}")
        _check(self.dead_time == 0 or self.dead_bins >= 1,
               f"dead_time ({self.dead_time} s) must be 0 or at least one TDC bin "
               f"({self.bin_width} s)")
        _check(0 < self.efficiency <= 1,
               f"efficiency must be in (0, 1], got {self.efficiency}")
        _check(np.isfinite(self.dark_count_rate) and self.dark_count_rate >= 0,
               f"dark_count_rate must be non-negative (counts/s), got {self.dark_count_rate}")
        for key in ("jitter", "jitter_tail", "afterpulse_delay"):
            val = getattr(self, key)
            _check(np.isfinite(val) and val >= 0, f"{key} must be a non-negative time in "
                   f"seconds, got {val}")
        _check(0 <= self.jitter_tail_weight <= 1,
               f"jitter_tail_weight must be in [0, 1], got {self.jitter_tail_weight}")
        _check(0 <= self.afterpulse_prob < 1,
               f"afterpulse_prob must be in [0, 1), got {self.afterpulse_prob}")
        _check(self.afterpulse_prob == 0 or self.afterpulse_delay > 0,
               "afterpulse_delay must be positive when afterpulse_prob > 0")
        _check(self.oversample is None or (int(self.oversample) == self.oversample
                                           and 1 <= self.oversample <= 64),
               f"oversample must be None or an integer in [1, 64], got {self.oversample}")
        _check(self.tol > 0, f"tol must be positive, got {self.tol}")

    # ------------------------------------------------------------------ units and the flux

    @property
    def dead_bins(self) -> float:
        """Dead time in TDC bins (rounded to an integer when within 1e-9 of one)."""
        d = self.dead_time / self.bin_width
        return float(round(d)) if abs(d - round(d)) < 1e-9 else d

    def _ap_rate(self) -> float:
        return self.bin_width / self.afterpulse_delay if self.afterpulse_prob else 0.0

    def flux(self, lam: np.ndarray, n_periods: int = 1, sub: int = 1) -> np.ndarray:
        """Avalanche-causing events per (sub-)bin per period before dead time, float64:
        ``efficiency * (IRF (*) lam) / n_periods + dark_count_rate * bin_width``, circular
        convolution with :func:`~spslidar.detectors.jitter.jitter_kernel`.

        Parameters
        ----------
        lam : ndarray, shape (B, L)
            Expected photons per bin over ``n_periods`` periods (uniform within a bin).
        n_periods : int
        sub : int
            Sub-bins per bin: the result has shape ``(B, L * sub)``.
        """
        lam = np.atleast_2d(np.asarray(lam, dtype=np.float64))
        if sub > 1:
            lam = np.repeat(lam / sub, sub, axis=1)
        width = self.bin_width / sub
        kern = jitter_kernel(lam.shape[1], self.jitter / width, self.jitter_tail / width,
                             self.jitter_tail_weight)
        mu = convolve_periodic(lam, kern) * (self.efficiency / n_periods)
        if self.dark_count_rate:
            mu = mu + self.dark_count_rate * width
        return mu

    def detection_probability(self, lam: np.ndarray, n_periods: int = 1) -> np.ndarray:
        """``q_t``: mean detections per bin per period (steady state), float64 (B, L).

        Parameters
        ----------
        lam : ndarray, shape (B, L) or (L,)
            Expected photons per bin over ``n_periods`` periods: finite and non-negative.
        n_periods : int
            Code periods accumulated: a positive number.

        Raises
        ------
        ConfigError
            For ``lam`` or ``n_periods`` out of range, at once, as :meth:`detect` refuses
            them (negative or NaN means, -1 or 0 periods ran the model for 13-30 s and
            returned negative or NaN means, or divided by zero: an outside audit).
        """
        return self._model(self._means(lam, n_periods), n_periods)[0]

    @staticmethod
    def _means(lam: Any, n_periods: Any) -> np.ndarray:
        """``lam`` as float64 ``(B, L)`` means (a row: one pattern's), checked as
        :meth:`detect` checks them, and ``n_periods`` checked (one line for either)."""
        check_periods(n_periods)
        arr = real_array(lam, "lam")
        if arr.ndim > 2:
            raise ConfigError(f"lam must be (B, L) means, one row per pattern, got shape "
                              f"{arr.shape}")
        arr = np.atleast_2d(arr.astype(np.float64, copy=False))
        check_rates(arr)
        return arr

    def _model(self, lam: np.ndarray, n_periods: int):
        """:meth:`detection_probability` of the float64 ``(B, L)`` ``lam``, with the flux per
        bin and each row's sub-bins it was solved with (:meth:`detect` draws from them)."""
        mu = self.flux(lam, n_periods)
        n_rows, period = lam.shape
        self._check_flux(mu)
        # each row sub-binned as its own flux needs: a batch sub-binned for its brightest row
        # was slower (64 rows at 0.01-100 photons per dead time) and its dim rows differed
        # from themselves alone
        subs = self._subs(mu)
        q = np.empty((n_rows, period))
        for sub in np.unique(subs):
            rows = np.flatnonzero(subs == sub)
            step = rows.size if sub == 1 else max(1, MAX_BLOCK // (period * sub))
            self._check_model_memory(min(rows.size, step), period, int(sub))
            args = (self.afterpulse_prob, self._ap_rate() / sub)
            if sub == 1:
                q[rows] = renewal_detection(mu[rows], self.dead_bins, *args, tol=self.tol)
                continue
            for i in range(0, rows.size, step):
                part = rows[i : i + step]
                fine = renewal_detection(self.flux(lam[part], n_periods, sub),
                                         self.dead_bins * sub, *args, tol=self.tol)
                q[part] = fine.reshape(-1, period, sub).sum(axis=2)
        return q, mu, subs

    def _check_model_memory(self, rows: int, period: int, sub: int) -> None:
        """Refuse, in one line, a dead time whose renewal model would not fit in memory: it
        keeps about ``MODEL_ARRAYS`` float64 arrays of the dead time plus a period per
        row (``--dead-time 1e-4``, a million bins, ended in a MemoryError traceback after
        3.3 GB: an outside audit of 2026-11-29)."""
        from ..machine import _gb, available_memory

        need = MODEL_ARRAYS * 8.0 * rows * (self.dead_bins + period) * sub
        if need > 0.8 * available_memory():
            raise ConfigError(
                f"--dead-time {self.dead_time:g} s is {self.dead_bins:.4g} TDC bins "
                f"({self.dead_bins / period:.3g} code periods): the dead-time model would hold "
                f"about {_gb(need)} for {rows} pattern(s) at a time, more than the "
                f"{_gb(available_memory())} available; a GMAPD's dead time is usually "
                f"10-100 ns")

    def _subs(self, mu: np.ndarray) -> np.ndarray:
        """Sub-bins per TDC bin of each row of the flux ``mu`` (B, L): ``oversample``, or as
        each row's own flux needs (a batch sub-binned for its brightest row was slower, 64
        rows at 0.01-100 photons per dead time, and its dim rows differed from themselves
        alone)."""
        if self.oversample:
            return np.full(mu.shape[0], int(self.oversample))
        return np.array([auto_oversample(float(m)) for m in mu.max(axis=1, initial=0.0)],
                        dtype=np.int64)

    def check_flux(self, lam: np.ndarray, n_periods: int = 1) -> None:
        """:meth:`_check_flux` of the means ``lam`` (the detector base's hook; ``lam`` and
        ``n_periods`` checked as :meth:`detection_probability` checks them)."""
        self._check_flux(self.flux(self._means(lam, n_periods), n_periods))

    def _check_flux(self, mu: np.ndarray) -> None:
        """Refuse a flux that saturates the detector beyond use (:data:`SATURATED_FLUX_PER_BIN`
        and :data:`SATURATED_PER_DEAD_TIME`), in one line that says by how much to lower it."""
        if self.dead_bins < 1 or mu.size == 0:
            return
        per_bin = float(mu.mean(axis=1).max())
        per_dead = per_bin * self.dead_bins
        if not (per_bin > SATURATED_FLUX_PER_BIN and per_dead > SATURATED_PER_DEAD_TIME):
            return
        raise ConfigError(
            f"--detector gmapd at {per_dead:.3g} incident photons per "
            f"{self.dead_time * 1e9:.3g} ns dead time ({per_bin:.3g} per TDC bin, the brightest "
            f"pattern's mean): it would fire in the first bin after nearly every re-arm, so its "
            f"histograms would hold almost no timing information (and the dead-time model "
            f"would take minutes to hours to say so); a GMAPD works at about 1-10 photons per "
            f"dead time: lower --signal and --noise by a factor of about "
            f"{per_dead / 3:.2g} and raise --periods to keep the photons")

    # -------------------------------------------------------------------------- contract

    def expected(self, lam: np.ndarray, n_periods: int = 1) -> np.ndarray:
        """Mean detected counts per bin over ``n_periods`` periods, ``n_periods * q_t``.

        ``lam`` (B, L) is accumulated over the ``n_periods`` periods (the contract of
        :class:`~spslidar.detectors.base.DetectorModel`); both are checked as
        :meth:`detection_probability` checks them."""
        return n_periods * self.detection_probability(lam, n_periods)

    def variance(self, lam: np.ndarray, n_periods: int = 1) -> np.ndarray:
        """Per-bin variance of a bin's counts when successive periods are independent,
        ``n q (1 - q)`` (a sum of ``n`` Bernoulli detections; the real detector's differs
        where the period is shorter than the dead time's memory: 1.08-1.16 times this at a
        period of 3.2 dead times and 8 photons per dead time, an audit's event-level reference
        of 2026-11-29; nothing in the chain reads it). ``lam`` and ``n_periods`` are checked
        as :meth:`detection_probability` checks them."""
        q = self.detection_probability(lam, n_periods)
        if self.dead_bins == 0:
            return n_periods * q
        return n_periods * q * (1.0 - q)

    def detect(self, lam: np.ndarray, rng: np.random.Generator, n_periods: int = 1,
               out: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        """Detected counts, drawn detection by detection with the dead time's correlations
        (:func:`~spslidar.detectors.sampling.renewal_counts`; Poisson without dead time).

        Parameters
        ----------
        lam : ndarray, shape (B, L)
            Expected photons per bin reaching the detector over the ``n_periods`` periods.
        rng : numpy.random.Generator
        n_periods : int
        out : ndarray, shape (B, L), optional
            Receives the counts (may be ``lam``).

        Returns
        -------
        counts : ndarray, shape (B, L)
            float32 unless ``out`` says otherwise.
        totals : ndarray of float64, shape (B,)
        """
        from ..randomness import as_generator

        rng = as_generator(rng)
        # (the dead-time sampler draws whole periods of lam / n_periods each)
        check_periods(n_periods, whole=bool(self.dead_bins))
        lam = means_block(lam).astype(np.float64, copy=False)
        check_rates(lam)
        q, mu, subs = self._model(lam, n_periods)
        if self.dead_bins == 0:
            counts = rng.poisson(n_periods * q)
        else:
            from .sampling import renewal_counts

            counts = np.empty(q.shape)
            for sub in np.unique(subs):
                rows = np.flatnonzero(subs == sub)
                step = max(1, MAX_BLOCK // (lam.shape[1] * int(sub)))
                for i in range(0, rows.size, step):
                    part = rows[i : i + step]
                    fine = mu[part] if sub == 1 else self.flux(lam[part], n_periods, int(sub))
                    counts[part] = renewal_counts(
                        fine, self.dead_bins * sub,
                        int(n_periods), n_periods * q[part], rng, self.afterpulse_prob,
                        self.afterpulse_delay / self.bin_width * sub, int(sub))
        if out is None:
            out = np.empty(q.shape, dtype=np.float32)
        out[...] = counts.reshape(out.shape)
        # (float: a long dwell's counts, scaled from fewer periods, are not whole numbers)
        return out, np.asarray(counts, dtype=np.float64).sum(axis=1)

    def correct(self, counts: np.ndarray, n_periods: int = 1,
                expected: bool = False) -> np.ndarray:
        """Pile-up corrected histograms: the generalised Coates estimate of
        ``n_periods * flux`` (:func:`~spslidar.detectors.pileup.coates_correction`), i.e. what
        a detector without dead time or afterpulses would have counted (dark counts
        included, jitter not undone). Where the model is sub-binned (high flux), the flux
        within a bin is taken as uniform, or as linear when the jitter is at least half a bin
        wide (:func:`~spslidar.detectors.pileup.sub_bin_profile`). ``expected``: ``counts`` is
        :meth:`expected`'s histogram (a noiseless run), inverted without the bounds that
        apply to counts (at one period they zeroed every bin).

        Raises
        ------
        ConfigError
            For ``counts`` that are not finite and non-negative, or an ``n_periods`` that is
            not a positive number (negative counts were corrected to zeros, 0 periods was a
            ZeroDivisionError and -5 was taken: an outside audit), with or without the
            correction.
        """
        check_periods(n_periods)
        check_rates(real_array(counts, "counts"), "counts (detections per bin)")
        if not self.correction:
            return counts
        smooth = max(self.jitter, self.jitter_tail * (self.jitter_tail_weight > 0))
        return coates_correction(counts, n_periods, self.dead_bins, self.afterpulse_prob,
                                 self.afterpulse_delay / self.bin_width, self.oversample,
                                 "linear" if smooth >= 0.5 * self.bin_width else "uniform",
                                 expected=expected)

    def noise_totals(self, counts: np.ndarray, totals: np.ndarray, n_periods: int = 1,
                     corrected: np.ndarray | None = None) -> np.ndarray:
        """Sum over bins of the corrected histogram's variance, by the delta method:
        ``Var(n mu_hat_t) ~= n (e^{mu_t} - 1) / alpha_t`` (Coates with ``alpha_t n`` armed
        periods, binomial counts), estimated from the measurement and bounded by
        ``(n mu_t)^2 + n mu_t`` (saturated bins); the counts themselves without dead time.
        ``corrected`` is :meth:`correct` of ``counts`` where the caller has it already."""
        if self.dead_bins == 0 or not self.correction:
            return np.asarray(totals, dtype=np.float64)
        c = np.atleast_2d(np.asarray(counts, dtype=np.float64))
        fixed = self.correct(c, n_periods) if corrected is None else corrected
        # (|mu|: counts less their expected afterpulses may read a little below 0)
        mu = np.abs(np.atleast_2d(np.asarray(fixed, dtype=np.float64))) / n_periods
        armed = np.clip(c / n_periods / np.maximum(-np.expm1(-mu), 1e-300), 0.0, 1.0)
        var = n_periods * np.expm1(np.minimum(mu, 700.0)) / np.maximum(armed, 1e-300)
        # a bin that (nearly) saturated carries almost no information, but its corrected value
        # is pinned near its cap (coates_correction), so its error is at most of the order of
        # that value: without this bound one such bin would set the weight of every slice
        var = np.minimum(var, (n_periods * mu) ** 2 + n_periods * mu)
        return np.where(c > 0, var, 0.0).sum(axis=1)

    def notes(self) -> list[str]:
        """What to say of this detector's settings before it counts (a GMAPD without a
        dead time counts linearly)."""
        if self.dead_time == 0:
            return ["--dead-time 0: this GMAPD never goes dead, so it counts linearly (no "
                    "pile-up to correct); its jitter and afterpulses still apply"]
        return []

    def report(self, counts_per_period: float, period_s: float,
               pulsed: bool = False, incident_per_period: float | None = None
               ) -> dict[str, Any]:
        """Detected rate, detections per dead time, the fraction of time dead, and the
        incident photons per dead time: the simulation's own where it gives them
        (``incident_per_period``), else read back from the detections as a steady flux's,
        ``n = r / (1 - r)`` (which reads a pulsed flux low)."""
        rate = counts_per_period / period_s
        per_dead = float(rate * self.dead_time)
        out = {"model": self.name, "count_rate_hz": float(rate),
               "counts_per_dead_time": per_dead, "dead_fraction": float(min(per_dead, 1.0))}
        if self.dead_time > 0 and incident_per_period is not None:
            # (the conventional lidar's pulse period, 1392 bins at the default gate, is longer
            # than twice the 500-bin dead time: its detector fires up to 3 times a period, on
            # the background, so -ln(1 - detections per pulse) read 0.84 for 0.88 photons per
            # dead time and warned of saturation on every run, an outside audit of
            # 2026-11-29; the simulation knows what arrived)
            out["incident_per_dead_time"] = float(incident_per_period / period_s
                                                  * self.dead_time)
            if pulsed:
                out["incident_per_pulse"] = float(incident_per_period)
                out["detections_per_pulse"] = float(counts_per_period)
        elif self.dead_time > 0 and per_dead < 1.0:
            # the non-paralysable count rate n / (1 + n) per dead time, inverted (dark
            # counts and afterpulses included)
            out["incident_per_dead_time"] = per_dead / (1.0 - per_dead)
        return out

    def notes_after(self, report: dict[str, Any], noiseless: bool = False) -> list[str]:
        """What to say once the counts are known: a detector saturated past reading a flux
        from its counts (``noiseless`` is kept for the callers: nothing said depends on it
        now)."""
        if self.dead_time and "incident_per_dead_time" not in report:
            # (said "at inf incident photons per dead time")
            return [f"the detector is saturated: {report['counts_per_dead_time']:.3g} detections "
                    f"per dead time, where a non-paralysable detector makes at most 1 (a long "
                    f"dwell's counts, scaled from fewer periods, can pass it): no incident "
                    f"flux can be read from them and the pile-up correction has nothing to "
                    f"invert; lower --signal and --noise (and raise --periods)"]
        # (a warning that the correction amplifies the counting noise more than it mends
        # above 10 photons per dead time was withdrawn on 2026-11-29: it was measured on
        # counts drawn bin by bin, without the dead time's correlations, 1.5-3.8 times the
        # uncorrected RMSE at 30; drawn as a detector records them, 0.02-1.20 at 30 and
        # 0.04-0.79 at 100, six built-in scenes)
        return []
