"""Calibrating a real instrument: its system delay and instrument response (IRF), measured
from an acquisition of a flat target at a known distance, and removed in ``reconstruct``.

``spslidar calibrate`` (:func:`calibrate_ptu`): every pattern's histogram is summed (the
patterns add up over the pixels, so whatever the patterns, the sum is the flat target's
response times the code), the code is deconvolved (Wiener, in the Fourier domain of one code
period: exact for an m-sequence, whose spectrum is flat, and regularised for codes with weak
frequencies), and the flat response ``g`` is left, one pulse wide plus the IRF, on a constant
background (removed by its median). With the target's true delay ``tau_D = 2 D / (c dt)``:

* the **system delay** is the time of the peak of ``g`` less the target's round trip and
  the pulse's half width, ``p + (1 - pulse_width) / 2 - tau_D`` bins, with ``p`` the maximum
  of the band-limited interpolant of ``g`` (:func:`_peak`: below a tenth of a bin where the
  IRF is wider than a bin); like every delay it is known modulo the code period ``L``;
* the **IRF** is ``g`` on whole bins about its peak bin, background-free (samples under three
  noise standard deviations dropped), normalised to unit sum. No fractional resampling (a
  response a bin or two wide rings when shifted by part of a bin): the whole bins the
  target's delay misses are ``lag_shift``, the rest ``lag_fraction``.

``spslidar reconstruct --calibration CAL.json``
(:func:`~spslidar.pipeline.calibrated.calibrated_filter`) then correlates
each histogram with the replica convolved with that IRF (the matched filter of eq. 5-6 for
the measured response, the best signal-to-noise ratio for a return of that shape) at the
gated lags plus ``lag_shift``, and reads the depths at the gated lags plus
``lag_fraction``: the range gate stays in true metres and the system delay is gone. The
gain is set so that a return's response sums to its strength over the three lags about its
peak (the reflectivity reads as an ideal instrument's), and the signal in the background
estimate is counted once however many lags the response spans.

An IRF wider than a bin costs signal-to-noise ratio however it is filtered: a return spread
over the IRF matches the filter by ``||IRF||_2`` (0.47 for 1.5 bins FWHM and a 4-bin tail
of weight 0.3) where an ideal instrument's matches by about 0.9, so a calibrated acquisition
reaches the ideal instrument's depth error with about ``(0.9 / 0.47)^2 = 3.7`` times its
photons, not with the same.
"""

from __future__ import annotations

import os
import warnings
from pathlib import Path
from typing import Any

import numpy as np

from ..constants import SPEED_OF_LIGHT
from ..errors import ConfigError
from ..outwrite import sha256_file  # one file hasher for the project
from .calibrated import (  # noqa: F401  (re-exported: they were here until 0.2)
    HALF_WIDTH_SHARE,
    IRF_AFTER,
    IRF_BEFORE,
    RESPONSE_HALF,
    WEAK_RESPONSE,
    WIENER_REG,
    CalibratedFilter,
    _vertex,
    calibrated_filter,
    code_response,
    delay_filter,
    refine_depth,
)
from .calibration_file import (  # noqa: F401  (re-exported: the calibration's file)
    CAL_KIND,
    check_calibration,
    check_calibration_out,
    code_bits,
    code_sha256,
    content_sha256,
    edited,
    load_calibration,
    write_calibration,
)

__all__ = ["calibrate_ptu", "measure_response"]

#: bins past the IRF's window that its noise is read over (and that :func:`_tail_end` checks
#: hold no response)
NOISE_AFTER = 3 * IRF_BEFORE - 1
#: the IRF's samples below this many noise standard deviations are set to zero
IRF_FLOOR_SIGMA = 3.0


#: upsampling of the response (band-limited) to find its peak below a bin
UPSAMPLE = 64


def _peak(g: np.ndarray, p0: int) -> float:
    """Sub-bin position of the maximum of ``g`` near bin ``p0``: the band-limited
    (trigonometric) interpolant of ``g`` on a grid of ``1 / UPSAMPLE`` bin, refined by a
    parabola through its three highest points."""
    period = g.size
    fine = np.fft.irfft(np.fft.rfft(g), period * UPSAMPLE) * UPSAMPLE
    idx = (p0 * UPSAMPLE + np.arange(-UPSAMPLE, UPSAMPLE + 1)) % fine.size
    k = int(np.argmax(fine[idx]))
    k = min(max(k, 1), idx.size - 2)
    frac = float(_vertex(fine[idx[k - 1]], fine[idx[k]], fine[idx[k + 1]]))
    return p0 + (k - UPSAMPLE + float(np.clip(frac, -1.0, 1.0))) / UPSAMPLE


#: a response whose top (above half its maximum) spans more than this many bins has its peak
#: found on the response smoothed over a quarter of that width (:func:`_top`)
WIDE_TOP_BINS = 6


def _top(g: np.ndarray) -> tuple[int, np.ndarray]:
    """The bin of the response's peak and the response its sub-bin peak is read on
    (:func:`_peak`): its largest bin and itself, or, where its top spans more than
    :data:`WIDE_TOP_BINS`, those of the response smoothed by a Gaussian of a quarter of the
    top's width (circularly). On a wide top the noise moves the largest bin
    by several bins: a Gaussian IRF of 25 bins FWHM at 0.57 M photons gave delays of
    2.99-3.53 ns for 3.30 over eight seeds, and reconstructions of the calibration's own
    wall 45 mm off (an audit of 2026-11-29). Smoothing moves a symmetric peak nowhere and a
    skewed one towards its tail, by far less than the noise did on such a top."""
    p0 = int(np.argmax(g))
    half = 0.5 * g[p0]
    period = g.size
    width = 1
    for step in (1, -1):
        k = 1
        while k < period // 2 and g[(p0 + step * k) % period] >= half:
            k += 1
        width += k - 1
    if width <= WIDE_TOP_BINS:
        return p0, g
    sigma = width / 4.0
    f = np.fft.rfftfreq(period)
    smooth = np.fft.irfft(np.fft.rfft(g) * np.exp(-2.0 * (np.pi * sigma * f) ** 2), period)
    near = (p0 + np.arange(-width, width + 1)) % period
    return int(near[np.argmax(smooth[near])]), smooth


#: the farthest calibration target taken, metres (1000 km: no lidar's, yet a number)
MAX_DISTANCE_M = 1e6


def _real_scalar(value: Any, what: str, unit: str) -> float:
    """``value`` as a float where it is one real number (not text, a bool, an array or a
    complex number), or one line naming ``what`` and its ``unit``."""
    if (isinstance(value, (bool, np.bool_, str, bytes)) or np.ndim(value) != 0
            or np.iscomplexobj(value)):
        raise ConfigError(f"{what} must be a number of {unit}, got {value!r}")
    try:
        return float(value)
    except (TypeError, ValueError):
        raise ConfigError(f"{what} must be a number of {unit}, got {value!r}") from None


def _check_distance(distance: Any) -> float:
    """The calibration target's distance as a float of metres in ``[0, MAX_DISTANCE_M]``, or
    one line (:class:`ConfigError`) that says the range taken."""
    d = _real_scalar(distance, "--distance", "metres")
    if not (np.isfinite(d) and 0.0 <= d <= MAX_DISTANCE_M):
        raise ConfigError(f"--distance must be a distance in metres in [0, "
                          f"{MAX_DISTANCE_M:g}], got {d:g}")
    return d


def _check_pulse_width(pulse_width: Any) -> float:
    """The laser pulse's width as a float of bins in ``(0, 1]`` (``run``'s
    ``--pulse-width``), or one line (:class:`ConfigError`)."""
    w = _real_scalar(pulse_width, "pulse_width", "bins")
    if not (np.isfinite(w) and 0.0 < w <= 1.0):
        raise ConfigError(f"pulse_width must be the laser pulse's width in bins, in (0, 1] "
                          f"(as run's --pulse-width), got {w:g}")
    return w


def measure_response(hist: np.ndarray, code: np.ndarray, bin_width: float, distance: float,
                     pulse_width: float = 0.5, response: np.ndarray | None = None,
                     phase: float | None = None) -> dict[str, Any]:
    """System delay and IRF from the summed histogram of a flat target at ``distance``.

    Parameters
    ----------
    hist : ndarray, shape (L,)
        Counts per TDC bin of one code period, summed over every pattern.
    code : ndarray, shape (L,)
        Unipolar code bits.
    bin_width : float
        TDC bin width, seconds.
    distance : float
        The flat target's distance, metres (beyond the code's unambiguous range too: the
        delay is measured modulo the code period, as every return is).
    pulse_width : float
        Laser pulse width, bins.
    response : ndarray, shape (L,), optional
        The code-free response itself
        (:func:`~spslidar.pipeline.calibrated.code_response` of ``hist``), where it was
        found otherwise: a flat wall's, with its range spread removed
        (:func:`spslidar.pipeline.target.range_free_response`).
    phase : float, optional
        Where ``response`` was found with the pulse starting ``phase`` bins into the axis's
        bin (a response narrower than a bin, :data:`spslidar.pipeline.target.PHASES`): its
        peak bin holds the pulse's start, so the delay is read from there, not from the
        bin's centre.

    Returns
    -------
    dict
        ``delay_bins`` (sub-bin), ``delay_s``, ``lag_shift`` (int) and ``lag_fraction``
        (bins, in [-0.5, 0.5]), ``irf_offsets``, ``irf_values`` (sum 1, peak at offset 0),
        ``irf_fwhm_bins``, ``peak_to_noise``.

    Notes
    -----
    Bin ``k`` holds the photons of ``[k, k + 1)``: a response peaking at ``p`` (sub-bin,
    :func:`_peak`) is centred at ``p + 1/2``, a pulse of ``pulse_width`` bins starting at the
    target's delay ``tau_D`` at ``tau_D + pulse_width / 2``, so the delay is
    ``p + c0 - tau_D`` with ``c0 = (1 - pulse_width) / 2``. The IRF is kept on whole bins
    (a fractional resampling of a response a bin or two wide rings); what its peak bin
    ``p0`` misses of the true alignment is ``lag_fraction``, which ``reconstruct`` adds to
    the depths it reads.
    """
    h = np.asarray(hist, dtype=np.float64)
    c = np.asarray(code, dtype=np.float64)
    period = c.size
    if h.shape != (period,):
        raise ConfigError(f"the histogram has {h.size} bins, the code {period}")
    if h.sum() <= 0:
        raise ConfigError("the calibration acquisition holds no photons")
    distance = _check_distance(distance)
    pulse_width = _check_pulse_width(pulse_width)
    # a return is known modulo the code period: so are the target's delay and the system delay
    tau_d = (2.0 * distance / (SPEED_OF_LIGHT * bin_width)) % period
    g = code_response(h, c) if response is None else np.asarray(response, np.float64).copy()
    g -= np.median(g)  # the background is a constant
    p0, top = _top(g)
    before, cut_head = _head_start(g, p0)
    after, cut_tail = _tail_end(g, p0, before)
    broad = ""
    if cut_head or cut_tail:
        broad = (f"the calibration's response still stands above the background "
                 f"{before if cut_head else after} bins {'before' if cut_head else 'after'}"
                 f" its peak, where it is cut (about a quarter of the {period}-bin code "
                 f"period): a flat target's response is narrower (a fluorescence decay is "
                 f"not); check --bit-rate, the code and that the acquisition is a lidar's")
    side = np.r_[np.arange(p0 - before - 2 * IRF_BEFORE, p0 - before),
                 np.arange(p0 + after + 1, p0 + after + 1 + NOISE_AFTER)] % period
    noise = float(np.std(g[side])) if side.size else 0.0
    peak_to_noise = float(g[p0] / noise) if noise > 0 else float("inf")
    if not peak_to_noise > 5:
        # (a response spread over the period reads its noise inside itself: a fluorescence
        # decay 30 times its background was "no clear return ... acquire longer", an audit)
        raise ConfigError(broad or
                          f"no clear return in the calibration acquisition (peak "
                          f"{peak_to_noise:.2g} noise standard deviations): check --distance, "
                          f"--bit-rate and the code, or acquire longer")
    if broad:
        warnings.warn(broad, RuntimeWarning, stacklevel=2)
    if peak_to_noise < WEAK_RESPONSE:
        warnings.warn(f"the calibration's response stands {peak_to_noise:.3g} noise standard "
                      f"deviations high: its shape is read through the noise (at 5.1-5.6 an "
                      f"audit measured a 1.7-bin IRF with a tail as one bin, or with a noise "
                      f"spike 7 bins early holding 44 %, and calibrated maps 30-70 % worse); "
                      f"acquire the target longer", RuntimeWarning, stacklevel=2)
    _second_return(g, p0, noise, bin_width)
    c0 = (1.0 - pulse_width) / 2.0 if phase is None else float(phase)
    delay = (_peak(top, p0) + c0 - tau_d) % period
    if delay > period - 2:  # photons arrive late: a delay a hair below 0 is noise, not L
        delay -= period
    exact = p0 + c0 - tau_d  # the gated lag + lag_shift where a return at tau_D peaks
    lag_shift = int(np.floor(exact + 0.5))
    offsets = np.arange(-before, after + 1)
    values = g[(p0 + offsets) % period].copy()
    values[values < IRF_FLOOR_SIGMA * noise] = 0.0
    if values.sum() <= 0:  # pragma: no cover - guarded by the peak test above
        raise ConfigError("the measured response is empty")
    values /= values.sum()
    if np.count_nonzero(values >= UNRESOLVED_SHARE * values.max()) <= UNRESOLVED_BINS:
        values = _unresolved(values, offsets, bin_width)
    return {"delay_bins": float(delay), "delay_s": float(delay * bin_width),
            "lag_shift": lag_shift, "lag_fraction": float(lag_shift - exact),
            "irf_offsets": offsets.tolist(), "irf_values": values.tolist(),
            "irf_fwhm_bins": fwhm_bins(values), "peak_to_noise": peak_to_noise}


def _head_start(g: np.ndarray, p0: int) -> tuple[int, bool]:
    """Bins before the peak ``p0`` that the IRF is read over: :data:`IRF_BEFORE`, doubled
    while the response still stands above the background just before that (the mean of the
    ``2 IRF_BEFORE`` bins there more than 3 standard errors above the bins half a period from
    the peak), at most a quarter of the period. A Gaussian IRF of 25 bins FWHM (2.5 ns at
    10 GHz; a HydraHarp's 16 ps bins under a 400 ps response are as many) was cut at 8 bins,
    its noise read inside its own rising edge (5.35 deviations where 17 M photons stand
    thousands high), its FWHM said as 20.6 bins and the delay 0.84 bin early (an audit of
    2026-11-28); a response that has risen within 8 bins is read as before. Also whether the
    response still stood above the background where it was cut."""
    period = g.size
    start = IRF_BEFORE
    if period < 16 * IRF_BEFORE:  # no background half a period away that the response spares
        return start, False
    far = g[(p0 + period // 2 + np.arange(-IRF_BEFORE, IRF_BEFORE)) % period]
    error = 3.0 * float(np.std(far)) * np.sqrt(2.0 / far.size)

    def stands(n: int) -> bool:
        head = g[(p0 - n - 1 - np.arange(2 * IRF_BEFORE)) % period]
        return float(head.mean() - far.mean()) > error

    return _grow(start, stands, period // 4)


def _grow(n: int, stands, cap: int) -> tuple[int, bool]:
    """``n`` doubled while the response ``stands(n)`` beyond it and twice ``n`` is within
    ``cap``; and whether it still stood where it was cut there."""
    while stands(n):
        if 2 * n > cap:
            # (a short code's first window may reach past ``cap`` already: a response that
            # still stands there spreads over more than a quarter of the period too; a
            # fluorescence decay through a 132-bit pulse code, 770 counts 33 bins after a
            # 13 500 peak over a background of 30, was not said, an outside audit)
            return n, True
        n *= 2
    return n, False


def _tail_end(g: np.ndarray, p0: int, start: int = IRF_BEFORE) -> tuple[int, bool]:
    """Bins after the peak ``p0`` that the IRF is read over: :data:`IRF_AFTER`, doubled while
    the response still stands above the noise just past it (the mean of the next
    ``2 IRF_BEFORE`` bins more than 3 standard errors of the noise before the response,
    which starts ``start`` bins before its peak), at most a quarter of the period. A
    diffusion tail of 4 ns at 10 GHz holding 90 % of the response was cut at 40 bins, and
    every calibrated depth read 2.2 cm long (an audit of 2026-11-28); an IRF that has ended
    by 40 bins is read as before. Also whether the response still stood above the noise
    where it was cut."""
    period = g.size
    wide = NOISE_AFTER
    if IRF_AFTER + 1 + wide > period - start:
        # (the first window past the tail wraps onto the response itself: a narrow IRF
        # through a 63-bit code was said to be cut in every seed, a review)
        return IRF_AFTER, False
    before = g[np.arange(p0 - start - 2 * IRF_BEFORE, p0 - start) % period]
    # against the background before the peak, not against 0: the median taken off a weak
    # response's skewed noise leaves its mean above 0, which read as a tail to the end
    sd = float(np.std(before))
    error = 3.0 * sd * np.sqrt(2.0 / before.size)
    error_wide = 3.0 * sd * np.sqrt(1.0 / before.size + 1.0 / wide)

    def stands(n: int) -> bool:
        past = g[(p0 + n + 1 + np.arange(wide)) % period]
        # the first 2 IRF_BEFORE bins, or the whole span the noise is then read over (a
        # reflection 57-63 bins after the peak, half its height, lay beyond the first and
        # inside the second: read as noise, it called a 1 100-sigma response 11 sigma and
        # dropped a third of the IRF, an audit of 2026-11-29)
        return (float(past[:2 * IRF_BEFORE].mean() - before.mean()) > error
                or float(past.mean() - before.mean()) > error_wide)

    return _grow(IRF_AFTER, stands, period // 4)


#: a measured response with at most UNRESOLVED_BINS bins above UNRESOLVED_SHARE of its peak
#: is narrower than a bin (unresolved; noise passes the 3-sigma floor at ~0.4 % of the peak,
#: the benchmark's 1.5-bin jitter puts 3 bins above 20 % and its tail bins at 3-15 %)
UNRESOLVED_BINS = 2
UNRESOLVED_SHARE = 0.05


def _unresolved(values: np.ndarray, offsets: np.ndarray, bin_width: float) -> np.ndarray:
    """A response narrower than a bin, binned at one position of the target within a bin: its
    two bins' shares say where the wall fell, not what the instrument does, so it is taken as a
    delta (no IRF filter), with a warning. Found by an audit of calibrations: an instrument
    without jitter, calibrated on walls at 25.000 / 25.011 m, measured (0.36, 0.64) and (0.89,
    0.11) and made the calibrated depth map worse than the uncalibrated one (RMSE 0.067 / 0.054
    against 0.031 m; as a delta 0.032 / 0.032 m)."""
    main = values[values >= UNRESOLVED_SHARE * values.max()]
    shares = ", ".join(f"{v:.2f}" for v in main)
    warnings.warn(f"the measured response lies on {main.size} bin(s) ({shares}): "
                  f"the instrument's response is narrower than a {bin_width * 1e12:.4g} ps "
                  f"bin, so its shape is where the target fell within a bin; it is taken as "
                  f"one bin (no IRF filter), and the sub-bin delay is good to about a quarter "
                  f"of a bin", RuntimeWarning, stacklevel=3)
    out = np.zeros_like(values)
    out[offsets == 0] = 1.0
    return out


#: a local maximum of the calibration response beyond +-2 bins of its peak above this share of
#: the peak (and 5 noise deviations) is a second surface, not the instrument's response
SECOND_RETURN_SHARE = 0.1
#: ... and the response between them falls below this share of that maximum
VALLEY = 0.5


def _second_return(g: np.ndarray, p0: int, noise: float, bin_width: float) -> None:
    """Warn (one line) where the response ``g`` holds a second return: a local maximum more
    than 2 bins from the peak ``p0`` above :data:`SECOND_RETURN_SHARE` of it and 5 noise
    deviations. A flat target gives one peak and a tail that only falls; the steps scene
    (24.5-25.5 m) gave a delay 0.5 m off, read from its farthest plane, without a word."""
    n = g.size
    offset = (np.arange(n) - p0 + n // 2) % n - n // 2
    local = (g >= np.roll(g, 1)) & (g >= np.roll(g, -1))
    second = local & (np.abs(offset) > 2) & (g > max(SECOND_RETURN_SHARE * g[p0], 5 * noise))
    # and apart from the peak: the response falls below VALLEY of it on the way (a plateau, a
    # shoulder or a long tail's noise is the same return: an audit's flat wall through a box
    # IRF read "a second return ... 100 % of it", through a 90 % tail of 20 bins "19 %")
    for i in np.flatnonzero(second):
        path = (p0 + np.arange(0, offset[i], np.sign(offset[i]))) % n
        second[i] = g[path].min() < VALLEY * g[i]
    if second.any():
        i = int(np.flatnonzero(second)[np.argmax(g[second])])
        metres = offset[i] * bin_width * SPEED_OF_LIGHT / 2
        # (an instrument's own second peak, a reflection in a fibre or an afterpulse bump, is
        # the same in the data: it was called the target's alone, an audit)
        warnings.warn(f"the calibration's response holds a second return {metres:+.3g} m from "
                      f"the strongest ({100 * g[i] / g[p0]:.0f} % of it): a second surface of "
                      f"the target (a calibration wants one flat surface at --distance), or "
                      f"the instrument's own (a reflection, an afterpulse bump); the delay was "
                      f"read from the strongest return, and the IRF keeps what lies within its "
                      f"window", stacklevel=3)


def fwhm_bins(values: np.ndarray) -> float:
    """Full width at half maximum of a response sampled on whole bins, in bins: the half-
    maximum crossings on either side of the peak, each placed by linear interpolation
    between the last bin above half and the first below (one bin for a response in a single
    bin; a Gaussian integrated over the TDC's bins reads, from 3 bins' FWHM up, within 5 % of
    ``sqrt(FWHM**2 + 1)``, its width as the TDC sees it, and at 1.5 bins 1.5-2.2 as its centre
    moves across a bin). Counting the bins above half instead read 1 or 2 for that last
    response, whichever way its centre fell. Written by hand: ``scipy.signal.peak_widths``
    measures at half the peak's *prominence* over its lowest base, not at half its height
    (a response on a floor of 0.1 reads 1.69 bins there against 2.16 here), and gives a
    peak at the window's edge zero prominence and zero width."""
    v = np.asarray(values, dtype=np.float64)
    p = int(np.argmax(v))
    half = v[p] / 2.0
    left = p
    while left > 0 and v[left - 1] >= half:
        left -= 1
    right = p
    while right < v.size - 1 and v[right + 1] >= half:
        right += 1
    lo = left - 0.5 if left == 0 else left - (v[left] - half) / (v[left] - v[left - 1])
    hi = (right + 0.5 if right == v.size - 1
          else right + (v[right] - half) / (v[right] - v[right + 1]))
    return float(hi - lo)


def calibrate_ptu(ptu: str | os.PathLike, patterns: np.ndarray | str | os.PathLike,
                  code: np.ndarray | str | os.PathLike, bit_rate: float, distance: float, *,
                  marker: int = 1, channel: int | None = None, pulse_width: float = 0.5,
                  allow_binning: bool = False, target: str = "auto",
                  fov_deg: float | None = None, marker_edge: str = "start",
                  settle: float = 0.0, dead_time: float | None = None,
                  afterpulse_prob: float = 0.0,
                  afterpulse_delay: float = 0.0, repeats: int = 1,
                  sync_divider: int | None = None, sync_channel: int | None = None,
                  align_channels: bool = False, pattern_size: int | None = None,
                  first_pattern: int | str | None = None) -> dict[str, Any]:
    """The calibration (:func:`measure_response`) of a T3 PTU acquisition of a flat target
    (``patterns`` an array or the file or folder that holds them, as
    :func:`~spslidar.pipeline.real.load_patterns` reads it, ``pattern_size`` as
    :func:`~spslidar.pipeline.real.reconstruct_ptu`'s; ``code`` its bits or the file that
    holds them), with what it was measured from (file, hash, photons, patterns, bit rate,
    code; ``measured_from.inputs``: :func:`~spslidar.pipeline.inputs.input_record`);
    ``allow_binning``, ``marker_edge``, ``settle``, ``repeats``, ``sync_divider``,
    ``sync_channel``, ``align_channels`` (the shifts kept in the JSON's
    ``channel_shifts_bins``, which ``reconstruct`` applies), ``first_pattern`` (a
    free-running DMD: block ``b`` shows pattern ``(first_pattern + b) mod M``, any number of
    blocks, each pattern's summed; ``"auto"`` finds it) and the
    detector's ``dead_time`` and
    afterpulsing (each block's histogram corrected for pile-up before the response is read:
    uncorrected, a bright wall's response is read through the detector's dead time; the
    JSON's ``detector`` says which) as :func:`~spslidar.pipeline.real.reconstruct_ptu`.

    ``target`` says what the target's pixels see (:mod:`spslidar.pipeline.target`):
    ``range``, one range (the patterns' sum is read as it is); ``plane``, a flat wall at
    ``distance`` on the optical axis, whose range spread over the field of view ``fov_deg``
    (fitted where not given) and tilt is removed; ``auto`` (the default), the plane where the
    blocks' delays ask for one, else one range. The JSON's ``target`` says which and why.

    Every argument is checked before the file is read: a ``distance`` that is not a number
    of metres in ``[0, 1e6]``, a ``pulse_width`` outside ``(0, 1]`` bins, an
    ``allow_binning`` that is not a bool, an unknown ``target`` or a ``fov_deg`` outside
    ``(0, 180)`` degrees (or with ``target='range'``) raise a one-line
    :class:`~spslidar.errors.ConfigError`."""
    from ..version import __version__
    from .blocks import channels_read, check_repeats
    from .deadtime import dead_time_model
    from .free_run import check_first_pattern
    from .inputs import code_in, input_record
    from .real import (
        check_ptu_path,
        check_real_inputs,
        patterns_in,
    )

    if isinstance(ptu, (list, tuple)):  # (before the path check, which offers lists)
        raise ConfigError("calibrate reads one PTU file: a calibration is one acquisition of "
                          "the flat target")
    check_ptu_path(ptu)
    patterns_given, code_given = patterns, code
    patterns = patterns_in(patterns, pattern_size, distinct=False)
    repeats = check_repeats(repeats)
    first = check_first_pattern(first_pattern, int(patterns.shape[0]), repeats=repeats)
    code = code_in(code)
    inputs = input_record(patterns_given, patterns, pattern_size, code_given, code)
    check_real_inputs(bit_rate, (0.0, 1.0), int(patterns.shape[1]), int(patterns.shape[0]),
                      int(code.size), repeats)
    shown = patterns
    # every argument before the file is read, each in one line (a distance given as text
    # and a NaN pulse width were tracebacks, found by an audit)
    distance = _check_distance(distance)
    pulse_width = _check_pulse_width(pulse_width)
    if not isinstance(allow_binning, (bool, np.bool_)):
        raise ConfigError(f"allow_binning must be True or False, got {allow_binning!r}")
    fov = _check_target(target, fov_deg)
    bin_width = 1.0 / float(bit_rate)
    detector = dead_time_model(bin_width, dead_time, afterpulse_prob, afterpulse_delay)
    if fov is not None:  # a wall wider than the code's period: refused before the read too
        from .target import wall_offsets

        side = int(round(np.sqrt(patterns.shape[1])))
        wall_offsets((side, side), distance, fov, bin_width, int(code.size))
    from .rows import calibration_rows
    from .skew import check_align

    data, keep, patterns, hists, pile, drift, notes, first = calibration_rows(
        ptu, shown, code, bin_width, detector=detector, marker=marker, channel=channel,
        allow_binning=allow_binning, marker_edge=marker_edge, settle=settle, repeats=repeats,
        sync_divider=sync_divider, first=first, sync_channel=sync_channel,
        align_channels=check_align(align_channels))
    for note in notes:
        warnings.warn(note, stacklevel=2)
    total = hists.astype(np.float64).sum(axis=0)
    with warnings.catch_warnings(record=True) as said:  # kept in the file, and said again
        warnings.simplefilter("always")
        geometry, response = _target_geometry(hists, patterns, code, bin_width, distance,
                                              target, fov_deg, pulse_width)
        cal = measure_response(total, code, bin_width, distance, pulse_width,
                               response=response, phase=geometry.get("phase_bins"))
        from .calibrated import wide_response_note

        wide = wide_response_note(cal["irf_fwhm_bins"])
        if wide:  # (surfaces were lost through such responses without a word: an audit)
            warnings.warn(wide, stacklevel=2)
        merged = channels_read(data, channel) if channel is None else []
        if len(merged) > 1 and any("holds a second return" in str(w.message) for w in said):
            # (two detectors cabled 1.5 ns apart were told of a second surface or the
            # instrument's reflection, just after being told they were merged: an outside
            # lab audit of 2026-11-30)
            warnings.warn(f"the detector channels {', '.join(map(str, merged))} were merged "
                          f"here: the second return may be their cables' difference in delay, "
                          f"each channel's own return; calibrate each with --channel C and "
                          f"reconstruct it with its own calibration", stacklevel=2)
    for w in said:
        warnings.warn_explicit(w.message, w.category, w.filename, w.lineno)
    path = Path(ptu)
    return {"kind": CAL_KIND, "version": __version__, **cal, "target": geometry,
            # (reconstruct says them again: an audit's calibration read through the noise
            # made a map 25 times worse while reconstruct said nothing)
            "warnings": [str(w.message) for w in said],
            "bin_width_s": bin_width,
            "bit_rate_hz": float(bit_rate), "code_length": int(code.size),
            "code_sha256": code_sha256(code), "code_bits": code_bits(code),
            "channel_shifts_bins": {str(c): k for c, k in sorted(data.channel_shifts.items())},
            "pulse_width": float(pulse_width), "distance_m": float(distance),
            "detector": pile,
            "timing_drift_bins": None if drift is None else drift.bins,
            "measured_from": {"ptu": path.name, "bytes": path.stat().st_size,
                              "sha256": sha256_file(path),
                              "photons": int(data.counts_per_pattern[keep].sum()),
                              "photons_in_file": int(data.n_photons),
                              "patterns": int(patterns.shape[0]),
                              "repeats": repeats, "first_pattern": first,
                              "settle_s": float(settle),
                              # (the detector channels read: each has its own cable delay,
                              # and a calibration applied to another went unsaid, an audit)
                              "channel": None if channel is None else channels_read(data,
                                                                                    channel),
                              "channels": channels_read(data, channel),
                              "inputs": inputs}}


def _check_target(target: Any, fov_deg: Any) -> float | None:
    """``target`` (one of :data:`~spslidar.pipeline.target.TARGETS`) and ``fov_deg`` (None or
    degrees in (0, 180), not with ``range``) checked, in one line; the field of view as a
    float."""
    from ..products import check_fov
    from .target import TARGETS

    if not isinstance(target, str) or target not in TARGETS:
        raise ConfigError(f"--target must be one of {', '.join(TARGETS)}, got {target!r}")
    if fov_deg is not None:
        fov_deg = check_fov(fov_deg)
        if target == "range":
            raise ConfigError("--fov gives a flat wall's field of view: it does not go with "
                              "--target range")
    return fov_deg


def _target_geometry(hists: np.ndarray, patterns: np.ndarray, code: np.ndarray,
                     bin_width: float, distance: float, target: str, fov_deg: float | None,
                     pulse_width: float = 0.5) -> tuple[dict[str, Any], np.ndarray | None]:
    """What the calibration target's pixels see (:mod:`~spslidar.pipeline.target`): its
    geometry for the JSON, and the response of one range where it is a plane (else None:
    the patterns' sum is read)."""
    from .target import measure_geometry, one_range, range_free_response

    fov_deg = _check_target(target, fov_deg)
    distance = _check_distance(distance)
    if target == "range":
        geo = one_range("--target range")
        geo.pop("offsets")
        return geo, None
    n = int(round(np.sqrt(patterns.shape[1])))
    geo = measure_geometry(hists, patterns, code, bin_width, distance, (n, n), fov_deg, target,
                           pulse_width)
    offsets = geo.pop("offsets")
    if geo["model"] != "plane":
        return geo, None
    phase = geo.get("phase_bins")
    response = range_free_response(hists, patterns, code, offsets, phase=phase,
                                   width=pulse_width)
    band = geo.pop("spread_band", None)
    total = hists.astype(np.float64).sum(axis=0)

    def read(resp: np.ndarray | None, ph: float | None = None) -> dict[str, Any] | None:
        return _quiet_response(total, code, bin_width, distance, pulse_width, resp, ph)

    guard = target == "auto" and geo.get("z") is not None
    fitted = read(response, phase) if guard or band is not None else None
    if guard:
        one = read(None)
        plane, one = (0.0 if r is None else r["peak_to_noise"] for r in (fitted, one))
        if plane < WEAK_RESPONSE <= one:
            # a plane fitted where the data barely tell it, whose range-free response is read
            # through the noise while one range's stands clear, is not kept: 8 x 8 walls at
            # one range through 10- and 25-bin IRFs fitted planes at 1.04-1.1 deviations,
            # their responses 6-15 deviations high against 28-36, and two delays 1.1-1.2 ns
            # short (one range's: 0.07-0.23 ns off; a true 10 degree wall at 16 x 16 stands
            # 54-73 through its plane, outside audits of 2026-11-29)
            spread, z = geo["spread_bins"], geo["z"]
            warnings.warn(f"the calibration target may be a flat wall whose pixels spread over "
                          f"{spread:g} bins of round trip ({z:.2g} deviations), but its "
                          f"response with that spread removed stands only {plane:.3g} noise "
                          f"deviations high against {one:.3g} for one range: it was read as "
                          f"one range; if it is a flat wall facing the lidar, calibrate with "
                          f"--target plane --fov (your optics' field of view)",
                          RuntimeWarning, stacklevel=3)
            why = (f"one range: the plane fitted ({spread:g} bins, {z:.2g} deviations) leaves "
                   f"a response {plane:.3g} deviations high, one range's {one:.3g}")
            geo = one_range(why, z)
            geo.pop("offsets")
            return geo, None
    if band is not None and fitted is not None:
        ends = [read(range_free_response(hists, patterns, code, off, width=pulse_width))
                for _, _, off in band]
        _delay_band(fitted["delay_bins"],
                    [float("nan") if e is None else e["delay_bins"] for e in ends], band,
                    bin_width, geo)
    return geo, response


#: a delay that moves by more than this many bins over the spreads a calibration cannot tell
#: apart is said (:func:`_delay_band`)
DELAY_BAND_BINS = 0.25


def _delay_band(fitted: float, ends: list[float], band: tuple, bin_width: float,
                geo: dict[str, Any]) -> None:
    """The delay ``fitted`` (bins) against ``ends``, the delays read through the two ends of
    the spreads the data cannot tell from the fitted one (``band``: ``(spread, fov,
    offsets)`` twice, from :func:`~spslidar.pipeline.target.measure_geometry`; NaN where
    none was read): kept in ``geo`` (``spread_band_bins``, ``delay_band_s``), and said where
    the delay moves by more than :data:`DELAY_BAND_BINS` over them: how far the fitted
    spread's uncertainty reaches the delay, which the fit's deviations alone do not tell (a
    10-bin IRF's 25 m wall at 1.2 deviations read 1.1 bins late, one at 3.4 deviations 0.7
    bin early, and a sharp wall at 2.4 deviations right; outside audits and a review of
    2026-11-29)."""
    (lo, fov_lo, _), (hi, fov_hi, _) = band
    geo["spread_band_bins"] = [round(float(lo), 4), round(float(hi), 4)]
    geo["delay_band_s"] = [round(d * bin_width, 15) if np.isfinite(d) else None for d in ends]
    moved = max((abs(d - fitted) for d in ends if np.isfinite(d)), default=0.0)
    if moved > DELAY_BAND_BINS:
        reads = " and ".join(f"{d * bin_width * 1e9:.4g} ns" for d in ends if np.isfinite(d))
        warnings.warn(f"the calibration's data cannot tell the wall's spread between {lo:g} and "
                      f"{hi:g} bins of round trip (fields of view {fov_lo:.3g}-{fov_hi:.3g} "
                      f"degrees), over which its delay reads {reads} against "
                      f"{fitted * bin_width * 1e9:.4g} ns fitted ({moved:.2g} bins apart): give "
                      f"your optics' field of view with --fov", RuntimeWarning, stacklevel=4)


def _quiet_response(total: np.ndarray, code: np.ndarray, bin_width: float, distance: float,
                    pulse_width: float, response: np.ndarray | None,
                    phase: float | None = None) -> dict[str, Any] | None:
    """:func:`measure_response` of the patterns' summed histogram ``total`` (``response``
    None) or of a range-free ``response``, its warnings kept quiet: what the plane's checks
    compare; None where no response stands out."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        try:
            return measure_response(total, code, bin_width, distance, pulse_width,
                                    response=response, phase=phase)
        except ConfigError:
            return None
