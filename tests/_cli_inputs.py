"""Shared by the tests of what new users give the command line (not collected: no ``test_``
prefix): the small run's options, the one-line check of stderr, a small acquisition."""

from __future__ import annotations

from pathlib import Path

from spslidar.cli import main

FAST = ["--size", "8", "--code-length", "127", "--no-figure"]


def one_line(capsys) -> str:
    """The one line a command printed on stderr (fails on more or fewer)."""
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1, err
    return err[0]


def small_acquisition(d: Path) -> Path:
    """A small PTU acquisition written by ``run --save-ptu`` into ``d`` (8x8, 127-bit code):
    ``scan.ptu``, ``scan_patterns.npy``, ``scan_code.npy`` and the run in ``run/``."""
    assert main(["run", *FAST, "--signal", "1", "--noise", "0.02", "--compression", "0.5",
                 "--save-ptu", str(d / "scan.ptu"), "--out", str(d / "run")]) == 0
    return d
