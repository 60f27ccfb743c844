"""Temporal pseudo-random codes that modulate the laser, and the registry of code families.

``CODES.load(family)(family, length, ones_ratio, rng, index)`` makes one code (``uint8``
0/1). The sequences themselves live in :mod:`spslidar.codes.sequences` (m-sequences, Gold
codes, Bernoulli bits, periodic correlation); this module holds only the registry and
re-exports that API on first access, so reading the registry (``spslidar run --help``,
config validation) imports no numerical library.

Adding a family is one module with a ``make(kind, length, ones_ratio, rng, index)`` function
plus one :meth:`~spslidar.registry.Registry.add` line here.
"""

from __future__ import annotations

from ..errors import ConfigError
from ..registry import Registry, lazy_exports

__all__ = ["CODES", "CODE_KINDS", "MSEQ_DEGREES", "GOLD_DEGREES", "canonical_kind", "make_code",
           "preferred_pair", "gold_family", "periodic_xcorr", "gold_bound", "valid_lengths",
           "unambiguous_range"]

__getattr__ = lazy_exports(__name__, {name: "sequences" for name in __all__ if name != "CODES"})


def _validate_length(cfg) -> None:
    """Registry hook: the config's code length is one the family can have (one line naming
    the nearest valid lengths otherwise)."""
    from .sequences import _as_int, _check_length

    length = _as_int(cfg.code_length, "code length")
    if (getattr(cfg, "lidar", "psst") == "conventional"
            and getattr(cfg, "fairness", "energy") != "power"):
        return  # the code is not made, its length only sets the dwell (Gold at 4095 refused)
    _check_length(cfg.code, length)


def _validate_fixed_ratio(cfg) -> None:
    """Registry hook of the m-sequence and Gold families: their share of '1' bits is fixed
    near 1/2, so a ``ones_ratio`` other than the default is a mistake, not a setting."""
    _validate_length(cfg)
    if cfg.ones_ratio != 0.5 and getattr(cfg, "lidar", "psst") != "conventional":  # (warned)
        shown = (f"{cfg.ones_ratio:g}" if isinstance(cfg.ones_ratio, (int, float))
                 else repr(cfg.ones_ratio))  # (None was a TypeError here, a review)
        raise ConfigError(f"--ones-ratio {shown} applies to --code random only: "
                          f"{_fixed_ones_text(cfg)}")


def _fixed_ones_text(cfg) -> str:
    """What fixes the ones of an m-sequence or a Gold code, for the refusal of a
    ``ones_ratio``: a Gold code's count depends on its member (992 of 2047 bits for the
    default member 2, not the ``(length + 1) / 2`` an m-sequence has), so it is counted."""
    if cfg.code == "mseq":
        return "an m-sequence has (length + 1) / 2 ones"
    if cfg.code != "gold":
        return f"a {cfg.code} code has a fixed share of ones"
    index = getattr(cfg, "code_index", None)
    index = CODES.get("gold").defaults["index"] if index is None else index
    try:
        from .sequences import make_code

        ones = int(make_code("gold", cfg.code_length, index=index).sum())
    except (ConfigError, TypeError, ValueError):  # an invalid index is refused elsewhere
        return "a Gold code has a share of ones fixed by its family member, near one half"
    return (f"a Gold code has a share of ones fixed by its family member ({ones} ones of "
            f"{cfg.code_length} bits for member {index})")


_MAKE = "spslidar.codes.sequences:make_code"

#: code families by name (the ``code`` config key / ``--code`` option); each entry's target
#: makes one code: ``target(kind, length, ones_ratio, rng, index)``
CODES = Registry("code family", "code")
CODES.add("mseq", _MAKE, "m-sequence", "maximal-length sequence, length 2^n - 1 (default)",
          validate=_validate_fixed_ratio, index=0)
CODES.add("gold", _MAKE, "Gold code", "Gold sequence of a preferred pair, length 2^n - 1, "
          "n not divisible by 4 (--code-index: member 2, the first Gold code, by default; "
          "members 0 and 1 are the pair's two m-sequences)", validate=_validate_fixed_ratio,
          index=2)
CODES.add("random", _MAKE, "Bernoulli code", "iid bits with a chosen share of ones "
          "(--ones-ratio)", validate=_validate_length, index=0)


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(__all__))
