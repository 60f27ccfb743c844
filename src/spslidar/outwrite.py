"""Files written all or nothing, and the marker that records what spslidar wrote.

Every output spslidar writes goes through :func:`atomic_file` (or :func:`atomic_path` for a
writer that wants a name): a temporary file in the same folder, flushed to disk and moved
onto its name only once complete, with the permissions the user's umask gives. An output
folder spslidar owns holds a marker, :data:`MARKER`, naming the kind of output and the
files spslidar wrote there with their SHA-256 (:func:`read_marker`, :func:`changed_files`);
a command that fills a folder over time journals each file's SHA-256 in the marker before
the file is moved into place (:func:`journal`, :func:`record_outputs`, :func:`owned_sums`),
so that an interrupt at any moment leaves no file the marker does not know.

This is the lowest layer of the output rules; :mod:`spslidar.outdir` builds the folders of
``run`` / ``reconstruct`` results and of ``sweep`` / ``reproduce`` on it, and
:mod:`spslidar.outfiles` the files of ``run --save-ptu``. Written by hand: the standard
library's ``tempfile`` and ``os.replace`` give the atomic move, but no library keeps a
folder's record of its own files across interrupts.
"""

from __future__ import annotations

import contextlib
import hashlib
import json
import os
import tempfile
from collections.abc import Iterator
from pathlib import Path
from typing import BinaryIO

__all__ = ["MARKER", "MAX_RECORD_BYTES", "atomic_file", "atomic_path", "atomic_write_bytes",
           "atomic_write_text", "changed_files", "foreign_outputs", "journal", "owned_sums",
           "read_json_record", "read_marker", "record_outputs", "sha256_file", "umask_mode"]

#: the marker file spslidar writes into every output folder it owns
MARKER = ".spslidar-output.json"

def umask_mode(base: int = 0o777) -> int:
    """``base`` with the process's umask applied (0o777 -> 0o755 under umask 022)."""
    mask = os.umask(0)
    os.umask(mask)
    return base & ~mask


#: the largest record of spslidar's own (a marker, a sidecar, a sweep's cached run) read back:
#: theirs are kilobytes
MAX_RECORD_BYTES = 16 * 2**20


def read_json_record(path: str | os.PathLike) -> object:
    """A JSON record spslidar wrote (a marker, a sidecar, a cached run), or None where
    ``path`` is not one: not a regular file, larger than :data:`MAX_RECORD_BYTES`, not JSON,
    or nested too deeply to parse. A FIFO of that name hung the command, a 3 GB sparse file
    took 3.2 GB and a 100 000-deep nesting gave a traceback (an outside audit, 2026-11-30)."""
    p = Path(path)
    try:
        if not p.is_file() or p.stat().st_size > MAX_RECORD_BYTES:
            return None
        with open(p, encoding="utf-8") as fh:
            return json.load(fh)
    except (OSError, ValueError, RecursionError):
        return None


def read_marker(folder: str | os.PathLike) -> dict | None:
    """The marker of an output folder spslidar wrote (``kind``, ``id``, ``version``,
    ``files``), or None."""
    meta = read_json_record(Path(folder) / MARKER)
    if not (isinstance(meta, dict) and isinstance(meta.get("files"), list)
            and isinstance(meta.get("kind"), str)):
        return None
    return meta


def _hashes(value) -> set[str]:
    """A marker's record of one file: a SHA-256, or a list of those that count as its."""
    if isinstance(value, str):
        return {value}
    if isinstance(value, (list, tuple, set, frozenset)):
        return {v for v in value if isinstance(v, str)}
    return set()


def changed_files(folder: Path, names, sums: dict) -> list[str]:
    """Of the files ``names`` (relative to ``folder``), those that exist and are not what
    spslidar wrote: not in ``sums`` (their SHA-256 as a marker recorded it, or a list of the
    SHA-256 that count as spslidar's) or changed since. ``run``'s result folders and
    ``reproduce``'s report folders both ask it."""
    return [name for name in names
            if (folder / name).is_file()
            and sha256_file(folder / name) not in _hashes(sums.get(name))]


#: folders whose outputs are being journaled: folder -> the names (relative, POSIX) of the
#: files whose SHA-256 goes into the marker before they are moved into place
_JOURNALS: dict[Path, frozenset[str]] = {}


@contextlib.contextmanager
def journal(folder: str | os.PathLike, names) -> Iterator[None]:
    """While the block runs, every file ``folder/NAME`` (``NAME`` in ``names``) written
    through :func:`atomic_file`, :func:`atomic_path` or the ``atomic_write_*`` functions has
    its SHA-256 added to the ``pending`` record of ``folder``'s marker *before* it is moved
    into place, so that an interrupt at any moment leaves no file the marker does not know
    (:func:`owned_sums`); :func:`record_outputs` then takes it into ``written``.

    Parameters
    ----------
    folder : str or os.PathLike
        A folder :func:`~spslidar.outdir.claim_folder` claimed.
    names : iterable of str
        Paths relative to ``folder`` (``fig2/fig2.png``).
    """
    key = Path(os.path.abspath(os.fspath(folder)))
    _JOURNALS[key] = frozenset(names)
    try:
        yield
    finally:
        _JOURNALS.pop(key, None)


def _note_pending(path: Path, tmp: str | os.PathLike) -> None:
    """Add the SHA-256 of ``tmp`` to the marker's pending record of ``path`` if a
    :func:`journal` covers it."""
    full = Path(os.path.abspath(os.fspath(path)))
    for folder, names in list(_JOURNALS.items()):
        try:
            rel = full.relative_to(folder).as_posix()
        except ValueError:
            continue
        if rel not in names:
            continue
        meta = read_marker(folder)
        if meta is None:
            return
        pending = meta.get("pending") if isinstance(meta.get("pending"), dict) else {}
        sums = sorted(_hashes(pending.get(rel)) | {sha256_file(tmp)})
        meta["pending"] = {**pending, rel: sums}
        atomic_write_text(folder / MARKER, json.dumps(meta, indent=1) + "\n")
        return


def owned_sums(folder: str | os.PathLike) -> dict[str, set[str]] | None:
    """The SHA-256 that count as the folder's command's own, per file: what its marker
    records as ``written`` and what a :func:`journal` noted before an interrupt. None: a
    marker of an earlier version, which recorded none (its files cannot be told apart)."""
    meta = read_marker(folder) or {}
    written = meta.get("written")
    if not isinstance(written, dict):
        return None
    sums = {name: _hashes(value) for name, value in written.items()}
    pending = meta.get("pending")
    for name, value in (pending.items() if isinstance(pending, dict) else ()):
        sums.setdefault(name, set()).update(_hashes(value))
    return sums


def foreign_outputs(folder: str | os.PathLike, names) -> list[str]:
    """Of the files ``names`` (relative to ``folder``), those that exist and that the
    folder's command did not write as they are (a user's, or edited since); none in a
    folder of an earlier version (:func:`owned_sums` None)."""
    sums = owned_sums(folder)
    return [] if sums is None else changed_files(Path(folder), names, sums)


def record_outputs(folder: str | os.PathLike, names, legacy=(), extra=None) -> None:
    """Record in the marker, as ``written`` with their SHA-256, the files ``names`` that
    exist (and ``legacy`` too, in a folder of an earlier version whose marker recorded none),
    and drop their pending record (``extra``: more keys for the marker, e.g. what made
    them)."""
    folder = Path(folder)
    meta = read_marker(folder) or {"kind": "unknown", "files": []}
    meta.update(extra or {})
    written = meta.get("written")
    if not isinstance(written, dict):
        written, names = {}, [*names, *legacy]
    pending = meta.get("pending") if isinstance(meta.get("pending"), dict) else {}
    for name in dict.fromkeys(names):
        pending.pop(name, None)
        if (folder / name).is_file():
            written[name] = sha256_file(folder / name)
    meta["written"] = dict(sorted(written.items()))
    meta.pop("pending", None)
    if pending:
        meta["pending"] = pending
    atomic_write_text(folder / MARKER, json.dumps(meta, indent=1) + "\n")


def sha256_file(path: str | os.PathLike) -> str:
    """The SHA-256 of a file's content (hex), read in 1 MiB blocks."""
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


@contextlib.contextmanager
def atomic_file(path: str | os.PathLike[str]) -> Iterator[BinaryIO]:
    """Open ``path`` for writing, all or nothing: a context manager yielding a binary file.

    Parameters
    ----------
    path : str or os.PathLike
        The file; its folder must exist. An existing file is replaced only once the block
        has finished without an exception.

    Yields
    ------
    BinaryIO
        A temporary file in the same folder (so ``os.replace`` is atomic).

    Notes
    -----
    When the block ends the file is flushed to disk and moved onto ``path``; on any error
    (a full disk, KeyboardInterrupt included) the temporary file is removed and ``path`` is
    untouched. The file's mode is ``0o666`` less the process's umask (``0o644`` under umask
    022), as for a file opened with ``open(path, 'w')``.
    """
    path = Path(path)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    try:
        with os.fdopen(fd, "wb") as fh:
            yield fh
            fh.flush()
            os.fsync(fh.fileno())
        os.chmod(tmp, umask_mode(0o666))
        _note_pending(path, tmp)  # (a journaled folder's marker knows it before it is there)
        os.replace(tmp, path)
    except BaseException:
        try:
            os.unlink(tmp)
        except OSError:
            pass
        raise


@contextlib.contextmanager
def atomic_path(path: str | os.PathLike[str]) -> Iterator[Path]:
    """A temporary path for a writer that wants a file name (``fig.savefig``), moved onto
    ``path`` once the block has finished: all or nothing, as :func:`atomic_file`.

    Parameters
    ----------
    path : str or os.PathLike
        The file; its folder must exist.

    Yields
    ------
    Path
        A new name in the same folder, ending as ``path`` does (``.png``: a writer that
        reads the format off the suffix writes the same format).
    """
    path = Path(path)
    fd, name = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.",
                                suffix=f".tmp{path.suffix}")
    os.close(fd)
    tmp = Path(name)
    try:
        yield tmp
        with open(tmp, "rb+") as fh:
            os.fsync(fh.fileno())
        os.chmod(tmp, umask_mode(0o666))
        _note_pending(path, tmp)
        os.replace(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise


def atomic_write_bytes(path: str | os.PathLike[str], data: bytes) -> None:
    """Write ``data`` to ``path`` atomically, with the umask's permissions.

    Parameters
    ----------
    path : str or os.PathLike
        The file; its folder must exist. An existing file is replaced.
    data : bytes
        The whole content.

    Notes
    -----
    See :func:`atomic_file` (temporary file in the same folder, fsync, ``os.replace``; on any
    error ``path`` is untouched and nothing is left behind).
    """
    with atomic_file(path) as fh:
        fh.write(data)


def atomic_write_text(path: str | os.PathLike[str], text: str) -> None:
    """Write ``text`` (UTF-8, newlines as given) to ``path`` atomically.

    See :func:`atomic_write_bytes` (same folder, fsync, ``os.replace``, umask permissions).
    """
    atomic_write_bytes(path, text.encode("utf-8"))
