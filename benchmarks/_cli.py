"""The benchmark scripts' shared argument checks: a bad value is one line and exit status 2.

Every script parses its options with :class:`ArgumentParser` (a bad option or value prints
``<script>: error: <message>`` on one line and exits with status 2, without the usage block;
``--help`` shows it) and runs its ``main`` through :func:`run`, which turns spslidar's
``SpslidarError`` (``ConfigError``, ``SceneError``: both ``ValueError``) and any other
``ValueError`` of a bad value into the same line. The ``type=`` checks below refuse a bad
number or an ``--out`` whose folder is missing while the options are read, before any work
(an audit of 2026-11-28: ``--size -64`` or ``--seed x`` gave tracebacks, and a missing
``--out`` folder was found only after all the work, 17 s of it in ``depth_quality.py``).

Light on purpose: no NumPy, no spslidar import (``scale.py``'s parent process imports
neither).
"""

from __future__ import annotations

import argparse
import math
import os
import sys
from collections.abc import Callable, Iterable
from pathlib import Path
from typing import Any


class ArgumentParser(argparse.ArgumentParser):
    """``argparse.ArgumentParser`` whose errors are one line: ``<prog>: error: <message>``,
    exit status 2."""

    def error(self, message: str):  # noqa: D102 - argparse's
        self.exit(2, f"{self.prog}: error: {message}\n")


def _number(kind: type, text: str, lo: float, lo_open: bool, hi: float | None = None,
            what: str = "") -> Any:
    try:
        v = kind(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected {what}, got {text!r}") from None
    if not math.isfinite(v) or v < lo or (lo_open and v == lo) or (hi is not None and v > hi):
        raise argparse.ArgumentTypeError(f"expected {what}, got {text}")
    return v


def positive_int(text: str) -> int:
    """``type=`` of an integer of 1 or more."""
    return _number(int, text, 1, False, what="an integer of 1 or more")


def nonneg_int(text: str) -> int:
    """``type=`` of an integer of 0 or more (a seed)."""
    return _number(int, text, 0, False, what="an integer of 0 or more")


def positive_float(text: str) -> float:
    """``type=`` of a finite number above 0."""
    return _number(float, text, 0.0, True, what="a number above 0")


def nonneg_float(text: str) -> float:
    """``type=`` of a finite number of 0 or more."""
    return _number(float, text, 0.0, False, what="a number of 0 or more")


def fraction(text: str) -> float:
    """``type=`` of a share in (0, 1] (a pattern ratio M / Q)."""
    return _number(float, text, 0.0, True, 1.0, what="a share in (0, 1]")


def int_list(text: str) -> list[int]:
    """``type=`` of seeds written as a list or ranges: ``0``, ``8-15``, ``0-19,40``."""
    out: list[int] = []
    for part in text.split(","):
        lo, _, hi = part.strip().partition("-")
        try:
            a, b = int(lo), int(hi or lo)
        except ValueError:
            raise argparse.ArgumentTypeError(
                f"expected seeds as 0, 8-15 or 0-19,40 (integers of 0 or more), got {text!r}"
            ) from None
        if b < a:
            raise argparse.ArgumentTypeError(f"empty range {part!r} in {text!r}")
        out.extend(range(a, b + 1))
    return out


def out_file(text: str) -> str:
    """``type=`` of an output file: its folder must exist and be writable (checked before the
    work, not after it)."""
    p = Path(text)
    if text == "" or p.is_dir():
        raise argparse.ArgumentTypeError(f"{text!r} is a folder, not a file")
    folder = p.parent
    if not folder.is_dir():
        raise argparse.ArgumentTypeError(f"the folder {str(folder)!r} of {text!r} does not exist")
    if not os.access(folder, os.W_OK | os.X_OK) or (p.exists() and not os.access(p, os.W_OK)):
        raise argparse.ArgumentTypeError(f"cannot write {text!r} (permission denied)")
    return text


def out_dir(text: str) -> str:
    """``type=`` of a folder the script writes into (made if missing): not a file, and the
    nearest existing folder on its path writable."""
    p = Path(text)
    if text == "":
        raise argparse.ArgumentTypeError("expected a folder, got ''")
    if p.exists() and not p.is_dir():
        raise argparse.ArgumentTypeError(f"{text!r} is a file, not a folder")
    q = p
    while not q.exists() and q != q.parent:
        q = q.parent
    if not q.is_dir():
        raise argparse.ArgumentTypeError(f"{str(q)!r} on the path {text!r} is a file")
    if not os.access(q, os.W_OK | os.X_OK):
        raise argparse.ArgumentTypeError(f"cannot write into {str(q)!r} (permission denied)")
    return text


def check_runs(scenes: Iterable[str], size: int, settings: Iterable[dict[str, Any]]) -> None:
    """Refuse, before the first run, a scene that cannot be loaded at ``size`` and a setting
    (``Config`` keys beside ``size``) that spslidar's ``Config`` refuses: raises ``ValueError``
    (spslidar's ``SceneError`` / ``ConfigError``; a bad scene or value was found only after
    the runs before it). spslidar is imported here, not when this module is."""
    from spslidar.config import Config
    from spslidar.scenes import load_scene

    for scene in dict.fromkeys(scenes):
        load_scene(scene, size)
    for setting in settings:
        Config(size=size, **setting)


def emit(lines: Iterable[str], out: str | None) -> int:
    """Print a benchmark's table (its lines) and, with ``--out``, write it there; exit 0."""
    text = "\n".join(lines)
    print(text)
    if out:
        Path(out).write_text(text + "\n", encoding="utf-8")
    return 0


def run(main: Callable[..., Any], argv: list[str] | None = None) -> int:
    """``main(argv)`` with a ``ValueError`` (spslidar's ``SpslidarError`` is one) or an
    ``OSError`` (a file or folder that cannot be written) printed as ``<script>: error:
    <message>`` on one line and exit status 2; ``main``'s own status otherwise (0 when it
    returns something that is not an int)."""
    prog = os.path.basename(sys.argv[0]) or "benchmark"
    try:
        rc = main(argv)
    except (ValueError, OSError) as exc:
        # (an OSError too: a --cache folder on a path the checks let through, /proc/x as
        # root, ended the run in a traceback after its work; an outside audit)
        msg = " ".join(str(exc).split()) or type(exc).__name__
        print(f"{prog}: error: {msg}", file=sys.stderr, flush=True)
        return 2
    return rc if isinstance(rc, int) else 0
