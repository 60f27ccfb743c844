"""Sweep points: canonical parameters, seeds, cache keys, grids and TOML sweep definitions.

Everything here is pure bookkeeping (no run is started): :func:`expand_grid` turns a grid into
points in a deterministic order, :func:`derive_seed` gives a point its seed from the sweep
seed and its parameters, :func:`point_key` names its cache file, and
:func:`load_sweep_config` reads and validates a TOML sweep (``seed``, ``trials``, ``[base]``,
``[grid]``). The canonical JSON written here is what both the seeds and the cache keys hash,
so it must not change (a change would silently re-seed every published sweep).
"""

from __future__ import annotations

import copy
import hashlib
import itertools
import json
import os
import sys
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from spslidar.errors import ConfigError

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover - exercised only on Python 3.10
    import tomli as tomllib

__all__ = [
    "ERROR_KEY",
    "KEY_LENGTH",
    "SEED_BOUND",
    "IRF_HASH_KEY",
    "SCENE_HASH_KEY",
    "SEED_KEY",
    "TRIAL_KEY",
    "SweepSpec",
    "canonical",
    "canonical_json",
    "derive_seed",
    "expand_grid",
    "same_value",
    "with_seed",
    "load_sweep_config",
    "point_key",
    "text_key",
]

#: Parameter added to every point by :func:`expand_grid` (the Monte-Carlo trial index).
TRIAL_KEY = "trial"
#: Parameter holding a point's random seed (set by :func:`run_sweep` unless the point has one).
SEED_KEY = "seed"
#: Parameter added to the points of a sweep of runs whose scene is a file: its SHA-256, so that
#: the cache key (and ``results.csv``) follow the file's content, not only its name.
SCENE_HASH_KEY = "scene_sha256"
#: the SHA-256 of a point's IRF file, as the scene's (an edited IRF file got cached results)
IRF_HASH_KEY = "irf_sha256"
#: Column holding the one-line error of a failed point.
ERROR_KEY = "error"
#: Seeds from :func:`derive_seed` lie in ``[0, SEED_BOUND)`` (valid for every numpy RNG API).
SEED_BOUND = 2**32
#: Length (hex digits) of the cache key of a point.
KEY_LENGTH = 16

_TOP_LEVEL_KEYS = ("seed", "trials", "base", "grid")


# --------------------------------------------------------------------------------------------
# Canonical JSON and seeds
# --------------------------------------------------------------------------------------------


def canonical(obj: Any, where: str = "params") -> Any:
    """Return a JSON-ready copy of ``obj`` (numpy scalars/arrays and tuples become plain values).

    Parameters
    ----------
    obj : Any
        A JSON-like value: dict with string keys, list/tuple, str, int, float, bool, None,
        numpy scalar or array, or an ``os.PathLike`` (stored as a string).
    where : str
        Dotted location of ``obj``, for error messages.

    Returns
    -------
    Any
        The same value built only from dict, list, str, int, float, bool and None.

    Raises
    ------
    ConfigError
        If ``obj`` holds a value of another type or a dict key that is not a string.
    """
    if obj is None or isinstance(obj, (bool, str)):
        return obj
    if isinstance(obj, int):
        return int(obj)
    if isinstance(obj, float):
        return float(obj)
    if isinstance(obj, np.generic):
        return canonical(obj.item(), where)
    if isinstance(obj, np.ndarray):
        return canonical(obj.tolist(), where)
    if isinstance(obj, Mapping):
        out = {}
        for key, value in obj.items():
            if not isinstance(key, str):
                raise ConfigError(f"{where}: key {key!r} is not a string")
            out[key] = canonical(value, f"{where}.{key}")
        return out
    if isinstance(obj, (list, tuple)):
        return [canonical(value, f"{where}[{i}]") for i, value in enumerate(obj)]
    if isinstance(obj, os.PathLike):
        return os.fspath(obj)
    raise ConfigError(
        f"{where} has unsupported type {type(obj).__name__} (use JSON-like values: "
        "numbers, strings, booleans, lists, dicts)"
    )


def canonical_json(obj: Any, where: str = "params") -> str:
    """Serialize ``obj`` as canonical JSON: sorted keys, no spaces, floats as shortest repr."""
    return json.dumps(
        canonical(obj, where),
        sort_keys=True,
        separators=(",", ":"),
        ensure_ascii=True,
        allow_nan=True,
    )


def sha256_hex(text: str) -> str:
    """Hex sha256 of an ASCII text (the canonical JSON of :func:`canonical_json`)."""
    return hashlib.sha256(text.encode("ascii")).hexdigest()


def check_int(value: Any, name: str) -> int:
    """``value`` as an int (numpy integers accepted, bools refused), or ConfigError."""
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
        raise ConfigError(f"{name} must be an integer, got {value!r}")
    return int(value)


def derive_seed(seed: int, params: Mapping[str, Any]) -> int:
    """Derive the random seed of one sweep point from the sweep seed and its parameters.

    The seed is a stable hash (sha256 of the canonical JSON of ``{"seed": seed, "params":
    params}``, keys sorted, floats written as their shortest round-trip ``repr``): it is the
    same on every machine, in every process and whatever the order of the dict keys, and it
    changes with any parameter (``trial`` included), so results do not depend on scheduling.
    ``1`` and ``1.0`` are different values here.

    Parameters
    ----------
    seed : int
        The sweep seed.
    params : Mapping[str, Any]
        The point's parameters (JSON-like values; numpy scalars/arrays are accepted).

    Returns
    -------
    int
        A seed in ``[0, 2**32)``, valid for ``numpy.random.default_rng`` and ``RandomState``.

    Raises
    ------
    ConfigError
        If ``seed`` is not an integer or ``params`` holds a non-JSON-like value.
    """
    seed = check_int(seed, "seed")
    if not isinstance(params, Mapping):
        raise ConfigError(f"params must be a dict, got {type(params).__name__}")
    digest = sha256_hex(canonical_json({"seed": seed, "params": canonical(params, "params")}))
    return int(digest[:16], 16) % SEED_BOUND


def with_seed(params: Mapping[str, Any], seed: int,
              ignore: Iterable[str] = ()) -> dict[str, Any]:
    """``params`` with its ``seed`` key: :func:`derive_seed` of the sweep seed and the params
    without ``ignore``, unless the point sets its own. What :func:`point_key` hashes, for
    :func:`~spslidar.experiments.sweep.run_sweep` and for whoever needs a point's cache file
    before running it."""
    out = dict(params)
    if SEED_KEY not in out:
        skip = frozenset(ignore)
        out[SEED_KEY] = derive_seed(seed, {k: v for k, v in params.items() if k not in skip})
    return out


def point_key(params: Mapping[str, Any]) -> str:
    """Return the cache key of a point: the first 16 hex digits of the sha256 of its params.

    Parameters
    ----------
    params : Mapping[str, Any]
        The point's full parameters (seed included).

    Returns
    -------
    str
        The key; the point is cached in ``out_dir/runs/<key>.json``.
    """
    return text_key(canonical_json(params))


def text_key(text: str) -> str:
    """The cache key of a point's canonical JSON text (:func:`point_key` of its params): for
    whoever holds the text already, to read the cache record against it."""
    return sha256_hex(text)[:KEY_LENGTH]


# --------------------------------------------------------------------------------------------
# Grids and TOML sweep configurations
# --------------------------------------------------------------------------------------------


#: the keys the sweep sets itself, with what to do instead
_RESERVED = {TRIAL_KEY: "set the number of trials instead",
             SCENE_HASH_KEY: "the sweep reads it from the scene file",
             IRF_HASH_KEY: "the sweep reads it from the IRF file"}


def _check_reserved(names, where: str) -> None:
    """One line for a key of ``names`` that the sweep sets itself (:data:`_RESERVED`)."""
    for name in names:
        if name in _RESERVED:
            raise ConfigError(f"{where}.{name} is reserved; {_RESERVED[name]}")


def _check_grid(grid: Mapping[str, Any], where: str = "grid") -> None:
    if not isinstance(grid, Mapping):
        raise ConfigError(f"{where} must be a table of lists, got {type(grid).__name__}")
    for name, values in grid.items():
        if not isinstance(name, str):
            raise ConfigError(f"{where}: key {name!r} is not a string")
        _check_reserved([name], where)
        if not isinstance(values, (list, tuple)) or len(values) == 0:
            raise ConfigError(f"{where}.{name} must be a non-empty list of values, got {values!r}")
        seen: dict[str, Any] = {}
        for value in values:  # (noise = [1, 1, 1.0] ran three points, two with one seed)
            same = file_spelling(name, value)  # (./a.npy and a.npy are one file)
            if name == "scene":  # (procedural:7 and procedural:007 are one scene)
                from spslidar.scenes import scene_spec

                same = scene_spec(same)
            key = canonical_json(same_value(same), f"{where}.{name}")
            if key in seen:
                raise ConfigError(f"{where}.{name} lists the same value twice ({seen[key]!r} and "
                                  f"{value!r}): each point would run twice and count twice")
            seen[key] = value


def file_spelling(name: str, value: Any) -> Any:
    """One spelling of a scene or IRF *file* named in a sweep (``./a.npy``, ``d/../a.npy``
    and ``a.npy`` are ``a.npy``); any other value as it is."""
    from spslidar.config import names_a_file

    return os.path.normpath(value) if names_a_file(name, value) else value


def resolve_point_files(point: Mapping[str, Any], folder: str | os.PathLike[str] | None
                        ) -> dict[str, Any]:
    """``point`` with its relative scene and IRF files read from ``folder`` (a sweep TOML's;
    ``None``: as they are)."""
    if folder is None:
        return dict(point)
    from spslidar.config import resolve_file_paths

    return resolve_file_paths(dict(point), Path(folder))


def with_scene_hashes(points: Sequence[Mapping[str, Any]]) -> list[dict[str, Any]]:
    """Each point whose scene (or IRF) is a file, with the file's SHA-256 as ``scene_sha256``
    (``irf_sha256``): the cache key (and ``results.csv``) then follow the file's content (an
    edited scene or IRF file was given the earlier file's cached results). Each file is read
    once."""
    from spslidar.outwrite import sha256_file
    from spslidar.scenes import SCENE_FILE_SUFFIXES

    sums: dict[str, str] = {}
    out = []
    for point in points:
        point = dict(point)
        for key, hashed, suffixes in (("scene", SCENE_HASH_KEY, SCENE_FILE_SUFFIXES),
                                      ("irf", IRF_HASH_KEY, (".npy",))):
            path = point.get(key)
            if (isinstance(path, str) and Path(path).suffix.lower() in suffixes
                    and os.path.isfile(path)):
                if path not in sums:
                    sums[path] = sha256_file(path)
                point[hashed] = sums[path]
        out.append(point)
    return out


def same_value(value: Any) -> Any:
    """``value`` with every float that is a whole number written as an int, so that ``1`` and
    ``1.0`` are one grid value and one seed (the pipeline's sweep seeds points so); lists and tables
    element by element; anything else as it is."""
    if isinstance(value, (float, np.floating)) and np.isfinite(value) and float(value).is_integer():
        return int(value)
    if isinstance(value, (list, tuple)):
        return [same_value(v) for v in value]
    if isinstance(value, Mapping):
        return {k: same_value(v) for k, v in value.items()}
    return value


def expand_grid(
    base: Mapping[str, Any], grid: Mapping[str, Sequence[Any]], trials: int = 1
) -> list[dict[str, Any]]:
    """Expand a parameter grid into sweep points (cartesian product x trials).

    Points come in a deterministic order: the grid keys in their insertion order, the first key
    varying slowest, and the trials of one combination adjacent (``trial`` varies fastest).

    Parameters
    ----------
    base : Mapping[str, Any]
        Parameters shared by every point (deep-copied into each one).
    grid : Mapping[str, Sequence[Any]]
        For each swept parameter, the non-empty list of its values; overrides ``base``.
    trials : int, default 1
        Monte-Carlo trials per grid combination; each point gets ``trial`` in
        ``0 .. trials - 1``.

    Returns
    -------
    list[dict[str, Any]]
        ``trials * prod(len(values))`` points; an empty grid gives ``trials`` copies of ``base``.

    Raises
    ------
    ConfigError
        If a grid value is not a non-empty list, ``trials < 1``, or ``trial`` is set in
        ``base`` or ``grid``.
    """
    if not isinstance(base, Mapping):
        raise ConfigError(f"base must be a table, got {type(base).__name__}")
    _check_reserved(base, "base")
    _check_grid(grid)
    trials = check_int(trials, "trials")
    if trials < 1:
        raise ConfigError(f"trials must be >= 1, got {trials}")
    names = list(grid)
    points = []
    for combo in itertools.product(*(grid[name] for name in names)):
        for trial in range(trials):
            point = copy.deepcopy(dict(base))
            point.update(copy.deepcopy(dict(zip(names, combo, strict=True))))
            point[TRIAL_KEY] = trial
            points.append(point)
    return points


@dataclass(frozen=True)
class SweepSpec:
    """A sweep read from a TOML file by :func:`load_sweep_config`.

    Attributes
    ----------
    seed : int
        The sweep seed (point seeds are derived from it, see :func:`derive_seed`).
    trials : int
        Monte-Carlo trials per grid combination.
    base : dict[str, Any]
        Parameters shared by every point.
    grid : dict[str, list[Any]]
        Swept parameters and their values.
    path : Path or None
        The file it was read from.
    """

    seed: int = 0
    trials: int = 1
    base: dict[str, Any] = field(default_factory=dict)
    grid: dict[str, list[Any]] = field(default_factory=dict)
    path: Path | None = None

    def resolve(self, point: Mapping[str, Any]) -> dict[str, Any]:
        """``point`` with its scene and IRF files named so that they open from the current
        folder (read from the TOML's folder, as ``run --config`` reads them)."""
        return resolve_point_files(point, None if self.path is None else self.path.parent)

    def points(self) -> list[dict[str, Any]]:
        """Return the sweep points, ``expand_grid(base, grid, trials)``.

        Returns
        -------
        list[dict[str, Any]]
            The points, in the deterministic order of :func:`expand_grid`.
        """
        return expand_grid(self.base, self.grid, self.trials)


def one_line(text: str) -> str:
    """``text`` with every run of whitespace (newlines included) made one space."""
    return " ".join(str(text).split())


#: most runs one sweep may have (grid points times trials): at a second or more per run,
#: 10^4 runs are hours of work, and a 10^6-point grid was killed by the kernel after 130 s
MAX_RUNS = 10_000


def _check_misplaced(path: Path, base: Mapping[str, Any], grid: Mapping[str, Any]) -> None:
    """Refuse, in one line of the kind a misplaced ``base = [1, 2]`` gets, a sweep key
    (``base``, ``grid``, ``trials``) written after the ``[base]`` or ``[grid]`` header, which
    TOML reads as a key of that table: ``grid = 3`` under ``[base]`` said "[grid] is empty and
    trials = 1, so there is nothing to sweep" (an outside audit of 2026-12-03).

    Parameters
    ----------
    path : Path
        The sweep TOML, for the message.
    base, grid : Mapping[str, Any]
        Its ``[base]`` and ``[grid]`` tables, as read.

    Raises
    ------
    ConfigError
        Where either table holds one of those keys.
    """
    for where, table in (("base", base), ("grid", grid)):
        for key in ("base", "grid", "trials"):
            if key not in table:
                continue
            value = table[key]
            read = (f"written after the [{where}] header, it is read as {where}.{key}: a "
                    f"TOML key belongs to the table above it")
            if key != "trials" and not isinstance(value, dict):
                raise ConfigError(f"{path}: {key} must be a table ([{key}]), got {value!r} "
                                  f"({read})")
            raise ConfigError(f"{path}: {where}.{key} is not a run key ({read}; write "
                              + ("trials before the first table)" if key == "trials" else
                                 f"[{key}] as a table of its own)"))


def load_sweep_config(path: str | os.PathLike[str]) -> SweepSpec:
    """Read a sweep configuration from a TOML file.

    The file has optional top-level ``seed`` (int, default 0) and ``trials`` (int >= 1,
    default 1), a ``[base]`` table of shared run-config keys, and a ``[grid]`` table whose every
    value is a non-empty list. ``seed`` inside ``[grid]`` sets explicit point seeds;
    ``seed`` inside ``[base]`` is refused when ``trials > 1`` (every trial would be identical).

    Parameters
    ----------
    path : str or os.PathLike
        The TOML file.

    Returns
    -------
    SweepSpec
        The validated sweep.

    Raises
    ------
    ConfigError
        If the file is missing or unreadable, is not valid TOML (the message names the file and
        line), has unknown top-level keys or tables, or holds invalid values.
    """
    from spslidar.config import check_toml_bytes, read_config_bytes, underscored_keys

    path = Path(path)
    raw = read_config_bytes(path, "sweep config")
    check_toml_bytes(raw, path, "sweep config")  # (a BOM read "Invalid statement" at 1:1)
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise ConfigError(f"cannot read sweep config {path}: {one_line(exc)}") from None
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(f"{path}: invalid TOML: {one_line(exc)}") from None
    except RecursionError:  # (a [grid] list nested 5000 deep: a traceback, an audit)
        raise ConfigError(f"{path}: invalid TOML: its arrays or tables are nested too "
                          f"deeply") from None

    unknown = [key for key in data if key not in _TOP_LEVEL_KEYS]
    if unknown:
        kinds = ["table" if isinstance(data[key], dict) else "key" for key in unknown]
        listed = ", ".join(f"{kind} '{key}'" for kind, key in zip(kinds, unknown, strict=True))
        raise ConfigError(
            f"{path}: unknown top-level {listed} (allowed: seed, trials, [base], [grid])"
        )
    seed = check_int(data.get("seed", 0), f"{path}: seed")
    if seed < 0:
        raise ConfigError(f"{path}: seed must be a non-negative integer, got {seed}")
    trials = check_int(data.get("trials", 1), f"{path}: trials")
    if trials < 1:
        raise ConfigError(f"{path}: trials must be >= 1, got {trials}")
    base = data.get("base", {})
    if not isinstance(base, dict):
        raise ConfigError(f"{path}: base must be a table ([base]), got {base!r}")
    grid = data.get("grid", {})
    if not isinstance(grid, dict):
        raise ConfigError(f"{path}: grid must be a table ([grid]), got {grid!r}")
    _check_misplaced(path, base, grid)
    # each key as a run reads it, two spellings of one refused: a grid over "lam-scale" drew
    # another seed for each weight (2361523904 and 2280320822 where lam_scale shares
    # 4221282710), and named its results.csv column as spelled (an outside audit)
    base = underscored_keys(base, f"{path}: base: key")[0]
    grid = underscored_keys(grid, f"{path}: grid: key")[0]
    try:
        _check_grid(grid)
    except ConfigError as exc:
        raise ConfigError(f"{path}: {exc}") from None
    n_runs = trials
    for values in grid.values():
        n_runs *= len(values)
    if n_runs > MAX_RUNS:
        raise ConfigError(f"{path}: the grid has {n_runs:.3g} runs (with its trials), more than "
                          f"the {MAX_RUNS} one sweep takes (a run takes a second or more: "
                          f"hours of work); split it into several sweeps")
    _check_reserved(base, f"{path}: base")
    from spslidar.config import CLI_ONLY_KEYS

    for where, table in (("base", base), ("grid", grid)):  # (was "unknown config key 'out'")
        said = sorted(k for k in table if str(k).replace("-", "_") in CLI_ONLY_KEYS)
        if said:
            # (grid.config was "a command-line option of a run's output", an audit)
            what = ("--config names a run's TOML file: a sweep's [base] and [grid] are that "
                    "file's keys" if said[0].replace("-", "_") == "config" else
                    "belongs to spslidar run's command line (its output), not to a sweep: "
                    "a sweep writes results.csv in the folder its own --out names")
            raise ConfigError(f"{path}: {where}.{said[0]} is not a sweep key: {what}")
    if SEED_KEY in base and trials > 1 and SEED_KEY not in grid:
        raise ConfigError(
            f"{path}: base.seed gives every trial the same noise; set the top-level seed instead"
        )
    if SEED_KEY in base and SEED_KEY not in grid and SEED_KEY in data:
        import warnings

        # (an outside audit of 2026-12-01: seed = 9 with [base] seed = 4 ran seed 4 unsaid)
        warnings.warn(f"{path}: the top-level seed = {seed} is not used: [base] seed = "
                      f"{base[SEED_KEY]!r} sets every point's seed", UserWarning, stacklevel=2)
    if SEED_KEY in grid and SEED_KEY in data:
        import warnings

        # (an outside audit of 2026-12-03: seed = 1 with [grid] seed = [0, 1] ran seeds 0
        # and 1 unsaid, where [base] seed was said)
        warnings.warn(f"{path}: the top-level seed = {seed} is not used: [grid] seed sets "
                      f"every point's seed", UserWarning, stacklevel=2)
    if SEED_KEY in grid and trials > 1:  # (the trials of each seed were the same to the bit)
        raise ConfigError(
            f"{path}: grid.seed with trials = {trials} gives every trial of a seed the same "
            f"noise; list the seeds as the grid's trials (trials = 1) or set the top-level "
            f"seed instead")
    both = sorted(set(base) & set(grid))
    if both:  # the grid wins: said, since a [base] value that never runs looks like an error
        import warnings

        warnings.warn(f"{path}: {', '.join(both)} {'is' if len(both) == 1 else 'are'} in both "
                      f"[base] and [grid]: the [grid] values are used and the [base] one "
                      f"ignored", UserWarning, stacklevel=2)
    if not grid and trials == 1:
        raise ConfigError(f"{path}: [grid] is empty and trials = 1, so there is nothing to "
                          f"sweep: give a list of values for at least one key, or trials > 1 "
                          f"(or use 'spslidar run --config')")
    # scene and IRF files stay named as the TOML names them (relative to its folder, one
    # spelling: ./a.npy is a.npy), so a point's seed, cache file and row are the same from
    # whatever folder the sweep runs (they were named relative to the current folder: three
    # folders gave three seeds, RMSE 0.081 / 0.048 / 0.056 m); SweepSpec.resolve reads them
    # from the TOML's folder, as `run --config` does
    base = {name: file_spelling(name, value) for name, value in base.items()}
    grid = {name: [file_spelling(name, v) for v in values] for name, values in grid.items()}
    return SweepSpec(
        seed=seed,
        trials=trials,
        base=base,
        grid=grid,
        path=path,
    )

