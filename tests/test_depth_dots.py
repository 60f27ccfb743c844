"""The MRF's dot step (spslidar.depth.dots): a pixel (or two) whose strong return no
neighbour shares keeps its argmax against the MRF, and nothing else does."""

from __future__ import annotations

from collections import deque

import numpy as np
import pytest

from spslidar.depth import DepthContext
from spslidar.depth.dots import (
    DOT_FDR,
    DOT_LEVEL,
    DOT_SIZE,
    WEAK_DOT_COUNT,
    argmax_groups,
    expected_spikes,
    keep_dots,
    weak_dots,
)
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


# -- weaker dots, kept together against the profiles' own noise (weak_dots) ---------------------
@pytest.mark.parametrize("null", ["empirical", "gumbel"])
@pytest.mark.parametrize("seed", [0, 1, 2])
def test_expected_spikes_is_the_sum_over_pixels(seed, null):
    """The sorted-prefix form of ``E(e) = sum_i S(max(e, r_i))`` against the sum itself
    (ties included: the noise and returns drawn on a grid of values), ``S`` the samples' own
    survival function or SciPy's Gumbel law at the quartiles' location and scale."""
    from scipy.stats import gumbel_r

    rng = np.random.default_rng(seed)
    noise = rng.integers(0, 30, 200) / 10
    r = rng.integers(0, 60, 200) / 10
    e = np.sort(rng.integers(0, 50, 17) / 10)[::-1]
    if null == "empirical":
        def sf(v):
            return np.mean(noise[None, :] >= v[:, None], axis=1)
    else:
        q25, q75 = np.quantile(noise, [0.25, 0.75])
        scale = (q75 - q25) / (np.log(np.log(4)) - np.log(np.log(4 / 3)))
        loc = q25 + np.log(np.log(4)) * scale

        def sf(v):
            return gumbel_r.sf(v, loc=loc, scale=scale)

    want = [sf(np.maximum(ek, r)).sum() for ek in e]
    np.testing.assert_allclose(expected_spikes(noise, r, e, null=null), want, rtol=1e-9,
                               atol=1e-12)


def test_the_gumbel_null_is_fitted_to_the_quartiles_and_ignores_the_dots_tail():
    """On maxima drawn from a Gumbel law (200 000, loc 2, scale 0.5) the fit is within 5 %
    of SciPy's law at 4 and 6 (its survival function there); with a tenth of the samples
    replaced by dots at 6, the empirical survival at 6 is 0.1 (every dot counted as noise)
    and the fitted one under 0.01 (1.8e-3: the upper quartile moves with the dots)."""
    from scipy.stats import gumbel_r

    rng = np.random.default_rng(7)
    m = rng.gumbel(2.0, 0.5, 200_000)
    at = np.array([4.0, 6.0])
    law = gumbel_r.sf(at, loc=2.0, scale=0.5)
    np.testing.assert_allclose(expected_spikes(m, [0.0], at), law, rtol=0.05)
    dotted = m.copy()
    dotted[:20_000] = 6.0
    assert expected_spikes(dotted, [0.0], [6.0], null="empirical")[0] == pytest.approx(
        0.1, abs=1e-3)  # (the law's own samples above 6 besides: 3.4e-4)
    assert expected_spikes(dotted, [0.0], [6.0])[0] < 0.01  # (5 times the law's: the
    # upper quartile moves up with the dots, and the scale with it)
    with pytest.raises(ValueError, match="null must be"):
        expected_spikes(m, [1.0], [1.0], null="normal")


def _dotted(n_dots, dot, wall, noise_sd, seed=0, shape=(24, 24)):
    """A wall at slice WALL of evidence ``wall`` with noise (half-normal maxima around 1),
    ``n_dots`` isolated pixels whose argmax is DOT at ``dot`` with the wall's spread at
    ``0.8 dot`` there, labelled the wall (as the MRF gives them)."""
    rng = np.random.default_rng(seed)
    q = shape[0] * shape[1]
    z = np.abs(rng.normal(0, noise_sd, (q, K)))
    z[:, WALL] += wall
    # dots on a lattice 3 pixels apart: no two are 4-neighbours
    grid = [(y, x) for y in range(1, shape[0], 3) for x in range(1, shape[1], 3)]
    idx = [y * shape[1] + x for y, x in grid[:n_dots]]
    z[idx, WALL] = 0.8 * dot
    z[idx, DOT] = dot
    a = np.argmax(z, axis=1)
    label = np.full(q, WALL)
    nu = float(np.median(np.max(np.where(np.abs(np.arange(K) - a[:, None]) > 2, z, 0), 1)))
    return z, a, label, nu, np.array(idx), shape


def test_many_weak_dots_over_a_bright_wall_are_kept_one_is_not():
    """Dots at 2.5 noise maxima (below DOT_LEVEL) on a wall whose returns stand far above
    the noise: noise cannot give that many, so they are kept; one alone is not (an isolated
    spike is kept by no count of one: WEAK_DOT_COUNT)."""
    z, a, label, nu, idx, shape = _dotted(20, 0.0, 8.0, 0.4)
    z[idx, DOT] = 2.5 * nu
    z[idx, WALL] = 2.0 * nu
    a = np.argmax(z, axis=1)
    assert np.all(a[idx] == DOT)
    assert 2.5 < DOT_LEVEL
    keep = weak_dots(a, label, z, nu, shape)
    assert set(np.nonzero(keep)[0]) == set(idx.tolist())
    out, kept = keep_dots(a, label, z, nu, shape)
    assert kept == 20 and np.all(out[idx] == DOT)
    assert WEAK_DOT_COUNT == 5  # (chosen: with one, the street kept a single spike)
    few = idx[:4]
    z2 = z.copy()
    z2[idx[4:], DOT] = 0.0
    z2[idx[4:], WALL] = 8.0
    a2 = np.argmax(z2, axis=1)
    assert np.all(a2[few] == DOT)
    assert not weak_dots(a2, label, z2, nu, shape).any()
    # nor are they where each holds more evidence at the label than at its argmax (the
    # argmax reads the raw profile, so it can differ from the evidence's tallest slice)
    z3 = z.copy()
    z3[idx, WALL] = 3.0 * nu
    assert not weak_dots(a, label, z3, nu, shape).any()


@pytest.mark.parametrize("how", ["near the label", "three pixels"])
def test_weak_returns_by_the_surface_or_in_groups_are_no_dots(how):
    """Returns within two slices of the label are the surface's own (a slanted surface's
    next slice: a review made 275 such pixels "dots" on a surface sloping two slices a pixel),
    and a group of three is a region: neither is a weaker dot, however many."""
    z, a, label, nu, idx, shape = _dotted(20, 0.0, 8.0, 0.4)
    z[idx, WALL] = 2.0 * nu
    if how == "near the label":
        z[idx, WALL + 2] = 2.5 * nu
    else:
        for i in idx:  # each dot with the pixels above and below it, alike
            line = [i - shape[1], i, i + shape[1]]
            z[line, DOT] = 2.5 * nu
            z[line, WALL] = 2.0 * nu
    a = np.argmax(z, axis=1)
    assert np.all(a[idx] != WALL)
    assert not weak_dots(a, label, z, nu, shape).any()


@pytest.mark.parametrize("level, kept", [(2.5, True), (1.8, False)])
def test_dots_on_a_dark_wall_are_kept_where_they_stand_above_its_noise(level, kept):
    """A dark wall whose returns are at the noise's level: 20 dots at 2.5 noise maxima (five
    of the noise's deviations, which none of its maxima reach) are kept and nothing else; at
    1.8, among the noise's own maxima, none. (With the samples' own survival function, the
    dots counted as noise above themselves and none was kept at any level: a review.)"""
    z, a, label, nu, idx, shape = _dotted(20, 0.0, 0.6, 0.4, seed=1)
    z[idx, DOT] = level * nu
    z[idx, WALL] = 0.8 * level * nu
    a = np.argmax(z, axis=1)
    keep = weak_dots(a, label, z, nu, shape)
    assert set(np.nonzero(keep)[0]) <= set(idx.tolist())  # never the noise's argmaxes
    assert (keep[idx].sum() >= 15) if kept else not keep.any()


def test_a_dotted_scene_with_a_dark_part_keeps_its_dots_and_noise_keeps_none():
    """A bright wall a quarter of which is dark, with 100 dots at 4 noise maxima: kept, with
    at most DOT_FDR of what is kept the noise's own (with the samples' own survival function
    a dark strip of a fifth kept none of 100 or 200: a review); pure noise keeps none."""
    shape = (40, 40)
    rng = np.random.default_rng(2)
    q = shape[0] * shape[1]
    z = np.abs(rng.normal(0, 0.4, (q, K)))
    z[:, WALL] += np.where(np.arange(q) < q // 4, 0.6, 8.0)
    idx = rng.choice(np.arange(q // 4, q), 100, replace=False)
    label = np.full(q, WALL)
    a = np.argmax(z, axis=1)
    nu = float(np.median(np.max(np.where(np.abs(np.arange(K) - a[:, None]) > 2, z, 0), 1)))
    z[idx, DOT] = 4.0 * nu
    z[idx, WALL] = 3.0 * nu
    a = np.argmax(z, axis=1)
    lone = argmax_groups(a, shape) <= DOT_SIZE
    keep = weak_dots(a, label, z, nu, shape)
    assert lone[idx].sum() >= 80 and keep[idx[lone[idx]]].all()
    # the noise's argmaxes in the dark part kept beside them: a false-discovery rate, at most
    # DOT_FDR of those kept (here 8 of 93, at 1.5-1.7 noise maxima)
    false = keep.copy()
    false[idx] = False
    assert false.sum() <= DOT_FDR * keep.sum()
    noise = np.abs(rng.normal(0, 0.4, (q, K)))
    a = np.argmax(noise, axis=1)
    assert not weak_dots(a, np.full(q, WALL), noise, nu, shape).any()


@pytest.mark.parametrize("expected, count, kept", [
    ([0, 0, 0, 5, 5, 5, 5, 5, 5, 5], 5, 0),  # three pass, fewer than the count
    ([0, 0, 0, 5, 5, 5, 5, 5, 5, 5], 1, 3),
    ([0, 0, 0, 0, 0, 0, 10, 10, 10, 10], 5, 6),  # the cut in the middle of the list
    ([0, 9, 0, 0, 0, 0, 0.5, 10, 10, 10], 5, 7),  # step-up: the largest k that passes
])
def test_the_cut_is_benjamini_hochbergs_step_up(monkeypatch, expected, count, kept):
    """The procedure itself, with the expected counts given: the ``k`` strongest are kept
    for the largest ``k >= count`` with ``E(e_k) <= DOT_FDR k`` (0.2 here), whatever the
    ``E`` of the ranks before it."""
    import spslidar.depth.dots as dots

    assert DOT_FDR == 0.2
    z, a, label, nu, idx, shape = _dotted(10, 0.0, 8.0, 0.4)
    z[idx, DOT] = np.linspace(5.0, 2.0, 10) * nu  # ten candidates, strongest first
    z[idx, WALL] = 1.5 * nu
    a = np.argmax(z, axis=1)
    monkeypatch.setattr(dots, "expected_spikes",
                        lambda noise, r, e: np.asarray(expected, dtype=float)[:len(e)])
    keep = weak_dots(a, label, z, nu, shape, count=count)
    assert set(np.nonzero(keep)[0]) == set(idx[:kept].tolist())


def test_noise_maxima_in_blocks_and_about_a_given_centre(monkeypatch):
    """The blocked form of the noise maxima is the one-pass form, about each pixel's tallest
    slice or about a given centre (the dot step's label), at any block size."""
    import spslidar.depth.profile as profile

    rng = np.random.default_rng(4)
    z = rng.normal(size=(301, 23))
    centre = rng.integers(0, 23, 301)

    def plain(c):
        far = np.abs(np.arange(23)[None, :] - c[:, None]) > 2
        return np.max(np.where(far, z, 0.0), axis=1)

    for entries in (profile.NOISE_BLOCK_ENTRIES, 100, 23, 1):
        monkeypatch.setattr(profile, "NOISE_BLOCK_ENTRIES", entries)
        np.testing.assert_array_equal(profile.noise_maxima(z), plain(np.argmax(z, axis=1)))
        np.testing.assert_array_equal(profile.noise_maxima(z, 2, centre=centre), plain(centre))


def test_expected_spikes_refuses_what_it_cannot_count():
    with pytest.raises(ValueError, match="at least one noise sample"):
        expected_spikes([], [1.0], [1.0])
    with pytest.raises(ValueError, match="finite"):
        expected_spikes([1.0], [np.nan, 1.0], [1.0])
