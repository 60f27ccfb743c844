"""DMD spatial patterns as operators (the rows of Phi, equation 7), and the registry of pattern
kinds.

``PATTERNS.load(kind)(kind, M, N, rng, dtype, **options)`` builds a
:class:`~spslidar.patterns.base.PatternOperator`; :func:`build_patterns` does it by name.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from ..registry import Registry, lazy_exports

if TYPE_CHECKING:
    from .base import PatternOperator

__all__ = ["HADAMARD_KINDS", "HADAMARD_ORDERS", "HADAMARD_REALISATIONS", "PATTERNS",
           "PATTERN_OPTIONS", "pattern_share", "realisation_note",
           "PATTERN_KINDS", "CentredPatterns", "DensePatterns", "PatternOperator",
           "as_patterns", "build_patterns", "make_patterns", "n_patterns_for"]

# the operators themselves import numpy: re-exported on first access, so reading the registry
# (``--help``, config validation) stays light
__getattr__ = lazy_exports(__name__, {
    "CentredPatterns": "base", "PatternOperator": "base", "as_patterns": "dense",
    "PATTERN_KINDS": "dense", "DensePatterns": "dense", "make_patterns": "dense",
    "n_patterns_for": "dense"})

#: row orderings of ``hadamard`` patterns (``hadamard_order`` / ``--hadamard-order``)
HADAMARD_ORDERS = ("sequency", "cake-cutting", "random", "natural")
#: how +-1 Hadamard patterns are shown on a 0/1 DMD (``--hadamard-realisation``)
HADAMARD_REALISATIONS = ("shifted", "differential", "complementary")
#: the pattern kinds whose rows ``--hadamard-realisation`` shows (both are +-1 Hadamard rows)
HADAMARD_KINDS = ("hadamard", "scrambled-hadamard")


def realisation_note(cfg) -> str:
    """``", complementary"`` (or ``", differential"``) where a run's Hadamard rows are not
    shown ``shifted``, else ``""``: for the summary line and the figure's title, which named
    the pattern kind alone, so that two runs of the same rows shown two ways read alike."""
    real = getattr(cfg, "hadamard_realisation", "shifted")
    return f", {real}" if cfg.patterns in HADAMARD_KINDS and real != "shifted" else ""


def pattern_share(n_patterns: int, size: int) -> str:
    """The patterns' share of the pixels, ``100 M / Q`` per cent to three digits, for the
    summary line and the figure's title: they said the ``compression`` asked for, which
    ``M = round(c Q)`` (at least 2) only nears (0.6 % for 2 patterns of 256, 0.78 %: an
    outside audit of 2026-12-01)."""
    return f"{100.0 * int(n_patterns) / max(int(size) ** 2, 1):.3g}"


#: pattern kinds by name (the ``patterns`` config key / ``--patterns`` option)
PATTERNS = Registry("pattern kind", "patterns")
PATTERNS.add("gaussian", "spslidar.patterns.dense:dense_patterns", "Gaussian grey-level",
             "grey-level Gaussian clip(0.5 + 0.25 N(0,1), 0, 1), the paper's (default)",
             dense=True)
PATTERNS.add("bernoulli", "spslidar.patterns.dense:dense_patterns", "Bernoulli binary",
             "binary, each mirror on with probability 1/2", dense=True)
PATTERNS.add("hadamard", "spslidar.patterns.hadamard:hadamard_patterns", "Walsh-Hadamard",
             "Walsh-Hadamard rows by fast transform (N a power of 2; --hadamard-order, "
             "--hadamard-realisation)", validate=lambda cfg: _check_side(cfg), dense=False)
PATTERNS.add("scrambled-hadamard", "spslidar.patterns.hadamard:hadamard_patterns",
             "scrambled Hadamard", "random rows of a Walsh-Hadamard transform with random "
             "pixel permutation and signs (N a power of 2)", validate=lambda cfg: _check_side(cfg),
             dense=False)


def _check_side(cfg: Any) -> None:
    n = cfg.size
    if n < 2 or n & (n - 1):
        from ..errors import ConfigError

        lo = 1 << max(1, int(n).bit_length() - 1)
        raise ConfigError(f"{cfg.patterns} patterns need --size a power of two (Q = N^2 = 2^k "
                          f"for the fast transform), got {n}: use {lo} or {2 * lo}")


def pattern_count(value: Any, name: str) -> int:
    """``value`` as a whole number >= 1 (a count of patterns, a side in mirrors), or a
    one-line :class:`~spslidar.errors.ConfigError` naming ``name``.

    Parameters
    ----------
    value : int
        An integer (``bool`` and fractions are refused).
    name : str
        The argument's name, for the message.

    Returns
    -------
    int
    """
    import operator

    from ..errors import ConfigError

    try:
        number = operator.index(value)
    except TypeError:
        raise ConfigError(f"{name} must be an integer, got {value!r}") from None
    if isinstance(value, bool):
        raise ConfigError(f"{name} must be an integer, got {value!r}")
    if number < 1:
        raise ConfigError(f"{name} must be an integer >= 1, got {value!r}")
    return int(number)


def build_patterns(kind: str, n_patterns: int, n_side: int, rng: Any,
                   dtype: Any = "float32", **options) -> PatternOperator:
    """The pattern set of a registered kind: ``M`` patterns over ``N x N`` mirrors, drawn
    from the ``numpy.random.Generator`` ``rng``.

    ``dtype`` may be any NumPy dtype spelling (``"float32"``, ``np.float32``,
    ``np.dtype("float32")``): the same seed gives the same patterns for each (the string, this
    function's default, drew other patterns than the pipeline's ``np.float32``).
    ``n_patterns`` and ``n_side`` must be integers >= 1 (a ``ConfigError`` otherwise: an
    ``n_side`` of -2 made ``(-2)**2 = 4`` pixels, an audit of 2026-12-02).
    ``options`` are the factories' keywords (:data:`PATTERN_OPTIONS`, and those a kind
    declares); a kind ignores the ones that are not its own (the pipeline gives each kind
    every one), but a keyword no kind takes is refused (``pattern_sigma=``, the config's key
    for ``sigma=``, and typos were dropped without a word: an audit of 2026-11-29).
    """
    import difflib

    import numpy as np

    from ..errors import ConfigError

    for name, value in (("n_patterns", n_patterns), ("n_side", n_side)):
        pattern_count(value, name)
    factory = PATTERNS.load(kind)
    # the built-in keywords, every declared option's config key and keyword (a plugin's
    # Option(param=...) was refused, a review of 2026-11-29) and the factory's own keywords
    known = set(PATTERN_OPTIONS) | {n for o in PATTERNS.options().values()
                                    for n in (o.name, o.param or o.name)}
    own, takes_any = None, True
    try:
        import inspect

        params = inspect.signature(factory).parameters.values()
        own = {p.name for p in params if p.kind in (p.POSITIONAL_OR_KEYWORD, p.KEYWORD_ONLY)}
        takes_any = any(p.kind is p.VAR_KEYWORD for p in params)
        known |= own
    except (TypeError, ValueError):  # pragma: no cover - a factory without a signature
        pass
    known -= {"kind", "n_patterns", "n_side", "rng", "dtype"}
    for key in options:
        if key not in known:
            config_key = {f"pattern_{k}": k for k in PATTERN_OPTIONS} | {
                f"hadamard_{k}": k for k in PATTERN_OPTIONS}
            near = config_key.get(key) or next(iter(difflib.get_close_matches(key, known, 1)),
                                               None)
            raise ConfigError(f"build_patterns() takes no option {key!r}"
                              + (f": did you mean {near!r}?" if near else "")
                              + f" (it takes {', '.join(sorted(known))})")
    if not takes_any:  # (a plugin's factory written to the docs, its own options only,
        # was given the built-in kinds' sigma, on_fraction... and raised TypeError, an
        # outside audit: a factory without **kwargs gets the keywords it names)
        options = {k: v for k, v in options.items() if k in own}
    return factory(kind, int(n_patterns), int(n_side), rng, dtype=np.dtype(dtype), **options)


#: the keywords of the built-in pattern factories: ``sigma`` (Gaussian grey levels' spread),
#: ``on_fraction`` (Bernoulli), ``order`` and ``realisation`` (Hadamard)
PATTERN_OPTIONS = ("sigma", "on_fraction", "order", "realisation")


def __dir__() -> list[str]:
    # the lazy names too, so dir() and a REPL's completion list them (an audit of 2026-11-30)
    return sorted(set(globals()) | set(__all__))
