"""The MRF's hole step (spslidar.depth.holes): a pixel that returns nothing at its neighbours'
surfaces keeps its weak argmax against the MRF; a spike on a surface, a dark surface's pixel,
a bright neighbour's halo and a region do not."""

from __future__ import annotations

import numpy as np
import pytest

from spslidar.depth import DepthContext
from spslidar.depth.holes import (
    HALO_SHARE,
    HOLE_DOT_LEVEL,
    HOLE_LEVEL,
    HOLE_SHARE,
    HOLE_SIZE,
    hole_dots,
    holes,
)
from spslidar.depth.mrf import MRFDepth

SHAPE = (12, 12)
K = 40
WALL, DOT = 30, 8
NU = 1.0


def _holes_by_loops(label, z, nu, shape, share=HOLE_SHARE, level=HOLE_LEVEL, near=1):
    """Independent reference for holes(): pixel by pixel, neighbour by neighbour."""
    n1, n2 = shape
    k = z.shape[1]
    out = np.zeros(n1 * n2, dtype=bool)
    for y in range(n1):
        for x in range(n2):
            i = y * n2 + x
            levels, seen = [], z[i, label[i]]
            for ny, nx in ((y, x + 1), (y, x - 1), (y + 1, x), (y - 1, x)):
                if 0 <= ny < n1 and 0 <= nx < n2:
                    j = ny * n2 + nx
                    levels.append(z[j, label[j]])
                    for o in range(-near, near + 1):
                        seen = max(seen, z[i, min(max(label[j] + o, 0), k - 1)])
            if levels:
                typical = float(np.median(levels))
                out[i] = typical >= level * nu and seen <= share * typical
    return out


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_holes_is_the_rule_read_pixel_by_pixel(seed):
    rng = np.random.default_rng(seed)
    shape = (7, 9)
    z = rng.gamma(1.0, 2.0, size=(shape[0] * shape[1], 12))
    label = rng.integers(0, 12, size=z.shape[0])
    z[np.arange(z.shape[0]), label] += rng.choice([0.0, 8.0], size=z.shape[0])  # some holes
    got = holes(label, z, NU, shape)
    np.testing.assert_array_equal(got, _holes_by_loops(label, z, NU, shape))
    assert got.any() and not got.all()  # (the case exercises both answers)


def _wall(pixels=((5, 5),), dot=1.5, at_wall=0.5, wall=6.0):
    """A wall at WALL whose returns stand ``wall`` noise maxima, labelled the wall; each of
    ``pixels`` holds ``dot`` at DOT and ``at_wall`` of the wall's slice (the TV's filling)."""
    z = np.zeros(SHAPE + (K,))
    z[..., WALL] = wall
    for y, x in pixels:
        z[y, x, DOT] = dot
        z[y, x, WALL] = at_wall
    z = z.reshape(-1, K)
    return z, np.argmax(z, axis=1), np.full(z.shape[0], WALL)


def test_one_weak_object_in_a_hole_keeps_its_argmax_and_nothing_else_moves():
    """One pixel at 1.5 noise maxima (below the dots' levels, and alone) whose wall slice
    holds a twelfth of the wall's: kept, and no other pixel, and no input changed."""
    z, a, label = _wall()
    z0, label0 = z.copy(), label.copy()
    keep = hole_dots(a, label, z, NU, SHAPE)
    assert np.flatnonzero(keep).tolist() == [5 * SHAPE[1] + 5]
    np.testing.assert_array_equal(z, z0)
    np.testing.assert_array_equal(label, label0)


@pytest.mark.parametrize("case", ["spike on the wall", "dark wall", "below the level",
                                  "weaker than its label", "near its label", "halo",
                                  "a region"])
def test_what_is_no_hole_object(case):
    """A spike whose pixel returns at the wall as its neighbours do; a wall too dark for a
    hole to be told; an argmax below HOLE_DOT_LEVEL, or under the label's evidence, or within
    two slices of it; a bright neighbour's halo at its slice; more than HOLE_SIZE pixels."""
    if case == "spike on the wall":
        z, a, label = _wall(dot=3.0, at_wall=5.5)
        z[5 * SHAPE[1] + 5, WALL] = 5.5
    elif case == "dark wall":
        z, a, label = _wall(dot=1.5, at_wall=0.5, wall=HOLE_LEVEL - 0.5)
    elif case == "below the level":
        z, a, label = _wall(dot=HOLE_DOT_LEVEL - 0.1, at_wall=0.2)
    elif case == "weaker than its label":
        z, a, label = _wall(dot=1.5, at_wall=1.6)  # (a hole still: 1.6 < 0.6 x 6)
        a[5 * SHAPE[1] + 5] = DOT  # (argmax reads the raw profile)
    elif case == "near its label":
        z, a, label = _wall(dot=0.0, at_wall=0.5)
        z[5 * SHAPE[1] + 5, WALL + 2] = 1.5
        a = np.argmax(z, axis=1)
    elif case == "halo":
        # a bright object (two pixels, its own business) beside a pixel that holds a third
        # of its evidence at its slice
        z, a, label = _wall(pixels=((5, 5), (5, 6), (5, 7)), dot=9.0, at_wall=0.2)
        z[5 * SHAPE[1] + 7, DOT] = 9.0 * (HALO_SHARE - 0.2)
        label = label.copy()
        label[[5 * SHAPE[1] + 5, 5 * SHAPE[1] + 6]] = DOT
        a = np.argmax(z, axis=1)
        keep = hole_dots(a, label, z, NU, SHAPE)
        assert not keep[5 * SHAPE[1] + 7]
        return
    else:
        region = [(5, x) for x in range(5, 5 + HOLE_SIZE + 1)]
        z, a, label = _wall(pixels=region)
    assert not hole_dots(a, label, z, NU, SHAPE).any()


def test_a_blob_of_four_in_holes_is_kept_where_its_wall_stands_high_enough():
    """Two of a 2 x 2 blob pixel's neighbours are the blob's: the median of its neighbours'
    returns is the mean of the wall's and the blob's at the wall's slice, so the blob is a
    hole where that mean reaches HOLE_LEVEL (a wall at 10, not at 6)."""
    blob = ((5, 5), (5, 6), (6, 5), (6, 6))
    assert len(blob) == HOLE_SIZE
    z, a, label = _wall(pixels=blob, dot=2.0, at_wall=1.0, wall=10.0)
    keep = hole_dots(a, label, z, NU, SHAPE).reshape(SHAPE)
    assert {tuple(p) for p in np.argwhere(keep)} == set(blob)
    z, a, label = _wall(pixels=blob, dot=2.0, at_wall=1.0, wall=6.0)
    assert (6.0 + 1.0) / 2 < HOLE_LEVEL
    assert not hole_dots(a, label, z, NU, SHAPE).any()


def test_many_holes_with_spikes_are_not_all_kept():
    """Where most of a wall is holes of dark pixels (the neighbours' returns vary 6 to 0.5),
    argmaxes at the noise's own level are what noise gives: the count against the holes'
    expected spikes keeps none of them."""
    rng = np.random.default_rng(3)
    shape = (24, 24)
    q = shape[0] * shape[1]
    z = np.abs(rng.normal(0.0, 0.45, (q, K)))  # noise maxima about 1 (nu)
    bright = rng.random(q) < 0.5
    z[:, WALL] = np.where(bright, 6.0, 0.5)
    a = np.argmax(z, axis=1)
    label = np.full(q, WALL)
    nu = 1.0
    keep = hole_dots(a, label, z, nu, shape)
    hole = holes(label, z, nu, shape)
    assert hole.sum() > 50  # (the case holds many holes)
    assert keep.sum() <= 0.2 * max(1, int((hole & (a != WALL)).sum()))


def test_the_mrf_keeps_a_weak_object_in_a_hole_it_would_fill():
    """End to end: a one-pixel object at 1.5 noise units in front of a bright wall whose
    slice holds a tenth of the wall's at that pixel (the TV's filling). The dots' step
    leaves it (one alone, far below DOT_LEVEL): the MRF gives it the wall; with the hole step
    its own depth. The wall is unchanged either way."""
    rng = np.random.default_rng(0)
    q = SHAPE[0] * SHAPE[1]
    x = 0.2 * rng.random((q, K)).astype(np.float32)
    x[:, WALL] += 2.0
    dot = 5 * SHAPE[1] + 5
    x[dot, WALL] = 0.2
    x[dot, DOT] += 0.5
    ctx = DepthContext(np.arange(1000, 1000 + K), bin_width=1e-10, shape=SHAPE)
    without = MRFDepth(holes=False).estimate(x, ctx)
    with_ = MRFDepth().estimate(x, ctx)
    assert np.argmax(x, axis=1)[dot] == DOT
    rest = np.arange(q) != dot
    np.testing.assert_allclose(with_.depth[rest], without.depth[rest])
    assert without.depth[dot] == pytest.approx(without.depth[dot + 1])  # filled
    assert without.info["dot_pixels"] == 0
    assert with_.depth[dot] == pytest.approx(with_.depth[dot + 1] - 22 * 0.015, abs=0.01)
    assert with_.info["hole_pixels"] == 1 and without.info["hole_pixels"] == 0


def test_an_image_without_neighbours_has_no_hole():
    z = np.zeros((1, K))
    z[0, WALL] = 9.0
    assert not holes(np.array([WALL]), z, NU, (1, 1)).any()
    assert not hole_dots(np.array([DOT]), np.array([WALL]), z, NU, (1, 1)).any()


def test_the_noise_is_counted_over_the_holes_only():
    """A weak object (2 noise maxima) in a hole of a bright half-image is kept, though the
    dark half (no holes: its neighbours return weakly too) holds hundreds of noise argmaxes
    at that level: counted over every pixel, noise would be expected to give many such
    argmaxes and none would be kept."""
    rng = np.random.default_rng(4)
    shape = (24, 24)
    q = shape[0] * shape[1]
    z = np.abs(rng.normal(0.0, 0.6, (q, K)))
    z[:, WALL] = np.where(np.arange(q) % shape[1] < shape[1] // 2, 8.0, 0.3)
    obj = 10 * shape[1] + 5  # in the bright half
    z[obj, WALL], z[obj, DOT] = 0.5, 2.0
    z[obj, np.arange(K) != DOT] = np.minimum(z[obj, np.arange(K) != DOT], 0.5)
    nu = 1.0
    a = np.argmax(z, axis=1)
    label = np.full(q, WALL)
    from spslidar.depth.dots import expected_spikes
    from spslidar.depth.profile import noise_maxima

    every = expected_spikes(noise_maxima(z, 2, centre=label), z[:, WALL], np.array([2.0]))
    assert every[0] > 5  # (the dark half alone: counted so, the object is not kept)
    keep = hole_dots(a, label, z, nu, shape)
    assert np.flatnonzero(keep).tolist() == [obj]


def test_a_dark_pole_the_label_holds_is_no_hole():
    """A one-pixel column of a dark pole (its returns 1.8 at its own slice) before a bright
    wall (10), labelled right; one pole pixel holds a noise spike of 2.6 elsewhere. Half its
    neighbours are the wall, so its return is under 0.6 of their median: a hole by that
    test, but its pole neighbours return as weakly at the same label, and that is their own
    tallest return: a dim structure the label holds, so the spike is not kept (room seed 267
    at m_n = 5, 50 % lost a lamp-pole pixel so, 0.0078 -> 0.0114 m, to a first version)."""
    pole, spike = 20, 3
    z = np.zeros(SHAPE + (K,))
    z[..., WALL] = 10.0
    z[:, 6, WALL] = 0.3
    z[:, 6, pole] = 1.8
    z[5, 6, spike] = 2.6
    z = z.reshape(-1, K)
    label = np.full(z.shape[0], WALL)
    label[np.arange(SHAPE[0]) * SHAPE[1] + 6] = pole
    a = np.argmax(z, axis=1)
    i = 5 * SHAPE[1] + 6
    assert a[i] == spike and holes(label, z, NU, SHAPE)[i]
    assert not hole_dots(a, label, z, NU, SHAPE).any()


@pytest.mark.parametrize("at_wall, dot, below", [(1.15, 1.5, 5.9),  # a dimmer wall pixel
                                                 (5.0, 6.0, 8.0)])  # a well filled hole
def test_a_dimmer_wall_neighbour_does_not_make_a_hole_a_dim_structure(at_wall, dot, below):
    """A dot in a hole of a wall at 13 whose pixel below returns less (a slanted surface's
    slice varies so: the ramp with dots at m_n = 5, 50 % held such a dot, 5.86 against
    11.7-14.6): that neighbour is not as dim as the hole (more than 1/0.6 of its return),
    or not dim against the surroundings (over 0.6 of their median), so the dot is kept."""
    z, a, label = _wall(dot=dot, at_wall=at_wall, wall=13.0)
    z[6 * SHAPE[1] + 5, WALL] = below
    keep = hole_dots(a, label, z, NU, SHAPE)
    assert np.flatnonzero(keep).tolist() == [5 * SHAPE[1] + 5]
