"""The warnings a run raises, kept for its own result, also where runs share a process's
threads (:func:`captured_warnings`), and from the run's own worker threads (:func:`carried`).

Python's ``warnings.catch_warnings`` is process-wide: two runs in a thread pool, each
inside its own, restored each other's state, and one run's warning landed in the other's
``Result.warnings`` (an audit of 2026-11-29: a GPSR run's odd-side wavelet warning in a TV
run's). Here the first run to enter replaces ``warnings.showwarning`` (public API) with a
dispatcher, and the last to leave puts back what it found. A warning goes to the innermost
run of the thread that raised it; a worker thread of a run's own pool (the simulation's
blocks, the solver's bands) carries its run (:func:`carried`); a thread in no run gives it
to the one run active, if there is exactly one, as the process-wide capture did; otherwise
it is shown as Python shows it. No ``catch_warnings`` is entered: a caller's own, entered
while a run was active and left after it, restored the dispatcher as the process's for good,
and the next run then called itself (a RecursionError, a review of 2026-11-29).
"""

from __future__ import annotations

import functools
import threading
import warnings
from contextlib import contextmanager
from typing import Any

__all__ = ["captured_warnings", "carried"]

_LOCK = threading.Lock()
_STATE: dict[str, Any] = {"shown": None, "active": []}  # the runs inside, by their logs
_LOCAL = threading.local()
#: what Python shows a warning with, before any run replaced it
_ORIGINAL = warnings.showwarning
#: a filter that matches no warning (a message starting with NUL): adding it is the public way
#: to reset Python's once-per-place registries, as entering ``catch_warnings`` does
_RESET = ("default", "\x00")


def _reset_registries() -> None:
    """Reset Python's once-per-place registries (adding a filter does), leaving the caller's
    filters as they were: the added one stayed in ``warnings.filters`` for good (an audit of
    the Python API, 2026-11-29). Taking it out again is a plain list edit, which does not
    count as a change of the filters: the reset stands."""
    warnings.filterwarnings(*_RESET, append=True)
    filters = getattr(warnings, "filters", None)
    if isinstance(filters, list):
        for f in [f for f in filters if f[0] == _RESET[0] and getattr(f[1], "pattern", None)
                  == _RESET[1]]:
            filters.remove(f)


def _shown() -> Any:
    show = _STATE["shown"]
    return _ORIGINAL if show is None or show is _dispatch else show


def _dispatch(message, category, filename, lineno, file=None, line=None) -> None:
    logs = getattr(_LOCAL, "logs", None)
    with _LOCK:
        active = list(_STATE["active"])
    target = logs[-1] if logs else (active[0] if len(active) == 1 else None)
    if target is not None:
        target.append(warnings.WarningMessage(message, category, filename, lineno, file, line))
    else:  # no run, or several and none of this thread's: as Python shows it
        _shown()(message, category, filename, lineno, file, line)


@contextmanager
def captured_warnings():
    """Yield the list that receives, as ``warnings.WarningMessage``, the warnings raised
    inside by this thread and by the worker threads it hands work to through
    :func:`carried` (the caller's filters hold: what they ignore stays ignored, an ``error``
    filter raises; the once-per-place registries are reset on entry, so a second run's
    warnings are kept too)."""
    log: list = []
    with _LOCK:
        if not _STATE["active"] and warnings.showwarning is not _dispatch:
            _STATE["shown"] = warnings.showwarning
        warnings.showwarning = _dispatch
        _reset_registries()
        _STATE["active"].append(log)
    logs = getattr(_LOCAL, "logs", None)
    if logs is None:
        logs = _LOCAL.logs = []
    logs.append(log)
    try:
        yield log
    finally:
        logs.pop()
        with _LOCK:
            # (by identity: list.remove compares by ==, and two runs' logs equal while both
            # empty, so one run took the other's log out and then failed to find its own)
            _STATE["active"] = [other for other in _STATE["active"] if other is not log]
            if not _STATE["active"]:
                if warnings.showwarning is _dispatch:
                    warnings.showwarning = _shown()
                _STATE["shown"] = None


def carried(fn):
    """``fn`` to run in a worker thread as part of the calling thread's run: the warnings it
    raises go to that run (the simulation's pool raised the dead-time model's warnings where
    no run was known, and they left ``metrics.json``, a review of 2026-11-29)."""
    logs = list(getattr(_LOCAL, "logs", None) or [])
    if not logs:
        return fn

    @functools.wraps(fn)
    def wrapper(*args, **kwargs):
        before = getattr(_LOCAL, "logs", None)
        _LOCAL.logs = logs
        try:
            return fn(*args, **kwargs)
        finally:
            _LOCAL.logs = before

    return wrapper
