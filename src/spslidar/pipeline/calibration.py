"""Calibrating a real instrument: its system delay and instrument response (IRF), measured
from an acquisition of a flat target at a known distance, and removed in ``reconstruct``.

``spslidar calibrate`` (:func:`calibrate_ptu`): every pattern's histogram is summed (the
patterns add up over the pixels, so whatever the patterns, the sum is the flat target's
response times the code), the code is deconvolved (Wiener, in the Fourier domain of one code
period: exact for an m-sequence, whose spectrum is flat, and regularised for codes with weak
frequencies), and the flat response ``g`` is left, one pulse wide plus the IRF, on a constant
background (removed by its median). With the target's true delay ``tau_D = 2 D / (c dt)``:

* the **system delay** is ``peak(g) - tau_D`` (bins; the peak interpolated by a parabola
  through its three highest bins, so below a bin), taken in ``[0, L)`` (photons arrive late;
  like every delay it is known modulo the code period ``L``);
* the **IRF** is ``g`` around its peak, background-free, normalised to unit sum, and resampled
  (band-limited, by a Fourier phase ramp) so that its origin is where a return at the true
  delay ``tau`` makes the matched filter peak at the lag the depth estimators read as ``tau``
  (eq. 2-3: lag ``tau - (1 - pulse_width) / 2``), plus a whole number of bins, the
  ``lag_shift`` that ``reconstruct`` adds to the gated lags.

``spslidar reconstruct --calibration CAL.json`` (:func:`calibrated_filter`) then correlates
each histogram with the replica convolved with that IRF at the gated lags plus the shift: the
range gate stays in true metres, the system delay is gone and the filter matches the measured
response (what the matched filter of eq. 5-6 is optimal for).
"""

from __future__ import annotations

import hashlib
import json
import os
from pathlib import Path
from typing import Any

import numpy as np

from ..constants import SPEED_OF_LIGHT
from ..errors import ConfigError
from ..outdir import _sha256 as sha256_file  # one file hasher for the project

__all__ = ["calibrate_ptu", "calibrated_filter", "load_calibration", "measure_response",
           "write_calibration"]

#: bins of the IRF kept before and after its peak (a diffusion tail of a few bins fits)
IRF_BEFORE, IRF_AFTER = 8, 40
#: the IRF's samples below this many noise standard deviations are set to zero
IRF_FLOOR_SIGMA = 3.0
#: format tag of a calibration file
CAL_KIND = "spslidar-calibration"


def _shift(g: np.ndarray, a: float) -> np.ndarray:
    """``g(x + a)`` on the circle, for a real ``a`` (band-limited: a Fourier phase ramp)."""
    n = g.size
    freqs = np.fft.rfftfreq(n)
    return np.fft.irfft(np.fft.rfft(g) * np.exp(2j * np.pi * freqs * a), n)


def measure_response(hist: np.ndarray, code: np.ndarray, bin_width: float, distance: float,
                     pulse_width: float = 0.5) -> dict[str, Any]:
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

    Returns
    -------
    dict
        ``delay_bins`` (sub-bin), ``delay_s``, ``lag_shift`` (int), ``irf_offsets``,
        ``irf_values`` (sum 1), ``irf_fwhm_bins``, ``peak_to_noise``.
    """
    h = np.asarray(hist, dtype=np.float64)
    c = np.asarray(code, dtype=np.float64)
    period = c.size
    if h.shape != (period,):
        raise ConfigError(f"the histogram has {h.size} bins, the code {period}")
    if h.sum() <= 0:
        raise ConfigError("the calibration acquisition holds no photons")
    if not (np.isfinite(distance) and 0.0 <= float(distance) <= 1e6):
        raise ConfigError(f"--distance must be a distance in metres, got {distance!r}")
    # a return is known modulo the code period: so are the target's delay and the system delay
    tau_d = (2.0 * float(distance) / (SPEED_OF_LIGHT * bin_width)) % period
    spec_c = np.fft.rfft(c)
    power = np.abs(spec_c) ** 2
    eps = 1e-3 * float(np.median(power))  # Wiener: weak frequencies of a random code
    g = np.fft.irfft(np.fft.rfft(h) * np.conj(spec_c) / (power + eps), period)
    g -= np.median(g)  # the background is a constant
    p0 = int(np.argmax(g))
    side = np.r_[np.arange(p0 - 3 * IRF_BEFORE, p0 - IRF_BEFORE),
                 np.arange(p0 + IRF_AFTER + 1, p0 + IRF_AFTER + 3 * IRF_BEFORE)] % period
    noise = float(np.std(g[side])) if side.size else 0.0
    peak_to_noise = float(g[p0] / noise) if noise > 0 else float("inf")
    if not peak_to_noise > 5:
        raise ConfigError(f"no clear return in the calibration acquisition (peak "
                          f"{peak_to_noise:.2g} noise standard deviations): check --distance, "
                          f"--bit-rate and the code, or acquire longer")
    y0, y1, y2 = g[(p0 - 1) % period], g[p0], g[(p0 + 1) % period]
    den = y0 - 2 * y1 + y2
    frac = 0.5 * (y0 - y2) / den if den < 0 else 0.0
    peak = p0 + float(np.clip(frac, -0.5, 0.5))
    delay = (peak - tau_d) % period  # photons arrive late: the delay is in [0, L)
    # resample so that a return at true delay tau peaks at lag tau - c0 + lag_shift
    c0 = (1.0 - pulse_width) / 2.0
    lag_shift = int(round(p0 - tau_d + c0))
    k = _shift(g, lag_shift - c0 + tau_d)
    offsets = np.arange(-IRF_BEFORE, IRF_AFTER + 1)
    values = k[offsets % period].copy()
    values[values < IRF_FLOOR_SIGMA * noise] = 0.0
    if values.sum() <= 0:  # pragma: no cover - guarded by the peak test above
        raise ConfigError("the measured response is empty")
    values /= values.sum()
    above = np.flatnonzero(values >= values.max() / 2)
    return {"delay_bins": float(delay), "delay_s": float(delay * bin_width),
            "lag_shift": lag_shift, "irf_offsets": offsets.tolist(),
            "irf_values": values.tolist(), "irf_fwhm_bins": float(above[-1] - above[0] + 1),
            "peak_to_noise": peak_to_noise}


def calibrate_ptu(ptu: str | os.PathLike, patterns: np.ndarray, code: np.ndarray,
                  bit_rate: float, distance: float, *, marker: int = 1,
                  channel: int | None = None, pulse_width: float = 0.5) -> dict[str, Any]:
    """The calibration (:func:`measure_response`) of a T3 PTU acquisition of a flat target,
    with what it was measured from (file, hash, photons, patterns, bit rate, code)."""
    from ..io import read_ptu_histograms
    from ..version import __version__
    from .real import check_real_inputs

    check_real_inputs(bit_rate, (0.0, 1.0), int(patterns.shape[1]), int(patterns.shape[0]),
                      int(code.size))
    bin_width = 1.0 / float(bit_rate)
    data = read_ptu_histograms(ptu, int(code.size), bin_width=bin_width, marker=marker,
                               channel=channel, n_patterns=int(patterns.shape[0]))
    total = data.histograms.astype(np.float64).sum(axis=0)
    cal = measure_response(total, code, bin_width, distance, pulse_width)
    path = Path(ptu)
    return {"kind": CAL_KIND, "version": __version__, **cal, "bin_width_s": bin_width,
            "bit_rate_hz": float(bit_rate), "code_length": int(code.size),
            "code_sha256": hashlib.sha256(np.asarray(code, np.uint8).tobytes()).hexdigest(),
            "pulse_width": float(pulse_width), "distance_m": float(distance),
            "measured_from": {"ptu": path.name, "bytes": path.stat().st_size,
                              "sha256": sha256_file(path), "photons": int(data.n_photons),
                              "patterns": int(patterns.shape[0])}}


def check_calibration_out(out: str | os.PathLike, overwrite: bool = False) -> Path:
    """Refuse (one line) to write ``CAL.json`` over anything but a calibration spslidar
    wrote, and that only with ``overwrite``: checked before the work and again at the end."""
    from ..errors import SpslidarError

    path = Path(out)
    if path.exists():
        if not overwrite:
            raise SpslidarError(f"--out {out} exists; use --overwrite to replace it")
        try:
            ours = json.loads(path.read_text()).get("kind") == CAL_KIND
        except (OSError, ValueError, AttributeError):
            ours = False
        if not ours:
            raise SpslidarError(f"--out {out} exists and is not a spslidar calibration; "
                                f"refusing to replace it")
    if not path.parent.is_dir():
        raise SpslidarError(f"--out {out}: the folder {path.parent} does not exist")
    return path


def write_calibration(cal: dict[str, Any], out: str | os.PathLike, overwrite: bool = False):
    """Write ``CAL.json``: a new file, or (with ``overwrite``) a calibration spslidar wrote;
    never a user's other file (all or nothing, under a temporary name)."""
    from ..outdir import atomic_write_text

    path = check_calibration_out(out, overwrite)
    atomic_write_text(path, json.dumps(cal, indent=1) + "\n")
    return path


def load_calibration(path: str | os.PathLike, bit_rate: float, code: np.ndarray):
    """Read ``CAL.json`` and check that it belongs to this instrument setting (bit rate and
    code); one line otherwise."""
    p = Path(path)
    try:
        cal = json.loads(p.read_text())
    except OSError as exc:
        raise ConfigError(f"cannot read --calibration {p}: {exc.strerror or exc}") from None
    except ValueError:
        raise ConfigError(f"--calibration {p} is not a calibration file (not JSON)") from None
    if not isinstance(cal, dict) or cal.get("kind") != CAL_KIND:
        raise ConfigError(f"--calibration {p} is not a file written by 'spslidar calibrate'")
    if abs(cal["bit_rate_hz"] - float(bit_rate)) > 1e-9 * float(bit_rate):
        raise ConfigError(f"--calibration {p} was measured at {cal['bit_rate_hz']:g} bits/s, "
                          f"not {float(bit_rate):g}")
    if int(cal["code_length"]) != int(np.asarray(code).size):
        raise ConfigError(f"--calibration {p} was measured with a code of "
                          f"{cal['code_length']} bits, not {np.asarray(code).size}")
    cal["file"] = str(p)
    return cal


def calibrated_filter(code: np.ndarray, replica: np.ndarray, cal: dict[str, Any]):
    """The matched filter of a calibrated instrument: the replica and the code convolved
    (circularly) with the measured IRF, and the whole-bin lag shift.

    Returns
    -------
    replica_cal, code_cal : ndarray, shape (L,)
    lag_shift : int
    """
    period = int(np.asarray(code).size)
    kern = np.zeros(period)
    np.add.at(kern, np.mod(np.asarray(cal["irf_offsets"], int), period),
              np.asarray(cal["irf_values"], float))
    spec = np.fft.rfft(kern)

    def conv(x):
        return np.fft.irfft(np.fft.rfft(np.asarray(x, np.float64)) * spec, period)

    return conv(replica), conv(code), int(cal["lag_shift"])
