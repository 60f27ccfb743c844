"""Problem-agnostic solvers for equation (18): FISTA, TwIST, TVAL3, GPSR.

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

from .entries import REGULARISERS, SOLVERS, TV_REGULARISERS

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
    "TV_REGULARISERS",
    "REGULARISERS",
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

_FROM_BASE = frozenset(__all__) - {"SOLVERS", "REGULARISERS"}


def __getattr__(name: str) -> Any:
    if name in _FROM_BASE:
        from . import base

        return getattr(base, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted(set(globals()) | _FROM_BASE)
