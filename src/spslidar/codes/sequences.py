"""Temporal pseudo-random codes that modulate the laser (unipolar bits, ``uint8`` 0/1).

Three families are offered, as in Fig. 3 of the paper: maximal-length sequences
(m-sequences), Gold sequences, and iid Bernoulli ("random") bits with a chosen share ``R_a`` of
'1' bits. The matched filter correlates the photon-count histogram with a replica of the code;
:func:`periodic_xcorr` is the circular correlation it relies on ([1]_, [2]_).

Notes
-----
The transmitted code is unipolar, ``s(t) in {0, 1}`` (the laser is on or off). Correlated with
a bipolar replica ``f = 2 s - 1`` an m-sequence has a two-valued periodic autocorrelation
``{T, -1}``, so a constant background cancels up to ``-1/T`` of itself; with a unipolar replica
the background stays as a DC term counted over the ``R_a T`` "on" bits, which is what eqs.
(8)-(10) of Shen et al. describe. The code period ``T dt`` sets the unambiguous range
``c T dt / 2`` (:func:`unambiguous_range`).

References
----------
.. [1] R. Gold, "Optimal binary sequences for spread spectrum multiplexing", IEEE Trans. Inf.
       Theory 13(4), 619-621 (1967).
.. [2] D. V. Sarwate and M. B. Pursley, "Crosscorrelation properties of pseudorandom and
       related sequences", Proc. IEEE 68(5), 593-619 (1980).
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np

from ..constants import SPEED_OF_LIGHT
from ..errors import ConfigError

__all__ = [
    "CODE_KINDS",
    "code_bits",
    "MAX_CODE_LENGTH",
    "MSEQ_DEGREES",
    "GOLD_DEGREES",
    "canonical_kind",
    "make_code",
    "preferred_pair",
    "gold_family",
    "periodic_xcorr",
    "gold_bound",
    "valid_lengths",
    "unambiguous_range",
    "XCORR_EXACT_LIMIT",
]

#: Canonical code kinds accepted by :func:`make_code`.
CODE_KINDS: tuple[str, ...] = ("mseq", "gold", "random")

_ALIASES: dict[str, str] = {
    "mseq": "mseq",
    "m-sequence": "mseq",
    "msequence": "mseq",
    "gold": "gold",
    "random": "random",
    "bernoulli": "random",
}

#: Register degrees ``n`` supported for m-sequences (length ``2**n - 1``).
MSEQ_DEGREES: tuple[int, ...] = tuple(range(3, 21))

# Preferred pairs of m-sequences, as feedback taps in the convention of
# ``scipy.signal.max_len_seq``: taps ``(k1, k2, ...)`` of degree ``n`` generate
# ``s[t + n] = s[t] ^ s[t + k1] ^ s[t + k2] ^ ...``, i.e. the characteristic polynomial
# ``x^n + x^k1 + x^k2 + ... + 1``. The first member of each pair is SciPy's default polynomial;
# the second is the polynomial of its decimation by ``q = 2^k + 1`` (k = 1 for odd n, k = 2 for
# n = 2 mod 4), which by Gold's theorem [1] makes a preferred pair. The second polynomials were
# found once with the Berlekamp-Massey algorithm and are written out here; the test-suite checks
# every pair by its three-valued cross-correlation {-t(n), -1, t(n) - 2}.
_PREFERRED_PAIRS: dict[int, tuple[tuple[int, ...], tuple[int, ...]]] = {
    3: ((2,), (1,)),
    5: ((3,), (3, 2, 1)),
    6: ((5,), (5, 4, 1)),
    7: ((6,), (6, 4, 2)),
    9: ((5,), (6, 5, 3)),
    10: ((7,), (8, 7, 2)),
    11: ((9,), (9, 6, 3)),
    13: ((12, 11, 8), (10, 9, 8, 7, 4)),
    14: ((13, 12, 2), (13, 12, 10, 9, 8, 6, 5, 3, 2)),
    15: ((14,), (14, 10, 5)),
    17: ((14,), (16, 15, 14)),
    18: ((11,), (13, 11, 8)),
    19: ((18, 17, 14), (16, 15, 14, 11, 6)),
}

#: Register degrees ``n`` supported for Gold codes (``n`` not divisible by 4).
GOLD_DEGREES: tuple[int, ...] = tuple(sorted(_PREFERRED_PAIRS))

# Largest degree for which :func:`gold_family` materialises the whole (T + 2, T) family.
_GOLD_FAMILY_MAX_N = 13

#: Longest random code :func:`make_code` draws, ``2**24`` bits (16 times the longest
#: m-sequence; the configuration's own ``code_length`` cap): ``10**12`` bits asked numpy for
#: 7.28 TiB of uniform draws and ended in a ``MemoryError`` (an audit of 2026-12-02).
MAX_CODE_LENGTH = 2**24

#: :func:`periodic_xcorr` refuses inputs whose correlations could reach this magnitude
#: (``||a|| ||b|| >= 2**44``, about 1.8e13): its float64 FFTs round to the exact integer
#: below it (an error under 0.01 measured at T = 65535), not far above it (0.5 at 2**50.5),
#: and int64 overflows at 2**63 (``[2**40, 1]`` with itself read ``-2**63``: an audit).
XCORR_EXACT_LIMIT = 2.0**44


def code_bits(code) -> np.ndarray:
    """``code`` as a real, finite, non-empty 1-D array of bits (0 or 1), or one line: the
    check of every consumer of a code's bits (the replicas, the expected counts). An empty
    code leaked "Mean of empty slice" and a NaN one was called balanced (an audit of
    2026-11-29); ``[2, 2, 0]`` was called balanced and a code matrix of ``0..126`` made means
    no photon count has (an audit of 2026-12-02)."""
    from ..arrays import real_array

    s = real_array(code, "code", ndim=1, finite=True)
    if not s.size:
        raise ConfigError("code is empty: a replica needs one bit or more")
    if not np.isin(s, (0, 1)).all():
        raise ConfigError("code must hold bits, 0 or 1 (1 = a laser pulse; a +-1 code is "
                          "(c + 1) / 2)")
    return s


def canonical_kind(kind: str) -> str:
    """Return the canonical name of a code kind (``'mseq'``, ``'gold'`` or ``'random'``).

    Parameters
    ----------
    kind : str
        Kind or alias, case-insensitive: ``'mseq'`` (``'m-sequence'``, ``'msequence'``),
        ``'gold'``, ``'random'`` (``'bernoulli'``).

    Returns
    -------
    str
        The canonical kind.

    Raises
    ------
    ConfigError
        If the kind is unknown.
    """
    key = str(kind).strip().lower() if isinstance(kind, str) else None
    if key not in _ALIASES:
        raise ConfigError(
            f"unknown code kind {kind!r}: use 'mseq' (or 'm-sequence', 'msequence'), 'gold' "
            "or 'random' (or 'bernoulli')"
        )
    return _ALIASES[key]


def _as_int(value, what: str) -> int:
    """Return ``value`` as an int, or raise ConfigError if it is not an integer."""
    if isinstance(value, (bool, np.bool_)):
        raise ConfigError(f"{what} must be an integer, got {value!r}")
    if isinstance(value, (int, np.integer)):
        return int(value)
    if isinstance(value, (float, np.floating)) and float(value).is_integer():
        return int(value)
    raise ConfigError(f"{what} must be an integer, got {value!r}")


def _degree_of(length: int) -> int | None:
    """Return ``n`` if ``length == 2**n - 1`` (n >= 1), else None."""
    m = length + 1
    if m >= 2 and m & (m - 1) == 0:
        return m.bit_length() - 1
    return None


def _nearest_text(length: int, lengths: list[int]) -> str:
    """Name the valid lengths just below and just above ``length``, e.g. ``'16383 or 32767'``."""
    below = [v for v in lengths if v < length]
    above = [v for v in lengths if v > length]
    return " or ".join([str(v) for v in below[-1:] + above[:1]])


def _check_length(kind: str, length: int) -> int:
    """Validate a code length for ``kind`` and return its degree n (0 for random codes)."""
    if kind == "random":
        if length < 2:
            raise ConfigError(f"code length {length} is too short: random codes need length >= 2")
        if length > MAX_CODE_LENGTH:
            raise ConfigError(f"code length {length} is too long: random codes are at most "
                              f"{MAX_CODE_LENGTH} (2^24) bits")
        return 0
    n = _degree_of(length)
    if kind == "mseq":
        if n not in MSEQ_DEGREES:
            near = _nearest_text(length, valid_lengths("mseq"))
            raise ConfigError(
                f"code length {length} is not valid for an m-sequence: use 2^n - 1 with n in "
                f"{MSEQ_DEGREES[0]}..{MSEQ_DEGREES[-1]}, nearest {near}"
            )
        return n
    # gold
    if n not in GOLD_DEGREES:
        near = _nearest_text(length, valid_lengths("gold"))
        if n is not None and n % 4 == 0:
            why = f"2^{n} - 1 has n divisible by 4, for which no preferred pair exists"
        else:
            why = (
                f"use 2^n - 1 with n in {GOLD_DEGREES[0]}..{GOLD_DEGREES[-1]} "
                "and n not divisible by 4"
            )
        raise ConfigError(
            f"code length {length} is not valid for a Gold code: {why}, nearest {near}"
        )
    return n


#: ``scipy.signal.max_len_seq``'s default feedback taps per degree (``scipy.signal.
#: _max_len_seq._mls_taps``, the first polynomial listed by New Wave Instruments for each n)
_MLS_TAPS: dict[int, tuple[int, ...]] = {
    2: (1,), 3: (2,), 4: (3,), 5: (3,), 6: (5,), 7: (6,), 8: (7, 6, 1), 9: (5,), 10: (7,),
    11: (9,), 12: (11, 10, 4), 13: (12, 11, 8), 14: (13, 12, 2), 15: (14,), 16: (15, 13, 4),
    17: (14,), 18: (11,), 19: (18, 17, 14), 20: (17,), 21: (19,), 22: (21,), 23: (18,),
    24: (23, 22, 17), 25: (22,), 26: (25, 24, 20), 27: (26, 25, 22), 28: (25,), 29: (27,),
    30: (29, 28, 7), 31: (28,), 32: (31, 30, 10)}


def lfsr_sequence(n: int, taps: tuple[int, ...] | None = None) -> np.ndarray:
    """The full period (``2^n - 1`` bits) of the Fibonacci LFSR ``s[t + n] = s[t] ^ s[t + k1]
    ^ s[t + k2] ^ ...`` from the all-ones state: bitwise the output of
    ``scipy.signal.max_len_seq(n, taps=taps)[0]`` (same taps convention and defaults).

    Written here so that a run does not import ``scipy.signal`` (0.5-0.8 s: it pulls in
    ``scipy.stats``) for ~16 k bits. The register is one Python integer; each bit costs a mask,
    a popcount and a shift (degree 14: ~5 ms; degree 20: ~0.4 s).

    Parameters
    ----------
    n : int
        Register degree (2..32 with the default taps).
    taps : tuple of int, optional
        Feedback taps in ``(0, n]``; default :data:`_MLS_TAPS`.

    Returns
    -------
    ndarray of uint8, shape (2^n - 1,)
    """
    if taps is None:
        if n not in _MLS_TAPS:
            raise ConfigError(f"no default m-sequence taps for degree {n}: use 2..32")
        taps = _MLS_TAPS[n]
    taps = tuple(sorted(set(int(t) for t in taps), reverse=True))
    if not taps or min(taps) < 0 or max(taps) > n:
        raise ConfigError(f"m-sequence taps must lie in [0, {n}], got {list(taps)}")
    mask = 1  # the feedback reads s[t] and s[t + k] (register bit k mod n) for every tap k
    for k in taps:
        mask ^= 1 << (k % n)
    top = n - 1
    state = (1 << n) - 1
    length = (1 << n) - 1
    out = bytearray(length)
    for t in range(length):
        out[t] = state & 1
        state = (state >> 1) | (((state & mask).bit_count() & 1) << top)
    return np.frombuffer(bytes(out), dtype=np.uint8).copy()


@lru_cache(maxsize=64)
def _mseq_cached(n: int, taps: tuple[int, ...] | None) -> np.ndarray:
    """The m-sequence of degree n from the all-ones register state (read-only)."""
    seq = lfsr_sequence(n, taps)
    seq.setflags(write=False)
    return seq


def _mseq(n: int, taps: tuple[int, ...] | None = None) -> np.ndarray:
    """A writable copy of the m-sequence of degree n (SciPy's default taps if ``taps`` is None)."""
    return _mseq_cached(int(n), None if taps is None else tuple(int(t) for t in taps)).copy()


def _check_gold_degree(n) -> int:
    n = _as_int(n, "Gold register degree n")
    if n not in _PREFERRED_PAIRS:
        raise ConfigError(
            f"no Gold code of degree n = {n}: use n in {GOLD_DEGREES[0]}..{GOLD_DEGREES[-1]} "
            f"not divisible by 4 ({', '.join(map(str, GOLD_DEGREES))})"
        )
    return n


def preferred_pair(n: int) -> tuple[tuple[int, ...], tuple[int, ...]]:
    """Feedback taps of a preferred pair of m-sequences of degree ``n``.

    Parameters
    ----------
    n : int
        Register degree; one of :data:`GOLD_DEGREES` (3..19, not divisible by 4).

    Returns
    -------
    (taps_u, taps_v) : tuple of tuple of int
        Taps in the convention of :func:`scipy.signal.max_len_seq` (``max_len_seq(n,
        taps=taps_u)`` generates the first sequence): taps ``(k1, k2, ...)`` mean the recurrence
        ``s[t + n] = s[t] XOR s[t + k1] XOR s[t + k2] ...``, i.e. the primitive polynomial
        ``x^n + x^k1 + x^k2 + ... + 1``.

    Raises
    ------
    ConfigError
        If no pair is tabulated for ``n`` (n divisible by 4 has none).

    Notes
    -----
    The table is hand-written because SciPy has no Gold codes. The first polynomial is SciPy's
    default for degree ``n``; the second is that of its decimation by ``q = 2^k + 1``, with
    ``gcd(n, k) = 1`` for odd ``n`` (``k = 1``) and ``gcd(n, k) = 2`` for ``n = 2 mod 4``
    (``k = 2``). Gold's theorem [1]_ (see also [2]_) then gives a three-valued periodic
    cross-correlation ``{-t(n), -1, t(n) - 2}`` with ``t(n) = 1 + 2^floor((n + 2) / 2)``
    (:func:`gold_bound`). The decimated polynomials were obtained once with the
    Berlekamp-Massey algorithm and are checked by the test-suite through that bound.

    References
    ----------
    .. [1] R. Gold, IEEE Trans. Inf. Theory 13(4), 619-621 (1967).
    .. [2] D. V. Sarwate and M. B. Pursley, Proc. IEEE 68(5), 593-619 (1980).
    """
    return _PREFERRED_PAIRS[_check_gold_degree(n)]


def _gold_pair_sequences(n: int) -> tuple[np.ndarray, np.ndarray]:
    taps_u, taps_v = _PREFERRED_PAIRS[n]
    return _mseq_cached(n, taps_u), _mseq_cached(n, taps_v)


def gold_family(n: int) -> np.ndarray:
    """The whole Gold family of degree ``n``.

    Parameters
    ----------
    n : int
        Register degree; one of :data:`GOLD_DEGREES` up to 13 (larger families are too big to
        hold: draw single members with ``make_code('gold', 2**n - 1, index=i)``).

    Returns
    -------
    numpy.ndarray
        ``uint8`` array of shape ``(T + 2, T)``, ``T = 2**n - 1``. Row 0 is the m-sequence ``u``,
        row 1 the m-sequence ``v`` of the preferred pair, and row ``2 + k`` is
        ``u XOR roll(v, -k)`` (``u[t] XOR v[(t + k) mod T]``) for ``k = 0..T-1``.

    Raises
    ------
    ConfigError
        If ``n`` is not a Gold degree or the family is too large.

    Notes
    -----
    Any two distinct members have periodic bipolar cross-correlation in
    ``{-t(n), -1, t(n) - 2}`` and out-of-phase autocorrelation bounded by ``t(n)`` [1]_.

    References
    ----------
    .. [1] R. Gold, IEEE Trans. Inf. Theory 13(4), 619-621 (1967).

    Examples
    --------
    >>> from spslidar.codes import gold_bound, gold_family, periodic_xcorr
    >>> family = gold_family(5)  # T = 31 bits: the preferred pair and 31 Gold codes
    >>> family.shape
    (33, 31)
    >>> sorted(set(periodic_xcorr(family[2], family[3]).tolist())), gold_bound(5)
    ([-9, -1, 7], 9)
    """
    n = _check_gold_degree(n)
    if n > _GOLD_FAMILY_MAX_N:
        raise ConfigError(
            f"Gold family of degree n = {n} is too large to hold ({2**n + 1} x {2**n - 1} bits): "
            f"use n <= {_GOLD_FAMILY_MAX_N}, or make_code('gold', {2**n - 1}, index=i) for "
            "single members"
        )
    u, v = _gold_pair_sequences(n)
    period = u.size
    family = np.empty((period + 2, period), dtype=np.uint8)
    family[0] = u
    family[1] = v
    shifts = np.lib.stride_tricks.sliding_window_view(np.concatenate([v, v[:-1]]), period)
    np.bitwise_xor(u[None, :], shifts, out=family[2:])
    return family


def make_code(
    kind: str,
    length: int,
    ones_ratio: float = 0.5,
    rng: np.random.Generator | int | None = None,
    index: int = 0,
) -> np.ndarray:
    """Make one temporal code of unipolar bits.

    Parameters
    ----------
    kind : str
        ``'mseq'`` (aliases ``'m-sequence'``, ``'msequence'``), ``'gold'`` or ``'random'``
        (alias ``'bernoulli'``); case-insensitive.
    length : int
        Code length ``T``. For m-sequences ``2^n - 1`` with ``n`` in 3..20; for Gold codes
        ``2^n - 1`` with ``n`` in 3..19 not divisible by 4 (e.g. 2047, 16383; not 255, 4095);
        for random codes any ``T`` in ``2..2**24`` (:data:`MAX_CODE_LENGTH`).
    ones_ratio : float, optional
        Probability ``R_a`` of a '1' bit for random codes, in the open interval (0, 1). It is
        checked for every kind but **ignored** by m-sequences and Gold codes, whose share of
        '1' bits is fixed near 0.5 (``(T + 1) / 2`` ones for an m-sequence).
    rng : numpy.random.Generator or int or None, optional
        Random source for random codes (a Generator, or a seed for
        :func:`numpy.random.default_rng`; None draws fresh entropy). Unused otherwise.
    index : int, optional
        For m-sequences, a cyclic shift (``0 <= index < T``; the code is ``roll(u, -index)``).
        For Gold codes, the family member ``0 <= index <= T + 1`` (see :func:`gold_family`).
        Must be 0 for random codes.

    Returns
    -------
    numpy.ndarray
        ``uint8`` array of 0/1 bits, shape ``(T,)``.

    Raises
    ------
    ConfigError
        Unknown kind, invalid length (the message names the nearest valid lengths),
        ``ones_ratio`` outside (0, 1), or ``index`` out of range.

    Notes
    -----
    ``R_a`` enters the signal (eq. 8) and noise (eq. 9) of the correlator output, and the SNR of
    eq. (10) grows as ``T R_a``. Random codes are drawn iid Bernoulli(``R_a``), as the paper's
    MATLAB threshold on uniform random numbers; if the draw has no '1' bit (possible only for
    tiny ``T R_a``), one bit chosen at random is set so the laser fires at least once per
    period; if it has no '0' bit, one is cleared, so the code has a timing at all (an all-ones
    7-bit draw at ``R_a = 0.99`` made the zero-mean replica zero and the weight NaN).
    m-sequences are those of :func:`scipy.signal.max_len_seq` with its default taps from
    the all-ones register state (generated bitwise identically by :func:`lfsr_sequence`).

    Examples
    --------
    A 255-bit m-sequence: (T + 1) / 2 ones, and a two-valued periodic autocorrelation

    >>> from spslidar.codes import make_code, periodic_xcorr
    >>> code = make_code("mseq", 255)
    >>> code.size, code.dtype, int(code.sum())
    (255, dtype('uint8'), 128)
    >>> r = periodic_xcorr(code, code)  # bipolar: T at zero delay, -1 at every other
    >>> int(r[0]), sorted(set(r[1:].tolist()))
    (255, [-1])
    >>> make_code("random", 255, ones_ratio=0.1, rng=0).size  # seeded Bernoulli bits
    255
    """
    kind = canonical_kind(kind)
    length = _as_int(length, "code length")
    try:
        ratio = float(ones_ratio)
    except (TypeError, ValueError):
        raise ConfigError(f"ones_ratio must be a number in (0, 1), got {ones_ratio!r}") from None
    if not (0.0 < ratio < 1.0):
        raise ConfigError(
            f"ones_ratio {ones_ratio!r} is not valid: it must lie strictly between 0 and 1"
        )
    index = _as_int(index, "code index")
    n = _check_length(kind, length)

    if kind == "random":
        if index != 0:
            raise ConfigError(f"code index {index} is not valid for random codes: use 0")
        from ..randomness import as_generator

        gen = as_generator(rng)
        code = (gen.random(length) < ratio).astype(np.uint8)
        if not code.any():
            code[gen.integers(length)] = 1
        elif code.all():  # the same for a draw without a '0' (a code with no timing)
            code[gen.integers(length)] = 0
        return code

    if kind == "mseq":
        if not 0 <= index < length:
            raise ConfigError(
                f"code index {index} is not valid for an m-sequence of length {length}: "
                f"use a cyclic shift 0..{length - 1}"
            )
        return np.roll(_mseq(n), -index)

    # gold
    if not 0 <= index <= length + 1:
        raise ConfigError(
            f"code index {index} is not valid for a Gold code of length {length}: "
            f"use a family member 0..{length + 1}"
        )
    u, v = _gold_pair_sequences(n)
    if index == 0:
        return u.copy()
    if index == 1:
        return v.copy()
    return np.bitwise_xor(u, np.roll(v, -(index - 2)))


def periodic_xcorr(a: np.ndarray, b: np.ndarray, bipolar: bool = True) -> np.ndarray:
    """Circular cross-correlation of two codes of equal length.

    Parameters
    ----------
    a, b : numpy.ndarray
        1-D codes of the same length ``T`` (0/1 bits, or integer counts when ``bipolar`` is
        False).
    bipolar : bool, optional
        Map bits to ``2 x - 1`` (+-1) before correlating (default). If False, correlate the
        values as given.

    Returns
    -------
    numpy.ndarray
        ``int64`` array ``r`` of shape ``(T,)``, ``r[k] = sum_t a'[t] b'[(t + k) mod T]``,
        computed with :mod:`scipy.fft` and rounded to the nearest integer.

    Raises
    ------
    ConfigError
        If the inputs are not 1-D arrays of the same non-zero length, hold a non-finite or
        fractional value, or values so large that a correlation could reach
        :data:`XCORR_EXACT_LIMIT` (``2**44``: ``||a'|| ||b'||``, which bounds every ``|r[k]|``,
        at or above it), past which the result would not be exact (and past ``2**63`` would
        overflow int64).

    Notes
    -----
    With ``a = b`` an m-sequence, ``r = {T at k = 0, -1 elsewhere}`` (bipolar); this is the
    correlation ``sum_t a'(t) b'(t + k)`` of eq. (1), the matched filter of eqs. (5)-(6), evaluated
    for every delay.
    """
    a = np.asarray(a)
    b = np.asarray(b)
    if np.iscomplexobj(a) or np.iscomplexobj(b):  # (cast to their real part: an audit)
        raise ConfigError("periodic_xcorr correlates real codes: got complex numbers")
    if a.ndim != 1 or b.ndim != 1 or a.size != b.size or a.size == 0:
        raise ConfigError(
            f"periodic_xcorr needs two 1-D codes of the same length, got shapes {a.shape} and "
            f"{b.shape}"
        )
    x = a.astype(np.float64)
    y = b.astype(np.float64)
    if not (np.isfinite(x).all() and np.isfinite(y).all()
            and np.array_equal(x, np.rint(x)) and np.array_equal(y, np.rint(y))):
        # (a NaN came back as -2^63 in every lag, and 0.4 counts were rounded away, an audit)
        raise ConfigError("periodic_xcorr correlates bits or whole counts: its inputs hold a "
                          "non-finite or fractional value")
    if bipolar:
        if not (np.isin(x, (0.0, 1.0)).all() and np.isin(y, (0.0, 1.0)).all()):
            # (3s and 0s read as +5 and -1: an audit of 2026-11-29)
            raise ConfigError("periodic_xcorr with bipolar=True maps 0/1 bits to -1/+1: its "
                              "inputs hold other values (use bipolar=False for counts)")
        x = 2.0 * x - 1.0
        y = 2.0 * y - 1.0
    bound = float(np.linalg.norm(x)) * float(np.linalg.norm(y))  # >= every |r[k]|
    if not bound < XCORR_EXACT_LIMIT:
        raise ConfigError(f"periodic_xcorr computes correlations below 2^44 exactly: its inputs "
                          f"could reach {bound:.3g} (||a|| ||b||); scale them down, or "
                          f"correlate them in floating point")
    period = x.size
    from scipy import fft as sp_fft  # imported on first use: a run needs no correlation here

    spec = np.conj(sp_fft.rfft(x)) * sp_fft.rfft(y)
    return np.rint(sp_fft.irfft(spec, n=period)).astype(np.int64)


def gold_bound(n: int) -> int:
    """The Gold correlation bound ``t(n) = 1 + 2^floor((n + 2) / 2)``.

    Parameters
    ----------
    n : int
        Register degree (``n >= 1``).

    Returns
    -------
    int
        ``t(n)``; e.g. 9 for n = 5, 65 for n = 10 and 11.

    Notes
    -----
    Cross-correlations within a Gold family take the values ``{-t(n), -1, t(n) - 2}`` [1]_.

    References
    ----------
    .. [1] R. Gold, IEEE Trans. Inf. Theory 13(4), 619-621 (1967).
    """
    n = _as_int(n, "register degree n")
    if n < 1:
        raise ConfigError(f"register degree n must be >= 1, got {n}")
    return 1 + 2 ** ((n + 2) // 2)


def valid_lengths(kind: str, max_n: int = 20) -> list[int]:
    """Valid code lengths of a kind, ascending.

    Parameters
    ----------
    kind : str
        Code kind or alias (see :func:`make_code`).
    max_n : int, optional
        Largest register degree to list (default 20).

    Returns
    -------
    list of int
        ``2^n - 1`` for ``n`` in :data:`MSEQ_DEGREES` (m-sequences) or :data:`GOLD_DEGREES`
        (Gold) up to ``max_n``. Random codes accept any length ``>= 2``; for them this returns
        the m-sequence lengths, so sweeps over code kinds can use comparable lengths.

    Notes
    -----
    The paper's "1024 ... 32768"-bit m-sequences are these lengths rounded (``2^n - 1``).
    """
    kind = canonical_kind(kind)
    max_n = _as_int(max_n, "max_n")
    degrees = GOLD_DEGREES if kind == "gold" else MSEQ_DEGREES
    return [2**n - 1 for n in degrees if n <= max_n]


def unambiguous_range(length: int, bit_rate: float) -> float:
    """Unambiguous range of a periodic code, in metres.

    Parameters
    ----------
    length : int
        Code period in bits ``T``.
    bit_rate : float
        Bit rate in bits per second (1 / bit width ``dt``).

    Returns
    -------
    float
        ``c T / (2 bit_rate)``; e.g. 15.33 m for ``T = 1023`` at 10 GHz, 245.6 m for 16383.

    Raises
    ------
    ConfigError
        If ``length`` or ``bit_rate`` is not positive.

    Notes
    -----
    A return delayed by more than one code period ``T dt`` wraps around (aliases) in the
    periodic correlation.
    """
    length = _as_int(length, "code length")
    if length < 1:
        raise ConfigError(f"code length must be positive, got {length}")
    try:  # (True was taken as 1 bit/s, 1.5e11 m: an audit of 2026-12-02)
        if isinstance(bit_rate, (bool, np.bool_, str, bytes)):
            raise TypeError
        rate = float(bit_rate)
    except (TypeError, ValueError):
        raise ConfigError(f"bit rate must be a positive number, got {bit_rate!r}") from None
    if not (np.isfinite(rate) and rate > 0):
        raise ConfigError(f"bit rate must be a positive number in bits/s, got {bit_rate!r}")
    return SPEED_OF_LIGHT * length / (2.0 * rate)
