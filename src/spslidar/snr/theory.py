"""Eq. (10) of Shen et al. and the input checks of :mod:`spslidar.snr`.

Only the standard library is imported at module level (the command line validates its options
before NumPy is imported); :func:`snr_theory` imports the code generators only for the kinds
whose share of ones comes from an actual code.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

__all__ = [
    "SNR_INTERVALS",
    "SNR_METHODS",
    "as_integer",
    "as_nonneg",
    "as_number",
    "check_choice",
    "check_on_fraction",
    "check_reflectivity",
    "check_size",
    "check_trials",
    "config_error",
    "default_code_index",
    "eq10",
    "code_family",
    "make_code_checked",
    "mirrors_on",
    "snr_theory",
]


def __getattr__(name: str) -> Any:
    # SNR_CODES: the code families of the registry (a family added there is one here too)
    if name == "SNR_CODES":
        from ..codes import CODES

        return CODES.names()
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")

#: Simulation paths of :func:`~spslidar.snr.snr_simulated`.
SNR_METHODS: tuple[str, ...] = ("sum", "histogram")
#: Interval estimators of :func:`~spslidar.snr.snr_simulated`.
SNR_INTERVALS: tuple[str, ...] = ("delta", "bootstrap")


def config_error(message: str) -> Exception:
    """A :class:`~spslidar.errors.ConfigError` (imported on first use)."""
    from ..errors import ConfigError

    return ConfigError(message)


def as_number(value: Any, what: str) -> float:
    """``value`` as a finite float, or ConfigError."""
    if isinstance(value, bool):
        raise config_error(f"{what} must be a number, got {value!r}")
    try:
        x = float(value)
    except (TypeError, ValueError):
        raise config_error(f"{what} must be a number, got {value!r}") from None
    if not math.isfinite(x):
        raise config_error(f"{what} must be a finite number, got {value!r}")
    return x


def as_integer(value: Any, what: str) -> int:
    """``value`` as an int (integral floats accepted), or ConfigError."""
    if isinstance(value, bool):
        raise config_error(f"{what} must be an integer, got {value!r}")
    try:
        if int(value) == value:
            return int(value)
    except (TypeError, ValueError, OverflowError):
        pass
    raise config_error(f"{what} must be an integer, got {value!r}")


def as_nonneg(value: Any, what: str) -> float:
    """``value`` as a finite non-negative float, or ConfigError."""
    x = as_number(value, what)
    if x < 0:
        raise config_error(f"{what} must be non-negative, got {value!r}")
    return x + 0.0  # (-0.0 is 0.0: it was printed "m_n=-0", an audit)


#: the largest ``N`` accepted: the simulation matches eq. (10) within its 95 % interval up to
#: here (N = 2048 and 8192: simulated / theory 1.014 and 1.013, 400 periods), while at
#: N = 65536 (4.3 G mirrors, no DMD has them) its sums lose precision (0.84)
MAX_SIZE = 8192


def check_size(size: Any) -> int:
    """Pixels per side ``N``: an integer in [1, ``MAX_SIZE``] (8192), or ConfigError."""
    n = as_integer(size, "size N")
    if not 1 <= n <= MAX_SIZE:
        raise config_error(f"size N must be a number of pixels per side in [1, {MAX_SIZE}], "
                           f"got {size!r}")
    return n


def check_on_fraction(on_fraction: Any) -> float:
    """Share ``F`` of mirrors on, in (0, 1], or ConfigError."""
    f = as_number(on_fraction, "on-fraction")
    if not 0.0 < f <= 1.0:
        raise config_error(f"on-fraction must lie in (0, 1], got {on_fraction!r}")
    return f


def check_reflectivity(reflectivity: Any) -> float:
    """Reflectivity ``a`` in [0, 1], or ConfigError."""
    a = as_number(reflectivity, "reflectivity")
    if not 0.0 <= a <= 1.0:
        raise config_error(f"reflectivity must lie in [0, 1], got {reflectivity!r}")
    return a


#: most code periods one ``snr`` simulation draws: the estimate's relative standard error is
#: about ``sqrt(2 / trials)``, 0.045 % at this cap, and the draws take 80 MB (10^9 took 43 s
#: and then ran out of memory)
MAX_TRIALS = 10**7


def check_trials(trials: Any) -> int:
    """Number of simulated periods, at least 2 (a variance needs two) and at most
    :data:`MAX_TRIALS`, or ConfigError."""
    k = as_integer(trials, "trials")
    if k < 2:
        raise config_error(f"trials must be at least 2 to estimate a variance, got {trials!r}")
    if k > MAX_TRIALS:
        raise config_error(f"--trials {k} is more than the {MAX_TRIALS:.0e} periods that pin "
                           f"the SNR to 0.045 % (relative error sqrt(2 / trials)); use fewer")
    return k


def check_choice(value: Any, choices: Sequence[str], what: str) -> str:
    """``value`` if it is one of ``choices``, or ConfigError naming them."""
    if value not in choices:
        raise config_error(f"unknown {what} {value!r}; choose {' or '.join(choices)}")
    return str(value)


#: how far (relative) a realised share of mirrors on or of a code's ones may lie from the one
#: asked for before it is said (a pattern has whole mirrors, a code whole bits)
REALISED_TOLERANCE = 0.1


def realised_far(realised: float, asked: float) -> bool:
    """Whether a whole count ``realised`` lies more than :data:`REALISED_TOLERANCE` (relative)
    from the ``asked`` one it rounds (mirrors on, a random code's ones)."""
    return abs(realised - asked) > REALISED_TOLERANCE * asked


def mirrors_on(on_fraction: float, size: int) -> int:
    """Number ``M_2`` of DMD mirrors switched on in a binary pattern.

    Parameters
    ----------
    on_fraction : float
        Share of mirrors on, ``F`` in (0, 1].
    size : int
        Pixels per side ``N`` (the DMD pattern is ``N x N``).

    Returns
    -------
    int
        ``M_2 = max(1, round(F N^2))``: a binary pattern has a whole number of mirrors on.

    Raises
    ------
    ConfigError
        If ``F`` is outside (0, 1] or ``N`` is not a positive integer.

    Notes
    -----
    ``M_2`` is the number of "on" pixels in eq. (8) and (10) of Shen et al.
    """
    f = check_on_fraction(on_fraction)
    n = check_size(size)
    m2 = max(1, int(round(f * n * n)))
    if realised_far(m2, f * n * n):
        import warnings

        # (--on-fraction 1e-300 at 8x8 ran with one mirror on, unsaid: an outside audit)
        warnings.warn(f"--on-fraction {f:g} of {n} x {n} mirrors is {f * n * n:.3g} mirrors: "
                      f"{m2} {'is' if m2 == 1 else 'are'} on (share {m2 / (n * n):.3g}), "
                      f"which eq. (10) is computed with", UserWarning, stacklevel=2)
    return m2


def eq10(ones: float, m2: int, a: float, m_s: float, n: int, m_n: float) -> float:
    """Eq. (10) with ``R_a T`` given as the number of '1' bits ``ones`` (a random code's
    expected number, ``r T``, need not be whole)."""
    sig = m2 * a * m_s  # signal photons per '1' bit of the code
    noise = n * n * m_n  # noise counts per TDC bin
    if sig + noise <= 0.0:
        raise config_error(
            "signal and noise are both zero (m_s * reflectivity = 0 and m_n = 0): the SNR is "
            "undefined"
        )
    return ones * sig * sig / (sig + noise)


def code_family(kind: str) -> str:
    """The registered code family (:data:`spslidar.codes.CODES`) that ``kind`` names, or
    whose alias it is (``'m-sequence'``, ``'bernoulli'``...)."""
    from ..codes import CODES, canonical_kind

    return kind if kind in CODES else canonical_kind(kind)


def default_code_index(kind: str, index: Any = None) -> int:
    """The family member / cyclic shift a code uses: ``index`` where given, else the
    family's default, as ``run`` takes it (Gold: member 2, the first true Gold code; members
    0 and 1 are the preferred pair's m-sequences; m-sequence and random: 0)."""
    from ..codes import CODES

    if index is not None:
        return as_integer(index, "code index")
    return int(CODES.get(code_family(kind)).defaults.get("index", 0))


def chosen_code_options(kind: str, options: dict[str, Any] | None = None) -> dict[str, Any]:
    """The options code family ``kind`` declares, as a code is made with them: those in
    ``options``, each checked by its declaration, the others at their defaults; one the
    family does not declare is a ConfigError."""
    from ..codes import CODES

    name = code_family(kind)
    entry = CODES.get(name)
    declared = {o.name: o for o in entry.options}
    given = dict(options or {})
    for key in given:
        if key not in declared:
            raise config_error(f"--{key.replace('_', '-')} is not an option of --code {name}"
                               + (f" (it takes {', '.join(o.flag for o in entry.options)})"
                                  if entry.options else " (it takes none)"))
    return {k: o.check(given[k]) if k in given else o.default for k, o in declared.items()}


def make_code_checked(kind: str, length: Any, ones_ratio: Any, rng, index: Any = None,
                      options: dict[str, Any] | None = None):
    """The code (uint8 0/1) of a registered family, built by its registry entry after the
    entry's own checks (the lengths it can have; a ones ratio only where the family has one),
    so ``snr`` takes exactly the codes ``run`` takes, with the same default member
    (:func:`~spslidar.snr.theory.default_code_index`) and the options the family declares
    (``chosen_code_options`` of this module); ConfigError on bad input."""
    from types import SimpleNamespace

    from ..codes import CODES

    name = code_family(kind)
    length = as_integer(length, "code length")
    index = default_code_index(name, index)
    entry = CODES.get(name)
    chosen = chosen_code_options(name, options)
    entry.check(SimpleNamespace(code=name, code_length=length, ones_ratio=ones_ratio,
                                code_index=index, **chosen))
    return entry.load()(name, length, ones_ratio, rng, index, **chosen)



def snr_theory(
    code_length: int,
    ones_ratio: float,
    signal: float,
    noise: float,
    size: int,
    on_fraction: float,
    reflectivity: float = 1.0,
    *,
    code: str | None = None,
    code_index: int | None = None,
) -> float:
    """Output SNR of one pattern's matched filter over one code period, eq. (10).

    Parameters
    ----------
    code_length : int
        Code length ``T`` in bits (``2^n - 1`` for m-sequences and Gold codes).
    ones_ratio : float
        Share ``R_a`` of '1' bits. Used as given when ``code`` is None or ``'random'`` (the
        expected share of a Bernoulli code); for ``'mseq'`` and ``'gold'``, whose share is that
        of the actual code, it must be left at 0.5 (another value is refused, as by ``run``).
    signal : float
        ``m_s``: mean signal photons per laser pulse per DMD pixel (mirror on, reflectivity 1).
    noise : float
        ``m_n``: mean noise counts per TDC bin per pixel (``N^2 m_n`` per bin in total).
    size : int
        Pixels per side ``N``.
    on_fraction : float
        Share ``F`` of mirrors on in the binary pattern, in (0, 1]: ``M_2 = round(F N^2)``.
    reflectivity : float, optional
        Mean reflectivity ``a`` of the pixels that are on, in [0, 1] (default 1).
    code : {None, 'mseq', 'gold', 'random'}, optional
        None (default): the formula with ``R_a = ones_ratio`` and any ``T >= 1``. A code kind:
        ``R_a`` is the share of ones of the code :func:`spslidar.codes.make_code` generates
        (``(T + 1) / (2 T)`` for an m-sequence), or ``ones_ratio`` for ``'random'``.
    code_index : int or None, optional
        Member of the Gold family / cyclic shift of the m-sequence (default None: ``run``'s
        default, member 2 for Gold codes, the first true Gold code; members 0 and 1 are the
        two m-sequences of the preferred pair; shift 0 for m-sequences).

    Returns
    -------
    float
        ``T R_a (M_2 a m_s)^2 / (M_2 a m_s + N^2 m_n)``.

    Raises
    ------
    ConfigError
        If a parameter is out of range (negative photon numbers, ``F`` outside (0, 1], an
        invalid code length for the kind...) or if signal and noise are both zero.

    Notes
    -----
    Eq. (10) of Shen et al. is the ratio of the squared mean signal of eq. (8),
    ``E[C_s] = T R_a M_2 a m_s``, to the variance of signal plus noise, eq. (9),
    ``Var[C] = R_a T M_2 a m_s + R_a T N^2 m_n`` (Poisson counts: variance = mean; the
    unipolar replica sums the counts of the ``R_a T`` bits where the code is on). The paper
    writes the noise as ``N^2 m_n^(1) + m_n^(2) + m_n^(3)``; following ``docs/reading.md`` all three
    terms are per pixel here, ``N^2 m_n`` in total
    (:class:`spslidar.detectors.counting.NoiseModel`).
    The SNR grows linearly with ``T`` and ``R_a``.

    Examples
    --------
    >>> round(snr_theory(1023, 0.5, 5.0, 10.0, 64, 0.5))  # 511.5 * 10240^2 / 51200
    1047552
    """
    m_s = as_nonneg(signal, "signal m_s")
    m_n = as_nonneg(noise, "noise m_n")
    a = check_reflectivity(reflectivity)
    m2 = mirrors_on(on_fraction, size)
    n = check_size(size)
    if code is None:
        t = as_integer(code_length, "code length")
        if t < 1:
            raise config_error(f"code length must be a positive integer, got {code_length!r}")
        r = as_number(ones_ratio, "ones ratio")
        if not 0.0 < r <= 1.0:
            raise config_error(f"ones ratio must lie in (0, 1], got {ones_ratio!r}")
        ones: float = r * t
    else:
        kind = code_family(code)
        if kind == "random":
            t = as_integer(code_length, "code length")
            if t < 2:
                raise config_error(f"code length {t} is too short: random codes need length >= 2")
            r = as_number(ones_ratio, "ones ratio")
            if not 0.0 < r < 1.0:
                raise config_error(f"ones ratio must lie strictly between 0 and 1, got {r!r}")
            ones = r * t
        else:
            c = make_code_checked(kind, code_length, ones_ratio, None, code_index)
            ones = int(c.sum())
    return float(eq10(ones, m2, a, m_s, n, m_n))


def __dir__() -> list[str]:
    # the lazy names too, so dir() and a REPL's completion list them (an audit of 2026-11-30)
    return sorted(set(globals()) | set(__all__))
