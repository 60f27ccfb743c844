"""A simulated or measured acquisition ready to reconstruct (:class:`Measurement`), the
config keys that change only its processing, and how a config is resolved.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..config import Config
from ..errors import ConfigError
from ..patterns import PatternOperator
from .acquisition import Acquisition

#: config keys that change only the processing, not the simulated measurement
PROCESSING_KEYS = frozenset({
    "auto_gate", "qcr", "qcr_form", "solver", "regulariser", "lam", "lam_scale", "iterations",
    "tol", "subbin", "nonneg", "depth", "max_memory", "max_time",
})


def processing_keys() -> frozenset[str]:
    """:data:`PROCESSING_KEYS` and the options the registered solvers and depth estimators
    declare (a plugin's too): what changes the processing of a measurement, not the
    measurement (a plugin estimator's option was "unknown" to ``reconstruct`` and split a
    sweep's seeds, an audit)."""
    from ..config import registries

    regs = registries()
    return PROCESSING_KEYS | frozenset(regs["solver"].options()) | frozenset(
        regs["depth"].options())


def check_processing_keys(processing: dict[str, Any], caller: str, fixed: str) -> None:
    """Refuse keyword arguments of ``caller`` that are not :data:`PROCESSING_KEYS`, in one
    line: an unknown key with its did-you-mean hint, a configuration key the caller cannot
    change with ``fixed``, the caller's own sentence for it (``{keys}`` stands for them)."""
    keys = processing_keys()
    bad = {k.replace("-", "_") for k in processing} - keys
    if not bad:
        return
    from dataclasses import fields

    from ..config import close_names, stage_options

    # (a stage's option, a detector's dead_time or a plugin code's, is the measurement's
    # key too: it was "unknown key 'dead_time'" where noise=5 was "cannot change", an
    # outside audit of a plugin developer)
    unknown = sorted(bad - {f.name for f in fields(Config)} - set(stage_options()))
    if unknown:
        said = ", ".join(
            f"{k!r}" + (f" (did you mean {' or '.join(map(repr, close))}?)"
                        if (close := close_names(k, keys)) else "")
            for k in unknown)
        raise ConfigError(f"{caller}: unknown key {said}; it takes "
                          f"{', '.join(sorted(keys))}")
    raise ConfigError(fixed.format(keys=", ".join(sorted(bad))))


def unchanged_keys(config: Config, keys: dict[str, Any]) -> dict[str, Any]:
    """The keyword arguments of ``keys`` that are not :data:`PROCESSING_KEYS` and whose value
    is the one ``config`` already holds (as :class:`Config` validates it: ``noise=5`` is the
    measurement's ``5.0``), under their names as given: what ``reconstruct(meas, **keys)``
    may take without simulating again. A value ``config`` refuses counts as changed."""
    from ..errors import SpslidarError

    same: dict[str, Any] = {}
    held = config.to_dict()
    processing = processing_keys()
    for key, value in keys.items():
        name = key.replace("-", "_")
        if name in processing or name not in held:
            continue
        try:
            if config.replace(**{name: value}).to_dict() == held:
                same[key] = value
        except SpslidarError:  # refused: "cannot change" says the rest
            continue
    return same


@dataclass(eq=False)
class Measurement:
    """A simulated acquisition: the matched-filter outputs of every pattern over the gate,
    and everything needed to reconstruct them (see :func:`measure`, :func:`reconstruct`).

    Its delays (``lags``, ``ulags``, ``inverse``) are read-only: every result reconstructed
    from it shares them (``result.lags``), and a notebook's ``r.lags -= r.lags[0]`` had made
    the next reconstruction's RMSE 19.9 m for 0.26 (an audit of 2026-11-29). Equality is
    identity; the repr is a summary."""

    config: Config
    scene: Any
    acq: Acquisition
    gate: tuple[float, float]
    lags: np.ndarray  # absolute gated delays (bins)
    ulags: np.ndarray  # distinct delays modulo the code period
    inverse: np.ndarray  # lags -> index into ulags
    patterns: PatternOperator
    sim: dict[str, np.ndarray]
    probe_seed: np.random.SeedSequence
    warnings: list[str]
    timing: dict[str, float]
    #: the processing keys the user asked for with the measurement (``measure(nonneg=True)``):
    #: what :func:`~spslidar.pipeline.plan.asked_notes` reads, beside reconstruct's own
    asked: dict = field(default_factory=dict)

    def __post_init__(self) -> None:
        for name in _DELAYS:
            object.__setattr__(self, name, _frozen(getattr(self, name)))
        # what it was simulated with, held against later edits (:meth:`check_unchanged`)
        object.__setattr__(self, "_made", self.config.to_dict())
        object.__setattr__(self, "_sealed", True)

    def __setattr__(self, name: str, value) -> None:
        # (`m.lags = m.lags + 5` moved every later depth by 7.5 cm without a word, an audit
        # of 2026-12-01; the patterns stay assignable, as a test of their checks does)
        if name in _SEALED and self.__dict__.get("_sealed"):
            raise AttributeError(f"a measurement's {name} is what it was simulated with: "
                                 f"simulate again with measure() to change it")
        object.__setattr__(self, name, value)

    def __setstate__(self, state: dict) -> None:  # (pickle gives arrays back writable)
        self.__dict__.update(state)
        self.__post_init__()

    def check_unchanged(self) -> None:
        """A one-line :class:`~spslidar.errors.ConfigError` where the measurement's config
        was edited after it was simulated (``m.config.noise = 7`` was reconstructed and
        recorded as noise 7 for data simulated at 2, an audit of 2026-12-01): processing keys
        are given to :func:`reconstruct` instead, anything else needs a new ``measure()``."""
        from ..errors import ConfigError

        now = self.config.to_dict()
        changed = [k for k in sorted(set(now) | set(self._made))
                   if now.get(k) != self._made.get(k)]
        if changed:
            what = ", ".join(f"{k} {self._made.get(k)!r} -> {now.get(k)!r}"
                             for k in changed[:3])
            raise ConfigError(f"this measurement's config was changed after it was simulated "
                              f"({what}): give processing keys to reconstruct(), and "
                              f"simulate again with measure() for anything else")

    def __repr__(self) -> str:
        c = self.config
        return (f"Measurement({c.scene!r}, {c.size}x{c.size}, {self.patterns.shape[0]} "
                f"{c.patterns} patterns, gate {self.gate[0]:g}-{self.gate[1]:g} m, "
                f"{int(np.size(self.lags))} lags, seed {c.seed})")


_DELAYS = ("lags", "ulags", "inverse")
#: what a measurement holds from its simulation and cannot be rebound once made
_SEALED = ("config", "scene", "acq", "gate", *_DELAYS, "sim", "probe_seed")


def _frozen(arr):
    """``arr`` read-only (a NumPy array; another backend's is left as it is): a view, so the
    caller's own array stays writable."""
    if isinstance(arr, np.ndarray):
        arr = arr.view()
        arr.flags.writeable = False
    return arr


def asked_keys(config, overrides) -> dict[str, Any]:
    """The keys a user set for ``run(config, **overrides)``: the overrides and, where the
    config is a mapping or a TOML file, its keys (a :class:`Config` holds no record of which
    of its values were asked for: {})."""
    import os
    from collections.abc import Mapping

    from ..config import read_toml

    base: dict[str, Any] = {}
    if isinstance(config, Mapping):
        base = dict(config)
    elif isinstance(config, (str, os.PathLike)) and os.fspath(config).lower().endswith(
            ".toml"):
        base = read_toml(config)
    return {str(k).replace("-", "_"): v for k, v in {**base, **overrides}.items()}


def _resolve(config, overrides) -> Config:
    """The config of ``run(config, **overrides)``: a :class:`Config`, a mapping of its keys,
    None (the defaults), a run's TOML file (``run('myrun.toml')``, as ``spslidar run
    --config``; it was read as a scene's name, "unknown scene": an outside audit of
    2026-12-03) or a scene (a built-in name or a file path: ``run('camera')``)."""
    import os
    from collections.abc import Mapping

    if isinstance(config, (str, os.PathLike)):
        if os.fspath(config).lower().endswith(".toml"):
            return Config.from_toml(config, **overrides)
        config, overrides = None, {"scene": os.fspath(config), **overrides}
    if config is None:
        cfg = Config.from_dict(overrides)
    elif isinstance(config, Config):
        cfg = config.replace(**overrides)  # a copy: the caller's later edits stay theirs
    elif isinstance(config, Mapping):
        cfg = Config.from_dict(dict(config), **overrides)  # (code-length, then code_length=)
    else:
        from ..errors import ConfigError

        raise ConfigError(f"the first argument must be a Config, a dict of its keys or a scene "
                          f"name or path, got {type(config).__name__}")
    return cfg
