"""Scenes: per-pixel depth (metres), reflectivity and ground-truth validity.

Built-in scenes need no network: they use images shipped inside scikit-image or are synthesised.

* ``camera`` (default): stand-in for the paper's 'airplane' (Fig. 2a, 20-20.8 m), the
  ``skimage.data.camera`` grey image mapped linearly onto the depth window.
* ``motorcycle``: stand-in for the paper's 'doll' (Fig. 6a), the Middlebury 2014 "Motorcycle"
  ground-truth disparity in ``skimage.data.stereo_motorcycle`` converted to metres.
* ``steps``: a back plane with raised rectangles and a disc at distinct depths.
* ``ramp``: a smooth linear ramp with a sphere-like bump.
* ``room``: a wide-depth indoor scene (2-5 m): a receding floor, a slanted side wall, a table
  on one-pixel legs, a one-pixel lamp pole, a dark cabinet and a dark poster on the back wall.
* ``street``: a wide-depth outdoor scene (2-5 m): a receding road, a slanted facade with dark
  windows, a parked car, three one-pixel poles (one dark), a slanted one-pixel wire and a dark
  far backdrop.

User scenes are read from ``.npy``, ``.npz`` or grey images (``.png``, ``.tif``, ``.tiff``,
``.jpg``, ``.jpeg``); see :func:`load_scene`.
"""

from __future__ import annotations

import math
import os
import warnings
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from . import scene_cache
from .errors import SceneError

__all__ = [
    "BUILTIN_SCENES",
    "DEFAULT_SCENE",
    "SCENE_FILE_SUFFIXES",
    "Scene",
    "load_scene",
    "motorcycle_source",
]

#: Names of the built-in scenes (the first is the default).
BUILTIN_SCENES: tuple[str, ...] = ("camera", "motorcycle", "steps", "ramp", "room", "street")
#: The default scene.
DEFAULT_SCENE = "camera"
#: File suffixes accepted for user scenes.
SCENE_FILE_SUFFIXES: tuple[str, ...] = (".npy", ".npz", ".png", ".tif", ".tiff", ".jpg", ".jpeg")

_IMAGE_SUFFIXES = (".png", ".tif", ".tiff", ".jpg", ".jpeg")
#: the farthest depth a scene file may hold, in metres (single-photon lidar has ranged ~200 km;
#: a larger value is a unit mistake, and would overflow the range gate's arithmetic)
MAX_SCENE_DEPTH_M = 1e6
_MIN_SIZE = 4
_MAX_SIZE = 2048
# Share of valid source pixels an output pixel needs to stay valid after resizing.
_MASK_VALID_SHARE = 0.999
#: stereo dropouts of at most this many source pixels are filled and counted as valid
_MOTO_PINHOLE_PX = 25

# Default depth windows (metres) of the scenes defined by a grey level or synthesised.
_IMAGE_WINDOW = (20.0, 20.8)  # the paper's 'airplane': 20 to 20.8 m (Sec. III)
_STEPS_WINDOW = (10.0, 10.6)
_RAMP_WINDOW = (5.0, 5.5)
_ROOM_WINDOW = (2.0, 5.0)
_STREET_WINDOW = (2.0, 5.0)
#: width of the thin structures (poles, legs, wire) of ``room`` and ``street``: one pixel at
#: 64 x 64, never less than one pixel
_THIN = 1.0 / 64

# Calibration of skimage.data.stereo_motorcycle (Middlebury 2014, down-sampled by 4).
_MOTO_FOCAL_PX = 994.978
_MOTO_DOFFS_PX = 31.086
_MOTO_BASELINE_M = 0.193001
_MOTO_REFLECTIVITY = (0.2, 1.0)


@dataclass
class Scene:
    """A scene seen by the lidar.

    Parameters
    ----------
    name : str
        Built-in name or file name.
    depth : numpy.ndarray
        ``(N, N)`` float64 depth in metres (finite and non-negative everywhere; pixels without
        ground truth hold a plausible fill value).
    reflectivity : numpy.ndarray
        ``(N, N)`` float64 reflectivity ``alpha(x, y)`` in [0, 1].
    valid : numpy.ndarray
        ``(N, N)`` bool, True where the ground-truth depth is known; metrics ignore the others.
    notes : list of str
        What loading did that a user should hear about (e.g. a non-square file cropped).
    has_truth : bool
        False for a measured acquisition (``spslidar reconstruct`` without ``--truth``): the
        depth is a placeholder, no pixel is valid, and no truth-based metric is computed.

    Raises
    ------
    SceneError
        If the arrays are not square, of different shapes, or out of range.

    Notes
    -----
    ``depth`` and ``reflectivity`` are the ``d(x, y)`` and ``alpha(x, y)`` of eqs. (1)-(8).
    """

    name: str
    depth: np.ndarray
    reflectivity: np.ndarray
    valid: np.ndarray
    #: what loading did that a user should hear about (e.g. a non-square file cropped)
    notes: list[str] = field(default_factory=list)
    has_truth: bool = True

    def __post_init__(self) -> None:
        self.depth = np.asarray(self.depth, dtype=np.float64)
        self.reflectivity = np.asarray(self.reflectivity, dtype=np.float64)
        self.valid = np.asarray(self.valid, dtype=bool)
        d = self.depth
        if d.ndim != 2 or d.shape[0] != d.shape[1]:
            raise SceneError(
                f"scene {self.name!r}: depth must be a square 2-D array, got {d.shape}"
            )
        for what, arr in (("reflectivity", self.reflectivity), ("valid mask", self.valid)):
            if arr.shape != d.shape:
                raise SceneError(
                    f"scene {self.name!r}: {what} has shape {arr.shape}, depth has {d.shape}"
                )
        bad = int(np.count_nonzero(~np.isfinite(d) | (d < 0)))
        if bad:
            raise SceneError(f"scene {self.name!r}: {_pixels(bad)} NaN, infinite or negative depth")
        r = self.reflectivity
        bad = int(np.count_nonzero(~np.isfinite(r) | (r < 0) | (r > 1)))
        if bad:
            raise SceneError(f"scene {self.name!r}: {bad} reflectivity values lie outside [0, 1]")
        if self.has_truth and not self.valid.any():
            raise SceneError(f"scene {self.name!r}: no pixel has a valid ground-truth depth")

    @property
    def size(self) -> int:
        """Side ``N`` of the square scene, in pixels."""
        return int(self.depth.shape[0])

    @property
    def depth_min(self) -> float:
        """Smallest depth over the valid pixels, in metres."""
        return float(self.depth[self.valid].min())

    @property
    def depth_max(self) -> float:
        """Largest depth over the valid pixels, in metres."""
        return float(self.depth[self.valid].max())


# ---------------------------------------------------------------------------------------------
# helpers


def _one_line(text: object, limit: int = 120) -> str:
    """Collapse whitespace and truncate, so a reader's error fits on one line."""
    line = " ".join(str(text).split())
    return line if len(line) <= limit else line[: limit - 3] + "..."


def _reason(exc: BaseException) -> str:
    """A short one-line reason for a reader's exception (its type and message)."""
    msg = _one_line(exc)
    return f"{type(exc).__name__}: {msg}" if msg else type(exc).__name__


def _pixels(count: int) -> str:
    return "1 pixel has" if count == 1 else f"{count} pixels have"


def _check_size(size) -> int:
    if isinstance(size, (bool, np.bool_)) or not isinstance(size, (int, np.integer)):
        raise SceneError(
            f"scene size must be an integer from {_MIN_SIZE} to {_MAX_SIZE}, got {size!r}"
        )
    size = int(size)
    if not _MIN_SIZE <= size <= _MAX_SIZE:
        raise SceneError(f"scene size {size} is out of range: use {_MIN_SIZE} to {_MAX_SIZE}")
    return size


def _check_bound(value, what: str) -> float | None:
    if value is None:
        return None
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise SceneError(f"{what} must be a number of metres, got {value!r}") from None
    if not math.isfinite(v):
        raise SceneError(f"{what} must be a finite number of metres, got {value!r}")
    if v < 0:
        raise SceneError(f"{what} must be >= 0 m, got {v:g}")
    return v


def _window(
    depth_min: float | None, depth_max: float | None, default: tuple[float, float]
) -> tuple[float, float]:
    """The depth window, each missing end taken from the scene's default."""
    lo = default[0] if depth_min is None else depth_min
    hi = default[1] if depth_max is None else depth_max
    if lo >= hi:
        raise SceneError(
            f"depth window is empty: depth_min {lo:g} m must be less than depth_max {hi:g} m"
        )
    return lo, hi


def _center_crop(arr: np.ndarray) -> np.ndarray:
    h, w = arr.shape[:2]
    s = min(h, w)
    top = (h - s) // 2
    left = (w - s) // 2
    return arr[top : top + s, left : left + s]


def _resize(img: np.ndarray, size: int) -> np.ndarray:
    """Bilinear resize of a square float image, anti-aliased when down-sampling."""
    from skimage.transform import resize

    img = np.asarray(img, dtype=np.float64)
    if img.shape == (size, size):
        return img.copy()
    return resize(
        img,
        (size, size),
        order=1,
        mode="edge",
        anti_aliasing=size < img.shape[0],
        preserve_range=True,
    )


def footprints(src: int, size: int) -> tuple[np.ndarray, np.ndarray]:
    """Source rows (or columns) ``start[i] .. stop[i] - 1`` that output pixel ``i`` covers when
    a side of ``src`` pixels is resized to ``size``."""
    edges = np.arange(size + 1) * src
    return edges[:-1] // size, -((-edges[1:]) // size)  # floor and ceiling division


def _resize_mask(mask: np.ndarray, size: int) -> np.ndarray:
    """Resize a square validity mask: a pixel stays valid when all its source pixels were valid.

    Output pixel ``i`` covers source rows ``floor(i s / N) .. ceil((i + 1) s / N) - 1`` (and
    likewise for columns); the share of valid pixels over that footprint, from an integral
    image, must reach ``_MASK_VALID_SHARE`` (0.999).
    """
    mask = np.asarray(mask, dtype=bool)
    if mask.shape == (size, size):
        return mask.copy()
    if mask.all():
        return np.ones((size, size), dtype=bool)
    src = mask.shape[0]
    start, stop = footprints(src, size)
    integral = np.zeros((src + 1, src + 1))
    integral[1:, 1:] = mask.astype(np.float64).cumsum(0).cumsum(1)
    r0, r1 = start[:, None], stop[:, None]
    c0, c1 = start[None, :], stop[None, :]
    count = integral[r1, c1] - integral[r0, c1] - integral[r1, c0] + integral[r0, c0]
    area = (r1 - r0) * (c1 - c0)
    return count >= _MASK_VALID_SHARE * area


def _small_holes(valid: np.ndarray, max_area: int) -> np.ndarray:
    """Invalid pixels in connected holes of at most ``max_area`` pixels."""
    from scipy.ndimage import label

    lab, n = label(~valid)
    if n == 0:
        return np.zeros_like(valid)
    sizes = np.bincount(lab.ravel())
    small = sizes <= max_area
    small[0] = False
    return small[lab]


def _fill_invalid(depth: np.ndarray, valid: np.ndarray) -> np.ndarray:
    """Fill invalid pixels from the nearest valid pixel."""
    if valid.all():
        return depth
    from scipy.ndimage import distance_transform_edt

    idx = distance_transform_edt(~valid, return_distances=False, return_indices=True)
    return depth[tuple(idx)]


def _remap(depth: np.ndarray, valid: np.ndarray, lo: float, hi: float) -> np.ndarray:
    """Map the valid depth range linearly onto [lo, hi] (a flat scene goes to ``lo``)."""
    dmin = float(depth[valid].min())
    dmax = float(depth[valid].max())
    if dmax > dmin:
        out = lo + (depth - dmin) * ((hi - lo) / (dmax - dmin))
    else:
        out = np.full_like(depth, lo)
    return np.clip(out, lo, hi)


def _grey_to_scene(name: str, grey: np.ndarray, size: int, lo: float, hi: float) -> Scene:
    """A grey image mapped onto the depth window; reflectivity 1."""
    notes = [_crop_note(name, grey.shape, size)] if grey.shape[0] != grey.shape[1] else []
    grey = _resize(_center_crop(grey), size)
    valid = np.ones((size, size), dtype=bool)
    depth = _remap(grey, valid, lo, hi)
    return Scene(name, depth, np.ones((size, size)), valid, notes)


def _crop_note(name: str, shape: tuple[int, ...], size: int) -> str:
    side = min(shape)
    return (f"scene {name} is {shape[0]}x{shape[1]}: its centre {side}x{side} is used "
            f"(resized to {size}x{size})")


def _finish(
    name: str,
    depth: np.ndarray,
    reflectivity: np.ndarray,
    valid: np.ndarray,
    size: int,
    depth_min: float | None,
    depth_max: float | None,
) -> Scene:
    """Fill, crop, resize and optionally remap a full-resolution scene."""
    notes = [_crop_note(name, depth.shape, size)] if depth.shape[0] != depth.shape[1] else []
    depth = _fill_invalid(depth, valid)
    depth = _resize(_center_crop(depth), size)
    reflectivity = np.clip(_resize(_center_crop(reflectivity), size), 0.0, 1.0)
    valid = _resize_mask(_center_crop(valid), size)
    if not valid.any():
        raise SceneError(
            f"scene {name!r}: no pixel keeps a valid depth at size {size}: use a larger size"
        )
    if depth_min is not None or depth_max is not None:
        native = (float(depth[valid].min()), float(depth[valid].max()))
        lo, hi = _window(depth_min, depth_max, native)
        depth = _remap(depth, valid, lo, hi)
    return Scene(name, depth, reflectivity, valid, notes)


# ---------------------------------------------------------------------------------------------
# built-in scenes


def _camera(size: int, depth_min: float | None, depth_max: float | None) -> Scene:
    lo, hi = _window(depth_min, depth_max, _IMAGE_WINDOW)
    hit = scene_cache.lookup("camera", size)
    if hit is None:
        from skimage import data

        return _grey_to_scene("camera", data.camera(), size, lo, hi)
    valid = np.ones((size, size), dtype=bool)
    return Scene("camera", _remap(hit["grey"], valid, lo, hi), np.ones((size, size)), valid)


def _motorcycle(size: int, depth_min: float | None, depth_max: float | None) -> Scene:
    hit = scene_cache.lookup("motorcycle", size)
    if hit is None:
        scene = _motorcycle_computed(size)
    else:
        shape = tuple(int(v) for v in hit["source_shape"])
        scene = Scene("motorcycle", hit["depth"], hit["reflectivity"], hit["valid"],
                      [_crop_note("motorcycle", shape, size)])
    if depth_min is not None or depth_max is not None:  # as _finish, after the resize
        valid = scene.valid
        native = (float(scene.depth[valid].min()), float(scene.depth[valid].max()))
        scene.depth = _remap(scene.depth, valid, *_window(depth_min, depth_max, native))
    return scene


def motorcycle_source() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The motorcycle at full resolution, before cropping and resizing.

    Returns
    -------
    depth : ndarray
        Metres from the Middlebury disparity (pin-holes filled; 0 in the large holes).
    luminance : ndarray
        Grey level of the left image in [0, 1].
    valid : ndarray of bool
        Pixels with a ground-truth depth (pin-holes counted as valid).
    """
    from skimage import data
    from skimage.color import rgb2gray

    left, _right, disp = data.stereo_motorcycle()
    disp = np.asarray(disp, dtype=np.float64)
    valid = np.isfinite(disp)
    # The ground truth has ~1800 pin-holes of a few pixels (stereo dropouts) besides its large
    # occluded regions. The pin-holes are filled from their neighbours and counted as valid
    # (an interpolated truth is far better than dropping every pixel near one at low
    # resolution); the large holes stay invalid and are excluded from the metrics.
    valid = valid | _small_holes(valid, _MOTO_PINHOLE_PX)
    disp = np.where(np.isfinite(disp), disp, np.nan)
    disp = _fill_invalid(np.nan_to_num(disp, nan=0.0), np.isfinite(disp))
    depth = np.zeros_like(disp)
    depth[valid] = _MOTO_BASELINE_M * _MOTO_FOCAL_PX / (disp[valid] + _MOTO_DOFFS_PX)
    return depth, rgb2gray(left), valid


def _motorcycle_computed(size: int) -> Scene:
    """The motorcycle in its native depth window, from scikit-image's sample data."""
    depth, lum, valid = motorcycle_source()
    scene = _finish("motorcycle", depth, lum, valid, size, None, None)
    lum = scene.reflectivity
    span = float(lum.max() - lum.min())
    r_lo, r_hi = _MOTO_REFLECTIVITY
    if span > 0:
        scene.reflectivity = np.clip(r_lo + (lum - lum.min()) * ((r_hi - r_lo) / span), r_lo, r_hi)
    else:
        scene.reflectivity = np.full_like(lum, r_hi)
    return scene


def _grid(size: int) -> tuple[np.ndarray, np.ndarray]:
    """Pixel-centre coordinates (y, x) in [0, 1]."""
    c = (np.arange(size) + 0.5) / size
    return np.meshgrid(c, c, indexing="ij")


def _steps(size: int, depth_min: float | None, depth_max: float | None) -> Scene:
    lo, hi = _window(depth_min, depth_max, _STEPS_WINDOW)
    y, x = _grid(size)
    level = np.ones((size, size))  # 1 = back plane (far), 0 = nearest
    refl = np.full((size, size), 0.8)
    # (y0, y1, x0, x1, depth level, reflectivity)
    for y0, y1, x0, x1, lev, r in (
        (0.10, 0.45, 0.08, 0.48, 0.0, 1.0),
        (0.10, 0.40, 0.58, 0.92, 0.25, 0.5),
        (0.55, 0.90, 0.08, 0.40, 0.5, 0.5),
    ):
        m = (y >= y0) & (y < y1) & (x >= x0) & (x < x1)
        level[m] = lev
        refl[m] = r
    disc = (y - 0.72) ** 2 + (x - 0.70) ** 2 < 0.17**2
    level[disc] = 0.75
    refl[disc] = 1.0
    depth = lo + level * (hi - lo)
    return Scene("steps", depth, refl, np.ones((size, size), dtype=bool))


def _ramp(size: int, depth_min: float | None, depth_max: float | None) -> Scene:
    lo, hi = _window(depth_min, depth_max, _RAMP_WINDOW)
    y, x = _grid(size)
    z = 0.3 + 0.7 * x  # recedes to the right
    r2 = ((y - 0.5) ** 2 + (x - 0.45) ** 2) / 0.28**2
    z = z - 0.5 * np.sqrt(np.clip(1.0 - r2, 0.0, None))  # a cap bulging towards the lidar
    valid = np.ones((size, size), dtype=bool)
    depth = _remap(z, valid, lo, hi)
    refl = 0.4 + 0.6 * y
    return Scene("ramp", depth, refl, valid)


def _nearer(depth: np.ndarray, refl: np.ndarray, surface: np.ndarray, r) -> None:
    """Z-buffer: where ``surface`` (metres, inf where absent) is nearer than ``depth``, the
    pixel sees it, with reflectivity ``r`` (scalar or array); in place."""
    near = surface < depth
    depth[near] = surface[near]
    refl[near] = np.broadcast_to(r, depth.shape)[near]


def _ground(y: np.ndarray, horizon: float, near: float) -> np.ndarray:
    """Depth of a horizontal plane below the lidar, ``a / (y - horizon)``, ``near`` metres at
    the bottom edge (y = 1) and absent (inf) above the horizon."""
    a = near * (1.0 - horizon)
    return np.where(y > horizon, a / np.maximum(y - horizon, 1e-12), np.inf)


def _band(t: np.ndarray, t0: float, size: int) -> np.ndarray:
    """A band ``[t0, t0 + w)`` of one pixel's width at 64 x 64 (at least one pixel)."""
    return (t >= t0) & (t < t0 + max(_THIN, 1.0 / size))


def _standing(x, y, x0, top, d, floor, size) -> np.ndarray:
    """A one-pixel pole at depth ``d`` from ``y = top`` down to where it meets ``floor``."""
    return np.where(_band(x, x0, size) & (y >= top) & (floor >= d), d, np.inf)


def _room(size: int, depth_min: float | None, depth_max: float | None) -> Scene:
    lo, hi = _window(depth_min, depth_max, _ROOM_WINDOW)
    y, x = _grid(size)
    depth = np.full((size, size), 5.0)  # back wall, metres (mapped to [lo, hi] at the end)
    refl = np.full((size, size), 0.6)
    refl[(x >= 0.45) & (x < 0.62) & (y >= 0.08) & (y < 0.30)] = 0.08  # dark poster, same depth
    floor = _ground(y, 0.30, 2.0)  # receding floor, 2 m at the bottom edge, a tiled pattern
    with np.errstate(divide="ignore"):
        tiles = (np.floor(8 * x) + np.floor(8 / floor)) % 2
    _nearer(depth, refl, floor, 0.35 + 0.3 * tiles)
    _nearer(depth, refl, np.where(x < 0.25, 2.4 + 2.6 * x / 0.25, np.inf), 0.5)  # side wall
    board = (x >= 0.35) & (x < 0.70) & (y >= 0.50) & (y < 0.54)  # table front at 3 m
    _nearer(depth, refl, np.where(board, 3.0, np.inf), 0.8)
    for x0, d, r in ((0.36, 3.0, 0.5), (0.69, 3.0, 0.12), (0.41, 3.4, 0.15), (0.64, 3.4, 0.5)):
        _nearer(depth, refl, _standing(x, y, x0, 0.54, d, floor, size), r)  # table legs
    _nearer(depth, refl, _standing(x, y, 0.28, 0.10, 4.2, floor, size), 0.2)  # lamp pole
    cabinet = (x >= 0.78) & (x < 0.95) & (y >= 0.20) & (y < 0.75)
    _nearer(depth, refl, np.where(cabinet, 3.8, np.inf), 0.1)
    valid = np.ones((size, size), dtype=bool)
    return Scene("room", _remap(depth, valid, lo, hi), refl, valid)


def _street(size: int, depth_min: float | None, depth_max: float | None) -> Scene:
    lo, hi = _window(depth_min, depth_max, _STREET_WINDOW)
    y, x = _grid(size)
    depth = np.full((size, size), 5.0)  # dark far backdrop, metres (mapped at the end)
    refl = np.full((size, size), 0.1)
    ground = _ground(y, 0.35, 2.0)
    _nearer(depth, refl, ground, 0.45)
    windows = ((10 * x) % 1 < 0.5) & ((10 * y) % 1 < 0.5)
    facade = np.where(x > 0.6, 5.0 - 2.8 * (x - 0.6) / 0.4, np.inf)  # recedes to the left
    _nearer(depth, refl, facade, np.where(windows, 0.12, 0.7))
    car = (x >= 0.04) & (x < 0.30) & (y >= 0.55) & (y < 0.82)
    _nearer(depth, refl, np.where(car, 2.8, np.inf), np.where(y < 0.63, 0.1, 0.6))
    for x0, d, r in ((0.15, 2.6, 0.4), (0.33, 3.5, 0.12), (0.50, 4.3, 0.6)):
        _nearer(depth, refl, _standing(x, y, x0, 0.05, d, ground, size), r)  # poles
    wire = _band(y, 0.12, size) & (x >= 0.15) & (x < 0.34)  # from pole 1 to pole 2, slanted
    _nearer(depth, refl, np.where(wire, 2.6 + 0.9 * (x - 0.15) / 0.18, np.inf), 0.3)
    sign = (x >= 0.11) & (x < 0.20) & (y >= 0.20) & (y < 0.29)
    _nearer(depth, refl, np.where(sign, 2.55, np.inf), 0.9)
    valid = np.ones((size, size), dtype=bool)
    return Scene("street", _remap(depth, valid, lo, hi), refl, valid)


_BUILTINS: dict[str, Callable[[int, float | None, float | None], Scene]] = {
    "camera": _camera,
    "motorcycle": _motorcycle,
    "steps": _steps,
    "ramp": _ramp,
    "room": _room,
    "street": _street,
}


# ---------------------------------------------------------------------------------------------
# user scenes


def _check_depth_values(label: str, depth: np.ndarray, where: np.ndarray | None = None) -> None:
    bad = ~np.isfinite(depth) | (np.nan_to_num(depth, nan=0.0) < 0)
    if where is not None:
        bad &= where
    count = int(np.count_nonzero(bad))
    if count:
        raise SceneError(
            f"scene file {label}: {_pixels(count)} NaN, infinite or negative depth "
            "(depth must be finite metres >= 0)"
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


def _load_npy(path: Path, label: str) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    _check_magic(path, label, b"\x93NUMPY", "NumPy .npy")
    try:
        depth = np.load(path, allow_pickle=False)
    except Exception as exc:
        raise SceneError(f"cannot read scene file {label} as .npy: {_reason(exc)}") from None
    depth = _as_2d(label, depth, "depth").astype(np.float64)
    _check_depth_values(label, depth)
    return depth, np.ones_like(depth), np.ones(depth.shape, dtype=bool)


def _load_npz(path: Path, label: str) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    _check_magic(path, label, b"PK", "NumPy .npz (zip)")
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
        valid = valid.astype(bool)
        if not valid.any():
            raise SceneError(f"scene file {label}: the valid mask marks no pixel as valid")
    else:
        valid = np.ones(depth.shape, dtype=bool)
    _check_depth_values(label, depth, valid)
    depth = np.where(valid, depth, 0.0)
    if "reflectivity" in arrays:
        refl = _as_2d(label, arrays["reflectivity"], "reflectivity").astype(np.float64)
        if refl.shape != depth.shape:
            raise SceneError(
                f"scene file {label}: reflectivity has shape {refl.shape}, depth has {depth.shape}"
            )
        bad = int(np.count_nonzero(~np.isfinite(refl) | (refl < 0) | (refl > 1)))
        if bad:
            raise SceneError(
                f"scene file {label}: {bad} reflectivity values lie outside [0, 1] "
                "(reflectivity must be in [0, 1])"
            )
    else:
        refl = np.ones_like(depth)
    return depth, refl, valid


def _load_image(path: Path, label: str) -> np.ndarray:
    from skimage import io
    from skimage.color import rgb2gray

    try:
        with warnings.catch_warnings():  # imageio warns while probing plugins on bad files
            warnings.simplefilter("ignore")
            img = np.asarray(io.imread(path))
    except Exception as exc:
        raise SceneError(
            f"cannot read scene image {label} ({type(exc).__name__}): use a grey or RGB "
            f"{'/'.join(_IMAGE_SUFFIXES)} image"
        ) from None
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
    return img


def _load_file(path: Path, size: int, depth_min: float | None, depth_max: float | None) -> Scene:
    label = path.name
    if not path.exists():
        raise SceneError(f"scene file not found: {path}")
    if not path.is_file():
        raise SceneError(f"scene path is not a file: {path}")
    suffix = path.suffix.lower()
    if suffix in _IMAGE_SUFFIXES:
        lo, hi = _window(depth_min, depth_max, _IMAGE_WINDOW)
        return _grey_to_scene(label, _load_image(path, label), size, lo, hi)
    if suffix == ".npy":
        depth, refl, valid = _load_npy(path, label)
    elif suffix == ".npz":
        depth, refl, valid = _load_npz(path, label)
    else:
        raise SceneError(
            f"scene file {label} has an unsupported format: use {', '.join(SCENE_FILE_SUFFIXES)}"
        )
    return _finish(label, depth, refl, valid, size, depth_min, depth_max)


# ---------------------------------------------------------------------------------------------
# public entry point


def load_scene(
    scene: str | os.PathLike = DEFAULT_SCENE,
    size: int = 64,
    depth_min: float | None = None,
    depth_max: float | None = None,
) -> Scene:
    """Load a built-in or user scene at ``size x size`` pixels.

    Parameters
    ----------
    scene : str or os.PathLike, optional
        A built-in name (:data:`BUILTIN_SCENES`, case-insensitive; default ``'camera'``) or a
        path to a ``.npy``, ``.npz``, ``.png``, ``.tif``, ``.tiff``, ``.jpg`` or ``.jpeg`` file.
        A plain string naming a built-in is the built-in even if a file of that name exists
        (write ``./camera`` for the file).
    size : int, optional
        Side ``N`` of the square output, 4 to 2048 (default 64).
    depth_min, depth_max : float or None, optional
        Depth window in metres. Scenes defined by a grey level (``camera``, images) and the
        synthetic scenes are mapped onto it; scenes with metric depth (``motorcycle``, ``.npy``,
        ``.npz``) keep their depth unless a bound is given, and are then rescaled linearly so
        that their valid depth range fills the window. A missing bound is taken from the scene's
        default: 20.0-20.8 m for ``camera`` and images, 10.0-10.6 m for ``steps``, 5.0-5.5 m for
        ``ramp``, 2.0-5.0 m for ``room`` and ``street``, the scene's own valid depth range for
        metric scenes.

    Returns
    -------
    Scene
        Depth (metres), reflectivity in [0, 1] and validity mask, all ``(size, size)``.

    Raises
    ------
    SceneError
        Unknown built-in name, missing or unreadable file, unsupported format, arrays that are
        not 2-D, NaN / infinite / negative depth (the count of such pixels is given),
        reflectivity outside [0, 1] or of the wrong shape, ``size`` outside 4..2048,
        ``depth_min < 0`` or an empty window (``depth_min >= depth_max``).

    Notes
    -----
    *Built-ins.* ``camera`` stands in for the paper's 'airplane' grey image at 20-20.8 m
    (Sec. III, Fig. 2a): grey level 0 maps to ``depth_min`` and the brightest level to
    ``depth_max``; its reflectivity is uniform 1.0, since the paper's signal model uses the mean
    reflectivity ``alpha-bar`` (eq. 8). ``motorcycle`` stands in for the 'doll' (Fig. 6a): the
    Middlebury disparity ``d`` (down-sampled by 4) becomes depth
    ``Z = b f / (d + doffs)`` with ``f = 994.978 px``, ``doffs = 31.086 px``,
    ``b = 0.193001 m`` (about 2-5 m); pixels without ground truth are filled from the nearest
    valid pixel and marked invalid; reflectivity is the left image's luminance rescaled to
    [0.2, 1.0].

    *User files.* ``.npy`` holds depth in metres. ``.npz`` holds ``depth`` and optional
    ``reflectivity`` and ``valid``; depth may be NaN where ``valid`` is False. Grey images are
    mapped onto the window like ``camera`` (their own darkest to brightest level), with
    reflectivity 1.

    *Resampling.* Non-square inputs are centre-cropped to a square, then resized bilinearly
    (anti-aliased when down-sampling). The validity mask is resized by the share of valid source
    pixels under each output pixel's footprint, thresholded at 0.999, so a pixel stays valid
    only when all its source pixels were valid.
    """
    size = _check_size(size)
    lo = _check_bound(depth_min, "depth_min")
    hi = _check_bound(depth_max, "depth_max")
    if lo is not None and hi is not None and lo >= hi:
        raise SceneError(
            f"depth window is empty: depth_min {lo:g} m must be less than depth_max {hi:g} m"
        )
    if isinstance(scene, str):
        key = scene.strip().lower()
        if key in _BUILTINS:
            return _BUILTINS[key](size, lo, hi)
        path = Path(scene)
        if path.suffix.lower() not in SCENE_FILE_SUFFIXES and not path.exists():
            raise SceneError(
                f"unknown scene {scene!r}: use a built-in ({', '.join(BUILTIN_SCENES)}) or a "
                f"path to a {', '.join(SCENE_FILE_SUFFIXES)} file"
            )
    elif isinstance(scene, os.PathLike):
        path = Path(scene)
    else:
        raise SceneError(
            f"scene must be a built-in name ({', '.join(BUILTIN_SCENES)}) or a file path, "
            f"got {type(scene).__name__}"
        )
    return _load_file(path, size, lo, hi)
