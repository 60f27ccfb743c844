"""The matched filter (equations 5-6) and the range gate.

The histogram ``h_i(t)`` of pattern ``i`` over one code period is cross-correlated with the code
replica ``f``:

    C_i(tau) = sum_t h_i(t) f((t - tau) mod L) / G                        (eq. 5-6)

which peaks at the round-trip delay of each return. ``G = sum_t s(t) f(t)`` normalises the
output so that a return of unit strength (one photon per pulse, ``n_periods`` periods
accumulated... see :func:`matched_filter`) reads 1 at its peak: the reconstructed slices are then
in units of reflectivity (times the pulse's share of the bin).

Replicas: ``bipolar`` ``f = 2 s - 1`` (an m-sequence then has zero periodic sidelobes and a
constant background cancels) or ``unipolar`` ``f = s`` (the background stays as a DC term, the
form eq. 10 analyses). The range gate keeps only the delays ``tau`` between the gate's ends;
delays longer than the code period are taken modulo ``L`` (the data cannot tell them apart:
range ambiguity).
"""

from __future__ import annotations

import warnings
from typing import Any

import numpy as np

from .arrays import floating_dtype, positive_number, real_array, whole_numbers
from .codes.sequences import code_bits
from .constants import MAX_GATE_BINS, SPEED_OF_LIGHT
from .errors import ConfigError

REPLICAS = ("bipolar", "zero-mean", "unipolar")


def make_replica(code: np.ndarray, kind: str = "bipolar") -> np.ndarray:
    """The receiver's code replica ``f`` (float64): ``bipolar`` ``2s - 1``, ``zero-mean``
    ``s - mean(s)`` or ``unipolar`` ``s``."""
    s = code_bits(code).astype(np.float64)
    if kind == "bipolar":
        return 2.0 * s - 1.0
    if kind == "zero-mean":
        return s - s.mean()
    if kind == "unipolar":
        return s.copy()
    raise ConfigError(f"unknown replica {kind!r}; choose bipolar, zero-mean or unipolar")


def auto_replica(code: np.ndarray) -> str:
    """The PSST lidar's default replica for this code: ``bipolar`` for a balanced code (``k``
    ones of ``T`` bits with ``0 <= 2k - T <= 1``: half the bits, or one more than half of an
    odd count, as an m-sequence's), ``zero-mean`` otherwise.

    ``2s - 1`` sums to zero only over a balanced code: for a Bernoulli code of ones ratio
    R_a its correlation with the code delayed off the peak is ``R_a (2 R_a - 1) T``, a
    negative pedestal under every slice (noiseless, R_a = 0.1, 16x16: RMSE 0.26 m and 40 % of
    the pixels without a return, against 0.013 m for ``s - mean(s)``; docs/reading.md).
    ``s - mean(s)`` sums to zero for any code, so a constant background cancels and a random
    code's off-peak correlation is zero on average; for an m-sequence ``2s - 1`` is exact
    (off-peak sum 0) where ``s - mean(s)`` leaves ``-(T + 1) / 4T``.

    The off-peak means as shares of the peak (:func:`replica_plateau`) are ``(2k - T - 1) /
    (T - 1)`` for ``2s - 1`` and ``-1 / (T - 1)`` for ``s - mean(s)``, so the balanced
    codes above are where the bipolar one is at least as level; a code one bit short of
    balance (``2k - T = -1``, taken as balanced before) has twice the zero-mean's pedestal
    under it: a 31-bit code of 15 ones -2/30 against -1/30 (a review of 2026-12-03).
    """
    s = code_bits(code)
    return "bipolar" if 0 <= 2 * int(np.count_nonzero(s)) - s.size <= 1 else "zero-mean"


#: a replica whose off-peak correlation with the code is at least this share of its peak
#: leaves a plateau under every pixel's profile that :func:`remove_plateau` takes away
PLATEAU_SHARE = 0.05


def replica_plateau(code: np.ndarray, kind: str) -> float:
    """The mean off-peak correlation of ``code`` with its ``kind`` replica, as a share ``q`` of
    the peak: a return of strength ``a`` reads ``a`` at its delay and ``q a`` at every other
    one. 0.5 for an m-sequence's ``unipolar`` replica (``(T + 1) / 4`` against ``(T + 1) /
    2``), 0 for its ``bipolar`` one and for a single pulse (the conventional lidar), about
    ``-1 / T`` for ``zero-mean``. The correlation summed over all ``T`` lags is
    ``sum(s) sum(f)``, so the off-peak mean is ``(sum(s) sum(f) - G) / (T - 1)`` with ``G``
    the peak (:func:`correlation_gain`)."""
    s = np.asarray(code, dtype=np.float64)
    f = make_replica(s, kind)
    peak = correlation_gain(s, f)
    if s.size < 2 or not peak > 0:
        return 0.0
    return float((s.sum() * f.sum() - peak) / ((s.size - 1) * peak))


def remove_plateau(slices: np.ndarray, share: float) -> np.ndarray:
    """Each pixel's profile (rows of ``slices``) without the plateau a replica of
    :func:`replica_plateau` ``share`` ``q`` leaves, scaled so that a return reads its
    strength: ``(x - p) / (1 - q)``. A return ``a`` reads ``a (1 - q)`` spread over its
    slices and ``q a`` at every gated delay, so the profile's sum over ``K`` gated delays is
    ``a (1 - q + q K)`` and the plateau ``p = q sum(x) / (1 - q + q K)``: exact for one or
    several returns inside the gate, a wide one or a gate of one slice (a median over the
    gate, first used, read half the strength on a 2-slice gate or a return over half the
    slices: a review). The depths do not change; the reflectivity, the confidence and the
    noise verdict read the return instead of ``(1 + 2q)`` times it over a floor of ``q``
    (an outside audit of 2026-11-29: ``--replica unipolar`` read 0.604 for a reflectivity of
    0.3 and called a 4.7 mm map "mostly noise")."""
    if not 0.0 <= share < 1.0:
        raise ValueError(f"a plateau share must be in [0, 1), got {share!r} (a code of all "
                         f"ones correlates flat: no delay can be read)")
    # (an integer or boolean profile came back truncated to its dtype: an audit of 2026-11-29)
    given = real_array(slices, "slices", ndim=2, floating=True)
    x = given.astype(np.float64, copy=False)
    k = x.shape[1]
    plateau = share * x.sum(axis=1, keepdims=True) / (1.0 - share + share * k)
    return ((x - plateau) / (1.0 - share)).astype(given.dtype, copy=False)


def window_response(code: np.ndarray, kind: str, half: int = 1) -> float:
    """What a return of unit strength at a whole lag reads summed over the ``2 half + 1``
    lags about its peak, after :func:`matched_filter` with the ``kind`` replica (and, for a
    replica with a plateau, :func:`remove_plateau`): 1 for an m-sequence's bipolar replica
    and for a single pulse, more where the code's own correlation has sidelobes beside its
    peak (a Gold code of 1023 bits, member 2: 1.125, its sidelobes 63 / 1023 of the peak at
    lags +-1 read through the replica as 0.0625 each).

    ``reflectivity.npy`` sums each pixel's profile over those lags
    (:func:`~spslidar.products.reflectivity_image`) and is divided by this, so that the
    reflectivity does not depend on the code family compared (an outside audit of
    2026-12-01: a noiseless wall of reflectivity 1 read 1.125 through the default Gold
    member at 1023 bits, 1.000 through an m-sequence).
    """
    s = code_bits(code).astype(np.float64)
    if s.size < 2:
        return 1.0
    f = make_replica(s, kind)
    peak = correlation_gain(s, f)
    if not peak > 0:
        return 1.0
    # r(k) = sum_t s(t + k) f(t) / G: the filter's output at lag k off a return's own
    r = np.fft.irfft(np.fft.rfft(s) * np.conj(np.fft.rfft(f)), s.size) / peak
    q = replica_plateau(s, kind)
    if PLATEAU_SHARE <= q < 1.0:  # (the plateau the chain takes away)
        r = (r - q) / (1.0 - q)
    lags = np.arange(-int(half), int(half) + 1) % s.size
    total = float(r[np.unique(lags)].sum())
    # (a replica whose sidelobes beside the peak are negative and as large as it, a bipolar
    # replica on a single pulse, is said by the chain; no division is made there)
    return total if 0.5 <= total <= 2.0 else 1.0


def correlation_gain(code: np.ndarray, replica: np.ndarray) -> float:
    """Peak of the code/replica correlation, ``G = sum_t s(t) f(t)``."""
    s = real_array(code, "code", ndim=1).astype(np.float64)
    f = real_array(replica, "replica", ndim=1)
    if f.size != s.size:
        raise ValueError(f"replica of {f.size} bins for a code of {s.size} bits")
    return float(np.dot(s, f))


def gate_lags(gate: tuple[float, float], bin_width: float) -> np.ndarray:
    """Integer delay bins covered by a range gate ``(d_min, d_max)`` in metres."""
    # two numbers (a 3-tuple's third and a string "25" were taken: an audit of 2026-12-02)
    if (isinstance(gate, (str, bytes)) or np.ndim(gate) != 1 or len(gate) != 2
            or any(isinstance(v, (bool, np.bool_, str, bytes)) for v in gate)):
        raise ConfigError(f"range gate must be two numbers (min, max) in metres, got {gate!r}")
    try:
        d0, d1 = float(gate[0]), float(gate[1])
    except (TypeError, ValueError):
        raise ConfigError(f"range gate must be two numbers (min, max) in metres, got "
                          f"{gate!r}") from None
    if not (np.isfinite(d0) and np.isfinite(d1)) or d0 < 0 or d1 <= d0:
        raise ConfigError(f"range gate must satisfy 0 <= min < max, got {d0} {d1}")
    width = None
    if not isinstance(bin_width, (bool, str, bytes)) and bin_width is not None and \
            np.ndim(bin_width) == 0 and not np.iscomplexobj(bin_width):
        width = float(bin_width)  # (a 0-d array is a number)
    if width is None or not (np.isfinite(width) and width > 0):
        # (0 was a ZeroDivisionError, a negative width no lags at all: an audit)
        raise ConfigError(f"bin_width must be a positive number of seconds, got {bin_width!r}")
    to_bins = 2.0 / (SPEED_OF_LIGHT * bin_width)
    lo, hi = int(np.floor(d0 * to_bins)), int(np.ceil(d1 * to_bins))
    if hi - lo + 1 > MAX_GATE_BINS:  # counted before any array exists
        raise ConfigError(f"range gate {d0:g}-{d1:g} m spans {hi - lo + 1:.3g} delay bins of "
                          f"{bin_width:.3g} s, more than {MAX_GATE_BINS} (range slices of "
                          f"several GB): narrow --range-gate")
    return np.arange(lo, hi + 1)


def replica_matrix(replica: np.ndarray, lags: np.ndarray, dtype=np.float32) -> np.ndarray:
    """The ``(L, K)`` matrix of replicas delayed by each lag: ``F[t, k] = f((t - lag_k) mod L)``.

    ``hist @ F`` is the matched filter at those lags; build it once and pass it to
    :func:`matched_filter` when filtering many blocks of patterns.
    """
    f = real_array(replica, "replica", ndim=1).astype(dtype)
    lags = np.mod(whole_numbers(lags, "lags"), f.size)
    if not lags.size:
        return np.empty((f.size, 0), dtype=dtype)
    # one np.roll per lag (row k of the stack is f delayed by lags[k]), then a single transpose
    # copy: far cheaper than gathering through an (L, K) table of modular indices
    rows = np.stack([np.roll(f, int(lag)) for lag in lags])
    return np.ascontiguousarray(rows.T)


#: the largest noise count, over the matched filter's normalisation, a run accepts: squared
#: with a margin of 1e6 it stays inside float32 (3.4e38)
MAX_NOISE_SCALE = 1e16


def check_noise_scale(noise_bin: np.ndarray, acq, gain: float) -> None:
    """Refuse (one line) a signal so small against the noise that the normalised matched
    filter's outputs leave float32.

    The correlations are float32, normalised so that a unit-reflectivity pixel reads 1: the
    noise counts over that scale must stay far inside float32, whose squares the solve takes
    (``--signal 1e-20`` overflowed in the TV, 1e-300 in the cast, leaking NumPy's warnings
    before a misleading refusal: an audit of 2026-11-29). Shared by the device path, which
    ran such signals to a map (an audit of the same day)."""
    noise_scale = float(np.max(noise_bin, initial=0.0)) * acq.code.size * acq.n_periods / gain
    if not noise_scale <= MAX_NOISE_SCALE:
        raise ConfigError(
            f"--signal {acq.signal_per_pulse:g} photons per pulse is too small against the "
            f"noise: the matched filter's outputs, normalised so that a unit-reflectivity "
            f"pixel reads 1, would carry noise counts of about {noise_scale:.1e}, past what "
            f"float32 correlations and their squares hold; raise --signal")


#: the most lags the matched filter correlates through a bank of shifted replicas (one BLAS
#: product); more go through the FFT in float64 (:func:`matched_filter`, and the device path)
FFT_LAGS = 256


def matched_filter(
    hist: np.ndarray,
    replica: np.ndarray,
    lags: np.ndarray,
    gain: float = 1.0,
    out_dtype=np.float32,
    bank: np.ndarray | None = None,
) -> np.ndarray:
    """Circular cross-correlation of histograms with the replica at the given delays.

    Parameters
    ----------
    hist : ndarray, shape (M, L)
        Counts per TDC bin, one row per pattern.
    replica : ndarray, shape (L,)
    lags : ndarray of int, shape (K,)
        Delays in bins (any integers; taken modulo L).
    gain : float
        Divide the output by this (see :func:`correlation_gain`).
    bank : ndarray, optional
        A precomputed :func:`replica_matrix` for these lags.
    out_dtype : dtype
        Of the output (default float32; float64 computes in float64 too, see Notes).

    Returns
    -------
    ndarray, shape (M, K)

    Notes
    -----
    Eq. (5)-(6). For few lags (a range gate) the correlation is a product with the ``(L, K)``
    matrix of shifted replicas (one BLAS call, in float32 unless ``out_dtype`` is float64:
    float32 sums of counts of 1e7 per bin were 8 counts off); for many lags it goes through
    the FFT in float64. The float32 product's error grows with the counts: 0.3 % of the
    Poisson noise at 1e7 counts per bin, 0.9 % at 1e8, 9.5 % at 1e10 and 12 times it at
    1e12 (an audit of 2026-11-30; the simulator refuses more than 1.5e7 per bin): pass
    ``out_dtype=np.float64`` for such counts.

    Examples
    --------
    A return of 3 photons per pulse delayed by 10 bins, over a constant background:

    >>> import numpy as np
    >>> from spslidar.codes import make_code
    >>> from spslidar.correlate import correlation_gain, make_replica, matched_filter
    >>> code = make_code("mseq", 127)
    >>> f = make_replica(code, "bipolar")
    >>> hist = 3.0 * np.roll(code, 10)[None, :] + 0.5  # one pattern's histogram
    >>> c = matched_filter(hist, f, np.arange(127), gain=correlation_gain(code, f))
    >>> c.shape, int(np.argmax(c[0])), round(float(c[0, 10]), 1)
    ((1, 127), 10, 3.0)
    >>> bool(np.abs(np.delete(c[0], 10)).max() < 0.01)  # the background all but cancels
    True
    """
    hist = real_array(hist, "hist")
    replica = real_array(replica, "replica")
    if hist.ndim != 2:
        raise ValueError(f"hist must be (M, L) histograms, one row per pattern, got shape "
                         f"{hist.shape}")
    period = hist.shape[1]
    if np.ndim(replica) != 1 or np.size(replica) != period:
        raise ValueError(f"replica of shape {np.shape(replica)} for histograms of {period} bins")
    if np.ndim(lags) > 1:
        raise ValueError(f"lags must be one list of delays, got shape {np.shape(lags)}")
    # (0.7 bin read as 0, a NaN as an arbitrary lag, an audit of 2026-11-29)
    lags = np.mod(whole_numbers(lags, "lags"), period)
    gain = positive_number(gain, "gain")
    # (an int dtype truncated the correlations, 3.03 to 3: an outside audit of 2026-12-02)
    floating_dtype(out_dtype, "out_dtype")
    if bank is not None and np.shape(bank) != (period, lags.size):
        # (a bank built for other lags was used as it was: 3 columns for 10 lags)
        raise ValueError(f"bank of shape {np.shape(bank)} for {lags.size} lags of a {period}-bin "
                         f"period: build it with replica_matrix(replica, lags)")
    if bank is not None or lags.size <= FFT_LAGS:
        wide = np.dtype(out_dtype) == np.float64
        calc = np.float64 if wide else np.float32
        fm = bank if bank is not None else replica_matrix(replica, lags, calc)
        out = hist.astype(np.result_type(calc, fm.dtype), copy=False) @ fm
        out = out.astype(out_dtype, copy=False)
    else:
        import scipy.fft as sfft

        hf = sfft.rfft(np.asarray(hist, dtype=np.float64), axis=1, workers=-1)
        ff = sfft.rfft(replica)
        full = sfft.irfft(hf * np.conj(ff)[None, :], n=period, axis=1, workers=-1)
        out = full[:, lags].astype(out_dtype)
    if gain != 1.0:
        out /= gain
    return out


def correlation_noise_sigma(hist: np.ndarray, replica: np.ndarray, gain: float = 1.0) -> np.ndarray:
    """Standard deviation of each pattern's matched-filter output, estimated from its counts
    (the noise of eq. 9, read from the measurement).

    For Poisson counts ``Var C_i(tau) = sum_t lambda_i(t) f(t - tau)^2 / G^2``; replacing the
    mean by the observed counts gives an unbiased estimate from the measurements alone (for the
    bipolar replica ``f^2 = 1`` and it is the pattern's total count). One value per pattern
    is returned: the variance averaged over ``tau``. For the bipolar replica (m-sequences)
    it does not depend on ``tau`` at all; for a replica whose ``f^2`` varies (the unipolar
    replica of the conventional lidar, the zero-mean replica of random codes) the variance
    at a strong return's lag is larger than the average (measured with one return of 200
    photons per '1' bit over a background of 0.5 per bin: 14.3 against 1.6 for a single
    pulse, 3.2 against 0.94 for a random code), and by about 8 % in the camera scene, whose
    returns spread over many lags.
    """
    hist = real_array(hist, "hist", ndim=2)
    if np.ndim(replica) != 1 or np.size(replica) != hist.shape[1]:  # (taken: an audit)
        raise ValueError(f"replica of shape {np.shape(replica)} for histograms of "
                         f"{hist.shape[1]} bins")
    return noise_sigma_from_totals(hist.sum(axis=1, dtype=np.float64), replica, gain)


def noise_sigma_from_totals(totals: np.ndarray, replica: np.ndarray,
                            gain: float = 1.0) -> np.ndarray:
    """:func:`correlation_noise_sigma` from each pattern's total count ``sum_t h_i(t)``.

    Parameters
    ----------
    totals : ndarray, shape (M,)
        Total counts of each pattern's histogram.
    replica : ndarray, shape (L,)
    gain : float
        The matched filter's normalisation (see :func:`correlation_gain`).

    Returns
    -------
    ndarray, shape (M,)
        ``sqrt(totals * mean(f^2)) / gain`` (``mean(f^2) = 1`` for the bipolar replica).
    """
    f2 = real_array(replica, "replica", ndim=1).astype(np.float64) ** 2
    var = real_array(totals, "totals").astype(np.float64)
    gain = real_array(gain, "gain").astype(np.float64)  # (one per pattern, or one for all)
    if not (np.isfinite(gain).all() and (gain > 0).all()):
        raise ValueError(f"gain must be positive and finite, got {gain!r}")
    if (var < 0).any():
        raise ValueError("totals holds a negative count")
    if not np.allclose(f2, 1.0):
        # average over tau of sum_t h(t) f(t - tau)^2 = sum_t h(t) * mean(f^2)
        var = var * f2.mean()
    return np.sqrt(var) / gain


#: a noiseless run warns where its float32 round-off reaches this share of a pixel's signal
NOISELESS_ROUNDOFF = 0.1


def noiseless_roundoff(noise_bin: np.ndarray, amp_sum: np.ndarray, acq: Any, q: int) -> None:
    """Warn where a noiseless run's float32 round-off of its background outweighs a pixel's
    signal: the expected counts and their correlations are float32, whose rounding of a
    large background per bin is noise that no Poisson draw hides (``--noiseless --noise
    1000 --signal 0.001`` at 16 x 16 gave an RMSE of 0.21 m with no word, 0.0015 m at
    ``--noise 0``; an audit of 2026-11-29). The round-off of one correlation is about
    ``eps * max(mean per bin) * sqrt(L)``; a pixel of average light adds
    ``m_s * periods * ones * mean(amp) / Q`` to it."""
    top = acq.n_periods * (float(np.max(np.abs(noise_bin), initial=0.0))
                           + acq.signal_per_pulse * float(np.max(np.abs(amp_sum), initial=0.0)))
    roundoff = float(np.finfo(np.float32).eps) * top * np.sqrt(acq.period)
    pixel = (acq.signal_per_pulse * acq.n_periods * float(acq.code.sum())
             * float(np.mean(np.abs(amp_sum))) / max(q, 1))
    if pixel > 0 and roundoff > NOISELESS_ROUNDOFF * pixel:
        warnings.warn(f"a noiseless run computes its expected counts in float32: the rounding "
                      f"of its background ({top:.3g} counts in a bin) is {roundoff / pixel:.2g} "
                      f"times what a pixel of average light adds to a correlation, so the map "
                      f"holds rounding noise; lower --noise (the noise-free limit needs no "
                      f"background) or raise --signal", RuntimeWarning, stacklevel=3)


#: a delay holds a return where the patterns' mean correlation stands this many of its own
#: noise levels above the background's floor (:func:`split_counts`)
SUPPORT_SIGMAS = 3.0
#: :func:`split_counts` gives no split (NaN) where the returns' delays cover more than this
#: share of the code period: weaker returns than the mean sink under the profile's floor
#: (returns of random strengths over 120 of 255 delays: within 3 %)
SPLIT_SHARE = 0.5


def split_counts(corr: np.ndarray, sigma: np.ndarray, totals: np.ndarray, lags: np.ndarray,
                 signal_code: np.ndarray, replica: np.ndarray, gain: float,
                 sigmas: float = SUPPORT_SIGMAS) -> tuple[np.ndarray, np.ndarray]:
    """Each pattern's counts split into signal and background, read off its correlations
    with no ground truth (a measured acquisition's ``mean_signal_counts_per_pattern``).

    Parameters
    ----------
    corr : ndarray, shape (M, K)
        :func:`matched_filter` outputs at the K distinct delays ``lags``, divided by
        ``gain``.
    sigma : ndarray, shape (M,)
        Their noise level (:func:`noise_sigma_from_totals`).
    totals : ndarray, shape (M,)
        Each pattern's total count over its dwell.
    lags : ndarray of int, shape (K,)
        The delays in bins, increasing.
    signal_code : ndarray, shape (L,)
        What one return looks like in the histogram, per unit (the code, or a calibrated
        instrument's code convolved with its response); L is the period in bins.
    replica : ndarray, shape (L,)
        The replica the correlations were made with.
    gain : float
        The matched filter's normalisation.
    sigmas : float
        A return is seen where it stands this many noise levels above the background (or
        ``sqrt(2 ln K)``, which the tallest of K delays of noise about reaches, if more).

    Returns
    -------
    signal : ndarray, shape (M,)
        The counts of the returns inside the gate; the rest of ``totals`` is background
        (and any return outside the gate). NaN where the returns found cover more than
        :data:`SPLIT_SHARE` of the period, where they and a flat background cannot be told
        apart (many weak returns over most of the period read low: 200 returns over 255
        delays read 0.05-0.09 of their counts).
    returns : ndarray, shape (K,)
        The patterns' mean correlation that the returns at each delay account for, the
        code's sidelobes taken out (:func:`_clean` down to ``sigmas`` of its noise
        level); 0 where no return is seen. The sum runs over these delays and those either
        side that a return's response reaches (one for the plain code; :func:`_reach`).

    Notes
    -----
    Eq. (5)-(6) with a flat background: ``B`` background counts add ``B * sum(f) / (L *
    gain)`` to every correlation (``f`` the replica; nothing for the zero-mean replica), and
    one count of a return at delay ``tau`` adds ``g(l - tau)`` at delay ``l``, ``g`` the
    code's periodic correlation with the replica per count. Over the delays ``S`` that hold
    a return, the sum of a pattern's correlations is then ``signal * G + (totals - signal)
    * |S| * sum(f) / (L * gain)``, ``G`` the mean over the returns' delays (weighted by the
    patterns' mean correlation there) of ``sum_{l in S} g(l - tau)``, which counts the
    code's sidelobes: one linear equation per pattern, solved for ``signal``. The returns'
    delays are read off the patterns' mean correlation with every count taken for
    background, where a return of ``c`` counts leaves ``c * (g - sum(f) / (L * gain))``
    exactly (the beam :func:`_clean` takes out).
    Summing the correlations over the whole gate, as this estimate did before, counted the
    background's share once per gated delay as signal: a gate as long as the code's period
    read every count as signal (a 16x16 acquisition of 65 635 signal and 20 966 background
    counts per pattern read 86 597 and 272; an audit of 2026-11-30). A return too weak to
    lift the patterns' mean above the noise is counted as background. Written by hand: it is
    the matched filter's own bookkeeping, not a general estimator a library offers.
    """
    corr = np.asarray(corr, np.float64)
    totals = np.asarray(totals, np.float64)
    sigma = np.asarray(sigma, np.float64)
    code = np.asarray(signal_code, np.float64)
    f = np.asarray(replica, np.float64)
    period, gain = f.size, float(gain)
    per_lag = float(f.sum()) / (period * gain)  # one background count's share of a delay
    m = max(corr.shape[0], 1)
    level = float(np.sqrt(np.mean(sigma ** 2)) / np.sqrt(m)) if sigma.size else 0.0
    lags = np.asarray(lags) % period
    if code.sum() <= 0 or not corr.shape[0]:
        return np.zeros_like(totals), np.zeros(corr.shape[1])
    # g(d) = sum_u code(u) f(u - d) per count; G(tau) = sum_{l in S} g(l - tau)
    g = np.fft.irfft(np.fft.rfft(code) * np.conj(np.fft.rfft(f)), period) / (code.sum()
                                                                            * gain)
    # (no fewer sigmas than the largest of K noise delays reaches: at 3, a 4095-delay gate
    # held about 5 of noise, each read at 3 sigmas as signal, +1.3 %)
    sigmas = max(float(sigmas), float(np.sqrt(2.0 * np.log(max(lags.size, 2)))))
    # Every count taken for background, a return of c counts at tau leaves c * (g(l - tau) -
    # per_lag) in the profile, exactly: CLEAN with that beam (with g alone, the unipolar
    # replica's and an unbalanced code's bipolar one read 2.3 times the signal or NaN, and
    # a floor read from the signal of a pass before diverged for them: a review). A flat
    # spread of returns over the whole period is no beam's: it and the background look
    # alike, and returns over more than SPLIT_SHARE of the period are given no split.
    beam = g - per_lag
    if not beam[0] > 0:
        return np.full_like(totals, np.nan), np.zeros(corr.shape[1])
    profile = (corr - (totals * per_lag)[:, None]).mean(axis=0)
    weight = _clean(profile, beam / beam[0], lags, sigmas * level)
    core = weight > 0
    if not core.any():
        return np.zeros_like(totals), weight
    # and the delays either side that the return's response reaches: a return read over two
    # delays (one either side), or over its response's width (a return at another sub-bin
    # phase than the calibration's has another sampled shape, which CLEAN's whole-delay beams
    # fit only at the peak: summed over one delay either side, it read 1.6-2.6 % more signal
    # through a 1.7-bin response, the background 16-33 % low; an outside audit of stop 80)
    support = core.copy()
    for step in range(1, _reach(beam) + 1):
        support[:-step] |= core[step:]
        support[step:] |= core[:-step]
    held = np.zeros(period)
    held[lags[support]] = 1.0
    big_g = np.fft.irfft(np.fft.rfft(held) * np.conj(np.fft.rfft(g)), period)
    per_count = float(weight @ big_g[lags] / weight.sum())
    floor_share = int(support.sum()) * per_lag
    if support.sum() > SPLIT_SHARE * period or not per_count > floor_share:
        return np.full_like(totals, np.nan), weight
    inside = corr[:, support].sum(axis=1)
    signal = (inside - totals * floor_share) / (per_count - floor_share)
    return np.clip(signal, 0.0, totals), weight


def peak_reach(response: np.ndarray, share: float) -> int:
    """Delays from a periodic ``response``'s peak (lag 0) to the farther side's last delay
    still above ``share`` of it, walking out from the peak on each side (at most half the
    period): how far a return's correlation reaches (:func:`_reach`; a calibrated filter's
    ``half_width``, :func:`spslidar.pipeline.calibrated.calibrated_filter`)."""
    r = np.asarray(response, np.float64)
    period, level = r.size, share * float(r[0])
    reach = 0
    for step in (1, -1):
        lag = 0
        while abs(lag) < period // 2 and r[(lag + step) % period] > level:
            lag += step
        reach = max(reach, abs(lag))
    return reach


def _reach(beam: np.ndarray, share: float = 0.1) -> int:
    """The delays either side of a return's peak that its correlation reaches: one past
    :func:`peak_reach` of the periodic ``beam`` at ``share`` of its peak. A return between
    two delays spreads its response one delay further than the beam's own reach: the plain
    code's beam is one delay wide, so a return is read over two (1); through a response,
    over its width and one more (the :data:`spslidar.pipeline.calibrated.HALF_WIDTH_SHARE`
    share). Summed over that reach, a return's correlations hardly depend on its sub-bin
    phase; summed one delay either side through a 1.7-bin response they did, its sampled
    peak not being a mix of two whole-delay ones (an outside audit of stop 80)."""
    return peak_reach(beam, share) + 1


#: :func:`returns_outside` reads every delay of the period: a return there stands this many
#: noise levels above the background (at 3, a 4095-bit period held about 5 delays of noise
#: above it)
OUTSIDE_SIGMAS = 5.0


#: a measured acquisition warns where more than this share of its returns lies outside the
#: range gate (:func:`returns_outside`, :func:`spslidar.pipeline.gate.outside_note`)
OUTSIDE_SHARE = 0.05
#: a deconvolved return under this share of the largest is the deconvolution's residue
OUTSIDE_FLOOR = 1e-3
#: the share of the returns outside a gate whose delays name where they are
OUTSIDE_SPAN = 0.99


def returns_outside(counts: np.ndarray, replica: np.ndarray, gain: float,
                    signal_code: np.ndarray, delays: np.ndarray,
                    response: tuple[np.ndarray, np.ndarray] | None = None
                    ) -> tuple[float, np.ndarray]:
    """Which share of an acquisition's returns lies outside the delays it was correlated at
    (a range gate that cuts part of the scene), read over the code's whole period.

    Parameters
    ----------
    counts : ndarray, shape (L,)
        The histogram summed over the patterns.
    replica, gain, signal_code
        As for :func:`split_counts`.
    delays : ndarray of int
        The gate's delays (modulo L).
    response : (offsets, values) or None
        A calibrated instrument's response (bins from the return, shares summing to 1).
        ``replica`` and ``signal_code`` are then the plain code's: CLEAN reads every
        return through any response exactly as a few of the plain code's, and the
        components are deconvolved by the response (Richardson-Lucy) into the returns'
        arrivals (the response's own beam left a Gold code's sidelobes standing 11-31 %
        high where the scene's sub-bin positions differ from the calibration wall's, and
        widening the gate by the response's 40-bin tail hid a real 75 %: an audit of
        2026-11-30).

    Returns
    -------
    share : float
        The returns' share (:func:`split_counts`'s ``returns``, over all L delays) at delays
        neither in ``delays`` nor beside them; 0 where no return is seen.
    outside : ndarray of int
        Those delays, the fewest that hold :data:`OUTSIDE_SPAN` of their returns.

    Notes
    -----
    One correlation of the summed histogram at every delay (the FFT, ``L log L``): without
    it, a gate holding part of the scene gave the pixels whose return lies beyond it depths
    in the gate, which are noise, with no word (a 16x16 acquisition of a 5.0-5.8 m scene
    through a 5.0-5.4 m gate: 172 of its 174 such pixels, 46 at confidence 0.5 or more;
    an audit of 2026-11-30).
    """
    counts = np.asarray(counts, np.float64)
    period = counts.size
    every = np.arange(period)
    total = np.array([counts.sum()])
    full = matched_filter(counts[None], replica, every, gain, out_dtype=np.float64)
    _, returns = split_counts(full, noise_sigma_from_totals(total, replica, gain), total,
                              every, signal_code, replica, gain, OUTSIDE_SIGMAS)
    if not returns.sum() > 0:
        return 0.0, np.zeros(0, int)
    if response is not None:
        returns = _deconvolve(returns, *response)
        returns[returns < OUTSIDE_FLOOR * returns.max()] = 0.0  # (its slow convergence)
    near = np.zeros(period, bool)
    near[np.asarray(delays) % period] = True
    near |= np.roll(near, 1) | np.roll(near, -1)  # a return read over two delays
    out = (returns > 0) & ~near
    share = float(returns[out].sum() / returns.sum())
    # the delays that hold most of it (a stray component at 0.9 % of the largest named a
    # span 0.2 m past the scene's end: a review)
    idx = np.flatnonzero(out)
    mass = returns[idx]
    order = np.argsort(mass)[::-1]
    keep = order[: int(np.searchsorted(np.cumsum(mass[order]), OUTSIDE_SPAN * mass.sum())) + 1]
    return share, np.sort(idx[keep])


def _deconvolve(components: np.ndarray, offsets: np.ndarray, values: np.ndarray,
                iterations: int = 200) -> np.ndarray:
    """Non-negative returns whose periodic convolution with the response ``(offsets,
    values)`` is ``components`` (Richardson-Lucy; the total is kept). Written here: a few
    FFT lines on a periodic vector, where scikit-image's ``richardson_lucy`` pads and clips
    an image."""
    c = np.clip(np.asarray(components, np.float64), 0.0, None)
    period = c.size
    v = np.asarray(values, float)
    if not (np.all(np.isfinite(v)) and v.min() >= 0 and v.sum() > 0):
        raise ValueError("a response's values must be finite, non-negative and not all 0")
    k = response_spectrum(offsets, v / v.sum(), period)
    a = np.full(period, c.sum() / period)
    for _ in range(iterations):
        model = periodic_filter(a, k, period)
        ratio = np.divide(c, model, out=np.zeros(period), where=model > 1e-12 * c.max())
        a = np.clip(a * periodic_filter(ratio, np.conj(k), period), 0.0, None)
    return a


def response_spectrum(offsets: np.ndarray, values: np.ndarray, period: int) -> np.ndarray:
    """The real FFT of an instrument's response (``values`` at bin ``offsets`` from the
    return) laid on the code's period, the offsets taken modulo it: what
    :func:`periodic_filter` applies (the calibrated filter and the outside-gate
    deconvolution)."""
    kern = np.zeros(period)
    np.add.at(kern, np.mod(np.asarray(offsets, int), period), np.asarray(values, float))
    return np.fft.rfft(kern)


def periodic_filter(x: np.ndarray, spectrum: np.ndarray, period: int) -> np.ndarray:
    """``x`` (one code period) filtered periodically by ``spectrum`` (a real FFT)."""
    return np.fft.irfft(np.fft.rfft(np.asarray(x, np.float64)) * spectrum, period)


def _clean(profile: np.ndarray, beam: np.ndarray, lags: np.ndarray, floor: float,
           loop_gain: float = 0.7, max_steps: int = 20_000) -> np.ndarray:
    """The returns behind a mean correlation profile, its sidelobes taken out (Hogbom's
    CLEAN): the highest delay's share is moved into the returns and its code's response
    ``beam`` (peak 1 at lag 0, periodic) is subtracted, until no delay stands above
    ``floor``. An m-sequence's flat sidelobes leave the thresholded profile itself; a
    random code's would lift hundreds of delays above the noise in a long gate (40 returns
    of a 1023-bit code: 250 delays). Written by hand: a dozen lines, no library offers it
    on a periodic beam (:func:`spslidar.pipeline.gate.occupied_lags` runs its own, which
    reads the background off the profile's median where this one is given it)."""
    resid = np.asarray(profile, np.float64).copy()
    out = np.zeros_like(resid)
    # (each step is a pass over the delays: at most about 2e8 entries in all)
    for _ in range(min(max_steps, max(100, int(2e8) // max(resid.size, 1)))):
        j = int(np.argmax(resid))
        if resid[j] <= floor:
            break
        step = loop_gain * resid[j]
        out[j] += step
        resid -= step * beam[(lags - lags[j]) % beam.size]
    return out
