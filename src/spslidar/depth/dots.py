"""One- and two-pixel objects: a strong return that no neighbour shares, kept against the
MRF (the MRF's last step).

The MRF's smoothness makes a pixel whose depth differs from all four neighbours pay the
truncation ``T`` four times (about two noise maxima, :func:`~.mrf.auto_truncation`), and the
per-slice TV of the reconstruction (eq. 18) has already spread the surface around it into
its own profile: a bright wall's slice holds, at a one-pixel dot surrounded by that wall,
most of the dot's own evidence. So a dot whose return stands far above any noise maximum is
still given the wall. The line rules (:mod:`.lines`) keep a dot only where it lines up with
others. Measured on a wall at 2 m with 10 % of its pixels at depths drawn from 1-3 m (not a
scene of the project's; 64 x 64, m_n 5 and 10, 25 % patterns, seeds 1-2): the MRF overrode
56-73 pixels per measurement that argmax had right, at 6.6-15 noise maxima each, and was
1.12-1.37 times argmax's RMSE.

:func:`keep_dots` keeps a pixel's argmax where the MRF moved it, its argmax belongs to a
group of at most :data:`DOT_SIZE` pixels (4-neighbours joined where their argmax slices are
within one of each other: the line rules' grouping, :func:`.lines._groups`, a
connected-components pass of :mod:`scipy.sparse.csgraph`), its evidence there reaches
:data:`DOT_LEVEL` times the block's median noise maximum ``nu``, and it is at least the
pixel's evidence at the MRF's label (the pixel's own profile prefers it). Half of the
profiles' noise maxima are below ``nu``, so a dot stands six times above the typical one; a
halo of a bright neighbour is at that neighbour's slice, so it is part of the neighbour's
group, not a dot. The rule reads the evidence only: no library models the per-slice TV's
spread around a dot.

Chosen on 2026-12-02 (``benchmarks/depth_quality.py``'s cached slices; 64 x 64, m_n 5 and
10, 25 and 50 % patterns) among group sizes 1-3, levels 2, 3, 4, 6 and 8 (of ``nu``, and of
the median noise maximum more than 8 slices from each tallest return) and three tests
against the label (none; the evidence at the label; the same halo-discounted), on two scenes
that are not the project's (the dots above and a text image at 1.5 / 2.5 m whose letters'
1-2 pixel pieces the MRF gave the wall behind; seeds 1-2), the seven built-in scenes at m_n
1, 5 and 10 (seed 0) and procedural seeds 150-174. On those, against the MRF without this
step: the two outside scenes from 10 of 16 measurements more than 5 % worse than argmax
(median ratio 1.097, worst 1.371) to 2 (median 0.999, worst 1.059, the text at m_n = 10,
25 %); the built-ins and procedural seeds unchanged within 0.4 %. Without the test against
the label the camera at m_n = 5, 25 % lost a pixel to a 6.5 ``nu`` spike beside its own
surface's 8.4 (1.23 times the MRF); at level 3 the street at m_n = 1, 50 % lost 3.1 times, at
2 the room 7-12 times.

Held out: procedural seeds 100-124 (100 measurements) unchanged (at level 4 seed 112 lost
27 %); four more outside scenes (32 measurements: a slanted floor with 3 % dark and bright
dots in front, 2 x 2 blobs on a wall, dark dots in front of a bright wall, a photograph of
coins as depth) unchanged but for 3 measurements better by 0.2-1.1 %: their dots are 1-4
``nu``, below any level the built-ins allow (the weaker dots' step below took them up).

*Weaker dots* (:func:`weak_dots`, the same day): no one level tells a dot of 1.5-6 ``nu`` from
a spike. The Benjamini-Hochberg procedure at a false-discovery rate of :data:`DOT_FDR` keeps at
least :data:`WEAK_DOT_COUNT` of them together against the expected count of the noise's
argmaxes, its null a Gumbel law fitted to the noise maxima's quartiles (their own survival
function counted the dots as noise: a review). ``guarded`` and ``evidence`` share the step
through :meth:`~.mrf.MRFDepth.labelling` (not measured apart). Chosen (rate 0.05 / 0.1 / 0.2,
least evidence 1.5 / 2 ``nu``, fewest 1 / 3 / 5, on the empirical null) on six outside scenes
written again for it (the dotted wall, the text, dots before a slanted floor, 2 x 2 blobs, dark
dots, the coins; 48 measurements), the built-ins (42) and procedural seeds 150-174 (100): with
the Gumbel null the outside ones from 16 to 9 more than 5 % worse than argmax (worst 2.20 ->
1.39; 19 better, none worse), the rest unchanged. Held out: four more outside scenes (dots
before a wall slanted across the image, a floor and wall with dark dots and pairs, bright dots
before a dark wall, a ramp with dots; 32 measurements) from 19 to 18 (worst 7.22 -> 2.95,
median 1.33 -> 1.09; 17 better, none worse); procedural seeds 100-124 and 175-199, the
built-ins at 32 x 32 and 128 x 128 unchanged. The slanted wall's dots below 1.5 ``nu`` are
still given the wall.
"""

from __future__ import annotations

import numpy as np

from .profile import noise_maxima

__all__ = ["DOT_FDR", "DOT_LEVEL", "DOT_SIZE", "WEAK_DOT_COUNT", "WEAK_DOT_LEVEL",
           "argmax_groups", "expected_spikes", "keep_dots", "step_up", "weak_dots"]

#: the most pixels a group of argmax returns may hold and still be a dot
DOT_SIZE = 2
#: the least evidence of a dot, in median noise maxima
DOT_LEVEL = 6.0
#: the false-discovery rate at which weaker dots are kept together (:func:`weak_dots`)
DOT_FDR = 0.2
#: the least evidence of a weaker dot, in median noise maxima
WEAK_DOT_LEVEL = 1.5
#: the fewest weaker dots kept at once: a scene of dots holds many, one is no evidence
WEAK_DOT_COUNT = 5
#: a Gumbel law's interquartile range in scales, ``ln(ln 4) - ln(ln(4/3))``, and its lower
#: quartile's distance below the location, ``-ln(ln 4)`` (:func:`expected_spikes`)
GUMBEL_IQR = float(np.log(np.log(4.0)) - np.log(np.log(4.0 / 3.0)))
GUMBEL_Q25 = float(np.log(np.log(4.0)))


def argmax_groups(a: np.ndarray, shape: tuple[int, int]) -> np.ndarray:
    """Per pixel, the size of its group: the pixels joined to it through 4-neighbours whose
    slices ``a`` differ by at most one.

    Parameters
    ----------
    a : ndarray of int, shape (Q,)
        Each pixel's slice (row-major over ``shape``).
    shape : tuple of int
        ``(N1, N2)``, with ``N1 * N2 == Q``.

    Returns
    -------
    ndarray of int, shape (Q,)
    """
    from .lines import _groups

    _, group, _ = _groups(np.ones(len(a), dtype=bool), np.asarray(a), shape, step=1,
                          diagonals=False)
    return np.bincount(group)[group]


def keep_dots(a: np.ndarray, label: np.ndarray, z: np.ndarray, nu: float,
              shape: tuple[int, int], size: int = DOT_SIZE, level: float = DOT_LEVEL
              ) -> tuple[np.ndarray, int]:
    """The labels with each dot's argmax kept (see the module docstring).

    Parameters
    ----------
    a : ndarray of int, shape (Q,)
        Each pixel's argmax slice.
    label : ndarray of int, shape (Q,)
        The MRF's labels so far.
    z : ndarray, shape (Q, K)
        Evidence (the pulse-matched profile in noise units).
    nu : float
        The block's median noise maximum.
    shape : tuple of int
        ``(N1, N2)``.
    size, level : int, float
        :data:`DOT_SIZE`, :data:`DOT_LEVEL`.

    Returns
    -------
    label : ndarray of int, shape (Q,)
        A new array.
    kept : int
        How many pixels were given their argmax.
    """
    rows = np.arange(label.size)
    za = z[rows, a]
    moved = (label != a) & (za >= level * nu) & (za >= z[rows, label])
    # (the grouping only where a dot moved: it ran on every MRF call, most with none; the
    # weaker dots' step groups its own candidates where there are enough of them)
    groups = argmax_groups(a, shape) if moved.any() else None
    keep = moved & (groups <= size) if groups is not None else moved
    label = np.where(keep, a, label)
    weak = weak_dots(a, label, z, nu, shape, size, groups=groups)
    return np.where(weak, a, label), int(keep.sum() + weak.sum())


def weak_dots(a: np.ndarray, label: np.ndarray, z: np.ndarray, nu: float,
              shape: tuple[int, int], size: int = DOT_SIZE, fdr: float = DOT_FDR,
              level: float = WEAK_DOT_LEVEL, count: int = WEAK_DOT_COUNT,
              exclude: int = 2, groups: np.ndarray | None = None) -> np.ndarray:
    """Which dots below :data:`DOT_LEVEL` to keep: the Benjamini-Hochberg procedure over
    the candidates' evidence against the profiles' own noise maxima.

    A candidate is a pixel whose argmax lies more than ``exclude`` slices from its label, in
    a group of at most ``size`` pixels (:func:`argmax_groups`), at ``level`` noise maxima or
    more and at least its evidence at the label. A pixel whose return has evidence ``r`` (at
    its label) shows a spike of ``e`` or more as its argmax only where its noise maximum ``M``
    reaches ``max(e, r)``, so noise is expected to give ``E(e) = sum_i S(max(e, r_i))`` such
    pixels (:func:`expected_spikes`; ``S`` the survival function of ``M``, sampled per pixel
    more than ``exclude`` slices from its label). The candidates sorted by evidence, the
    ``k`` strongest are kept for the largest ``k >= count`` with ``E(e_k) <= fdr * k``.

    The null (a review of 2026-12-02): the sample of ``M`` holds each candidate's own return
    (more than ``exclude`` slices from its label, as a spike is; leaving the candidates out of
    it leaves out the very spikes it is to count, and on a dark wall of noise it then
    expected none and kept 42 noise argmaxes). Read as its own survival function it counts
    every dot as noise above itself, ``E(e_k) >= k W(e_k) / Q`` (``W`` the pixels whose label
    holds less than ``e_k``, the dots among them): dots were kept only where fewer than a
    fifth of the pixels return more weakly, and a bright wall with a dark strip over 19 % of
    the image kept 20 dots at 4 noise maxima and none of 100 or 200. ``S`` is therefore a
    Gumbel law (a maximum's) fitted to the sample's quartiles, which the dots move little
    (:func:`expected_spikes`): a bright wall a quarter of which is dark keeps its 100 dots
    (with the noise's argmaxes beside them at most at the rate: 8 of 93), pure noise none.

    Not one per-pixel test: on the built-ins the candidates the MRF rightly overrode stand
    at 1.5-2.1 noise maxima and 1.1-2.2 times their labels' evidence (10-90 %), the outside
    scenes' dots it wrongly did at 1.8-5.1 and 1.1-2.9. Not a count of one
    (:data:`WEAK_DOT_COUNT`): with one, and the noise maxima read away from the argmax too,
    the street at m_n = 1, 50 % kept a single spike at 3.4 noise maxima beside its wall's 2.8
    (0.0044 -> 0.0146 m). SciPy's ``false_discovery_control`` takes one p-value per test;
    here what noise is expected to give at a level depends on every pixel's return, so the
    step-up is written over the expected count itself.

    Parameters
    ----------
    a, label : ndarray of int, shape (Q,)
        Each pixel's argmax slice; the labels so far.
    z : ndarray, shape (Q, K)
        Evidence (noise units).
    nu : float
        The block's median noise maximum.
    shape : tuple of int
        ``(N1, N2)``.
    size, fdr, level, count : int, float, float, int
        :data:`DOT_SIZE`, :data:`DOT_FDR`, :data:`WEAK_DOT_LEVEL` (in ``nu``),
        :data:`WEAK_DOT_COUNT`.
    exclude : int
        Slices either side of the label that belong to its surface.
    groups : ndarray of int, shape (Q,), optional
        :func:`argmax_groups` of ``a``, where the caller has it.

    Returns
    -------
    ndarray of bool, shape (Q,)
        The pixels to give their argmax.
    """
    q, k = z.shape
    rows = np.arange(q)
    za, r = z[rows, a], z[rows, label]
    cand = (np.abs(a - label) > exclude) & (za >= level * nu) & (za >= r)
    keep = np.zeros(q, dtype=bool)
    if np.count_nonzero(cand) < count:
        return keep
    cand &= (argmax_groups(a, shape) if groups is None else groups) <= size
    if np.count_nonzero(cand) < count:
        return keep
    return step_up(za, cand, noise_maxima(z, exclude, centre=label), r, fdr, count)


def step_up(za: np.ndarray, cand: np.ndarray, noise: np.ndarray, r: np.ndarray,
            fdr: float, count: int = 1) -> np.ndarray:
    """The Benjamini-Hochberg step-up over candidates' evidence against the noise's expected
    argmaxes: the candidates sorted by evidence ``e_1 >= e_2 >= ...``, the ``k`` strongest
    kept for the largest ``k >= count`` with ``E(e_k) <= fdr * k``
    (:func:`expected_spikes` over the noise maxima ``noise`` and the returns ``r``).

    Parameters
    ----------
    za : ndarray, shape (Q,)
        Each pixel's evidence at its argmax.
    cand : ndarray of bool, shape (Q,)
        The candidates (at least one).
    noise, r : ndarray
        As :func:`expected_spikes`' ``noise`` and ``r``.
    fdr : float
        The false-discovery rate.
    count : int
        The fewest candidates kept together.

    Returns
    -------
    ndarray of bool, shape (Q,)
    """
    e = np.sort(za[cand])[::-1]
    expected = expected_spikes(noise, r, e)
    ranks = np.arange(1, e.size + 1)
    ok = np.nonzero((expected <= fdr * ranks) & (ranks >= count))[0]
    if not ok.size:
        return np.zeros(za.shape, dtype=bool)
    return cand & (za >= e[ok[-1]])


def expected_spikes(noise: np.ndarray, r: np.ndarray, e: np.ndarray,
                    null: str = "gumbel") -> np.ndarray:
    """``E(e) = sum_i S(max(e, r_i))`` for each of ``e``: how many pixels noise is expected
    to give an argmax of ``e`` or more over their returns ``r``, in ``O((Q + C) log Q)``:
    the pixels with ``r >= e`` add their own ``S(r)`` (a prefix sum over ``r`` sorted), the
    rest ``S(e)`` each.

    Parameters
    ----------
    noise : array_like, shape (P,)
        Samples of a profile's noise maximum ``M``, at least one, finite.
    r : array_like, shape (Q,)
        Each pixel's return evidence, finite.
    e : array_like, shape (C,)
        The evidence levels.
    null : {"gumbel", "empirical"}
        ``S(v) = P(M >= v)``: a Gumbel law (the law of a maximum) fitted to the samples'
        quartiles, or the samples' own survival function. The samples hold the dots' own
        returns too (more than two slices from their labels, as a spike is): the empirical
        ``S`` then counts each dot as noise above its own evidence, so ``E(e_k) >= k W(e_k)
        / Q`` (``W`` the pixels whose return is under ``e_k``) and a scene a fifth of which
        is dark, or dotted, kept none (a review of 2026-12-02). Their quartiles move little
        with a tenth of them dots, and the Gumbel tail above them does not count the dots.
        Fitted by quartiles, not by maximum likelihood (``scipy.stats.gumbel_r.fit``), which
        the dots' tail pulls; the survival function is one line, so ``scipy.stats`` (a third
        of a second to import) is not imported for it.

    Returns
    -------
    ndarray, shape (C,)
    """
    null_s = np.sort(np.asarray(noise, dtype=np.float64).ravel())
    r = np.asarray(r, dtype=np.float64).ravel()
    e = np.asarray(e, dtype=np.float64).ravel()
    if not null_s.size or not (np.all(np.isfinite(null_s)) and np.all(np.isfinite(r))
                               and np.all(np.isfinite(e))):
        # (an empty sample was 0/0; a NaN in r sorted first and broke the search: a review)
        raise ValueError("expected_spikes needs at least one noise sample, and finite noise, "
                         "returns and levels")
    if null not in ("gumbel", "empirical"):
        raise ValueError(f"null must be 'gumbel' or 'empirical', got {null!r}")
    q = null_s.size
    if null == "empirical":
        def survival(v: np.ndarray) -> np.ndarray:
            return (q - np.searchsorted(null_s, v, side="left")) / q
    else:
        # Gumbel quantiles: mu - beta ln(-ln p); the quartiles are 1.5725 beta apart
        q25, q75 = np.quantile(null_s, [0.25, 0.75])
        beta = (q75 - q25) / GUMBEL_IQR
        mu = q25 + GUMBEL_Q25 * beta

        def survival(v: np.ndarray) -> np.ndarray:
            if not beta > 0:  # (no spread: every maximum the same)
                return np.where(v > mu, 0.0, 1.0)
            return -np.expm1(-np.exp(-(v - mu) / beta))

    r_desc = np.sort(r)[::-1]
    head = np.concatenate([[0.0], np.cumsum(survival(r_desc))])
    above = np.searchsorted(-r_desc, -e, side="right")  # how many r >= e
    return head[above] + (r_desc.size - above) * survival(e)
