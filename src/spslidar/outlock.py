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
folders; each lock file is removed by its holder as it lets go (a waiter that then holds the
removed file's lock sees so and locks the new one). Written here: the standard library's
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
    yields whether it is held.

    The lock file is removed by its holder on leaving, while it still holds it; a waiter that
    then gets the lock of the removed file sees that its path now names another file, or
    none, and takes the lock again (files of every folder ever written had piled up in the
    lock folder, 573 after one test session, and one made under a umask of 0222 or 0777 could
    not be opened again, so that folder's writers went unserialised without a word: a review
    of 2026-11-30)."""
    try:
        import fcntl
    except ImportError:  # pragma: no cover - Windows
        yield False
        return
    for _ in range(100):
        try:
            path = lock_file(folder)
            try:
                fd = os.open(path, os.O_RDWR | os.O_CREAT, 0o600)
            except PermissionError:  # one left unreadable by an earlier version: ours
                os.chmod(path, 0o600)
                fd = os.open(path, os.O_RDWR | os.O_CREAT, 0o600)
        except (OSError, RuntimeError):  # (a temporary folder that cannot be written)
            yield False
            return
        try:
            fcntl.flock(fd, fcntl.LOCK_EX)
            mine = os.fstat(fd)
            try:
                now = os.stat(path)
            except FileNotFoundError:
                now = None
        except OSError:  # pragma: no cover - a filesystem without locks
            os.close(fd)
            yield False
            return
        if now is not None and (now.st_ino, now.st_dev) == (mine.st_ino, mine.st_dev):
            break
        os.close(fd)  # its holder removed it meanwhile: lock the new one
    else:  # pragma: no cover - a hundred holders in a row removed it under us
        yield False
        return
    try:
        os.fchmod(fd, 0o600)  # (0o600 less a umask: 0400 or 000 could not be opened again)
        yield True
    finally:
        with contextlib.suppress(OSError):
            os.unlink(path)
        os.close(fd)  # (closing releases the lock)
