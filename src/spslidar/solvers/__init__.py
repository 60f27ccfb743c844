"""Problem-agnostic solvers for eq. (18): FISTA, TwIST, TVAL3, GPSR.

:data:`SOLVERS` lists them by import path, with the defaults the pipeline uses (``iterations``,
``lam_scale``, the ``regulariser`` that ``auto`` picks) and a ``validate`` hook for the
regularisers each accepts. The registry is complete on ``import spslidar.solvers``; a solver's
module is imported when its entry is loaded (:func:`get_solver`, ``SOLVERS.load``). The
numbers given here are the single copy: each solver class reads its ``default_iterations``,
``default_lam_scale`` and ``default_regulariser`` from its entry
(:func:`~spslidar.solvers.base.registered_defaults`).

Every solver is step-wise (``setup`` / ``step`` / ``done`` / ``run`` / ``finish``, see
:class:`Solver`); ``Solver(stop=..., threads=...).solve(A, y, reg, lam, x0=None)`` returns
``(x, info)``.

``import spslidar.solvers`` imports neither NumPy nor SciPy (``spslidar run --help`` and config
validation need only the registry): the names of :mod:`spslidar.solvers.base` re-exported here
are loaded on first access.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from ..errors import ConfigError
from ..registry import Registry

if TYPE_CHECKING:  # pragma: no cover
    from .base import (
        Monitor,
        SolveInfo,
        Solver,
        StopRule,
        available_solvers,
        get_solver,
        progress,
        register,
        solve,
    )

__all__ = [
    "SOLVERS",
    "Monitor",
    "Solver",
    "SolveInfo",
    "StopRule",
    "available_solvers",
    "get_solver",
    "progress",
    "register",
    "solve",
]

_FROM_BASE = frozenset(__all__) - {"SOLVERS"}


def __getattr__(name: str) -> Any:
    if name in _FROM_BASE:
        from . import base

        return getattr(base, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted(set(globals()) | _FROM_BASE)


def _regulariser_in(allowed: tuple[str, ...], message: str):
    """A ``validate(cfg)`` hook accepting the regularisers ``allowed`` (``cfg.regulariser``)."""

    def validate(cfg: Any) -> None:
        if getattr(cfg, "regulariser", "auto") not in allowed:
            raise ConfigError(message)

    return validate


#: the solvers, by name (``--solver``)
SOLVERS = Registry("solver", "solver")
SOLVERS.add("fista", "spslidar.solvers.fista:FISTA", "FISTA",
            "FISTA, accelerated proximal gradient (default)",
            iterations=60, lam_scale=0.3, regulariser="tv")
SOLVERS.add("twist", "spslidar.solvers.twist:TwIST", "TwIST",
            "TwIST, two-step iterative shrinkage (the paper's)",
            iterations=60, lam_scale=0.3, regulariser="tv")
SOLVERS.add("tval3", "spslidar.solvers.tval3:TVAL3", "TVAL3",
            "TVAL3, augmented Lagrangian for TV (regulariser tv)",
            validate=_regulariser_in(
                ("auto", "tv"),
                "the tval3 solver minimises total variation: use --regulariser tv"),
            iterations=100, lam_scale=0.3, regulariser="tv")
SOLVERS.add("gpsr", "spslidar.solvers.gpsr:GPSR", "GPSR",
            "GPSR-BB, gradient projection for l1 (regulariser l1 or wavelet)",
            validate=_regulariser_in(
                ("auto", "l1", "wavelet"),
                "the gpsr solver minimises an l1 norm: use --regulariser l1 or wavelet"),
            iterations=120, lam_scale=0.3, regulariser="wavelet")
