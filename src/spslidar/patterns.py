"""DMD spatial patterns: the rows of the measurement matrix Phi of eq. (7).

A DMD only switches mirrors on or off, so every pattern here is non-negative:

* ``gaussian``: the paper's "Gaussian patterns", realised as grey-level transmittances
  ``clip(0.5 + sigma * N(0, 1), 0, 1)`` (displayed on a real DMD by pulse-width modulation over
  the exposure). With the default ``sigma = 0.25`` about 4.6 % of the values are clipped.
* ``bernoulli``: binary patterns, each mirror on with probability ``on_fraction``.
"""

from __future__ import annotations

import numpy as np

from .errors import ConfigError

PATTERN_KINDS = ("gaussian", "bernoulli")


def n_patterns_for(compression: float, n_pixels: int) -> int:
    """Number of patterns ``M = round(compression * Q)`` (at least 1).

    Parameters
    ----------
    compression : float
        The paper's compression proportion M / Q, in (0, 1].
    n_pixels : int
        Q = N^2.
    """
    if not (0.0 < compression <= 1.0) or not np.isfinite(compression):
        raise ConfigError(f"compression must be in (0, 1], got {compression}")
    return max(1, int(round(compression * n_pixels)))


def make_patterns(
    kind: str,
    n_patterns: int,
    n_pixels: int,
    rng: np.random.Generator | int | None = None,
    sigma: float = 0.25,
    on_fraction: float = 0.5,
    dtype=np.float32,
) -> np.ndarray:
    """Generate ``M`` DMD patterns as the rows of an ``(M, Q)`` matrix with entries in [0, 1].

    Parameters
    ----------
    kind : {'gaussian', 'bernoulli'}
    n_patterns : int
        M.
    n_pixels : int
        Q = N^2 (patterns are flattened in C order, like the images).
    rng : Generator or int or None
        Random source.
    sigma : float
        Standard deviation of the grey levels of ``gaussian`` patterns around 0.5.
    on_fraction : float
        Probability that a mirror is on in ``bernoulli`` patterns.
    dtype : numpy dtype
        Output precision.

    Notes
    -----
    Phi in eq. (7) and (11)-(17). The paper assumes zero-mean Gaussian entries (RIP argument);
    non-negative patterns carry a large common (DC) component, which QCR removes (eq. 11).
    """
    rng = np.random.default_rng(rng)
    if n_patterns < 1 or n_pixels < 1:
        raise ConfigError("need at least one pattern and one pixel")
    if kind == "gaussian":
        if not sigma > 0:
            raise ConfigError(f"pattern sigma must be positive, got {sigma}")
        phi = rng.standard_normal((n_patterns, n_pixels), dtype=np.float32 if dtype == np.float32
                                  else np.float64)
        phi *= sigma
        phi += 0.5
        np.clip(phi, 0.0, 1.0, out=phi)
        return phi.astype(dtype, copy=False)
    if kind == "bernoulli":
        if not 0.0 < on_fraction < 1.0:
            raise ConfigError(f"pattern on-fraction must be in (0, 1), got {on_fraction}")
        return (rng.random((n_patterns, n_pixels)) < on_fraction).astype(dtype)
    raise ConfigError(f"unknown pattern kind {kind!r}; choose one of {', '.join(PATTERN_KINDS)}")
