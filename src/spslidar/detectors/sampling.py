"""Detection counts of a free-running GMAPD drawn detection by detection, with the
correlations its dead time makes (:meth:`spslidar.detectors.gmapd.GMAPD.detect`).

Drawing each bin on its own (``Binomial(n, q_t)``) has the right mean and per-bin variance,
but not the dead time's correlations: a real detector records at most one photon per dead
time, so the counts in any dead-time window of a period add up to nearly the same number
every time. The pile-up correction (eq. D7 of ``docs/model.md``) divides each bin by the armed
fraction that window's counts estimate, so independent draws feed it a far noisier armed
fraction than a real detector's (an audit of 2026-11-29, against a photon-by-photon
simulation, 100 periods: at 3.5 photons per dead time the corrected matched-filter peak came
out 45 % high with 4 times the spread, at 10 photons 49 % low).

Here each row's detections are drawn in time order as the renewal process they are: from
the time ``a`` the detector re-arms, the next avalanche is the first event of a Poisson
process of the row's periodic flux ``mu`` (photons after efficiency and jitter, plus dark
counts), found by inverting its integral ``Lambda(t') - Lambda(a) = E``, ``E ~ Exp(1)``, the
flux uniform within each (sub-)bin; an avalanche fills an afterpulse trap with probability
``P``, which empties ``Exp(tau)`` after re-arming and is detected if no photon came first.
The cost is one step per detection, whatever the number of photons (vectorised over the rows;
numpy's ``searchsorted`` does the inversion).

Beyond :data:`EXACT_DETECTIONS` detections per row (long dwells: 10^5 code periods are
millions), ``m`` periods are drawn so and the ``n`` periods' counts are their mean plus their
fluctuation scaled by ``sqrt(n / m)``: the sum of ``n`` periods has about ``n / m`` times the
covariance of ``m`` of them (central limit), the dead time's correlations included, when the
``m`` periods hold many detections and span many dead times (:data:`SCALED_DEAD_TIMES`), so
that the correlations across their two ends are a small part (an audit of 2026-11-29: ``m``
spanning 11 dead times gave the total's variance 1.8 times the exact, 1 dead time 6 times;
at the default, within 17 % of a variance 1/9000 of Poisson's); those counts are not whole numbers
(rounding them biased the mean or swamped the variance the dead time holds low). No library
samples this process (it is the reference :func:`~spslidar.detectors.events.simulate_events`
without its photon-by-photon cost).
"""

from __future__ import annotations

import numpy as np

__all__ = ["EXACT_DETECTIONS", "SCALED_DEAD_TIMES", "renewal_counts"]

#: largest expected detections per row drawn one by one over the whole dwell (one step per
#: detection, about 20 us for a block of 64 rows, so 0.1 s a block); beyond it the dwell is
#: scaled from fewer periods
EXACT_DETECTIONS = 5_000
#: periods the detector runs before a pattern's are counted, in dead times at least
WARMUP_DEAD_TIMES = 20
#: the periods a long dwell is scaled from span at least this many dead times
SCALED_DEAD_TIMES = 200


def _draw(mu: np.ndarray, dead: float, n_periods: int, prob: float, delay: float,
          rng: np.random.Generator) -> np.ndarray:
    """Detections per sub-bin over ``n_periods`` periods, drawn one by one per row.

    ``mu`` (B, S) events per sub-bin per period, ``dead`` and ``delay`` in sub-bins.
    """
    n_rows, span = mu.shape
    stride = span + 1
    cum = np.zeros((n_rows, stride))
    np.cumsum(mu, axis=1, out=cum[:, 1:])
    total = cum[:, -1].copy()
    rows = np.flatnonzero(total > 0)
    if rows.size == 0:
        return np.zeros((n_rows, span), dtype=np.int64)
    # one increasing array over the rows, for one searchsorted: row r's integral offset past
    # the row before it
    gap = np.concatenate(([0.0], np.cumsum(total + 1.0)[:-1]))
    flat = (cum + gap[:, None]).ravel()
    rate = np.zeros((n_rows, stride))
    rate[:, :span] = mu
    rate = rate.ravel()
    end = float(n_periods) * span
    warm = np.ceil(max(span, WARMUP_DEAD_TIMES * dead) / span) * span
    base, tot, off = rows * stride, total[rows], gap[rows]
    # each row armed at a random phase of the period: armed at a period boundary, a detector
    # that fires nearly periodically (many photons per dead time) had not forgotten that
    # phase after the warm-up, and a dwell of a few periods came out 20 % off the stationary
    # histogram in its worst bin (chi^2/dof 27; 1.4 with a random phase: an outside audit
    # against an event-level reference, 2026-11-29)
    armed = -warm - span * rng.random(rows.size)
    trap = np.zeros(rows.size, dtype=bool)
    hits = []
    while rows.size:
        # the integral of the flux up to the re-arming time, then the next avalanche
        k = np.floor(armed / span)
        u = armed - k * span
        i = base + np.minimum(u.astype(np.int64), span - 1)
        target = (k * tot + flat[i] - off + (u - (i - base)) * rate[i]
                  + rng.standard_exponential(rows.size))
        k = np.floor(target / tot)
        rem = target - k * tot + off
        j = np.minimum(np.searchsorted(flat, rem, side="right") - 1, base + span - 1)
        frac = np.clip((rem - flat[j]) / np.maximum(rate[j], 1e-300), 0.0, 1.0)
        t = k * span + (j - base) + frac
        if prob:
            ap = armed + rng.exponential(delay, rows.size)
            t = np.where(trap & (ap < t), ap, t)
            trap = rng.random(rows.size) < prob
        seen = t >= 0
        keep = t < end
        hits.append(base[seen & keep] // stride * span
                    + np.floor(t[seen & keep]).astype(np.int64) % span)
        if not keep.all():
            rows, base, tot, off = rows[keep], base[keep], tot[keep], off[keep]
            t, trap = t[keep], trap[keep]
        armed = t + dead
    return np.bincount(np.concatenate(hits), minlength=n_rows * span).reshape(n_rows, span)


def renewal_counts(mu: np.ndarray, dead_bins: float, n_periods: int, expected: np.ndarray,
                   rng: np.random.Generator, afterpulse_prob: float = 0.0,
                   afterpulse_delay_bins: float = 0.0, sub: int = 1) -> np.ndarray:
    """Detections per bin over ``n_periods`` periods of a free-running, non-paralysable GMAPD
    (see the module docstring).

    Parameters
    ----------
    mu : ndarray, shape (B, L * sub)
        Avalanche-causing events per sub-bin per period (after efficiency and jitter, dark
        counts included): :meth:`~spslidar.detectors.gmapd.GMAPD.flux`.
    dead_bins : float
        Dead time in sub-bins, at least 1.
    n_periods : int
        Code periods of the dwell.
    expected : ndarray, shape (B, L)
        Mean detections per bin over the dwell (the renewal model's), which sets the number
        of steps and, for long dwells, the mean the scaled fluctuation is added to.
    rng : numpy.random.Generator
    afterpulse_prob : float
        Trap-filling probability per avalanche.
    afterpulse_delay_bins : float
        Mean trap release after re-arming, in sub-bins.
    sub : int
        Sub-bins per TDC bin.

    Returns
    -------
    ndarray of float64, shape (B, L)
        Counts, non-negative (whole numbers unless the dwell was scaled).
    """
    mu = np.atleast_2d(np.asarray(mu, dtype=np.float64))
    expected = np.atleast_2d(np.asarray(expected, dtype=np.float64))
    n_rows, fine = mu.shape
    period = fine // sub

    def draw(rows: np.ndarray, periods: int) -> np.ndarray:
        counts = _draw(mu[rows], float(dead_bins), periods, float(afterpulse_prob),
                       float(afterpulse_delay_bins), rng)
        return counts.reshape(-1, period, sub).sum(axis=2)

    per_row = expected.sum(axis=1)
    # each row drawn exactly where its own detections allow (a dim row beside a bright one
    # was scaled with it, an audit): the scaled rows apart
    long = per_row > EXACT_DETECTIONS
    # and the periods drawn span many dead times, so their ends' correlations are a small
    # part (an audit: 8 periods spanning one dead time gave the total's variance 6 times the
    # exact; 89 spanning 11, 1.8 times)
    m = max(1, int(n_periods * EXACT_DETECTIONS / per_row.max(initial=1.0)),
            int(np.ceil(SCALED_DEAD_TIMES * float(dead_bins) / fine)))
    if m >= n_periods:
        long[:] = False
    out = np.empty((n_rows, period))
    if (~long).any():
        out[~long] = draw(~long, int(n_periods))
    if long.any():
        e = expected[long]
        drawn = draw(long, m)
        scaled = e + (drawn - e * (m / n_periods)) * np.sqrt(n_periods / m)
        # not rounded: np.rint of these lattice values lost 0.2 % of a row's counts, and
        # rounding at random added up to 1/4 per bin to a variance the dead time holds far
        # below that (a row's total, 45 over 200 bins, read 78); never below 0 (at d = 0 it
        # is expected * (1 - sqrt(m / n)) > 0)
        out[long] = np.maximum(scaled, 0.0)
    return out
