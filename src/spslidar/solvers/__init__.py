"""Problem-agnostic solvers for eq. (18): FISTA, TwIST, TVAL3, GPSR."""

from .base import (
    SolveInfo,
    Solver,
    StopRule,
    available_solvers,
    get_solver,
    register,
    solve,
)

__all__ = [
    "Solver",
    "SolveInfo",
    "StopRule",
    "available_solvers",
    "get_solver",
    "register",
    "solve",
]
