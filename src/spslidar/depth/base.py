"""The depth-estimation stage's contract: reconstructed range slices in, depth and a per-pixel
confidence out.

The reconstruction gives each pixel a profile over the gated delays (the columns of the
``(Q, K)`` solution of eq. 18). A :class:`DepthEstimator` turns the whole block into a depth
map (eq. 2-3 for the paper's ML argmax), a confidence in [0, 1] per pixel and a mask of
low-confidence pixels, and may use the image structure (``ctx.shape``) to do so.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..arrays import pair_shape
from ..errors import ConfigError

__all__ = ["DepthContext", "DepthEstimate", "DepthEstimator", "checked_slices"]


@dataclass(frozen=True)
class DepthContext:
    """What an estimator may know besides the slices.

    Attributes
    ----------
    lags : ndarray, shape (K,)
        Absolute delay (TDC bins) of each slice, increasing (a calibrated acquisition's hold a
        part of a bin).
    bin_width : float
        TDC bin width in seconds.
    pulse_width : float
        Return pulse width in bins.
    shape : tuple of int
        Image shape ``(N, N)``; ``Q = N * N`` pixels in C order.
    subbin : bool
        Refine peaks below one bin where the estimator supports it.
    """

    lags: np.ndarray
    bin_width: float
    pulse_width: float = 0.5
    shape: tuple[int, int] = (0, 0)
    subbin: bool = False

    def __post_init__(self) -> None:
        """Refuse what no estimator can read: a bin width of 0 or NaN gave every depth 0 or
        NaN, decreasing lags an argmax read against the wrong delays."""
        for name, unit in (("bin_width", "seconds"), ("pulse_width", "bins")):
            value = getattr(self, name)
            # (a string or None was a ufunc TypeError from isfinite, an audit of 2026-11-29)
            if isinstance(value, (bool, str, bytes)) or not isinstance(
                    value, (int, float, np.integer, np.floating)) or not (
                    np.isfinite(value) and value > 0):
                raise ConfigError(f"{name} must be a positive number of {unit}, got {value!r}")
        # held as an array and a pair of whole numbers (a list of lags failed in estimate()
        # on '.size', a shape of (16, 16, 1) as "too many values to unpack": an audit)
        object.__setattr__(self, "lags", check_delays(self.lags))
        object.__setattr__(self, "shape", pair_shape(self.shape, "shape (rows, cols)", 0))


def check_delays(lags) -> np.ndarray:
    """The slices' delays as an array, or one line: they must be finite and increasing (a
    calibrated instrument's hold the delay's part of a bin: not integers). Shared by
    :class:`DepthContext` and :func:`~spslidar.depth.argmax.ml_depth` (which read decreasing
    or NaN lags as they were: an audit of 2026-11-29)."""
    lags = np.asarray(lags)
    if lags.ndim != 1 or lags.dtype.kind not in "iuf" or not np.isfinite(lags).all():
        raise ConfigError("lags must be a 1-D array of finite delays (TDC bins)")
    if lags.size > 1 and not (np.diff(lags) > 0).all():
        raise ConfigError("lags must be increasing")
    return lags


@dataclass
class DepthEstimate:
    """An estimator's output (all per pixel, flattened in C order, length Q).

    Attributes
    ----------
    depth : ndarray
        Metres; NaN where no return was detected.
    confidence : ndarray
        In [0, 1]; 0 where no return was detected.
    peak : ndarray
        Reconstructed return strength at the chosen delay.
    low_confidence : ndarray of bool
        Pixels with a depth whose confidence is below the estimator's threshold.
    info : dict
        Estimator-specific numbers for ``metrics.json``.
    depth2 : ndarray or None
        A second surface per pixel, metres: where the profile holds a second return that
        passes the estimator's significance test, its depth; NaN where the pixel shows one
        surface. None: the estimator does not look for a second surface.
    """

    depth: np.ndarray
    confidence: np.ndarray
    peak: np.ndarray
    low_confidence: np.ndarray
    info: dict[str, Any] = field(default_factory=dict)
    depth2: np.ndarray | None = None


class DepthEstimator:
    """Base class: subclasses set ``name`` and implement :meth:`estimate`.

    Parameters
    ----------
    low_confidence : float
        Confidence below which a pixel with a depth is flagged low-confidence.
    """

    name = "base"
    #: default of ``low_confidence``
    LOW_CONFIDENCE = 0.25

    def __init__(self, low_confidence: float | None = None, **options: Any):
        self.low_confidence = self.LOW_CONFIDENCE if low_confidence is None else low_confidence
        if not 0.0 <= self.low_confidence <= 1.0:
            raise ConfigError(f"low_confidence must be in [0, 1], got {self.low_confidence}")
        self.options = options

    def __init_subclass__(cls, **kwargs: Any) -> None:
        """Every estimator's :meth:`estimate` gets :func:`checked_slices` around it: the
        contract's input checks and its handling of non-finite values in one place."""
        super().__init_subclass__(**kwargs)
        if "estimate" in cls.__dict__:
            cls.estimate = _checked(cls.__dict__["estimate"])

    def estimate(self, slices: np.ndarray, ctx: DepthContext) -> DepthEstimate:
        """Depth, confidence and peak per pixel from the ``(Q, K)`` slices."""
        raise NotImplementedError  # pragma: no cover - abstract

    def _flag(self, depth: np.ndarray, confidence: np.ndarray) -> np.ndarray:
        return np.isfinite(depth) & (confidence < self.low_confidence)


#: a cube whose largest magnitude is outside [2^-RANGE_EXP, 2^RANGE_EXP] is scaled by a power
#: of two into it: the estimators work in float32 (max 3.4e38), and a 1e39 peak, finite in
#: float64, became inf there after the check (every MRF depth the first lag, confidence NaN);
#: squares of 1e20 overflow too. Every built-in estimator is invariant to the scale (equal
#: depths and confidences at 2^-60 .. 2^60, measured), and a power of two scales exactly.
RANGE_EXP = 60
#: a cube whose typical pixel's peak (the median over pixels) is below this share of its
#: largest value is refused in one line: scaled so that the largest fits float32, the rest
#: underflow (min normal 1.2e-38; measured: a value 1e36 above the rest is read right, 3e38
#: is not)
SPAN_FLOOR = 1e-37


def option(name: str, value: Any, lo: float = 0.0, hi: float = np.inf, *,
           integer: bool = False, open_lo: bool = False) -> float | int:
    """An estimator option checked as one line: a finite number in ``[lo, hi]`` (``(lo, hi]``
    with ``open_lo``), a whole number where ``integer`` (``gap=2.9`` was taken as 2 and
    ``scale=nan`` passed every ``<`` test: an audit of 2026-11-29).

    Raises
    ------
    ConfigError
    """
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise ConfigError(f"{name} must be a number, got {value!r}") from None
    if (isinstance(value, bool | np.bool_) or not np.isfinite(v) or v < lo or v > hi
            or (open_lo and v == lo)):
        left = "(" if open_lo else "["
        span = f"> {lo:g}" if hi == np.inf and open_lo else (
            f">= {lo:g}" if hi == np.inf else f"in {left}{lo:g}, {hi:g}]")
        raise ConfigError(f"{name} must be a finite number {span}, got {value!r}")
    if integer:
        if v != int(v):
            raise ConfigError(f"{name} must be a whole number, got {value!r}")
        return int(v)
    return v


def checked_slices(slices: Any, ctx: DepthContext) -> tuple[np.ndarray, np.ndarray, float]:
    """The ``(Q, K)`` slices as a real array that matches ``ctx``, with every value that is
    not finite set to 0; the mask of the pixels without any finite value; and the power of two
    the slices were multiplied by (1.0 unless their magnitude is outside
    ``2^±RANGE_EXP``: see ``RANGE_EXP`` in this module).

    A NaN in one pixel moved 62 of 64 MRF depths to the first lag and made every confidence
    NaN (a solve whose weight overflows float32 gives such slices): a pixel with no finite
    value has no return, and the others are read as if it held nothing.

    Raises
    ------
    ConfigError
        Slices that are not a non-empty 2-D array of real numbers, or whose number of
        slices differs from ``ctx.lags``.
    """
    x = np.asarray(slices)
    if x.ndim != 2 or 0 in x.shape:
        raise ConfigError(f"slices must be a non-empty (Q, K) array (pixels x delays), got "
                          f"shape {x.shape}")
    if x.dtype.kind not in "biuf":
        raise ConfigError(f"slices must hold real numbers, got dtype {x.dtype}")
    k = np.size(ctx.lags)
    if k != x.shape[1]:
        raise ConfigError(f"ctx.lags has {k} delays but the slices {x.shape[1]}")
    # (a float64 sum per pixel is NaN or infinite where a value is: O(Q) memory, not O(QK))
    bad = (~np.isfinite(x.sum(axis=1, dtype=np.float64)) if x.dtype.kind == "f"
           else np.zeros(x.shape[0], bool))
    if bad.any():
        # a value that is not finite is no evidence (0); a pixel without any finite value has
        # no return (one NaN delay voided every pixel, all "no return" without a word, an
        # outside audit: as ml_depth, a NaN slice is never the tallest)
        finite = np.isfinite(x)
        x = np.where(finite, x, 0)
        bad = ~finite.any(axis=1)
    scale = 1.0
    if x.dtype.kind == "f":
        peaks = np.abs(x).max(axis=1)  # each pixel's, and so the largest value: one pass
        top = float(peaks.max())
        if top > 0:
            # the typical pixel's peak against the largest value, at any scale (a median
            # over all non-zero values read the dust of a sparse cube, and a check made only
            # where the cube was rescaled refused it at one scale and not another: a review)
            peaks = peaks[peaks > 0]
            typical = float(np.median(peaks))
            if typical < SPAN_FLOOR * top:
                # (one value of 3e38 or 1e45 among values of 1: scaled into float32, the
                # others underflowed, every MRF depth the first lag or NaN, an audit)
                raise ConfigError(
                    f"the slices' values span {np.log10(top / typical):.0f} decades (largest "
                    f"{top:.3g}, a typical pixel's peak {typical:.3g}): more than the depth "
                    f"estimators' float32 resolves; is a value corrupt?")
        if top > 0 and not 2.0**-RANGE_EXP <= top <= 2.0**RANGE_EXP:
            scale = 2.0 ** -np.frexp(top)[1]
            x = np.asarray(x, dtype=np.float64) * scale
    return x, bad, scale


#: how far (in bins) an estimator's depths may lie outside its slices' depths (each read as
#: :func:`~spslidar.depth.profile.index_to_depth` reads it): a sub-bin refinement reaches half
#: a bin past the first or last slice
GATE_SLACK_BINS = 2.0


def _checked_estimate(out: Any, q: int, who: str, ctx: DepthContext | None = None) -> Any:
    """An estimator's :class:`DepthEstimate` as the pipeline takes it: each per-pixel array of
    ``q`` entries (depth, confidence, peak, low-confidence; a ``depth2`` too), the confidence
    in [0, 1], NaN read as 0 and its depth flagged; a one-line ConfigError naming the
    estimator otherwise (a plugin's short depth array ended in a reshape traceback, a
    confidence in [-2, 4] was written to ``confidence.npy``; an audit)."""
    if not hasattr(out, "depth"):
        # (a plugin's estimate returning None was told it "returned depth of 1 entries for
        # 256 pixels": an outside audit of 2026-12-02)
        got = "None" if out is None else f"a {type(out).__name__}"
        raise ConfigError(f"the depth estimator {who} returned {got}, not a DepthEstimate: "
                          f"estimate(slices, ctx) returns spslidar.depth.DepthEstimate(depth, "
                          f"confidence, peak, low_confidence) of one entry per pixel")
    for name in ("depth", "confidence", "peak", "low_confidence", "depth2"):
        value = getattr(out, name, None)
        if value is None and name == "depth2":
            continue
        arr = np.asarray(value)
        if arr.size != q:
            raise ConfigError(f"the depth estimator {who} returned {name} of {arr.size} "
                              f"entries for {q} pixels")
        if arr.dtype.kind not in "biuf":
            # (strings as depths ended in numpy's "could not convert string to float", a
            # traceback: an outside audit of 2026-12-01)
            raise ConfigError(f"the depth estimator {who} returned {name} of dtype "
                              f"{arr.dtype}, where real numbers are expected")
        if name == "low_confidence" and arr.dtype.kind != "b":
            if not np.isin(arr, (0, 1)).all():  # (a float mask was taken as it was)
                raise ConfigError(f"the depth estimator {who} returned a low_confidence of "
                                  f"dtype {arr.dtype} that is not 0 / 1: a mask is expected")
            arr = arr.astype(bool)
        setattr(out, name, arr.reshape(q))
    if ctx is not None and ctx.lags.size:
        from ..forward import lag_to_depth

        # (the slices' depths as index_to_depth reads them)
        lo, hi = (float(lag_to_depth(ctx.lags[i] + s * GATE_SLACK_BINS, ctx.bin_width,
                                     ctx.pulse_width))
                  for i, s in ((0, -1), (-1, 1)))
        for name in ("depth", "depth2"):
            d = getattr(out, name, None)
            if d is None:
                continue
            d = np.asarray(d, dtype=np.float64)
            off = np.isfinite(d) & ((d < lo) | (d > hi))
            if off.any():
                # (negative depths ran to exit 0 with an RMSE of 40.9 m, unsaid: an outside
                # audit of 2026-12-01)
                raise ConfigError(
                    f"the depth estimator {who} returned {name} outside its slices' range "
                    f"({int(off.sum())} pixel(s), {float(d[off].min()):.4g} to "
                    f"{float(d[off].max()):.4g} m, for {lo:.4g}-{hi:.4g} m)")
    c = np.asarray(out.confidence, dtype=np.float64)
    if np.any((c < 0) | (c > 1)):
        raise ConfigError(f"the depth estimator {who} returned confidences outside [0, 1] "
                          f"({float(np.nanmin(c)):.3g} to {float(np.nanmax(c)):.3g})")
    nan = np.isnan(c)
    if nan.any():
        # no confidence is 0 confidence (a peak share of an all-zero profile, 0/0), and a
        # depth that has none is flagged (NaN confidences were written as they were: an
        # audit; refusing them refused a plugin over pixels it had no return in, a review)
        out.confidence = np.where(nan, 0.0, c)
        depth = np.asarray(out.depth, dtype=np.float64)
        out.low_confidence = np.asarray(out.low_confidence, dtype=bool) | (
            nan & np.isfinite(depth))
    return out


def _checked(estimate):
    @functools.wraps(estimate)
    def wrapper(self, slices, ctx):
        x, bad, scale = checked_slices(slices, ctx)
        out = _checked_estimate(estimate(self, x, ctx), x.shape[0], type(self).__name__, ctx)
        if scale != 1.0:  # the peaks in the slices' own units
            out.peak = np.asarray(out.peak, dtype=np.float64) / scale
        if bad.any():  # no return there, as for a profile without a positive value
            out.depth[bad] = np.nan
            out.confidence[bad] = 0.0
            out.peak[bad] = 0.0
            out.low_confidence[bad] = False
            if out.depth2 is not None:
                out.depth2[bad] = np.nan
        return out

    return wrapper
