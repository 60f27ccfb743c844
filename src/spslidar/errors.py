"""Exceptions raised for bad input, and how a warning's origin is said.

Every user-facing error is a :class:`SpslidarError`; the command-line tool prints its message as
one line on stderr and exits with status 2.
"""

from __future__ import annotations


class SpslidarError(ValueError):
    """A user-facing error with a one-line message (bad config, bad scene, bad code length...)."""


class ConfigError(SpslidarError):
    """An invalid configuration value."""


class SceneError(SpslidarError):
    """A scene that cannot be read or is physically invalid (NaN or negative depth...)."""


def one_line(message: object) -> str:
    """An error's text on one line: a newline or carriage return in it (a path holding one
    split the one-line error over two lines, an audit of stop 60) written as ``\\n`` /
    ``\\r``, as Python writes them in a string (the command line's refusals: ``cli`` and
    ``cli_inspect``)."""
    return str(message).replace("\r", "\\r").replace("\n", "\\n")


def first_line(exc: BaseException) -> str:
    """The first line of a library's exception message, or its type's name where it has
    none: what a one-line refusal says of a reader's failure."""
    return str(exc).splitlines()[0] if str(exc) else type(exc).__name__


def raised_text(exc: BaseException) -> str:
    """What an exception a researcher's code raised says in a one-line refusal: its type and
    first line (``RuntimeError: boom``), or for a ``SystemExit`` its exit code as Python writes
    the call (``SystemExit(0)``: "SystemExit: 0" read as a message "0"; an outside audit of
    2026-12-02 met ``raise SystemExit(0)`` in a plugin stage, a silent exit 0)."""
    if isinstance(exc, SystemExit):
        return f"SystemExit({exc.code!r})"
    text = str(exc).splitlines()[0] if str(exc) else ""
    return f"{type(exc).__name__}: {text}"


def numbers_blanked(text: str) -> str:
    """``text`` with its numbers replaced by ``#``: what tells a warning that comes again with
    other numbers (a fixed point's relative change, per block) from another one."""
    import re

    return re.sub(r"[-+]?\d[\d.,]*(e[-+]?\d+)?", "#", text)


#: warnings that tell a library's users of its future, not spslidar's of their run
NOTICES = (DeprecationWarning, PendingDeprecationWarning, FutureWarning)


def library_notice(category: type) -> bool:
    """Whether a warning is a library's notice of its own future (a deprecation or a
    ``FutureWarning``): nothing a user of spslidar can act on, so the command line drops it
    and ``metrics.json`` leaves it out, while the Python API issues it again for Python's
    filters to say or not (a test plugin making scikit-image's ``resize`` warn of a
    deprecated argument failed 7 tests that count the command line's lines; an audit of
    2026-11-29). Told by its category alone: spslidar raises none of its own, and a library
    raises its notices with ``stacklevel=2``, naming spslidar's calling line as the origin
    (a review)."""
    return issubclass(category, NOTICES)


def warning_origin(category: type, filename: str, lineno: int) -> str:
    """Where a library's warning came from, as the user sees it after the warning's text
    (`` (RuntimeWarning in fromnumeric.py:3860)``); ``""`` for spslidar's own, which say
    what they are (an audit read "(RuntimeWarning in calibration.py:378)" after a
    calibration's advice as a fault of the code)."""
    from pathlib import Path

    try:
        Path(filename).resolve().relative_to(Path(__file__).resolve().parent)
        return ""
    except (ValueError, OSError):
        return f" ({category.__name__} in {Path(filename).name}:{lineno})"

