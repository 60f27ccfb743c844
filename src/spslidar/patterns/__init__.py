"""DMD spatial patterns as operators (the rows of Phi, eq. 7), and the registry of pattern
kinds.

``PATTERNS.load(kind)(kind, M, N, rng, dtype, **options)`` builds a
:class:`~spslidar.patterns.base.PatternOperator`; :func:`build_patterns` does it by name.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from ..registry import Registry, lazy_exports

if TYPE_CHECKING:
    from .base import PatternOperator

__all__ = ["PATTERNS", "PATTERN_KINDS", "CentredPatterns", "DensePatterns", "PatternOperator",
           "as_patterns", "build_patterns", "make_patterns", "n_patterns_for"]

# the operators themselves import numpy: re-exported on first access, so reading the registry
# (``--help``, config validation) stays light
__getattr__ = lazy_exports(__name__, {
    "CentredPatterns": "base", "PatternOperator": "base", "as_patterns": "base",
    "PATTERN_KINDS": "dense", "DensePatterns": "dense", "make_patterns": "dense",
    "n_patterns_for": "dense"})

#: pattern kinds by name (the ``patterns`` config key / ``--patterns`` option)
PATTERNS = Registry("pattern kind", "patterns")
PATTERNS.add("gaussian", "spslidar.patterns.dense:dense_patterns", "Gaussian grey-level",
             "grey-level Gaussian clip(0.5 + 0.25 N(0,1), 0, 1), the paper's (default)",
             dense=True)
PATTERNS.add("bernoulli", "spslidar.patterns.dense:dense_patterns", "Bernoulli binary",
             "binary, each mirror on with probability 1/2", dense=True)


def build_patterns(kind: str, n_patterns: int, n_side: int, rng: Any,
                   dtype: Any = "float32", **options) -> PatternOperator:
    """The pattern set of a registered kind: ``M`` patterns over ``N x N`` mirrors, drawn
    from the ``numpy.random.Generator`` ``rng``."""
    return PATTERNS.load(kind)(kind, n_patterns, n_side, rng, dtype=dtype, **options)
