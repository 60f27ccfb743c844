"""The MRF's gap rule (spslidar.depth.gaps): argmax returns behind the MRF's surface are kept
where they line up in a one-pixel gap between two sides of it, and only there."""

from __future__ import annotations

import numpy as np
import pytest

from spslidar.depth.gaps import between_sides, gap_lines

SHAPE = (32, 32)
FENCE, WALL = 40, 160  # slices: a fence in front of a wall
NU = 3.0


def _fence(gap_cols=(11, 15, 19), rows=slice(4, 28)):
    """The MRF's labelling: the fence everywhere (it closed the gaps); the argmax: the wall
    through one-pixel gaps at ``gap_cols`` on ``rows``, at 1.5 noise maxima."""
    label = np.full(SHAPE, FENCE)
    a = np.full(SHAPE, FENCE)
    s = np.full(SHAPE, 8.0 * NU)
    for c in gap_cols:
        a[rows, c] = WALL
        s[rows, c] = 1.5 * NU
    return a, label, s


def _evidence(a, label, s, front=None):
    """The evidence block ``(Q, K)``: each pixel's ``s`` at its argmax ``a`` and, at its label,
    ``front`` (default: 0.3 noise maxima where the argmax is elsewhere, a hole in the front
    surface, as seed 19's gaps hold 0.04-0.12 of their sides')."""
    k = 256
    q = np.arange(a.size)
    if front is None:
        front = np.where(a == label, s, 0.3 * NU)
    z = np.zeros((a.size, k))
    z[q, label.ravel()] = np.ravel(front)
    z[q, a.ravel()] = s.ravel()
    return z


def _keep(a, label, s, front=None, **kw):
    z = _evidence(a, label, s, front)
    return gap_lines(a.ravel(), label.ravel(), z, NU, SHAPE, **kw).reshape(SHAPE)


def test_a_fence_s_one_pixel_gaps_are_opened():
    a, label, s = _fence()
    z = _evidence(a, label, s)
    a0, l0, z0 = a.copy(), label.copy(), z.copy()
    keep = gap_lines(a.ravel(), label.ravel(), z, NU, SHAPE).reshape(SHAPE)
    assert keep[4:28, [11, 15, 19]].all() and keep.sum() == 3 * 24
    np.testing.assert_array_equal(a, a0)  # no side effects
    np.testing.assert_array_equal(label, l0)
    np.testing.assert_array_equal(z, z0)


def test_a_slanted_gap_and_a_diagonal_gap_are_opened():
    a, label, s = _fence(gap_cols=())
    rows = np.arange(6, 20)
    a[rows, 10] = WALL + (rows - 6)  # a wall receding along the gap, a slice a row
    s[rows, 10] = 1.5 * NU
    a[rows, rows + 8] = WALL  # a diagonal slot: its sides are its diagonal neighbours
    s[rows, rows + 8] = 1.5 * NU
    keep = _keep(a, label, s)
    assert keep[rows, 10].all() and keep[rows, rows + 8].all()
    assert keep.sum() == 2 * rows.size


def test_the_gap_s_pixels_the_mrf_holds_anchor_its_broken_pieces():
    # procedural seed 19's gaps: the MRF holds a gap on some rows, and the argmax of the rest
    # breaks where the slats' halo wins a pixel, leaving single pixels no line test passes
    a, label, s = _fence(gap_cols=())
    label[4:12, 11] = WALL  # held by the MRF
    a[4:12, 11] = WALL
    rows = np.array([13, 15, 17, 19])  # the argmax's single pixels between, each at the wall
    a[rows, 11] = WALL
    s[rows, 11] = 1.5 * NU
    keep = _keep(a, label, s)
    assert keep[rows, 11].all() and keep.sum() == rows.size  # never an anchor itself
    # without the anchors the four pixels, two apart, are too few for the two-pixel pass
    label[4:12, 11] = FENCE
    a[4:12, 11] = FENCE
    assert not _keep(a, label, s).any()
    # a pixel off the gap's axis, two columns over, is not taken with it
    label[4:12, 11] = WALL
    a[4:12, 11] = WALL
    a[rows, 11] = FENCE
    a[7, 13] = WALL
    s[7, 13] = 1.5 * NU
    assert not _keep(a, label, s).any()


@pytest.mark.parametrize("case", ["no_hole", "dark", "edge", "border", "weak", "spikes", "in_front",
                                  "wide"])
def test_what_is_not_a_gap_is_left_to_the_mrf(case):
    a, label, s = _fence(gap_cols=())
    front = None
    if case == "no_hole":  # lined up behind, but the front surface is there as beside it
        # (procedural seed 16: a column of returns 1.4 m behind a dark panel, 0.9-1.2 of the
        # sides' evidence at the panel's slice)
        a[4:28, 11] = WALL
        s[4:28, 11] = 1.5 * NU
        front = np.where(a == label, s, 0.6 * 8.0 * NU)
    elif case == "dark":  # a dark surface's weak pixels between two as weak: a fifth of
        # their evidence, but 2 noise maxima below them together, no more than noise
        s[:] = 1.2 * NU
        a[4:28, 11] = WALL
        s[4:28, 11] = 1.5 * NU
        front = np.where(a == label, s, 0.2 * NU)
    elif case == "edge":  # a surface's edge column read behind: the far surface on one side
        label[:, 20:] = WALL
        a[:, 20:] = WALL
        a[4:28, 19] = WALL
        s[4:28, 19] = 1.5 * NU
    elif case == "border":  # the image's border column is no side
        a[4:28, 0] = WALL
        s[4:28, 0] = 1.5 * NU
    elif case == "weak":  # below the evidence floor (0.8 noise maxima)
        a[4:28, 11] = WALL
        s[4:28, 11] = 0.5 * NU
    elif case == "spikes":  # noise behind the fence: scattered, at random slices
        rng = np.random.default_rng(3)
        idx = rng.choice(SHAPE[0] * SHAPE[1], 40, replace=False)
        a.ravel()[idx] = rng.integers(FENCE + 10, 250, idx.size)
        s.ravel()[idx] = 1.5 * NU
    elif case == "in_front":  # a pole in front is the thin-structure rule's, not this one's
        a[4:28, 11] = FENCE - 30
        s[4:28, 11] = 1.5 * NU
    elif case == "wide":  # a two-pixel gap: the MRF's own to judge
        label[4:28, 11:13] = WALL
        a[4:28, 11:13] = WALL
        a[4:28, 13] = WALL
        s[4:28, 13] = 1.5 * NU
    assert not _keep(a, label, s, front).any()
    if case == "no_hole":  # under half the sides' evidence, the same column is a gap
        front = np.where(a == label, s, 0.45 * 8.0 * NU)
        assert _keep(a, label, s, front)[4:28, 11].all()


def test_between_sides():
    label = np.full((5, 5), FENCE)
    label[:, 4] = WALL  # the right-hand column is the wall
    a = np.full((5, 5), WALL)
    out = between_sides(a.ravel(), label.ravel(), (5, 5)).reshape(5, 5)
    # a pixel is between sides where its two row neighbours or its two column neighbours are
    # the fence: not where a side is the wall or off the image
    expect = np.zeros((5, 5), bool)
    expect[:, 1:3] = True  # left and right: the fence for columns 1 and 2
    expect[1:4, :4] = True  # above and below
    assert (out == expect).all()
    assert not between_sides(a.ravel(), label.ravel(), (5, 5), gap=WALL).any()
    # a region's corner has the fence on a diagonal only: no gap (procedural seed 0)
    label = np.full((5, 5), WALL)
    label[:2, :2] = FENCE
    label[3:, 3:] = FENCE
    assert not between_sides(a.ravel(), label.ravel(), (5, 5)).reshape(5, 5)[2, 2]


def test_degenerate_inputs():
    a, label, s = _fence()
    z = _evidence(a, label, s)
    assert not gap_lines(a.ravel(), label.ravel(), z, 0.0, SHAPE).any()
    empty = np.zeros(0, int)
    assert gap_lines(empty, empty, np.zeros((0, 8)), NU, (0, 0)).size == 0


def test_the_mrf_opens_a_fence_s_gaps():
    """End to end through :class:`MRFDepth`: slats two pixels wide, one-pixel gaps onto a wall
    whose return through them is weak (procedural seed 19's fence at m_n = 5, 50 %)."""
    from spslidar.depth.argmax import ArgmaxDepth
    from spslidar.depth.base import DepthContext
    from spslidar.depth.mrf import MRFDepth

    k = 200
    rng = np.random.default_rng(19)
    x = rng.normal(0.0, 1.0, SHAPE + (k,))
    x[..., FENCE] += 30.0
    gaps = [7, 10, 13, 16, 19, 22]
    for c in gaps:
        x[4:28, c, FENCE] -= 29.0
        x[4:28, c, WALL] += 4.5
    ctx = DepthContext(np.arange(k), 1e-10, 0.5, SHAPE, False)
    on = MRFDepth().estimate(x.reshape(-1, k).astype(np.float32), ctx)
    off = MRFDepth(gaps=False).estimate(x.reshape(-1, k).astype(np.float32), ctx)
    truth = np.full(SHAPE, FENCE * 1e-10 * 299_792_458.0 / 2.0)
    truth[4:28, gaps] = WALL * 1e-10 * 299_792_458.0 / 2.0
    err_on = np.abs(on.depth.reshape(SHAPE) - truth)
    err_off = np.abs(off.depth.reshape(SHAPE) - truth)
    argmax = ArgmaxDepth().estimate(x.reshape(-1, k).astype(np.float32), ctx)
    err_arg = np.abs(argmax.depth.reshape(SHAPE) - truth)
    # a slice is 1.5 cm. The MRF alone gives three gap pixels in four the fence 1.8 m in
    # front; with the rule it holds as many as the argmax (about 92 % here: the rest are
    # pixels whose wall return the noise beats, which no rule reads)
    right = {n: float((e[4:28, gaps] < 0.02).mean())
             for n, e in (("on", err_on), ("off", err_off), ("argmax", err_arg))}
    assert right["off"] < 0.3
    assert off.info["gap_pixels"] == 0 and on.info["gap_pixels"] > 50
    assert right["on"] > 0.85 and right["on"] >= right["argmax"] - 0.02
    # and nothing else is lost: the fence is held as before
    fence = np.ones(SHAPE, bool)
    fence[4:28, gaps] = False
    assert (err_on[fence] < 0.02).mean() >= (err_off[fence] < 0.02).mean() - 0.002
