"""The ``Examples`` sections of the public entry points' docstrings run as written.

Each module below is run through :mod:`doctest`; a module whose examples fail, or whose
examples vanish (none attempted), fails its test.
"""

from __future__ import annotations

import doctest
import importlib

import pytest

MODULES = [
    "spslidar.pipeline.chain",
    "spslidar.config",
    "spslidar.pipeline.results",
    "spslidar.codes.sequences",
    "spslidar.patterns.dense",
    "spslidar.patterns.hadamard",
    "spslidar.operators.base",
    "spslidar.forward",
    "spslidar.correlate",
    "spslidar.qcr",
    "spslidar.detectors.linear",
    "spslidar.detectors.gmapd",
    "spslidar.depth.argmax",
    "spslidar.depth.mrf",
    "spslidar.io.ptu_write",
    "spslidar.io.ptu",
    "spslidar.registry",
    "spslidar.snr.theory",
    "spslidar.solvers.weighted_tv",
]

FLAGS = doctest.ELLIPSIS | doctest.NORMALIZE_WHITESPACE


@pytest.mark.parametrize("name", MODULES)
def test_docstring_examples(name):
    module = importlib.import_module(name)
    finder = doctest.DocTestFinder(exclude_empty=True)
    runner = doctest.DocTestRunner(optionflags=FLAGS)
    for test in finder.find(module, name):  # each in a copy of its module's namespace
        runner.run(test)
    failed, attempted = runner.summarize(verbose=False)
    assert attempted > 0, f"{name}: no docstring examples found"
    assert failed == 0, f"{name}: {failed} of {attempted} docstring examples failed"
