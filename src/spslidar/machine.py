"""What this machine offers a run: the memory it may still use (read before any large array
is made, by the run's budget and by the PTU reader)."""

from __future__ import annotations

import os

__all__ = ["available_memory"]


def _gb(b: float) -> str:
    return f"{b / 1e9:.1f} GB" if b >= 1e8 else f"{b / 1e6:.0f} MB"


def available_memory() -> float:
    """Bytes of memory this process may still use: ``MemAvailable`` of ``/proc/meminfo``
    (falling back to the physical memory), capped by ``RLIMIT_AS`` when one is set."""
    avail = None
    try:
        with open("/proc/meminfo") as fh:
            for line in fh:
                if line.startswith("MemAvailable:"):
                    avail = float(line.split()[1]) * 1024
                    break
    except OSError:
        pass
    if avail is None:
        try:
            avail = float(os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES"))
        except (ValueError, OSError, AttributeError):  # pragma: no cover - not POSIX
            avail = float("inf")
    try:
        import resource

        soft, _ = resource.getrlimit(resource.RLIMIT_AS)
        if soft not in (resource.RLIM_INFINITY, -1) and soft > 0:
            avail = min(avail, float(soft))
    except (ImportError, ValueError, OSError):  # pragma: no cover - not POSIX
        pass
    return avail
