"""The regularisation of equation (18) a run uses: the regulariser, the solver's registered
defaults, and the default weight read from the measurements' noise level (never the truth).
"""

from __future__ import annotations

import numpy as np

from ..config import Config
from ..patterns import PatternOperator
from ..qcr import centre

#: inner (dual) iterations of the warm-started TV prox per outer iteration: the prox's dual is
#: carried over between outer iterations, so a few suffice (measured: the same depth RMSE
#: with 3, 5, 10 or 20 on the default problem, and on the motorcycle with FISTA and TwIST)
TV_INNER = 3


def regulariser_kind(cfg: Config) -> str:
    """The name of the regulariser the config asks for, ``auto`` resolved to the solver's
    default."""
    if cfg.regulariser == "auto":
        return solver_default(cfg.solver, "regulariser")
    return cfg.regulariser


def build_regulariser(cfg: Config, shape: tuple[int, int]):
    """The regulariser of eq. (18) the config asks for (``auto``: the solver's default), from
    the registry :data:`spslidar.solvers.REGULARISERS`."""
    from ..solvers import REGULARISERS

    return REGULARISERS.load(regulariser_kind(cfg))(shape, nonneg=cfg.nonneg,
                                                     max_inner=TV_INNER)


def solver_default(name: str, key: str):
    """A registered solver's default ``key`` (``iterations``, ``lam_scale``, ``regulariser``):
    its registry entry's, else the solver class's ``default_<key>``."""
    from ..solvers import SOLVERS

    defaults = SOLVERS.get(name).defaults
    if key in defaults:
        return defaults[key]
    return getattr(SOLVERS.load(name), f"default_{key}")


def noise_level(A, patterns: PatternOperator, sigma: np.ndarray, cfg: Config, rng) -> float:
    """RMS of ``A^H e_y`` for measurement noise ``e`` of the estimated per-pattern level,
    pushed through the same data preparation (centring / covariance) as the data.

    This is the noise that reaches the regulariser's prox in a gradient step; the default
    regularisation weight is a fixed multiple of it. It uses the measurements only (through
    ``sigma``), never the truth.
    """
    m = patterns.shape[0]
    e = rng.standard_normal((m, 4)) * sigma[:, None]
    if cfg.qcr and cfg.qcr_form == "centred":
        ey = centre(e) / np.sqrt(m)
    elif cfg.qcr:
        # Phi_c^T e_c = Phi^T e_c: the centred noise sums to zero over the patterns
        ey = np.asarray(patterns.rmatvec(centre(e).astype(patterns.dtype)), np.float64) / m
    else:
        ey = e
    z = A.rmatvec(ey.astype(A.dtype))
    return float(np.sqrt(np.mean(np.asarray(z, dtype=np.float64) ** 2)))


#: the default weight is at least this share of ``lam_max = max |A^H y|``
LAM_FLOOR = 3e-3
#: where the floor sets the weight (high signal-to-noise ratios) the solver's default
#: iteration count is multiplied by this: at the floor's small weight FISTA's 60 iterations
#: stopped far from the minimum, so that more light gave a worse map (steps 16x16 at m_s 50 /
#: 500: 0.0015 / 0.039 m). Chosen on m_s = 500 and 5000, seeds 0-1 (x5: steps 0.039 / 0.0096
#: -> 0.0015 / 0.028 m, room 32x32 0.093 / 0.063 -> 0.0038 / 0.0038 m, camera, motorcycle,
#: ramp unchanged); held out at m_s = 500, 32x32: room seeds 2-5 0.110 / 0.137 / 0.170 / 0.174
#: -> 0.004 / 0.066 / 0.038 / 0.038 m, procedural 100-107 6 better (0.072 -> 0.003 m) and 2
#: worse (0.19 -> 0.21, 0.15 -> 0.18 m), street 0.0046 -> 0.0046 / 0.0050 m, fence 0.147 /
#: 0.154 -> 0.133 / 0.045 m; the solve takes 4-5 times as long (32x32: 0.35 -> 1.6 s)
FLOORED_ITERATIONS = 5


def default_weight(cfg: Config, sigma_eff: float, lam_max: float) -> tuple[float, float, bool]:
    """The regularisation weight: ``cfg.lam`` if given, else
    ``max(lam_scale * sigma_eff, LAM_FLOOR * lam_max)``.

    The first term follows the noise that reaches the prox (:func:`noise_level`); it goes to
    zero as the photon count grows, but a compressive problem (``M < Q``) needs its prior even
    without noise: with a vanishing weight the solver returns a minimum-norm-like estimate
    (measured: the conventional lidar at 25 %, noiseless, 0.11-0.14 m whatever the flux). The
    floor is a fixed share of ``lam_max = ||A^H y||_inf`` (the weight at which an l1 estimate
    is zero), a scale read from the data; at the paper's settings the noise term is 2 to 6
    times larger (camera, seeds 0-1: m_n = 10 ``lam = 0.014-0.018 lam_max``, m_n = 1
    ``0.006-0.008 lam_max``), so
    the floor binds only at high signal-to-noise ratios (e.g. a dwell of many code periods),
    and for ``noiseless`` data, where no noise reaches the prox: their weight took the noisy
    run's Poisson level, so the noise-free case was no better than the noisy one (the room,
    32x32: 0.16 m; at the floor 0.0038 m).

    Returns
    -------
    lam : float
    lam_scale : float
        The multiple of ``sigma_eff`` (the solver's default unless the config sets it).
    floored : bool
        Whether the floor set the weight.
    """
    lam_scale = (cfg.lam_scale if cfg.lam_scale is not None
                 else solver_default(cfg.solver, "lam_scale"))
    if cfg.lam is not None:
        return float(cfg.lam), lam_scale, False
    noise_term = 0.0 if cfg.noiseless else lam_scale * sigma_eff
    floor = LAM_FLOOR * lam_max
    return max(noise_term, floor), lam_scale, bool(floor > noise_term)


def weight_warnings(cfg: Config, lam: float, lam_max: float,
                    floored: bool = False) -> list[str]:
    """A weight at or above ``lam_max = max |A^H y|`` makes the regulariser win outright: the
    l1 solution is zero and every TV slice flat, so the depth map carries no information
    (``--lam 1e12`` ran silently; so did ``--lam-scale 1e6``). The default weight is about
    0.01 ``lam_max``. A ``--lam-scale`` the floor overrides is said too (``floored``): three
    scales 0.01-0.3 at 64x64 Hadamard gave one weight and one RMSE, and a sweep over it came
    out flat, without a word (an audit of 2026-11-28)."""
    out = []
    if cfg.lam is None and floored and cfg.lam_scale is not None and not cfg.noiseless:
        cap = ("" if cfg.iterations else
               f" (with {FLOORED_ITERATIONS} times the solver's iteration cap)")
        out.append(f"--lam-scale {cfg.lam_scale:g} gives a weight below the floor of "
                   f"{LAM_FLOOR:g} max|A^H y| = {lam:.3g}, which was used instead{cap}: a "
                   f"smaller --lam-scale changes nothing here; set the weight itself with "
                   f"--lam")
    if not lam_max > 0 or lam < lam_max:
        return out
    given = (f"--lam {lam:g}" if cfg.lam is not None else
             f"the default weight {lam:.3g}" if cfg.lam_scale is None else
             f"the weight {lam:.3g} of --lam-scale {cfg.lam_scale:g}")
    return out + [f"{given} is {lam / lam_max:.3g} times max|A^H y| = {lam_max:.3g}: the "
                  f"regulariser wins outright (every slice zero or flat), so the depth map "
                  f"carries no information; the default weight is about 0.01 max|A^H y|"]
