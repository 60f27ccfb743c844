"""The built-in scenes: ``camera`` and ``motorcycle`` from scikit-image's sample data,
``steps``, ``ramp``, ``room`` and ``street`` synthesised (see :mod:`spslidar.scenes`).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from .. import scene_cache
from .base import (
    _IMAGE_WINDOW,
    Scene,
    _crop_note,
    _fill_invalid,
    _finish,
    _grey_to_scene,
    _remap,
    _small_holes,
    _window,
)

#: stereo dropouts of at most this many source pixels are filled and counted as valid
_MOTO_PINHOLE_PX = 25

# Default depth windows (metres) of the scenes defined by a grey level or synthesised.
_STEPS_WINDOW = (10.0, 10.6)
_RAMP_WINDOW = (5.0, 5.5)
_ROOM_WINDOW = (2.0, 5.0)
_STREET_WINDOW = (2.0, 5.0)
#: width of the thin structures (poles, legs, wire) of ``room`` and ``street``, as a share of
#: the side from 64 x 64 up (one pixel at 64 x 64, 2 at 128, 8 at 512); one pixel below 64
#: (:func:`_band`: ``max(1/64, 1/size)``)
_THIN = 1.0 / 64

# Calibration of skimage.data.stereo_motorcycle (Middlebury 2014, down-sampled by 4).
_MOTO_FOCAL_PX = 994.978
_MOTO_DOFFS_PX = 31.086
_MOTO_BASELINE_M = 0.193001
_MOTO_REFLECTIVITY = (0.2, 1.0)


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
        # (a new scene: a built scene's arrays are read-only)
        scene = replace(scene, depth=_remap(scene.depth, valid,
                                            *_window(depth_min, depth_max, native)))
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
        refl = np.clip(r_lo + (lum - lum.min()) * ((r_hi - r_lo) / span), r_lo, r_hi)
    else:
        refl = np.full_like(lum, r_hi)
    return replace(scene, reflectivity=refl)


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
    """A band ``[t0, t0 + w)``, ``w = max(1/64, 1/size)``: from 64 x 64 up a fixed width in
    the scene, one pixel at 64 x 64 and ``size / 64`` pixels above (2 at 128, 8 at 512); one
    pixel at every size below 64. It holds the
    pixels whose centres ``t`` fall in it: none where it starts past the last centre (at the
    smallest sizes, a band that starts within half a pixel of the far edge)."""
    return (t >= t0) & (t < t0 + max(_THIN, 1.0 / size))


def _standing(x, y, x0, top, d, floor, size) -> np.ndarray:
    """A thin pole (:func:`_band`: one pixel wide at 64 x 64) at depth ``d`` from ``y = top``
    down to where it meets ``floor``."""
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
