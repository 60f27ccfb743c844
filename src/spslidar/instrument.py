"""A real instrument is not ideal: a system delay and an instrument response (IRF).

Photons arrive later than their time of flight by the cables and electronics (the *system
delay*, nanoseconds, i.e. metres), and the laser pulse and the detector's jitter spread each
return over several TDC bins, often with a diffusion tail (the *IRF*). ``spslidar run``
simulates both (``--system-delay SECONDS``, ``--irf SPEC``) on every return of eq. (4) (the
noise is neither delayed nor spread); ``spslidar calibrate`` measures them from a flat target
(:mod:`spslidar.pipeline.calibration`) and ``spslidar reconstruct --calibration`` removes
them.

An IRF is given as

* ``gaussian:FWHM`` (seconds), optionally ``gaussian:FWHM,tail:TAU`` or
  ``gaussian:FWHM,tail:TAU,weight:W``: a Gaussian of that full width at half maximum, and with
  probability ``W`` (default 0.3 when a tail is given) an added exponential delay of mean
  ``TAU`` (an ex-Gaussian, the usual shape of a SPAD's diffusion tail);
* a ``.npy`` file: the response sampled per TDC bin (non-negative; normalised here; its time
  origin is its peak).

A parametric IRF is applied to each return in continuous time (:func:`exact_weights`: the
share of each TDC bin from the antiderivative of the jitter's CDF,
:func:`spslidar.detectors.jitter.jitter_antiderivative`), so the sub-bin delay of a return
survives the jitter, as in a real instrument; a sampled one is a per-bin kernel
(:func:`irf_kernel`). The ``gmapd`` detector's own ``--jitter`` is a further convolution in
the detector.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

from .errors import ConfigError

__all__ = ["IRF", "exact_weights", "instrument_weights", "irf_kernel", "parse_irf",
           "window_share"]

#: FWHM / sigma of a Gaussian
_FWHM_PER_SIGMA = 2.3548200450309493
#: the tail weight when a tail is given without one
DEFAULT_TAIL_WEIGHT = 0.3
#: widest IRF accepted (seconds): a microsecond is 150 m of blur, a unit mistake
MAX_IRF_S = 1e-6


@dataclass(frozen=True)
class IRF:
    """A parsed ``--irf`` specification (seconds, or a file)."""

    fwhm: float = 0.0
    tail: float = 0.0
    weight: float = 0.0
    path: str | None = None

    def describe(self) -> str:
        """The response as ``--irf`` takes it (``gaussian:FWHM[,tail:TAU[,weight:W]]`` or
        ``file PATH``), for messages and ``metrics.json``."""
        if self.path is not None:
            return f"file {self.path}"
        text = f"gaussian:{self.fwhm:g}"
        if self.tail > 0:
            text += f",tail:{self.tail:g},weight:{self.weight:g}"
        return text


def parse_irf(spec: str | os.PathLike | None) -> IRF | None:
    """Parse ``--irf`` (see the module docstring); a malformed one is one ConfigError line."""
    if spec is None or str(spec).strip() == "":
        return None
    text = os.fspath(spec).strip()
    if text.lower().endswith(".npy"):
        if not Path(text).is_file():
            raise ConfigError(f"--irf file not found: {text}")
        return IRF(path=text)
    fields: dict[str, float] = {}
    for i, part in enumerate(text.split(",")):
        key, sep, value = part.partition(":")
        key = key.strip().lower()
        if not sep or key not in ("gaussian", "tail", "weight") or (i == 0) != (key == "gaussian"):
            raise ConfigError(f"--irf {text!r}: write gaussian:FWHM[,tail:TAU[,weight:W]] "
                              f"(seconds) or a .npy file of the response per TDC bin")
        if key in fields:  # (the last one silently won)
            raise ConfigError(f"--irf {text!r}: {key} is given twice")
        try:
            fields[key] = float(value)
        except ValueError:
            raise ConfigError(f"--irf {text!r}: {key} must be a number, got {value!r}") from None
    fwhm, tail = fields["gaussian"], fields.get("tail", 0.0)
    weight = fields.get("weight", DEFAULT_TAIL_WEIGHT if tail > 0 else 0.0)
    if "weight" in fields and not tail > 0:  # (it did nothing, saying nothing)
        raise ConfigError(f"--irf {text!r}: a weight without a tail does nothing; give "
                          f"tail:TAU too, or leave weight out")
    if tail > 0 and weight == 0:
        raise ConfigError(f"--irf {text!r}: a tail of weight 0 does nothing; leave the tail "
                          f"out, or give it a weight in (0, 1]")
    for name, v in (("FWHM", fwhm), ("tail", tail)):
        if not 0.0 <= v <= MAX_IRF_S:
            raise ConfigError(f"--irf {name} must be in [0, {MAX_IRF_S:g}] s, got {v:g}: a "
                              f"microsecond of response blurs the range by 150 m")
    if not 0.0 <= weight <= 1.0:
        raise ConfigError(f"--irf weight must be in [0, 1], got {weight:g}")
    return IRF(fwhm, tail, weight)


def _widths(irf: IRF, bin_width: float, period: int) -> tuple[float, float]:
    """The Gaussian's sigma and the tail's mean of a parsed ``--irf``, in bins; refused where
    wider than half the code period (``gaussian:1e-6`` gave a map of noise, saying nothing)."""
    if max(irf.fwhm, irf.tail) / bin_width > period / 2:
        raise ConfigError(f"--irf {irf.describe()}: a response of {max(irf.fwhm, irf.tail):g} s "
                          f"is wider than half the code period ({period} bins of "
                          f"{bin_width:g} s): no range can be resolved through it")
    return irf.fwhm / _FWHM_PER_SIGMA / bin_width, irf.tail / bin_width


def irf_kernel(irf: IRF | None, bin_width: float, period: int):
    """The IRF as ``(offsets, values)``: bin offsets from the return's own bin (may be
    negative; the time origin of a sampled file is its peak) and the share of the photons
    recorded there (sum 1). ``None`` for an ideal instrument."""
    import numpy as np

    if irf is None:
        return None
    if irf.path is not None:
        from .npyfile import load_npy

        # (header, size and archive checked first: an .npz or an empty file gave a traceback,
        # a 2 GB sparse file took 2.2 GB before its refusal, an audit of 2026-11-30)
        h = load_npy(irf.path, "--irf")
        if h.dtype.kind not in "iuf":  # complex was cast with a library warning
            raise ConfigError(f"--irf {irf.path}: a 1-D array of real, non-negative numbers "
                              f"is expected, got dtype {h.dtype}")
        h = np.asarray(h, dtype=np.float64)
        if h.size and np.all(np.isfinite(h)) and h.max() > 0:
            h = h / h.max()  # (a sum of 2e308 overflowed, and h / sum was all zeros)
        if h.ndim != 1 or h.size < 1 or not np.all(np.isfinite(h)) or h.min() < 0 or h.sum() <= 0:
            raise ConfigError(f"--irf {irf.path}: a 1-D array of non-negative numbers, one per "
                              f"TDC bin, with a positive sum is expected")
        if h.size > period:
            raise ConfigError(f"--irf {irf.path}: {h.size} bins, longer than the code period "
                              f"({period} bins)")
        if np.count_nonzero(h >= 0.5 * h.max()) > period / 2:  # (a map of noise, silently)
            raise ConfigError(f"--irf {irf.path}: the response is above half its peak over "
                              f"more than half the code period ({period} bins): no range can "
                              f"be resolved through it")
        offsets = np.arange(h.size) - int(np.argmax(h))
        keep = h > 0
        return offsets[keep], h[keep] / h.sum()
    from .detectors.jitter import jitter_kernel

    sigma, tail = _widths(irf, bin_width, period)
    return _compact(jitter_kernel(period, sigma, tail, irf.weight))


def apply_kernel(shifts, weights, kernel, period: int):
    """Spread each return over the kernel: ``W'[:, (s + o) mod L] += W[:, s] h(o)``.

    Parameters
    ----------
    shifts : ndarray of int, shape (S,)
    weights : ndarray, shape (Q, S)
        :func:`spslidar.forward.return_weights`.
    kernel : (offsets, values) or None
    period : int

    Returns
    -------
    (shifts, weights)
        The occupied bins after the spread, and the spread weights (Q, S').
    """
    import numpy as np

    if kernel is None:
        return shifts, weights
    offsets, values = kernel
    target = np.mod(np.asarray(shifts)[:, None] + np.asarray(offsets)[None, :], period)
    new_shifts, inverse = np.unique(target, return_inverse=True)
    inverse = inverse.reshape(target.shape)
    spread = np.zeros((shifts.size, new_shifts.size))
    for k in range(offsets.size):
        np.add.at(spread, (np.arange(shifts.size), inverse[:, k]), values[k])
    return new_shifts, np.asarray(weights, dtype=np.float64) @ spread


def exact_weights(reflectivity, delay, pulse_width: float, irf: IRF, bin_width: float,
                  period: int):
    """Each return through a parametric IRF, per TDC bin, exactly below a bin.

    A photon of a return at ``delay`` (bins) leaves at ``delay + U pulse_width`` (``U``
    uniform: the RZ pulse), is recorded ``J`` later (the IRF's jitter) and lands in bin
    ``floor(delay + U pulse_width + J)``; with ``G`` the antiderivative of the jitter's CDF
    (:func:`spslidar.detectors.jitter.jitter_antiderivative`) the share of bin ``b + o``
    (``b = floor(delay)``, ``r = delay - b``) is
    ``(G(o + 1 - r) - G(o + 1 - r - p) - G(o - r) + G(o - r - p)) / p``. So the sub-bin delay
    survives the jitter as in a real instrument (the per-bin kernel of
    :func:`irf_kernel` treats a photon as uniform in its bin).

    Returns ``(shifts, weights)`` as :func:`spslidar.forward.return_weights`.
    """
    import numpy as np

    from .detectors.jitter import jitter_antiderivative

    sigma, tail = _widths(irf, bin_width, period)
    delay = np.asarray(delay, dtype=np.float64).ravel()
    base = np.floor(delay)
    frac = delay - base
    lo = -int(np.ceil(10 * sigma)) - 2
    hi = int(np.ceil(10 * sigma + (40 * tail if irf.weight else 0.0) + pulse_width)) + 2
    offsets = np.arange(lo, hi + 1, dtype=np.float64)
    share = np.zeros((delay.size, offsets.size))
    for rows in np.array_split(np.arange(delay.size), max(1, delay.size // 4096)):
        y = offsets[None, :] - frac[rows, None]

        def g(v):
            return jitter_antiderivative(v, sigma, tail, irf.weight)

        share[rows] = (g(y + 1) - g(y + 1 - pulse_width) - g(y) + g(y - pulse_width))
    share = np.maximum(share / pulse_width, 0.0)
    col = share.max(axis=0) > 1e-7 * share.max()  # drop offsets no return reaches
    share, offsets = share[:, col], offsets[col].astype(np.int64)
    share /= share.sum(axis=1, keepdims=True)
    circ = np.mod(base.astype(np.int64)[:, None] + offsets[None, :], period)
    shifts, inverse = np.unique(circ, return_inverse=True)
    inverse = inverse.reshape(circ.shape)
    w = np.zeros((delay.size, shifts.size))
    a = np.asarray(reflectivity, dtype=np.float64).ravel()
    for k in range(offsets.size):
        np.add.at(w, (np.arange(delay.size), inverse[:, k]), a * share[:, k])
    return shifts, w


def instrument_weights(scene, acq, cfg):
    """Each pixel's return per occupied delay bin as the instrument records it: the time of
    flight (eq. 2-3) plus the system delay, the RZ pulse over its bins, spread by the IRF
    (:func:`exact_weights` for a parametric IRF, the per-bin kernel of a sampled one).

    Returns ``(shifts, weights)`` as :func:`spslidar.forward.return_weights`.
    """
    import numpy as np

    from .forward import depth_to_delay, return_weights

    depth, refl = scene.depth.ravel(), scene.reflectivity.ravel()
    behind = getattr(scene, "behind_depth", None)  # a second surface (scenes.procedural)
    if behind is not None:
        depth = np.concatenate([depth, np.nan_to_num(behind.ravel(), nan=depth.max())])
        refl = np.concatenate([refl, scene.behind_reflectivity.ravel()])
    delay = depth_to_delay(depth, acq.bin_width)
    delay = delay + float(getattr(cfg, "system_delay", 0.0) or 0.0) / acq.bin_width
    irf = parse_irf(getattr(cfg, "irf", None))
    if irf is not None and irf.path is None:
        shifts, weights = exact_weights(refl, delay, cfg.pulse_width, irf, acq.bin_width,
                                        acq.period)
    else:
        shifts, weights = return_weights(refl, delay, cfg.pulse_width, acq.period)
        shifts, weights = apply_kernel(shifts, weights,
                                       irf_kernel(irf, acq.bin_width, acq.period), acq.period)
    if behind is not None:  # each pixel's two returns add up
        weights = weights[: scene.depth.size] + weights[scene.depth.size:]
    return shifts, weights


def _compact(kern):
    """A periodic kernel as ``(offsets, values)`` about offset 0 (values over 1e-7 of its
    peak, summing to 1): a parametric IRF's (:func:`irf_kernel`) and a detector's jitter
    (:func:`window_share`)."""
    import numpy as np

    idx = np.flatnonzero(kern > 1e-7 * kern.max())
    offsets = np.where(idx > kern.size // 2, idx - kern.size, idx)
    order = np.argsort(offsets)
    return offsets[order], kern[idx][order] / kern[idx].sum()


def window_share(cfg, bin_width: float, period: int, detector: dict | None = None,
                 half: int = 1, offsets: int = 32) -> float:
    """The share of a return's recorded photons that lies within ``half`` bins of its
    tallest bin, through the simulated instrument (``cfg``'s ``irf`` and ``pulse_width``,
    and the ``detector``'s options ``jitter``, ``jitter_tail``, ``jitter_tail_weight`` where
    it has them: :func:`spslidar.pipeline.plan.detector_options`), averaged
    over ``offsets`` sub-bin delays; 1.0 for an ideal instrument, whose half-bit pulse
    covers at most two bins.

    ``reflectivity.npy`` reads each return within that window of its depth (the refit's
    shapes and the window's sum, :func:`spslidar.refit.return_shapes`,
    :func:`spslidar.products.reflectivity_image`) and is divided by this share in ``run``,
    as by the code's own :func:`~spslidar.correlate.window_response`: through the README's
    IRF (150 ps FWHM, a 400 ps tail of weight 0.3, at 10 GHz) the window holds 0.77 of a
    return, and the reflectivity read 0.74-0.79 of the scene's (an outside audit of
    2026-12-03). A measured acquisition's instrument is not known here (1.0).
    """
    import numpy as np

    from .detectors.jitter import jitter_kernel
    from .forward import return_weights

    irf = parse_irf(getattr(cfg, "irf", None))
    jitter = detector or {}
    sigma = float(jitter.get("jitter") or 0.0) / bin_width
    tail = float(jitter.get("jitter_tail") or 0.0) / bin_width
    weight = float(jitter.get("jitter_tail_weight") or 0.0) if tail > 0 else 0.0
    if irf is None and sigma == 0 and weight == 0:
        return 1.0
    pulse = float(getattr(cfg, "pulse_width", 0.5))
    delay = period // 2 + (np.arange(offsets) + 0.5) / offsets
    ones = np.ones(offsets)
    if irf is not None and irf.path is None:
        shifts, w = exact_weights(ones, delay, pulse, irf, bin_width, period)
    else:
        shifts, w = return_weights(ones, delay, pulse, period)
        shifts, w = apply_kernel(shifts, w, irf_kernel(irf, bin_width, period), period)
    if sigma > 0 or weight > 0:
        shifts, w = apply_kernel(shifts, w, _compact(jitter_kernel(period, sigma, tail,
                                                                   weight)), period)
    rows = np.arange(offsets)[:, None]
    top = shifts[w.argmax(axis=1)]
    reach = np.arange(-int(half), int(half) + 1)[: period]  # (a period of fewer bins)
    near = (top[:, None] + reach[None, :]) % period
    at = np.minimum(np.searchsorted(shifts, near), shifts.size - 1)
    held = np.where(shifts[at] == near, w[rows, at], 0.0).sum(axis=1) / w.sum(axis=1)
    return float(held.mean())
