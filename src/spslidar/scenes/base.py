"""The scene a lidar sees (:class:`Scene`) and the resampling every scene goes through
(centre crop, anti-aliased resize, validity mask, depth window).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from ..constants import MAX_DEPTH_M
from ..errors import SceneError

SCENE_FILE_SUFFIXES: tuple[str, ...] = (".npy", ".npz", ".png", ".tif", ".tiff", ".jpg", ".jpeg")

_IMAGE_SUFFIXES = (".png", ".tif", ".tiff", ".jpg", ".jpeg")
#: the farthest depth a scene file may hold, in metres (:data:`spslidar.constants.MAX_DEPTH_M`)
MAX_SCENE_DEPTH_M = MAX_DEPTH_M
_MIN_SIZE = 4
_MAX_SIZE = 2048
#: default depth window (m) of scenes given by a grey level: the paper's 'airplane', 20 to
#: 20.8 m (Sec. III)
_IMAGE_WINDOW = (20.0, 20.8)
# Share of valid source pixels an output pixel needs to stay valid after resizing.
_MASK_VALID_SHARE = 0.999
#: a user's file: a pixel is valid where half its footprint is, as its depth is the one that
#: covers most of it (all of it, as the built-in motorcycle is, scored 43 % of a file whose
#: valid pixels were 95 % at --size 32, and 44 % of one 75 % valid up-sampled 40 -> 64, which
#: the depth rule reads pixel for pixel: an outside audit of 2026-12-03)
_FILE_VALID_SHARE = 0.5

#: the scene's arrays: read-only, and not to be rebound once it is built
_ARRAYS = ("depth", "reflectivity", "valid")


@dataclass(eq=False)
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
        What loading did that a user should hear about (e.g. a non-square file cropped):
        warnings of the run.
    has_truth : bool
        False for a measured acquisition (``spslidar reconstruct`` without ``--truth``): the
        depth is a placeholder, no pixel is valid, and no truth-based metric is computed.
    description : str
        What the scene is, in words, where its name alone does not say (``procedural:7``:
        ``"a clutter at 2.51-5.56 m"``); empty otherwise. Not a warning: ``metrics.json``
        keeps it as ``scene_note`` and the run's summary line shows it.

    Raises
    ------
    SceneError
        If the arrays are not square, of different shapes, or out of range.

    Notes
    -----
    ``depth`` and ``reflectivity`` are the ``d(x, y)`` and ``alpha(x, y)`` of eqs. (1)-(8).
    Once built, the scene's arrays are read-only views: a measurement and every result
    reconstructed from it share the scene, and each result is scored against it, so writing
    into ``result.scene.depth`` would change the next result's score. To change a scene, build
    another (``dataclasses.replace(scene, depth=new_depth)``).
    """

    name: str
    depth: np.ndarray
    reflectivity: np.ndarray
    valid: np.ndarray
    #: what loading did that a user should hear about (e.g. a non-square file cropped)
    notes: list[str] = field(default_factory=list)
    has_truth: bool = True
    #: what the scene is, in words (not a warning; ``metrics.json``'s ``scene_note``)
    description: str = ""

    def __post_init__(self) -> None:
        self.depth = _read_only(self.depth, np.float64)
        self.reflectivity = _read_only(self.reflectivity, np.float64)
        valid = np.asarray(self.valid)
        if valid.dtype != np.bool_ and valid.size and not np.isin(valid, (0, 1)).all():
            # (0.3 everywhere was read as all valid, an audit of 2026-11-29)
            raise SceneError(f"scene {self.name!r}: the valid mask must hold booleans or 0/1, "
                             f"got values such as {valid[~np.isin(valid, (0, 1))].flat[0]!r}")
        self.valid = _read_only(valid, bool)
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
        object.__setattr__(self, "_sealed", True)

    def __setattr__(self, name: str, value) -> None:
        # (the arrays were read-only but could be rebound: `r.scene.depth = r.scene.depth + 1`
        # moved every later result's score, an audit of 2026-12-01)
        if name in _ARRAYS and self.__dict__.get("_sealed"):
            raise AttributeError(f"a scene's {name} is fixed once built: every result of its "
                                 f"measurement is scored against it; build another with "
                                 f"dataclasses.replace(scene, {name}=...)")
        object.__setattr__(self, name, value)

    def __setstate__(self, state: dict) -> None:
        # (pickle and deepcopy give arrays back writable: a scene through joblib or a deepcopy
        # let a result's scene be written into, changing the next result's score, an audit)
        self.__dict__.update(state)
        for name in _ARRAYS:
            getattr(self, name).flags.writeable = False

    def __repr__(self) -> str:
        return (f"Scene({self.name!r}, {self.size}x{self.size}, depth "
                f"{float(self.depth.min()):.4g}-{float(self.depth.max()):.4g} m"
                + ("" if self.has_truth else ", no truth") + ")")

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


def _read_only(arr, dtype) -> np.ndarray:
    """``arr`` as a read-only copy of ``dtype``, the scene's own (a view of the caller's array
    let them change the checked scene afterwards: depths set to 5 m in a scene at 20 m, an
    audit of 2026-11-29; a copy of N x N values is cheap). The caller's array stays theirs."""
    own = np.array(arr, dtype=dtype, copy=True)
    own.flags.writeable = False
    return own


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
    # a whole float is a size as Config takes one (run(size=16.0) ran, load_scene refused it)
    if (isinstance(size, (float, np.floating)) and np.isfinite(size)
            and float(size).is_integer()):
        size = int(size)
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
    if isinstance(value, (bool, np.bool_)):  # (True was read as 1 m)
        raise SceneError(f"{what} must be a number of metres, got {value!r}")
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
        own = " (the scene's own: not given)"
        raise SceneError(
            f"depth window is empty: depth_min {lo:g} m{own if depth_min is None else ''} must "
            f"be less than depth_max {hi:g} m{own if depth_max is None else ''}"
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


#: depths (m) of a footprint that :func:`_resize_surfaces` takes as one surface when it
#: averages the reflectivity: a third of a 10 GHz bin (15 mm), so a surface is one return
SURFACE_TOL = 0.005


def _resize_surfaces(img: np.ndarray, size: int, companion: np.ndarray | None = None):
    """Resize a square depth map so that every output pixel holds a depth its footprint holds:
    the lower median of the source pixels it covers (:func:`footprints`; one source pixel when
    up-sampling, the nearer of two where a footprint straddles them). With ``companion`` (the
    reflectivity, same shape), also its mean over the footprint's pixels on that surface
    (depths within :data:`SURFACE_TOL` of the one taken): ``(depth, companion)``. (The
    reflectivity was resized bilinearly beside it: a 0/1 texture up-sampled to greys of
    0.25-0.75 that are in no file, and a pixel given a dark surface's depth took a bright
    neighbour's light, an audit. It was then read at the one source pixel the median picked,
    which on a flat surface is the same place in every footprint: a 0.2 / 1.0 striped
    texture halved in size read 1.0 everywhere and its mirror image 0.2, where a pixel
    collects its footprint's mean, 0.6: an audit of 2026-11-30.)

    The simulation gives each pixel one return. A bilinear, anti-aliased resize averaged the
    depths across edges: a one-pixel pole at 8 m in front of a 10 m wall became a surface at
    9.7-9.9 m that is in no file, a 2 m step up-sampled four "flying pixels" between its two
    surfaces, and each was scored as the truth. The median keeps the surface that covers most
    of the footprint (the nearer one at an even split); an object under half a footprint wide
    is dropped, as its return would be the weaker one. Written here because scikit-image's
    ``downscale_local_mean`` / ``resize`` average and ``rank.median`` is for 8/16-bit images
    on a fixed footprint, not for float depths over the uneven footprints of any size ratio.
    """
    img = np.asarray(img, dtype=np.float64)
    src = img.shape[0]
    other = None if companion is None else np.asarray(companion, dtype=np.float64)
    if img.shape == (size, size):
        return img.copy() if other is None else (img.copy(), other.copy())
    start, stop = footprints(src, size)
    k = int((stop - start).max())
    idx = start[:, None] + np.arange(k)[None, :]  # (size, k) source rows (or columns)
    inside = idx < stop[:, None]
    idx = np.minimum(idx, src - 1)
    out = np.empty((size, size))
    out2 = None if other is None else np.empty((size, size))
    rows = max(1, (1 << 22) // max(1, size * k * k))  # output rows per block (~32 MB)
    for r0 in range(0, size, rows):
        r = slice(r0, min(size, r0 + rows))
        at = (idx[r][:, None, :, None], idx[None, :, None, :])
        block = img[at]  # (R, size, k, k)
        mask = inside[r][:, None, :, None] & inside[None, :, None, :]
        vals = np.where(mask, block, np.inf).reshape(block.shape[0], size, k * k)
        order = np.argsort(vals, axis=2, kind="stable")
        count = mask.reshape(block.shape[0], size, k * k).sum(axis=2)
        pick = np.take_along_axis(order, ((count - 1) // 2)[..., None], axis=2)
        out[r] = np.take_along_axis(vals, pick, axis=2)[..., 0]
        if out2 is not None:
            comp = other[at].reshape(block.shape[0], size, k * k)
            same = np.abs(vals - out[r][..., None]) <= SURFACE_TOL  # (outside: inf, never)
            out2[r] = (comp * same).sum(axis=2) / same.sum(axis=2)
    return out if out2 is None else (out, out2)


def footprints(src: int, size: int) -> tuple[np.ndarray, np.ndarray]:
    """Source rows (or columns) ``start[i] .. stop[i] - 1`` that output pixel ``i`` covers when
    a side of ``src`` pixels is resized to ``size``."""
    edges = np.arange(size + 1) * src
    return edges[:-1] // size, -((-edges[1:]) // size)  # floor and ceiling division


def _resize_mask(mask: np.ndarray, size: int, share: float = _MASK_VALID_SHARE) -> np.ndarray:
    """Resize a square validity mask: a pixel stays valid when ``share`` of its source
    pixels were valid (all of them at the default, the built-in motorcycle's rule).

    Output pixel ``i`` covers source rows ``floor(i s / N) .. ceil((i + 1) s / N) - 1`` (and
    likewise for columns); the share of valid pixels over that footprint, from an integral
    image, must reach ``share`` (:data:`_MASK_VALID_SHARE`, 0.999; a user's file
    :data:`_FILE_VALID_SHARE`).
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
    return count >= share * area


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
    """Map the valid depth range linearly onto [lo, hi]; a flat scene has no range to map and
    keeps its depth, moved to the nearer end where it lies outside (it went to ``lo``: a file
    flat at 6 m given ``--depth-min 5`` was simulated at 5 m without a word; an audit of
    2026-11-29)."""
    dmin = float(depth[valid].min())
    dmax = float(depth[valid].max())
    if dmax > dmin:
        out = lo + (depth - dmin) * ((hi - lo) / (dmax - dmin))
    else:
        out = np.full_like(depth, min(max(dmin, lo), hi))
    return np.clip(out, lo, hi)


def _grey_to_scene(name: str, grey: np.ndarray, size: int, lo: float, hi: float,
                   surfaces: bool = False) -> Scene:
    """A grey image mapped onto the depth window; reflectivity 1. ``surfaces``: resized by
    :func:`_resize_surfaces` (a user's file), else bilinearly (the built-in camera, as the
    paper's figures were made)."""
    notes = [_crop_note(name, grey.shape, size)] if grey.shape[0] != grey.shape[1] else []
    if surfaces and min(grey.shape) != size:
        notes.append(_surface_note(name, min(grey.shape), size))
    grey = (_resize_surfaces if surfaces else _resize)(_center_crop(grey), size)
    valid = np.ones((size, size), dtype=bool)
    if float(grey.max()) > float(grey.min()):
        depth = _remap(grey, valid, lo, hi)
    else:
        # a uniform image has no darkest and brightest level to map onto the window: its
        # grey level was taken as metres and clipped, so level 0 or 1 was a wall at the
        # window's near end and 128-255 one at its far end, unsaid (an outside audit of
        # 2026-12-02); a flat wall at the window's middle, said
        mid = 0.5 * (lo + hi)
        depth = np.full((size, size), mid)
        notes.append(f"scene image {name} is uniform (grey level {float(grey.flat[0]):.4g} "
                     f"everywhere at {size}x{size}): no range of grey "
                     f"levels to map onto the depth window {lo:g}-{hi:g} m, so its depth is a "
                     f"flat wall at {mid:g} m, the window's middle (--depth-min/--depth-max "
                     f"move it; an .npy depth map gives any depth)")
    return Scene(name, depth, np.ones((size, size)), valid, notes)


def _surface_note(name: str, side: int, size: int) -> str:
    return (f"scene {name} ({side}x{side}) is resized to {size}x{size}: each pixel takes the "
            f"depth that covers most of its footprint (the median), so an object under half a "
            f"pixel wide at this size is dropped; a file of {size}x{size} is simulated as it "
            f"is" if side > size else
            f"scene {name} ({side}x{side}) is resized to {size}x{size}: each pixel takes the "
            f"depth of the file's pixel it lies in, the nearer of two where it straddles them "
            f"(no depths between two surfaces; a near object's edge may grow by a pixel)")


def _crop_note(name: str, shape: tuple[int, ...], size: int) -> str:
    side, long = min(shape), max(shape)
    # (a field of view across the file's longer side is not the crop's: an outside audit of
    # 2026-12-01)
    # (it said "resized to 48x48" of a 48x64 file at --size 48, where nothing is resized: an
    # outside audit of 2026-12-01)
    resized = f" (resized to {size}x{size})" if side != size else ""
    return (f"scene {name} is {shape[0]}x{shape[1]}: its centre {side}x{side} is used"
            f"{resized}; its ranges seen through a field of view F across "
            f"its {long} pixels span 2 atan(tan(F/2) {side}/{long}) in the crop, the --fov "
            f"of the point cloud")


def _finish(
    name: str,
    depth: np.ndarray,
    reflectivity: np.ndarray,
    valid: np.ndarray,
    size: int,
    depth_min: float | None,
    depth_max: float | None,
    surfaces: bool = False,
) -> Scene:
    """Fill, crop, resize and optionally remap a full-resolution scene. ``surfaces`` (a user's
    file): the depth resized by :func:`_resize_surfaces`, and the depths the file gives at
    pixels it does not mark valid kept (simulated, not scored); else (the built-in
    motorcycle, as its benchmarks were measured) bilinearly, every invalid pixel filled from
    the nearest valid one."""
    notes = [_crop_note(name, depth.shape, size)] if depth.shape[0] != depth.shape[1] else []
    if surfaces and min(depth.shape) != size:
        notes.append(_surface_note(name, min(depth.shape), size))
    given = valid | (np.isfinite(depth) & (depth > 0)) if surfaces else valid
    depth = _fill_invalid(depth, given)
    if surfaces:  # each pixel's reflectivity from the file's pixel whose depth it holds
        depth, reflectivity = _resize_surfaces(_center_crop(depth), size,
                                               _center_crop(reflectivity))
    else:
        depth = _resize(_center_crop(depth), size)
        reflectivity = _resize(_center_crop(reflectivity), size)
    reflectivity = np.clip(reflectivity, 0.0, 1.0)
    crop = _center_crop(valid)
    if not crop.any():  # ("use a larger size" was said where the crop held none of them)
        side = min(valid.shape)
        raise SceneError(
            f"scene {name!r}: the centre {side}x{side} of its {valid.shape[0]}x"
            f"{valid.shape[1]} pixels, the square a scene is cut to, holds none of its valid "
            f"pixels: crop the file around them")
    valid = _resize_mask(crop, size, _FILE_VALID_SHARE if surfaces else _MASK_VALID_SHARE)
    if not valid.any():
        raise SceneError(
            f"scene {name!r}: no pixel keeps a valid depth at size {size}: use a larger size"
        )
    if depth_min is not None or depth_max is not None:
        native = (float(depth[valid].min()), float(depth[valid].max()))
        lo, hi = _window(depth_min, depth_max, native)
        depth = _remap(depth, valid, lo, hi)
        if native[0] == native[1]:
            kept = float(depth[valid][0])
            notes.append(f"scene {name} is flat at {native[0]:g} m: the depth window "
                         f"{lo:g}-{hi:g} m has no range to map it onto, so it " + (
                             "keeps its depth" if kept == native[0] else
                             f"is moved to the window's nearer end, {kept:g} m"))
    return Scene(name, depth, reflectivity, valid, notes)
