"""One writer at a time at the moment an output folder is put in place.

Each command checks its ``--out`` before any work and writes into a temporary folder, but
the check made again at the end and the swap into place were two steps: two ``run
--overwrite`` into one folder, or two sweeps into one, interleaved there, and an outside
audit of 2026-11-29 found a folder holding one run's files under the other's marker
(refused as edited by every later ``--overwrite``), a run that said "wrote" having lost its
files, and one sweep's ``results.csv`` replaced by another's. :func:`folder_lock` holds an
advisory lock (``fcntl.flock``) for the folder that holds the output, from that last check
to the end of the swap; the second writer waits a moment, then checks what it now finds
there.

The lock is taken on a file of spslidar's own, named by the folder's resolved path, in a
folder of the user's under the system's temporary folder (:func:`lock_file`), not on the
output's folder itself: ``flock DIR spslidar run --out DIR/a``, the way ``flock(1)``
serialises jobs, held that folder's lock in the parent process, and the run waited for it
forever after its work (an outside audit of 2026-11-30). Nothing is written in the user's
folders; the lock files are empty and stay (removing one while another process waits on it
would let a third lock a new file beside the old). Written here: the standard library's
``fcntl`` is the tool. Where ``fcntl`` is missing (Windows), the temporary folder cannot be
written, or the filesystem refuses a lock, the writers are not serialised, as before.
"""

from __future__ import annotations

import contextlib
import hashlib
import os
import tempfile
from collections.abc import Iterator
from pathlib import Path

__all__ = ["folder_lock", "lock_file"]


def lock_file(folder: str | os.PathLike) -> Path:
    """The lock file of ``folder``: ``<tmp>/spslidar-locks-<uid>/<sha256 of its resolved
    path>.lock`` (the folder of locks made, mode 0700, where missing)."""
    key = os.fsencode(os.path.realpath(folder))
    uid = os.getuid() if hasattr(os, "getuid") else "user"
    base = Path(tempfile.gettempdir()) / f"spslidar-locks-{uid}"
    base.mkdir(mode=0o700, exist_ok=True)
    if base.stat().st_mode & 0o700 != 0o700:  # (a umask of 0222 made it 0500: every lock
        os.chmod(base, 0o700)                  # then failed without a word, a review)
    return base / f"{hashlib.sha256(key).hexdigest()[:32]}.lock"


@contextlib.contextmanager
def folder_lock(folder: str | os.PathLike) -> Iterator[bool]:
    """Hold an exclusive advisory lock for ``folder`` (an existing directory) while inside;
    yields whether it is held."""
    try:
        import fcntl
    except ImportError:  # pragma: no cover - Windows
        yield False
        return
    try:
        fd = os.open(lock_file(folder), os.O_RDWR | os.O_CREAT, 0o600)
    except (OSError, RuntimeError):  # (a temporary folder that cannot be written)
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
