"""The per-slice TV's halo discounted in the MRF's data cost (spslidar.depth.halo)."""

from __future__ import annotations

import numpy as np
import pytest

from spslidar.depth import DepthContext
from spslidar.depth.halo import HALO_DEEP_RATIO, HALO_POWER, HALO_RATIO, halo_discount
from spslidar.depth.mrf import MRFDepth


def test_halo_pixel_discounted_plateau_and_interior_unchanged():
    """A value beside a bright region that falls off again beyond it is lowered by
    ``(z / (ratio m)) ** power``; a region's interior, its edge at its own level and an
    isolated spike are not."""
    z = np.zeros((1, 5, 7), np.float32)
    z[0, :, :3] = 20.0  # a bright region, columns 0-2
    z[0, :, 3] = 4.0  # its halo, column 3
    z[0, :, 4] = 1.0  # falling off beyond
    z[0, 2, 6] = 6.0  # an isolated spike
    out = halo_discount(z)
    expect = 4.0 * (4.0 / (HALO_RATIO * 20.0)) ** HALO_POWER
    np.testing.assert_allclose(out[0, :, 3], expect, rtol=1e-6)
    np.testing.assert_array_equal(out[0, :, :3], z[0, :, :3])  # interior and own edge
    assert out[0, 2, 6] == 6.0  # a local maximum
    assert out.dtype == z.dtype and out is not z
    assert z[0, 0, 3] == 4.0  # the input untouched


def test_two_pixel_deep_halo_discounted_at_its_first_pixel():
    """A halo two pixels deep (the room's shelf top edge in the wall's slice: 26.4 on the
    wall, 3.4 and 3.4 on the shelf's first two rows, then 1.0) is discounted on the pixel next
    to the bright region; a level that does not fall off within two pixels is not."""
    z = np.zeros((1, 6, 3), np.float32)
    z[0, 0] = 26.4
    z[0, 1] = 3.4
    z[0, 2] = 3.4
    z[0, 3:] = 1.0
    out = halo_discount(z)
    expect = 3.4 * (3.4 / (HALO_RATIO * 26.4)) ** HALO_POWER
    np.testing.assert_allclose(out[0, 1], expect, rtol=1e-6)
    np.testing.assert_array_equal(out[0, 2:], z[0, 2:])
    z[0, 1] = 6.0  # above HALO_DEEP_RATIO of 26.4: three pixels at one level are a plateau
    z[0, 2:4] = 6.0
    np.testing.assert_array_equal(halo_discount(z)[0, 1], z[0, 1])


def test_three_pixel_deep_halo_only_below_the_deep_ratio():
    """The room's shelf edge on seed 9 (m_n = 5, 50 %): the wall's slice reads 26.4 on the
    wall, then 4.4, 3.2, 3.2 and less. Three pixels deep, the first is discounted at the
    deep ratio (4.4 < 0.2 x 26.4); at a ratio above it, and four pixels deep, it is not."""
    z = np.zeros((1, 7, 3), np.float32)
    z[0, 0] = 26.4
    z[0, 1:4] = np.array([4.4, 3.2, 3.2])[:, None]
    z[0, 4:] = 1.0
    out = halo_discount(z)
    expect = 4.4 * (4.4 / (HALO_DEEP_RATIO * 26.4)) ** HALO_POWER
    np.testing.assert_allclose(out[0, 1], expect, rtol=1e-6)
    np.testing.assert_array_equal(out[0, 2:], z[0, 2:])
    brighter = z.copy()
    brighter[0, 1:4] = 6.0  # 0.23 of the wall: a dim strip of its own surface
    np.testing.assert_array_equal(halo_discount(brighter)[0, 1], brighter[0, 1])
    deeper = z.copy()
    deeper[0, 4] = 3.2  # four pixels at the level: beyond any reach
    np.testing.assert_array_equal(halo_discount(deeper)[0, 1], deeper[0, 1])


def test_dim_pixel_on_a_plateau_of_its_own_surface_kept():
    """A dim pixel between a bright pixel and more of its own surface (no fall-off on the
    opposite side) is a texture, not a halo: unchanged."""
    z = np.full((1, 5, 5), 5.0, np.float32)
    z[0, 1, 2] = 60.0  # a bright pixel above (2, 2)
    out = halo_discount(z)
    assert out[0, 2, 2] == 5.0


def test_halo_discount_bad_options():
    z = np.ones((2, 3, 3))
    for kw in ({"ratio": 0.0}, {"ratio": 1.5}, {"power": -1.0}):
        with pytest.raises(ValueError, match="halo ratio"):
            halo_discount(z, **kw)
    with pytest.raises(ValueError, match="shape"):
        halo_discount(np.ones((3, 3)))
    np.testing.assert_array_equal(halo_discount(z * 3.0, power=0.0), z * 3.0)


def _room_errors(seed: int, estimates: dict,
                 lam_scale: float | None = None) -> tuple[dict, dict]:
    """Absolute depth errors and RMSE on the built-in room at 64x64, m_n = 5, 50 % patterns,
    for each ``key: estimate(slices, ctx) -> depth`` on the same reconstruction (at the
    solver's default weight unless ``lam_scale`` is given)."""
    import spslidar

    meas = spslidar.measure(scene="room", size=64, noise=5, compression=0.5, seed=seed)
    r = spslidar.reconstruct(meas, lam_scale=lam_scale)
    ctx = DepthContext(np.asarray(r.lags), meas.acq.bin_width, r.config.pulse_width,
                       (64, 64), False)
    truth, valid = r.scene.depth, r.scene.valid
    err = {}
    for key, estimate in estimates.items():
        d = np.asarray(estimate(r.slices, ctx)).reshape(truth.shape)
        have = valid & np.isfinite(d)
        err[key] = np.abs(d[have] - truth[have])
    return err, {k: float(np.sqrt(np.mean(e ** 2))) for k, e in err.items()}


def test_room_shelf_edge_kept_end_to_end():
    """The case the discount is for (its docstring): the built-in room at 64x64, m_n = 5,
    50 % patterns, seed 0, where the wall's halo took the dark shelf's edge column. Measured
    with today's releases: RMSE 0.054 m without the discount, 0.0049 m with it on FISTA's
    default 0.45 slices (0.049 and 0.016 m at 0.3; argmax 0.28 m); the bound leaves room
    for other BLAS and SciPy builds to move a pixel or two."""
    err, rmse = _room_errors(0, {h: lambda x, c, h=h: MRFDepth(halo=h).estimate(x, c).depth
                                 for h in (False, True)})
    assert rmse[True] < 0.75 * rmse[False]
    assert (err[True] > 0.5).sum() < (err[False] > 0.5).sum()


def test_room_shelf_edge_three_pixel_halo_end_to_end(monkeypatch):
    """The three-pixel reach's case (the module docstring): the room at 64x64, m_n = 5, 50 %
    patterns, seed 9, where the wall's halo spans the dark shelf's first three columns.
    Measured with today's releases: RMSE 0.045 m with the two-pixel reach alone, 0.027 m with
    the third pixel; the bounds leave room for other BLAS and SciPy builds to move a pixel.
    The slices are FISTA's at ``lam_scale`` 0.3, where the case arose: at the default 0.45
    the shelf's edge keeps its depth without the third pixel (0.029 m with or without it).
    Both without the corner step (:mod:`spslidar.depth.corner`), which gives back part of the
    same edge's top corner (two-pixel reach 0.031 m with it)."""
    import spslidar.depth.halo as halo

    def two_pixel_reach(slices, ctx):
        with monkeypatch.context() as m:  # a ratio no value is below: no third pixel
            m.setattr(halo, "HALO_DEEP_RATIO", 1e-30)
            return MRFDepth(corners=False).estimate(slices, ctx).depth

    err, rmse = _room_errors(9, {False: two_pixel_reach,
                                 True: lambda x, c: MRFDepth(corners=False).estimate(x, c).depth},
                             lam_scale=0.3)
    assert rmse[True] < 0.8 * rmse[False]
    assert rmse[True] < 0.035
    assert (err[True] > 0.5).sum() < (err[False] > 0.5).sum()
