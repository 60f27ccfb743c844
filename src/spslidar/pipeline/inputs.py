"""The user's inputs to a measured acquisition, checked: the patterns shown, the code, the
PTU path(s), the range gate and a ground truth.

Each ``check_*`` takes what the Python API is given (an array, a list) and refuses in one
line (:class:`~spslidar.errors.ConfigError`) what cannot be used; each ``load_*`` reads a
user's file first (:mod:`spslidar.io.lab_arrays`: a ``.npy``, a folder of DMD images, a
MATLAB file, a text file of bits). :mod:`spslidar.pipeline.real` and
:mod:`spslidar.pipeline.calibration` take them from here (``real`` re-exports them, their
public home since they were written).
"""

from __future__ import annotations

import math
import os
from pathlib import Path
from typing import Any

import numpy as np

from ..constants import MAX_DEPTH_M
from ..errors import ConfigError

__all__ = ["check_bit_rate", "check_code", "check_gate", "check_pattern_size", "check_patterns",
           "check_ptu_path", "code_in", "input_record", "load_code", "load_patterns",
           "patterns_in"]


def load_patterns(path: str | os.PathLike, distinct: bool = True,
                  size: int | None = None) -> np.ndarray:
    """``(M, N, N)`` mirror states (0/1 or grey levels in [0, 1]) as float32 ``(M, N*N)``,
    checked by :func:`check_patterns`: a ``.npy``, an ``.npz`` or MATLAB ``.mat`` file, a
    multi-page TIFF or a folder of images, one per pattern
    (:func:`spslidar.io.lab_arrays.read_patterns_file` gives each file's conventions);
    ``size``: read each as ``size x size`` blocks of mirrors (``--pattern-size``)."""
    from ..io.lab_arrays import read_patterns_file

    return check_patterns(read_patterns_file(path, check_pattern_size(size)), distinct,
                          f"--patterns {path}")


def patterns_in(patterns: Any, size: Any = None, distinct: bool = True) -> np.ndarray:
    """The patterns a caller gives: a path read by :func:`load_patterns` (inside the caller's
    kept warnings, so a reader's word reaches ``metrics.json``), or an array checked by
    :func:`check_patterns`; ``size`` as :func:`load_patterns`'s."""
    if isinstance(patterns, (str, os.PathLike)):
        return load_patterns(patterns, distinct, size)
    size = check_pattern_size(size)
    if size is not None:
        from ..io.lab_images import reduce_patterns

        patterns = reduce_patterns(_as_array(patterns, "patterns"), size, "patterns")
    return check_patterns(patterns, distinct, "patterns")


def code_in(code: Any) -> np.ndarray:
    """The code a caller gives: a file's path read by :func:`load_code`, or an array checked
    by :func:`check_code` (a family's name is refused, naming how to get its bits: the API
    has no ``code_length``)."""
    if isinstance(code, (str, os.PathLike)):
        if is_family(code):
            raise ConfigError(f"code={os.fspath(code)!r} names a code family: give its bits, "
                              f"spslidar.pipeline.real.load_code({os.fspath(code)!r}, L) "
                              f"for L bits")
        return load_code(code)
    return check_code(code, None, "code")


def is_family(code: Any) -> bool:
    """Whether ``--code`` names a registered code family (``mseq``, ``gold``, a plugin's)
    rather than a file: its name, any case, and no file of that name (one there too is
    refused by :func:`load_code`)."""
    name = os.fspath(code) if isinstance(code, os.PathLike) else str(code)
    return not Path(name).exists() and _names_family(name)


def _names_family(name: str) -> bool:
    """Whether ``name`` is a registered code family's, any case (a file of that name or not)."""
    from ..codes import CODES

    return name.lower() in {n.lower() for n in CODES.names()}


def input_record(patterns_given: Any, patterns: np.ndarray, pattern_size: int | None,
                 code_given: Any, code: np.ndarray) -> dict[str, Any]:
    """What a measured acquisition's patterns and code were read from, for ``metrics.json``
    (``inputs``) and ``CAL.json`` (``measured_from.inputs``): each file as given (None for an
    array), ``--pattern-size``, and the SHA-256 of what was read, the patterns as float32
    ``(M, N*N)`` rows and the code as one byte a bit, so two runs can be told to have used
    the same patterns and code whatever the files' formats (a folder of PNGs and its
    ``.npy`` hash alike)."""
    import hashlib

    from .calibration_file import code_sha256

    def given(value: Any) -> str | None:
        return os.fspath(value) if isinstance(value, (str, os.PathLike)) else None

    rows = np.ascontiguousarray(patterns, dtype=np.float32)
    return {"patterns": {"file": given(patterns_given),
                         "pattern_size": check_pattern_size(pattern_size),
                         "n_patterns": int(rows.shape[0]),
                         "side": int(round(np.sqrt(rows.shape[1]))),
                         "sha256": hashlib.sha256(rows.tobytes()).hexdigest()},
            "code": {"file": given(code_given), "family": None, "bits": int(np.size(code)),
                     "sha256": code_sha256(code)}}


def check_pattern_size(size: Any) -> int | None:
    """``--pattern-size`` as a whole number of 4 or more, or None; one line otherwise."""
    if size is None:
        return None
    from ..arrays import real_number

    value = real_number(size)
    if value is None or not (value == value and abs(value) < 2**31 and value == int(value)
                             and value >= 4):
        raise ConfigError(f"--pattern-size must be a whole number of 4 or more (the patterns' "
                          f"side N), got {size!r}")
    return int(value)


#: how far outside [0, 1] a pattern's values may lie and be taken as the rounding of grey
#: levels computed in floating point (clipped): about eight of float32's steps above 1
PATTERN_ROUNDOFF = 1e-6


def check_patterns(patterns: Any, distinct: bool = True, what: str = "patterns") -> np.ndarray:
    """Mirror states shown, ``(M, N, N)`` or ``(M, N*N)``, as float32 ``(M, N*N)`` (integers
    are stored levels, read as images are: :func:`spslidar.io.lab_images.to_states`, so
    uint8 0/255 is 0/1 and 8-bit grey is divided by 255); refused in one line
    (:class:`ConfigError`) where they cannot be (fewer than 2 patterns, fewer than 4 x 4
    mirrors, not square, not real numbers in [0, 1]) or cannot form an image: every
    mirror off, or (with ``distinct``, a scene's reconstruction) M copies of one pattern. A
    calibration may show one pattern throughout (``distinct=False``)."""
    arr = _as_array(patterns, what)
    if arr.ndim == 2 and arr.shape[0] >= 2:
        side = int(round(np.sqrt(arr.shape[1])))
        if side * side == arr.shape[1]:
            arr = arr.reshape(arr.shape[0], side, side)
    if arr.ndim != 3 or arr.shape[1] != arr.shape[2] or arr.shape[0] < 2 or arr.shape[1] < 4:
        # (an N^2 x M matrix, one pattern per column, was refused without naming the
        # transpose: an outside audit of 2026-12-01)
        rows = arr.shape[0] if arr.ndim == 2 else 0
        side = math.isqrt(rows)
        hint = (f": one pattern of {side} x {side} per column? save its transpose (A.T)"
                if arr.ndim == 2 and rows >= 16 and side * side == rows
                and arr.shape[1] >= 2 else "")
        raise ConfigError(f"{what} must be an (M, N, N) array (or (M, N*N)) with M >= 2 "
                          f"patterns of N x N >= 4 x 4 mirrors, got shape {arr.shape}{hint}")
    _real_numbers(arr, what)
    if np.issubdtype(arr.dtype, np.integer):
        # stored levels, read as an image's wherever they come from (a .mat of imread's
        # uint8 was, while the same array as a .npy or in Python was refused: an audit):
        # binary as 0/1 at any level, 8- and 16-bit grey over their full scale
        from ..io.lab_images import to_states

        arr = to_states(arr, what)
    arr = np.asarray(arr, dtype=np.float64)
    if not np.all(np.isfinite(arr)):
        bad = int(np.count_nonzero(~np.isfinite(arr)))
        raise ConfigError(f"{what} holds {bad} NaN or infinite value(s): mirror states are "
                          f"numbers in [0, 1] (0/1 or grey levels)")
    lo, hi = float(arr.min()), float(arr.max())
    if lo < 0 or hi > 1:
        if lo >= -PATTERN_ROUNDOFF and hi <= 1 + PATTERN_ROUNDOFF:
            # grey levels computed in floating point: float32's 1.0000001, a pattern scaled
            # by (1 + 1e-12) or less 1e-9 were refused as "got values from 0 to 1" and as
            # "+1/-1 differences?" (an outside audit of 2026-12-02)
            arr = np.clip(arr, 0.0, 1.0)
        else:
            # (a DMD bitplane saved as 0/255 uint8 was told only "must hold ... [0, 1]")
            hint = (": 8-bit levels 0-255? divide by 255" if lo >= 0 and hi <= 255
                    and np.all(arr == np.round(arr)) else
                    ": +1/-1 differences? give the two complementary patterns as rows of "
                    "their own" if -1 <= lo <= -0.5 and hi <= 1 else "")
            raise ConfigError(f"{what} must hold mirror states in [0, 1] (0/1 or grey "
                              f"levels), got values from {lo:.9g} to {hi:.9g}{hint}")
    flat = arr.reshape(arr.shape[0], -1)
    if not flat.any():
        raise ConfigError(f"{what}: every mirror of every pattern is off, so no light reaches "
                          f"the scene")
    if distinct and np.all(flat == flat[0]):
        # the reconstruction (QCR, eq. 11-17) uses how the patterns differ from their mean:
        # the same pattern M times measures one number per delay, not an image
        raise ConfigError(f"{what}: all {arr.shape[0]} patterns are the same, so they hold no "
                          f"spatial information (single-pixel imaging needs patterns that "
                          f"differ)")
    return flat.astype(np.float32)


def _as_array(value: Any, what: str) -> np.ndarray:
    """``value`` as a NumPy array (a list is fine), or one line."""
    if isinstance(value, np.ndarray):
        return value
    try:
        return np.asarray(value)
    except (ValueError, TypeError) as exc:
        raise ConfigError(f"{what} must be an array of numbers ({exc})") from None


def _real_numbers(arr: np.ndarray, what: str) -> None:
    """Refuse an array whose dtype is not real numbers (complex numbers, strings, objects);
    booleans are taken as 0/1."""
    if not (np.issubdtype(arr.dtype, np.number) or arr.dtype == np.bool_) or \
            np.issubdtype(arr.dtype, np.complexfloating):
        raise ConfigError(f"{what} must hold real numbers, got dtype {arr.dtype}")


def _check_truth(truth: Any, n: int) -> np.ndarray:
    """``truth`` as an ``(n, n)`` float64 depth map in metres, NaN where unknown; one line for
    anything else: a complex, boolean or non-numeric array (a complex one was cast to its
    real part with a library warning, a boolean mask scored as depths of 0 and 1 m), an
    infinite, negative or zero depth (zero is "no data" in many datasets), or one beyond
    :data:`~spslidar.constants.MAX_DEPTH_M`."""
    arr = _as_array(truth, "--truth")
    if arr.dtype == np.bool_:
        raise ConfigError("--truth holds booleans (a mask?): a depth map in metres is expected, "
                          "NaN where the depth is unknown")
    if arr.dtype.kind not in "iuf":
        raise ConfigError(f"--truth must be a ({n}, {n}) depth map in metres of real numbers, "
                          f"got dtype {arr.dtype}")
    arr = arr.astype(np.float64)
    if arr.shape != (n, n):
        raise ConfigError(f"--truth must be a ({n}, {n}) depth map, got {arr.shape}")
    known = ~np.isnan(arr)
    if not known.any():  # (refused after the file was read, naming the PTU as a "scene")
        raise ConfigError("--truth holds no depth (every pixel is NaN): give the depths in "
                          "metres where they are known, or leave --truth out")
    bad = int(np.count_nonzero(known & (np.isinf(arr) | (arr < 0))))
    if bad:
        raise ConfigError(f"--truth has {bad} infinite or negative depths (depths are finite "
                          f"metres >= 0; NaN marks a pixel without a truth)")
    zeros = int(np.count_nonzero(known & (arr == 0)))
    if zeros:  # (0 for "no data" was scored as a depth: a 16x16 plane read 9.29 m for 0.028)
        raise ConfigError(f"--truth has {zeros} depths of 0 m, where a lidar measures no "
                          f"distance: mark pixels without a truth NaN (0 is 'no data' in many "
                          f"depth datasets)")
    if known.any() and float(arr[known].max()) > MAX_DEPTH_M:
        raise ConfigError(f"--truth holds depths up to {float(arr[known].max()):.3g} m, beyond "
                          f"any lidar range (at most {MAX_DEPTH_M:.0e} m): are the values in "
                          f"metres?")
    return arr


def load_code(code: str | os.PathLike, code_length: int | None = None,
              code_index: int | None = None) -> np.ndarray:
    """The unipolar code of one period: a file of its bits (a ``.npy``; a text file of 0/1
    characters or of 0/1 or -1/+1 numbers; a ``.mat`` or ``.npz`` vector:
    :func:`spslidar.io.lab_arrays.read_code_file`), or the name of a registered
    code family (:data:`spslidar.codes.CODES`: ``mseq``, ``gold``, a plugin's) with
    ``code_length`` and, optionally, ``code_index`` (the family's member or shift, as
    ``spslidar run --code-index``; default the family's, as ``run``'s). A family that draws
    its bits from a seed (``random``) is refused: its bits are the ``.npy`` that ``run
    --save-ptu`` writes beside its file."""
    from ..codes import CODES

    name = str(code)
    if Path(name).exists() and _names_family(name):
        # (a file named mseq in the folder was read for the family without a word, a stale
        # copy of the code 0.57 m off: an audit of stop 67)
        raise ConfigError(f"--code {name} names both the code family and a "
                          f"{'folder' if Path(name).is_dir() else 'file'} in this folder: "
                          f"give ./{name} for the file, or run where there is none for the "
                          f"family")
    if is_family(name):
        name = CODES.canonical(name)
        if code_length is None:
            raise ConfigError(f"--code {name} needs --code-length L")
        entry = CODES.get(name)
        index = entry.defaults.get("index", 0) if code_index is None else code_index
        if isinstance(index, bool) or not isinstance(index, int | np.integer) or index < 0:
            raise ConfigError(f"--code-index must be a whole number >= 0, got {index!r}")
        file = "give its bits as a .npy of 0/1 bits (run --save-ptu writes <stem>_code.npy)"
        if entry.options:  # (reconstruct has no flag for them: the code run made may differ)
            raise ConfigError(f"--code {name} takes options ("
                              f"{', '.join(o.flag for o in entry.options)}): {file}")
        make = entry.load()
        bits = [np.asarray(make(name, int(code_length), ratio, rng=np.random.default_rng(seed),
                                index=int(index)), dtype=np.uint8)
                for seed, ratio in ((0, 0.5), (1, 0.5), (0, 0.3))]
        if not np.array_equal(bits[0], bits[1]):
            raise ConfigError(f"--code {name} draws its bits from a seed: {file}")
        if not np.array_equal(bits[0], bits[2]):  # (run --ones-ratio: no flag here either)
            raise ConfigError(f"--code {name}'s bits depend on its ones ratio: {file}")
        return check_code(bits[0], code_length, f"--code {name}")
    if code_index is not None:
        raise ConfigError(f"--code-index is for a code family's name (mseq, gold), not a "
                          f"file: {name}")
    from ..io.lab_arrays import read_code_file

    return check_code(read_code_file(code), code_length, f"--code {code}")


def check_code(code: Any, code_length: int | None = None, what: str = "code") -> np.ndarray:
    """The unipolar bits of one code period as uint8; refused in one line
    (:class:`ConfigError`) unless a 1-D array of real 0/1 values with both present (and of
    ``code_length`` bits where that is given). The bipolar form of a code, -1/+1 (both
    present, nothing else), is the same code: -1 is read as 0, the laser off."""
    arr = _as_array(code, what)
    if arr.ndim != 1 or arr.size < 2:
        raise ConfigError(f"{what} must be a 1-D array of 0/1 bits, got shape {arr.shape}")
    _real_numbers(arr, what)
    if arr.dtype != np.bool_ and np.any(arr == -1) and np.all((arr == -1) | (arr == 1)):
        arr = (arr == 1).astype(np.uint8)  # (a MATLAB lab's code as +-1: the same bits)
    bad = ~((arr == 0) | (arr == 1))
    if bad.any():
        raise ConfigError(f"{what} must hold 0/1 bits (unipolar, one period; or -1/+1), got "
                          f"{int(bad.sum())} other values (first: {arr[bad][0].item()!r})")
    if code_length is not None and int(code_length) != arr.size:
        raise ConfigError(f"--code-length {code_length} disagrees with {what}, which holds "
                          f"{arr.size} bits (--code-length is for a named code family)")
    ones = int(arr.sum())
    if ones in (0, arr.size):  # no modulation: nothing to correlate with
        raise ConfigError(f"{what}: all {arr.size} bits are {int(ones > 0)}; a code needs "
                          f"both 0 and 1 bits (the laser is modulated by them)")
    return arr.astype(np.uint8)


def check_ptu_path(ptu: Any) -> list:
    """The PTU file(s): a path (str or os.PathLike), or a non-empty list or tuple of them
    (an acquisition saved one file per pass), as a list; one line otherwise (the reader
    checks that each names a regular file)."""
    many = isinstance(ptu, (list, tuple))
    files = list(ptu) if many else [ptu]
    if not files or not all(isinstance(f, (str, os.PathLike)) for f in files):
        got = "an empty list" if many and not files else type(ptu).__name__
        raise ConfigError(f"ptu must be the path of a PTU file (or a list of them), got {got}")
    seen: dict[str, Any] = {}
    for f in files:  # (a file given twice was summed with itself, without a word: a review)
        key = os.path.realpath(os.fspath(f))
        if key in seen:
            raise ConfigError(f"the PTU file {os.fspath(f)!r} is given twice (as "
                              f"{os.fspath(seen[key])!r} too): each pass once")
        seen[key] = f
    return files


def check_bit_rate(bit_rate: Any) -> float:
    """A measured file's ``--bit-rate`` as a float of bits (TDC bins) per second in [1e6,
    1e13], the range ``run`` takes, or one line (``reconstruct``, ``calibrate`` and
    ``inspect`` say it alike: ``inspect`` said "a positive number", an audit)."""
    if isinstance(bit_rate, (str, bytes, bool, np.bool_)):  # (float('10e9') was taken)
        raise ConfigError(f"--bit-rate must be a number of bits per second, got {bit_rate!r}")
    try:
        rate = float(bit_rate)
    except (TypeError, ValueError):
        raise ConfigError(f"--bit-rate must be a number, got {bit_rate!r}") from None
    if not (math.isfinite(rate) and 1e6 <= rate <= 1e13):
        raise ConfigError(f"--bit-rate must be in [1e6, 1e13] bits (TDC bins) per second, got "
                          f"{bit_rate!r}")
    return rate


def check_gate(range_gate: Any) -> tuple[float, float]:
    """``(MIN, MAX)`` metres, two finite numbers with ``0 <= MIN < MAX``, or one line."""
    import math

    try:
        lo, hi = (float(v) for v in range_gate)
    except (TypeError, ValueError):
        raise ConfigError(f"range_gate must be two numbers (MIN, MAX) in metres, got "
                          f"{range_gate!r}") from None
    if not (math.isfinite(lo) and math.isfinite(hi) and 0 <= lo < hi):
        raise ConfigError(f"--range-gate must be MIN MAX with 0 <= MIN < MAX metres, got "
                          f"{lo:g} {hi:g}")
    return lo, hi
