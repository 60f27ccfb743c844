"""The detector stage's contract: expected photons per TDC bin in, detected counts out.

The simulation (``spslidar.pipeline.simulate``) computes, for a block of patterns, the expected
number of photons per TDC bin reaching the detector over one pattern's acquisition (``n_periods``
code periods, signal plus the noise terms of eq. 9) and hands them to the detector model. The
model returns the detected-count histogram and each row's total; it also says what the matched
filter needs to know about the noise of its histograms (the effective count behind each
pattern's matched-filter variance) and, where the model is not linear, corrects its histograms
(pile-up) before the matched filter. Models are registered in :data:`spslidar.detectors.DETECTORS`.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from ..arrays import real_array, real_number
from ..errors import ConfigError

__all__ = ["DetectorModel", "check_periods", "checked_detect"]


def check_periods(n_periods: Any, whole: bool = False) -> None:
    """Refuse, in one :class:`~spslidar.errors.ConfigError` naming it, an ``n_periods`` that
    is not a positive finite number of code periods (with ``whole``, a whole one): what
    every detector model's :meth:`~DetectorModel.detect`, :meth:`~DetectorModel.expected`
    and pile-up correction take.

    0 was a ZeroDivisionError, -1 a silent negative histogram after a long computation, and
    ``"2"`` a NumPy ufunc error naming nothing (audits of 2026-11-29 and of the Python API);
    half a period is a differential frame's, without dead time, so fractions pass unless
    ``whole`` (a detector with a dead time draws whole periods: 1.5 periods gave 68 % of the
    expected counts, half a period none).
    """
    x = real_number(n_periods)
    if x is None or not (np.isfinite(x) and x > 0):
        raise ConfigError(f"n_periods must be a positive number of code periods, got "
                          f"{n_periods!r}")
    if whole and not x.is_integer():
        raise ConfigError(f"a GMAPD with a dead time draws whole code periods: n_periods "
                          f"must be a whole number, got {n_periods!r}")


def means_block(lam: Any) -> np.ndarray:
    """``lam`` as the real ``(B, L)`` means a model's :meth:`DetectorModel.detect` draws
    from, or one line: a 1-D row was taken by one model and refused by the other, a complex
    one crashed in numpy's cast (an audit of 2026-11-29)."""
    if np.ndim(lam) != 2:
        raise ValueError(f"lam must be (B, L) means, one row per pattern, got shape "
                         f"{np.shape(lam)}")
    return real_array(lam, "lam")


class DetectorModel:
    """Base class of detector models.

    Subclasses set ``name`` and implement :meth:`detect` and :meth:`expected`.
    """

    name = "base"
    #: whether the detected mean is proportional to the incident mean (no pile-up)
    linear = True

    def detect(self, lam: np.ndarray, rng: np.random.Generator, n_periods: int = 1,
               out: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        """Detected counts per bin.

        Parameters
        ----------
        lam : ndarray, shape (B, L)
            Expected photons per TDC bin reaching the detector, accumulated over the
            ``n_periods`` code periods of one pattern (``lam / n_periods`` per period).
        rng : numpy.random.Generator
            The block's own random stream.
        n_periods : int
            Code periods accumulated per pattern.
        out : ndarray, shape (B, L), optional
            Receives the counts (may be ``lam`` itself).

        Returns
        -------
        counts : ndarray, shape (B, L)
            Detected counts (``out`` when given).
        totals : ndarray, shape (B,)
            Each row's total count.
        """
        raise NotImplementedError  # pragma: no cover - abstract

    def expected(self, lam: np.ndarray, n_periods: int = 1) -> np.ndarray:
        """Mean detected counts per bin (the noiseless limit of :meth:`detect`)."""
        raise NotImplementedError  # pragma: no cover - abstract

    def check_flux(self, lam: np.ndarray, n_periods: int = 1) -> None:
        """Refuse (one line, :class:`~spslidar.errors.ConfigError`) means ``lam`` whose flux
        the model cannot work at, before any work on them; nothing for a model without such
        a limit. :meth:`detect` makes the same check."""

    def correct(self, counts: np.ndarray, n_periods: int = 1,
                expected: bool = False) -> np.ndarray:
        """Histograms as the matched filter should see them (pile-up corrected); the identity
        for a linear model. ``expected``: ``counts`` are expected values (a noiseless run),
        not counts, so no bound that holds for counts applies."""
        return counts

    def noise_totals(self, counts: np.ndarray, totals: np.ndarray, n_periods: int = 1,
                     corrected: np.ndarray | None = None) -> np.ndarray:
        """Per pattern, the sum over bins of the count variance of the (corrected) histogram,
        estimated from the measurement: what the matched-filter noise level is built from.
        For Poisson counts it is the total count itself. ``corrected``: :meth:`correct` of
        ``counts``, where the caller has computed it (saves a second correction)."""
        return totals

    def report(self, counts_per_period: float, period_s: float,
               pulsed: bool = False, incident_per_period: float | None = None
               ) -> dict[str, Any]:
        """Numbers for ``metrics.json`` (e.g. detections per dead time); ``pulsed``: the
        period holds one short pulse (the conventional lidar), not a code's spread flux;
        ``incident_per_period``: the photons that reached the detector per period (mean over
        the patterns), where the simulation knows them. (A model whose ``report`` does not
        take that keyword is called without it.)"""
        return {"model": self.name}

    def notes(self) -> list[str]:
        """What a user should hear about this model's settings (legal but suspicious ones),
        said as warnings by the run."""
        return []

    def notes_after(self, report: dict[str, Any], noiseless: bool = False) -> list[str]:
        """What a user should hear once the counts are known (``report`` is :meth:`report`'s
        dict; ``noiseless``: the histograms are expected values, without counting noise),
        said as warnings by the run."""
        return []


def model_words(detector) -> str:
    """A detector model as its one-line refusals name it: ``'gmapd' (GMAPD)``, its registered
    name and its class."""
    return f"{getattr(detector, 'name', '?')!r} ({type(detector).__name__})"


def checked_detect(detector, lam, rng, n_periods: int, out=None) -> tuple:
    """``detector.detect(...)``'s ``(counts, totals)``, or a one-line ConfigError naming the
    model where it returns anything else (a plugin's counts alone ended in "too many values
    to unpack", a traceback: an outside audit of 2026-12-01). The host and the device
    paths both call it."""
    got = detector.detect(lam, rng, n_periods, out=out)
    if not (isinstance(got, (tuple, list)) and len(got) == 2):
        name = model_words(detector)
        what = (f"a {len(got)}-tuple" if isinstance(got, tuple) else
                f"an array of shape {np.shape(got)}" if hasattr(got, "shape") else
                type(got).__name__)
        raise ConfigError(f"the detector model {name} returned {what} from its detect(), "
                          f"where (counts, totals) is expected")
    return got
