"""The prose of the report: the settings every experiment shares and the layout of a section
(what was run, figures, table, findings against the paper, data files).
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

from spslidar.experiments.reproduce.context import Context
from spslidar.experiments.sweep import ERROR_KEY

__all__ = ["common_text", "failed_note", "section"]


def common_text(ctx: Context, scene: str = "camera") -> str:
    """The settings shared by the experiments on ``scene``, for their "What was run"."""
    stand_in = {
        "camera": "`camera` (stand-in for the paper's 'airplane', grey levels mapped to "
        "20.0-20.8 m)",
        "motorcycle": "`motorcycle` (Middlebury ground-truth depth, stand-in for the paper's "
        "'doll')",
    }[scene]
    return (
        f"scene {stand_in}, {ctx.size}x{ctx.size} pixels, Gaussian DMD patterns "
        f"clip(0.5 + 0.25 N(0,1), 0, 1), 10 GHz bit rate (1.5 cm bins), m_s = 5"
    )


def section(
    ctx: Context,
    title: str,
    what: str,
    body: str,
    findings: Sequence[str],
    *,
    rows: Sequence[dict[str, Any]] = (),
    figures: Sequence[tuple[str, Path]] = (),
    data: Sequence[Path] = (),
    mode: str | None = None,
) -> str:
    """One experiment's report section (Markdown).

    Parameters
    ----------
    ctx : Context
        Gives the mode line and the report folder the paths are written relative to.
    title : str
        The heading (``## title``).
    what : str
        What was run (settings, trials).
    body : str
        The results (usually a table); a note on failed runs of ``rows`` goes first.
    findings : sequence of str
        One bullet per claim of the paper, with its verdict.
    rows : sequence of dict, optional
        The experiment's runs, for the failed-runs note.
    figures : sequence of (str, Path), optional
        Alt text and file of each figure (inside ``ctx.out``).
    data : sequence of Path
        The data files (CSV, Markdown tables) inside ``ctx.out``.
    mode : str, optional
        The line saying which mode ran, where it is not ``ctx.mode`` (e.g. another size).

    Returns
    -------
    str
        The section, image and data paths relative to the report folder.
    """
    parts = [f"## {title}\n", (mode or ctx.mode) + "\n", f"**What was run.** {what}\n"]
    for alt, path in figures:
        parts.append(f"![{alt}]({_rel(ctx, path)})\n")
    parts.append(failed_note(rows) + body)
    parts.append("**Against the paper.**\n")
    parts.extend(f"- {f}" for f in findings)
    parts.append("")
    parts.append("Data: " + ", ".join(f"`{_rel(ctx, c)}`" for c in data) + ".\n")
    return "\n".join(parts)


def _rel(ctx: Context, path: Path) -> str:
    """``path`` relative to the report folder, with forward slashes."""
    return Path(path).relative_to(ctx.out).as_posix()


def failed_note(rows: Sequence[dict[str, Any]]) -> str:
    """A line on the failed runs (count and first error), empty when none failed."""
    bad = [r for r in rows if ERROR_KEY in r]
    if not bad:
        return ""
    return f"**{len(bad)} run(s) failed**; first error: `{bad[0][ERROR_KEY]}`.\n"
