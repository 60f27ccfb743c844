"""Warnings in tests: spslidar's own as errors, a library's notices of its future as they are."""

from __future__ import annotations

import warnings
from contextlib import contextmanager

from spslidar.errors import NOTICES


@contextmanager
def ours_as_errors():
    """Every warning raised inside is an error but a deprecation or ``FutureWarning`` (a
    library's notice of its next release, which a fresh machine's newest releases may add:
    those tests then failed on what the code does not do; an audit of 2026-11-29)."""
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        for category in NOTICES:
            warnings.simplefilter("default", category)
        yield
