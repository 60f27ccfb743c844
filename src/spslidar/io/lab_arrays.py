"""A lab's own pattern and code files, read as they are saved.

A lab's DMD sequence is rarely a ``.npy``: it is the images uploaded to the DMD (a folder of
PNG or BMP files, a multi-page TIFF) or the arrays a MATLAB script made (a ``.mat`` file), and
its code generator's bits are a text file of 0s and 1s (or +1/-1). ``spslidar reconstruct``
and ``calibrate`` refused all of these ("load a TIFF, .mat, image or text file in Python and
np.save it"). These readers take them as saved and hand back plain arrays, which
:func:`spslidar.pipeline.real.check_patterns` and :func:`~spslidar.pipeline.real.check_code`
then check as they check a ``.npy``.

Conventions (the ones a file of that kind carries):

* **A folder of images**: one pattern per image, in the natural order of the file names
  (``p2.png`` before ``p10.png``), each image's row 0 at the top. 8-bit images are grey levels
  0-255 (divided by 255), or 0/1 where no pixel of the sequence exceeds 1 (an array of 0/1
  saved as 8-bit); 16-bit ones 0-65535; 1-bit images 0/1. A grey image stored as RGB (the
  three channels equal) is read as grey; an image whose channels differ is refused (a DLP
  controller's 24 bit planes packed in one RGB image are not unpacked here).
* **A multi-page TIFF**: one pattern per page, the same levels.
* **Images at the DMD's resolution**, each pattern pixel a K x K block of mirrors (a 64 x 64
  pattern shown on 512 x 512 mirrors), are read at the patterns' size, with a warning: every
  pattern shows one state inside a block, so no reconstruction tells its mirrors apart. An
  image that is not square (the DMD's whole frame around the region the scene is imaged
  through) is refused: crop it to that region.
* **A MATLAB file** (``.mat``, versions 4-7; a 7.3 file is HDF5 and is refused with the
  save option that avoids it): ``P(:,:,k)``, an ``N x N x M`` array with the pattern index
  last, as MATLAB stacks images (``M x N x N`` is taken too), or a sensing matrix ``A``
  whose row ``m`` is pattern ``m`` flattened by MATLAB's column-major ``P(:)'`` (``N^2 x M``
  is taken where only its first axis is a square, or both are and it is the longer: fewer
  patterns than pixels, as a compressive sequence has). Where the file holds several arrays,
  ``FILE.mat:NAME`` names one.
* **A code** as text (``.txt``, ``.csv``, ``.dat``, ``.tsv``): the bits as characters
  ``0110...`` (whitespace, commas and line breaks between them or not), or numbers separated
  by whitespace, commas or semicolons (0/1, or -1/+1, which
  :func:`~spslidar.pipeline.real.check_code` takes as the bipolar form of the same code);
  lines starting with ``#`` are comments. A ``.mat`` or ``.npz`` holding one vector works too.

Written here: scikit-image (through imageio and tifffile) reads each image and SciPy reads
MATLAB files; what is this project's is the conventions above (which axis is the pattern,
the order of the files, what an 8-bit level means), and refusing in one line what they
cannot settle.
"""

from __future__ import annotations

import math
import os
import re
import warnings
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import ConfigError
from ..npyfile import check_npz_sizes, load_npy

__all__ = ["CODE_TEXT_SUFFIXES", "IMAGE_SUFFIXES", "read_code_file", "read_patterns_file"]

#: image files a folder of patterns may hold (lossless formats: a JPEG's blocks blur each
#: mirror's state, so it is refused by name)
IMAGE_SUFFIXES = (".png", ".bmp", ".tif", ".tiff", ".pbm", ".pgm", ".gif")
#: lossy image formats, refused in a folder of patterns
_LOSSY_SUFFIXES = (".jpg", ".jpeg", ".jpe", ".webp")
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


def _memory_check(n_values: float, what: str, p: Path) -> None:
    from ..machine import _gb, available_memory

    need = float(n_values) * 8 * 2  # float64 copies while checking
    if need > 0.8 * available_memory():
        raise ConfigError(f"{what} {p} holds {n_values:.3g} values: {_gb(need)} to check, "
                          f"more than the memory available")


def _pick(arrays: dict[str, Any], name: str | None, p: Path, what: str, fits) -> tuple[str, Any]:
    """The one array of ``arrays`` that ``fits`` (or the one named ``name``), or one line."""
    shown = ", ".join(f"{k} {tuple(v)}" for k, v in
                      ((k, getattr(a, "shape", a)) for k, a in arrays.items()))
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


def _mat_arrays(p: Path, what: str) -> dict[str, tuple]:
    """The numeric arrays of a MATLAB file, name -> shape, read from its directory (no data)."""
    from scipy import io as sio

    with open(p, "rb") as fh:
        head = fh.read(128)
    if b"MATLAB 7.3" in head[:116] or head[:8] == b"\x89HDF\r\n\x1a\n":
        raise ConfigError(f"{what} {p} is a MATLAB 7.3 file (HDF5): save it with "
                          f"save(..., '-v7') in MATLAB, or as an .npy")
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            listed = sio.whosmat(str(p))
    except Exception as exc:  # (scipy raises ValueError, TypeError, MatReadError ... on junk)
        raise ConfigError(f"cannot read {what} {p} as a MATLAB file: "
                          f"{str(exc).splitlines()[0] if str(exc) else type(exc).__name__}"
                          ) from None
    numeric = {"double", "single", "logical", "int8", "uint8", "int16", "uint16", "int32",
               "uint32", "int64", "uint64"}
    return {name: tuple(shape) for name, shape, cls in listed if cls in numeric}


def _load_mat(p: Path, name: str, what: str) -> np.ndarray:
    from scipy import io as sio

    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            arr = sio.loadmat(str(p), variable_names=[name])[name]
    except Exception as exc:
        raise ConfigError(f"cannot read {what} {p}:{name} as a MATLAB array: "
                          f"{str(exc).splitlines()[0] if str(exc) else type(exc).__name__}"
                          ) from None
    return np.asarray(arr)


def _npz_arrays(p: Path, what: str) -> dict[str, Any]:
    check_npz_sizes(p, what)
    try:
        with np.load(p, allow_pickle=False) as z:
            return {k: z[k] for k in z.files}
    except Exception as exc:
        raise ConfigError(f"cannot read {what} {p} as an .npz archive: "
                          f"{str(exc).splitlines()[0] if str(exc) else type(exc).__name__}"
                          ) from None


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


def _mat_patterns(arr: np.ndarray, p: Path) -> np.ndarray:
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
        rows, cols = arr.shape
        # N^2 x M, one pattern per column: where only the first axis is a square, or both
        # are and it is the longer (a compressive sequence has fewer patterns than pixels)
        if _is_square(rows) and (not _is_square(cols) or rows > cols):
            arr = arr.T
        m, nn = arr.shape
        if _is_square(nn):
            side = math.isqrt(nn)
            return arr.reshape(m, side, side, order="F")
    return arr


def _image_levels(img: np.ndarray, label: str) -> np.ndarray:
    """One image as a 2-D array of levels as stored (RGB with equal channels made grey)."""
    if img.ndim == 3 and img.shape[-1] in (2, 3, 4):
        if img.shape[-1] in (2, 4):  # grey or RGB with an alpha channel
            alpha = img[..., -1]
            if alpha.min() != alpha.max():
                raise ConfigError(f"pattern image {label} has transparency that varies: give "
                                  f"the mirror states as grey levels")
            img = img[..., :-1]
        if img.shape[-1] == 3 and not (np.array_equal(img[..., 0], img[..., 1])
                                       and np.array_equal(img[..., 0], img[..., 2])):
            raise ConfigError(f"pattern image {label} is in colour (its red, green and blue "
                              f"differ): give one grey or 1-bit image per pattern (a DLP "
                              f"controller's 24 bit planes in one image are not unpacked)")
        img = img[..., 0]
    if img.ndim != 2:
        raise ConfigError(f"pattern image {label} has shape {img.shape}: one 2-D image per "
                          f"pattern is expected")
    if np.iscomplexobj(img) or not (np.issubdtype(img.dtype, np.number) or img.dtype == bool):
        raise ConfigError(f"pattern image {label} holds {img.dtype} values, not grey levels")
    return img


def _scale_levels(stack: np.ndarray) -> np.ndarray:
    """Stored image levels -> mirror states in [0, 1]: 1-bit as 0/1, 8- and 16-bit integers
    by their full scale unless no value exceeds 1 (0/1 saved as integers), floats as they
    are (checked later)."""
    if stack.dtype == bool:
        return stack.astype(np.float64)
    if np.issubdtype(stack.dtype, np.integer):
        top = int(stack.max()) if stack.size else 0
        if top <= 1:
            return stack.astype(np.float64)
        full = float(np.iinfo(stack.dtype).max) if stack.dtype.itemsize <= 2 else None
        if full is not None and stack.min() >= 0:
            return stack.astype(np.float64) / full
    return stack.astype(np.float64)


def _block_side(stack: np.ndarray) -> int:
    """The side K of the square blocks of mirrors that every image of ``stack`` (M, H, W)
    holds at one state (1 where none): the largest K dividing H and W such that no image
    changes inside a K x K block."""
    k = math.gcd(stack.shape[1], stack.shape[2])
    for axis in (1, 2):
        moved = np.moveaxis(stack, axis, 1)
        change = np.flatnonzero(np.any(moved[:, 1:] != moved[:, :-1], axis=(0, 2))) + 1
        for c in change:
            k = math.gcd(k, int(c))
            if k == 1:
                return 1
    return k


def _dmd_images(stack: np.ndarray, where: Path) -> np.ndarray:
    """Images as the DMD showed them, each pattern pixel a K x K block of mirrors, read as
    the patterns (one value per block), said in a warning; the image itself otherwise.
    Inside a block every pattern shows one state, so no reconstruction can tell its mirrors
    apart: the map is made at the patterns' own size."""
    if stack.ndim != 3 or stack.shape[1] < 2:
        return stack
    k = _block_side(stack)
    if k > 1 and min(stack.shape[1:]) // k >= 2:
        h, w = stack.shape[1] // k, stack.shape[2] // k
        warnings.warn(f"--patterns {where}: every image is made of {k} x {k} blocks of "
                      f"mirrors at one state, so the patterns are {w} x {h} (read as such; "
                      f"the images are {stack.shape[2]} x {stack.shape[1]})", stacklevel=3)
        stack = np.ascontiguousarray(stack[:, ::k, ::k])
    if stack.shape[1] != stack.shape[2]:
        raise ConfigError(f"--patterns {where}: the images are {stack.shape[2]} x "
                          f"{stack.shape[1]} patterns, not square: crop them to the square "
                          f"region the scene is imaged through (pad a region that is not "
                          f"square with mirrors at 0)")
    return stack


def _natural_key(name: str) -> list:
    return [int(t) if t.isdigit() else t.lower() for t in re.split(r"(\d+)", name)]


def _read_image(path: Path) -> np.ndarray:
    import logging

    from skimage import io as skio

    quiet = logging.getLogger("tifffile")
    level = quiet.level
    quiet.setLevel(logging.CRITICAL)
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            img = np.asarray(skio.imread(path))
    except Exception as exc:
        reason = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        raise ConfigError(f"cannot read pattern image {path}: {reason[:120]}") from None
    finally:
        quiet.setLevel(level)
    if img.size == 0:
        raise ConfigError(f"pattern image {path} holds no image")
    return img


def _folder_patterns(folder: Path) -> np.ndarray:
    """One pattern per image file of ``folder``, in the natural order of their names."""
    entries = [e for e in folder.iterdir() if not e.name.startswith(".") and e.is_file()]
    lossy = sorted(e.name for e in entries if e.suffix.lower() in _LOSSY_SUFFIXES)
    if lossy:
        raise ConfigError(f"--patterns {folder} holds lossy images ({lossy[0]}"
                          f"{' ...' if len(lossy) > 1 else ''}): a JPEG's compression blurs "
                          f"each mirror's state; give PNG, BMP or TIFF files")
    files = sorted((e for e in entries if e.suffix.lower() in IMAGE_SUFFIXES),
                   key=lambda e: _natural_key(e.name))
    if not files:
        raise ConfigError(f"--patterns {folder} is a folder with no image in it (one "
                          f"{'/'.join(IMAGE_SUFFIXES)} file per pattern, in name order)")
    first = _image_levels(_read_image(files[0]), files[0].name)
    _memory_check(float(first.size) * len(files), "--patterns", folder)
    stack = np.empty((len(files),) + first.shape, dtype=first.dtype)
    stack[0] = first
    for i, f in enumerate(files[1:], start=1):
        img = _image_levels(_read_image(f), f.name)
        if img.shape != first.shape:
            raise ConfigError(f"--patterns {folder}: {f.name} is {img.shape[1]} x "
                              f"{img.shape[0]} pixels, {files[0].name} "
                              f"{first.shape[1]} x {first.shape[0]}: every pattern image must "
                              f"have the same size")
        if img.dtype != stack.dtype:
            stack = stack.astype(np.result_type(stack.dtype, img.dtype))
        stack[i] = img
    return _scale_levels(_dmd_images(stack, folder))


def _tiff_patterns(p: Path) -> np.ndarray:
    import tifffile

    try:
        with tifffile.TiffFile(p) as tif:
            n = len(tif.pages)
            shape = tif.pages[0].shape if n else ()
            _memory_check(float(np.prod(shape)) * n, "--patterns", p)
            stack = tif.asarray(key=range(n)) if n > 1 else tif.asarray()
    except ConfigError:
        raise
    except Exception as exc:
        reason = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        raise ConfigError(f"cannot read --patterns {p} as a TIFF: {reason[:120]}") from None
    stack = np.asarray(stack)
    if stack.ndim == 2 or (stack.ndim == 3 and stack.shape[-1] in (3, 4) and n == 1):
        raise ConfigError(f"--patterns {p} is a TIFF of one page: give one page per pattern "
                          f"(a multi-page TIFF) or a folder of images")
    if stack.ndim == 4:
        stack = np.stack([_image_levels(page, f"{p.name} page {i}")
                          for i, page in enumerate(stack)])
    return _scale_levels(_dmd_images(stack, p))


def read_patterns_file(path: str | os.PathLike) -> np.ndarray:
    """The mirror states a pattern file holds, as an array for
    :func:`~spslidar.pipeline.real.check_patterns` (``(M, N, N)``, or ``(M, N*N)`` flattened
    row-major).

    Parameters
    ----------
    path : str or os.PathLike
        A ``.npy``; an ``.npz`` or ``.mat`` (``FILE:NAME`` for one of several arrays); a
        multi-page ``.tif``; or a folder of images, one per pattern in the natural order of
        their names (the module's docstring gives each convention).

    Raises
    ------
    ConfigError
        In one line, where the file cannot be read or its layout is ambiguous.
    """
    p, name = _split_name(path)
    if p.is_dir():
        return _folder_patterns(p)
    suffix = p.suffix.lower()
    if not p.exists():
        raise ConfigError(f"patterns file not found: {p}")
    if suffix == ".mat":
        shapes = _mat_arrays(p, "--patterns")
        key, shape = _pick(shapes, name, p, "--patterns", _pattern_shape)
        _memory_check(float(np.prod(shape)), "--patterns", p)
        return _mat_patterns(_load_mat(p, key, "--patterns"), p)
    if suffix == ".npz":
        arrays = _npz_arrays(p, "--patterns")
        return np.asarray(_pick(arrays, name, p, "--patterns", _pattern_shape)[1])
    if suffix in (".tif", ".tiff"):
        return _tiff_patterns(p)
    if suffix in IMAGE_SUFFIXES or suffix in _LOSSY_SUFFIXES:
        raise ConfigError(f"--patterns {p} is one image: give the folder that holds one image "
                          f"per pattern (or a multi-page TIFF)")
    return _npy_or_say(p, "patterns", ".npy, .npz, .mat, a multi-page .tif or a folder of "
                                      "images")


def _text_bits(p: Path) -> np.ndarray:
    size = p.stat().st_size
    if size > _MAX_TEXT_BYTES:
        raise ConfigError(f"--code {p} is a text file of {size / 1e6:.0f} MB: more than a "
                          f"code's bits (save them as an .npy)")
    try:
        text = p.read_text(encoding="utf-8-sig")
    except (UnicodeDecodeError, OSError) as exc:
        raise ConfigError(f"cannot read --code {p} as text: {exc}") from None
    body = "\n".join(line for line in text.splitlines() if not line.lstrip().startswith("#"))
    packed = re.sub(r"[\s,;]+", "", body)
    if not packed:
        raise ConfigError(f"--code {p} holds no bits")
    if set(packed) <= {"0", "1"}:
        return np.frombuffer(packed.encode("ascii"), dtype=np.uint8) - ord("0")
    tokens = [t for t in re.split(r"[\s,;]+", body.strip()) if t]
    try:
        values = np.array([float(t) for t in tokens])
    except ValueError:
        bad = next(t for t in tokens if not re.fullmatch(r"[+-]?\d+(\.\d*)?([eE][+-]?\d+)?", t))
        raise ConfigError(f"--code {p}: {bad[:20]!r} is not a bit (a code file holds 0/1 or "
                          f"-1/+1 values, or the bits as 0 and 1 characters)") from None
    return values


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
    return _npy_or_say(p, "code", f".npy, .mat, .npz or text ({', '.join(CODE_TEXT_SUFFIXES)})")


def _npy_or_say(p: Path, what: str, formats: str) -> np.ndarray:
    """A ``.npy`` (any other name read as one too), or one line naming the formats read."""
    try:
        return load_npy(p, what)
    except ConfigError as exc:
        if p.suffix.lower() == ".npy" or "is not a .npy file" not in str(exc):
            raise
        raise ConfigError(f"cannot read {what} {p}: spslidar reads {what} from {formats}"
                          ) from None
