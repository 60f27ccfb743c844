"""DMD spatial patterns as operators (the rows of Phi, eq. 7), and the registry of pattern
kinds.

``PATTERNS.load(kind)(kind, M, N, rng, dtype, **options)`` builds a
:class:`~spslidar.patterns.base.PatternOperator`; :func:`build_patterns` does it by name.
"""

from __future__ import annotations

import numpy as np

from ..registry import Registry
from .base import CentredPatterns, PatternOperator, as_patterns
from .dense import PATTERN_KINDS, DensePatterns, make_patterns, n_patterns_for

__all__ = ["PATTERNS", "PATTERN_KINDS", "CentredPatterns", "DensePatterns", "PatternOperator",
           "as_patterns", "build_patterns", "make_patterns", "n_patterns_for"]

#: pattern kinds by name (the ``patterns`` config key / ``--patterns`` option)
PATTERNS = Registry("pattern kind", "patterns")
PATTERNS.add("gaussian", "spslidar.patterns.dense:dense_patterns", "Gaussian grey-level",
             "grey-level Gaussian clip(0.5 + 0.25 N(0,1), 0, 1), the paper's (default)")
PATTERNS.add("bernoulli", "spslidar.patterns.dense:dense_patterns", "Bernoulli binary",
             "binary, each mirror on with probability 1/2")


def build_patterns(kind: str, n_patterns: int, n_side: int, rng: np.random.Generator,
                   dtype=np.float32, **options) -> PatternOperator:
    """The pattern set of a registered kind: ``M`` patterns over ``N x N`` mirrors."""
    return PATTERNS.load(kind)(kind, n_patterns, n_side, rng, dtype=dtype, **options)
