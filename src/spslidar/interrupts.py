"""Ctrl-C, SIGTERM and SIGHUP for the command line: one line, exit 130 / 143 / 129, no process
left behind, and a bounded time to get there.

A command run as a process of its own (``spslidar ...``, ``main(argv=None)``) installs a
:class:`Stopper` for both signals. The first signal raises :class:`KeyboardInterrupt` (or
:class:`Terminated`) in the main thread, so the same clean-up runs as for any exception
(temporary files removed, the worker pool stopped), and arms a watchdog: if the command has not
exited :data:`STOP_GRACE_S` seconds later, the watchdog kills the pool's workers, says the
command's one line if it was not said, and ends the process with the signal's status. A second
signal during the clean-up is ignored instead of interrupting it, and the handlers stay in
place until the process ends: a signal that comes once the command has returned, while
Python's exit hooks join the pool's threads, only arms the watchdog.

Why a watchdog: the clean-up goes through joblib / loky (shutting the pool down, joining its
threads in Python's exit hooks), and a signal that lands in the wrong place there can leave
the command waiting forever on a worker or a thread (seen twice: once in ``multiprocessing``'s
exit hook after a late Ctrl-C, once on a loaded 2-core CI machine, where ``sweep --jobs 2``
was still running 60 s after its Ctrl-C). No library offers a time-bounded shutdown for this,
hence the few lines here. Inside a Python session (``main([...])``) the stopper has no
watchdog (``grace=None``: a session is never ended by :func:`os._exit`), handles SIGTERM
alone, and its previous handler is put back when the command returns.
"""

from __future__ import annotations

import os
import signal
import sys
import threading

#: exit status after Ctrl-C (128 + SIGINT), as a shell reports it
EXIT_INTERRUPTED = 130
#: exit status after SIGTERM (128 + SIGTERM)
EXIT_TERMINATED = 143
#: seconds a command has, after its first Ctrl-C or SIGTERM, to clean up and exit on its own
STOP_GRACE_S = 20.0


#: the signals a command handles: Ctrl-C, SIGTERM and (a closed terminal) SIGHUP, which
#: ended a run with status 129 and nothing said (an audit of 2026-11-29)
SIGNALS = tuple(getattr(signal, name) for name in ("SIGINT", "SIGTERM", "SIGHUP")
                if hasattr(signal, name))


class Terminated(KeyboardInterrupt):
    """SIGTERM (or SIGHUP), raised in the main thread so that the same clean-up as Ctrl-C runs
    (temporary files removed, worker processes stopped); ``status`` is the exit status a
    shell reports for it, 128 + the signal's number."""

    def __init__(self, status: int = EXIT_TERMINATED):
        super().__init__()
        self.status = status


class Stopper:
    """The signal handlers of one command and the watchdog they arm.

    Parameters
    ----------
    line : callable
        ``line(terminated) -> str``: the command's one line for the signal.
    grace : float or None
        Seconds before the watchdog ends the process; None: no watchdog (every signal
        raises, nothing ends the process).
    """

    def __init__(self, line, grace: float | None = STOP_GRACE_S):
        self.line = line
        self.grace = grace
        self.said = False
        self.timer: threading.Timer | None = None
        #: set once the command returned: a signal then only arms the watchdog (Python's exit
        #: hooks still join the pool's threads; a signal raised in them printed a traceback)
        self.exiting = False
        self._previous: dict[int, object] = {}

    def install(self, signals=SIGNALS) -> None:
        """Handle ``signals`` (main thread only; a no-op elsewhere)."""
        if threading.current_thread() is not threading.main_thread():
            return
        for sig in signals:
            self._previous[sig] = signal.signal(sig, self._handle)

    def restore(self) -> None:
        """Put back the handlers :meth:`install` replaced (the watchdog, if armed, stays)."""
        try:
            for sig, handler in self._previous.items():
                # None: the handler before was installed outside Python (an embedding host),
                # which signal.signal cannot put back; the default is the nearest (a TypeError
                # here hid the command's result, an audit of 2026-11-30)
                signal.signal(sig, signal.SIG_DFL if handler is None else handler)
        finally:
            self._previous.clear()

    def say(self, terminated: bool) -> None:
        """Print the command's one line (once)."""
        if not self.said:
            self.said = True
            print(self.line(terminated), file=sys.stderr, flush=True)

    def _handle(self, signum, frame):  # noqa: ARG002 - the signal handler's signature
        if self.timer is not None:  # already stopping: let the clean-up finish
            return
        terminated = signum != signal.SIGINT
        status = 128 + int(signum)
        if self.grace is not None:  # arm the watchdog
            self.timer = threading.Timer(self.grace, self._fire, (terminated, status))
            self.timer.daemon = True
            self.timer.start()
            if self.exiting:
                return
        raise Terminated(status) if terminated else KeyboardInterrupt()

    def _fire(self, terminated: bool, status: int = EXIT_TERMINATED) -> None:
        """The clean-up took too long: kill the workers, say the line, end the process."""
        kill_pool()
        self.say(terminated)
        try:
            sys.stderr.flush()
        finally:
            os._exit(status if terminated else EXIT_INTERRUPTED)


def _executor():
    """joblib's reusable loky executor, or None where no pool was started (loky not even
    imported: nothing is imported here to find out)."""
    reusable = sys.modules.get("joblib.externals.loky.reusable_executor")
    return getattr(reusable, "_executor", None)


def stop_pool() -> None:
    """Stop joblib's worker pool while a Ctrl-C is still this command's to report: left to
    Python's exit hook, which joins loky's threads after ``main`` returned, a Ctrl-C then
    printed a ``KeyboardInterrupt`` traceback and the command exited 0. Only for a process of
    its own: in a Python session the pool is kept for the next call."""
    executor = _executor()
    if executor is not None:
        executor.shutdown(wait=True)


def kill_pool() -> None:
    """Kill the worker processes of joblib's pool, if any: after Ctrl-C or SIGTERM in a
    process of its own. A signal that lands while :func:`stop_pool` shuts the pool down
    can leave its idle workers waiting on their task queue for a stop message that never
    comes, and Python's exit then joins them forever (seen here: a late Ctrl-C left the
    command and both workers hanging, in ``multiprocessing``'s exit hook)."""
    executor = _executor()
    try:
        processes = list((getattr(executor, "_processes", None) or {}).values())
    except RuntimeError:  # the dict changed under us (the watchdog's thread): none listed
        processes = []
    pids = {getattr(p, "pid", None) for p in processes} | set(_worker_children())
    # (Windows has no SIGKILL: os.kill with SIGTERM ends a process there, TerminateProcess)
    kill = getattr(signal, "SIGKILL", signal.SIGTERM)
    for pid in pids:
        try:  # (loky's process handle has no kill())
            os.kill(pid, kill)
        except (OSError, TypeError):  # gone already (Windows: an OSError), or never started
            pass


def _worker_children() -> list[int]:
    """This process's loky workers as the system lists them (Linux ``/proc``; none
    elsewhere): while the pool shuts down its own list can already be empty with the workers
    still running. A clean-clone CI run saw a late Ctrl-C's sweep exit 130 with its one line
    and its pipes held open 60 s more by a process that outlived it. Read by hand: the
    standard library lists no children but its own ``multiprocessing`` ones, and psutil is
    not a dependency."""
    me, found = os.getpid(), []
    try:
        entries = os.listdir("/proc")
    except OSError:
        return found
    for entry in entries:
        if not entry.isdigit():
            continue
        try:
            with open(f"/proc/{entry}/stat", "rb") as f:
                ppid = int(f.read().rsplit(b")", 1)[1].split()[1])
            if ppid != me:
                continue
            with open(f"/proc/{entry}/cmdline", "rb") as f:
                if b"popen_loky" in f.read():
                    found.append(int(entry))
        except (OSError, ValueError, IndexError):  # gone meanwhile, or not ours to read
            continue
    return found


def quiet_resource_tracker() -> None:
    """Silence, through the environment it inherits, the warnings of loky's resource tracker
    (a process the worker pool starts): after Ctrl-C or SIGTERM this command kills the
    workers so that none outlives it, the tracker then cleans up the semaphores they held
    and warns of each on the command's stderr (five lines after its one, seen on CI). Only
    for a process of its own, before any pool exists."""
    rule = "ignore::UserWarning:joblib.externals.loky.backend.resource_tracker"
    old = os.environ.get("PYTHONWARNINGS")
    os.environ["PYTHONWARNINGS"] = f"{old},{rule}" if old else rule
