"""Stages of your own, from outside the package: ``--plugin MODULE`` or ``SPSLIDAR_PLUGINS``.

A plugin is a Python module that registers stages when it is imported (``CODES.add(...)``,
``PATTERNS.add(...)``, ``DETECTORS.add(...)``, ``SOLVERS.add(...)``, ``ESTIMATORS.add(...)``,
``REGULARISERS.add(...)``, ``SCENES.add(...)``, each with the object itself: see
``docs/architecture.md``). ``spslidar --plugin mystages run --solver mine ...`` imports it
before the command line is read, so its stages are among the choices and their options have
flags; ``SPSLIDAR_PLUGINS`` (modules or ``.py`` files, separated by commas) does the same, and
``--plugin`` sets it, so the worker processes of ``sweep --jobs N`` and ``reproduce --jobs N``
import the plugins too (an audit of 2026-11-28 found no way to reach a plugin from the command
line, and a sweep's workers without it: every point "unknown code").

Written here: entry points (``importlib.metadata``) would need the plugin installed as a
distribution; a researcher's module beside their data needs only a name or a path.
"""

from __future__ import annotations

import hashlib
import importlib
import importlib.util
import os
import sys
from pathlib import Path

from .errors import ConfigError, raised_text

__all__ = ["ENV", "code_fingerprint", "load_plugins", "plugin_specs", "raised_in_plugin", "where"]

#: the environment variable of the plugins to import (modules or ``.py`` files, commas)
ENV = "SPSLIDAR_PLUGINS"

_LOADED: dict[str, object] = {}
#: the plugins being imported now, innermost last (their keys in ``_LOADED``)
_IMPORTING: list[str] = []
#: the errors of the environment's plugins that failed to import with ``import spslidar``
FAILED: list[str] = []


def plugin_specs(value: str | None = None) -> list[str]:
    """The plugins named in ``value`` (default: :data:`ENV`), in order, without repeats."""
    raw = os.environ.get(ENV, "") if value is None else value
    out: list[str] = []
    for part in raw.split(","):
        part = part.strip()
        if part and part not in out:
            out.append(part)
    return out


def _import(spec: str):
    """Import one plugin: a ``.py`` file by its path, else a module by its dotted name."""
    if spec.endswith(".py"):
        path = Path(spec).expanduser().resolve()
        if not path.is_file():
            raise ConfigError(f"plugin {spec}: no such file")
        name = f"spslidar_plugin_{path.stem}"
        if str(path.parent) not in sys.path:
            # (its own sibling modules: `import helpers` beside mystages.py failed, where
            # `python mystages.py` finds them, an audit)
            sys.path.append(str(path.parent))
        module_spec = importlib.util.spec_from_file_location(name, path)
        module = importlib.util.module_from_spec(module_spec)
        sys.modules[name] = module
        try:
            module_spec.loader.exec_module(module)
        except BaseException:
            sys.modules.pop(name, None)
            raise
        return module
    return importlib.import_module(spec)


def importing() -> str:
    """The plugin being imported now ('' outside one), as :func:`load_plugins` names it: the
    registry records it in each entry, so that a stage a plugin package's submodule
    registers is known to be that plugin's (a fresh process's check was skipped for it
    without a word, an audit of plugins)."""
    return _IMPORTING[-1] if _IMPORTING else ""


def _place(frame) -> str:
    """`` (file.py:LINE)`` of a traceback frame."""
    return f" ({Path(frame.filename).name}:{frame.lineno})"


def where(exc: BaseException) -> str:
    """`` (file.py:LINE)`` of the innermost frame an exception came from ('' without one):
    a plugin's error said in one line still says where it is."""
    import traceback

    # (not the import machinery's own frames: "(<frozen importlib._bootstrap>:1140)" for a
    # module that is not there; nor the registry's, whose refusal of a declaration is the
    # caller's line)
    machinery = (str(Path(importlib.__file__).parent), __file__,
                 str(Path(__file__).with_name("registry.py")))
    frames = [f for f in traceback.extract_tb(exc.__traceback__)
              if not (f.filename.startswith("<") or f.filename.startswith(machinery))]
    return _place(frames[-1]) if frames else ""


def _loaded_files() -> list[Path]:
    """The resolved files of the loaded plugins (a package plugin's ``__init__.py``)."""
    return [Path(m.__file__).resolve() for m in _LOADED.values()
            if getattr(m, "__file__", None)]


def raised_in_plugin(exc: BaseException) -> str | None:
    """`` (file.py:LINE)`` of the last frame of a loaded plugin's own code in ``exc``'s
    traceback, or ``None`` where none of it ran there: an error raised while a researcher's
    stage ran, which the command line says in one line rather than as a traceback (an audit
    of 2026-11-29: ``--scene disc:abc``, a pattern factory's wrong shape and a solver
    without its monitor each ended in one)."""
    import traceback

    files = {str(f) for f in _loaded_files()}
    if not files:
        return None
    found = None
    for frame in traceback.extract_tb(exc.__traceback__):
        try:
            if str(Path(frame.filename).resolve()) in files:
                found = frame
        except (OSError, ValueError):  # pragma: no cover - an unresolvable frame name
            continue
    return None if found is None else _place(found)


def load_plugins(specs: list[str] | None = None, export: bool = False) -> list[str]:
    """Import the plugins ``specs`` (default: those of :data:`ENV`), each once.

    Parameters
    ----------
    specs : list of str, optional
        Dotted module names (importable from ``sys.path``: the working folder included) or
        paths to ``.py`` files.
    export : bool
        Also add them to :data:`ENV`, so that worker processes import them.

    Returns
    -------
    list of str
        The plugins now loaded.

    Raises
    ------
    ConfigError
        A plugin that cannot be found or fails to import, in one line with its error.
    """
    specs = plugin_specs() if specs is None else list(specs)
    for spec in specs:
        key = str(Path(spec).expanduser().resolve()) if spec.endswith(".py") else spec
        if key in _LOADED:
            continue
        if not spec.endswith(".py") and "" not in sys.path and os.getcwd() not in sys.path:
            sys.path.append(os.getcwd())  # (a module beside the data, as python -m finds it)
        _IMPORTING.append(key)
        try:
            _LOADED[key] = _import(key if spec.endswith(".py") else spec)
        except ConfigError:
            raise
        except (Exception, SystemExit) as exc:  # a plugin's own error: one line, its type
            # (a SystemExit too: `sys.exit(0)` at a plugin's import made every command a
            # silent exit 0, and `import spslidar` under SPSLIDAR_PLUGINS ended the process;
            # an outside audit of 2026-12-02)
            raise ConfigError(f"plugin {spec} failed to import: {raised_text(exc)}"
                              f"{where(exc)}") from None
        finally:
            _IMPORTING.pop()
    if export and specs:
        keys = [str(Path(s).expanduser().resolve()) if s.endswith(".py") else s for s in specs]
        os.environ[ENV] = ",".join(plugin_specs(",".join([*plugin_specs(), *keys])))
    return list(_LOADED)


def _fingerprint_files(package: Path) -> set[Path]:
    """The files :func:`code_fingerprint` reads: the package's modules and data, the loaded
    plugins and the modules imported from their folders."""
    plugin_files = _loaded_files()
    # (with the data the package ships, its built-in scenes: regenerated, they left the
    # cache's old numbers in a sweep's results, an audit of 2026-11-29)
    files = set(package.rglob("*.py")) | set((package / "data").glob("*")) | set(plugin_files)
    folders = {f.parent for f in plugin_files}
    if folders:
        for module in list(sys.modules.values()):
            name = getattr(module, "__file__", None)
            if not name:
                continue
            try:
                path = Path(name).resolve()
            except (OSError, ValueError):  # pragma: no cover - an unresolvable module file
                continue
            if ("site-packages" not in path.parts and "dist-packages" not in path.parts
                    and any(folder in path.parents for folder in folders)):
                files.add(path)  # (a plugin beside a venv: not the venv's libraries)
    return files


def code_fingerprint() -> str:
    """The code a run's result depends on, as 16 hex digits: the SHA-256 of spslidar's version,
    the bytes of every module of the package and of the data it ships (``spslidar/data``: the
    built-in scenes), and those of every loaded plugin and of the modules imported from a
    plugin's folder (its helpers).

    The run caches of ``sweep`` and ``reproduce`` record it and read a cached run only under
    the same fingerprint, so a plugin edited between two sweeps, or spslidar upgraded or edited,
    runs its points again (with the same seeds, so on the same noise) instead of returning the
    old code's results (a known limit of stop 51: a plugin's bug fixed and the sweep run again
    gave the buggy code's rows, from the cache). NumPy's or SciPy's version is not in it:
    results across library releases agree to float tolerance, not bit for bit, and a cache is
    not a claim of either. A module a worker imports that the parent never did is not seen.
    """
    from .version import __version__

    package = Path(__file__).resolve().parent
    files = _fingerprint_files(package)
    digest = hashlib.sha256(__version__.encode())
    for path in sorted(files):
        try:
            data = path.read_bytes()
        except OSError:  # a module deleted since it was imported: its name still counts
            data = b""
        # named inside its folder: the same code cloned elsewhere keeps its cache
        label = path.relative_to(package) if package in path.parents else Path(path.name)
        digest.update(label.as_posix().encode("utf-8", "surrogateescape") + b"\0")
        digest.update(hashlib.sha256(data).digest())
    return digest.hexdigest()[:16]
