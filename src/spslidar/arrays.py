"""Checks of the arrays the public functions take, each refused in one line naming it.

The stages' own entry points (the operators, the depth estimators, the scenes) check their
inputs; the helpers of the chain below them (``forward``, ``correlate``, ``qcr``,
``metrics``, ``products``) read what numpy made of theirs, so that a user calling them
directly got silent wrong answers: integer profiles truncated, fractional lags read as the
bin below, complex data cast to its real part, a ``(3, N)`` point array written as scrambled
points (an outside audit of the Python API, 2026-11-29). These few checks are what numpy has
no single call for (``np.asarray`` casts without a word; ``np.can_cast`` says nothing of
fractions or shapes). Each raises :class:`~spslidar.errors.SpslidarError`, a ``ValueError``
the command line prints as one line.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from .errors import SpslidarError


def real_array(a: Any, what: str, *, ndim: int | None = None, floating: bool = False,
               finite: bool = False) -> np.ndarray:
    """``a`` as a real numeric array, or one line naming ``what``.

    Refuses a masked array (its mask would be dropped), complex numbers (their imaginary
    part would be dropped with only numpy's ``ComplexWarning``), anything that is not
    numbers, a number of dimensions other than ``ndim`` and, with ``finite``, a NaN or an
    infinity. With ``floating``, integers and booleans come back as float64 (an integer
    profile's arithmetic cast back to its dtype truncated it); floating arrays keep their
    dtype. The array is not copied where numpy need not.
    """
    if isinstance(a, np.ma.MaskedArray):
        raise SpslidarError(f"{what} is a masked array: fill the masked entries first "
                            f"(e.g. a.filled(0))")
    arr = np.asarray(a)
    if np.iscomplexobj(arr):
        raise SpslidarError(f"{what} holds complex numbers: it must be real")
    if arr.dtype.kind not in "biuf":
        raise SpslidarError(f"{what} must hold numbers, got dtype {arr.dtype}")
    if ndim is not None and arr.ndim != ndim:
        raise SpslidarError(f"{what} must have {ndim} dimension{'s' if ndim != 1 else ''}, "
                            f"got shape {arr.shape}")
    if floating and arr.dtype.kind in "biu":
        arr = arr.astype(np.float64)
    if finite and arr.dtype.kind == "f" and not np.isfinite(arr).all():
        raise SpslidarError(f"{what} holds a NaN or an infinity")
    return arr


def whole_numbers(a: Any, what: str, unit: str = "bins") -> np.ndarray:
    """``a`` as a flat int64 array of whole numbers (delays, shifts, lags), or one line:
    a fraction or a NaN was truncated to the bin below or to an arbitrary one (``1.9`` read
    as 1), where :func:`spslidar.correlate.matched_filter` refused them."""
    arr = real_array(a, what)
    if arr.dtype.kind == "f" and not (np.isfinite(arr).all()
                                      and np.array_equal(arr, np.round(arr))):
        raise SpslidarError(f"{what} must be whole {unit}: got fractions, a NaN or an "
                            f"infinity")
    if arr.dtype.kind == "u" and arr.size and arr.max() > np.iinfo(np.int64).max:
        raise SpslidarError(f"{what} holds a value past int64")
    return arr.astype(np.int64, copy=False).ravel()


def positive_number(v: Any, what: str, *, integer: bool = False,
                    unit: str = "", zero: bool = False) -> float | int:
    """``v`` as a finite positive number (a whole one with ``integer``; ``zero``: 0 too), or
    one line: a zero bin width gave infinite delays with a warning, a negative one negative
    delays, a negative count of periods negative means."""
    ok = (not isinstance(v, (bool, np.bool_, str, bytes)) and np.ndim(v) == 0
          and not np.iscomplexobj(v))
    try:
        x = float(v) if ok else float("nan")
    except (TypeError, ValueError):
        x = float("nan")
    if not (np.isfinite(x) and (x >= 0 if zero else x > 0)
            and (not integer or x.is_integer())):
        kind = (f"a whole number >= {0 if zero else 1}" if integer
                else "a number >= 0" if zero else "a positive number")
        kind += f" of {unit}" if unit else ""
        raise SpslidarError(f"{what} must be {kind}, got {v!r}")
    return int(x) if integer else x


def real_number(value: Any) -> float | None:
    """``value`` as a float where it is a real number (not a bool, text or bytes, which
    ``float()`` takes: ``dead_time=False`` read as 0 and ``'1e-7'`` was taken, an outside
    audit of 2026-11-30), else ``None``: the caller says what it wanted, in its own words
    (``--dead-time``, ``--settle``)."""
    if isinstance(value, np.ndarray) and value.ndim == 0:  # a 0-d array is its number
        value = value[()]
    if isinstance(value, bool | np.bool_) or not isinstance(value, int | float | np.integer
                                                              | np.floating):
        return None
    return float(value)


def pair_shape(shape: Any, what: str, least: int) -> tuple[int, int]:
    """``shape`` as two whole numbers of at least ``least``; one clear ``ValueError``
    otherwise (an int for a pair was "'int' object is not subscriptable", an audit; a bool
    was read as 1 and 4.7 as 4, a review of 2026-12-02). The image shapes of the operators,
    the regularisers, the depth estimators' context and the point cloud's rays."""
    from .errors import ConfigError

    try:
        a, b = shape
        if isinstance(a, (bool, np.bool_, str, bytes)) or isinstance(b, (bool, np.bool_, str,
                                                                          bytes)):
            raise TypeError
        out = (int(a), int(b))
    except (TypeError, ValueError):
        raise ConfigError(f"{what} must be a pair of whole numbers, got {shape!r}") from None
    if out != (a, b) or min(out) < least:
        raise ConfigError(f"{what} must be a pair of whole numbers >= {least}, got {shape!r}")
    return out


def floating_dtype(dtype: Any, name: str = "dtype", why: str = "") -> np.dtype:
    """``dtype`` as a real floating NumPy dtype, or one line naming ``name`` (``why``: what
    the caller needs it for). The check of the patterns', the centred patterns', a matrix
    operator's and the matched filter's dtypes (an integer one truncated or zeroed them, a
    complex one failed at the first product: audits)."""
    from .errors import ConfigError

    try:
        dt = np.dtype(dtype)
    except TypeError:
        dt = None
    if dt is None or dt.kind != "f":
        raise ConfigError(f"{name} must be a real floating type{why}, got "
                          f"{dtype if dt is None else dt}; use float32 or float64")
    return dt


def real_scalar(value: Any, name: str, *, low: float | None = None,
                finite: bool = False) -> float:
    """``value`` as a float where it is a real number (a Python or NumPy integer or float, or
    a 0-d array of one), or a one-line :class:`~spslidar.errors.ConfigError` naming ``name``.

    Text, ``None``, booleans, complex numbers and arrays are refused (``lam="0.1"``,
    ``StopRule(rtol="1e-3")``, ``efficiency="0.5"`` failed in a comparison or a ufunc naming
    no argument, and ``float(True)`` is 1: an outside audit of 2026-12-02). Where ``low`` is
    given, NaN and values below it are refused too, and with ``finite`` infinities; without
    ``low`` only the type is checked and the caller checks the range in its own words.
    Callers that need their own value (a NumPy scalar computing as before) keep it and use
    this as a check.
    """
    from .errors import ConfigError

    if low is None:
        want = "a finite number" if finite else "a number"
    elif low == -np.inf:  # any number but NaN
        want = "a finite number" if finite else "a number, not NaN"
    else:
        bound = "non-negative" if low == 0 else f">= {low:g}"
        want = f"finite and {bound}" if finite else f"a {bound} number"
    x = real_number(value)
    if x is None or (low is not None and (np.isnan(x) or x < low)) or (
            finite and not np.isfinite(x)):
        raise ConfigError(f"{name} must be {want}, got {value!r}")
    return x


def same_length(a: np.ndarray, n: int, what: str, of: str) -> None:
    """Refuse (one line) ``a`` whose length is not ``n``, the length of ``of``: numpy's
    broadcast and matmul errors named neither argument."""
    if np.ndim(a) != 1 or np.size(a) != n:
        raise SpslidarError(f"{what} of shape {np.shape(a)} for {of} of {n}: one entry each")
