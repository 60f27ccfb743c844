"""What a sweep writes: atomic files, the run cache records and the tidy CSV table.

Every file of a sweep or a reproduction report goes through
:func:`~spslidar.outwrite.atomic_write_text` or :func:`~spslidar.outwrite.atomic_write_bytes`
(temporary file in the same folder, fsync, ``os.replace``), so an interrupted run never leaves
a half-written file, and the files get the permissions of the user's umask like every other
output of spslidar (:func:`spslidar.outwrite.umask_mode`; ``tempfile.mkstemp`` alone would
leave them ``0600``).
"""

from __future__ import annotations

import csv
import io
import json
import os
import re
import sys
from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import Any

from spslidar.errors import ConfigError
from spslidar.experiments.sweep.grid import (
    ERROR_KEY,
    canonical,
    canonical_json,
    text_key,
    with_seed,
)
from spslidar.outwrite import atomic_write_bytes, atomic_write_text

__all__ = [
    "CACHE_FORMAT",
    "atomic_write_bytes",
    "atomic_write_text",
    "cached_point",
    "cached_point_state",
    "cached_state",
    "load_cached",
    "store_run",
    "write_csv",
]

#: Version of the cache record format (``runs/<key>.json``).
CACHE_FORMAT = 1


# --------------------------------------------------------------------------------------------
# Atomic files and the run cache
# --------------------------------------------------------------------------------------------


def load_cached(path: Path, params_json: str, code: str | None = None) -> dict[str, Any] | None:
    """Return the cached result at ``path`` if it exists and was computed for these params
    (and, with ``code``, by that code: :func:`spslidar.plugins.code_fingerprint`)."""
    return cached_state(path, params_json, code)[0]


def cached_state(path: Path, params_json: str,
                 code: str | None = None) -> tuple[dict[str, Any] | None, bool]:
    """:func:`load_cached`'s result, and whether the record holds these params' result made by
    other code than ``code`` (stale: run again, and said), from one read of the file (the
    sweep read each uncached point's file twice to tell the two apart)."""
    from ...outwrite import read_json_record

    record = read_json_record(path)  # (None for a FIFO, a huge or a too deeply nested file)
    if not isinstance(record, dict) or not isinstance(record.get("result"), dict):
        return None, False
    try:
        if canonical_json(record.get("params")) != params_json:
            return None, False
    except ConfigError:
        return None, False
    if "result_sha256" in record and record["result_sha256"] != result_sha256(record["result"]):
        # (a record's depth_rmse_m edited to 123.0 was read back into results.csv on resume:
        # an outside audit of 2026-12-02; it is run again, as a damaged record is)
        return None, False
    if code is not None and record.get("code") != code:
        return None, True
    return record["result"], False


def result_sha256(result: Any) -> str:
    """The checksum a cache record keeps of its result (its JSON with sorted keys)."""
    import hashlib

    text = json.dumps(result, sort_keys=True, allow_nan=True, default=str)
    return hashlib.sha256(text.encode()).hexdigest()


def cached_point(runs_dir: Path, point: Mapping[str, Any], seed: int,
                 ignore: Iterable[str], code: str | None) -> tuple[str, dict[str, Any] | None]:
    """A point's cache key and its cached result under ``code`` (None where it has none): the
    record :func:`~spslidar.experiments.sweep.engine.run_sweep` names and reads, for the
    estimates that price only the runs not cached (``sweep --max-time`` and each batch of
    ``reproduce``, which had each written the key's derivation out again)."""
    return cached_point_state(runs_dir, point, seed, ignore, code)[:2]


def cached_point_state(runs_dir: Path, point: Mapping[str, Any], seed: int,
                       ignore: Iterable[str], code: str | None
                       ) -> tuple[str, dict[str, Any] | None, bool]:
    """:func:`cached_point` and whether its record is stale (:func:`cached_state`)."""
    text = canonical_json(with_seed(point, seed, frozenset(ignore)))
    key = text_key(text)
    return (key, *cached_state(Path(runs_dir) / f"{key}.json", text, code))


def store_run(path: Path, key: str, params: Any, result: dict[str, Any], elapsed: float,
              code: str | None = None) -> None:
    """Cache one finished point at ``path`` (``runs/<key>.json``), atomically (``code``: the
    fingerprint of the code that ran it, when known)."""
    record = {
        "format": CACHE_FORMAT,
        "key": key,
        "params": params,
        "result": result,
        # (of the result as it will be read back: JSON's own keys and numbers)
        "result_sha256": result_sha256(json.loads(json.dumps(result, allow_nan=True))),
        "elapsed_s": round(elapsed, 6),
    }
    if code is not None:
        record["code"] = code
    # keys in insertion order (not sorted): a cached result then gives the same columns, in
    # the same order, as a fresh one
    atomic_write_text(path, json.dumps(record, indent=1, allow_nan=True) + "\n")


# --------------------------------------------------------------------------------------------
# Tidy CSV output
# --------------------------------------------------------------------------------------------


def _flatten(row: Mapping[str, Any], prefix: str = "") -> dict[str, Any]:
    out: dict[str, Any] = {}
    for key, value in row.items():
        name = f"{prefix}{key}"
        if isinstance(value, Mapping) and value:
            items = _flatten(value, f"{name}.")
        else:
            items = {name: value}
        for column, item in items.items():
            if column in out:
                raise ConfigError(f"column {column!r} appears twice after flattening nested dicts")
            out[column] = item
    return out


def _cell(value: Any) -> Any:
    value = canonical(value, "value")
    if value is None:
        return ""
    if isinstance(value, (list, dict)):
        return json.dumps(value, allow_nan=True)
    return value


def write_csv(rows: Iterable[Mapping[str, Any]], path: str | os.PathLike[str]) -> Path:
    """Write sweep rows as a tidy CSV (one row per run, one column per parameter or metric).

    Columns are the union of the rows' keys in first-seen order (``error`` last); nested
    dicts are flattened as ``a.b``, lists are written as JSON, missing values and None as empty
    cells. The file is written atomically.

    Parameters
    ----------
    rows : Iterable[Mapping[str, Any]]
        The rows, e.g. from :func:`run_sweep`.
    path : str or os.PathLike
        The CSV file; its folder must exist.

    Returns
    -------
    Path
        ``path``.

    Raises
    ------
    ConfigError
        If a row is not a dict, a value is not JSON-like, or two keys flatten to one column.
    """
    path = Path(path)
    flat = []
    for i, row in enumerate(rows):
        if not isinstance(row, Mapping):
            raise ConfigError(f"row {i} must be a dict, got {type(row).__name__}")
        flat.append(_flatten(row))
    columns: dict[str, None] = {}
    for row in flat:
        columns.update(dict.fromkeys(row))
    if ERROR_KEY in columns:
        del columns[ERROR_KEY]
        columns[ERROR_KEY] = None
    buffer = io.StringIO()
    writer = csv.DictWriter(buffer, fieldnames=list(columns), restval="", lineterminator="\n")
    writer.writeheader()
    for row in flat:
        writer.writerow({name: _cell(value) for name, value in row.items()})
    atomic_write_text(path, buffer.getvalue())
    return path


#: kinds of warning :func:`say_outcome` says, and the points it names for each
SAID_KINDS, SAID_POINTS = 5, 4


def say_outcome(rows: list[dict[str, Any]], names: list[str], csv_path: Path,
                counts: dict[str, int] | None = None) -> int:
    """Say on stderr how a sweep's runs went: how many were read from the cache and how many
    run (``counts``, from :func:`~spslidar.experiments.sweep.engine.run_sweep`; a resumed
    sweep said "48 runs" of 23 cached and 25 run, an audit), the count of failures and the
    first few, each warning its runs gave once (where first and how often) and how many runs
    warned. Returns the number of failed runs."""
    failed = [row for row in rows if ERROR_KEY in row]
    how = (f" ({counts['cached']} read from the cache, {counts['run']} run)"
           if counts and counts.get("cached") else "")
    print(
        f"sweep: {len(rows)} runs{how}, {len(rows) - len(failed)} ok, {len(failed)} failed; "
        f"results in {csv_path}",
        file=sys.stderr,
    )
    for row in failed[:3]:
        where = ", ".join(f"{name}={row.get(name)!r}" for name in names)
        print(f"sweep: failed ({where}): {row[ERROR_KEY]}", file=sys.stderr)
    if len(failed) > 3:
        print(f"sweep: ... and {len(failed) - 3} more failures (see results.csv)", file=sys.stderr)
    # what run would have said of a point (a gate past the unambiguous range, a map of noise)
    # was kept in the workers' results and never shown
    warned = [row for row in rows if row.get("n_warnings")]
    # each kind of warning once (its text with the numbers left out: a map of noise is said
    # with its own numbers in every run, so each run's was a kind of its own and the first
    # two named 2 of an audit's 12 warned runs), with how many runs gave it and where
    kinds: dict[str, list[tuple[dict[str, Any], str]]] = {}
    for row in warned:
        for text in str(row["warnings"]).split(" | "):
            hits = kinds.setdefault(re.sub(r"\d+(\.\d+)?([eE][-+]?\d+)?", "#", text), [])
            if not hits or hits[-1][0] is not row:  # (runs, not warnings: a review)
                hits.append((row, text))
    for hits in list(kinds.values())[:SAID_KINDS]:
        points = "; ".join(", ".join(f"{name}={row.get(name)!r}" for name in names)
                           for row, _ in hits[:SAID_POINTS])
        more = f"; and {len(hits) - SAID_POINTS} more" if len(hits) > SAID_POINTS else ""
        print(f"sweep: warning in {len(hits)} run{'s' if len(hits) > 1 else ''} ({points}{more})"
              f", the first: {hits[0][1]}", file=sys.stderr)
    if len(kinds) > SAID_KINDS:
        print(f"sweep: ... and {len(kinds) - SAID_KINDS} more kinds of warning", file=sys.stderr)
    if warned:
        print(f"sweep: {len(warned)} of {len(rows)} runs warned (the warnings column of "
              f"results.csv)", file=sys.stderr)
    return len(failed)
