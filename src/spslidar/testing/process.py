"""The same stage output in a fresh process: what a sweep's or a reproduction's workers rely on.

A code family or a scene kind that draws from Python's ``hash`` of a string (randomised per
process by ``PYTHONHASHSEED``), the time or a global random state gives another code or scene
in each worker, so a sweep's points stop being reproducible and its paired comparisons stop
being paired, while every check made within one process passes (a known limit of stop 51: a
code seeded from ``hash(kind)`` passed the kit). :func:`fresh_digest` computes the stage's
probe output again in two new interpreters under two ``PYTHONHASHSEED`` values (with the
loaded plugins imported there, as ``--plugin`` makes workers do), and the code and scene
checks compare them with this process's.

A stage registered by code the new interpreter cannot import (a test function's own
registration, ``__main__``) is not checked this way: :func:`fresh_digest` returns ``None``,
and the check says the contract skipped. A stage registered while a plugin was imported (in
a plugin package's submodule too) is built there by importing the plugins.
"""

from __future__ import annotations

import hashlib
import os
import subprocess
import sys

import numpy as np

__all__ = ["digest", "fresh_digest", "output_digest"]

#: seconds a fresh interpreter may take to import spslidar, the plugins and make the output
TIMEOUT_S = 120
#: the hash seeds of the two fresh interpreters
HASH_SEEDS = ("1", "2")


def digest(arrays) -> str:
    """SHA-256 of a stage's probe output, its arrays' bytes in order."""
    h = hashlib.sha256()
    for a in arrays:
        h.update(np.ascontiguousarray(a).tobytes())
    return h.hexdigest()


def _importable(entry) -> list[str] | None:
    """The plugin specs a new interpreter needs to know ``entry`` (``None``: it cannot)."""
    from .. import plugins
    from . import is_plugin

    if not is_plugin(entry):
        return []
    loaded = {getattr(m, "__name__", None) for m in plugins._LOADED.values()}
    # registered while a loaded plugin was imported (by a submodule of a plugin package too:
    # that check was skipped without a word, an audit of plugins), or by a plugin's module
    if (getattr(entry, "plugin", "") not in plugins._LOADED
            and getattr(entry, "origin", "") not in loaded):
        return None
    return list(plugins._LOADED)  # all of them, in order: one may import another's stages


def output_digest(kind: str, name: str) -> str:
    """:func:`digest` of the probe output of stage ``name``
    (``kind`` ``code`` or ``scene``), as the conformance checks build it: what
    :func:`fresh_digest` has new interpreters print."""
    from .probes import probe_code, scene_size, scene_spec

    if kind == "code":
        make, index, _ = probe_code(name)
        return digest((make(index),))
    if kind == "scene":
        from ..scenes import load_scene

        scene = load_scene(scene_spec(name), scene_size(name))
        return digest((scene.depth, scene.reflectivity, scene.valid))
    raise ValueError(f"no fresh-process digest for stage kind {kind!r}")


def fresh_digest(kind: str, name: str) -> list[str] | None:
    """:func:`output_digest` computed in two new interpreters, under
    ``PYTHONHASHSEED`` 1 and 2 (two, so that a hash-seeded stage fails whatever this
    process's seed happens to be), or ``None`` where the stage cannot be built there (see
    the module docstring).

    Raises
    ------
    AssertionError
        A new interpreter failed (its last line of error said).
    """
    from . import registry_of

    specs = _importable(registry_of(kind).get(name))
    if specs is None:
        return None
    code = ("import sys\nfrom spslidar.plugins import load_plugins\nload_plugins()\n"
            "from spslidar.testing.process import output_digest\n"
            "print(output_digest(sys.argv[1], sys.argv[2]))\n")
    from pathlib import Path

    # this spslidar, also where it is imported from a source tree rather than installed
    here = str(Path(__file__).resolve().parents[2])
    path = os.pathsep.join(p for p in (here, os.environ.get("PYTHONPATH", "")) if p)
    out = []
    for seed in HASH_SEEDS:
        env = {**os.environ, "PYTHONHASHSEED": seed, "SPSLIDAR_PLUGINS": ",".join(specs),
               "PYTHONPATH": path}
        proc = subprocess.run([sys.executable, "-c", code, kind, name], env=env,
                              capture_output=True, text=True, timeout=TIMEOUT_S,
                              cwd=os.getcwd())
        if proc.returncode != 0:
            last = (proc.stderr.strip().splitlines() or ["no message"])[-1]
            raise AssertionError(f"{kind} {name!r}: a fresh process could not build it: {last}")
        out.append(proc.stdout.strip().splitlines()[-1])
    return out
