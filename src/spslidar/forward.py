"""The deterministic forward model: expected photon counts per TDC bin for each DMD pattern.

Chain: scene (depth, reflectivity) -> round-trip delays -> each pixel's return pulse shared
between the TDC bins it overlaps -> per pattern, the sum over pixels weighted by the pattern
(eq. 4) -> convolved (circularly, one code period) with the transmitted bit code -> plus the
noise floor. The random detection process (Poisson counting) lives in
:mod:`spslidar.detectors.counting`; everything here is an expectation.

Time is measured in TDC bins of width ``bin_width`` (the bit width 1 / bit_rate). A pixel at
depth ``d`` returns after ``delta = 2 d / (c * bin_width)`` bins (a real number). A return-to-zero
bit is a pulse of ``pulse_width`` bins (0.5 for RZ) starting at the bit's leading edge; the
return of pixel ``j`` therefore occupies ``[delta_j, delta_j + pulse_width)`` and each TDC bin
receives the overlapping fraction of its photons. The period of the code is ``L`` bins, and a
delay is only known modulo ``L`` (range ambiguity, handled by the range gate).
"""

from __future__ import annotations

import numpy as np

from .arrays import positive_number, real_array, same_length, whole_numbers
from .codes.sequences import code_bits
from .constants import SPEED_OF_LIGHT


def depth_to_delay(depth, bin_width: float) -> np.ndarray:
    """Round-trip delay in (fractional) TDC bins: ``tau = 2 d / c`` (eq. 3 inverted)."""
    width = positive_number(bin_width, "bin_width", unit="seconds")
    return 2.0 * real_array(depth, "depth").astype(np.float64) / (SPEED_OF_LIGHT * width)


def delay_to_depth(delay_bins, bin_width: float) -> np.ndarray:
    """Depth in metres of a delay in TDC bins: ``d = tau c / 2`` (eq. 3)."""
    width = positive_number(bin_width, "bin_width", unit="seconds")
    return real_array(delay_bins, "delay_bins").astype(np.float64) * width * SPEED_OF_LIGHT / 2.0


def lag_to_depth(lag, bin_width: float, pulse_width: float) -> np.ndarray:
    """Depth in metres of a return whose correlation peaks at (fractional) lag ``lag``:
    eq. (3) at the pulse's leading edge, ``tau = lag + 1/2 - w/2`` for a pulse of ``w`` bins
    (a return at delay ``tau`` spreads over ``[tau, tau + w)``, whose centre the bin
    ``lag`` holds). The one statement of that offset: the argmax estimator, the profile's
    slice depths, the calibrated cube's grid and the estimators' range check all call it."""
    # (a NaN width gave every pixel NaN, "no return"; a negative one shifted every depth:
    # an outside audit of 2026-12-02)
    width = positive_number(pulse_width, "pulse_width", unit="bins")
    return delay_to_depth(np.asarray(lag, dtype=np.float64) + 0.5 - width / 2.0, bin_width)


def pulse_overlaps(delay: np.ndarray, pulse_width: float) -> tuple[np.ndarray, np.ndarray]:
    """Split each return pulse ``[delay, delay + pulse_width)`` over the integer TDC bins.

    Returns
    -------
    bins : ndarray of int, shape (Q, P)
        Absolute bin indices touched by each pixel's pulse (P = ceil(pulse_width) + 1).
    weights : ndarray, shape (Q, P)
        Fraction of the pulse's photons in each of those bins (rows sum to 1).
    """
    if not 0.0 < pulse_width <= 1.0:
        raise ValueError("pulse_width must be in (0, 1] bins")
    # (a NaN became bin -2^63 with a NaN weight: an audit of 2026-11-29)
    delay = real_array(delay, "delay", finite=True).astype(np.float64).ravel()
    start = np.floor(delay).astype(np.int64)
    n_touch = 2
    bins = start[:, None] + np.arange(n_touch)[None, :]
    lo = np.maximum(bins, delay[:, None])
    hi = np.minimum(bins + 1.0, delay[:, None] + pulse_width)
    weights = np.clip(hi - lo, 0.0, None) / pulse_width
    return bins, weights


def return_weights(
    reflectivity: np.ndarray,
    delay: np.ndarray,
    pulse_width: float,
    period: int,
) -> tuple[np.ndarray, np.ndarray]:
    """Each pixel's return per occupied delay bin: the map from patterns to return amplitudes.

    ``W[j, s] = alpha_j * w_j(shift_s)``, the share of pixel ``j``'s pulse in circular bin
    ``shift_s`` times its reflectivity, so that ``Phi @ W`` is :func:`return_amplitudes`.

    Parameters
    ----------
    reflectivity : ndarray, shape (Q,)
    delay : ndarray, shape (Q,)
        Round-trip delays in (fractional) TDC bins.
    pulse_width : float
        Return pulse width in bins.
    period : int
        Code period in bins (delays are taken modulo it).

    Returns
    -------
    shifts : ndarray of int, shape (S,)
        The distinct occupied bins, in ``[0, period)``.
    W : ndarray, shape (Q, S)
        float64; dense (S, the number of occupied depth bins, is small).
    """
    if isinstance(period, bool) or not float(period).is_integer() or period < 1:
        # (0 put every return in bin 0, 1.5 gave fractional shifts: an audit of 2026-11-29)
        raise ValueError(f"period must be a whole number of bins >= 1, got {period!r}")
    period = int(period)
    bins, weights = pulse_overlaps(delay, pulse_width)  # (a NaN or infinite delay refused)
    q = bins.shape[0]
    refl = np.ravel(real_array(reflectivity, "reflectivity"))
    if refl.size != 1:  # (one value is every pixel's)
        same_length(refl, q, "reflectivity", "delays")
    circ = np.mod(bins, period)
    shifts, inverse = np.unique(circ, return_inverse=True)
    inverse = inverse.reshape(circ.shape)
    w = np.zeros((q, shifts.size), dtype=np.float64)
    a = np.asarray(reflectivity, dtype=np.float64).ravel()
    for p in range(bins.shape[1]):
        np.add.at(w, (np.arange(q), inverse[:, p]), a * weights[:, p])
    return shifts, w


def return_amplitudes(
    patterns: np.ndarray,
    reflectivity: np.ndarray,
    delay: np.ndarray,
    pulse_width: float,
    period: int,
) -> tuple[np.ndarray, np.ndarray]:
    """Per-pattern return amplitude at each occupied delay bin (mod the code period).

    ``amp[i, s] = sum_j Phi[i, j] * alpha_j * w_j(shift_s)``: the photons (per unit signal
    strength ``m_s``) that pattern ``i`` collects from all pixels whose pulse overlaps circular
    bin ``shift_s``. This is the first term of eq. (4) with the temporal code factored out.

    Returns
    -------
    shifts : ndarray of int, shape (S,)
        The distinct occupied bins, in ``[0, period)``.
    amp : ndarray, shape (M, S)
    """
    shifts, w = return_weights(reflectivity, delay, pulse_width, period)
    if hasattr(patterns, "apply_rows"):  # a pattern operator (build_patterns' own result)
        return shifts, np.asarray(patterns.apply_rows(slice(0, patterns.shape[0]), w))
    phi = real_array(patterns, "patterns", ndim=2)
    if phi.shape[1] != w.shape[0]:
        raise ValueError(f"patterns of shape {phi.shape} for {w.shape[0]} pixels: one column "
                         f"per pixel")
    return shifts, phi.astype(np.float64) @ w


def shifted_codes(code: np.ndarray, shifts: np.ndarray, dtype=np.float32) -> np.ndarray:
    """Matrix whose row ``s`` is the code delayed by ``shifts[s]`` bins (circularly).

    Float32 by default: the bits are exact, and the expected counts it produces are accurate to
    ~1e-7 relative, far below the Poisson fluctuations they feed.
    """
    code = real_array(code, "code").astype(dtype).ravel()
    shifts = np.mod(whole_numbers(shifts, "shifts"), code.size)
    if not shifts.size:
        return np.empty((0, code.size), dtype=code.dtype)
    return np.stack([np.roll(code, int(s)) for s in shifts])


def expected_counts(
    amp: np.ndarray,
    shifts: np.ndarray,
    code: np.ndarray,
    signal: float,
    noise_per_bin,
    n_periods: int = 1,
    code_matrix: np.ndarray | None = None,
) -> np.ndarray:
    """Mean photon counts per TDC bin, accumulated over ``n_periods`` code periods.

    ``lambda_i(t) = n_periods * (m_s * sum_s amp[i, s] * code(t - shift_s) + b_i)``

    Parameters
    ----------
    amp, shifts : from :func:`return_amplitudes`
    code : ndarray, shape (L,)
        Transmitted bits (1 = a laser pulse in that bit).
    signal : float
        ``m_s``: mean signal photons per laser pulse per DMD pixel (mirror fully on,
        reflectivity 1).
    noise_per_bin : float or ndarray of shape (M,)
        Noise counts per TDC bin per period for each pattern (see
        :meth:`spslidar.detectors.counting.NoiseModel.per_bin`).
    n_periods : int
        Code periods accumulated per pattern (1 for the PSST lidar; the number of laser shots
        for the conventional one).
    code_matrix : ndarray, optional
        A precomputed ``shifted_codes(code, shifts)`` (reused across blocks of patterns).

    Returns
    -------
    ndarray, shape (M, L)
        In the dtype of ``code_matrix`` (float64 when it is not given).

    Notes
    -----
    Eq. (4) in expectation, with ``P_R`` expressed as ``m_s`` photons per pulse (eq. 8).

    Examples
    --------
    A 2x2 wall at 3 m seen through one all-on pattern, a 127-bit code at 10 GHz:

    >>> import numpy as np
    >>> from spslidar.codes import make_code
    >>> from spslidar.forward import depth_to_delay, expected_counts, return_amplitudes
    >>> code = make_code("mseq", 127)
    >>> delay = depth_to_delay(np.full((2, 2), 3.0), bin_width=1e-10)  # 200.14 bins
    >>> shifts, amp = return_amplitudes(np.ones((1, 4)), np.ones((2, 2)), delay, 0.5, code.size)
    >>> int(shifts[0])  # the return's bin, modulo the code period: 200 - 127
    73
    >>> lam = expected_counts(amp, shifts, code, signal=5.0, noise_per_bin=0.1)
    >>> lam.shape, round(float(lam.sum()), 2)  # 4 pixels x 5 photons x 64 pulses + 12.7 noise
    ((1, 127), 1292.7)
    """
    # (an outside audit of 2026-12-02: a matrix of a 127-bit code was used with a 255-bit
    # code, bits of 0..126 and negative or NaN noise made means no photon count has, and a
    # signal of [5.0] or None was a TypeError naming nothing; every check comes before the
    # (L, L) code matrix is built: a review)
    bits = code_bits(code)
    n_periods = positive_number(n_periods, "n_periods")
    signal = positive_number(signal, "signal", unit="photons per pulse", zero=True)
    noise = real_array(noise_per_bin, "noise_per_bin")
    if not (np.isfinite(noise).all() and (noise >= 0).all()):
        raise ValueError("noise_per_bin must be finite counts >= 0")
    amp = real_array(amp, "amp", ndim=2)
    if code_matrix is not None and (np.ndim(code_matrix) != 2
                                    or np.shape(code_matrix)[1] != bits.size):
        raise ValueError(f"code_matrix of shape {np.shape(code_matrix)} for a {bits.size}-bit "
                         f"code: build it with shifted_codes(code, shifts)")
    s = code_matrix if code_matrix is not None else shifted_codes(bits, shifts, np.float64)
    if amp.shape[1] != s.shape[0]:
        raise ValueError(f"amp of shape {amp.shape} for {s.shape[0]} shifts: one column each")
    noise = noise.astype(s.dtype, copy=False)
    if noise.ndim == 2 and noise.shape[1] == 1:  # (M, 1), one column: unambiguous
        noise = noise[:, 0]
    if noise.ndim > 1 or noise.size not in (1, amp.shape[0]):
        raise ValueError(f"noise_per_bin of shape {noise.shape} for {amp.shape[0]} patterns: "
                         f"one number, or one per pattern")
    lam = (signal * amp.astype(s.dtype, copy=False)) @ s
    lam += noise.reshape(-1, 1)
    if n_periods != 1:
        lam *= n_periods
    return lam
