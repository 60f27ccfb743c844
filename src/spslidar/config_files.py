"""Reading a TOML config file: its bytes (a size cap, a byte-order mark refused), its tables
(``[run]``), the keys that belong to the command line, and the file paths it names, read from
its own folder. :mod:`spslidar.config` re-exports these names (moved out of it, which had grown
past 700 lines).
"""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Any

from .errors import ConfigError

__all__ = ["CLI_ONLY_KEYS", "FILE_KEYS", "MAX_CONFIG_BYTES", "check_toml_bytes",
           "names_a_file", "read_config_bytes", "read_toml", "resolve_file_paths"]

#: a TOML config is a few kilobytes: a file or stream past this is not one
MAX_CONFIG_BYTES = 16 * 2**20


def read_config_bytes(path: Path, what: str = "config file") -> bytes:
    """The bytes of a config file, or of a stream such as bash's ``<(...)`` (it was "not
    found"), read to at most :data:`MAX_CONFIG_BYTES` (``/dev/zero`` ran out of memory, an
    audit of 2026-11-29); one line (:class:`ConfigError`) naming ``what`` otherwise."""
    if path.is_dir():
        raise ConfigError(f"{what} {path} is a directory, not a TOML file")
    if not path.exists():
        raise ConfigError(f"{what} not found: {path}")
    try:
        with open(path, "rb") as fh:
            raw = fh.read(MAX_CONFIG_BYTES + 1)
    except OSError as exc:
        raise ConfigError(f"cannot read {what} {path}: {exc.strerror or exc}") from None
    if len(raw) > MAX_CONFIG_BYTES:
        raise ConfigError(f"{what} {path} holds more than {MAX_CONFIG_BYTES // 2**20} MiB: "
                          f"not a TOML config")
    return raw


def _decodes(raw: bytes, encoding: str) -> bool:
    try:
        raw.decode(encoding)
    except UnicodeDecodeError:
        return False
    return True


def check_toml_bytes(raw: bytes, path: Path, what: str = "config file") -> None:
    """Refuse, in one line, a TOML file that starts with a byte-order mark: UTF-8's (Windows
    editors write it; invisible, and TOML refuses it at 1:1) or UTF-16's (PowerShell 5's
    ``>`` writes it; it read as "'utf-8' codec can't decode byte 0xff")."""
    if raw.startswith(b"\xef\xbb\xbf"):
        raise ConfigError(f"{what} {path} starts with a UTF-8 byte-order mark, which TOML "
                          f"does not allow: save it as UTF-8 without BOM")
    if raw.startswith((b"\xff\xfe", b"\xfe\xff")) and _decodes(raw, "utf-16"):
        raise ConfigError(f"{what} {path} is UTF-16 (PowerShell 5's '>' writes it), and TOML "
                          f"is UTF-8: save it as UTF-8 without BOM")


def read_toml(path: str | Path) -> dict[str, Any]:
    """Read a TOML config file into a flat dict (a ``[run]`` table is also accepted)."""
    if sys.version_info >= (3, 11):
        import tomllib
    else:  # pragma: no cover
        import tomli as tomllib
    p = Path(path)
    raw = read_config_bytes(p)
    check_toml_bytes(raw, p)
    try:
        data = tomllib.loads(raw.decode("utf-8"))
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
        raise ConfigError(f"cannot parse config file {p}: {exc}") from None
    except RecursionError:  # (a list nested 5000 deep: 3000 lines of traceback, an audit)
        raise ConfigError(f"cannot parse config file {p}: its arrays or tables are nested too "
                          f"deeply") from None
    if "run" in data and isinstance(data["run"], dict):
        rest = {k: v for k, v in data.items() if k != "run"}
        both = sorted({k.replace("-", "_") for k in rest}
                      & {k.replace("-", "_") for k in data["run"]})
        if both:  # (noise = 1 beside [run] noise = 7 took 7 without a word)
            raise ConfigError(f"config file {p}: {', '.join(both)} given both at the top and "
                              f"in [run]")
        data = {**rest, **data["run"]}
    elif "grid" in data and isinstance(data["grid"], dict):
        # (a sweep's file given to run --config said "unknown config key 'base' (a plugin
        # stage's option? ...)": an outside audit of 2026-12-03)
        raise ConfigError(f"config file {p} is a sweep's file (its [grid] table): run it with "
                          f"'spslidar sweep {p} --out DIR'")
    unknown = sorted(k for k in data if k.replace("-", "_") in CLI_ONLY_KEYS)
    if unknown:
        what, it = (("is a command-line option", "it") if len(unknown) == 1 else
                    ("are command-line options", "them"))
        raise ConfigError(f"config file {p}: {', '.join(unknown)} {what} (of the output, not "
                          f"of the run): give {it} on the command line")
    return resolve_file_paths(data, p.parent)


#: keys of ``spslidar run`` that belong to the command, not to the run's configuration
CLI_ONLY_KEYS = frozenset({"out", "overwrite", "save_ptu", "fov", "no_figure", "config"})

#: config keys that may name a file: a relative one in a TOML file is read from its folder
FILE_KEYS = ("scene", "irf")


def resolve_file_paths(data: dict[str, Any], base: Path) -> dict[str, Any]:
    """A relative scene or IRF *file* named in a config file is relative to that file's folder
    (a built-in scene name or an IRF spec like ``gaussian:2`` is left alone), as a user writing
    ``scene = "data/bike.npz"`` next to the TOML expects wherever the command is run from (a
    relative ``irf = "irf.npy"`` was read from the current folder: the same TOML gave another
    response in another folder)."""
    out = dict(data)
    for key, value in data.items():
        if names_a_file(key, value):
            # (`~/odd.npy` was read as `<toml folder>/~/odd.npy`: an outside audit of
            # 2026-12-03; the shell expands it on the command line, a TOML has no shell)
            path = Path(value).expanduser()
            out[key] = str(path if path.is_absolute() else base / path)
    return out


def names_a_file(key: str, value: Any) -> bool:
    """Whether config key ``key`` (dashed or not) holds a *file* name: a scene or IRF given as
    a path with a suffix, not a built-in scene name or an IRF spec like ``gaussian:2``."""
    return (key.replace("-", "_") in FILE_KEYS and isinstance(value, str)
            and bool(Path(value).suffix) and ":" not in value)
