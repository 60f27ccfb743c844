"""Registries of the chain's interchangeable stages (code families, pattern kinds, detector
models, solvers, depth estimators).

Each domain package owns one :class:`Registry` and lists its entries in its ``__init__``.
An entry names its implementation by import path (``"spslidar.solvers.fista:FISTA"``), so
the registry is complete as soon as the (light) domain package is imported, while the numeric
module behind an entry is imported only when the entry is used (``spslidar run --help`` and
config validation never import a solver). An entry carries what the CLI, :class:`Config` and
the report need: a display name, one line of help, defaults, and an optional ``validate``
hook that checks a whole config for that choice (e.g. a code family's admissible lengths).

Adding a stage is one module plus one :meth:`Registry.add` line (or a call from user code:
third-party stages register the same way, with the object itself instead of a path).

No library offers this: entry points (``importlib.metadata``) cover only installed
distributions and would need a reinstall for every change of an in-tree stage.
"""

from __future__ import annotations

import importlib
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from typing import Any

from .errors import ConfigError

__all__ = ["Entry", "Registry", "lazy_exports"]


@dataclass(frozen=True)
class Entry:
    """One registered choice.

    Attributes
    ----------
    name : str
        The key used in configs and on the command line.
    target : str or object
        ``"package.module:attribute"`` (imported on first :meth:`load`) or the object itself.
    display : str
        Human-readable name (reports, figure titles, summaries).
    help : str
        One line for ``--help``.
    defaults : dict
        Per-choice defaults (e.g. a solver's iteration cap and weight scale).
    validate : callable, optional
        ``validate(cfg)`` raises :class:`~spslidar.errors.ConfigError` when the config cannot
        use this choice. Must not import heavy modules.
    """

    name: str
    target: Any
    display: str = ""
    help: str = ""
    defaults: dict[str, Any] = field(default_factory=dict)
    validate: Callable[[Any], None] | None = None

    def load(self) -> Any:
        """The implementation (imported on first use)."""
        if not isinstance(self.target, str):
            return self.target
        module, _, attr = self.target.partition(":")
        obj = importlib.import_module(module)
        for part in attr.split(".") if attr else ():
            obj = getattr(obj, part)
        return obj

    def check(self, cfg: Any) -> None:
        """Run the entry's ``validate`` hook, if any."""
        if self.validate is not None:
            self.validate(cfg)


class Registry:
    """An ordered name -> :class:`Entry` map for one kind of stage.

    Parameters
    ----------
    kind : str
        What the entries are, for messages (``"solver"``, ``"code family"``...).
    option : str
        The config key / CLI option that selects an entry (``"solver"``, ``"code"``...).
    """

    def __init__(self, kind: str, option: str):
        self.kind = kind
        self.option = option
        self._entries: dict[str, Entry] = {}

    def add(self, name: str, target: Any, display: str = "", help: str = "",
            validate: Callable[[Any], None] | None = None, **defaults: Any) -> Entry:
        """Register ``target`` under ``name`` (replacing an entry of that name)."""
        if not name or not isinstance(name, str):
            raise ValueError(f"a {self.kind} needs a non-empty name")
        entry = Entry(name, target, display or name, help, dict(defaults), validate)
        self._entries[name] = entry
        return entry

    def register(self, name: str, display: str = "", help: str = "",
                 validate: Callable[[Any], None] | None = None, **defaults: Any):
        """Decorator form of :meth:`add` for objects defined in user code."""

        def deco(obj):
            self.add(name, obj, display, help, validate, **defaults)
            return obj

        return deco

    def get(self, name: str) -> Entry:
        """The entry for ``name``; an unknown name is a one-line :class:`ConfigError`."""
        try:
            return self._entries[name]
        except (KeyError, TypeError):
            raise ConfigError(f"unknown {self.option.replace('_', '-')} {name!r}; choose one of "
                              f"{', '.join(self.names())}") from None

    def load(self, name: str) -> Any:
        """The implementation registered under ``name``."""
        return self.get(name).load()

    def names(self) -> tuple[str, ...]:
        return tuple(self._entries)

    def help_text(self) -> str:
        """``name: help`` for each entry, for ``--help``."""
        return "; ".join(f"{e.name}: {e.help}" if e.help else e.name
                         for e in self._entries.values())

    def __contains__(self, name: object) -> bool:
        return name in self._entries

    def __iter__(self) -> Iterator[Entry]:
        return iter(self._entries.values())

    def __len__(self) -> int:
        return len(self._entries)

    def __repr__(self) -> str:
        return f"Registry({self.kind!r}: {', '.join(self.names())})"


def lazy_exports(package: str, names: dict[str, str]) -> Callable[[str], Any]:
    """A module ``__getattr__`` (PEP 562) that imports ``names[attr]`` (a submodule of
    ``package``) on first access, so a domain package can hold its registry and re-export
    its numeric API without importing numpy when only the registry is read.

    Parameters
    ----------
    package : str
        The package's ``__name__``.
    names : dict
        Public name -> submodule (relative, e.g. ``"sequences"``) defining it.
    """

    def __getattr__(attr: str) -> Any:
        try:
            sub = names[attr]
        except KeyError:
            raise AttributeError(f"module {package!r} has no attribute {attr!r}") from None
        return getattr(importlib.import_module(f"{package}.{sub}"), attr)

    return __getattr__
