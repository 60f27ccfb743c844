"""Files written beside a path the user names, not into an output folder: the PTU of
``run --save-ptu`` and its two arrays.

The rule of :mod:`spslidar.outdir` holds for them too: a file is replaced only when the
marker written beside the first of them (``.NAME.spslidar.json``, with each file's SHA-256)
proves that spslidar wrote it, unchanged since; a user's file of the marker's own name is
refused too (an audit found it replaced, 2026-11-28). Written all or nothing: the files go in
under temporary names, the ones they replace are moved aside, and an interrupt puts them
back.
"""

from __future__ import annotations

import json
import os
import uuid
from collections.abc import Callable
from pathlib import Path

from .errors import SpslidarError
from .outdir import (
    _check_writable,
    _hashes,
    _put_back,
    atomic_write_text,
    sha256_file,
    umask_mode,
)
from .outwrite import read_json_record

__all__ = ["check_files", "write_files"]


def _files_marker(first: Path) -> Path:
    return first.with_name(f".{first.name}.spslidar.json")


def _files_sums(marker: Path) -> dict[str, set[str]] | None:
    """The SHA-256 per file that a marker of :func:`write_files` counts as spslidar's (the
    files it wrote and, while they were being moved in, the ones they replaced), or None
    when ``marker`` is not such a marker (a user's file of that name)."""
    try:
        if marker.is_symlink():
            return None
    except OSError:  # (an unreadable folder: no marker of spslidar's)
        return None
    meta = read_json_record(marker)
    if not (isinstance(meta, dict) and meta.get("kind") == "files"
            and isinstance(meta.get("sha256"), dict)):
        return None
    sums = {name: _hashes(value) for name, value in meta["sha256"].items()}
    previous = meta.get("previous_sha256")
    for name, value in (previous.items() if isinstance(previous, dict) else ()):
        sums.setdefault(name, set()).update(_hashes(value))
    return sums


def check_files(paths, overwrite: bool = False, option: str = "--save-ptu",
                outside: str | os.PathLike | None = None) -> None:
    """Refuse (one line, before any work) to write files that exist, unless ``overwrite``
    and their marker (written by :func:`write_files` beside the first) proves that spslidar
    wrote them, unchanged since (the SHA-256 of each); files that are the result folder
    ``outside`` (``--out``) or lie in it (``run --out same --save-ptu same`` wrote the PTU,
    then refused the result folder, leaving both); and a file where the marker goes
    (``.NAME.spslidar.json``) that is not a marker of spslidar's (a user's file of that name
    was replaced without a word)."""
    paths = [Path(p) for p in paths]
    if outside is not None and str(outside).strip():
        folder = Path(os.path.abspath(os.fspath(outside)))
        # (and the marker: --out .FILE.ptu.spslidar.json wrote the PTU, then refused the
        # folder the marker had become, leaving the files; an audit of 2026-11-29)
        for p in [*paths, _files_marker(paths[0])]:
            full = Path(os.path.abspath(p))
            if full == folder or folder in full.parents:
                where = "the --out folder" if full == folder else "inside --out"
                raise SpslidarError(f"{option} {paths[0]}: {p} would be {where} {outside}; "
                                    f"save it beside the result folder")
    for folder in dict.fromkeys(Path(os.path.abspath(p)).parent for p in paths):
        _check_writable(folder, f"{option} {paths[0]}", make_parents=False)
    from .outdir import check_name_fits

    marker = _files_marker(paths[0])
    for p in [*paths, marker]:  # (the marker, .NAME.spslidar.json, has a temporary name too)
        check_name_fits(p, f"{option} {paths[0]}")
    sums = _files_sums(marker)
    if sums is None and (marker.exists() or marker.is_symlink()):
        raise SpslidarError(f"{option}: {marker} exists and is not a marker spslidar wrote "
                            f"(it would be replaced by the marker of {paths[0].name}); "
                            f"refusing to replace it, even with --overwrite (move it away, "
                            f"or choose another file name)")
    sums = sums or {}
    present = [p for p in paths if p.exists() or p.is_symlink()]
    if not present:
        return
    # (whose files they are said first: "use --overwrite" was said of a user's file, which
    # --overwrite then refused, an outside audit of 2026-12-03)
    for p in present:
        if not p.is_file() or sha256_file(p) not in sums.get(p.name, set()):
            why = ("or it changed since" if marker.exists() else
                   f"no marker {marker.name} beside it; spslidar before 0.2.0 wrote none")
            raise SpslidarError(f"{option}: {p} exists and is not a file spslidar wrote ({why}); "
                                f"refusing to replace it, even with --overwrite")
    if not overwrite:
        raise SpslidarError(f"{option}: {present[0]} exists; use --overwrite to replace it")


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

        old = {p.name: sha256_file(p) for p in paths if p.is_file()}
        try:
            old_marker: bytes | None = marker.read_bytes()
        except FileNotFoundError:
            old_marker = None
        # the marker first knows both (a kill during the moves leaves files it accepts)...
        meta = {"kind": "files", "version": __version__, "sha256": sums}
        asides = [p.with_name(f".{p.name}.old-{uuid.uuid4().hex[:8]}") for p in paths]
        done = False
        try:  # (the marker inside: an interrupt just after it left it rewritten, an audit)
            atomic_write_text(marker,
                              json.dumps({**meta, "previous_sha256": old}, indent=1) + "\n")
            for p, t, a in zip(paths, tmps, asides, strict=True):
                if p.name in old:
                    os.replace(p, a)
                os.replace(t, p)
            atomic_write_text(marker, json.dumps(meta, indent=1) + "\n")  # ...then the new
            done = True
        except BaseException:
            if not done:  # an interrupt during the moves: the files put back as they were
                _put_back(list(zip(paths, tmps, asides, strict=True)), sums, marker, old_marker)
            raise
        for a in asides:
            a.unlink(missing_ok=True)
    except BaseException as exc:
        for t in tmps:
            try:
                t.unlink()
            except OSError:
                pass
        if isinstance(exc, OSError) and not exc.filename:
            # (a full disk under --save-ptu was said as "while writing --out DIR", a folder
            # on another disk with room: an outside audit of 2026-12-03)
            raise OSError(exc.errno, exc.strerror or str(exc),
                          f"while writing {option} {paths[0]} (nothing of it was left, and "
                          f"what was there before is as it was)") from exc
        raise
