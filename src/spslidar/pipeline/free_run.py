"""A free-running DMD (``--first-pattern I``): a DMD that loops its pattern sequence on its
own while the time tagger records from some moment on. The file's first marker block then
shows pattern ``I``, not 0, and the recording stops wherever it stops, so its number of
blocks ``B`` is no multiple of the ``M`` patterns: block ``b`` shows pattern ``(I + b) mod M``,
and each pattern's blocks are summed (histograms and dwells, as ``--repeats`` sums them:
:func:`~spslidar.pipeline.blocks.fold_repeats`), whatever their number.

The flag says the sequence loops, so it goes with neither ``--repeats`` (the passes are
whatever the file holds) nor ``--frame`` (no pass is whole but by chance), nor several
``--ptu`` files (each would start at its own pattern); each is refused in one line.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from ..errors import ConfigError

__all__ = ["block_numbers", "check_first_pattern", "free_block_patterns"]


def check_first_pattern(first: Any, m: int, *, repeats: int = 1, n_files: int = 1,
                        frame: Any = None) -> int | None:
    """``--first-pattern`` (the ``--patterns`` row, from 0, that the file's first marker
    block shows) as an int in ``[0, m)``, or None where not given; one line
    (:class:`ConfigError`) for anything else, and for ``--repeats`` of 2 or more, several
    files or ``--frame`` with it."""
    if first is None:
        return None
    from ..arrays import real_number

    value = real_number(first)
    if value is None or not (math.isfinite(value) and value == int(value)):
        raise ConfigError(f"--first-pattern must be a whole number, the --patterns row (from 0) "
                          f"the file's first marker block shows, got {first!r}")
    if not 0 <= value < m:
        raise ConfigError(f"--first-pattern must be a row of --patterns, 0 to {m - 1} ({m} "
                          f"patterns), got {int(value)}")
    if repeats != 1:
        raise ConfigError("--first-pattern reads a free-running sequence, looped any number "
                          "of times, each pattern's blocks summed: leave --repeats out")
    if n_files > 1:
        raise ConfigError(f"--first-pattern reads one PTU file (each file of a free-running "
                          f"sequence starts at its own pattern), got {n_files}: reconstruct "
                          f"them one at a time")
    if frame is not None:
        raise ConfigError("--frame picks one repeat of a sequence shown --repeats times; a "
                          "free-running sequence (--first-pattern) is summed over every pass")
    return int(value)


def block_numbers(first: int | None, n_blocks: int, m: int) -> np.ndarray:
    """The pattern each of ``n_blocks`` marker blocks shows: ``(first + b) mod m``
    (``first`` None: 0, block ``b`` showing pattern ``b mod m`` as under ``--repeats``)."""
    return (int(first or 0) + np.arange(n_blocks)) % m


def free_block_patterns(shown: np.ndarray, numbers: np.ndarray) -> np.ndarray:
    """What the screening reads of each block's pattern (its light alone, a column, as
    :func:`~spslidar.pipeline.blocks.block_patterns` gives under ``--repeats``): no
    ``(B, Q)`` copy of the patterns for a long free-running file."""
    return shown.sum(axis=1, dtype=np.float64)[numbers][:, None]
