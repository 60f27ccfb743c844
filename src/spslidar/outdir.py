"""Output folders that never lose a user's files.

``spslidar run --out DIR`` writes its result into a temporary folder next to ``DIR`` and moves
it into place only once complete. ``DIR`` may be

* a path that does not exist yet (the finished folder is renamed to it, atomically);
* an existing empty folder (the finished files are moved into it);
* a previous spslidar result, and only with ``overwrite=True`` (the new files replace the old
  ones; the folder itself, its permissions and anything a shell has open there stay).

Anything else (a file, or a folder holding anything but a spslidar result's files) is refused
with a one-line :class:`~spslidar.errors.SpslidarError` before any work is done. Nothing is
ever deleted or replaced that spslidar did not write: spslidar knows its own outputs by a
marker file, :data:`MARKER`, that it writes with them (the kind of output, a random id, the
version and the names of the files it wrote), not by their names; a folder that merely holds
a ``metrics.json`` is not a result. The same rule holds for every command that writes:
``sweep`` and ``reproduce`` write into a folder that is new, empty or marked as theirs
(:func:`claim_folder`), ``run --save-ptu`` replaces a PTU file and its two arrays only when
their own marker proves they are what it wrote (:func:`check_files`, :func:`write_files`).

Folders and files are created with the user's umask (``tempfile.mkdtemp`` alone would leave
the folder ``0700``).
"""

from __future__ import annotations

import contextlib
import hashlib
import json
import os
import shutil
import tempfile
import uuid
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import BinaryIO

from .errors import ConfigError, SpslidarError

__all__ = ["MARKER", "RESULT_FILES", "atomic_file", "atomic_write_bytes", "atomic_write_text",
           "changed_files", "check_files", "check_output", "claim_folder", "is_result",
           "read_marker",
           "release_folder",
           "sha256_file", "umask_mode", "write_files", "write_result_dir"]

#: the marker file spslidar writes into every output folder it owns
MARKER = ".spslidar-output.json"

#: Every file a ``spslidar run`` / ``reconstruct`` result folder may hold. A new output of
#: :meth:`~spslidar.pipeline.results.Result.save` needs its name here (one line): a name not
#: listed stops the save as a programming error. The marker of each result lists the files
#: that result actually wrote, and only those are ever replaced or removed.
RESULT_FILES = frozenset({
    "metrics.json",
    "depth.npy",
    "truth.npy",
    "valid.npy",
    "confidence.npy",
    "reflectivity.npy",
    "points.ply",
    "depth2.npy",
    "depth.png",
})


def umask_mode(base: int = 0o777) -> int:
    """``base`` with the process's umask applied (0o777 -> 0o755 under umask 022)."""
    mask = os.umask(0)
    os.umask(mask)
    return base & ~mask


def read_marker(folder: str | os.PathLike) -> dict | None:
    """The marker of an output folder spslidar wrote (``kind``, ``id``, ``version``,
    ``files``), or None."""
    try:
        with open(Path(folder) / MARKER) as fh:
            meta = json.load(fh)
    except (OSError, ValueError):
        return None
    if not (isinstance(meta, dict) and isinstance(meta.get("files"), list)
            and isinstance(meta.get("kind"), str)):
        return None
    return meta


def _marker_text(kind: str, files, run_id: str | None = None,
                 sums: dict[str, str] | None = None) -> str:
    from .version import __version__

    meta = {"kind": kind, "id": run_id or uuid.uuid4().hex, "version": __version__,
            "files": sorted(files)}
    if sums is not None:
        meta["sha256"] = dict(sorted(sums.items()))
    return json.dumps(meta, indent=1) + "\n"


def _write_marker(folder: Path, kind: str, files, run_id: str | None = None,
                  hashed: bool = False) -> None:
    sums = {name: sha256_file(folder / name) for name in files} if hashed else None
    atomic_write_text(folder / MARKER, _marker_text(kind, files, run_id, sums))


def changed_files(folder: Path, names, sums: dict[str, str]) -> list[str]:
    """Of the files ``names`` (relative to ``folder``), those that exist and are not what
    spslidar wrote: not in ``sums`` (their SHA-256 as a marker recorded it) or changed since.
    ``run``'s result folders and ``reproduce``'s report folders both ask it."""
    return [name for name in names
            if (folder / name).is_file() and sums.get(name) != sha256_file(folder / name)]


def _changed_files(folder: Path) -> list[str]:
    """The files of a previous result that differ from what spslidar wrote (the SHA-256 its
    marker records; a marker written before the hashes were kept has none to compare)."""
    sums = (read_marker(folder) or {}).get("sha256")
    if not isinstance(sums, dict):
        return []
    return changed_files(folder, sorted(sums), sums)


def is_result(folder: Path) -> bool:
    """Whether ``folder`` holds a result spslidar wrote (its marker says so) and nothing else
    (every file in it is one the marker lists)."""
    meta = read_marker(folder)
    if meta is None or meta["kind"] != "result":
        return False
    try:
        names = {p.name for p in Path(folder).iterdir()} - {MARKER}
    except OSError:
        return False
    return names <= set(meta["files"])


def check_output(out: str | os.PathLike, overwrite: bool = False, option: str = "--out",
                 replace: str = "--overwrite") -> Path:
    """Check that a result can be written to ``out`` without losing anything.

    Parameters
    ----------
    out : path
        The output folder.
    overwrite : bool
        Allow replacing a previous spslidar result.
    option, replace : str
        How the messages name the folder's argument and the permission to replace
        (the command line's ``--out`` and ``--overwrite``; Python's ``out_dir`` and
        ``overwrite=True``).

    Returns
    -------
    Path
        ``out`` made absolute.

    Raises
    ------
    SpslidarError
        One line saying why ``out`` cannot be used and what to do instead.
    """
    if out is None or str(out).strip() == "":
        raise SpslidarError(f"{option} must name an output folder")
    path = Path(os.path.abspath(os.fspath(out)))
    if path.exists() or path.is_symlink():
        if not path.is_dir():
            raise SpslidarError(f"{option} {out}: exists and is not a folder")
        try:
            empty = next(path.iterdir(), None) is None
        except OSError as exc:
            raise SpslidarError(f"{option} {out}: cannot read the folder "
                                f"({exc.strerror})") from None
        if not empty:
            if not is_result(path):
                why = ("it holds a metrics.json but no spslidar marker, so spslidar did not "
                       "write it (or wrote it before version 0.2.0)"
                       if (path / "metrics.json").exists() and read_marker(path) is None else
                       "it holds files spslidar did not write")
                raise SpslidarError(
                    f"{option} {out}: the folder is not empty and is not a spslidar result "
                    f"({why}); refusing to write into it (choose a new or empty folder)")
            if not overwrite:
                raise SpslidarError(f"{option} {out}: holds a previous spslidar result; pass "
                                    f"{replace} to replace it, or choose a new folder")
            changed = _changed_files(path)
            if changed:  # (a user's depth.npy copied over the result's was replaced)
                raise SpslidarError(
                    f"{option} {out}: {', '.join(changed)} changed since spslidar wrote "
                    f"{'it' if len(changed) == 1 else 'them'}; refusing to replace a file "
                    f"someone edited (move it away, or choose a new folder)")
        # the files are moved into it: a read-only folder failed only after the work, naming
        # a temporary path
        _check_writable(path, f"{option} {out}", make_parents=False)
    parent = path.parent
    if parent.exists() and not parent.is_dir():
        raise SpslidarError(f"{option} {out}: {parent} is not a folder")
    _check_writable(path.parent, f"{option} {out}", make_parents=True)
    return path


def _check_writable(folder: Path, what: str, make_parents: bool) -> None:
    """Refuse, before any work, a place nothing can be written to: ``folder`` (or, with
    ``make_parents``, its nearest existing ancestor, since the missing folders are created)
    must exist and be writable."""
    base = folder
    if make_parents:
        while not base.exists() and base != base.parent:
            base = base.parent
    elif not base.exists():
        raise SpslidarError(f"{what}: the folder {base} does not exist")
    if not base.is_dir():
        raise SpslidarError(f"{what}: {base} is not a folder")
    import tempfile

    try:  # (os.access says yes to root everywhere, /proc included: try it)
        with tempfile.TemporaryFile(dir=base):
            pass
    except OSError as exc:
        raise SpslidarError(f"{what}: cannot write in {base} "
                            f"({exc.strerror or type(exc).__name__})") from None


def write_result_dir(out: str | os.PathLike, fill: Callable[[Path], None],
                     overwrite: bool = False, option: str = "--out",
                     replace: str = "--overwrite") -> Path:
    """Create the result folder ``out`` through ``fill(tmp)``, all or nothing.

    ``fill`` writes the files (names from :data:`RESULT_FILES`) into a fresh temporary folder
    beside ``out``; the marker listing them is added; on any exception (KeyboardInterrupt
    included) the temporary folder is removed and ``out`` is untouched. Replacing a previous
    result removes only the files its marker lists.
    """
    path = check_output(out, overwrite, option, replace)
    parent = path.parent
    parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=f".{path.name}.tmp-", dir=parent))
    try:
        os.chmod(tmp, umask_mode())
        fill(tmp)
        written = {p.name for p in tmp.iterdir()}
        unknown = written - RESULT_FILES
        if unknown:  # pragma: no cover - a programming error, not user input
            raise RuntimeError(f"Result.save wrote {sorted(unknown)}, not named in "
                               f"spslidar.outdir.RESULT_FILES: add them there")
        _write_marker(tmp, "result", written, hashed=True)
        path = check_output(out, overwrite, option, replace)  # nothing appeared meanwhile
        if not path.exists():
            os.replace(tmp, path)
            return path
        previous = set((read_marker(path) or {"files": []})["files"])
        for name in sorted(written):
            os.replace(tmp / name, path / name)
        for name in previous - written:  # only what the previous result's marker lists
            stale = path / name
            if stale.is_file():
                stale.unlink()
        os.replace(tmp / MARKER, path / MARKER)
        tmp.rmdir()
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    return path


def claim_folder(out: str | os.PathLike, kind: str, option: str = "--out") -> Path:
    """The output folder of a command that fills it over time (``sweep``, ``reproduce``):
    created (with its marker) when new or empty, taken as it is when its marker says this
    kind of command wrote it (an interrupted run resumes there), refused in one line
    otherwise, before any work: a folder holding a user's ``results.csv`` or ``report.md``
    is never written into.

    Returns
    -------
    Path
        ``out`` made absolute.
    """
    if out is None or str(out).strip() == "":
        raise ConfigError(f"{option} must name an output folder")
    path = Path(os.path.abspath(os.fspath(out)))
    if path.exists() and not path.is_dir():
        raise ConfigError(f"{option} {out}: exists and is not a folder")
    try:
        empty = not path.exists() or next(path.iterdir(), None) is None
    except OSError as exc:
        raise ConfigError(f"{option} {out}: cannot read the folder ({exc.strerror})") from None
    if path.is_dir():  # what it writes goes into it
        _check_writable(path, f"{option} {out}", make_parents=False)
    if empty:
        _check_writable(path.parent, f"{option} {out}", make_parents=True)
        path.mkdir(parents=True, exist_ok=True)
        _write_marker(path, kind, [])
        return path
    meta = read_marker(path)
    if meta is None or meta["kind"] != kind:
        what = ("no spslidar marker (outputs of spslidar before 0.2.0 have none)"
                if meta is None else f"a spslidar {meta['kind']}")
        raise ConfigError(
            f"{option} {out}: the folder is not empty and holds {what}, not the output of an "
            f"earlier 'spslidar {kind}' (which it would resume); refusing to write into it "
            f"(choose a new or empty folder)")
    return path


def release_folder(folder: Path, existed: bool) -> bool:
    """Take back a folder :func:`claim_folder` claimed if nothing but its marker and empty
    folders (a cache made ready) are in it (the work was refused before it wrote anything):
    they go, and the folder too where it did not exist before. Returns whether it was taken
    back."""
    subdirs = []
    for root, dirs, files in os.walk(folder):
        if Path(root) == folder:
            files = [f for f in files if f != MARKER]
        if files or any((Path(root) / d).is_symlink() for d in dirs):
            return False
        subdirs.extend(Path(root) / d for d in dirs)
    for d in sorted(subdirs, key=lambda p: len(p.parts), reverse=True):
        d.rmdir()
    (folder / MARKER).unlink(missing_ok=True)
    if not existed:
        folder.rmdir()
    return True


def sha256_file(path: str | os.PathLike) -> str:
    """The SHA-256 of a file's content (hex), read in 1 MiB blocks."""
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def _files_marker(first: Path) -> Path:
    return first.with_name(f".{first.name}.spslidar.json")


def check_files(paths, overwrite: bool = False, option: str = "--save-ptu",
                outside: str | os.PathLike | None = None) -> None:
    """Refuse (one line, before any work) to write files that exist, unless ``overwrite``
    and their marker (written by :func:`write_files` beside the first) proves that spslidar
    wrote them, unchanged since (the SHA-256 of each); and files that are the result folder
    ``outside`` (``--out``) or lie in it (``run --out same --save-ptu same`` wrote the PTU,
    then refused the result folder, leaving both)."""
    paths = [Path(p) for p in paths]
    if outside is not None and str(outside).strip():
        folder = Path(os.path.abspath(os.fspath(outside)))
        for p in paths:
            full = Path(os.path.abspath(p))
            if full == folder or folder in full.parents:
                where = "the --out folder" if full == folder else "inside --out"
                raise SpslidarError(f"{option} {paths[0]}: {p} would be {where} {outside}; "
                                    f"save it beside the result folder")
    for folder in dict.fromkeys(Path(os.path.abspath(p)).parent for p in paths):
        _check_writable(folder, f"{option} {paths[0]}", make_parents=False)
    present = [p for p in paths if p.exists() or p.is_symlink()]
    if not present:
        return
    if not overwrite:
        raise SpslidarError(f"{option}: {present[0]} exists; use --overwrite to replace it")
    marker = _files_marker(paths[0])
    try:
        with open(marker) as fh:
            sums = json.load(fh).get("sha256", {})
    except (OSError, ValueError, AttributeError):
        sums = {}
    for p in present:
        if not p.is_file() or sums.get(p.name) != sha256_file(p):
            why = ("or it changed since" if marker.exists() else
                   f"no marker {marker.name} beside it; spslidar before 0.2.0 wrote none")
            raise SpslidarError(f"{option}: {p} exists and is not a file spslidar wrote ({why}); "
                                f"refusing to replace it, even with --overwrite")


def write_files(paths, write: Callable[[list[Path]], None], overwrite: bool = False,
                option: str = "--save-ptu") -> None:
    """Write a group of files all or nothing: ``write(tmp_paths)`` writes each under a
    temporary name in its own folder; on success they are moved into place and a marker
    (names and SHA-256) is written beside the first; on any failure (a full disk, Ctrl-C) the
    temporary files are removed and nothing of the user's is touched."""
    paths = [Path(os.path.abspath(os.fspath(p))) for p in paths]
    check_files(paths, overwrite, option)
    tmps = [p.with_name(f".{p.name}.tmp-{uuid.uuid4().hex[:8]}") for p in paths]
    try:
        write(tmps)
        for t in tmps:
            os.chmod(t, umask_mode(0o666))
        sums = {p.name: sha256_file(t) for p, t in zip(paths, tmps, strict=True)}
        check_files(paths, overwrite, option)  # nothing appeared meanwhile
        marker = _files_marker(paths[0])
        from .version import __version__

        for p, t in zip(paths, tmps, strict=True):
            os.replace(t, p)
        atomic_write_text(marker, json.dumps({"kind": "files", "version": __version__,
                                              "sha256": sums}, indent=1) + "\n")
    except BaseException:
        for t in tmps:
            try:
                t.unlink()
            except OSError:
                pass
        raise


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
        os.replace(tmp, path)
    except BaseException:
        try:
            os.unlink(tmp)
        except OSError:
            pass
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
