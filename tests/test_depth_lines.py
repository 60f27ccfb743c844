"""The MRF's thin-structure rule (spslidar.depth.lines): argmax returns in front of the MRF's
surface are kept where, and only where, they line up."""

from __future__ import annotations

import numpy as np
import pytest

from spslidar.depth.lines import thin_structures

SHAPE = (32, 32)
WALL = 200  # the MRF's label everywhere: a wall at slice 200
NU = 3.0  # the block's typical noise maximum


def _blank():
    a = np.full(SHAPE, WALL)
    strength = np.full(SHAPE, 2.0 * NU)
    return a, strength


def _keep(a, strength, **kw):
    label = np.full(a.size, WALL)
    return thin_structures(a.ravel(), label, strength.ravel(), NU, SHAPE, **kw).reshape(SHAPE)


def test_a_pole_at_one_depth_is_kept():
    a, s = _blank()
    a[4:20, 10] = 120  # a one-pixel pole 80 slices in front of the wall
    keep = _keep(a, s)
    assert keep[4:20, 10].all() and keep.sum() == 16


def test_a_slanted_wire_is_kept():
    # the depth changes by 12 slices a pixel along the wire (procedural seed 13's lost wire)
    a, s = _blank()
    cols = np.arange(5, 16)
    a[19, cols] = 40 + 12 * (cols - 5)
    s[19, cols] = np.array([1.5, 3.0, 2.6, 2.7, 3.4, 1.4, 1.3, 2.4, 2.3, 3.3, 2.3]) * NU
    keep = _keep(a, s)
    assert keep[19, cols].all() and keep.sum() == cols.size


def test_a_wire_found_on_every_other_pixel_is_kept_by_the_two_pixel_pass():
    # procedural seed 101's dark staircase wire: argmax finds half its pixels, none of them
    # 8-neighbours; only the pass joining pixels two apart sees the line
    from spslidar.depth.lines import PASSES

    a, s = _blank()
    cols = np.arange(4, 30, 2)
    a[10, cols] = 120 + (cols - 4) // 2
    s[10, cols] = 1.5 * NU
    keep = _keep(a, s)
    assert keep[10, cols].all() and keep.sum() == cols.size
    assert not _keep(a, s, passes=PASSES[:2]).any()


def test_a_shallow_wire_found_on_one_pixel_in_three_is_kept_by_the_three_pixel_pass():
    # held-out procedural seed 101 (m_n = 10, 50 %): a wire 1 row down every 5-6 columns,
    # its depth 4 slices nearer a column; argmax finds 14 of its 28 pixels, some 3 apart
    from spslidar.depth.lines import PASSES

    a, s = _blank()
    cols = np.array([10, 13, 15, 17, 18, 20, 23, 26, 28, 29])
    rows = 20 - (cols - 10) // 6
    a[rows, cols] = 160 - 4 * (cols - 10)
    s[rows, cols] = 1.5 * NU
    keep = _keep(a, s)
    assert keep[rows, cols].all() and keep.sum() == cols.size
    assert not _keep(a, s, passes=PASSES[:3]).any()
    # the same pixels at depths that do not line up: nothing
    a[rows, cols] = 160 - 4 * (cols - 10) + 9 * (np.arange(cols.size) % 2)
    assert not _keep(a, s).any()


@pytest.mark.parametrize("case", ["blob", "behind", "weak", "short", "curved"])
def test_what_is_not_a_line_is_left_to_the_mrf(case):
    a, s = _blank()
    if case == "blob":  # a compact cluster in front: the MRF's to judge
        a[10:14, 10:14] = 120
    elif case == "behind":  # a line behind the MRF's surface
        a[4:20, 10] = 230
    elif case == "weak":  # each return below the floor (0.8 noise maxima)
        a[4:20, 10] = 120
        s[4:20, 10] = 0.7 * NU
    elif case == "short":  # three pixels whose evidence sums to 3 noise maxima, not 5
        a[4:7, 10] = 120
        s[4:7, 10] = 1.0 * NU
    else:  # a line whose depth is not linear along it (a zigzag of 5 slices)
        a[4:20, 10] = 120 + 5 * (np.arange(16) % 2)
    assert not _keep(a, s).any()


def test_scattered_noise_spikes_do_not_line_up():
    # 5 % of the pixels with a spike in front of the wall at a random slice and a strength
    # of 1-3 noise maxima: a line of them by chance is rare (none at this seed; the rule
    # takes groups of 3+ joined pixels 3.5 times longer than wide with a linear depth)
    rng = np.random.default_rng(7)
    a, s = _blank()
    spikes = rng.random(SHAPE) < 0.05
    a[spikes] = rng.integers(0, WALL - 4, spikes.sum())
    s[spikes] = rng.uniform(1.0, 3.0, spikes.sum()) * NU
    assert _keep(a, s).mean() < 0.002


def test_degenerate_inputs():
    a, s = _blank()
    a[4:20, 10] = 120
    assert not thin_structures(a.ravel(), np.full(a.size, WALL), s.ravel(), 0.0, SHAPE).any()
    empty = np.zeros(0, int)
    assert thin_structures(empty, empty, empty.astype(float), NU, (0, 0)).size == 0


def _extend(a, label, strength, **kw):
    from spslidar.depth.lines import extend_lines

    label_strength = np.full(a.size, 2.0 * NU)
    return extend_lines(a.ravel(), label.ravel(), strength.ravel(), label_strength, NU, SHAPE,
                        **kw).reshape(SHAPE)


def _piecewise_pole():
    # the room's lamp pole at m_n = 1: the MRF labels rows 4-9 and 14-19 of the pole and gives
    # rows 10-12 the wall, whose argmax is the pole's slice at 1-1.5 noise maxima; three
    # candidate pixels alone are too short for thin_structures
    a, s = _blank()
    label = np.full(SHAPE, WALL)
    label[4:10, 10] = label[14:20, 10] = 120
    a[4:20, 10] = 120
    a[13, 10] = WALL
    s[10:13, 10] = 1.2 * NU
    return a, s, label


def test_a_pole_the_mrf_keeps_in_pieces_is_continued():
    a, s, label = _piecewise_pole()
    assert not thin_structures(a.ravel(), label.ravel(), s.ravel(), NU, SHAPE).any()
    keep = _extend(a, label, s)
    assert keep[10:13, 10].all() and keep.sum() == 3


def test_a_pole_s_bleed_beside_it_is_not_continued():
    # the pixel beside the pole whose argmax is the pole's slice joins the group but lies a
    # pixel off its axis (street, m_n = 1: kept, it cost 2.4 m)
    a, s, label = _piecewise_pole()
    a[7, 11] = 120
    keep = _extend(a, label, s)
    assert not keep[7, 11] and keep[10:13, 10].all()
    assert _extend(a, label, s, axis=1.5)[7, 11]  # the axis test is what refuses it


@pytest.mark.parametrize("case", ["no anchor", "other depth", "weak"])
def test_what_continues_no_structure_is_left_alone(case):
    a, s, label = _piecewise_pole()
    if case == "no anchor":  # the MRF holds no one-pixel structure
        label[:] = WALL
    elif case == "other depth":  # the candidates 30 slices off the pole's depth
        a[10:13, 10] = 90
    else:  # below the floor
        s[10:13, 10] = 0.7 * NU
    assert not _extend(a, label, s).any()


def _leg_with_an_offset_run(candidates: int = 2):
    # the room's table leg (held-out seed 287, m_n = 5, 50 %): the MRF labels it on rows
    # 14-20 but two of those rows 8 slices nearer, and gives its top rows the wall behind,
    # whose argmax is the leg's slice; a Theil-Sen line through the group holds 7 of 9
    a, s = _blank()
    label = np.full(SHAPE, WALL)
    top = 14 - candidates
    label[14:21, 10] = 120
    label[14:16, 10] = 112
    a[top:21, 10] = 120
    s[top:14, 10] = 1.5 * NU
    return a, s, label, top


def test_a_leg_whose_labels_are_off_on_a_few_rows_is_still_continued():
    from spslidar.depth import lines

    a, s, label, top = _leg_with_an_offset_run()
    keep = _extend(a, label, s)
    assert keep[top:14, 10].all() and keep.sum() == 14 - top
    # the share of all members on the line is what lets it through (7 of 9 here)
    saved = lines.EXTEND_SHARE
    try:
        lines.EXTEND_SHARE = 0.8
        assert not _extend(a, label, s).any()
    finally:
        lines.EXTEND_SHARE = saved


def test_candidates_off_the_line_of_an_offset_leg_are_not_kept():
    a, s, label, top = _leg_with_an_offset_run(3)
    a[top:14, 10] = [120, 131, 109]  # two of the three 11 slices off the line
    assert not _extend(a, label, s).any()


def test_one_pixel_wide():
    from spslidar.depth.lines import one_pixel_wide

    label = np.full(SHAPE, WALL)
    label[4:20, 10] = 120  # a pole: one pixel wide
    label[4:20, 20:23] = 120  # a panel three pixels wide: not
    label[25, 3:9] = 150  # a wire along a row
    thin = one_pixel_wide(label.ravel(), SHAPE).reshape(SHAPE)
    assert thin[4:20, 10].all() and thin[25, 3:9].all()
    # a rectangle's corners are one pixel wide along a diagonal; nothing else of the panel is
    corners = [(4, 20), (4, 22), (19, 20), (19, 22)]
    assert all(thin[c] for c in corners) and thin[:, 20:23].sum() == 4
    assert thin.sum() == 16 + 6 + 4


def _evidence_cube(label, line_rows, col, line_slice, level):
    """Evidence (Q, K): 2 nu at each pixel's label, ``level`` (per row, in nu) at the line's
    slice along ``col`` for ``line_rows``, zero elsewhere."""
    k = WALL + 10
    z = np.zeros((SHAPE[0] * SHAPE[1], k))
    z[np.arange(z.shape[0]), label.ravel()] = 2.0 * NU
    for r, lv in zip(line_rows, level, strict=True):
        z[r * SHAPE[1] + col, line_slice] = lv * NU
    return z


def test_a_pole_is_followed_beyond_its_labelled_end():
    # the MRF holds rows 10-19 of a pole at slice 120; rows 2-9 are labelled wall, with the
    # pole's evidence there at 0.7-1.3 noise maxima (the room's pole at m_n = 5, 50 %); above
    # row 2 nothing. The walk takes a pixel while the mean over the pixel before it, it and the
    # next holds, so it stops one pixel short of the pole's top (row 2: a window reaching
    # past the end)
    from spslidar.depth.lines import track_lines

    label = np.full(SHAPE, WALL)
    label[10:20, 10] = 120
    rows = np.arange(2, 10)
    z = _evidence_cube(label, rows, 10, 120, [0.9, 1.0, 1.0, 0.8, 1.3, 0.8, 1.1, 1.2])
    z[np.arange(10, 20) * SHAPE[1] + 10, 120] = 2.0 * NU
    new, added = track_lines(z, label.ravel(), NU, SHAPE)
    new = new.reshape(SHAPE)
    assert added == 7 and (new[3:20, 10] == 120).all()
    assert (new[:3, 10] == WALL).all() and (new[:, 11] == WALL).all()


def test_a_table_leg_labelled_on_three_rows_is_followed():
    # the room's table legs at m_n = 1, 25 %: the MRF holds 3 rows of a leg, the rows below
    # it hold the leg's evidence at 1 noise maximum
    from spslidar.depth.lines import track_lines

    label = np.full(SHAPE, WALL)
    label[20:23, 10] = 120
    z = _evidence_cube(label, np.arange(23, 28), 10, 120, [1.0] * 5)
    new, added = track_lines(z, label.ravel(), NU, SHAPE)
    new = new.reshape(SHAPE)
    assert added == 4 and (new[20:27, 10] == 120).all() and (new[27:, 10] == WALL).all()
    assert track_lines(z, label.ravel(), NU, SHAPE, min_pixels=4)[1] == 0


def test_a_strong_pole_s_bleed_beyond_its_end_is_not_taken():
    # procedural seed 17 (m_n = 5, 25 %): a pole at 8-10 noise maxima ends at row 3; above
    # it the reconstruction's bleed at the pole's slice is 1.6, 1.0, 0.7: enough for the
    # window alone, not a fifth of the pole's own evidence (kept, it cost 1.1 m on one pixel)
    from spslidar.depth.lines import track_lines

    label = np.full(SHAPE, WALL)
    label[3:12, 10] = 120
    z = _evidence_cube(label, np.arange(0, 3), 10, 120, [0.7, 1.0, 1.6])
    z[np.arange(3, 12) * SHAPE[1] + 10, 120] = 9.0 * NU
    new, added = track_lines(z, label.ravel(), NU, SHAPE)
    assert added == 0 and (new == label.ravel()).all()
    assert track_lines(z, label.ravel(), NU, SHAPE, relative=0.0)[1] == 2


@pytest.mark.parametrize("case", ["weak", "one strong pixel", "in front", "short", "blob"])
def test_the_walk_stops_where_the_evidence_does(case):
    from spslidar.depth.lines import track_lines

    label = np.full(SHAPE, WALL)
    label[10:20, 10] = 120
    level = [1.0] * 6
    if case == "weak":  # below 0.5 noise maxima
        level = [0.4] * 6
    elif case == "one strong pixel":  # a 2-nu spike at the line's slice, a pixel past a gap
        level = [0, 0, 0, 0, 2.0, 0]
    elif case == "in front":  # the next pixels hold something nearer than the pole
        label[4:10, 10] = 100
    elif case == "short":  # two labelled pixels are no structure
        label[12:20, 10] = WALL
    z = _evidence_cube(label, np.arange(4, 10), 10, 120, level)
    if case == "blob":  # the reconstruction's bleed over a patch, as high beside the line
        for col in (9, 11):  # (procedural seed 117, m_n = 1, 50 %: it cost 2.5 m on a pixel)
            z[np.arange(4, 10) * SHAPE[1] + col, 120] = 1.0 * NU
    new, added = track_lines(z, label.ravel(), NU, SHAPE)
    assert added == 0 and (new == label.ravel()).all()


def test_one_wrong_argmax_does_not_refuse_a_line():
    # procedural seed 109 (m_n = 1, 50 %): a dark pole argmax finds on 13 of 20 rows, one of
    # them 13 slices off; the least-squares line fails the 2-slice test, the Theil-Sen line's
    # inliers (12 of 13) are kept, the stray pixel is not
    a, s = _blank()
    rows = np.array([2, 4, 5, 6, 8, 9, 10, 11, 12, 14, 15, 17, 18])
    a[rows, 10] = 72
    a[11, 10] = 85
    s[rows, 10] = 1.3 * NU
    keep = _keep(a, s)
    assert keep[rows[rows != 11], 10].all() and not keep[11, 10] and keep.sum() == 12
    assert not _keep(a, s, robust=None).any()


def test_a_leg_at_one_depth_with_a_stray_argmax_keeps_its_straight_pixels():
    # the room at m_n = 5, 50 %, seed 40: a table leg argmax finds at slice 96 on five of six
    # rows and at 91 on the sixth; no line through them fits within 2 slices, the Theil-Sen
    # inliers are 5 of 6 (under 0.9), but the five lie on one column at one slice
    a, s = _blank()
    rows = np.arange(6, 12)
    a[rows, 10] = 96
    a[9, 10] = 91
    s[rows, 10] = np.array([1.5, 1.9, 1.1, 1.2, 1.3, 1.4]) * NU
    keep = _keep(a, s)
    assert keep[rows[rows != 9], 10].all() and not keep[9, 10] and keep.sum() == 5


def test_pixels_at_one_depth_off_one_column_are_not_kept_as_straight():
    # the same group with its pixels at slice 96 on two columns: no straight structure
    a, s = _blank()
    rows = np.arange(6, 12)
    cols = np.array([10, 10, 10, 11, 11, 11])
    a[rows, cols] = 96
    a[9, 11] = 91
    s[rows, cols] = 1.4 * NU
    assert not _keep(a, s, passes=((2, 1, 3, 5.0), (16, 1, 3, 5.0))).any()


def test_a_pole_s_weak_pixel_between_two_pieces_is_mended():
    # the room's lamp pole at m_n = 5, 50 %, seed 2: the MRF holds the pole above and below
    # one row whose evidence at the pole's slice is too weak for the walk (here 0.3 noise
    # maxima, below its sides): the walk steps over it because the pole's own pixels hold the
    # next two, and takes it because the pole runs through it straight at one depth
    from spslidar.depth.lines import track_lines

    label = np.full(SHAPE, WALL)
    label[4:12, 10] = 120
    label[13:22, 10] = 120
    z = _evidence_cube(label, [12], 10, 120, [0.3])
    for col in (9, 11):
        z[12 * SHAPE[1] + col, 120] = 0.6 * NU
    new, added = track_lines(z, label.ravel(), NU, SHAPE)
    new = new.reshape(SHAPE)
    assert added == 1 and (new[4:22, 10] == 120).all()
    assert (new[:4, 10] == WALL).all() and (new[22:, 10] == WALL).all()


def test_the_walk_steps_over_one_weak_pixel_to_the_pole_beyond():
    # the room's table leg at m_n = 5, 50 %, seed 2: rows 10-19 held, row 9 weak, rows 7-8
    # held (too short to be a structure of their own), rows 4-6 with the leg's evidence at 1
    # noise maximum: one walk mends row 9 and goes on through 7-8 to take 4-6 (it stops a
    # pixel short of the top, as the window test does)
    from spslidar.depth.lines import track_lines

    label = np.full(SHAPE, WALL)
    label[10:20, 10] = 120
    label[7:9, 10] = 120
    z = _evidence_cube(label, [4, 5, 6, 9], 10, 120, [1.0, 1.0, 1.0, 0.2])
    new, added = track_lines(z, label.ravel(), NU, SHAPE)
    new = new.reshape(SHAPE)
    assert (new[5:20, 10] == 120).all() and added == 3
    assert (new[:4, 10] == WALL).all() and (new[:, 11] == WALL).all()


@pytest.mark.parametrize("case", ["two weak", "one held beyond", "in front", "slanted"])
def test_what_the_walk_does_not_step_over(case):
    # on a slanted wire (2 slices a row), where neither the row-or-column joining nor the
    # bridge to a surface applies, so that the step-over rule alone is tested
    from spslidar.depth.lines import track_lines

    rows = np.arange(SHAPE[0])
    wire = 100 + 2 * rows  # the wire's slice on each row
    label = np.full(SHAPE, WALL)
    label[12:22, 10] = wire[12:22]
    weak = [11]
    if case == "two weak":  # two failing pixels in a row end the walk (the next is not held)
        label[7:10, 10] = wire[7:10]
        weak = [10, 11]
    elif case == "one held beyond":  # the line's pixels must hold the next two, or the walk
        label[10, 10] = wire[10]  # would go on to take rows 6-9 (1 noise maximum each)
        weak = [6, 7, 8, 9, 11]
    elif case == "in front":  # a pixel nearer than the line is not stepped over
        label[11, 10] = 100
        label[8:11, 10] = wire[8:11]
    else:  # stepped over, not taken: the line is not at one depth through it
        label[8:11, 10] = wire[8:11]
    z = _evidence_cube(label, [], 10, 0, [])  # 2 nu at each pixel's label
    for r in weak:
        z[r * SHAPE[1] + 10, wire[r]] = (0.2 if r in (10, 11) else 1.0) * NU
    new, added = track_lines(z, label.ravel(), NU, SHAPE)
    assert added == 0 and (new == label.ravel()).all()


@pytest.mark.parametrize("width", [3, 16])
def test_a_leg_s_walk_does_not_cross_the_table_top(width):
    # a leg under a table top at its depth: the top is wider than a pole and its bleed, so
    # the walk up the leg stops there and never takes the top's bleed into the wall above
    from spslidar.depth.lines import track_lines

    label = np.full(SHAPE, WALL)
    label[12:24, 10] = 120  # the leg
    label[10:12, 10 - width // 2:10 + (width + 1) // 2] = 120  # the table top, two rows
    z = _evidence_cube(label, [7, 8, 9], 10, 120, [1.5, 1.5, 1.5])
    new, added = track_lines(z, label.ravel(), NU, SHAPE)
    assert added == 0 and (new == label.ravel()).all()


def test_a_pole_with_its_bleed_labelled_beside_it_is_still_the_line():
    # the room's lamp pole, seed 2: where the MRF gave the pixel beside the pole the pole's
    # depth too, the pole is no longer one pixel wide there, yet still the line (one pixel at
    # its depth across it, where a table top has four): the walk goes on through it
    from spslidar.depth.lines import one_pixel_wide, track_lines

    label = np.full(SHAPE, WALL)
    label[4:12, 10] = 120
    label[13:22, 10] = 120
    label[13:16, 11] = 120  # the bleed
    assert not one_pixel_wide(label.ravel(), SHAPE).reshape(SHAPE)[14, 10]
    z = _evidence_cube(label, [12], 10, 120, [0.3])
    new, added = track_lines(z, label.ravel(), NU, SHAPE)
    assert added == 1 and new.reshape(SHAPE)[12, 10] == 120


def test_a_leg_in_pieces_a_pixel_apart_is_joined_and_mended():
    # the room's table leg at m_n = 5, 50 %, seed 7: the MRF holds a leg only on scattered
    # rows, one pixel apart (no piece of 3): pieces along one column, at one depth, are joined
    # up to two pixels apart and the single rows between them taken, however weak
    from spslidar.depth.lines import track_lines

    label = np.full(SHAPE, WALL)
    rows = [10, 12, 13, 15, 17]
    label[rows, 10] = 120
    z = _evidence_cube(label, [11, 14, 16], 10, 120, [0.2, 0.2, 0.2])
    new, added = track_lines(z, label.ravel(), NU, SHAPE)
    new = new.reshape(SHAPE)
    assert added == 3 and (new[10:18, 10] == 120).all()
    assert (new[:10, 10] == WALL).all() and (new[18:, 10] == WALL).all()
    # the same pieces off one column (a diagonal) are not joined across the gaps
    diag = np.full(SHAPE, WALL)
    diag[rows, [10, 11, 12, 13, 14]] = 120
    assert track_lines(_evidence_cube(diag, [], 10, 120, []), diag.ravel(), NU, SHAPE)[1] == 0


def test_a_leg_s_walk_bridges_a_short_gap_to_its_table_top():
    # the room at m_n = 5, 50 %, seed 5: under the table top the TV left the leg's top four
    # rows at 0.3-2 noise maxima, too weak for the walk, yet above the pixels beside them; a
    # gap of at most 4 pixels that ends at a surface at the line's own depth is taken
    from spslidar.depth.lines import track_lines

    label = np.full(SHAPE, WALL)
    label[6:8, 4:20] = 120  # the table top
    label[12:24, 10] = 120  # the leg, four rows short of it
    level = [1.9, 0.4, 0.4, 0.3]
    z = _evidence_cube(label, [8, 9, 10, 11], 10, 120, level)
    new, added = track_lines(z, label.ravel(), NU, SHAPE)
    new = new.reshape(SHAPE)
    assert added == 4 and (new[6:24, 10] == 120).all()
    assert (new[:6, 10] == WALL).all() and (new[24:, 10] == WALL).all()


def test_a_leg_s_walk_bridges_a_long_gap_that_stands_above_its_sides():
    # the room at m_n = 5, 50 %, seed 37: the leg's walk stops 7 rows under its table top,
    # where the TV left it at 0.6-1.1 noise maxima and 0-0.7 beside it (0.5 above its sides
    # on average); a gap of 5-12 pixels is taken where it stands 0.3 above its sides
    from spslidar.depth.lines import track_lines

    label = np.full(SHAPE, WALL)
    label[3:5, 4:20] = 120  # the table top
    label[12:24, 10] = 120  # the leg, seven rows short of it
    rows = np.arange(5, 12)
    z = _evidence_cube(label, rows, 10, 120, [1.1, 0.9, 0.7, 0.7, 0.6, 0.8, 0.7])
    for col in (9, 11):
        z[rows * SHAPE[1] + col, 120] = 0.3 * NU
    new, added = track_lines(z, label.ravel(), NU, SHAPE)
    new = new.reshape(SHAPE)
    assert added == 7 and (new[3:24, 10] == 120).all()
    assert (new[:3, 10] == WALL).all() and (new[24:, 10] == WALL).all()


@pytest.mark.parametrize("case", ["too long", "long and faint", "other depth",
                                  "beside as high"])
def test_what_the_walk_does_not_bridge(case):
    from spslidar.depth.lines import track_lines

    label = np.full(SHAPE, WALL)
    top, leg = 120, 12
    rows = [8, 9, 10, 11]
    level, beside = 0.4, 0.0
    if case == "too long":  # thirteen rows short of the top, 0.4 above the pixels beside
        rows, leg = list(range(5, 18)), 18
    elif case == "long and faint":  # five rows short, 0.2 above the pixels beside them
        rows, beside = [7, 8, 9, 10, 11], 0.2
    elif case == "other depth":  # the surface the gap ends at is not at the leg's depth
        top = 100
    elif case == "beside as high":  # the top's bleed below it, as high beside the leg
        level, beside = 1.0, 1.2
    label[rows[0] - 2:rows[0], 4:20] = top
    label[leg:leg + 12, 10] = 120
    z = _evidence_cube(label, rows, 10, 120, [level] * len(rows))
    if beside:
        for col in (9, 11):
            z[np.array(rows) * SHAPE[1] + col, 120] = beside * NU
    new, added = track_lines(z, label.ravel(), NU, SHAPE)
    assert added == 0 and (new == label.ravel()).all()


@pytest.mark.parametrize("line_slice", [0, WALL + 9])
def test_a_line_at_the_gate_s_first_or_last_slice_is_left_alone(line_slice):
    # the walk tests a slice and its two neighbours, so a structure at the gate's edge is not
    # walked (a README example's pole at the first slice once raised on an empty selection)
    from spslidar.depth.lines import track_lines

    label = np.full(SHAPE, WALL)
    label[4:12, 10] = line_slice
    label[14:20, 10] = line_slice
    z = _evidence_cube(label, [12, 13], 10, line_slice, [1.0, 1.0])
    new, added = track_lines(z, label.ravel(), NU, SHAPE)
    assert added == 0 and (new == label.ravel()).all()


# held-out room at m_n = 5, 50 %, seed 9: the lamp pole's evidence at its slice on rows 6-20
# (in nu), where the MRF gave the wall; the walk from the pole's lower piece stops at row 20
POLE_ROWS_6_TO_20 = [2.31, 1.67, 1.56, 1.41, 1.73, 1.55, 1.33, 0.94, 1.46, 0.77, 0.73, 0.90,
                     0.55, 0.55, 0.76]


def _stretch_case(level, strong=2.0):
    label = np.full(SHAPE, WALL)
    label[22:30, 10] = 120
    rows = np.arange(2, 22)  # above the pole's top (row 6) the evidence falls to 0.2-0.5
    z = _evidence_cube(label, rows, 10, 120, [0.22, 0.25, 0.32, 0.48, *level, 0.86])
    z[np.arange(22, 30) * SHAPE[1] + 10, 120] = strong * NU
    return label, z


def test_a_pole_s_weak_stretch_is_crossed_where_its_summed_evidence_holds():
    # the walk takes row 21 and stops at row 20 (window mean 0.72 < 0.9); the stretch from
    # row 20 whose summed evidence less 0.5 a pixel is largest ends at row 6, the pole's top
    from spslidar.depth.lines import track_lines

    label, z = _stretch_case(POLE_ROWS_6_TO_20)
    new, added = track_lines(z, label.ravel(), NU, SHAPE)
    new = new.reshape(SHAPE)
    assert added == 16 and (new[6:30, 10] == 120).all()
    assert (new[:6, 10] == WALL).all() and (new[:, 11] == WALL).all()


@pytest.mark.parametrize("case", ["weak", "too short", "strong pole's bleed", "as high beside"])
def test_what_a_stretch_does_not_take(case):
    from spslidar.depth.lines import track_lines

    level = POLE_ROWS_6_TO_20
    strong = 2.0
    if case == "weak":  # 0.65 nu a pixel: 15 x 0.15 = 2.25 < 3 summed
        level = [0.65] * 15
    elif case == "too short":  # 3 held rows beyond 12 weak ones do not make up for them
        level = [1.6, 1.2, 1.0] + [0.3] * 12
    elif case == "strong pole's bleed":  # beyond a 9-nu pole, below 0.3 of its evidence
        strong = 9.0
    label, z = _stretch_case(level, strong)
    if case == "as high beside":  # a blob of the reconstruction's bleed, not a line
        for col in (9, 11):
            z[np.arange(6, 21) * SHAPE[1] + col, 120] = np.array(level) * NU
    new, added = track_lines(z, label.ravel(), NU, SHAPE)
    new = new.reshape(SHAPE)
    assert (new[:21, 10] == WALL).all() and (new[:, 11] == WALL).all()


@pytest.mark.parametrize("top", [1.2, 0.4])
def test_a_leg_s_top_pixel_under_a_nearer_table_top(top):
    # held-out room at m_n = 5, 50 %, seed 10: a leg (1 noise maximum at its slice) ends under
    # a table top nearer than it; its top pixel, labelled wall, holds 1.4 at the leg's slice.
    # The window reaching past it reads the table top, which hides the line, so that pixel is
    # left out of the window: the top pixel is taken where its own evidence holds (1.2 nu),
    # not where it does not (0.4 nu, below the walk's least of 0.5)
    from spslidar.depth.lines import track_lines

    label = np.full(SHAPE, WALL)
    label[20:23, 5:16] = 60  # the table top, in front of the leg
    label[24:32, 10] = 120
    z = _evidence_cube(label, [23], 10, 120, [top])
    z[np.arange(24, 32) * SHAPE[1] + 10, 120] = 1.0 * NU
    new, added = track_lines(z, label.ravel(), NU, SHAPE)
    new = new.reshape(SHAPE)
    assert (new[24:32, 10] == 120).all() and (new[20:23, 5:16] == 60).all()
    assert new[23, 10] == (120 if top > 1 else WALL) and added == (1 if top > 1 else 0)


def test_a_short_piece_of_a_pole_is_walked_at_its_one_slice():
    """The room's lamp pole on seed 28 (m_n = 5, 50 %): the MRF holds three of its rows,
    labelled 149 / 149 / 150, whose line fit leaves the pole's slice by a slice every two
    rows. The piece is also walked at its median slice, and that walk, which the pole's
    evidence holds for 16 rows, is kept; with the fit alone the walk stops within a few
    rows."""
    from spslidar.depth import lines

    label = np.full(SHAPE, WALL)
    label[14:17, 10] = [149, 149, 150]
    rows = [r for r in range(4, 28) if not 14 <= r < 17]
    z = _evidence_cube(label, rows, 10, 149, [1.2] * len(rows))
    new, added = lines.track_lines(z, label.ravel(), NU, SHAPE)
    new = new.reshape(SHAPE)
    assert (np.abs(new[5:27, 10] - 149) <= 1).all() and added >= 19
    assert (new[:, 9] == WALL).all() and (new[:, 11] == WALL).all()
    old = lines.SNAP_EXTENT
    try:  # the fit's walk alone
        lines.SNAP_EXTENT = 0
        _, fit_only = lines.track_lines(z, label.ravel(), NU, SHAPE)
    finally:
        lines.SNAP_EXTENT = old
    assert fit_only < added - 10


def test_a_short_piece_of_a_slanted_wire_keeps_its_slope():
    """A wire along a row whose slice grows by one every two columns (procedural seed 113): a
    piece of three labelled 120 / 121 / 121 is as close to one slice as the pole's, but the
    walk along the slope goes further, so the slope is kept."""
    from spslidar.depth.lines import track_lines

    label = np.full(SHAPE, WALL)
    cols = np.arange(2, 30)
    slices = 113 + (cols + 1) // 2  # 114, 114, 115, 115, ...
    label[12, 13:16] = slices[11:14]
    assert np.ptp(label[12, 13:16]) == 1
    k = WALL + 10
    z = np.zeros((SHAPE[0] * SHAPE[1], k))
    z[np.arange(z.shape[0]), label.ravel()] = 2.0 * NU
    for c, sl in zip(cols, slices, strict=True):
        z[12 * SHAPE[1] + c, sl] = 1.2 * NU
    new, added = track_lines(z, label.ravel(), NU, SHAPE)
    new = new.reshape(SHAPE)
    assert added >= 20
    assert (np.abs(new[12, 4:28] - slices[2:26]) <= 1).all()


def _hanging_leg(own=1.2, col=10, side=0.2):
    """A table top at slice 120 (rows 3-4, columns 4-10) over a wall at ``WALL``; under the
    top's column ``col`` the leg's evidence at 120 is 1 noise maximum on rows 5-16, ``side``
    beside it, and every wall pixel's evidence at its own label ``own``."""
    label = np.full(SHAPE, WALL)
    label[3:5, 4:11] = 120
    z = np.zeros((SHAPE[0] * SHAPE[1], WALL + 10))
    z[np.arange(z.shape[0]), label.ravel()] = own * NU
    z[(label == 120).ravel(), 120] = 8.0 * NU
    rows = np.arange(5, 17)
    z[rows * SHAPE[1] + col, 120] = 1.0 * NU
    for c in (col - 1, col + 1):
        z[rows * SHAPE[1] + c, 120] = side * NU
    return label, z


def test_a_leg_hanging_from_its_table_top_s_corner_is_taken():
    # the room at m_n = 5, 50 %, seeds 35, 41, 58, 59: a leg under the top's last column that
    # the labelling holds on none of its rows (its pieces too short to walk), its evidence at
    # the top's slice about 1 noise maximum on a dozen rows, 0-0.6 beside it
    from spslidar.depth.hang import hang_lines

    label, z = _hanging_leg()
    new, added = hang_lines(z, label.ravel(), NU, SHAPE)
    new = new.reshape(SHAPE)
    assert added == 12 and (new[3:17, 10] == 120).all()
    assert (new[17:, 10] == WALL).all() and (new[5:, 9] == WALL).all()


@pytest.mark.parametrize("case", ["strong own label", "under the top's middle",
                                  "as high beside", "along the border"])
def test_what_does_not_hang(case):
    from spslidar.depth.hang import hang_lines

    if case == "strong own label":  # a strong surface's sidelobe at the top's slice
        label, z = _hanging_leg(own=4.0)
    elif case == "under the top's middle":  # the top's bleed under an edge, not an end
        label, z = _hanging_leg(col=7)
    elif case == "as high beside":
        label, z = _hanging_leg(side=0.9)
    else:  # the same top and leg against the image's left edge
        label, z = _hanging_leg(col=0)
        label[3:5, 4:11] = WALL
        label[3:5, 0] = 120
        z[:, 120] = 0.0
        z[(label == 120).ravel(), 120] = 8.0 * NU
        z[np.arange(5, 17) * SHAPE[1], 120] = 1.0 * NU
    new, added = hang_lines(z, label.ravel(), NU, SHAPE)
    assert added == 0 and (new == label.ravel()).all()


def test_a_hung_leg_longer_than_a_stretch_is_walked_on():
    # the room at m_n = 5, 50 %, seed 110: the lamp pole hung from the floor's end for the
    # 16 rows a stretch reaches, and the 17 rows above (1.0-2.4 noise maxima at its slice, 0-1
    # beside it) were taken only once the MRF walked the hung line as a structure
    from spslidar.depth.hang import hang_lines
    from spslidar.depth.lines import STRETCH_REACH, track_lines

    label, z = _hanging_leg()
    rows = np.arange(17, 29)
    z[rows * SHAPE[1] + 10, 120] = 1.0 * NU  # the leg goes on to row 28
    z[rows * SHAPE[1] + 9, 120] = z[rows * SHAPE[1] + 11, 120] = 0.2 * NU
    hung, added = hang_lines(z, label.ravel(), NU, SHAPE)
    assert added == STRETCH_REACH and (hung.reshape(SHAPE)[29:, 10] == WALL).all()
    assert (hung.reshape(SHAPE)[5 + STRETCH_REACH:, 10] == WALL).all()  # the stretch stops
    taken = hung != label.ravel()
    walked, more = track_lines(z, hung, NU, SHAPE, within=taken)
    none, zero = track_lines(z, hung, NU, SHAPE, within=np.zeros_like(taken))
    assert zero == 0 and (none == hung).all()  # no structure holds a pixel of `within`
    walked = walked.reshape(SHAPE)
    # rows 21-27 (the walk's window, which reads one pixel past it, stops at the last row)
    assert more == 24 - STRETCH_REACH - 1
    assert (walked[3:28, 10] == 120).all() and (walked[29:, 10] == WALL).all()
    assert (walked[5:, 9] == WALL).all() and (walked[5:, 11] == WALL).all()


@pytest.mark.parametrize("wide", [False, True])
def test_a_hanging_leg_goes_on_through_a_piece_the_labelling_holds(wide):
    # the room at m_n = 5, 50 %, seed 140: the leg's row 46 held its slice, and the stretch
    # from the top ended there, its sum 2.95 short of 3 noise maxima; a pixel of the line
    # (one pixel wide, at its slice) is passed through, a surface at its depth is not
    from spslidar.depth.hang import hang_lines
    from spslidar.depth.lines import STRETCH_LEVEL, STRETCH_TOTAL

    label, z = _hanging_leg(own=1.0)
    rows = np.arange(5, 17)
    z[rows * SHAPE[1] + 10, 120] = 0.8 * NU
    assert (14 - 5) * (0.8 - STRETCH_LEVEL) < STRETCH_TOTAL  # rows 5-13 alone fall short
    label[14, 10] = 120  # the piece
    z[14 * SHAPE[1] + 10, 120] = 1.5 * NU
    if wide:  # a patch of a surface at the top's depth, not a line's piece
        label[14, 11] = 120
        z[14 * SHAPE[1] + 11, 120] = 1.5 * NU
    new, added = hang_lines(z, label.ravel(), NU, SHAPE)
    new = new.reshape(SHAPE)
    if wide:
        assert added == 0 and (new == label).all()
    else:
        assert added == 11  # the piece is not counted
        assert (new[3:17, 10] == 120).all() and (new[17:, 10] == WALL).all()
        assert (new[5:, 9] == WALL).all()


@pytest.mark.parametrize("piece_rows", [2, 1])
def test_a_walk_goes_on_past_a_bridge_to_a_piece_of_its_own_line(piece_rows):
    # the room at m_n = 5, 50 %, seed 153: the lamp pole's walk bridged four weak rows to a
    # two-row piece of the pole that the MRF held, took it for a table top and stopped, and
    # the 14 rows above (1.6-2.5 noise maxima at the pole's slice, 0.2-0.6 beside) kept the
    # wall; a piece of two one-pixel-wide pixels is the line's own, and the walk goes on (one
    # pixel could be a table top's corner, and the walk stops there as before)
    from spslidar.depth.lines import track_lines

    pole, col = 100, 10
    label = np.full(SHAPE, WALL)
    z = np.zeros((SHAPE[0] * SHAPE[1], WALL + 10))
    z[np.arange(z.shape[0]), label.ravel()] = 2.0 * NU
    at = np.arange(SHAPE[0]) * SHAPE[1] + col
    label[20:26, col] = pole  # the piece the walk starts from
    z[at[20:26], pole] = 3.0 * NU
    z[at[16:20], pole] = 0.3 * NU  # weak rows: bridged, not walked
    piece = range(16 - piece_rows, 16)
    for r in piece:  # the MRF's piece of the pole above them
        label[r, col] = pole
        z[at[r], pole] = 3.0 * NU
    z[at[4:16 - piece_rows], pole] = 1.5 * NU  # the pole's rows above, walkable
    new, added = track_lines(z, label.ravel(), NU, SHAPE)
    new = new.reshape(SHAPE)
    assert (new[16:20, col] == pole).all()  # the bridge, as before
    if piece_rows == 2:
        assert added == 4 + 10 and (new[4:14, col] == pole).all()
    else:
        assert added == 4 and (new[4:15, col] == WALL).all()
    assert (new[:4, col] == WALL).all() and (new[:, col - 1] == WALL).all()


@pytest.mark.parametrize("case", ["fill", "sidelobe", "too weak", "strong enough",
                                  "a dimmer surface"])
def test_what_the_walk_on_from_a_hung_line_keeps(case):
    # walk_on: a pixel whose own label is the per-slice TV's fill behind a line (the room at
    # m_n = 5, 50 %, seed 110: the wall's slice read 1.9-2.8 noise maxima on the lamp pole's
    # upper rows against 10 beside them) is kept without the sidelobe test; one whose own
    # label holds as much as its neighbours do there (a random code's sidelobe over a real
    # return) must hold HANG_OWN of it
    from spslidar.depth.hang import HANG_FILL, HANG_OWN, walk_on
    from spslidar.depth.lines import LO

    pole, col, rows = 100, 10, np.arange(5, 15)
    label = np.full(SHAPE, WALL)
    z = np.zeros((SHAPE[0] * SHAPE[1], WALL + 10))
    z[:, WALL] = 10.0 * NU
    at = rows * SHAPE[1] + col
    own, line = {"fill": (2.5, 1.5), "sidelobe": (10.0, 7.0), "too weak": (2.5, 0.9 * LO),
                 "strong enough": (10.0, 8.5), "a dimmer surface": (6.0, 4.0)}[case]
    assert (own < HANG_FILL * 10.0) == (case in ("fill", "too weak"))
    assert (line >= HANG_OWN * own) == (case == "strong enough")
    z[at, WALL] = own * NU
    z[at, pole] = line * NU
    walked = label.copy()
    walked[rows, col] = pole
    z0 = z.copy()
    ok = walk_on(z, label.ravel(), walked.ravel(), NU, SHAPE).reshape(SHAPE)
    assert ok[rows, col].all() == (case in ("fill", "strong enough"))
    assert ok.sum() == (rows.size if case in ("fill", "strong enough") else 0)
    np.testing.assert_array_equal(z, z0)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_hanging_lines_prefilter_changes_nothing(seed, monkeypatch):
    """The anchors tested together before the loop (``_may_stretch``) are only those the loop
    would reject whatever the labelling: the result is bit for bit the loop's alone, on
    labellings of heavy-tailed noise (where lines do hang), a planted leg, and NaN evidence."""
    from spslidar.depth import hang

    rng = np.random.default_rng(seed)
    n, k = 48, 30
    z = rng.exponential(size=(n * n, k))
    label = z.argmax(axis=1)
    z[rng.integers(0, n * n, 40), rng.integers(0, k, 40)] = np.nan
    leg_label, leg_z = _hanging_leg()
    nu = float(np.nanmedian(np.nanmax(z, axis=1))) * 0.4  # low: many anchors near a stretch
    cases = [(z, label, nu, (n, n)), (leg_z, leg_label.ravel(), NU, SHAPE)]
    with np.errstate(invalid="ignore"):
        fast = [hang.hang_lines(*c) for c in cases]
        monkeypatch.setattr(hang, "_may_stretch",
                            lambda z, ys, *a, **kw: np.ones(ys.size, dtype=bool))
        loop = [hang.hang_lines(*c) for c in cases]
    for (a, na), (b, nb) in zip(fast, loop, strict=True):
        assert na == nb and np.array_equal(a, b)
    assert loop[0][1] > 0 and loop[1][1] == 12  # lines were hung: the test compares something
