"""Pattern images as a lab saves them: a folder of image files or a multi-page TIFF, read into
mirror states (:func:`spslidar.io.lab_arrays.read_patterns_file` dispatches here).

The conventions (the module docstring of :mod:`spslidar.io.lab_arrays` lists them all):

* **Order**: one pattern per image, in the order of the file names: plain order where every
  name has the same length (zero-padded numbers, decimal or hexadecimal: ``f_0a`` after
  ``f_09``), else natural order (``p2`` before ``p10``). Two names of one number (``p05``,
  ``p5``) or of one stem (``p3.png``, ``p3.bmp``) are refused, and so is an entry with an
  image's name that is no readable file (a broken link, a folder): either would shift every
  pattern after it against its marker block.
* **Levels**: each image as it is displayed: a TIFF whose photometric interpretation is
  *min-is-white* (Photoshop's bitmap mode, fax tools) inverted, a palette applied, an alpha
  channel that is the same everywhere dropped, RGB with equal channels made grey (colour is
  refused: a DLP controller's 24 bit planes in one image are not unpacked). A sequence of
  binary images (each holding 0 and one other level: 1-bit, 0/1, 0/255, 0/4095 in 16 bits)
  is read as 0/1 whatever each image's bit depth; grey levels are divided by their type's
  full scale (255, 65535).
* **Size**: images at the DMD's resolution, each pattern pixel a block of mirrors, are read
  at the patterns' size with ``size`` (``--pattern-size N``: every block checked to hold one
  state), image by image, so the memory is the patterns'; without it they are read as they
  are, and a warning says the size that holds the same information.

Written here: Pillow reads PNG, BMP, GIF and PNM files (a folder of 4096 images of 64x64
reads in 1.4 s, where ``skimage.io.imread`` alone took 2.4 s over the same files in the same
process, 2026-11-30; an outside audit had timed the folder at 8-9.5 s through it on a loaded
machine), tifffile reads TIFFs (Pillow where a compression needs ``imagecodecs``,
which is no dependency: LZW, CCITT G3/G4); what is this project's is the conventions.
"""

from __future__ import annotations

import math
import re
import warnings
from pathlib import Path

import numpy as np

from ..errors import ConfigError, first_line

__all__ = ["IMAGE_SUFFIXES", "block_reduce", "folder_patterns", "reduce_patterns",
           "tiff_patterns", "to_states"]

#: image files a folder of patterns may hold (lossless formats: a JPEG's blocks blur each
#: mirror's state, so it is refused by name)
IMAGE_SUFFIXES = (".png", ".bmp", ".tif", ".tiff", ".pbm", ".pgm", ".ppm", ".pnm", ".gif")
#: lossy image formats, refused in a folder of patterns
LOSSY_SUFFIXES = (".jpg", ".jpeg", ".jpe", ".webp")
_TIFF = (".tif", ".tiff")


def memory_check(n_values: float, what: str, p: Path, hint: str = "") -> None:
    """Refuse (one line) ``n_values`` values that would not fit in memory checked as float64."""
    from ..machine import _gb, available_memory

    need = float(n_values) * 8 * 2  # float64 copies while checking
    if need > 0.8 * available_memory():
        raise ConfigError(f"{what} {p} holds {n_values:.3g} values: {_gb(need)} to check, "
                          f"more than the memory available{hint}")


def block_reduce(img: np.ndarray, size: int, label: str) -> np.ndarray:
    """An ``(H, W)`` image of ``size x size`` blocks of mirrors, each at one state, as the
    ``(size, size)`` pattern (one value a block); one line where it is not."""
    h, w = img.shape[-2:]
    if h != w:  # (a DMD's mirrors are square: rectangular blocks are a frame not cropped)
        raise ConfigError(f"--pattern-size {size}: {label} is {w} x {h}, not square: crop it "
                          f"to the square region the scene is imaged through")
    if h % size:
        raise ConfigError(f"--pattern-size {size}: {label} is {w} x {h}, not {size} x {size} "
                          f"blocks of mirrors (crop it to the region the scene is imaged "
                          f"through)")
    kh, kw = h // size, w // size
    if kh == kw == 1:
        return img
    blocks = img.reshape(img.shape[:-2] + (size, kh, size, kw))
    lo, hi = blocks.min(axis=(-3, -1)), blocks.max(axis=(-3, -1))
    if np.any(lo != hi):
        r, c = np.argwhere(lo != hi)[0][-2:]
        raise ConfigError(f"--pattern-size {size}: {label}'s block at row {r}, column {c} "
                          f"({kw} x {kh} mirrors) holds two states, so the pattern is finer "
                          f"than {size} x {size}")
    return np.ascontiguousarray(lo)


def reduce_patterns(arr: np.ndarray, size: int, label: str) -> np.ndarray:
    """Patterns ``(M, H, W)``, or ``(M, H*W)`` whose rows are square images flattened
    row-major, read as ``size x size`` blocks (:func:`block_reduce`): ``--pattern-size``
    on a file's array or an array given to the API alike; one line for any other shape."""
    if arr.ndim == 2 and arr.shape[0] >= 2 and math.isqrt(arr.shape[1]) ** 2 == arr.shape[1]:
        side = math.isqrt(arr.shape[1])
        arr = arr.reshape(arr.shape[0], side, side)
    if arr.ndim != 3:
        raise ConfigError(f"--pattern-size {size}: {label} holds an array of shape "
                          f"{arr.shape}, not (M, H, W) patterns")
    return block_reduce(arr, size, label)


def _block_side(img: np.ndarray) -> int:
    """The side K of the square blocks of one state that ``img`` (``(..., H, W)``) is made
    of (1 where none)."""
    k = math.gcd(img.shape[-2], img.shape[-1])
    for axis in (-2, -1):
        moved = np.moveaxis(img, axis, 0)
        change = np.flatnonzero(np.any((moved[1:] != moved[:-1]).reshape(
            moved.shape[0] - 1, -1), axis=1)) + 1
        for c in change:
            k = math.gcd(k, int(c))
            if k == 1:
                return 1
    return k


def _display_levels(img: np.ndarray, label: str) -> np.ndarray:
    """One image as a 2-D array of levels as stored (alpha that is the same everywhere
    dropped, RGB with equal channels made grey)."""
    if np.iscomplexobj(img) or not (np.issubdtype(img.dtype, np.number) or img.dtype == bool):
        raise ConfigError(f"pattern image {label} holds {img.dtype} values, not grey levels")
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
    return img


def _pil_pages(path: Path, label: str, turned: dict[str, int] | None = None
               ) -> list[np.ndarray]:
    """Every page of an image file through Pillow, palettes applied; ``turned``, where
    given, receives the file's EXIF orientation where it is not 1 (as stored)."""
    from PIL import Image, ImageSequence, UnidentifiedImageError

    try:
        with Image.open(path) as im:
            if turned is not None:
                _turned(turned, path, im.getexif().get(274))
            pages = []
            for page in ImageSequence.Iterator(im):
                if page.mode in ("P", "PA", "CMYK", "YCbCr", "LAB", "HSV"):
                    page = page.convert("RGBA" if "transparency" in page.info
                                        or page.mode == "PA" else "RGB")
                pages.append(np.array(page))
    except (OSError, UnidentifiedImageError, ValueError, SyntaxError) as exc:
        reason = first_line(exc)
        raise ConfigError(f"cannot read pattern image {label}: {reason[:120]}") from None
    if not pages or pages[0].size == 0:
        raise ConfigError(f"pattern image {label} holds no image")
    return pages


def _tiff_pages(path: Path, label: str, each=None, turned: dict[str, int] | None = None
                ) -> list[np.ndarray]:
    """Every page of a TIFF as displayed (a min-is-white page inverted), through tifffile,
    or Pillow where tifffile needs ``imagecodecs`` for the compression; ``each(page, i)``,
    where given, is applied to each page as it is read (the memory is then its results');
    ``turned``, where given, receives the file's orientation tag where it is not 1."""
    import logging

    import tifffile

    quiet = logging.getLogger("tifffile")
    level = quiet.level
    quiet.setLevel(logging.CRITICAL)
    try:
        with tifffile.TiffFile(path) as tif:
            pages = []
            if each is not None and len(tif.pages):
                each(None, len(tif.pages), tif.pages[0].shape)  # (the memory, before reading)
            for i, page in enumerate(tif.pages):
                if turned is not None:
                    tag = page.tags.get(274)
                    _turned(turned, path, None if tag is None else tag.value)
                arr = page.asarray()
                if page.photometric == tifffile.PHOTOMETRIC.MINISWHITE:
                    if arr.dtype == bool:
                        arr = ~arr
                    elif np.issubdtype(arr.dtype, np.integer):
                        arr = (2 ** int(page.bitspersample) - 1) - arr
                    else:
                        raise ConfigError(f"pattern image {label}: a min-is-white TIFF of "
                                          f"{arr.dtype} values is not read (save it "
                                          f"min-is-black)")
                pages.append(arr if each is None else each(arr, i))
    except ConfigError:
        raise
    except Exception as exc:
        if "imagecodecs" in str(exc):  # (LZW, CCITT: Pillow decodes them itself)
            pages = _pil_pages(path, label, turned)
            return pages if each is None else [each(pg, i) for i, pg in enumerate(pages)]
        reason = first_line(exc)
        raise ConfigError(f"cannot read pattern image {label} as a TIFF: {reason[:120]}"
                          ) from None
    finally:
        quiet.setLevel(level)
    if not pages or pages[0].size == 0:
        raise ConfigError(f"pattern image {label} holds no image")
    return pages


def _binary_level(img: np.ndarray) -> int | None:
    """The one level besides 0 that an integer image holds (0 where it holds only 0), or
    None where it holds more (grey levels)."""
    if img.dtype == bool:
        return 1
    if not np.issubdtype(img.dtype, np.integer) or img.min() < 0:
        return None
    top = int(img.max())
    return top if top == 0 or np.all((img == 0) | (img == top)) else None


def _full_scale(dtype: np.dtype) -> float:
    """The full scale grey levels are read over: 255 / 65535 for unsigned 8- and 16-bit
    images; 1 for any other type (its levels stay as they are: above 1, refused by the
    patterns' check, which says to divide; a signed int16 image's 0..255 read over 32767 gave
    a reflectivity 128 times high without a word, an audit of stop 67)."""
    if dtype.kind == "u" and dtype.itemsize <= 2:
        return float(np.iinfo(dtype).max)
    return 1.0


def _mixed(where: str, which: str, dtype: np.dtype, top: float) -> ConfigError:
    """The refusal of 0/1 images of a type whose full scale is more, beside grey ones: read
    over the scale, their 1s would be 1/255 (a uint8 set of 0/1 patterns with one of 0..255
    levels, or one stray 2, read every 0/1 pattern at 1/255 with exit 0: an audit)."""
    return ConfigError(f"{where}: {which} hold only 0 and 1 as {dtype}, beside grey levels up "
                       f"to {top:g}: 0/1 states with a stray value, or {dtype} levels whose "
                       f"1 is 1/{_full_scale(dtype):g}? give the mirror states as floats in "
                       f"[0, 1] (or every binary pattern at one level)")


def _sixteen_note(where: str, top: int) -> None:
    warnings.warn(f"{where}: 16-bit grey levels up to {top}, read over 65535 (levels of 12 "
                  f"bits or fewer stored in 16? the depths are the same; the reflectivity "
                  f"reads {65535 // 4095} or more times low)", stacklevel=5)


def _levels_note(where: str, seen: set) -> None:
    if len(seen) > 1:
        seen = sorted(seen)
        warnings.warn(f"{where}: the images are binary at different levels "
                      f"({', '.join(map(str, seen[:4]))}{' ...' if len(seen) > 4 else ''})"
                      f": each is read as off and on", stacklevel=5)


def _array_states(arr: np.ndarray, where: str) -> np.ndarray:
    """:func:`to_states` of one ``(M, H, W)`` integer or boolean array, vectorised (an image
    at a time took 11.9 s for 16384 patterns of 128 x 128, against 4.9 s for floats)."""
    if arr.dtype == bool:
        return arr.astype(np.float64)
    flat = arr.reshape(arr.shape[0], -1)
    low, top = flat.min(axis=1), flat.max(axis=1)
    binary = (low >= 0) & np.all((flat == 0) | (flat == top[:, None]), axis=1)
    if binary.all():
        _levels_note(where, {int(t) for t in top if t})
        return (arr != 0).astype(np.float64)
    scale = _full_scale(arr.dtype)
    ones = np.flatnonzero(binary & (top == 1))
    if scale > 1 and ones.size and low.min() >= 0:
        raise _mixed(where, f"pattern {int(ones[0])}{' and others' if ones.size > 1 else ''}",
                     arr.dtype, float(top.max()))
    if low.min() < 0 or scale == 1:
        return arr.astype(np.float64)  # (as stored: refused above 1 by the check)
    if arr.dtype.itemsize == 2 and int(top.max()) <= 4095:
        _sixteen_note(where, int(top.max()))
    return arr / scale


def to_states(images: list[np.ndarray] | np.ndarray, where: str) -> np.ndarray:
    """Stored levels -> mirror states: a sequence of binary images (each holding 0 and one
    other level) as 0/1 whatever their depth; else grey levels over their type's full scale
    (:func:`_full_scale`), a 0/1 image of an 8- or 16-bit type beside grey ones refused;
    floats as they are (checked later). ``images``: a list (files of their own types) or one
    ``(M, H, W)`` array (vectorised); ``where`` names them in a warning or refusal
    (``--patterns FILE``)."""
    if isinstance(images, np.ndarray) and images.ndim == 3 and (
            np.issubdtype(images.dtype, np.integer) or images.dtype == bool):
        return _array_states(images, where)
    levels = [_binary_level(img) for img in images]
    if all(lv is not None for lv in levels):
        stack = np.stack([img != 0 for img in images]).astype(np.float64)
        kinds: dict[str, set] = {}  # (levels of one type: 1-bit beside 0/255 is no news)
        for img, lv in zip(images, levels, strict=True):
            if lv:
                kinds.setdefault(img.dtype.str, set()).add(lv)
        _levels_note(where, max(kinds.values(), key=len, default=set()))
        return stack
    ones = [i for i, (img, lv) in enumerate(zip(images, levels, strict=True))
            if lv == 1 and img.dtype != bool and _full_scale(img.dtype) > 1]
    if ones:
        raise _mixed(where, f"image {ones[0]}{' and others' if len(ones) > 1 else ''}",
                     images[ones[0]].dtype,
                     max(float(np.max(img)) for img, lv in zip(images, levels, strict=True)
                         if lv is None))
    out = np.empty((len(images),) + images[0].shape, dtype=np.float64)
    sixteen = []
    for i, img in enumerate(images):
        if np.issubdtype(img.dtype, np.integer) or img.dtype == bool:
            out[i] = img / _full_scale(img.dtype) if img.min() >= 0 else img
            if img.dtype.itemsize == 2 and np.issubdtype(img.dtype, np.unsignedinteger):
                sixteen.append(int(img.max()))
        else:
            out[i] = img
    if sixteen and max(sixteen) <= 4095:
        _sixteen_note(where, max(sixteen))
    return out


def _order(files: list[Path], folder: Path) -> list[Path]:
    """Plain order where every name has one length, else natural; ties refused."""
    if len({len(f.name) for f in files}) == 1:
        ordered = sorted(files, key=lambda f: f.name)
    else:
        def key(f: Path) -> list:
            return [int(t) if t.isdigit() else t.lower() for t in re.split(r"(\d+)", f.stem)]
        ordered = sorted(files, key=lambda f: (key(f), f.name))
        for a, b in zip(ordered, ordered[1:], strict=False):
            if key(a) == key(b):
                raise ConfigError(f"--patterns {folder}: {a.name} and {b.name} have the same "
                                  f"number, so their order is not known: rename one")
    stems: dict[str, str] = {}
    for f in ordered:
        if f.stem in stems:
            raise ConfigError(f"--patterns {folder}: {stems[f.stem]} and {f.name} are one "
                              f"pattern saved twice? keep one per pattern")
        stems[f.stem] = f.name
    return ordered


def _turned(turned: dict[str, int], path: Path, value) -> None:
    """Note a file's orientation tag (TIFF tag 274, or an EXIF one) where it is not 1, the
    image as stored."""
    if value is not None and int(value) != 1:
        turned.setdefault(path.name, int(value))


def _orientation_note(turned: dict[str, int], n_files: int, where: Path) -> None:
    """Say, once, that images carry an orientation tag that is not applied: a viewer that
    honours it shows them turned or mirrored, and the depth map followed the stored rows
    without a word (an outside audit of 2026-12-01: a TIFF tagged 3 read as the map turned
    half a turn). ``turned``: file name -> tag, as :func:`_turned` noted them."""
    if turned:
        values = ", ".join(str(v) for v in sorted(set(turned.values())))
        warnings.warn(f"--patterns {where}: {len(turned)} of {n_files} image files carry an "
                      f"orientation tag ({values}; 1 is as stored) that asks a viewer to "
                      f"turn or mirror them, e.g. {next(iter(turned))}: they are "
                      f"read as stored, row 0 the first row stored, as a DMD loader that "
                      f"ignores the tag shows them; if yours applies it, turn the depth map "
                      f"the same way", stacklevel=3)


def folder_patterns(folder: Path, size: int | None = None) -> np.ndarray:
    """One pattern per image file of ``folder`` (the module's conventions), ``(M, N, N)``
    mirror states; each image reduced to ``size x size`` blocks as it is read."""
    entries = [e for e in folder.iterdir() if not e.name.startswith(".")]
    lossy = sorted(e.name for e in entries if e.suffix.lower() in LOSSY_SUFFIXES)
    if lossy:
        raise ConfigError(f"--patterns {folder} holds lossy images ({lossy[0]}"
                          f"{' ...' if len(lossy) > 1 else ''}): a JPEG's compression blurs "
                          f"each mirror's state; give PNG, BMP or TIFF files")
    named = [e for e in entries if e.suffix.lower() in IMAGE_SUFFIXES]
    odd = sorted(e.name for e in named if not e.is_file())
    if odd:
        raise ConfigError(f"--patterns {folder}: {odd[0]} is named as an image but is no "
                          f"readable file (a broken link, a folder): it would shift every "
                          f"pattern after it")
    if not named:
        raise ConfigError(f"--patterns {folder} is a folder with no image in it (one "
                          f"{'/'.join(IMAGE_SUFFIXES)} file per pattern, in name order)")
    files = _order(named, folder)
    images: list[np.ndarray] = []
    first: tuple = ()
    turned: dict[str, int] = {}
    for f in files:
        pages = (_tiff_pages(f, f.name, turned=turned) if f.suffix.lower() in _TIFF
                 else _pil_pages(f, f.name, turned))
        if len(pages) > 1:
            kind = "a multi-page TIFF: give its path" if f.suffix.lower() in _TIFF else \
                "an image of several frames: give one image per pattern"
            raise ConfigError(f"--patterns {folder}: {f.name} is {kind}")
        img = _display_levels(pages[0], f.name)
        if images and img.shape != first:
            raise ConfigError(f"--patterns {folder}: {f.name} is {img.shape[1]} x "
                              f"{img.shape[0]} pixels, {files[0].name} {first[1]} x {first[0]}"
                              f": every pattern image must have the same size")
        if not images:  # (the memory the sequence takes, from its first image)
            first = img.shape
            side = img.size if size is None else size * size
            memory_check(float(side) * len(files), "--patterns", folder,
                         "" if size else ": images at the DMD's resolution? --pattern-size N "
                                         "reads each as N x N blocks")
        images.append(img if size is None else block_reduce(img, size, f.name))
    _orientation_note(turned, len(files), folder)
    return _sized(to_states(images, f"--patterns {folder}"), size, folder)


def tiff_patterns(p: Path, size: int | None = None) -> np.ndarray:
    """One pattern per page of a multi-page TIFF, as :func:`folder_patterns` reads images:
    its memory checked before a page is decoded, each page reduced as it is read."""
    first: list = []

    def each(page, i, shape=None):
        if page is None:  # (the page count and size, before any is decoded)
            side = float(np.prod(shape[:2])) if size is None else float(size * size)
            memory_check(side * i, "--patterns", p,
                         "" if size else ": pages at the DMD's resolution? --pattern-size N "
                                         "reads each as N x N blocks")
            return None
        img = _display_levels(page, f"{p.name} page {i}")
        if not first:
            first.append(img.shape)
        elif img.shape != first[0]:
            raise ConfigError(f"--patterns {p}: page {i} is {img.shape[1]} x {img.shape[0]}, "
                              f"page 0 {first[0][1]} x {first[0][0]} (a preview page?): every "
                              f"page must be a pattern of one size")
        return img if size is None else block_reduce(img, size, f"{p.name} page {i}")

    turned: dict[str, int] = {}
    images = _tiff_pages(p, p.name, each, turned)
    _orientation_note(turned, 1, p)
    if len(images) == 1:
        raise ConfigError(f"--patterns {p} is a TIFF of one page: give one page per pattern "
                          f"(a multi-page TIFF) or a folder of images")
    return _sized(to_states(images, f"--patterns {p}"), size, p)


def block_hint(stack: np.ndarray, where, what: str = "image", stacklevel: int = 3) -> None:
    """Warn where every pattern of ``stack`` (``(M, H, W)``, at least 8 x 8) is made of K x K
    blocks of one state, K > 1: ``--pattern-size`` reads them as the patterns they show, the
    same information in a map K^2 times smaller to solve."""
    if stack.ndim != 3 or stack.shape[1] < 8 or stack.shape[0] == 0:
        return
    k = _block_side(stack)
    if k > 1 and stack.shape[1] // k >= 4 and stack.shape[2] // k >= 4:
        warnings.warn(f"--patterns {where}: every {what} is made of {k} x {k} blocks of "
                      f"mirrors at one state: --pattern-size "
                      f"{stack.shape[1] // k if stack.shape[1] == stack.shape[2] else '...'} "
                      f"reads them as the patterns they show ({stack.shape[2] // k} x "
                      f"{stack.shape[1] // k}), the same information in a map "
                      f"{k * k} times smaller to solve", stacklevel=stacklevel)


def _sized(stack: np.ndarray, size: int | None, where: Path) -> np.ndarray:
    """Images read at their own size: a warning where they are blocks of one state (the
    size that holds the same information), one line where they are not square."""
    if size is None:
        block_hint(stack, where, "image", stacklevel=4)
    if stack.shape[1] != stack.shape[2]:
        raise ConfigError(f"--patterns {where}: the images are {stack.shape[2]} x "
                          f"{stack.shape[1]}, not square: crop them to the square region "
                          f"the scene is imaged through (pad a region that is not square "
                          f"with mirrors at 0)")
    return stack
