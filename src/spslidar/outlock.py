"""One writer at a time at the moment an output folder is put in place.

Each command checks its ``--out`` before any work and writes into a temporary folder, but
the check made again at the end and the swap into place were two steps: two ``run
--overwrite`` into one folder, or two sweeps into one, interleaved there, and an outside
audit of 2026-11-29 found a folder holding one run's files under the other's marker
(refused as edited by every later ``--overwrite``), a run that said "wrote" having lost its
files, and one sweep's ``results.csv`` replaced by another's. :func:`folder_lock` holds an
advisory lock (``fcntl.flock``) on the folder that holds the output, from that last check
to the end of the swap; the second writer waits a moment, then checks what it now finds
there. Written here: the standard library's ``fcntl`` is the tool; no lock file is left
behind (the lock is on the folder itself). Where ``fcntl`` is missing (Windows) or the
filesystem refuses a lock, the writers are not serialised, as before.
"""

from __future__ import annotations

import contextlib
import os
from collections.abc import Iterator
from pathlib import Path

__all__ = ["folder_lock"]


@contextlib.contextmanager
def folder_lock(folder: str | os.PathLike) -> Iterator[bool]:
    """Hold an exclusive advisory lock on ``folder`` (an existing directory) while inside;
    yields whether it is held."""
    try:
        import fcntl
    except ImportError:  # pragma: no cover - Windows
        yield False
        return
    try:
        fd = os.open(Path(folder), os.O_RDONLY)
    except OSError:
        yield False
        return
    try:
        try:
            fcntl.flock(fd, fcntl.LOCK_EX)
            held = True
        except OSError:  # pragma: no cover - a filesystem without locks
            held = False
        yield held
    finally:
        os.close(fd)  # (closing releases the lock)
