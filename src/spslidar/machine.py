"""What this machine offers a run: the memory it may still use (read before any large array
is made, by the run's budget and by the PTU reader), and the time limits a run is given
(``--max-time``, :func:`parse_duration`)."""

from __future__ import annotations

import os

__all__ = ["DURATION_UNITS", "MEMORY_UNITS", "available_memory", "parse_duration",
           "parse_memory"]


def _gb(b: float) -> str:
    # (under 1 MB two significant digits: "--max-memory 1e-6" read "more than the 0 MB")
    # (two decimals: "needs ~1.2 GB ... more than the 1.2 GB --max-memory" was 1.22 against
    # 1.2, and --max-memory 0.25 read "0.2 GB", an audit)
    if b >= 1e10:
        return f"{b / 1e9:.0f} GB"
    if b >= 1e8:
        return f"{b / 1e9:.2f} GB"
    return f"{b / 1e6:.0f} MB" if b >= 1e6 else f"{b / 1e6:.2g} MB"


def resident_memory() -> float:
    """Bytes this process holds now (its resident set, ``/proc/self/statm``; 0 where the
    system does not say)."""
    try:
        with open("/proc/self/statm", encoding="ascii") as fh:
            return float(fh.read().split()[1]) * os.sysconf("SC_PAGE_SIZE")
    except (OSError, ValueError, IndexError, AttributeError):  # pragma: no cover - not Linux
        return 0.0


def available_memory() -> float:
    """Bytes of memory this process may still use: ``MemAvailable`` of ``/proc/meminfo``
    (elsewhere psutil's available memory where it is installed, then the physical memory),
    capped by ``RLIMIT_AS`` when one is set. On Windows without psutil there is neither, and
    no run is refused for its memory before it starts (a portability audit)."""
    avail = None
    try:
        with open("/proc/meminfo", encoding="ascii") as fh:
            for line in fh:
                if line.startswith("MemAvailable:"):
                    avail = float(line.split()[1]) * 1024
                    break
    except OSError:
        pass
    if avail is None:  # (macOS, Windows: psutil where installed, which both have)
        try:
            import psutil

            avail = float(psutil.virtual_memory().available)
        except Exception:  # noqa: BLE001 - not installed, or it cannot tell: the next way
            pass
    if avail is None:
        try:
            avail = float(os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES"))
        except (ValueError, OSError, AttributeError):  # pragma: no cover - not POSIX
            # (Windows without psutil: no estimate, so no run is refused before it starts)
            avail = float("inf")
    try:
        import resource

        soft, _ = resource.getrlimit(resource.RLIMIT_AS)
        if soft not in (resource.RLIM_INFINITY, -1) and soft > 0:
            avail = min(avail, float(soft))
    except (ImportError, ValueError, OSError):  # pragma: no cover - not POSIX
        pass
    return avail


#: units ``--max-time`` takes after its number (seconds when none is given)
DURATION_UNITS = {"s": 1.0, "sec": 1.0, "second": 1.0, "seconds": 1.0,
                  "m": 60.0, "min": 60.0, "minute": 60.0, "minutes": 60.0,
                  "h": 3600.0, "hour": 3600.0, "hours": 3600.0,
                  "d": 86400.0, "day": 86400.0, "days": 86400.0}


def parse_duration(text: str | float | int, what: str = "--max-time") -> float:
    """A time limit in seconds from ``90``, ``90s``, ``2min``, ``1.5h`` or ``1d``.

    Parameters
    ----------
    text : str or float or int
        A positive number of seconds, or a number followed by one of
        :data:`DURATION_UNITS` (spaces allowed, case ignored).
    what : str
        The option named in the error message.

    Returns
    -------
    float
        Seconds, positive and finite.

    Raises
    ------
    ConfigError
        On anything else (one line).
    """
    import math
    import re

    from .errors import ConfigError

    if isinstance(text, bool):
        raise ConfigError(f"{what} must be a duration such as 600, 10min or 2h, got {text!r}")
    if isinstance(text, (int, float)):
        value, unit = float(text), 1.0
    else:
        match = re.fullmatch(r"\s*([0-9.eE+-]+)\s*([A-Za-z]*)\s*", str(text))
        try:
            value = float(match.group(1)) if match else math.nan
        except ValueError:
            value = math.nan
        unit = DURATION_UNITS.get(match.group(2).lower() if match and match.group(2) else "s")
        if unit is None or math.isnan(value):
            raise ConfigError(f"{what} must be a duration such as 600, 10min or 2h (units: s, "
                              f"min, h, d), got {text!r}")
    seconds = value * unit
    if not (math.isfinite(seconds) and seconds > 0):
        raise ConfigError(f"{what} must be a positive, finite duration, got {text!r}")
    return seconds


#: units ``--max-memory`` takes after its number, in gigabytes (GB when none is given)
MEMORY_UNITS = {"": 1.0, "k": 1e-6, "kb": 1e-6, "m": 1e-3, "mb": 1e-3, "g": 1.0, "gb": 1.0,
                "t": 1e3, "tb": 1e3, "kib": 2**10 / 1e9, "mib": 2**20 / 1e9,
                "gib": 2**30 / 1e9, "tib": 2**40 / 1e9}


def parse_memory(text: str | float | int, what: str = "--max-memory") -> float:
    """A memory size in gigabytes from ``2``, ``500MB``, ``2GB`` or ``1.5GiB`` (a number is
    in GB): the command line's and a TOML's ``max_memory`` alike (``"500MB"`` in a TOML was
    "must be a number" while the command line took it, an audit of 2026-11-29).

    Raises
    ------
    ConfigError
        Anything else (one line); the range is checked by the config.
    """
    import re

    from .errors import ConfigError

    if isinstance(text, bool):
        raise ConfigError(f"{what} must be a memory size such as 2, 500MB or 2GB, got {text!r}")
    if isinstance(text, (int, float)):
        return float(text)
    match = re.fullmatch(r"\s*([0-9.eE+-]+)\s*([A-Za-z]*)\s*", str(text))
    unit = match.group(2).lower() if match else None
    try:
        if unit in MEMORY_UNITS:
            return float(match.group(1)) * MEMORY_UNITS[unit]
    except ValueError:
        pass
    raise ConfigError(f"{what}: not a memory size: {text!r} (write GB, or e.g. 500MB, 2GB, "
                      f"1.5GiB)")
