"""One spelling of "a random stream" for every public function that draws: a
:class:`numpy.random.Generator` (used as it is, so it advances), a seed (an integer >= 0, a
sequence of them or a :class:`numpy.random.SeedSequence`) or None (fresh entropy), as
:func:`numpy.random.default_rng` takes them; anything else is one line naming the argument
(``rng=1.5`` gave SeedSequence's own error, a detector's ``rng=0`` an AttributeError: an audit
of 2026-11-29)."""

from __future__ import annotations

from typing import Any

import numpy as np

from .errors import ConfigError

__all__ = ["as_generator"]


def as_generator(rng: Any, what: str = "rng") -> np.random.Generator:
    """``rng`` as a :class:`numpy.random.Generator` (see the module), or a
    :class:`~spslidar.errors.ConfigError` naming ``what``."""
    if isinstance(rng, np.random.Generator):
        return rng
    if isinstance(rng, (bool, float, complex, str, bytes)):
        raise ConfigError(f"{what} must be a numpy.random.Generator, a seed (an integer >= 0) "
                          f"or None, got {rng!r}")
    try:
        return np.random.default_rng(rng)
    except (TypeError, ValueError):
        raise ConfigError(f"{what} must be a numpy.random.Generator, a seed (an integer >= 0) "
                          f"or None, got {rng!r}") from None
