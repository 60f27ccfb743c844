"""Output folders that never lose a user's files.

``spslidar run --out DIR`` writes its result into a temporary folder on the filesystem of
``DIR`` and moves it into place only once complete. ``DIR`` may be

* a path that does not exist yet (the temporary folder is made beside it and renamed to it,
  atomically);
* an existing empty folder, a mount point or a link to a folder on another filesystem
  included (the temporary folder is made inside it, so that only the folder itself need be
  writable, and the finished files are moved into it);
* a previous spslidar result, and only with ``overwrite=True`` (the new files replace the old
  ones; the folder itself, its permissions and anything a shell has open there stay). The
  marker lists the old and the new files' SHA-256 while they are moved, and an interrupted
  move is undone, so the folder holds the old result or the new one, never a mix refused as
  edited.

Anything else (a file, or a folder holding anything but a spslidar result's files) is refused
with a one-line :class:`~spslidar.errors.SpslidarError` before any work is done. Nothing is
ever deleted or replaced that spslidar did not write: spslidar knows its own outputs by a
marker file, :data:`~spslidar.outwrite.MARKER`, that it writes with them (the kind of output,
a random id, the version and the names of the files it wrote), not by their names; a folder
that merely holds a ``metrics.json`` is not a result. The same rule holds for every command
that writes: ``sweep`` and ``reproduce`` write into a folder that is new, empty or marked as
theirs (:func:`claim_folder`), ``run --save-ptu`` replaces a PTU file and its two arrays only
when their own marker proves they are what it wrote (:mod:`spslidar.outfiles`).
A command writing files into a folder it fills over time first notes each file's SHA-256 in
the folder's marker (:func:`~spslidar.outwrite.journal`), then moves it into place, so that
whatever the moment of an interrupt the marker knows every file it wrote
(:func:`~spslidar.outwrite.owned_sums`, :func:`~spslidar.outwrite.record_outputs`). The
files themselves are written all or nothing by :mod:`spslidar.outwrite`.

Folders and files are created with the user's umask (``tempfile.mkdtemp`` alone would leave
the folder ``0700``).
"""

from __future__ import annotations

import contextlib
import errno
import json
import os
import shutil
import tempfile
import uuid
from collections.abc import Callable
from pathlib import Path

from .errors import ConfigError, SpslidarError
from .outwrite import (  # re-exported: the names of the output rules' public API
    MARKER,
    _hashes,
    atomic_file,
    atomic_path,
    atomic_write_bytes,
    atomic_write_text,
    changed_files,
    foreign_outputs,
    journal,
    owned_sums,
    read_marker,
    record_outputs,
    sha256_file,
    umask_mode,
)

__all__ = ["MARKER", "RESULT_FILES", "atomic_file", "atomic_path", "atomic_write_bytes",
           "atomic_write_text", "changed_files", "check_output", "claim_folder",
           "foreign_outputs", "is_result", "journal", "owned_sums", "read_marker",
           "record_outputs", "release_folder", "sha256_file", "umask_mode", "write_result_dir"]

#: the prefix of the temporary folder a result is written into inside ``--out`` (ignored when
#: a folder is checked: it is this module's own, and removed when the write ends)
TMP_PREFIX = ".spslidar-tmp-"

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


def _marker_text(kind: str, files, run_id: str | None = None,
                 sums: dict[str, str] | None = None) -> str:
    from .version import __version__

    meta = {"kind": kind, "id": run_id or uuid.uuid4().hex, "version": __version__,
            "files": sorted(files)}
    if sums is not None:
        meta["sha256"] = dict(sorted(sums.items()))
    return json.dumps(meta, indent=1) + "\n"


def _changed_files(folder: Path) -> list[str]:
    """The files of a previous result that differ from what spslidar wrote (the SHA-256 its
    marker records, or while a replacement was moving files in, the previous result's too),
    and those its marker lists without a SHA-256 (a marker of an earlier version, or edited:
    such a file cannot be told from a user's, and ``--overwrite`` deleted a user's
    ``notes.txt`` added to the list, an outside audit of 2026-12-03)."""
    meta = read_marker(folder) or {}
    sums = meta.get("sha256")
    both = ({name: _hashes(value) for name, value in sums.items()}
            if isinstance(sums, dict) else {})
    previous = meta.get("previous_sha256")
    if isinstance(previous, dict):  # a replacement cut short (power lost) during its moves
        for name, value in previous.items():
            both.setdefault(name, set()).update(_hashes(value))
    listed = {n for n in meta.get("files", ()) if isinstance(n, str)}
    return changed_files(folder, sorted(listed | set(both)), both)


def _entries(folder: Path) -> set[str]:
    """The names in ``folder``, less the temporary folders of this module."""
    return {p.name for p in Path(folder).iterdir()
            if not (p.name.startswith(TMP_PREFIX) and p.is_dir() and not p.is_symlink())}


def is_result(folder: Path) -> bool:
    """Whether ``folder`` holds a result spslidar wrote (its marker says so) and nothing else
    (every file in it is one the marker lists)."""
    meta = read_marker(folder)
    if meta is None or meta["kind"] != "result":
        return False
    try:
        names = _entries(folder) - {MARKER}
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
    # (an --out through a symlink loop, loopA/sub, ran the whole work and then ended in a
    # RuntimeError traceback where its folder was resolved; and an --out of 4070 bytes ran,
    # then failed naming a temporary path too long for the filesystem: an audit of
    # 2026-11-30) the folder that receives the files, links resolved, is known here, and so
    # is the longest path written under it
    exists = path.exists() or path.is_symlink()  # (tested once: a folder removed between two
    # tests left the name below unbound, a review of 2026-11-30)
    if not exists:
        real = _resolve(path.parent, f"{option} {out}") / path.name
        check_name_fits(real, f"{option} {out}", inside=INSIDE_EXTRA)
    if exists:
        if not path.is_dir():
            raise SpslidarError(f"{option} {out}: exists and is not a folder")
        # its temporary folder is made inside it (.spslidar-tmp-XXXXXXXX/...)
        _check_path_fits(_resolve(path, f"{option} {out}"), len(TMP_PREFIX) + TMP_RANDOM + 2
                         + INSIDE_EXTRA, f"{option} {out}")
        try:
            empty = not _entries(path)
        except OSError as exc:
            raise SpslidarError(f"{option} {out}: cannot read the folder "
                                f"({exc.strerror})") from None
        if not empty:
            if not is_result(path):
                marker = read_marker(path)
                other = marker.get("kind") if isinstance(marker, dict) else None
                # (a result's folder with a user's file added was said to be "the folder of
                # a 'spslidar result', not of a run", an audit: the user's files are named)
                extra = (sorted(_entries(path) - {MARKER} - set(marker.get("files") or []))
                         if isinstance(marker, dict) else [])
                why = ("it holds a metrics.json but no spslidar marker, so spslidar did not "
                       "write it (or wrote it before version 0.2.0)"
                       if (path / "metrics.json").exists() and marker is None else
                       "it holds a spslidar result and files spslidar did not write: "
                       + ", ".join(extra[:3]) + (f" and {len(extra) - 3} more"
                                                  if len(extra) > 3 else "")
                       if other == "result" and extra else
                       f"it is the folder of a 'spslidar {other}', not of a run"
                       if isinstance(other, str) and other else
                       "it holds files spslidar did not write")
                # (not "is not a spslidar result (it holds a spslidar result and ...)",
                # which read as a contradiction, an outside audit)
                what = ("holds files besides a spslidar result" if other == "result" and extra
                        else "is not empty and is not a spslidar result")
                raise SpslidarError(
                    f"{option} {out}: the folder {what} ({why}); refusing to write into it "
                    f"(choose a new or empty folder)")
            if not overwrite:
                raise SpslidarError(f"{option} {out}: holds a previous spslidar result; pass "
                                    f"{replace} to replace it, or choose a new folder")
            changed = _changed_files(path)
            if changed:  # (a user's depth.npy copied over the result's was replaced)
                raise SpslidarError(
                    f"{option} {out}: {', '.join(changed)} changed since spslidar wrote "
                    f"{'it' if len(changed) == 1 else 'them'} (or its marker records no "
                    f"checksum of {'it' if len(changed) == 1 else 'them'}); refusing to "
                    f"replace a file someone edited (move it away, or choose a new folder)")
        # the files are written and moved in it: a read-only folder failed only after the
        # work, naming a temporary path; its parent is not written (a writable empty folder
        # in a read-only one is accepted)
        _check_writable(path, f"{option} {out}", make_parents=False)
        return path
    parent = path.parent
    if parent.exists() and not parent.is_dir():
        raise SpslidarError(f"{option} {out}: {parent} is not a folder")
    # (where its missing folders are made: through a dangling link, at the link's target)
    _check_writable(real.parent, f"{option} {out}", make_parents=True)
    return path


def _resolve(path: Path, what: str) -> Path:
    """``path`` with its links resolved (where files written there really go); a path that
    cannot be followed (a loop of symbolic links: Python's ``RuntimeError`` or ``OSError``
    ``ELOOP``) refused in one line.

    The deepest part of ``path`` that exists is resolved strictly first: from Python 3.13 a
    non-strict ``Path.resolve`` hands a loop back unresolved instead of raising, and the
    loop was met only after the work, in a temporary folder's name (a portability audit of
    2026-11-30)."""

    def is_loop(exc: BaseException) -> bool:
        return isinstance(exc, RuntimeError) or getattr(exc, "errno", None) == errno.ELOOP

    part, loop = path, False
    while True:  # (lstat follows every component but the last: a loop above it raises)
        try:
            os.lstat(part)
            break
        except FileNotFoundError:
            if part.parent == part:
                break
            part = part.parent
        except OSError as exc:  # (another error, an unreadable folder: resolved as before)
            loop = is_loop(exc)
            break
    if not loop:
        try:
            part.resolve(strict=True)
        except (RuntimeError, OSError) as exc:  # (a dangling link: followed as far as it goes)
            loop = is_loop(exc)
    try:
        if loop:
            raise RuntimeError("a loop of symbolic links")
        return path.resolve()
    except (RuntimeError, OSError) as exc:
        why = ("it leads through a loop of symbolic links" if is_loop(exc) else
               f"it cannot be followed ({getattr(exc, 'strerror', None) or exc})")
        raise SpslidarError(f"{what}: {path}: {why}; choose another path") from None


#: what spslidar's temporary names add to a name (``.NAME.tmp-XXXXXXXX``,
#: ``.NAME.XXXXXXXX.tmp``, ``.NAME.old-XXXXXXXX``)
TMP_NAME_EXTRA = 14
#: the random part of a temporary name (``tempfile``'s, and spslidar's own)
TMP_RANDOM = 8
#: the folder, inside a result's temporary folder, that a replaced result's files are moved
#: aside into while the new ones are moved in
ASIDE = ".previous"
#: the longest path a result's temporary folder holds: the marker's temporary name
#: (``.spslidar-output.json.XXXXXXXX.tmp``), or a previous result's file moved aside
INSIDE_EXTRA = max(len(MARKER) + TMP_NAME_EXTRA, len(ASIDE) + 1 + max(map(len, RESULT_FILES)))


def _pathconf(base: Path, name: str, default: int) -> int:
    """``os.pathconf(name)`` of the filesystem of ``base`` (or of its nearest existing
    ancestor), ``default`` where it cannot tell."""
    while not base.exists() and base != base.parent:
        base = base.parent
    try:
        limit = int(os.pathconf(base, name))
    except (OSError, ValueError, AttributeError):  # pragma: no cover - no pathconf
        return default
    return limit if limit > 0 else default


def _path_max(base: Path) -> int:
    """``PC_PATH_MAX`` of the filesystem of ``base``, the terminating NUL included: 4096
    where ``os.pathconf`` cannot tell."""
    return _pathconf(base, "PC_PATH_MAX", 4096)


def _check_path_fits(path: Path, more: int, what: str) -> None:
    """Refuse, before any work, an absolute ``path`` under which spslidar writes paths
    ``more`` bytes longer than the filesystem's ``PC_PATH_MAX`` allows."""
    size = len(os.fsencode(path))
    most = _path_max(path.parent) - 1  # (PATH_MAX counts the terminating NUL)
    if size + more > most:
        raise SpslidarError(f"{what}: its path is {size} bytes long (absolute), and "
                            f"spslidar writes paths up to {more} bytes longer under it "
                            f"(its temporary names), beyond this filesystem's "
                            f"limit of {most} bytes for a path: choose a path of at most "
                            f"{most - more} bytes")


def check_name_fits(path: Path, what: str, extra: int = TMP_NAME_EXTRA,
                    inside: int = 0) -> None:
    """Refuse, before any work, a name that fits the filesystem but not with the ``extra``
    bytes of the temporary name it is written under (a 245-character ``--out`` was refused
    after the whole run, naming a temporary folder: an outside audit of 2026-11-29), and an
    absolute path that does not fit ``PC_PATH_MAX`` with them and, for a folder written under
    a temporary name, with ``/`` and the ``inside`` bytes of the longest path written into it
    (an ``--out`` of 4070 bytes was refused after the whole run: an audit of 2026-11-30)."""
    limit = _pathconf(Path(os.path.abspath(path)).parent, "PC_NAME_MAX", 255)
    size = len(os.fsencode(path.name))
    if size + extra > limit:
        raise SpslidarError(f"{what}: its name is {size} bytes long, and spslidar writes it "
                            f"under a temporary name {extra} bytes longer, beyond this "
                            f"filesystem's {limit}: choose a name of at most "
                            f"{limit - extra} bytes")
    _check_path_fits(Path(os.path.abspath(path)), extra + (1 + inside if inside else 0), what)


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
    try:  # (os.access says yes to root everywhere, /proc included: try it)
        with tempfile.TemporaryFile(dir=base):
            pass
    except OSError as exc:
        raise SpslidarError(f"{what}: cannot write in {base} "
                            f"({exc.strerror or type(exc).__name__})") from None


def _target(path: Path, what: str) -> Path:
    """Where ``path``'s files really go: links resolved (a link to a folder on another
    filesystem is written through on that filesystem); a loop refused in one line."""
    if path.exists():
        return _resolve(path, what)
    return _resolve(path.parent, what) / path.name


def _move(src: Path, dst: Path) -> None:
    """``os.replace(src, dst)``; across filesystems (``EXDEV``), a copy under a temporary name
    beside ``dst`` moved onto it, then ``src`` removed: ``dst`` is never partial."""
    try:
        os.replace(src, dst)
        return
    except OSError as exc:
        if exc.errno != errno.EXDEV:
            raise
    tmp = dst.with_name(f".{dst.name}.{uuid.uuid4().hex[:8]}.tmp")
    try:
        shutil.copy2(src, tmp)
        os.replace(tmp, dst)
    except BaseException:
        with contextlib.suppress(OSError):
            tmp.unlink()
        raise
    with contextlib.suppress(OSError):
        src.unlink()


def _swap_in(target: Path, tmp: Path, written: set[str], previous: set[str],
             new_sums: dict[str, str], kind: str) -> None:
    """Move the files ``written`` from ``tmp`` into the existing folder ``target`` and the
    previous result's files (``previous``, which no longer belong) out of it, all or
    nothing.

    The marker first lists both results (their files and SHA-256), so that a process killed
    during the moves leaves a folder that a later ``--overwrite`` knows as spslidar's; the
    previous files are moved aside into ``tmp`` (not deleted) and, on any exception
    (KeyboardInterrupt included), put back with the previous marker: the folder then holds
    the previous result as it was, and "nothing was written" is true.
    """
    marker = target / MARKER
    try:
        old_marker = marker.read_bytes()
    except FileNotFoundError:
        old_marker = None
    old_sums = {name: sha256_file(target / name) for name in sorted(previous)
                if (target / name).is_file() and not (target / name).is_symlink()}
    meta = json.loads(_marker_text(kind, set(written) | set(old_sums), None, new_sums))
    meta["previous_sha256"] = old_sums
    aside = tmp / ASIDE
    aside.mkdir()
    os.chmod(aside, 0o700)  # (mkdir's mode less a umask of 0222 refused the moves aside)
    done = False
    try:
        atomic_write_text(marker, json.dumps(meta, indent=1) + "\n")
        for name in sorted(written):
            if name in old_sums:
                os.replace(target / name, aside / name)
            _move(tmp / name, target / name)
        for name in sorted(set(old_sums) - set(written)):  # only what the old marker lists
            os.replace(target / name, aside / name)
        final = json.loads(_marker_text(kind, written, None, new_sums))
        atomic_write_text(marker, json.dumps(final, indent=1) + "\n")
        done = True
    except BaseException:
        if not done:
            _undo_swap(target, tmp, aside, written, new_sums, old_marker)
        raise


def _put_back(moves, new_sums: dict[str, str], marker: Path, old_marker: bytes | None) -> None:
    """Undo moves ``(final, temporary, aside)`` from the state of the files (not from a log a
    signal could cut between a move and its record): a new file moved in goes, the old one
    put aside comes back, and so does the old marker."""
    for final, tmp, aside in moves:
        if not tmp.exists() and final.is_file() and not final.is_symlink() \
                and sha256_file(final) == new_sums.get(final.name):
            final.unlink()
        if aside.exists():
            os.replace(aside, final)
    if old_marker is None:
        marker.unlink(missing_ok=True)
    else:
        atomic_write_bytes(marker, old_marker)


def _undo_swap(target: Path, tmp: Path, aside: Path, written: set[str],
               new_sums: dict[str, str], old_marker: bytes | None) -> None:
    """Put back a folder :func:`_swap_in` was changing (:func:`_put_back`)."""
    names = sorted(set(written) | {p.name for p in aside.iterdir()})
    _put_back([(target / n, tmp / n, aside / n) for n in names], new_sums, target / MARKER,
              old_marker)


def write_result_dir(out: str | os.PathLike, fill: Callable[[Path], None],
                     overwrite: bool = False, option: str = "--out",
                     replace: str = "--overwrite") -> Path:
    """Create the result folder ``out`` through ``fill(tmp)``, all or nothing.

    ``fill`` writes the files (names from :data:`RESULT_FILES`) into a fresh temporary folder
    on ``out``'s filesystem (inside ``out`` when it exists, links resolved; beside it when it
    does not); the marker listing them is added; on any exception (KeyboardInterrupt
    included) the temporary folder is removed and ``out`` is untouched, or put back as it
    was when the files were being moved in. Replacing a previous result removes only the
    files its marker lists.

    The temporary folder stays writable by its owner (``0700``) while it is filled; a new
    folder is given the umask's mode (:func:`~spslidar.outwrite.umask_mode`) last, once its
    files and marker are in it, just before it is moved into place, and the files keep the
    mode they were created with (``0o666`` less the umask), so that a umask of ``0222`` gives
    a complete, read-only result.
    """
    path = check_output(out, overwrite, option, replace)
    existed = path.exists()
    target = _target(path, f"{option} {out}")
    was_empty = existed and not _entries(target)
    if existed:
        tmp = Path(tempfile.mkdtemp(prefix=TMP_PREFIX, dir=target))
    else:
        # (under umask 0222 the first missing folder was made read-only and the next one
        # could not be made in it, after the work: an audit of 2026-11-30) made as mkdir -p
        # makes them, writable and searchable by their owner whatever the umask
        for folder in reversed([p for p in (target.parent, *target.parent.parents)
                                if not p.exists()]):
            try:
                folder.mkdir()
            except FileExistsError:
                continue
            os.chmod(folder, umask_mode() | 0o300)
        tmp = Path(tempfile.mkdtemp(prefix=f".{path.name}.tmp-", dir=target.parent))
    # (the umask's mode was given to the folder before fill wrote into it: as non-root,
    # umask 0222 failed after the work, and 0777 also left a .NAME.tmp-* folder of mode 000
    # behind that could not be removed: an audit of 2026-11-30) 0700 while it is filled
    # (mkdtemp's 0700 less the umask: 0500 under 0222), the umask's mode last
    file_mode = umask_mode(0o666)
    try:
        os.chmod(tmp, 0o700)
        fill(tmp)
        written = {p.name for p in tmp.iterdir()}
        unknown = written - RESULT_FILES
        if unknown:  # pragma: no cover - a programming error, not user input
            raise RuntimeError(f"Result.save wrote {sorted(unknown)}, not named in "
                               f"spslidar.outdir.RESULT_FILES: add them there")
        for name in written:  # readable by their owner while their SHA-256 is taken
            os.chmod(tmp / name, file_mode | 0o600)
        sums = {name: sha256_file(tmp / name) for name in written}
        from .outlock import folder_lock

        with folder_lock(target.parent):  # (one writer from the last check to the swap)
            if not existed and not path.exists() and not path.is_symlink():
                atomic_write_text(tmp / MARKER, _marker_text("result", written, None, sums))
                for name in written:
                    os.chmod(tmp / name, file_mode)
                os.chmod(tmp, umask_mode())
                os.replace(tmp, target)
                return path
            if not existed or was_empty and _entries(target) - {tmp.name}:
                # another command wrote it meanwhile (two runs on one new or empty folder)
                raise SpslidarError(
                    f"{out}: another command wrote into this folder while this run was "
                    f"working (it was {'new' if not existed else 'empty'} when the run "
                    f"started); this run's result was not saved (run it again into a new "
                    f"folder)")
            path = check_output(out, overwrite, option, replace)  # nothing appeared meanwhile
            previous = set((read_marker(target) or {"files": []})["files"])
            _swap_in(target, tmp, written, previous, sums, "result")
            for name in written:  # (the folder itself stays as it is)
                os.chmod(target / name, file_mode)
    finally:
        with contextlib.suppress(OSError):  # (given the umask's mode, then not moved)
            os.chmod(tmp, 0o700)
        shutil.rmtree(tmp, ignore_errors=True)
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
        if not path.is_dir():
            _check_writable(path.parent, f"{option} {out}", make_parents=True)
        path.mkdir(parents=True, exist_ok=True)
        meta = json.loads(_marker_text(kind, []))
        meta["written"] = {}  # what it writes is recorded (a user's file put there is not)
        atomic_write_text(path / MARKER, json.dumps(meta, indent=1) + "\n")
        return path
    meta = read_marker(path)
    if meta is None and ((path / MARKER).exists() or (path / MARKER).is_symlink()):
        # (a damaged marker was said to be none, which sent the user looking for a file that
        # is there: an outside audit of 2026-12-03)
        raise ConfigError(
            f"{option} {out}: its spslidar marker {MARKER} is there but unreadable (damaged "
            f"or edited: not a marker's JSON), so the folder cannot be told to be an earlier "
            f"'spslidar {kind}''s, which it would resume; refusing to write into it, nothing "
            f"was changed (choose a new or empty folder)")
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

