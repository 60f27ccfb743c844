"""The warnings a run raises, kept for its own result, also where runs share a process's
threads (:func:`captured_warnings`).

Python's :class:`warnings.catch_warnings` is process-wide: two runs in a thread pool, each
inside its own, restored each other's state, and one run's warning landed in the other's
``Result.warnings`` (an audit of 2026-11-29: a GPSR run's odd-side wavelet warning in a TV
run's). Here the first run to enter replaces :func:`warnings.showwarning` (public API) with a
dispatcher that gives each warning to the innermost run of the thread that raised it, and the
last to leave restores it; a warning from a thread outside every run is shown as before.
"""

from __future__ import annotations

import threading
import warnings
from contextlib import contextmanager
from typing import Any

__all__ = ["captured_warnings"]

_LOCK = threading.Lock()
_STATE: dict[str, Any] = {"depth": 0, "context": None, "shown": None}
_LOCAL = threading.local()
#: a filter that matches no warning (a message starting with NUL): adding it is the public way
#: to reset Python's once-per-place registries, as entering ``catch_warnings`` does
_RESET = ("default", "\x00")


def _dispatch(message, category, filename, lineno, file=None, line=None) -> None:
    logs = getattr(_LOCAL, "logs", None)
    if logs:
        logs[-1].append(warnings.WarningMessage(message, category, filename, lineno, file,
                                                line))
    else:  # a thread in no run: as Python shows it
        _STATE["shown"](message, category, filename, lineno, file, line)


@contextmanager
def captured_warnings():
    """Yield the list that receives, as :class:`warnings.WarningMessage`, the warnings this
    thread raises inside (the caller's filters hold: what they ignore stays ignored, an
    ``error`` filter raises; the once-per-place registries are reset on entry, so a second
    run's warnings are kept too)."""
    log: list = []
    with _LOCK:
        if _STATE["depth"] == 0:
            context = warnings.catch_warnings()
            context.__enter__()  # (the filters and showwarning, restored by the last to leave)
            _STATE["context"], _STATE["shown"] = context, warnings.showwarning
            warnings.showwarning = _dispatch
        warnings.filterwarnings(*_RESET, append=True)
        _STATE["depth"] += 1
    logs = getattr(_LOCAL, "logs", None)
    if logs is None:
        logs = _LOCAL.logs = []
    logs.append(log)
    try:
        yield log
    finally:
        logs.pop()
        with _LOCK:
            _STATE["depth"] -= 1
            if _STATE["depth"] == 0:
                context, _STATE["context"] = _STATE["context"], None
                context.__exit__(None, None, None)
