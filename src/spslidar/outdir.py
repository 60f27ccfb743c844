"""Output folders that never lose a user's files.

``spslidar run --out DIR`` writes its result into a temporary folder next to ``DIR`` and moves
it into place only once complete. ``DIR`` may be

* a path that does not exist yet (the finished folder is renamed to it, atomically);
* an existing empty folder (the finished files are moved into it);
* a previous spslidar result, and only with ``overwrite=True`` (the new files replace the old
  ones; the folder itself, its permissions and anything a shell has open there stay).

Anything else (a file, or a folder holding anything but a spslidar result's files) is refused
with a one-line :class:`~spslidar.errors.SpslidarError` before any work is done. Nothing is
ever deleted that spslidar did not write: a previous result is recognised by its
``metrics.json`` and by holding nothing but result files.

Folders and files are created with the user's umask (``tempfile.mkdtemp`` alone would leave
the folder ``0700``).
"""

from __future__ import annotations

import json
import os
import shutil
import tempfile
from collections.abc import Callable
from pathlib import Path

from .errors import SpslidarError

__all__ = ["RESULT_FILES", "check_output", "is_result", "write_result_dir", "umask_mode"]

#: every file a ``spslidar run`` result folder may hold
RESULT_FILES = frozenset({"metrics.json", "depth.npy", "truth.npy", "valid.npy",
                          "confidence.npy", "reflectivity.npy", "points.ply", "depth2.npy",
                          "depth.png"})


def umask_mode(base: int = 0o777) -> int:
    """``base`` with the process's umask applied (0o777 -> 0o755 under umask 022)."""
    mask = os.umask(0)
    os.umask(mask)
    return base & ~mask


def is_result(folder: Path) -> bool:
    """Whether ``folder`` holds a previous spslidar result and nothing else."""
    try:
        names = {p.name for p in folder.iterdir()}
    except OSError:
        return False
    if "metrics.json" not in names or not names <= RESULT_FILES:
        return False
    try:
        with open(folder / "metrics.json") as fh:
            meta = json.load(fh)
    except (OSError, ValueError):
        return False
    return isinstance(meta, dict) and "version" in meta and "config" in meta


def check_output(out: str | os.PathLike, overwrite: bool = False) -> Path:
    """Check that a result can be written to ``out`` without losing anything.

    Parameters
    ----------
    out : path
        The output folder.
    overwrite : bool
        Allow replacing a previous spslidar result.

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
        raise SpslidarError("--out must name an output folder")
    path = Path(os.path.abspath(os.fspath(out)))
    if path.exists() or path.is_symlink():
        if not path.is_dir():
            raise SpslidarError(f"--out {out}: exists and is not a folder")
        try:
            empty = next(path.iterdir(), None) is None
        except OSError as exc:
            raise SpslidarError(f"--out {out}: cannot read the folder ({exc.strerror})") from None
        if not empty:
            if not is_result(path):
                raise SpslidarError(
                    f"--out {out}: the folder is not empty and is not a spslidar result; "
                    f"refusing to write into it (choose a new or empty folder)")
            if not overwrite:
                raise SpslidarError(f"--out {out}: holds a previous spslidar result; pass "
                                    f"--overwrite to replace it, or choose a new folder")
    parent = path.parent
    if parent.exists() and not parent.is_dir():
        raise SpslidarError(f"--out {out}: {parent} is not a folder")
    return path


def write_result_dir(out: str | os.PathLike, fill: Callable[[Path], None],
                     overwrite: bool = False) -> Path:
    """Create the result folder ``out`` through ``fill(tmp)``, all or nothing.

    ``fill`` writes the files (names from :data:`RESULT_FILES`) into a fresh temporary folder
    beside ``out``; on any exception (KeyboardInterrupt included) the temporary folder is
    removed and ``out`` is untouched.
    """
    path = check_output(out, overwrite)
    parent = path.parent
    parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=f".{path.name}.tmp-", dir=parent))
    try:
        os.chmod(tmp, umask_mode())
        fill(tmp)
        written = {p.name for p in tmp.iterdir()}
        unknown = written - RESULT_FILES
        if unknown:  # pragma: no cover - a programming error, not user input
            raise RuntimeError(f"unexpected result files {sorted(unknown)}")
        path = check_output(out, overwrite)  # nothing appeared meanwhile
        if not path.exists():
            os.replace(tmp, path)
            return path
        for name in sorted(written):
            os.replace(tmp / name, path / name)
        for name in RESULT_FILES - written:
            stale = path / name
            if stale.is_file():
                stale.unlink()
        tmp.rmdir()
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    return path
