"""Detector models (the stage after the forward model) and their registry; the noise terms of
equations (4), (9) and the Poisson counting they share are in :mod:`spslidar.detectors.counting`.

``DETECTORS.load(name)(**options)`` is a :class:`~spslidar.detectors.base.DetectorModel`;
``linear`` is the paper's counter (the default).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from ..registry import Option, Registry, lazy_exports

if TYPE_CHECKING:
    from .base import DetectorModel

__all__ = ["DETECTORS", "DetectorModel", "build_detector"]

# the models import numpy: re-exported on first access (the registry stays light)
__getattr__ = lazy_exports(__name__, {"DetectorModel": "base"})

#: detector models by name (the ``detector`` config key / ``--detector`` option)
DETECTORS = Registry("detector model", "detector")

#: the dead time: the GMAPD's, and the linear counter's pile-up report's
DEAD_TIME = Option("dead_time", 50e-9, "dead time after a detection (linear: only for the "
                   "pile-up report)", "s", lo=0.0, hi=1e-3,
                   why="GMAPD dead times are 10 ns to 10 us; a millisecond is a unit mistake")
_JITTER_WHY = "a microsecond of timing jitter blurs the range by 150 m"

DETECTORS.add("linear", "spslidar.detectors.linear:LinearDetector", "linear counter",
              "the paper's linear Poisson counter, no dead time (default)",
              options=(DEAD_TIME,))


def _check_gmapd(cfg) -> None:
    """Config rules of the ``gmapd`` model (light: no numpy)."""
    from ..errors import ConfigError

    if cfg.dead_time and cfg.dead_time * cfg.bit_rate < 1 - 1e-9:
        raise ConfigError(f"--dead-time ({cfg.dead_time:g} s) must be 0 or at least one TDC bin "
                          f"(1 / --bit-rate = {1 / cfg.bit_rate:g} s) for --detector gmapd")
    if cfg.afterpulse_prob > 0 and not cfg.afterpulse_delay > 0:
        raise ConfigError("--afterpulse-delay must be positive when --afterpulse-prob > 0")
    # an option that does nothing without its partner is said, not ignored
    for opt, partner, lone in (("jitter_tail", "jitter_tail_weight", "the share of photons in "
                                "the tail"), ("jitter_tail_weight", "jitter_tail", "the tail's "
                                "mean"), ("afterpulse_delay", "afterpulse_prob", "the "
                                "probability of an afterpulse")):
        if getattr(cfg, opt, 0) > 0 and not getattr(cfg, partner, 0) > 0:
            raise ConfigError(f"--{opt.replace('_', '-')} does nothing without "
                              f"--{partner.replace('_', '-')} ({lone}) above 0")
    widest = max(getattr(cfg, "jitter", 0.0), getattr(cfg, "jitter_tail", 0.0))
    if cfg.lidar == "psst" and widest * cfg.bit_rate > cfg.code_length / 2:
        raise ConfigError(f"--jitter or --jitter-tail of {widest:g} s is wider than half the "
                          f"code period ({cfg.code_length} bins): no range can be resolved "
                          f"through it")


DETECTORS.add("gmapd", "spslidar.detectors.gmapd:GMAPD", "GMAPD",
              "free-running Geiger-mode APD: non-paralysable --dead-time, --jitter, "
              "--afterpulse-prob, pile-up corrected before the matched filter "
              "(--pileup-correction)", validate=_check_gmapd, context=("bin_width",),
              options=(
                  DEAD_TIME,
                  Option("jitter", 0.0, "standard deviation of the Gaussian timing jitter",
                         "s", lo=0.0, hi=1e-6, why=_JITTER_WHY),
                  Option("jitter_tail", 0.0, "mean of the IRF's exponential tail, with weight "
                         "--jitter-tail-weight", "s", lo=0.0, hi=1e-6, why=_JITTER_WHY),
                  Option("jitter_tail_weight", 0.0, "share of photons in the exponential tail",
                         lo=0.0, hi=1.0),
                  Option("afterpulse_prob", 0.0, "probability that an avalanche causes an "
                         "afterpulse", lo=0.0, hi=1.0, hi_open=True),
                  Option("afterpulse_delay", 0.0, "mean afterpulse delay after re-arming, "
                         "required (> 0) with --afterpulse-prob", "s",
                         lo=0.0, hi=1e-3, why="afterpulses follow within microseconds"),
                  Option("pileup_correction", True, "correct each histogram for pile-up "
                         "before the matched filter", kind=bool, param="correction"),
              ))


def build_detector(name: str, **options) -> DetectorModel:
    """The detector model registered under ``name``, built with ``options``; its ``name``
    is the registered one (a plugin's subclass that forgot its own was recorded and named in
    its errors as its base's, ``linear``, an outside audit; as solvers are recorded)."""
    det = DETECTORS.load(name)(**options)
    name = DETECTORS.canonical(name)
    if getattr(det, "name", None) != name:
        try:
            det.name = name
        except AttributeError:  # (a read-only name: kept as the model says it)
            pass
    return det


def __dir__() -> list[str]:
    # the lazy names too, so dir() and a REPL's completion list them (an audit of 2026-11-30)
    return sorted(set(globals()) | set(__all__))
