"""Expected histogram of a free-running, non-paralysable GMAPD under a periodic flux, and its
inverse (pile-up / dead-time correction).

Units: everything here is per TDC bin and per code period (``L`` bins); times are in bins.

The renewal model
-----------------
A Geiger-mode APD that is *armed* detects the first photon (or dark count) to arrive; it is
then dead for ``D`` bins (non-paralysable: photons during the dead time are lost and do not
extend it), whatever the code period. With ``alpha(x)`` the probability that the detector is
armed at time ``x`` and ``mu(x)`` the photon rate (photons per bin), the detection density is
``rho(x) = mu(x) alpha(x)`` (Poisson photons are independent of the detector's past), and the
detector is dead iff it detected during the last ``D`` bins, so in the stationary regime

.. math:: \\alpha(x) = 1 - \\int_{x-D}^{x} \\rho(y)\\,dy, \\qquad
          \\alpha'(x) = -\\rho(x) + \\rho(x - D)                                  (R1)

(the second form: armed-ness is lost by detections and regained by re-arming). This is the
renewal formulation of the Markov chain of Rapp, Ma, Dawson & Goyal, "Dead time compensation
for high-flux ranging", IEEE Trans. Signal Process. 67(13), 2019 (their chain on the detection
positions modulo the period has the stationary law ``h / sum(h)`` below); it avoids the
``L x L`` transition matrix. For a constant flux it gives the classic non-paralysable count
rate ``mu / (1 + mu D)``.

Discretisation. The flux is constant within a bin (``mu_t``) and the re-arming inflow
``g_t = (1 - f) h_{t-d} + f h_{t-d-1}`` (``D = d + f``, ``d`` integer) is taken as uniform
within bin ``t``. (R1) is then solved exactly within each bin:

.. math:: \\alpha_{t+1} = e^{-\\mu_t}\\alpha_t + g_t\\,\\varphi(\\mu_t), \\qquad
          h_t = p_t\\,\\alpha_t + g_t\\,(1 - \\varphi(\\mu_t))                  (R2)

with ``p_t = 1 - exp(-mu_t)`` (the detection probability of a bin armed at its start) and
``phi(mu) = (1 - exp(-mu)) / mu``. Without the re-arm term this is the discrete model
``h_t = p_t a_t``, ``a_t = 1 - sum_{s=t-D}^{t-1} h_s`` of Rapp et al.; the ``g_t`` term is the
partially armed bin in which the detector re-arms (first order in the bin width; for a
constant flux the discrete model alone is off by ``mu / (2 (1 + mu D))``, (R2) by
``O(mu^2)``). ``alpha_t = 1 - W_t`` with ``W_t = sum_{s=t-d}^{t-1} h_s + f h_{t-d-1}`` holds
exactly along (R2), which is what makes the inverse (:func:`coates_correction`) exact.

Afterpulsing. Each avalanche fills a trap with probability ``P``; the trap empties at rate
``r = 1 / tau_ap`` (bins) *after the detector re-arms* and triggers an afterpulse if the
detector is still armed (a photon detection first discards it). With ``gamma`` the
probability of being armed with a full trap, ``gamma' = -(mu + r) gamma + P g`` and the
detection density is ``mu alpha + r gamma``. Both linear ODEs are solved exactly per bin (same
uniform-inflow assumption), which adds ``gamma`` as a second state to (R2): see
:func:`bin_map`. So afterpulsing is in the fixed point exactly, not to first order.

Solving the periodic fixed point. (R2) is a first-order linear recurrence in ``alpha`` (and
``gamma``) driven by ``h`` at lags ``>= d``: over a chunk of at most ``d`` bins the driving
term is known, and the recurrence is summed in closed form with cumulative sums of ``mu``
(no Python loop over bins). One *sweep* runs the chunks over one period (the unrolled time
evolution of the expectation, history of ``d + 1`` bins carried across period boundaries, so
``D`` longer or shorter than the period is the same code), or over ``ceil((d + 1) / L)``
periods where the dead time is longer than the period (the state is the ``d + 1``-bin history,
so the mixing below costs that much per sweep: paid once per dead time, not once per period);
sweeps repeat until the period's ``h`` stops changing, accelerated by Anderson mixing.
Vectorised over rows.

Jitter. The timing jitter (Gaussian, optionally plus an exponential tail) is applied to the
photon flux by a circular convolution with the bin-integrated IRF
(:func:`spslidar.detectors.jitter.jitter_kernel`, re-exported here) before detection (the dead
time acts on jittered avalanche times).

Nothing here is in a maintained library (SciPy gives the IRF's CDF and the FFT): published
codes (Rapp et al.) are MATLAB, synchronous (one detection per laser period) or build the
dense Markov matrix.
"""

from __future__ import annotations

import warnings

import numpy as np
from scipy import fft as sfft

from ..arrays import real_array, real_scalar
from ..errors import ConfigError
from ._renewal import (
    _Anderson,
    _chunks,
    _circular_window,
    _Coefficients,
    _invert_photon_map,
    _one_minus_phi,
    _periodic_scan,
    _phi,
    _Scan,
    _shifted_left,
)
from .base import check_periods
from .counting import check_rates
from .jitter import convolve_periodic, jitter_antiderivative, jitter_kernel

__all__ = [
    "auto_oversample",
    "bin_map",
    "coates_correction",
    "convolve_periodic",
    "jitter_antiderivative",
    "jitter_kernel",
    "renewal_detection",
    "sub_bin_profile",
]

#: auto_oversample keeps the flux per sub-bin below this (<~0.3 % error per bin)
SUB_BIN_FLUX = 0.15
#: most sub-bins per TDC bin chosen by auto_oversample
MAX_OVERSAMPLE = 16
#: a row of the fixed-point iteration whose residual grows past this many times its best
#: has diverged (Anderson mixing of nearly collinear residuals) and restarts
_DIVERGED = 1e3
#: a relative change of the period's detections below this at the sweep cap is round-off
#: (the chunked closed form's floor is about 1e-10 at 16383 bins), far below any count's noise:
#: no warning
_NEGLIGIBLE = 1e-7
#: sweeps of several periods each (a dead time longer than the period) before the fixed point
#: is sought one period a sweep (8-13 suffice at 1-10 photons per dead time, about 110 at
#: 150, where the detector nearly locks into a cycle but converges)
_COMPOSITE_SWEEPS = 150
#: sweeps without halving the worst row's best change, once it is below _FLOOR, that end the
#: iteration at the round-off floor (the inverse, near saturation, amplifies what is left by
#: up to ~1e3, so the floor is well below _NEGLIGIBLE)
_STALLED = 10
_FLOOR = 1e-9


def auto_oversample(mu_max: float, limit: int = MAX_OVERSAMPLE) -> int:
    """Sub-bins per TDC bin for the renewal model: ``ceil(mu_max / SUB_BIN_FLUX)`` in
    ``[1, limit]``.

    The bin-level model (R2) assumes uniform re-arming within a bin; its per-bin error grows
    like ``(mu / S)^1.5`` with the flux per (sub-)bin ``mu / S`` (measured against a 32-fold
    refined solution: about 3 % at ``mu = 0.5`` photon per bin and period with ``S = 1``,
    0.2 % with ``S = 4``). Realistic lidar fluxes stay well below 0.15 photon per 100 ps bin
    and period, hence ``S = 1``.
    """
    if not np.isfinite(mu_max) or mu_max <= SUB_BIN_FLUX:
        return 1
    return int(min(limit, np.ceil(mu_max / SUB_BIN_FLUX)))


# ------------------------------------------------------------------------------- the bin map


def bin_map(alpha0, gamma0, g, mu, afterpulse_prob: float = 0.0, afterpulse_rate: float = 0.0):
    """One bin of the renewal model, solved exactly for constant flux and re-arm inflow.

    Parameters
    ----------
    alpha0, gamma0 : ndarray
        Probability of being armed (``alpha``), and armed with a full trap (``gamma``), at the
        start of the bin.
    g : ndarray
        Probability of re-arming during the bin (uniform within it).
    mu : ndarray
        Mean photons (and dark counts) in the bin, per period.
    afterpulse_prob, afterpulse_rate : float
        ``P`` and ``r = 1 / tau_ap`` (per bin).

    Returns
    -------
    alpha1, gamma1, h : ndarray
        The states at the end of the bin and the detection probability in the bin.

    Notes
    -----
    With ``kappa = mu + r``, ``gamma_inf = P g / kappa``:
    ``gamma1 = gamma_inf + (gamma0 - gamma_inf) e^{-kappa}``,
    ``alpha1 = alpha0 e^{-mu} + (g - r gamma_inf) phi(mu) - (gamma0 - gamma_inf)
    (e^{-mu} - e^{-kappa})``, and ``h = alpha0 - alpha1 + g`` (R2 for ``P = 0``).
    """
    mu = np.asarray(mu, dtype=np.float64)
    p = -np.expm1(-mu)
    if afterpulse_prob == 0:
        return (np.exp(-mu) * alpha0 + g * _phi(mu), np.zeros_like(mu),
                p * alpha0 + g * _one_minus_phi(mu))
    c = _Coefficients(mu, afterpulse_prob, afterpulse_rate)
    gamma1 = gamma0 * c.ekap + g * c.coef_gamma
    h = p * alpha0 + g * c.hcoef_g + gamma0 * c.dexp
    return alpha0 - h + g, gamma1, h


# ------------------------------------------------------------------------------ forward model


def renewal_detection(mu: np.ndarray, dead_bins: float, afterpulse_prob: float = 0.0,
                      afterpulse_rate: float = 0.0, tol: float = 1e-10,
                      max_sweeps: int | None = None, anderson: int = 8,
                      return_info: bool = False, warn: bool = True):
    """Stationary detection probability per bin of a free-running non-paralysable detector.

    Parameters
    ----------
    mu : ndarray, shape (B, L) or (L,)
        Mean photons plus dark counts per bin per code period (after efficiency and jitter).
    dead_bins : float
        Dead time ``D`` in bins; 0 (no dead time) or at least 1.
    afterpulse_prob, afterpulse_rate : float
        Trap-filling probability per avalanche ``P`` and release rate ``r = 1 / tau_ap`` per
        bin after re-arming (see the module docstring).
    tol : float
        Convergence: the largest change of a period's ``h`` between sweeps, relative to the
        row's largest ``h``.
    max_sweeps : int, optional
        Cap on sweeps (default: enough for ``4e6`` bins of unrolled time one period a sweep,
        at least 200; for a dead time longer than the period the first 150 sweeps run
        ``ceil((D + 1) / L)`` periods each); a warning is issued if the fixed point has not
        converged.
    anderson : int
        Depth of the Anderson acceleration of the sweeps (0: plain sweeps).
    return_info : bool
        Also return ``{'sweeps': int, 'change': float}``.
    warn : bool
        Warn where the fixed point has not converged (a caller that says it better itself,
        from ``return_info``, turns this off).

    Returns
    -------
    h : ndarray, same shape as ``mu``
        Mean detections per bin per period: the expected histogram of one period (``<= 1``
        with a dead time, one detection per bin at most; without one, ``mu`` itself, with
        the afterpulse cascade, and not bounded).

    Notes
    -----
    Recurrence (R2) of the module docstring with the afterpulse state; the periodic fixed
    point is reached by sweeping the unrolled time evolution of the expectation (the
    deviation from it decays like the renewal process forgets its phase: a few dead times at
    moderate flux; many when detections are nearly periodic, ``mu D >> 1`` with ``mu >> 1/D``).
    Without dead time, ``h = mu`` convolved with the afterpulse cascade.
    """
    mu = np.asarray(mu, dtype=np.float64)
    one_d = mu.ndim == 1
    mu2 = np.atleast_2d(mu)
    n_rows, period = mu2.shape
    prob, rate = float(afterpulse_prob), float(afterpulse_rate)
    if dead_bins == 0:
        h = mu2.copy()
        if prob:
            kern = jitter_kernel(period, 0.0, 1.0 / rate, 1.0)
            h = sfft.irfft(sfft.rfft(mu2, axis=1) / (1 - prob * sfft.rfft(kern)), n=period,
                           axis=1)
        info = {"sweeps": 0, "change": 0.0}
        h = h[0] if one_d else h
        return (h, info) if return_info else h
    if dead_bins < 1:
        raise ValueError("the dead time must be 0 or at least one bin")
    d = int(np.floor(dead_bins))
    f = float(dead_bins - d)
    # a dead time longer than the period: one sweep runs over as many periods as the state's
    # history spans, so that the mixing's cost per sweep (the history's length) is paid once
    # per dead time, not once per period (2 us at 10 GHz over 1 023 bins: 20 periods a sweep);
    # for at most _COMPOSITE_SWEEPS, then one period a sweep (below)
    reps = max(1, -(-(d + 1) // period))
    last = d + 1 + (reps - 1) * period  # the last period's h in hist
    if max_sweeps is None:
        max_sweeps = max(200, int(np.ceil(4e6 / period)))

    chunks = _chunks(np.max(mu2 + rate, axis=0), min(d, period))
    p = -np.expm1(-mu2)
    scan_a = _Scan(mu2, chunks)
    if prob:
        coef = _Coefficients(mu2, prob, rate)
        scan_g = _Scan(mu2 + rate, chunks)
        force_a = 1.0 - coef.hcoef_g  # g coefficient of alpha's forcing: phi - A_g
        hcoef = coef.hcoef_g
    else:
        force_a = _phi(mu2)
        hcoef = _one_minus_phi(mu2)

    # history: H[:, j] is h at unrolled time j - (d + 1) relative to the sweep's start
    hist = np.empty((n_rows, d + 1 + reps * period))

    def sweep(state: np.ndarray) -> np.ndarray:
        """``reps`` periods of (R2) from the boundary state ``[h_{-d-1} .. h_{-1}, alpha,
        gamma]``; the last period's ``h`` is left in ``hist[:, last:]``."""
        hist[:, : d + 1] = state[:, : d + 1]
        alpha, gamma = state[:, d + 1], state[:, d + 2]
        for o, k, e in ((j * period, k, e) for j in range(reps) for k, e in chunks):
            g = hist[:, o + k + 1 : o + e + 1]
            if f:
                g = (1.0 - f) * g + f * hist[:, o + k : o + e]
            if prob:
                gnext = scan_g.run(k, e, g * coef.coef_gamma[:, k:e], gamma)
                gcur = _shifted_left(gamma, gnext)
                anext = scan_a.run(k, e, g * force_a[:, k:e] - gcur * coef.dexp[:, k:e], alpha)
                acur = _shifted_left(alpha, anext)
                h = p[:, k:e] * acur + g * hcoef[:, k:e] + gcur * coef.dexp[:, k:e]
                gamma = gnext[:, -1]
            else:
                anext = scan_a.run(k, e, g * force_a[:, k:e], alpha)
                h = p[:, k:e] * _shifted_left(alpha, anext) + g * hcoef[:, k:e]
            alpha = anext[:, -1]
            hist[:, d + 1 + o + k : d + 1 + o + e] = h
        return np.concatenate((hist[:, reps * period :], alpha[:, None], gamma[:, None]),
                              axis=1)

    # start: the constant-flux solution h = mu / (1 + D mean(mu)), alpha = 1 - W exactly
    # (alpha + W is conserved by (R2), so an inconsistent start would scale the result)
    init = mu2 / (1.0 + dead_bins * mu2.mean(axis=1, keepdims=True))
    tail = init[:, np.arange(-(d + 1), 0) % period]
    window = tail[:, 1:].sum(axis=1) + f * tail[:, 0]
    scale = np.where(window > 0.999, 0.999 / np.maximum(window, 1e-300), 1.0)
    state = np.concatenate((tail * scale[:, None], (1.0 - window * scale)[:, None],
                            np.zeros((n_rows, 1))), axis=1)

    def on_invariant(x: np.ndarray, fallback: np.ndarray) -> np.ndarray:
        """``x`` scaled per row onto ``alpha + W = 1`` (a row that cannot be: ``fallback``'s).
        The period map is linear and homogeneous in the state, so the iteration fixes only
        the direction of its fixed point and conserves ``alpha + W``: mixed iterates that
        drift off it in round-off (large mixing coefficients) kept their error as a scale,
        6e-5 to 0.54 of the right histogram with a 'converged' change of 3e-10 (a dead time
        of 1.5-3.3 periods of 16383 bins; a batch sub-binned for its brightest row)."""
        total = x[:, 1 : d + 1].sum(axis=1) + f * x[:, 0] + x[:, d + 1]
        ok = np.isfinite(total) & (total > 0) & np.isfinite(x).all(axis=1)
        out = np.where(ok[:, None], x / np.where(ok, total, 1.0)[:, None], fallback)
        return out

    # Anderson acceleration (type II, Walker & Ni 2011) of the affine period map: affine
    # combinations of iterates keep alpha + W = 1 up to round-off, which on_invariant
    # removes. Safeguarded per row: a row that has converged takes plain sweeps (at
    # round-off its residual differences make the mixing's Gram matrix singular, and one such
    # row blew a 64-row batch up to 1e233), and a row whose residual grows past DIVERGED
    # times its best restarts from its best sweep.
    mixer = _Anderson(anderson)
    start = state.copy()
    best = np.full(n_rows, np.inf)
    best_state = state.copy()
    best_out = state.copy()
    change = np.inf
    sweeps = 0
    mark, stalled = np.inf, 0
    for sweeps in range(1, max_sweeps + 1):  # noqa: B007 - reported below
        if reps > 1 and sweeps > _COMPOSITE_SWEEPS:
            # a detector that nearly locks into a cycle of as many periods as a sweep runs
            # makes the sweeps' map nearly singular at its fixed point, where the one-period
            # map is not (bright bins at a dead time of 2.9 periods: 9 133 sweeps, not
            # converged, 1 % off; an outside audit of stop 68): one period a sweep from the
            # start again (from the sweeps' best state the mixing stalled in the cycle they
            # had locked into: 3 of 6 such fluxes 32 % off at the cap)
            reps, last = 1, d + 1
            hist = np.empty((n_rows, d + 1 + period))
            mixer.clear()
            state = start.copy()
            best[:] = np.inf
            mark, stalled = np.inf, 0
        out = sweep(state)
        res = out - state
        scale_h = np.maximum(hist[:, last:].max(axis=1), 1e-300)
        # h's change relative to its own scale, alpha's and gamma's (of order 1) as they are:
        # alpha's round-off (1e-16) over a histogram of 1e-13 never fell below the tolerance
        # (a GMAPD run at 1e-12 photons: 15 687 sweeps, 13.6 s, "not converged"; an audit)
        row_change = np.maximum(np.abs(res[:, : d + 1]).max(axis=1) / scale_h,
                                np.abs(res[:, d + 1 :]).max(axis=1))
        row_change[~np.isfinite(row_change)] = np.inf
        change = float(np.max(row_change))
        if change <= tol:
            break
        improved = row_change < best
        best[improved] = row_change[improved]
        best_state[improved] = state[improved]
        best_out[improved] = out[improved]
        # at the round-off floor (reached in ~10 sweeps at 1-10 photons per dead time, then
        # 235 more sweeps at 1.6e-10 went by without a gain): stop with the best sweep
        if best.max() < 0.5 * mark:
            mark, stalled = float(best.max()), 0
        else:
            stalled += 1
        if stalled >= _STALLED and mark <= _FLOOR:
            break
        diverged = row_change > _DIVERGED * best
        if diverged.any():
            mixer.clear()
            out[diverged] = best_out[diverged]
            state = out
            continue
        if not anderson:
            state = out
            continue
        coeffs, d_x = mixer.push(out, res)
        if coeffs.shape[1]:
            # no mixing for a converged row, nor where the mix is wild (nearly collinear
            # residuals: coefficients of 1e3 and more amplify round-off)
            wild = ~np.isfinite(coeffs).all(axis=1)
            wild |= np.abs(np.nan_to_num(coeffs)).sum(axis=1) > _DIVERGED
            coeffs[wild | (row_change <= tol)] = 0.0
            mixed = out.copy()
            for i, v in enumerate(d_x):
                mixed -= coeffs[:, i, None] * v
            state = on_invariant(mixed, out)
        else:
            state = out
    if change > tol:
        # the cap or the floor: the period's h is that of each row's best sweep, not the last
        sweep(on_invariant(best_state, best_state))
        change = float(np.max(best))
    if warn and change > tol and change > _NEGLIGIBLE:
        # (the brightest row's: one such row among dim ones was given the bare warning, an
        # outside audit of stop 68)
        per_dead = float(mu2.mean(axis=1).max()) * float(dead_bins)
        why = (f" at {per_dead:.3g} photons per dead time: the detector fires at nearly every "
               f"re-arm, so its histograms carry little timing information and the model's "
               f"period map barely forgets its phase; a GMAPD works at about 1-10 photons per "
               f"dead time (lower --signal / --noise; --periods makes up the photons)"
               if per_dead > 100.0 else "")
        warnings.warn(f"dead-time fixed point not converged after {max_sweeps} sweeps "
                      f"(relative change {change:.2e}){why}", RuntimeWarning, stacklevel=2)
    # the mean of the sweep's periods: a sweep of several periods has a fixed point for each
    # phase of a detector that locks into a cycle of that many periods (a bright bin fired
    # every third period at a dead time of 2.4 periods: 0.42 detections a period, against the
    # exact 1/3, "converged" in 2 sweeps; an outside audit of stop 68), and their mean over
    # the cycle is the one-period map's fixed point (the other phases' parts cancel); where
    # the sweep's periods agree, as they do at the one-period fixed point, it is that
    h = hist[:, d + 1 :].reshape(n_rows, reps, period).mean(axis=1)
    h = h[0] if one_d else h
    info = {"sweeps": sweeps, "change": change}
    return (h, info) if return_info else h


# -------------------------------------------------------------------------------- the inverse


def coates_correction(hist: np.ndarray, n_periods: int, dead_time_bins: float,
                      afterpulse_prob: float = 0.0, afterpulse_delay_bins: float = 0.0,
                      oversample: int | None = 1, profile: str = "uniform",
                      max_iter: int = 50, tol: float = 1e-12,
                      expected: bool = False) -> np.ndarray:
    """Incident flux per bin from a free-running GMAPD histogram (generalised Coates estimator).

    Parameters
    ----------
    hist : ndarray, shape (B, L) or (L,)
        Detected counts per bin accumulated over ``n_periods`` code periods.
    n_periods : int
        Code periods accumulated.
    dead_time_bins : float
        Dead time ``D`` in bins (0, or at least 1; need not be an integer nor shorter than the
        period).
    afterpulse_prob, afterpulse_delay_bins : float
        Afterpulsing model of the detector (see :mod:`spslidar.detectors.pileup`); the mean
        afterpulse delay after re-arming, in bins.
    oversample : int or None
        Sub-bins per bin of the forward model to invert (None: :func:`auto_oversample` of the
        bin-level estimate). With ``1`` (default) the bin-level model (R2) is inverted in
        closed form; otherwise by defect correction, ``mu <- mu + C(hist) - C(F_S(mu))`` with
        ``C`` the bin-level inverse and ``F_S`` the sub-binned forward model (flux uniform
        within each bin), which converges because ``C`` inverts ``F_S`` to within its
        discretisation error.
    profile : {'uniform', 'linear'}
        Within-bin flux profile assumed by the sub-binned model (:func:`sub_bin_profile`).
    max_iter, tol : int, float
        Iterations (afterpulsing or oversampling) and their relative tolerance.
    expected : bool
        ``hist`` is an expected histogram (``n_periods`` times the model's mean detections,
        a noiseless run), not counts: no bin is read as saturated nor capped at what counts
        can resolve (both are bounds on counts; at one period, ``n (alpha_t + g_t) < 1/2``
        everywhere, the cap was 0 and erased every bin of an expected histogram).

    Returns
    -------
    ndarray, same shape as ``hist``
        ``n_periods * mu_t``: the mean photons (plus dark counts) per bin that a detector
        without dead time would have counted (efficiency and jitter are not undone).

    Raises
    ------
    ConfigError
        For an argument out of its range, before any work, naming it: ``hist`` not finite
        and non-negative, ``n_periods`` not a positive number, ``dead_time_bins`` neither 0
        nor a finite number >= 1, ``afterpulse_prob`` outside [0, 1), ``oversample``
        neither None nor a whole number >= 1, an unknown ``profile`` (negative counts were
        corrected to zeros, a NaN dead time failed in a cast to an integer: an outside
        audit).

    Notes
    -----
    Coates (J. Phys. E 1, 878, 1968) for a synchronous TCSPC: ``mu_t = -log(1 - h_t / N_t)``
    with ``N_t`` the periods in which bin ``t`` was armed. For a free-running detector the
    armed fraction is estimated from the histogram itself (Rapp et al. 2019; the
    "asynchronous" Coates of Gupta et al., "Photon-flooded single-photon 3D cameras",
    CVPR 2019): ``alpha_t = 1 - W_t``, ``W_t = sum_{s=t-d}^{t-1} h_s + f h_{t-d-1}``
    (``h = hist / n_periods``), and the re-arm inflow ``g_t = (1-f) h_{t-d} + f h_{t-d-1}``.
    Each bin's (R2) ``h_t = alpha_t p(mu_t) + g_t (1 - phi(mu_t))`` is inverted by Newton's
    method; with ``g = 0`` it is Coates's formula. On the expected histogram of
    :func:`renewal_detection` the inverse is exact. With afterpulsing, the afterpulse share of
    each bin (which depends on the trap state, a periodic recurrence in ``mu``) is subtracted
    and the photon map inverted again, until ``mu`` stops changing.

    Counts (``expected=False``): a bin that detected in every armed period
    (``h_t >= alpha_t + g_t``, only in noisy counts) is set to the flux of half a count less
    (but at least half its ceiling), and no bin's flux exceeds
    ``max(log(2 n (alpha_t + g_t)), log 2)``, where Coates's map is half a count below its
    ceiling (the most the counts can resolve), or half way to it where the ceiling is under a
    count (a few periods: the cap was ``log(1) = 0`` there, which erased every bin).
    """
    h = _checked_inputs(hist, n_periods, dead_time_bins, afterpulse_prob,
                        afterpulse_delay_bins, oversample, profile)
    one_d = h.ndim == 1
    h = np.atleast_2d(h) / float(n_periods)
    if dead_time_bins == 0:
        mu = h
        if afterpulse_prob:
            kern = jitter_kernel(h.shape[1], 0.0, float(afterpulse_delay_bins), 1.0)
            mu = h - afterpulse_prob * convolve_periodic(h, kern)
        # (not clipped at 0: the inverse is linear here and unbiased only signed; clipped, the
        # half of a low-count histogram's bins that hold no count kept their share of the
        # afterpulses, +5 % of the photons at P = 0.1, an outside audit)
        out = mu * n_periods
        return out[0] if one_d else out
    args = (float(n_periods), dead_time_bins, float(afterpulse_prob),
            float(afterpulse_delay_bins), max_iter, tol, bool(expected))
    mu = _coates_bins(h, *args)
    # each row sub-binned as its own flux needs (as the forward model does)
    subs = (np.array([auto_oversample(float(m)) for m in mu.max(axis=1, initial=0.0)])
            if oversample is None else np.full(mu.shape[0], int(oversample)))
    for sub in np.unique(subs[subs > 1]):
        rows = np.flatnonzero(subs == sub)
        mu[rows] = _defect_correction(h[rows], mu[rows], int(sub), profile, args)
    out = mu * n_periods
    return out[0] if one_d else out


def _checked_inputs(hist, n_periods, dead_time_bins, afterpulse_prob, afterpulse_delay_bins,
                    oversample, profile) -> np.ndarray:
    """:func:`coates_correction`'s ``hist`` as float64, its other arguments checked (one
    :class:`~spslidar.errors.ConfigError` naming the first one out of range)."""
    check_periods(n_periods)
    dead = real_scalar(dead_time_bins, "dead_time_bins")
    if not (dead == 0 or (np.isfinite(dead) and dead >= 1)):
        raise ConfigError(f"dead_time_bins must be 0 or a finite number of TDC bins >= 1, got "
                          f"{dead_time_bins!r}")
    prob = real_scalar(afterpulse_prob, "afterpulse_prob")
    if not 0 <= prob < 1:
        raise ConfigError(f"afterpulse_prob must be in [0, 1), got {afterpulse_prob!r}")
    delay = real_scalar(afterpulse_delay_bins, "afterpulse_delay_bins")
    if not (np.isfinite(delay) and (delay > 0 if prob else delay >= 0)):
        raise ConfigError(f"afterpulse_delay_bins must be a finite number of TDC bins >= 0 (> 0 "
                          f"where afterpulse_prob > 0), got {afterpulse_delay_bins!r}")
    if oversample is not None:
        sub = real_scalar(oversample, "oversample")
        if not (sub >= 1 and sub.is_integer()):
            raise ConfigError(f"oversample must be None or a whole number >= 1, got "
                              f"{oversample!r}")
    if not (isinstance(profile, str) and profile in ("uniform", "linear")):
        raise ConfigError(f"unknown sub-bin profile {profile!r}; use 'uniform' or 'linear'")
    h = real_array(hist, "hist").astype(np.float64, copy=False)
    check_rates(h, "hist (detected counts per bin)")
    return h


def sub_bin_profile(mu: np.ndarray, sub: int, profile: str = "uniform") -> np.ndarray:
    """Split each bin's flux (B, L) into ``sub`` sub-bins (B, L * sub), conserving bin totals.

    ``'uniform'``: ``mu / sub`` each (the flux of a bin is uniform, e.g. no jitter).
    ``'linear'``: a periodic piecewise-linear reconstruction with minmod-limited slopes
    (second order for smooth, e.g. jitter-broadened, flux; never negative).
    """
    if profile == "uniform":
        return np.repeat(mu / sub, sub, axis=1)
    if profile != "linear":
        raise ValueError(f"unknown sub-bin profile {profile!r}; use 'uniform' or 'linear'")
    up, down = np.roll(mu, -1, axis=1) - mu, mu - np.roll(mu, 1, axis=1)
    slope = np.where(up * down > 0, np.sign(up) * np.minimum(np.abs(up), np.abs(down)), 0.0)
    x = (np.arange(sub) + 0.5) / sub - 0.5
    fine = (mu[:, :, None] + slope[:, :, None] * x) / sub
    return fine.reshape(mu.shape[0], -1)


def _defect_correction(h, mu, sub, profile, args, max_iter: int = 100, tol: float = 1e-7):
    """``mu`` with ``F_S(mu) = h`` for the sub-binned forward model ``F_S``, from the bin-level
    inverse ``C``: ``mu <- mu + w (C(h) - C(F_S(mu)))``, with a per-bin step weight ``w``
    halved whenever that bin's step changes sign (``C`` is ill-conditioned in saturated bins,
    where a plain iteration oscillates). Stops when the forward model matches ``h`` to
    ``tol`` or when the worst residual has not improved by 1 % in five steps."""
    _, dead, prob, delay, _, _, _ = args
    rate = 1.0 / delay if prob else 0.0
    period = h.shape[1]
    base = mu.copy()
    mu = np.maximum(mu, 0.0)
    weight = np.ones_like(mu)
    prev = np.zeros_like(mu)
    scale = max(float(h.max(initial=0.0)), 1e-300)
    best = []
    for _ in range(max_iter):
        # (its own warning said "not converged at 156 photons per dead time" for the flux this
        # refinement tries, where the detections said 25: said once below, as the correction's)
        fwd, info = renewal_detection(sub_bin_profile(mu, sub, profile), dead * sub, prob,
                                      rate / sub, tol=1e-8, return_info=True, warn=False)
        fwd = fwd.reshape(-1, period, sub).sum(axis=2)
        worst = float(np.max(np.abs(fwd - h)))
        # converged, or stuck (capped or saturated bins the model cannot reach: no gain of
        # 1 % in the worst residual over the last 5 steps)
        if worst <= tol * scale or (len(best) >= 5 and worst > 0.99 * best[-5]):
            break
        best.append(min(worst, best[-1]) if best else worst)
        step = base - _coates_bins(fwd, *args)
        weight = np.where(step * prev < 0, 0.5 * weight, np.minimum(1.5 * weight, 1.0))
        prev = step
        mu = np.maximum(mu + weight * step, 0.0)
    if info["change"] > max(1e-8, _NEGLIGIBLE):
        warnings.warn(
            f"the pile-up correction's dead-time model, run at the corrected flux of the "
            f"brightest histograms ({float(mu.mean()) * dead:.3g} photons per dead time, above "
            f"what their detections give for a steady flux), did not converge (relative "
            f"change {info['change']:.2e}): so near saturation the corrected counts are "
            f"uncertain; --pileup-correction off, or less light and more --periods",
            RuntimeWarning, stacklevel=3)
    # bins whose counts are fewer than their expected afterpulses read below 0 at the bin
    # level (unbiased, signed: :func:`_coates_bins`), where the sub-binned model, a flux,
    # cannot follow: they keep that reading (clipped, +22-47 % of the photons at P = 0.3,
    # a 20 ns dead time and 100 periods, an outside audit)
    return np.where(base < 0, base, mu)


def _coates_bins(h: np.ndarray, n_periods: float, dead_time_bins: float,
                 afterpulse_prob: float, afterpulse_delay_bins: float, max_iter: int,
                 tol: float, expected: bool = False) -> np.ndarray:
    """The closed-form inverse of the bin-level model (R2), per period (see
    :func:`coates_correction`); ``h`` is (B, L) detections per period (``expected``: means,
    neither read as saturated nor capped)."""
    d = int(np.floor(dead_time_bins))
    f = float(dead_time_bins - d)
    alpha = np.maximum(1.0 - _circular_window(h, d, f), 0.0)
    g = np.roll(h, d, axis=1)
    if f:
        g = (1.0 - f) * g + f * np.roll(h, d + 1, axis=1)
    limit = alpha + g
    if expected:
        # an expected histogram is below its ceiling and resolves any flux: inverted exactly
        target, cap = h, np.inf
    else:
        sat = h >= limit
        target = np.where(sat, np.maximum(limit - 0.5 / n_periods, 0.5 * limit), h)
        # the flux at which Coates's map comes within half a count of its ceiling: counts
        # cannot resolve more (the re-arm term saturates only as 1/mu, so near-saturated bins
        # would otherwise read thousands of photons per bin from a fraction of a count); not
        # below log 2, half way to a ceiling under one count (n (alpha + g) < 1/2, e.g. one
        # period at 0.19 armed: the cap was log 1 = 0, and every bin read 0 photons)
        cap = np.log(np.maximum(2.0 * n_periods * limit, 2.0))
    mu = np.minimum(_invert_photon_map(target, alpha, g), cap)
    if afterpulse_prob:
        rate = 1.0 / float(afterpulse_delay_bins)
        for _ in range(max_iter):
            # (the trap's state from the flux the bins can have, never below 0)
            flux = np.maximum(mu, 0.0)
            coef = _Coefficients(flux, afterpulse_prob, rate)
            gamma = _periodic_scan(flux + rate, g * coef.coef_gamma)
            extra = g * coef.ap_g + gamma * coef.dexp
            # signed: a bin with fewer counts than its expected afterpulses reads below 0
            # (clipped there, the bins without a count kept their share of the afterpulses:
            # +8 % of the photons at P = 0.1 and a 20 ns dead time, +27 % at 0.3, an audit)
            new = np.minimum(_invert_photon_map(target - extra, alpha, g,
                                                min_armed=1.0 / n_periods), cap)
            change = np.max(np.abs(new - mu)) / max(float(np.max(mu)), 1e-300)
            mu = new
            if change <= tol:
                break
    return mu
