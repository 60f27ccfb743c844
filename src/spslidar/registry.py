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
import re
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from typing import Any

from .errors import ConfigError

__all__ = ["RESERVED_NAMES", "Entry", "Option", "Registry", "lazy_exports",
           "registrations"]


@dataclass(frozen=True)
class Option:
    """An option a stage declares: the config key, the CLI flag ``--name-with-dashes``, its
    help, unit, default and the values it admits. ``Config`` accepts it, validates it and
    records it in ``metrics.json``; the CLI adds its flag; the stage receives it as the
    keyword ``param`` (default: ``name``) when it is built.

    Attributes
    ----------
    name : str
        Config key (``snake_case``).
    default : object
        Value when not given.
    help : str
        One line for ``--help`` and the docs.
    unit : str
        Physical unit (``"s"``, ``"m"``, ``""`` for a pure number).
    kind : type
        ``float``, ``int``, ``bool`` (``on``/``off``/``true``/``false`` accepted) or ``str``.
    lo, hi : float, optional
        Bounds of a number; ``lo_open`` / ``hi_open`` exclude them.
    why : str
        The physical reason of the bounds, said when a value is refused.
    choices : tuple, optional
        The admissible values of a ``str`` option.
    param : str, optional
        The stage's keyword for it, when it differs from ``name``.
    """

    name: str
    default: Any
    help: str = ""
    unit: str = ""
    kind: type = float
    lo: float | None = None
    hi: float | None = None
    lo_open: bool = False
    hi_open: bool = False
    why: str = ""
    choices: tuple | None = None
    param: str | None = None

    @property
    def flag(self) -> str:
        """The command-line flag, ``--name-with-dashes``."""
        return "--" + self.name.replace("_", "-")

    def describe(self) -> str:
        """Help with unit and default, for ``--help``."""
        unit = f" [{self.unit}]" if self.unit else ""
        default = ("on" if self.default else "off") if self.kind is bool else self.default
        return f"{self.help}{unit} (default {default})"

    def check(self, value: Any) -> Any:
        """``value`` normalised to ``kind``; a value out of bounds or of the wrong type is a
        one-line :class:`~spslidar.errors.ConfigError`."""
        import math

        if self.kind is bool:
            if isinstance(value, str) and value.lower() in ("on", "off", "true", "false"):
                return value.lower() in ("on", "true")
            if isinstance(value, bool):
                return value
            raise ConfigError(f"{self.flag} must be on or off, got {value!r}")
        if self.kind is str:
            if self.choices is not None and value not in self.choices:
                raise ConfigError(f"{self.flag} must be one of {', '.join(self.choices)}, "
                                  f"got {value!r}")
            return str(value)
        if getattr(value, "ndim", None) == 0 and hasattr(value, "item"):
            value = value.item()  # a NumPy scalar, as Python's (np.bool_ as bool)
        if isinstance(value, (bool, str, bytes)):
            # (TOML's window = true ran with 1 and window = "3" with 3, where Config's own
            # iterations = true is refused, an audit of plugins; the command line's text is
            # a number already, read by its flag's argparse type)
            quoted = " (in TOML: a number without quotes)" if isinstance(value, str) else ""
            raise ConfigError(f"{self.flag} must be a number, got {value!r}{quoted}")
        if not isinstance(value, (int, float)):
            try:
                value = float(value)
            except (TypeError, ValueError):
                raise ConfigError(f"{self.flag} must be a number, got {value!r}") from None
        if not math.isfinite(value):
            raise ConfigError(f"{self.flag} must be finite, got {value}")
        if self.kind is int:
            if float(value) != int(value):
                raise ConfigError(f"{self.flag} must be an integer, got {value}")
            value = int(value)
        else:
            value = float(value)
        low = self.lo is not None and (value < self.lo or (self.lo_open and value == self.lo))
        high = self.hi is not None and (value > self.hi or (self.hi_open and value == self.hi))
        if low or high:
            lo = "-inf" if self.lo is None else f"{self.lo:g}"
            hi = "inf" if self.hi is None else f"{self.hi:g}"
            span = (f"{'(' if self.lo_open or self.lo is None else '['}{lo}, {hi}"
                    f"{')' if self.hi_open or self.hi is None else ']'}")
            unit = f" {self.unit}" if self.unit else ""
            why = f": {self.why}" if self.why else ""
            raise ConfigError(f"{self.flag} must be in {span}{unit}, got {value:g}{why}")
        return value


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
    options : tuple of Option
        The options this choice takes (its constructor's keywords), declared once: the
        config, the CLI flags, ``--help`` and ``metrics.json`` follow them.
    origin : str
        The module that registered it (``spslidar.*`` for the built-in stages; a plugin's
        own module otherwise, also where it registers a built-in class under a new name).
    plugin : str
        The plugin (``--plugin``, ``SPSLIDAR_PLUGINS``) whose import registered it, also
        from a module that plugin imports; ``''`` outside a plugin's import.
    kind : str
        What it is (its registry's ``kind``: ``"depth estimator"``), for messages.
    """

    name: str
    target: Any
    display: str = ""
    help: str = ""
    defaults: dict[str, Any] = field(default_factory=dict)
    validate: Callable[[Any], None] | None = None
    options: tuple[Option, ...] = ()
    origin: str = ""
    plugin: str = ""
    kind: str = ""

    def load(self) -> Any:
        """The implementation (imported on first use).

        Raises
        ------
        ConfigError
            A stage registered from outside the package whose ``"module:attribute"`` does
            not import, in one line (``ESTIMATORS.add("x", "nonexistent.module:Thing")`` in a
            plugin was a 42-line ModuleNotFoundError traceback from ``run --depth x``, where
            ``check`` and ``sweep`` said it in one line: an outside audit of 2026-12-02). A
            built-in stage's failure stays a traceback: it is spslidar's bug.
        """
        if not isinstance(self.target, str):
            return self.target
        module, _, attr = self.target.partition(":")
        try:
            obj = importlib.import_module(module)
            for part in attr.split(".") if attr else ():
                obj = getattr(obj, part)
        except Exception as exc:
            if _built_in(self):
                raise
            from .errors import raised_text
            from .plugins import where  # (the line of a module that fails in its own code)

            what = f"{self.kind} {self.name!r}" if self.kind else repr(self.name)
            raise ConfigError(f"{what}, registered as {self.target!r}, does not load: "
                              f"{raised_text(exc)}{where(exc)}") from None
        return obj

    def check(self, cfg: Any) -> None:
        """Run the entry's ``validate`` hook, if any."""
        if self.validate is not None:
            self.validate(cfg)


#: names no stage's option may take: :class:`~spslidar.config.Config`'s own keys and the
#: other options of ``spslidar run`` (``--noise`` of a plugin's detector crashed the command
#: line with argparse's "conflicting option string", an audit of plugins). Written out: the
#: config imports the stages' packages, which import this module (an import of the config
#: here would close a circle); a test holds it to ``Config``'s fields and the flags of ``run``,
#: ``reconstruct`` and ``calibrate``.
RESERVED_NAMES = frozenset({
    "ambient", "auto_gate", "backend", "background_rate", "bit_rate", "code", "code_index",
    "code_length", "compression", "dark_count_rate", "depth", "depth_max", "depth_min",
    "detector", "device", "dtype", "fairness", "hadamard_order", "hadamard_realisation", "irf",
    "iterations", "lam", "lam_scale", "lidar", "max_memory", "max_time", "noise",
    "noise_split", "noiseless", "nonneg", "ones_ratio", "pattern_sigma", "patterns", "periods",
    "pulse_width", "qcr", "qcr_form", "range_gate", "regulariser", "rep_rate", "replica",
    "scene", "seed", "signal", "size", "solver", "subbin", "system_delay", "tol",
    "extra", "config", "fov", "no_figure", "out", "overwrite", "save_ptu", "help",
    "no_auto_gate", "no_noiseless", "no_nonneg", "no_qcr", "no_subbin",
    # reconstruct's and calibrate's own flags: the parser builds every command, so a plugin
    # option named as one (settle, new in stop 64) refused every command, run's too (a review)
    "allow_binning", "calibration", "channel", "distance", "marker", "marker_edge", "ptu",
    "first_pattern", "frame", "pattern_size", "repeats", "settle", "sync_channel",
    "sync_divider", "target", "truth", "align_channels",
    # the command line's own flags before the command (--plugin 2.5 was read as a module to
    # import, an audit of 2026-12-01)
    "plugin", "version"})

#: how many times any registry's entries changed (:meth:`Registry.add`, :meth:`Registry.remove`):
#: part of what identifies a simulated measurement that a process keeps
#: (:func:`spslidar.pipeline.shared.simulation_key`), so that a code family registered again
#: under its name simulates anew (``run_shared`` gave the earlier code's data, an audit of
#: 2026-12-01)
_CHANGES = [0]


#: the function that gives the registries a config chooses among
#: (:func:`spslidar.config.registries`), installed by the config when it is imported (this
#: module imports nothing of the stages' or the config's: they import it)
_CHOOSERS: list[Callable[[], dict]] = []


def registrations() -> int:
    """How many times any registry's entries were added or removed in this process."""
    return _CHANGES[0]


def _declaration_fault(opt: Any) -> str:
    """What is wrong with an option's declaration ('' where nothing is): checked where it is
    registered, as a default outside its own bounds failed every run later, those of other
    stages too (an audit of plugins)."""
    if not isinstance(opt, Option):
        return f"{opt!r} is not an Option"
    if not isinstance(opt.name, str) or not re.fullmatch(r"[a-z][a-z0-9_]*", opt.name):
        # (isidentifier() let "halfWidth" through, a flag --halfWidth: an outside audit)
        return (f"its name must be snake_case, lower-case letters, digits and _ (the flag "
                f"--a-b is made from the key a_b), got {opt.name!r}")
    if opt.name in RESERVED_NAMES:
        return "the name is one of spslidar's own config keys or flags: name it otherwise"
    if opt.kind not in (float, int, bool, str):
        return f"its kind must be float, int, bool or str, got {opt.kind!r}"
    try:
        opt.check(opt.default)
    except ConfigError as err:
        return f"its default {opt.default!r} is refused by its own declaration: {err}"
    return ""


def _built_in(entry: Entry) -> bool:
    """Whether spslidar itself registered ``entry`` (a plugin loaded from a file is a module
    named ``spslidar_plugin_<stem>``: not spslidar's, a review of 2026-11-29)."""
    return entry.origin == "spslidar" or entry.origin.startswith("spslidar.")


class Registry:
    """An ordered name -> :class:`Entry` map for one kind of stage.

    Parameters
    ----------
    kind : str
        What the entries are, for messages (``"solver"``, ``"code family"``...).
    option : str
        The config key / CLI option that selects an entry (``"solver"``, ``"code"``...).
    takes_options : bool
        Whether its entries may declare options (:class:`Option`): a registry whose stages
        are built without the config's options (the regularisers, the scenes) refuses them
        at registration, where an option declared would be a key no config could set.
    takes_defaults : bool, optional
        Whether its entries may declare defaults (default: as ``takes_options``; the scenes
        take ``argument=`` and ``example=`` but no options).
    """

    def __init__(self, kind: str, option: str, takes_options: bool = True,
                 takes_defaults: bool | None = None):
        self.kind = kind
        self.option = option
        self.takes_options = takes_options
        self.takes_defaults = takes_options if takes_defaults is None else takes_defaults
        self._entries: dict[str, Entry] = {}
        self._replaced: dict[str, Entry] = {}  # the built-in entries add() replaced

    def add(self, name: str, target: Any, display: str = "", help: str = "",
            validate: Callable[[Any], None] | None = None,
            options: tuple[Option, ...] = (), **defaults: Any) -> Entry:
        """Register ``target`` under ``name`` (replacing an entry of that name).

        An option declared by several entries (``dead_time`` of every detector) must be
        declared alike (same default, kind and bounds): it is one config key. Each
        declaration is checked here (a ``ValueError`` line): a name that is a Python
        identifier and not one of spslidar's own keys (:data:`RESERVED_NAMES`), a kind of
        ``float``, ``int``, ``bool`` or ``str``, and a default its own bounds admit.

        Examples
        --------
        A depth estimator of your own (here the paper's argmax under a new name), held to
        its contract, used by a run and taken back:

        >>> import spslidar
        >>> from spslidar.depth import ESTIMATORS
        >>> from spslidar.depth.argmax import ArgmaxDepth
        >>> from spslidar.testing import check_stage
        >>> class MyArgmax(ArgmaxDepth):
        ...     name = "my-argmax"
        >>> _ = ESTIMATORS.add("my-argmax", MyArgmax, "My argmax", "the paper's ML depth")
        >>> bool(check_stage("depth", "my-argmax"))  # raises AssertionError on a breach
        True
        >>> r = spslidar.run(scene="camera", size=16, code_length=2047, depth="my-argmax")
        >>> r.config.depth, r.depth.shape
        ('my-argmax', (16, 16))
        >>> _ = ESTIMATORS.remove("my-argmax")
        >>> "my-argmax" in ESTIMATORS
        False
        """
        if not name or not isinstance(name, str):
            raise ValueError(f"a {self.kind} needs a non-empty name")
        if not re.fullmatch(r"[A-Za-z0-9][A-Za-z0-9_.+-]*", name):
            # ("my est" and "--mrf" were registered: the second cannot be given as
            # "--depth --mrf", an outside audit of a plugin developer)
            raise ValueError(f"a {self.kind}'s name is letters, digits, '_', '-', '.' or "
                             f"'+', not starting with a sign or a dot: {name!r}")
        twin = [n for n in tuple(self._entries) if n != name and n.casefold() == name.casefold()]
        if twin:  # ("MRF" beside "mrf": which one --depth MRF means depends on the spelling)
            raise ValueError(f"a {self.kind} {name!r} differs from the registered {twin[0]!r} "
                             f"only in case (names are read in any case): name it otherwise")
        refused = ([getattr(o, "name", o) for o in options] if not self.takes_options
                   else []) + (list(defaults) if not self.takes_defaults else [])
        if refused:
            what = "options" if self.takes_defaults else "options or defaults"
            raise ValueError(f"a {self.kind} declares no {what} (no config key or flag would "
                             f"reach them: {', '.join(map(str, refused))} of {name!r}): give "
                             f"its factory fixed values, or register one entry per setting")
        import sys

        # who registered it: the caller, past this module's own decorator (register)
        frame = sys._getframe(1)
        while frame is not None and frame.f_globals.get("__name__") == __name__:
            frame = frame.f_back
        origin = "" if frame is None else str(frame.f_globals.get("__name__", ""))
        own = origin == "spslidar" or origin.startswith("spslidar.")
        seen: set[str] = set()
        for opt in options:
            fault = _declaration_fault(opt)
            if not fault and opt.name in seen:
                # (the first won and the second was ignored without a word: an audit)
                fault = "it is declared twice in this entry's options"
            if not fault and not own:  # (spslidar's own stages: held by its tests)
                fault = self._foreign(opt.name)
            if fault:
                raise ValueError(f"option {getattr(opt, 'name', opt)!r} of {self.kind} "
                                 f"{name!r}: {fault}")
            seen.add(opt.name)
            # (not the entry this one replaces: a notebook cell re-run with another default
            # was refused, with no way back but a new kernel, an audit of 2026-11-29)
            for other in (e for e in self._snapshot() if e.name != name):
                for o in other.options:
                    if o.name == opt.name and (o.default, o.kind, o.lo, o.hi) != (
                            opt.default, opt.kind, opt.lo, opt.hi):
                        raise ValueError(f"option {opt.name!r} of {self.kind} {name!r} differs "
                                         f"from {other.name!r}'s declaration")
        from .plugins import importing

        entry = Entry(name, target, display or name, help, dict(defaults), validate,
                      tuple(options), origin, importing(), self.kind)
        old = self._entries.get(name)
        if old is not None and old.target != entry.target:
            # (a plugin's "fista" replaced the built-in without a word, and metrics.json still
            # said fista; an audit): said, and still done, as this method promises
            import warnings

            warnings.warn(f"the {self.kind} {name!r} ({old.target!r}) is replaced by "
                          f"{entry.target!r}", RuntimeWarning, stacklevel=2)
        if old is not None and _built_in(old) and name not in self._replaced:
            self._replaced[name] = old  # (a plugin's own earlier versions are not kept)
        self._entries[name] = entry
        _CHANGES[0] += 1
        return entry

    def _foreign(self, option: str) -> str:
        """Why ``option`` cannot be declared in this registry ('' where it can): another of
        the registries a config chooses among declares it, and one config key and flag is
        one stage kind's. Refused here, where it is registered: accepted, it made every later
        ``Config()`` of the process a ConfigError, runs that used neither stage too (an
        audit of 2026-12-01). Before :mod:`spslidar.config` is imported nothing is checked
        here, and ``Config()`` refuses such a pair in one line instead."""
        if not _CHOOSERS:  # (no config imported yet: Config() says it, in one line)
            return ""
        others = _CHOOSERS[0]()
        if others.get(self.option) is not self:
            return ""
        for reg in others.values():
            if reg is not self and option in reg.options():
                return (f"--{reg.option} {', '.join(reg.owners(option))} declares it: one "
                        f"config key and flag is one stage kind's, name it otherwise")
        return ""

    def replaced(self, name: str) -> Entry | None:
        """The built-in entry that :meth:`add` replaced under ``name`` (None where none was),
        for a run's record of what it used."""
        return self._replaced.get(name)

    def remove(self, name: str) -> Entry:
        """Take back what :meth:`add` registered under ``name``: a built-in stage it replaced
        comes back, or the name goes (a notebook cell run twice, then taken back, leaves
        nothing of it). A built-in stage itself is not removed (the defaults name them).
        Returns the entry removed."""
        entry = self.get(name)
        if name in self._replaced:
            self._entries[name] = self._replaced.pop(name)
        elif _built_in(entry):
            raise ConfigError(f"the {self.kind} {name!r} is built in and cannot be removed "
                              f"(register another under its name to replace it)")
        else:
            del self._entries[name]
        _CHANGES[0] += 1
        return entry

    def register(self, name: str, display: str = "", help: str = "",
                 validate: Callable[[Any], None] | None = None,
                 options: tuple[Option, ...] = (), **defaults: Any):
        """Decorator form of :meth:`add` for objects defined in user code."""

        def deco(obj):
            self.add(name, obj, display, help, validate, options, **defaults)
            return obj

        return deco

    def options(self) -> dict[str, Option]:
        """Every option any entry declares, by config key (first declaration)."""
        out: dict[str, Option] = {}
        for entry in self._snapshot():
            for opt in entry.options:
                out.setdefault(opt.name, opt)
        return out

    def owners(self, option: str) -> list[str]:
        """The entries that take ``option``."""
        return [e.name for e in self._snapshot()
                if any(o.name == option for o in e.options)]

    def get(self, name: str) -> Entry:
        """The entry for ``name``; an unknown name is a one-line :class:`ConfigError`."""
        try:
            return self._entries[name]
        except (KeyError, TypeError):
            opt = self.option.replace("_", "-")
            if not isinstance(name, str):  # e.g. a TOML table [detector] with its options
                example = (': dead_time = 1e-8 beside detector = "gmapd"'
                           if opt == "detector" else "")
                raise ConfigError(f"{opt} must be a name, one of {', '.join(self.names())}, "
                                  f"got {type(name).__name__} {name!r} (a stage's options are "
                                  f"keys of their own beside its name, not a table"
                                  f"{example})") from None
            from .plugins import FAILED

            failed = f" ({'; '.join(FAILED)})" if FAILED else ""
            raise ConfigError(f"unknown {opt} {name!r}; choose one of "
                              f"{', '.join(self.names())}{failed}") from None

    def canonical(self, name: Any) -> Any:
        """``name`` as registered where it differs only in case (``"FISTA"`` -> ``"fista"``,
        as scene names already were read), else ``name`` unchanged, for :meth:`get` to take
        or refuse. (:meth:`add` refuses a name that differs from another only in case.)"""
        if not isinstance(name, str) or name in self._entries:
            return name
        same = [n for n in tuple(self._entries) if n.casefold() == name.casefold()]
        return same[0] if len(same) == 1 else name

    def load(self, name: str) -> Any:
        """The implementation registered under ``name``."""
        return self.get(name).load()

    def names(self) -> tuple[str, ...]:
        return tuple(self._entries)

    def help_text(self) -> str:
        """``name: help`` for each entry, for ``--help``."""
        return "; ".join(f"{e.name}: {e.help}" if e.help else e.name
                         for e in self._snapshot())

    def __contains__(self, name: object) -> bool:
        return name in self._entries

    def __iter__(self) -> Iterator[Entry]:
        return iter(self._snapshot())

    def _snapshot(self) -> tuple[Entry, ...]:
        """The entries now, as a tuple: a plugin added or removed from another thread while
        they were read was a "dictionary changed size during iteration" RuntimeError (3 of
        2 000 ``Config(...)`` calls, an audit of 2026-11-30); ``tuple`` copies the values in
        one step."""
        return tuple(self._entries.values())

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
