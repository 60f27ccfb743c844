"""The MRF's corner step (spslidar.depth.corner): a notch that the per-slice TV cut from a
region's corner is given back to the region where the evidence, relative to each surface's
own level, holds it, and only there."""

from __future__ import annotations

import numpy as np
import pytest

from spslidar.depth.corner import (
    CORNER_LEAST,
    CORNER_LEVEL,
    CORNER_MARGIN,
    GAP,
    fill_corners,
)

SHAPE = (16, 16)
K = 60
WALL, SHELF = 50, 20  # slices: a bright wall, a dark shelf in front of it
NU = 1.0
NOTCH = [(4, 4), (4, 5), (5, 4)]  # the shelf's top-left corner, rounded off


def _case(at_shelf=0.6, at_wall=0.2, shelf=7.0, wall=40.0):
    """The shelf on rows 4-11, columns 4-11, at ``shelf``; the wall around it at ``wall``.
    The labelling gives the three corner pixels of ``NOTCH`` the wall; each holds ``at_shelf``
    of the shelf's level at its slice and ``at_wall`` of the wall's at the wall's (the room at
    m_n = 5, 50 %, seed 139: 0.4-0.6 and 0.2)."""
    z = np.zeros(SHAPE + (K,))
    z[..., WALL] = wall
    z[4:12, 4:12, WALL] = 0.5
    z[4:12, 4:12, SHELF] = shelf
    label = np.full(SHAPE, WALL)
    label[4:12, 4:12] = SHELF
    for y, x in NOTCH:
        z[y, x, SHELF] = at_shelf * shelf
        z[y, x, WALL] = at_wall * wall
        label[y, x] = WALL
    return z.reshape(-1, K), label.ravel()


def test_a_rounded_corner_is_given_back_to_its_region():
    z, label = _case()
    z0, l0 = z.copy(), label.copy()
    out, filled = fill_corners(z, label, NU, SHAPE)
    # at the wall's slice each corner pixel holds 8 noise units against the shelf's 4.2: read
    # as they stand, the wall; relative to each surface's level, the shelf
    assert filled == 3
    expect = l0.reshape(SHAPE).copy()
    expect[4:12, 4:12] = SHELF
    np.testing.assert_array_equal(out.reshape(SHAPE), expect)
    np.testing.assert_array_equal(z, z0)  # no side effects
    np.testing.assert_array_equal(label, l0)


def test_one_pass_fills_the_notch_s_two_inner_pixels_and_the_next_the_corner():
    z, label = _case()
    once, n1 = fill_corners(z, label, NU, SHAPE, passes=1)
    assert n1 == 2 and once.reshape(SHAPE)[4, 4] == WALL
    assert (once.reshape(SHAPE)[[4, 5], [5, 4]] == SHELF).all()


@pytest.mark.parametrize("case", ["halo", "margin", "weak region", "straight edge",
                                  "a hole, not a notch", "along the border",
                                  "at the region's depth", "two lines' joint",
                                  "beside a straight edge"])
def test_what_is_not_filled(case):
    kw = {}
    if case == "halo":  # under a fifth of the shelf's level: its halo, though the wall's is
        kw = {"at_shelf": 0.9 * CORNER_LEAST, "at_wall": 0.01}  # weaker still
    elif case == "margin":  # as much of the wall's level as of the shelf's
        assert CORNER_MARGIN > 1.0
        kw = {"at_wall": 0.6}
    elif case == "weak region":  # the shelf's neighbours below CORNER_LEVEL noise maxima
        kw = {"shelf": 0.9 * CORNER_LEVEL * NU}
    z, label = _case(**kw)
    lab, z3 = label.reshape(SHAPE), z.reshape(SHAPE + (K,))
    if case in ("straight edge", "a hole, not a notch"):
        # a dent in the shelf's top edge (the shelf on three sides), a hole in it (on four):
        # each holds the shelf's evidence a corner pixel would be given back for
        y, x = (4, 7) if case == "straight edge" else (7, 7)
        lab[4:12, 4:12] = SHELF
        z3[4:12, 4:12, SHELF] = 7.0
        lab[y, x] = WALL
        z3[y, x, SHELF], z3[y, x, WALL] = 4.2, 0.5
    elif case == "along the border":  # the shelf's corner at the image's corner
        lab[:] = WALL
        z3[..., WALL] = 40.0
        z3[..., SHELF] = 0.0
        lab[0:8, 0:8] = SHELF
        z3[0:8, 0:8, SHELF] = 7.0
        z3[0:8, 0:8, WALL] = 0.5
        for y, x in ((0, 0), (0, 1), (1, 0)):
            lab[y, x] = WALL
            z3[y, x, SHELF], z3[y, x, WALL] = 4.2, 8.0
    elif case == "beside a straight edge":  # above the shelf's full top edge: the shelf on
        # one side only (the halo discount's case, not a corner's)
        lab[4:12, 4:12] = SHELF
        z3[4:12, 4:12, SHELF] = 7.0
        z3[3, 7, SHELF], z3[3, 7, WALL] = 4.2, 8.0
    elif case == "two lines' joint":  # one-pixel lines down and right of the corner pixel,
        # the pixel diagonal between them the wall: no region's corner to round
        lab[4:12, 4:12] = WALL
        z3[4:12, 4:12, SHELF], z3[4:12, 4:12, WALL] = 0.0, 40.0
        lab[5:12, 4] = lab[4, 5:12] = SHELF
        z3[5:12, 4, SHELF] = z3[4, 5:12, SHELF] = 7.0
        z3[4, 4, SHELF], z3[4, 4, WALL] = 4.2, 8.0
    elif case == "at the region's depth":  # GAP slices from the shelf: at its depth already
        lab[4, 4] = SHELF + GAP
        lab[4, 5] = lab[5, 4] = SHELF
    before = label.copy()
    out, filled = fill_corners(z, label, NU, SHAPE)
    assert filled == 0 and (out == before).all()


def test_the_mrf_runs_it_last_and_counts_it():
    from spslidar.depth.base import DepthContext
    from spslidar.depth.mrf import MRFDepth

    z, _ = _case()
    rng = np.random.default_rng(0)
    x = (z + rng.normal(0.0, 0.05, z.shape)).astype(np.float32)
    ctx = DepthContext(np.arange(K), 1e-10, 0.5, SHAPE, False)
    # the halo discount off: here it would catch the corner (a halo one pixel deep), which
    # on real slices is three deep at the corner and escapes it (module docstring)
    on = MRFDepth(halo=False).estimate(x, ctx)
    off = MRFDepth(halo=False, corners=False).estimate(x, ctx)
    assert off.info["corner_pixels"] == 0
    assert on.info["corner_pixels"] == 3
    corner = np.ravel_multi_index(tuple(np.array(NOTCH).T), SHAPE)
    np.testing.assert_allclose(on.depth[corner], on.depth[5 * SHAPE[1] + 5])  # the shelf's
    behind = (WALL - SHELF) * 1e-10 * 299_792_458.0 / 2.0  # the wall, 0.45 m behind
    np.testing.assert_allclose(off.depth[corner] - on.depth[corner], behind, rtol=0.05)
    rest = np.setdiff1d(np.arange(z.shape[0]), corner)
    np.testing.assert_array_equal(on.depth[rest], off.depth[rest])


def test_a_corner_rounded_two_deep_is_read_past_its_weak_neighbours():
    # room seeds 44 and 88 at m_n = 5, 50 %: the shelf's top-left 2 x 2 pixels given the
    # wall, each holding a fifth of the wall's level; the notch (5, 5)'s two wall neighbours
    # are as weak as it, so the wall's level is read one pixel further on
    z, label = _case()
    lab, z3 = label.reshape(SHAPE), z.reshape(SHAPE + (K,))
    cut = [(4, 4), (4, 5), (5, 4), (5, 5)]
    for y, x in cut:
        lab[y, x] = WALL
        z3[y, x, SHELF], z3[y, x, WALL] = 0.6 * 7.0, 0.2 * 40.0
    out, filled = fill_corners(z, label, NU, SHAPE)
    assert filled == 4
    assert all(out.reshape(SHAPE)[y, x] == SHELF for y, x in cut)
    # where the pixel further on is no brighter than twice the neighbour (a surface's dim
    # edge, not a cut: procedural seed 108), the neighbour's own level stands
    for y, x in ((3, 5), (5, 3), (3, 4), (4, 3)):
        z3[y, x, WALL] = 0.3 * 40.0
    assert fill_corners(z, label, NU, SHAPE)[1] == 0
