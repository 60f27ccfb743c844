"""A line's walk (spslidar.depth.walk) bridging to a surface nearer than the line: a pole
that ends behind a table top is taken up to the top where the pixels between are hidden
from the surface they are labelled with, and only there."""

from __future__ import annotations

import numpy as np
import pytest

from spslidar.depth.lines import track_lines
from spslidar.depth.walk import BRIDGE_REACH, OCCLUDED

SHAPE = (32, 32)
WALL, POLE, TOP = 200, 120, 60  # slices: the wall, a pole in front of it, a nearer table top
NU = 3.0


def _case(gap_rows=(8, 9, 10, 11), at_wall=0.2, at_pole=0.5, beside_pole=0.1):
    """The table top on rows 4-7 (columns 4-19), the pole on rows 12-23 of column 10, both
    labelled; the rows between, labelled the wall, hold ``at_wall`` of the wall's evidence
    beside them at the wall's slice (the wall hidden by the pole: room seed 186 at m_n = 5,
    50 % held 0.09-0.2) and ``at_pole`` noise maxima at the pole's slice, against
    ``beside_pole`` beside it (0.36-0.58 against 0.1-0.2)."""
    label = np.full(SHAPE, WALL)
    label[4:8, 4:20] = TOP
    first = max(gap_rows) + 1
    label[first:first + 12, 10] = POLE
    q = np.arange(SHAPE[0] * SHAPE[1])
    z = np.zeros((q.size, WALL + 10))
    z[q, label.ravel()] = 8.0 * NU
    for r in gap_rows:
        z[r * SHAPE[1] + 10, WALL] = at_wall * 8.0 * NU
        z[r * SHAPE[1] + 10, POLE] = at_pole * NU
        for c in (9, 11):
            z[r * SHAPE[1] + c, POLE] = beside_pole * NU
    return label, z


def test_a_pole_ending_behind_a_nearer_table_top_is_walked_up_to_it():
    label, z = _case()
    l0, z0 = label.copy(), z.copy()
    new, added = track_lines(z, label.ravel(), NU, SHAPE)
    new = new.reshape(SHAPE)
    assert added == 4 and (new[8:24, 10] == POLE).all()
    assert (new[4:8, 4:20] == TOP).all()  # the top is not crossed
    assert (new[:4, 10] == WALL).all()
    np.testing.assert_array_equal(label, l0)  # no side effects
    np.testing.assert_array_equal(z, z0)


@pytest.mark.parametrize("case", ["wall_there", "too_long", "faint", "slanted"])
def test_what_is_not_bridged_to_a_nearer_surface(case):
    kw = {}
    if case == "wall_there":  # the pixels hold the wall as beside them: the pole ends there
        kw = {"at_wall": 1.0}
    elif case == "too_long":  # one row more than a bridge reaches
        kw = {"gap_rows": tuple(range(8, 9 + BRIDGE_REACH))}
    elif case == "faint":  # no more at the pole's slice than beside it
        kw = {"at_pole": 0.1}
    label, z = _case(**kw)
    if case == "slanted":  # a slanted line is never bridged (only a straight one, at one depth)
        label[12:24, 10] = POLE + np.arange(12)
        z[np.arange(12, 24) * SHAPE[1] + 10, POLE + np.arange(12)] = 8.0 * NU
    new, _ = track_lines(z, label.ravel(), NU, SHAPE)
    assert (new.reshape(SHAPE)[8:12, 10] == WALL).all()


def test_the_hidden_share_is_the_threshold():
    # just under OCCLUDED of the wall beside, the rows are bridged; just over, they are not
    for share, taken in ((OCCLUDED * 0.95, True), (OCCLUDED * 1.05, False)):
        label, z = _case(at_wall=share)
        new, _ = track_lines(z, label.ravel(), NU, SHAPE)
        assert ((new.reshape(SHAPE)[8:12, 10] == POLE).all()) == taken


def test_a_pixel_whose_own_label_is_weaker_than_the_line_is_bridged_too():
    # room seed 107 at m_n = 5, 50 %: under the table top the pole's rows are labelled the
    # wall, but so weakly (0.6-0.75 noise maxima) that the wall is no more there than beside
    # them, which are another surface; at the pole's slice they hold 0.8-1.2: the data
    # prefer the line there, and the walk bridges them to the top
    label, z = _case(at_wall=0.0)
    for r in (8, 9, 10, 11):
        for c in (9, 10, 11):
            z[r * SHAPE[1] + c, WALL] = 0.7 * NU  # the wall's slice, weak here and beside
        z[r * SHAPE[1] + 10, POLE] = 1.0 * NU
        label[r, 9] = label[r, 11] = WALL - 30  # beside: another surface, labelled
    new, added = track_lines(z, label.ravel(), NU, SHAPE)
    assert added == 4 and (new.reshape(SHAPE)[8:24, 10] == POLE).all()
    # where the wall's slice holds more than the pole's, the pixels keep it
    for r in (8, 9, 10, 11):
        z[r * SHAPE[1] + 10, WALL] = 1.2 * NU
    new, _ = track_lines(z, label.ravel(), NU, SHAPE)
    assert (new.reshape(SHAPE)[8:12, 10] == WALL).all()
