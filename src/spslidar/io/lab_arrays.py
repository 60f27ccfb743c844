"""A lab's own pattern and code files, read as they are saved.

A lab's DMD sequence is rarely a ``.npy``: it is the images uploaded to the DMD (a folder of
PNG or BMP files, a multi-page TIFF) or the arrays a MATLAB script made (a ``.mat`` file), and
its code generator's bits are a text file of 0s and 1s (or +1/-1). ``spslidar reconstruct``
and ``calibrate`` refused all of these ("load a TIFF, .mat, image or text file in Python and
np.save it"). These readers take them as saved and hand back plain arrays, which
:func:`spslidar.pipeline.real.check_patterns` and :func:`~spslidar.pipeline.real.check_code`
then check as they check a ``.npy``.

Conventions (the ones a file of that kind carries):

* **A folder of images, or a multi-page TIFF**: one pattern per image (page), in the order
  of the names, each image as it is displayed (row 0 at the top, a min-is-white TIFF
  inverted, a palette applied), binary images read as 0/1 whatever their bit depth, grey
  levels over their type's full scale; :mod:`spslidar.io.lab_images` gives the rules, and
  what it refuses (JPEGs, colour, two files of one pattern, images of two sizes).
* **Images at the DMD's resolution**, each pattern pixel a block of mirrors (a 64 x 64
  pattern shown on 512 x 512 mirrors), are read as they are (the same map as their
  ``.npy``), with a warning naming ``--pattern-size N``, which reads any pattern file as
  ``N x N`` square blocks, each checked to hold one state. An image that is not square (the
  DMD's whole frame around the region the scene is imaged through) is refused: crop it.
* **A MATLAB file** (``.mat``, versions 4-7; a 7.3 file is HDF5 and is refused with the
  save option that avoids it): ``P(:,:,k)``, an ``N x N x M`` array with the pattern index
  last, as MATLAB stacks images (``M x N x N`` is taken too; ``N x N x N`` is refused), or a
  sensing matrix ``A`` whose row ``m`` is pattern ``m`` flattened by MATLAB's column-major
  ``P(:)'`` (``N^2 x M`` is taken where only its first axis is a square; where both are,
  ``--pattern-size N`` says which holds the pixels, and a square ``N^2 x N^2`` basis is
  refused, its rows and columns alike possible). Integer arrays
  (``imread``'s uint8) are read as images are, as they are in every format and in Python
  (:func:`~spslidar.pipeline.inputs.check_patterns`). Where the file holds several arrays,
  ``FILE.mat:NAME`` names one; a struct or cell is named, not opened.
* **An ``.npy`` or ``.npz``** in NumPy's order, the pattern index first: ``(M, N, N)``, or
  ``(M, N^2)`` rows flattened row-major (as ``run --save-ptu`` writes). Where the shape
  alone leaves the layout open (a square ``N^2 x N^2`` basis that is not symmetric, an
  ``N x N x N`` stack, more rows than pixels with both sides squares) it is read so, with a
  warning naming the transpose.
* **A code** as text (``.txt``, ``.csv``, ``.dat``, ``.tsv``; UTF-8 or UTF-16): the bits as
  characters ``0110...`` (whitespace, commas and line breaks between them or not), or
  numbers separated by whitespace, commas or semicolons (0/1, or -1/+1, which
  :func:`~spslidar.pipeline.inputs.check_code` takes as the bipolar form of the same code);
  ``#`` and ``%`` start comments. A table of 2-4 columns is refused (bit and complement read
  interleaved). A ``.npy``, ``.mat`` or ``.npz`` vector (``1 x L`` too) works alike.

Written here: SciPy reads MATLAB files, Pillow and tifffile the images; what is this
project's is the conventions above (which axis is the pattern, the order of the files, what
a level means), and refusing in one line what they cannot settle.
"""

from __future__ import annotations

import math
import os
import re
import warnings
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import ConfigError, first_line
from ..npyfile import check_npz_sizes, load_npy
from .lab_images import (
    IMAGE_SUFFIXES,
    LOSSY_SUFFIXES,
    folder_patterns,
    memory_check,
    reduce_patterns,
    tiff_patterns,
    to_states,
)

__all__ = ["CODE_TEXT_SUFFIXES", "IMAGE_SUFFIXES", "read_code_file", "read_patterns_file"]

#: text files read as a code's bits
CODE_TEXT_SUFFIXES = (".txt", ".csv", ".dat", ".tsv")
#: the largest text file read as a code (a code of 2^24 bits written as "0, " is 50 MB)
_MAX_TEXT_BYTES = 200_000_000


def _split_name(path: str | os.PathLike) -> tuple[Path, str | None]:
    """``FILE.mat:NAME`` / ``FILE.npz:NAME`` -> (file, NAME); a path that exists as given is
    never split (a colon is legal in a file name, and a Windows drive has one)."""
    p = Path(path)
    text = os.fspath(path)
    if not p.exists() and ":" in text:
        head, _, name = text.rpartition(":")
        if name and Path(head).suffix.lower() in (".mat", ".npz") and Path(head).is_file():
            return Path(head), name
    return p, None


def _pick(arrays: dict[str, Any], name: str | None, p: Path, what: str, fits) -> tuple[str, Any]:
    """The one array of ``arrays`` that ``fits`` (or the one named ``name``), or one line."""
    shown = ", ".join([f"{k} {tuple(v)}" for k, v in
                       ((k, getattr(a, "shape", a)) for k, a in arrays.items())]
                      + getattr(arrays, "others", []))
    if getattr(arrays, "others", None):
        shown += ": only numeric arrays are read; save the array itself, not in a struct or cell"
    if name is not None:
        if name not in arrays:
            raise ConfigError(f"{what} {p} has no array named {name!r} (it holds: "
                              f"{shown or 'none'})")
        return name, arrays[name]
    good = [k for k, a in arrays.items() if fits(getattr(a, "shape", a))]
    if len(good) == 1:
        return good[0], arrays[good[0]]
    if not good:
        raise ConfigError(f"{what} {p} holds no array that can be {what} (it holds: "
                          f"{shown or 'none'})")
    raise ConfigError(f"{what} {p} holds {len(good)} arrays that could be {what} "
                      f"({', '.join(good)}): name one as {p}:{good[0]}")


def _mat_header(p: Path) -> bytes:
    """A MATLAB file's first 128 bytes: its 116-byte text (version, platform, date; or an
    HDF5 signature) and its subsystem and version fields."""
    with open(p, "rb") as fh:
        return fh.read(128)


def _mat_arrays(p: Path, what: str) -> dict[str, tuple]:
    """The numeric arrays of a MATLAB file, name -> shape, read from its directory (no data)."""
    from scipy import io as sio

    head = _mat_header(p)
    if b"MATLAB 7.3" in head[:116] or head[:8] == b"\x89HDF\r\n\x1a\n":
        raise ConfigError(f"{what} {p} is a MATLAB 7.3 file (HDF5): save it with "
                          f"save(..., '-v7') in MATLAB, or as an .npy")
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            listed = sio.whosmat(str(p))
    except Exception as exc:  # (scipy raises ValueError, TypeError, MatReadError ... on junk)
        raise ConfigError(f"cannot read {what} {p} as a MATLAB file: {first_line(exc)}") from None
    numeric = {"double", "single", "logical", "int8", "uint8", "int16", "uint16", "int32",
               "uint32", "int64", "uint64"}
    others = [f"{name} ({cls} {'x'.join(map(str, shape))})" for name, shape, cls in listed
              if cls not in numeric]
    return _Listed({name: tuple(shape) for name, shape, cls in listed if cls in numeric},
                   others)


class _Listed(dict):
    """A MATLAB file's numeric arrays (name -> shape), with its other variables named (a
    struct, a cell, a char or sparse array: said as what the file holds, not as "none")."""

    def __init__(self, arrays: dict, others: list[str]):
        super().__init__(arrays)
        self.others = others


def _load_mat(p: Path, name: str, what: str) -> np.ndarray:
    from scipy import io as sio

    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            arr = sio.loadmat(str(p), variable_names=[name])[name]
    except Exception as exc:
        raise ConfigError(f"cannot read {what} {p}:{name} as a MATLAB array: "
                          f"{first_line(exc)}") from None
    return np.asarray(arr)


def _npz_arrays(p: Path, what: str) -> dict[str, Any]:
    check_npz_sizes(p, what)
    try:
        with np.load(p, allow_pickle=False) as z:
            return {k: z[k] for k in z.files}
    except Exception as exc:
        raise ConfigError(f"cannot read {what} {p} as an .npz archive: {first_line(exc)}") from None


def _is_square(n: int) -> bool:
    r = math.isqrt(n)
    return n >= 16 and r * r == n


def _pattern_shape(shape: tuple) -> bool:
    """Whether an array of this shape can be a pattern sequence (3-D N x N x M or M x N x N,
    2-D with one square axis)."""
    if len(shape) == 3:
        return (shape[0] == shape[1] or shape[1] == shape[2]) and min(shape) >= 2
    return len(shape) == 2 and (_is_square(shape[0]) or _is_square(shape[1])) \
        and min(shape) >= 2


def _scipy_note(p: Path, key: str, shape: tuple) -> None:
    """Say where a 2-D pattern matrix comes from a ``.mat`` that SciPy wrote (its header's
    platform is Python's ``posix`` or ``nt``, where MATLAB writes ``GLNXA64``, ``PCWIN64``,
    ``MACI64``...): its rows are read as MATLAB's column-major ``P(:)'``, and a Python
    user's rows, flattened row-major, give a transposed depth map without a word (an
    outside audit of 2026-12-01: the same numbers as an ``.npy`` read right)."""
    try:
        head = _mat_header(p)[:116]
    except OSError:
        return
    if not head.startswith(b"MATLAB 5.0 MAT-file") or not (
            b"Platform: posix" in head or b"Platform: nt" in head):
        return
    warnings.warn(f"--patterns {p}:{key} was written by SciPy (its header), not MATLAB: its "
                  f"{shape[0]} x {shape[1]} matrix is read as MATLAB stores one, each pattern "
                  f"flattened column-major (P(:)'); patterns flattened in NumPy's row-major "
                  f"order (P.reshape(M, -1)) give a transposed depth map: save those as an "
                  f".npy, or as an N x N x M stack", stacklevel=2)


def _npy_layout_note(arr: np.ndarray, where: str) -> None:
    """Say where NumPy's order settles an ``.npy`` or ``.npz`` pattern array's layout that its
    shape alone leaves open (an outside audit of 2026-12-01: a square basis saved one pattern
    per column read 0.130 m for 0.038 m at 16x16, without a word, where a ``.mat`` refuses
    it). Warned, not refused: NumPy's order (the pattern index first, one pattern per row) is
    what ``run --save-ptu`` writes and what most Python code saves, and refusing every square
    basis would refuse a full Hadamard set saved as rows. A symmetric square matrix (a
    Sylvester Hadamard basis) reads the same either way and is not warned."""
    if arr.ndim == 3 and arr.shape[0] == arr.shape[1] == arr.shape[2] and arr.shape[0] >= 2:
        n = arr.shape[0]
        warnings.warn(f"--patterns {where} has shape ({n}, {n}, {n}): read as {n} patterns "
                      f"of {n} x {n}, the pattern index first (NumPy's order, as run "
                      f"--save-ptu writes); a stack with the pattern index last (N x N x M, as "
                      f"MATLAB stacks images) gives a wrong map without a word: save "
                      f"np.moveaxis(P, -1, 0)", stacklevel=3)
    elif arr.ndim == 2:
        rows, cols = arr.shape
        if rows == cols and _is_square(rows):
            if not np.array_equal(arr, arr.T):
                warnings.warn(f"--patterns {where} is a square {rows} x {rows} matrix: read "
                              f"as one pattern per row (NumPy's order, as run --save-ptu "
                              f"writes); a basis saved one pattern per column gives a wrong "
                              f"map without a word: save its transpose (A.T)", stacklevel=3)
        elif _is_square(rows) and _is_square(cols) and rows > cols:
            a, b = math.isqrt(cols), math.isqrt(rows)
            warnings.warn(f"--patterns {where} is a {rows} x {cols} matrix, both sides "
                          f"squares: read as its {rows} rows of {a} x {a} (more patterns than "
                          f"pixels); if its {cols} columns of {b} x {b} are the patterns, save "
                          f"its transpose (A.T)", stacklevel=3)


def _mat_patterns(arr: np.ndarray, p: Path, key: str, size: int | None) -> np.ndarray:
    """A MATLAB array as ``(M, N, N)``: ``N x N x M`` (the pattern index last, as MATLAB
    stacks images) or ``M x N x N``; a sensing matrix ``M x N^2`` (or ``N^2 x M``) whose rows
    are patterns flattened column-major."""
    if arr.ndim == 3:
        a, b, c = arr.shape
        if a == b == c:
            raise ConfigError(f"--patterns {p}: a {a} x {a} x {a} array, so which axis counts "
                              f"the patterns is not known (N x N x M is read, with M != N): "
                              f"save it as an .npy of shape (M, N, N)")
        if a == b:
            return np.moveaxis(arr, -1, 0)
        return arr
    if arr.ndim == 2:
        _scipy_note(p, key, arr.shape)
        rows, cols = arr.shape
        if rows == cols and _is_square(rows):
            # (a full basis, one pattern per row or per column, or one N x N pattern: a
            # column-major basis read as rows gave 0.22 m for 0.006, exit 0, an audit)
            n = math.isqrt(rows)
            raise ConfigError(
                f"--patterns {p}:{key} is a square {rows} x {rows} matrix: its patterns may be "
                f"its rows or its columns (or it is one {rows} x {rows} pattern): save them as "
                f"an N x N x M stack, P = reshape(A', {n}, {n}, []) for patterns in rows, "
                f"reshape(A, {n}, {n}, []) for patterns in columns")
        if _is_square(rows) and _is_square(cols):
            # (both sides squares: 1024 x 256 is 1024 patterns of 16 x 16 or 256 of 32 x 32;
            # the longer side taken as the pixels misread M = 4 N^2, and the block count's
            # hint then led to --repeats, a review)
            a, b = math.isqrt(cols), math.isqrt(rows)
            if size is None or size not in (a, b):
                raise ConfigError(
                    f"--patterns {p}:{key} is a {rows} x {cols} matrix, both sides squares: "
                    f"its patterns may be its {rows} rows of {a} x {a} or its {cols} columns "
                    f"of {b} x {b}: give --pattern-size {a} (rows) or {b} (columns)")
            if size == b:
                arr = arr.T
        elif _is_square(rows):  # N^2 x M: one pattern per column
            arr = arr.T
        m, nn = arr.shape
        if _is_square(nn):
            side = math.isqrt(nn)
            return arr.reshape(m, side, side, order="F")
    return arr


def read_patterns_file(path: str | os.PathLike, size: int | None = None) -> np.ndarray:
    """The mirror states a pattern file holds, as an array for
    :func:`~spslidar.pipeline.inputs.check_patterns` (``(M, N, N)``, or ``(M, N*N)``
    flattened row-major).

    Parameters
    ----------
    path : str or os.PathLike
        A ``.npy``; an ``.npz`` or ``.mat`` (``FILE:NAME`` for one of several arrays); a
        multi-page ``.tif``; or a folder of images, one per pattern (the module's docstring
        gives each convention).
    size : int, optional
        The patterns' side ``N`` where the file holds them at a finer resolution (images at
        the DMD's, each pattern pixel a block of mirrors): each pattern is read as ``N x N``
        blocks, every block checked to hold one state (``--pattern-size``); for a MATLAB
        sensing matrix whose two sides are squares, which of them holds the pixels.

    Raises
    ------
    ConfigError
        In one line, where the file cannot be read or its layout is ambiguous.
    """
    p, name = _split_name(path)
    if p.is_dir():
        return folder_patterns(p, size)
    suffix = p.suffix.lower()
    if not p.exists():
        raise ConfigError(f"patterns file not found: {p}")
    if suffix in (".tif", ".tiff"):
        return tiff_patterns(p, size)
    if suffix in IMAGE_SUFFIXES or suffix in LOSSY_SUFFIXES:
        raise ConfigError(f"--patterns {p} is one image: give the folder that holds one image "
                          f"per pattern (or a multi-page TIFF)")
    if suffix == ".mat":
        shapes = _mat_arrays(p, "--patterns")
        key, shape = _pick(shapes, name, p, "--patterns", _pattern_shape)
        memory_check(float(np.prod(shape)), "--patterns", p)
        arr = _mat_patterns(_load_mat(p, key, "--patterns"), p, key, size)
        if arr.ndim == 3 and arr.dtype != bool and np.issubdtype(arr.dtype, np.integer):
            # (imread's uint8: levels as images)
            arr = to_states(arr, f"--patterns {p}:{key}")
    elif suffix == ".npz":
        arrays = _npz_arrays(p, "--patterns")
        key, arr = _pick(arrays, name, p, "--patterns", _pattern_shape)
        arr = np.asarray(arr)
        _npy_layout_note(arr, f"{p}:{key}")
    else:
        arr = _npy_or_say(p, "patterns", ".npy, .npz, .mat, a multi-page .tif or a folder "
                                         "of images")
        _npy_layout_note(arr, str(p))
    if size is None and arr.ndim == 3 and (np.issubdtype(arr.dtype, np.number)
                                           or arr.dtype == bool):
        # (patterns at the DMD's resolution got the hint as images, not as an .npy: an
        # outside audit of 2026-12-03)
        from .lab_images import block_hint

        block_hint(arr, p, "pattern", stacklevel=3)
    return arr if size is None else reduce_patterns(arr, size, f"--patterns {p}")


def _text_bits(p: Path) -> np.ndarray:
    """The bits of a text file: ``0110...`` characters (separators or none), or numbers (0/1
    or -1/+1); ``#`` and ``%`` start comments (MATLAB's too); UTF-8 or UTF-16 (Notepad's
    "Unicode")."""
    size = p.stat().st_size
    if size > _MAX_TEXT_BYTES:
        raise ConfigError(f"--code {p} is a text file of {size / 1e6:.0f} MB: more than a "
                          f"code's bits (save them as an .npy)")
    try:
        data = p.read_bytes()
        utf16 = data[:2] in (b"\xff\xfe", b"\xfe\xff")
        text = data.decode("utf-16" if utf16 else "utf-8-sig")
    except (UnicodeDecodeError, OSError) as exc:
        reason = exc.strerror if isinstance(exc, OSError) else "not UTF-8 or UTF-16 text"
        raise ConfigError(f"cannot read --code {p} as text: {reason}") from None
    body = "\n".join(re.split(r"[#%]", line, maxsplit=1)[0] for line in text.splitlines())
    packed = re.sub(r"[\s,;]+", "", body)
    if not packed:
        raise ConfigError(f"--code {p} holds no bits")
    lines = [ln for ln in body.splitlines() if ln.strip()]
    rows = [[t for t in re.split(r"[\s,;]+", ln.strip()) if t] for ln in lines]
    fields = {len(r) for r in rows}
    single = all(len(t) == 1 or not set(t) <= {"0", "1"} for r in rows for t in r)
    if len(lines) >= 8 and len(fields) == 1 and 2 <= min(fields) <= 4 and single:
        # (columns by spaces too, MATLAB's save -ascii: a review; runs of bits, "0110 1001",
        # are a code wrapped, not a table)
        # (a table, bit and complement or index and bit, was read interleaved: an audit)
        raise ConfigError(f"--code {p} holds {min(fields)} columns on each of its "
                          f"{len(lines)} lines: give the code's bits alone, one column or "
                          f"one row")
    if set(packed) <= {"0", "1"}:
        return np.frombuffer(packed.encode("ascii"), dtype=np.uint8) - ord("0")
    tokens = [t for t in re.split(r"[\s,;]+", body.strip()) if t]
    number = r"[+-]?(\d+\.?\d*|\.\d+)([eE][+-]?\d+)?"
    bad = next((t for t in tokens if not re.fullmatch(number, t)), None)
    if bad is not None:
        header = tokens.index(bad) == 0 and re.search(r"[A-Za-z]", bad)
        raise ConfigError(f"--code {p}: {bad[:20]!r} is not a bit (a code file holds 0/1 or "
                          f"-1/+1 values, or the bits as 0 and 1 characters"
                          + ("; a header line? start it with #" if header else "") + ")")
    long = next((t for t in tokens if len(t) > 2 and set(t.lstrip("+-")) <= set("0123456789")
                 and not set(t) <= {"0", "1"}), None)
    if long is not None:  # (a string of bits with a typo: "0110...2" read as one number)
        pos = next(i for i, ch in enumerate(long) if ch not in "01")
        raise ConfigError(f"--code {p}: a run of bits holds {long[pos]!r} at character "
                          f"{pos + 1} of {len(long)}: bits are 0 and 1")
    return np.array([float(t) for t in tokens])


def read_code_file(path: str | os.PathLike) -> np.ndarray:
    """The values a code file holds, as a 1-D array for
    :func:`~spslidar.pipeline.real.check_code`.

    Parameters
    ----------
    path : str or os.PathLike
        A ``.npy``; a text file (``.txt``, ``.csv``, ``.dat``, ``.tsv``) of 0/1 characters or
        of numbers (0/1 or -1/+1); an ``.npz`` or ``.mat`` holding one vector (``FILE:NAME``
        names one of several).

    Raises
    ------
    ConfigError
        In one line, where the file cannot be read.
    """
    p, name = _split_name(path)
    if not p.exists():
        raise ConfigError(f"code file not found: {p}")
    if p.is_dir():
        raise ConfigError(f"--code {p} is a folder, not a file of bits")
    suffix = p.suffix.lower()

    def vector(shape: tuple) -> bool:
        return len(shape) >= 1 and int(np.prod(shape)) == max(shape) and max(shape) >= 2

    if suffix in CODE_TEXT_SUFFIXES:
        return _text_bits(p)
    if suffix == ".mat":
        shapes = _mat_arrays(p, "--code")
        key, _shape = _pick(shapes, name, p, "--code", vector)
        arr = _load_mat(p, key, "--code")
        return arr.reshape(-1) if vector(arr.shape) else arr
    if suffix == ".npz":
        arr = np.asarray(_pick(_npz_arrays(p, "--code"), name, p, "--code", vector)[1])
        return arr.reshape(-1) if vector(arr.shape) else arr
    arr = _npy_or_say(p, "code", f".npy, .mat, .npz or text "
                                 f"({', '.join(CODE_TEXT_SUFFIXES)})")
    return arr.reshape(-1) if vector(arr.shape) else arr


def _npy_or_say(p: Path, what: str, formats: str) -> np.ndarray:
    """A ``.npy`` (any other name read as one too), or one line naming the formats read."""
    try:
        return load_npy(p, what)
    except ConfigError as exc:
        if p.suffix.lower() == ".npy" or "is not a .npy file" not in str(exc):
            raise
        raise ConfigError(f"cannot read {what} {p}: spslidar reads {what} from {formats}"
                          ) from None
