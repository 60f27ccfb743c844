"""Scenes from the user's files: ``.npy`` depth, ``.npz`` with depth / reflectivity / valid,
or a grey image mapped into the depth window (see :func:`spslidar.scenes.load_scene`).
"""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np

from ..errors import SceneError
from .base import (
    _IMAGE_SUFFIXES,
    _IMAGE_WINDOW,
    MAX_SCENE_DEPTH_M,
    SCENE_FILE_SUFFIXES,
    Scene,
    _finish,
    _grey_to_scene,
    _pixels,
    _reason,
    _window,
)


def _check_depth_values(label: str, depth: np.ndarray, where: np.ndarray | None = None) -> None:
    bad = ~np.isfinite(depth) | (np.nan_to_num(depth, nan=0.0) < 0)
    if where is not None:
        bad &= where
    count = int(np.count_nonzero(bad))
    if count:
        hint = ("; holes without a depth belong in an .npz with a 'valid' mask (False there)"
                if where is None and np.isnan(depth).any() else "")
        raise SceneError(
            f"scene file {label}: {_pixels(count)} NaN, infinite or negative depth "
            f"(depth must be finite metres >= 0){hint}"
        )
    far = depth if where is None else depth[where]
    if far.size and float(far.max()) > MAX_SCENE_DEPTH_M:
        raise SceneError(
            f"scene file {label}: depths up to {float(far.max()):.3g} m are beyond any lidar "
            f"range (at most {MAX_SCENE_DEPTH_M:.0e} m): are the values in metres?"
        )


def _as_2d(label: str, arr: np.ndarray, what: str) -> np.ndarray:
    arr = np.asarray(arr)
    if arr.ndim != 2:
        raise SceneError(f"scene file {label}: {what} must be a 2-D array, got shape {arr.shape}")
    if arr.size == 0:
        raise SceneError(f"scene file {label}: {what} is empty")
    if np.iscomplexobj(arr):
        raise SceneError(f"scene file {label}: {what} is complex ({arr.dtype}); it must be real")
    if arr.dtype == bool and what != "valid mask":
        raise SceneError(f"scene file {label}: {what} is a boolean array; it must hold numbers "
                         f"(a boolean array belongs in the 'valid' key of an .npz)")
    if not (np.issubdtype(arr.dtype, np.number) or arr.dtype == bool):
        raise SceneError(f"scene file {label}: {what} must be numeric, got dtype {arr.dtype}")
    return arr


def _check_magic(path: Path, label: str, magic: bytes, kind: str) -> None:
    """Raise SceneError unless the file starts with ``magic``."""
    try:
        with open(path, "rb") as fh:
            head = fh.read(len(magic))
    except OSError as exc:
        raise SceneError(f"cannot read scene file {label}: {_reason(exc)}") from None
    if head != magic:
        raise SceneError(f"cannot read scene file {label}: it is not a {kind} file")


def _load_npy(path: Path, label: str) -> tuple[np.ndarray, np.ndarray, np.ndarray, list[str]]:
    from ..npyfile import load_npy

    _check_magic(path, label, b"\x93NUMPY", "NumPy .npy")
    depth = load_npy(path, "scene file", error=SceneError)  # (its header checked first)
    depth = _as_2d(label, depth, "depth").astype(np.float64)
    _check_depth_values(label, depth)
    return depth, np.ones_like(depth), np.ones(depth.shape, dtype=bool), []


def _load_npz(path: Path, label: str) -> tuple[np.ndarray, np.ndarray, np.ndarray, list[str]]:
    from ..npyfile import check_npz_sizes

    _check_magic(path, label, b"PK", "NumPy .npz (zip)")
    check_npz_sizes(path, f"scene file {label}", error=SceneError)  # (a deflated bomb)
    try:
        with np.load(path, allow_pickle=False) as npz:
            keys = set(npz.files)
            if "depth" not in keys:
                raise SceneError(
                    f"scene file {label} has no 'depth' array (found: "
                    f"{', '.join(sorted(keys)) or 'none'}); optional keys are 'reflectivity' "
                    "and 'valid'"
                )
            arrays = {k: npz[k] for k in ("depth", "reflectivity", "valid") if k in keys}
            unknown = sorted(keys - set(arrays))
    except SceneError:
        raise
    except Exception as exc:
        raise SceneError(f"cannot read scene file {label} as .npz: {_reason(exc)}") from None
    depth = _as_2d(label, arrays["depth"], "depth").astype(np.float64)
    if "valid" in arrays:
        valid = _as_2d(label, arrays["valid"], "valid mask")
        if valid.shape != depth.shape:
            raise SceneError(
                f"scene file {label}: valid mask has shape {valid.shape}, depth has {depth.shape}"
            )
        if valid.dtype != bool and not np.isin(valid, (0, 1)).all():
            # (a NaN was cast to True, and the depth under it then blamed)
            raise SceneError(f"scene file {label}: the valid mask must hold booleans or 0/1 "
                             f"values")
        valid = valid.astype(bool)
        if not valid.any():
            raise SceneError(f"scene file {label}: the valid mask marks no pixel as valid")
    else:
        valid = np.ones(depth.shape, dtype=bool)
    _check_depth_values(label, depth, valid)
    # (a depth given where the mask says "do not score" is kept: it was replaced by the
    # nearest valid pixel's, and a ramp valid at one pixel was simulated as a flat wall)
    depth = np.where(valid | (np.isfinite(depth) & (depth > 0)), depth, 0.0)
    if "reflectivity" in arrays:
        refl = _as_2d(label, arrays["reflectivity"], "reflectivity").astype(np.float64)
        if refl.shape != depth.shape:
            raise SceneError(
                f"scene file {label}: reflectivity has shape {refl.shape}, depth has {depth.shape}"
            )
        out = ~np.isfinite(refl) | (np.nan_to_num(refl) < 0) | (np.nan_to_num(refl) > 1)
        bad = int(np.count_nonzero(out & (valid | np.isfinite(refl))))
        if bad:
            raise SceneError(
                f"scene file {label}: {bad} reflectivity values are NaN or lie outside [0, 1] "
                "(reflectivity must be in [0, 1]; NaN only where 'valid' is False)"
            )
        refl = np.where(np.isfinite(refl), refl, 0.0)  # no reflectivity given: no return
    else:
        refl = np.ones_like(depth)
    notes = ([f"scene file {label}: key(s) {', '.join(unknown)} ignored (a scene .npz holds "
              f"'depth', and optionally 'reflectivity' and 'valid')"] if unknown else [])
    return depth, refl, valid, notes


def _tiff_page_count(path: Path) -> int:
    """How many pages a TIFF holds (1 for any other file, or one tifffile cannot open:
    the image reader then says why)."""
    if path.suffix.lower() not in (".tif", ".tiff"):
        return 1
    try:
        import tifffile

        with tifffile.TiffFile(path) as tif:
            return max(1, len(tif.pages))
    except Exception:
        return 1


def _load_image(path: Path, label: str) -> tuple[np.ndarray, np.dtype, tuple[float, float]]:
    import logging

    from skimage import io
    from skimage.color import rgb2gray

    if path.is_file() and path.stat().st_size == 0:  # (imageio's plugin list, cut: an audit)
        raise SceneError(f"cannot read scene image {label}: the file is empty (0 bytes)")
    quiet = logging.getLogger("tifffile")  # (it logged "invalid offset to first page" on a
    level = quiet.level                     # damaged file, beside the refusal: an audit)
    quiet.setLevel(logging.CRITICAL)
    try:
        pages = _tiff_page_count(path)
        if pages == 1:
            with warnings.catch_warnings():  # imageio warns while probing plugins on bad files
                warnings.simplefilter("ignore")
                img = np.asarray(io.imread(path))
            if img.size == 0:  # (a TIFF with no page read as an empty array: "shape (0,)")
                raise ValueError("no image in it")
    except Exception as exc:
        reason = _reason(exc)
        # (cut at a word, not inside one: "Based on the extension, the fo...", an audit)
        reason = reason if len(reason) <= 120 else reason[:117].rsplit(" ", 1)[0] + " ..."
        raise SceneError(
            f"cannot read scene image {label} ({reason}): use a grey or RGB "
            f"{'/'.join(_IMAGE_SUFFIXES)} image"
        ) from None
    finally:
        quiet.setLevel(level)
    if pages > 1:
        # (a 3- or 4-page TIFF was read as one RGB(A) image, its pages mixed into one grey
        # map by the luminance weights, silently: an outside audit of 2026-12-03)
        raise SceneError(f"scene image {label} is a TIFF of {pages} pages: a scene is one "
                         f"image; save the page you mean on its own (or give a .npy depth "
                         f"map)")
    if np.iscomplexobj(img) or not (np.issubdtype(img.dtype, np.number)
                                    or img.dtype == bool):
        # a complex TIFF (e.g. a saved FFT) has no grey level to map onto depth
        raise SceneError(f"scene image {label} holds {img.dtype} values, not grey levels: use "
                         f"a grey or RGB image (or a real .npy depth map)")
    # the file's own type and range, before an RGB image is made grey (an 8-bit RGB PNG was
    # said to be "(float64, 0 .. 1)", a float TIFF or 16-bit PNG, an audit)
    kind = img.dtype
    span = (float(np.nanmin(img)), float(np.nanmax(img))) if img.size else (0.0, 0.0)
    if img.ndim == 3 and img.shape[-1] == 2:  # grey + alpha: the alpha dropped, as RGBA's
        img = img[..., 0]
    if img.ndim == 3 and img.shape[-1] in (3, 4):
        if img.shape[-1] == 4:
            img = img[..., :3]
        img = rgb2gray(img)
    if img.ndim != 2 or img.size == 0:
        raise SceneError(
            f"scene image {label} must be a 2-D grey or RGB image, got shape {img.shape}"
        )
    img = img.astype(np.float64)
    if not np.isfinite(img).all():
        count = int(np.count_nonzero(~np.isfinite(img)))
        raise SceneError(f"scene image {label}: {_pixels(count)} NaN or infinite values")
    return img, kind, span


def _load_file(path: Path, size: int, depth_min: float | None, depth_max: float | None) -> Scene:
    label = path.name
    if not path.exists():
        raise SceneError(f"scene file not found: {path}")
    if not path.is_file():
        raise SceneError(f"scene path is not a file: {path}")
    suffix = path.suffix.lower()
    if suffix in _IMAGE_SUFFIXES:
        lo, hi = _window(depth_min, depth_max, _IMAGE_WINDOW)
        img, kind, span = _load_image(path, label)
        scene = _grey_to_scene(label, img, size, lo, hi, surfaces=True)
        if kind.kind == "f" or kind.itemsize > 1:  # a float TIFF or 16-bit PNG: metres?
            scene.notes.append(
                f"scene image {label} ({kind}, {span[0]:.4g} .. {span[1]:.4g}) is read as grey "
                f"levels mapped onto {lo:g}-{hi:g} m (--depth-min/--depth-max), not as "
                f"distances: a depth map in metres belongs in an .npy or .npz")
        if suffix in (".jpg", ".jpeg"):  # (taken without a word, an outside audit)
            scene.notes.append(
                f"scene image {label} is a JPEG, whose lossy compression moves grey levels "
                f"(blocks, ringing at edges) and with them the depths they map to: a PNG or "
                f"TIFF keeps them as drawn")
        return scene
    if suffix == ".npy":
        depth, refl, valid, notes = _load_npy(path, label)
    elif suffix == ".npz":
        depth, refl, valid, notes = _load_npz(path, label)
    else:
        raise SceneError(
            f"scene file {label} has an unsupported format: use {', '.join(SCENE_FILE_SUFFIXES)}"
        )
    known = np.asarray(depth)[np.asarray(valid, dtype=bool)]
    if known.size and not np.any(known > 0) and depth_min is None and depth_max is None:
        # a lidar measures distance: a scene entirely at 0 m is a wrong file or wrong units
        raise SceneError(f"scene file {label}: every depth is 0 m; give distances from the "
                         f"lidar in metres (or a window with --depth-min/--depth-max)")
    zeros = int(np.count_nonzero(known == 0))
    if zeros and depth_min is None:  # (--depth-max alone keeps the nearest depth: a review)
        # (0 is "no data" in many depth datasets: such holes were simulated as a surface at
        # 0 m and scored, over 100 % of the pixels, with no word, an audit; --depth-min maps
        # the file's nearest depth to it, so 0 is a depth there)
        raise SceneError(f"scene file {label}: {_pixels(zeros)} a depth of 0 m, where a lidar "
                         f"measures no distance: holes without a depth (0 in many depth "
                         f"datasets) belong in an .npz with a 'valid' mask, False there")
    scene = _finish(label, depth, refl, valid, size, depth_min, depth_max, surfaces=True)
    scene.notes[:0] = notes
    return scene
