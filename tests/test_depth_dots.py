"""The MRF's dot step (spslidar.depth.dots): a pixel (or two) whose strong return no
neighbour shares keeps its argmax against the MRF, and nothing else does."""

from __future__ import annotations

from collections import deque

import numpy as np
import pytest

from spslidar.depth import DepthContext
from spslidar.depth.dots import DOT_LEVEL, DOT_SIZE, argmax_groups, keep_dots
from spslidar.depth.mrf import MRFDepth

SHAPE = (12, 12)
K = 40
WALL, DOT = 30, 8
NU = 1.0


def _groups_by_search(a: np.ndarray, shape: tuple[int, int]) -> np.ndarray:
    """Independent reference for argmax_groups: a breadth-first search per pixel."""
    n1, n2 = shape
    grid = a.reshape(shape)
    out = np.zeros(shape, dtype=int)
    for start in np.ndindex(shape):
        seen, todo = {start}, deque([start])
        while todo:
            y, x = todo.popleft()
            for ny, nx in ((y + 1, x), (y - 1, x), (y, x + 1), (y, x - 1)):
                if (0 <= ny < n1 and 0 <= nx < n2 and (ny, nx) not in seen
                        and abs(int(grid[ny, nx]) - int(grid[y, x])) <= 1):
                    seen.add((ny, nx))
                    todo.append((ny, nx))
        out[start] = len(seen)
    return out.ravel()


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_argmax_groups_is_a_search_over_the_grid(seed):
    rng = np.random.default_rng(seed)
    shape = (9, 11)
    a = rng.integers(0, 6, size=shape[0] * shape[1])  # many groups of every size
    np.testing.assert_array_equal(argmax_groups(a, shape), _groups_by_search(a, shape))


def _case(dot=8.0, at_wall=6.0, pixels=((5, 5),)):
    """A wall at ``WALL`` everywhere (5 noise maxima), the labelling the wall's; each of
    ``pixels`` holds a return of ``dot`` at ``DOT`` and ``at_wall`` of the wall's slice
    (the TV's spread of the wall around it)."""
    z = np.zeros(SHAPE + (K,))
    z[..., WALL] = 5.0
    for y, x in pixels:
        z[y, x, DOT] = dot
        z[y, x, WALL] = at_wall
    z = z.reshape(-1, K)
    return z, np.argmax(z, axis=1), np.full(z.shape[0], WALL)


def test_a_strong_dot_keeps_its_argmax_and_nothing_else_moves():
    z, a, label = _case(pixels=((5, 5), (2, 9)))
    z0, label0 = z.copy(), label.copy()
    out, kept = keep_dots(a, label, z, NU, SHAPE)
    expected = label0.reshape(SHAPE).copy()
    expected[5, 5] = expected[2, 9] = DOT
    np.testing.assert_array_equal(out.reshape(SHAPE), expected)
    assert kept == 2
    np.testing.assert_array_equal(z, z0)  # no side effects
    np.testing.assert_array_equal(label, label0)


def test_two_pixels_are_a_dot_three_are_not():
    two = ((5, 5), (5, 6))
    z, a, label = _case(pixels=two)
    out, kept = keep_dots(a, label, z, NU, SHAPE)
    assert kept == DOT_SIZE == 2
    assert all(out.reshape(SHAPE)[p] == DOT for p in two)
    z, a, label = _case(pixels=((5, 5), (5, 6), (6, 6)))
    out, kept = keep_dots(a, label, z, NU, SHAPE)
    assert kept == 0  # a region: the MRF's and the other rules' business
    np.testing.assert_array_equal(out, WALL)


@pytest.mark.parametrize("dot, at_wall", [(DOT_LEVEL - 0.1, 2.0),  # below the level
                                          (8.0, 8.5)])  # weaker than at the MRF's label
def test_a_weak_dot_is_left_to_the_mrf(dot, at_wall):
    z, a, label = _case(dot=dot, at_wall=at_wall)
    # (argmax reads the raw profile, so a dot weaker than the wall's slice in z can still
    # be the argmax: that is the case the second test is for)
    a[5 * SHAPE[1] + 5] = DOT
    out, kept = keep_dots(a, label, z, NU, SHAPE)
    assert kept == 0
    np.testing.assert_array_equal(out, label)


def test_a_halo_at_the_neighbours_slice_is_no_dot():
    """A pixel whose argmax is its bright neighbour's slice (the TV's halo) belongs to that
    neighbour's group, however strong."""
    z, a, label = _case(dot=0.0, at_wall=0.0, pixels=((5, 5), (5, 6), (5, 7)))
    # a bright region of three pixels at DOT (a region, not a dot) with a halo pixel beside
    for y, x in ((5, 5), (5, 6), (5, 7), (5, 8)):
        z[y * SHAPE[1] + x, DOT] = 9.0
    a = np.argmax(z, axis=1)
    out, kept = keep_dots(a, label, z, NU, SHAPE)
    assert kept == 0


def test_the_mrf_keeps_a_one_pixel_object_it_would_smooth_away():
    """End to end on a profile block: a one-pixel object at 10 noise units in front of a
    wall whose spread reaches 9 at that pixel. Without the step the MRF gives it the wall;
    with it, its own depth; the wall is unchanged either way."""
    rng = np.random.default_rng(0)
    q = SHAPE[0] * SHAPE[1]
    x = 0.05 * rng.random((q, K)).astype(np.float32)
    x[:, WALL] += 1.0
    dot = 5 * SHAPE[1] + 5
    x[dot, WALL] = 0.9
    x[dot, DOT] += 1.0
    ctx = DepthContext(np.arange(1000, 1000 + K), bin_width=1e-10, shape=SHAPE)
    without = MRFDepth(dots=False).estimate(x, ctx)
    with_ = MRFDepth().estimate(x, ctx)
    argmax = np.argmax(x, axis=1)
    assert argmax[dot] == DOT
    rest = np.arange(q) != dot
    np.testing.assert_allclose(with_.depth[rest], without.depth[rest])
    assert without.depth[dot] == pytest.approx(without.depth[dot + 1])  # smoothed away
    # kept: 22 slices (0.33 m at 100 ps) in front of the wall
    assert with_.depth[dot] == pytest.approx(with_.depth[dot + 1] - 22 * 0.015, abs=0.01)
    assert with_.info["dot_pixels"] == 1 and without.info["dot_pixels"] == 0
