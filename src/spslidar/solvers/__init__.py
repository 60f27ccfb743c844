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


# transitional registry (the lead's; the solver redesign replaces it)
from ..errors import ConfigError as _ConfigError  # noqa: E402
from ..registry import Registry as _Registry  # noqa: E402


def _needs_l1(cfg):
    if cfg.regulariser == "tv":
        raise _ConfigError("the gpsr solver minimises an l1 norm: use --regulariser l1 or "
                           "wavelet")


def _needs_tv(cfg):
    if cfg.regulariser in ("l1", "wavelet"):
        raise _ConfigError("the tval3 solver minimises total variation: use --regulariser tv")


SOLVERS = _Registry("solver", "solver")
SOLVERS.add("fista", "spslidar.solvers.fista:FISTA", "FISTA", "FISTA (default)",
            iterations=60, lam_scale=0.3, regulariser="tv")
SOLVERS.add("twist", "spslidar.solvers.twist:TwIST", "TwIST", "TwIST, the paper's",
            iterations=60, lam_scale=0.3, regulariser="tv")
SOLVERS.add("tval3", "spslidar.solvers.tval3:TVAL3", "TVAL3", "TVAL3", validate=_needs_tv,
            iterations=100, lam_scale=0.3, regulariser="tv")
SOLVERS.add("gpsr", "spslidar.solvers.gpsr:GPSR", "GPSR", "GPSR-BB", validate=_needs_l1,
            iterations=120, lam_scale=0.3, regulariser="wavelet")
