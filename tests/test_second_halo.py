"""A second surface that is a neighbour's halo (:func:`spslidar.depth.guarded.second_halo`):
a one-pixel post before a wall holds the wall's TV halo in the wall's slice, which the
second-surface tests took for the wall seen past it (an outside audit of 2026-12-03: 77 of
the built-in fence's 426 second surfaces at 32 px were on one-surface pixels)."""

from __future__ import annotations

import numpy as np
import pytest

import spslidar
from spslidar.depth.guarded import GuardedDepth, second_halo
from spslidar.scenes import load_scene


def _reference(z, second, shape, share):
    """Pixel by pixel: the largest evidence of the 8 neighbours within a slice of the
    second return's slice, and the pixel's own there below ``share`` of it."""
    n1, n2 = shape
    out = np.zeros(z.shape[0], bool)
    for q, s in enumerate(second):
        if s < 0:
            continue
        i, j = divmod(q, n2)
        top = -np.inf
        for a in range(max(0, i - 1), min(n1, i + 2)):
            for b in range(max(0, j - 1), min(n2, j + 2)):
                if (a, b) != (i, j):
                    top = max(top, z[a * n2 + b, max(0, s - 1):s + 2].max())
        out[q] = top > 0 and z[q, s] < share * top
    return out


def test_a_post_holds_the_walls_halo_a_mesh_pixel_the_wall():
    """A wall at slice 15 (evidence 10); a post at pixel (4, 4), slice 5, with the wall's
    halo (3) at 15; a mesh pixel at (1, 1) that sees the wall at 8 past its wire: the post's
    second return is a halo, the mesh pixel's is not, and a pixel without one is neither."""
    n, k = 8, 20
    z = np.zeros((n * n, k))
    z[:, 15] = 10.0
    for q in (4 * n + 4, 1 * n + 1):
        z[q, 5] = 10.0
    z[4 * n + 4, 15] = 3.0
    z[1 * n + 1, 15] = 8.0
    second = np.full(n * n, -1)
    second[[4 * n + 4, 1 * n + 1]] = 15
    got = second_halo(z, second, (n, n), 0.5)
    assert got[4 * n + 4] and not got[1 * n + 1] and got.sum() == 1
    assert not second_halo(z, second, (n, n), 0.25).any()  # (3 / 10 above a quarter)


def test_equal_to_a_pixel_by_pixel_reference():
    """On 200 random blocks (images of 1 x 1 to 9 x 7, second returns anywhere, at the
    slices' ends too, shares 0.1-0.9): the same pixels as the loop above."""
    rng = np.random.default_rng(3)
    for _ in range(200):
        n1, n2, k = int(rng.integers(1, 10)), int(rng.integers(1, 8)), int(rng.integers(1, 12))
        z = rng.gamma(1.0, 2.0, (n1 * n2, k))
        second = np.where(rng.random(n1 * n2) < 0.5, rng.integers(0, k, n1 * n2), -1)
        share = float(rng.uniform(0.1, 0.9))
        np.testing.assert_array_equal(second_halo(z, second, (n1, n2), share),
                                      _reference(z, second, (n1, n2), share))


def test_the_option_is_checked_and_zero_turns_it_off():
    """``halo`` is a share in [0, 1]; 0 keeps every second surface the other tests pass."""
    from spslidar.errors import ConfigError

    with pytest.raises(ConfigError, match="halo"):
        GuardedDepth(halo=1.5)
    assert GuardedDepth().halo == 0.5 and GuardedDepth(halo=0).halo == 0


def test_the_fences_posts_lose_their_false_second_surfaces():
    """The built-in fence at 32 px (m_n = 5, 50 %, seed 0), read with and without the test:
    the second surfaces on its one-surface pixels (the posts and the rail) fall from 22 to
    at most 5, while at least 350 of its 480 mesh pixels keep theirs (375 without, 371
    with it when measured)."""
    from spslidar.depth.base import DepthContext

    m = spslidar.measure(scene="fence", size=32, noise=5, compression=0.5, seed=0)
    r = spslidar.reconstruct(m, depth="guarded")
    ctx = DepthContext(r.lags, m.acq.bin_width, r.config.pulse_width, (32, 32), True)
    two = load_scene("fence", 32).two_surface.ravel()
    counts = {}
    for halo in (0.0, 0.5):
        est = GuardedDepth(halo=halo).estimate(np.asarray(r.slices), ctx)
        found = np.isfinite(np.asarray(est.depth2)).ravel()
        counts[halo] = (int((found & two).sum()), int((found & ~two).sum()))
    assert np.array_equal(np.isfinite(r.depth2).ravel(), found)  # (the default is 0.5)
    assert counts[0.0][1] >= 15 and counts[0.5][1] <= 5
    assert counts[0.5][0] >= 350 and counts[0.0][0] - counts[0.5][0] <= 15
