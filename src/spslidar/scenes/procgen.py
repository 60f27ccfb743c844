"""Seeded procedural wide-depth scenes (``procedural:SEED``) and a fence in front of a wall
(``fence``), for judging depth estimators on scenes nobody tuned a default on.

``procedural:SEED`` draws, from ``numpy.random.default_rng(SEED)``, one of three layouts

* ``room``: a back wall, a receding floor (and sometimes a ceiling), one or two slanted side
  walls;
* ``street``: a far backdrop, a receding road, slanted facades with dark windows;
* ``clutter``: a back wall and a floor crowded with objects;

and then clutter on top: thin poles standing on the floor, straight (often slanted) thin
wires, tables on thin legs, fences of thin slats, boxes (flat or slanted planes, some dark in
front of bright ones), discs bulging towards the lidar. Nearer objects occlude farther ones
(a z-buffer). Walls, floors and backdrops have reflectivity 0.15-1 (some textured); each
object one time in four is dark (0.05-0.2, log-uniform), else 0.2-1.

The floor (or road) is 1.5-2.5 m away at the image's bottom edge and the far wall (or
backdrop) 2-3.5 m behind that; the pixels sample the floor at their centres, above the edge,
so the depths a scene holds span less, the more so the smaller the scene: 1.97-3.47 m at
64 x 64 (seeds 0-199), 1.56-3.01 m at 4 x 4 (seeds 0-49). At the default 10 GHz bit rate a
64 x 64 scene's range gate holds 140-240 range slices (seeds 0-199).

A thin structure is a band ``max(1/64, 1/N)`` of the side of an ``N x N`` scene wide: from
64 x 64 up a fixed width in the scene, one pixel at 64 x 64 and ``N / 64`` pixels above (2 at
128, 8 at 512); one pixel at every size below 64. A band holds the pixels whose centres fall
in it, so one that starts past the last pixel centre, within half a pixel of the far edge,
holds none: rarely at 64 x 64 (a table leg at the edge, 1 of 683 bands that start inside the
image over seeds 0-99), more often the smaller the scene (3 % of them at 8 x 8, 6 % at
4 x 4). Every pixel sees one surface and has a valid truth.

``fence`` is a wall at 4 m seen through a wire-mesh fence at 3 m: each mesh pixel returns
both from the mesh (a share of its footprint) and from the wall behind it, a two-surface
pixel; its ``depth`` is the mesh (the first surface, what the RMSE scores) and the wall is its
:attr:`LayeredScene.behind_depth`. Two posts and a rail are solid (one surface), thin bands
of the same width as ``procedural``'s.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import SceneError
from .base import Scene, _read_only
from .builtin import _band, _grid, _ground, _nearer

__all__ = ["LayeredScene", "fence_scene", "procedural_scene"]

#: layouts drawn by ``procedural:SEED``
LAYOUTS = ("room", "street", "clutter")
#: reflectivity range of the procedural scenes
REFL_RANGE = (0.05, 1.0)
_THIN = 1.0 / 64
_MAX_SEED = 2**63 - 1


@dataclass
class LayeredScene(Scene):
    """A :class:`Scene` whose pixels may also see a second, farther surface.

    ``depth`` and ``reflectivity`` are the first surface (the one the RMSE scores; its
    reflectivity already weighted by the share of the footprint it covers); where a pixel
    also sees a surface behind it, ``behind_depth`` holds its depth (NaN elsewhere) and
    ``behind_reflectivity`` its weighted reflectivity (0 elsewhere). The simulation renders
    both returns (:func:`spslidar.instrument.instrument_weights`).
    """

    behind_depth: np.ndarray | None = None
    behind_reflectivity: np.ndarray | None = None

    def __post_init__(self) -> None:
        super().__post_init__()
        if self.behind_depth is None:
            return
        self.behind_depth = _read_only(self.behind_depth, np.float64)
        self.behind_reflectivity = _read_only(self.behind_reflectivity, np.float64)
        for arr in (self.behind_depth, self.behind_reflectivity):
            if arr.shape != self.depth.shape:
                raise SceneError(f"scene {self.name!r}: second layer of shape {arr.shape}, "
                                 f"depth has {self.depth.shape}")
        two = np.isfinite(self.behind_depth)
        r2 = self.behind_reflectivity
        if np.any(self.behind_depth[two] <= self.depth[two]) or np.any(
                (r2 < 0) | (r2 > 1) | ~np.isfinite(r2)) or np.any(r2[~two] != 0):
            raise SceneError(f"scene {self.name!r}: the second layer must lie behind the first, "
                             f"with a reflectivity in [0, 1] (0 where absent)")

    @property
    def two_surface(self) -> np.ndarray:
        """Pixels that see two surfaces."""
        if self.behind_depth is None:
            return np.zeros(self.depth.shape, dtype=bool)
        return np.isfinite(self.behind_depth) & (self.behind_reflectivity > 0)


def _seed(arg: str) -> int:
    """The seed of ``procedural:ARG``: ``ARG`` is ASCII decimal digits only (``int`` also
    read ``+5``, ``' 5'``, ``5_000`` as 5000 and other scripts' digits, an Arabic-Indic three
    as 3: spellings a record did not tell apart). Leading zeros are read (``007`` is 7)."""
    arg = str(arg)
    spec = (repr(f"procedural:{arg}") if len(arg) <= 40 else
            f"{f'procedural:{arg[:20]}...'!r} (a seed of {len(arg)} characters)")
    if not (arg.isascii() and arg.isdigit()):
        raise SceneError(f"scene {spec}: the seed must be written in the ASCII digits 0-9 "
                         f"alone (no sign, space, underscore or other digits), e.g. "
                         f"procedural:7")
    digits = arg.lstrip("0") or "0"
    if len(digits) > len(str(_MAX_SEED)) or int(digits) > _MAX_SEED:
        raise SceneError(f"scene {spec}: the seed must be from 0 to {_MAX_SEED}")
    return int(digits)


def _refl(rng: np.random.Generator, lo: float | None = None, hi: float = REFL_RANGE[1]):
    """A reflectivity drawn log-uniformly in [lo, hi]; without ``lo``, a surface's: dark
    (0.05-0.2, log-uniform) one time in four, else uniform in 0.2-1."""
    if lo is None:
        if rng.random() < 0.25:
            return float(np.exp(rng.uniform(np.log(REFL_RANGE[0]), np.log(0.2))))
        return float(rng.uniform(0.2, hi))
    return float(np.exp(rng.uniform(np.log(lo), np.log(hi))))


def _texture(rng: np.random.Generator, x: np.ndarray, y: np.ndarray, base: float):
    """A plain or textured (stripes, checks) reflectivity around ``base``."""
    kind = rng.integers(3)
    if kind == 0:
        return np.full(x.shape, base)
    f = rng.uniform(4, 14)
    other = _refl(rng)
    pat = (np.floor(f * x) % 2) if kind == 1 else (np.floor(f * x) + np.floor(f * y)) % 2
    return np.where(pat > 0, other, base)


class _Canvas:
    """A z-buffer of depth (metres) and reflectivity on the pixel-centre grid."""

    def __init__(self, size: int, far: float, refl: float):
        self.size = size
        self.y, self.x = _grid(size)
        self.depth = np.full((size, size), far)
        self.refl = np.full((size, size), refl)

    def put(self, surface: np.ndarray, r) -> None:
        _nearer(self.depth, self.refl, surface, r)

    def thin(self, t: np.ndarray, t0: float) -> np.ndarray:
        return _band(t, t0, self.size)


def _layout_room(c: _Canvas, rng, near: float, far: float) -> np.ndarray:
    x, y = c.x, c.y
    c.refl[:] = _texture(rng, x, y, _refl(rng, 0.3, 1.0))  # back wall
    floor = _ground(y, rng.uniform(0.25, 0.45), near)
    c.put(floor, _texture(rng, x, y, _refl(rng, 0.25, 0.8)))
    if rng.random() < 0.4:  # a ceiling
        c.put(_ground(1.0 - y, rng.uniform(0.6, 0.8), near * rng.uniform(1.0, 1.4)),
              _refl(rng, 0.3, 1.0))
    for side in rng.permutation(2)[: rng.integers(1, 3)]:
        w = rng.uniform(0.12, 0.3)
        t = x / w if side == 0 else (1.0 - x) / w
        d0 = near + rng.uniform(0.0, 0.6)
        c.put(np.where(t < 1, d0 + (far - d0) * np.clip(t, 0, 1), np.inf),
              _texture(rng, x, y, _refl(rng)))
    return floor


def _layout_street(c: _Canvas, rng, near: float, far: float) -> np.ndarray:
    x, y = c.x, c.y
    c.refl[:] = _refl(rng, 0.15, 0.5)  # far backdrop
    road = _ground(y, rng.uniform(0.3, 0.45), near)
    c.put(road, _refl(rng, 0.25, 0.7))
    for side in range(2):
        if rng.random() < 0.25:
            continue
        w = rng.uniform(0.2, 0.45)
        t = x / w if side == 0 else (1.0 - x) / w
        d0 = near + rng.uniform(0.2, 1.0)
        f = rng.uniform(6, 14)
        windows = ((f * x) % 1 < 0.5) & ((f * y) % 1 < 0.5)
        c.put(np.where(t < 1, d0 + (far - 0.3 - d0) * np.clip(t, 0, 1), np.inf),
              np.where(windows, _refl(rng, 0.05, 0.15), _refl(rng, 0.3, 1.0)))
    return road


def _layout_clutter(c: _Canvas, rng, near: float, far: float) -> np.ndarray:
    x, y = c.x, c.y
    c.refl[:] = _texture(rng, x, y, _refl(rng, 0.3, 1.0))
    floor = _ground(y, rng.uniform(0.4, 0.6), near)
    c.put(floor, _refl(rng, 0.25, 0.7))
    return floor


def _pole(c: _Canvas, rng, near, far, floor) -> None:
    x0, d = rng.uniform(0.02, 0.97), rng.uniform(near + 0.2, far - 0.1)
    top = rng.uniform(0.0, 0.5)
    c.put(np.where(c.thin(c.x, x0) & (c.y >= top) & (floor >= d), d, np.inf), _refl(rng))


def _wire(c: _Canvas, rng, near, far, floor) -> None:
    x0, x1 = np.sort(rng.uniform(0.0, 1.0, 2))
    x1 = max(x1, x0 + 0.15)
    y0, slope = rng.uniform(0.05, 0.5), rng.uniform(-0.3, 0.3)
    d0, d1 = rng.uniform(near + 0.2, far - 0.1, 2)
    s = np.clip((c.x - x0) / (x1 - x0), 0, 1)
    on = c.thin(c.y - slope * (c.x - x0), y0) & (c.x >= x0) & (c.x < x1)
    c.put(np.where(on, d0 + (d1 - d0) * s, np.inf), _refl(rng))


def _table(c: _Canvas, rng, near, far, floor) -> None:
    x0 = rng.uniform(0.0, 0.7)
    x1 = x0 + rng.uniform(0.15, 0.35)
    d = rng.uniform(near + 0.3, far - 0.6)
    depth_back = d + rng.uniform(0.2, 0.5)
    top = rng.uniform(0.35, 0.6)
    board = (c.x >= x0) & (c.x < x1) & (c.y >= top) & (c.y < top + rng.uniform(0.02, 0.06))
    c.put(np.where(board, d, np.inf), _refl(rng))
    for xl, dl in ((x0 + 0.01, d), (x1 - 0.02, d), (x0 + 0.05, depth_back),
                   (x1 - 0.06, depth_back)):
        c.put(np.where(c.thin(c.x, xl) & (c.y >= top) & (floor >= dl), dl, np.inf),
              _refl(rng))


def _fence(c: _Canvas, rng, near, far, floor) -> None:
    x0 = rng.uniform(0.0, 0.6)
    x1 = x0 + rng.uniform(0.2, 0.4)
    d0 = rng.uniform(near + 0.2, far - 0.5)
    d1 = d0 + rng.uniform(-0.3, 0.3)
    top = rng.uniform(0.3, 0.6)
    pitch = rng.integers(2, 5) * max(_THIN, 1.0 / c.size)
    s = np.clip((c.x - x0) / (x1 - x0), 0, 1)
    d = d0 + (d1 - d0) * s
    span = (c.x >= x0) & (c.x < x1) & (c.y >= top) & (floor >= d)
    slats = ((c.x - x0) % pitch) < max(_THIN, 1.0 / c.size)
    rail = c.thin(c.y, top + rng.uniform(0.02, 0.1))
    c.put(np.where(span & (slats | rail), d, np.inf), _refl(rng))


def _box(c: _Canvas, rng, near, far, floor) -> None:
    x0, y0 = rng.uniform(0.0, 0.85, 2)
    x1, y1 = x0 + rng.uniform(0.06, 0.3), y0 + rng.uniform(0.06, 0.35)
    d = rng.uniform(near + 0.1, far - 0.2)
    gx, gy = (rng.uniform(-0.8, 0.8, 2) if rng.random() < 0.5 else (0.0, 0.0))  # slanted
    inside = (c.x >= x0) & (c.x < x1) & (c.y >= y0) & (c.y < y1)
    surface = d + gx * (c.x - x0) + gy * (c.y - y0)
    if rng.random() < 0.4:  # a dark object in front of a bright one
        c.put(np.where(inside, surface + 0.4, np.inf), _refl(rng, 0.6, 1.0))
        shrink = (c.x >= x0 + 0.02) & (c.x < x1 - 0.02) & (c.y >= y0 + 0.02) & (c.y < y1 - 0.02)
        c.put(np.where(shrink, surface, np.inf), _refl(rng, 0.05, 0.12))
    else:
        c.put(np.where(inside, surface, np.inf), _texture(rng, c.x, c.y, _refl(rng)))


def _disc(c: _Canvas, rng, near, far, floor) -> None:
    cx, cy = rng.uniform(0.1, 0.9, 2)
    r = rng.uniform(0.04, 0.15)
    d = rng.uniform(near + 0.3, far - 0.2)
    rr = ((c.x - cx) ** 2 + (c.y - cy) ** 2) / r**2
    bulge = rng.uniform(0.05, 0.3)
    c.put(np.where(rr < 1, d - bulge * np.sqrt(np.clip(1 - rr, 0, None)), np.inf), _refl(rng))


_LAYOUTS = {"room": _layout_room, "street": _layout_street, "clutter": _layout_clutter}
#: object makers and how many of each a layout gets (low, high inclusive)
_OBJECTS = (("pole", _pole, 1, 4), ("wire", _wire, 0, 2), ("table", _table, 0, 1),
            ("fence", _fence, 0, 1), ("box", _box, 1, 4), ("disc", _disc, 0, 2))


def _window_map(depth: np.ndarray, lo: float, hi: float, depth_min, depth_max) -> np.ndarray:
    """Depths mapped linearly from ``[lo, hi]`` onto the window given (a missing bound kept)."""
    new_lo = lo if depth_min is None else float(depth_min)
    new_hi = hi if depth_max is None else float(depth_max)
    if new_lo >= new_hi:
        own = " (the scene's own: not given)"  # as the built-ins' (base._window)
        raise SceneError(f"depth window is empty: depth_min {new_lo:g} m"
                         f"{own if depth_min is None else ''} must be less than depth_max "
                         f"{new_hi:g} m{own if depth_max is None else ''}")
    return new_lo + (depth - lo) * ((new_hi - new_lo) / (hi - lo))


def procedural_scene(size: int, depth_min: float | None, depth_max: float | None,
                     arg: str) -> Scene:
    """The scene ``procedural:SEED`` (see the module's description).

    Parameters
    ----------
    size : int
        Side of the square scene in pixels.
    depth_min, depth_max : float or None
        A depth window: given either bound, the scene's depths are mapped linearly onto it
        (the missing bound kept from the scene); by default the scene keeps its own depths.
    arg : str
        The seed, a non-negative integer.

    Returns
    -------
    Scene
        The same scene for the same seed and size, on any machine.
    """
    seed = _seed(arg)
    rng = np.random.default_rng(seed)
    layout = LAYOUTS[int(rng.integers(len(LAYOUTS)))]
    near = rng.uniform(1.5, 2.5)
    far = near + rng.uniform(2.0, 3.5)
    c = _Canvas(size, far, 0.5)
    floor = _LAYOUTS[layout](c, rng, near, far)
    extra = 2 if layout == "clutter" else 0
    for _name, make, lo, hi in _OBJECTS:
        for _ in range(int(rng.integers(lo, hi + 1 + (extra if hi > 1 else 0)))):
            make(c, rng, near, far, floor)
    depth = np.clip(c.depth, 0.5, far)
    refl = np.clip(c.refl, *REFL_RANGE)
    valid = np.ones((size, size), dtype=bool)
    if depth_min is not None or depth_max is not None:
        # every layout has a receding floor: the depths always span a range
        depth = _window_map(depth, float(depth.min()), float(depth.max()), depth_min,
                            depth_max)
    # what the scene is: a description (metrics.json's scene_note, the summary), no warning
    return Scene(f"procedural:{seed}", depth, refl, valid,
                 description=f"a {layout} at {depth.min():.2f}-{depth.max():.2f} m")


#: the fence scene: wall and fence depths (m), the mesh's share of a pixel's footprint
_FENCE_WALL, _FENCE_AT, _FENCE_COVER = 4.0, 3.0, 0.5


def fence_scene(size: int, depth_min: float | None, depth_max: float | None) -> LayeredScene:
    """A wall at 4 m (reflectivity 0.6, a dark band of 0.15) behind a wire-mesh fence at 3 m.

    The mesh covers rows 0.2-0.85 and columns 0.1-0.9 of the image; each of its pixels sees
    the mesh (half the footprint, reflectivity 0.9: 0.45) and the wall behind (half: 0.3, or
    0.075 on the dark band), two surfaces 1 m apart. Two posts and a top rail, thin bands
    ``max(1/64, 1/size)`` of the side wide (one pixel at 64 x 64 and below), are solid (one
    surface). A depth window maps both layers.
    """
    y, x = _grid(size)
    wall_r = np.where((y >= 0.45) & (y < 0.6), 0.15, 0.6)
    depth = np.full((size, size), _FENCE_WALL)
    refl = wall_r.copy()
    mesh = (x >= 0.1) & (x < 0.9) & (y >= 0.2) & (y < 0.85)
    posts = (_band(x, 0.1, size) | _band(x, 0.88, size)) & (y >= 0.15)
    rail = _band(y, 0.2, size) & (x >= 0.1) & (x < 0.9)
    solid = posts | rail
    depth[mesh | solid] = _FENCE_AT
    refl[mesh] = _FENCE_COVER * 0.9
    refl[solid] = 0.9
    two = mesh & ~solid
    behind = np.where(two, _FENCE_WALL, np.nan)
    behind_r = np.where(two, (1 - _FENCE_COVER) * wall_r, 0.0)
    if depth_min is not None or depth_max is not None:
        depth = _window_map(depth, _FENCE_AT, _FENCE_WALL, depth_min, depth_max)
        behind = _window_map(behind, _FENCE_AT, _FENCE_WALL, depth_min, depth_max)
    return LayeredScene("fence", depth, refl, np.ones((size, size), dtype=bool),
                        behind_depth=behind, behind_reflectivity=behind_r)
