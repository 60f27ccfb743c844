"""The ``spslidar reproduce`` entry point: run registered experiments and rebuild the report."""

from __future__ import annotations

import sys
import time
import traceback
from pathlib import Path
from typing import Any

import numpy as np

from spslidar.errors import ConfigError, SpslidarError
from spslidar.experiments.report import SECTION_FILE, build_report, write_section
from spslidar.experiments.reproduce import ALL, EXPERIMENT_REGISTRY, in_all_names
from spslidar.experiments.reproduce.context import Context, n_cached
from spslidar.experiments.sweep.engine import WorkerLost

__all__ = ["reproduce_main"]


#: most Monte-Carlo trials per setting
MAX_TRIALS = 1000


def reproduce_main(
    experiment: str,
    out: str | Path,
    quick: bool = False,
    trials: int | None = None,
    jobs: int = 1,
    scheduler: Any = None,
    progress: bool = True,
    max_time: float | None = None,
) -> int:
    """Run one experiment of the paper (or ``'all'``) and update the report.

    Parameters
    ----------
    experiment : str
        A registered experiment (:data:`~spslidar.experiments.reproduce.EXPERIMENT_REGISTRY`:
        ``fig2`` ... ``fig8``, ``table1``, ``snr``, ``ambiguity``...) or ``all`` (every
        experiment registered with ``in_all`` true, the default).
    out : str or Path
        Report folder ``DIR``: ``DIR/<experiment>/`` (figures, CSV, section), ``DIR/cache/``
        (runs shared by all experiments, and their depth maps), ``DIR/report.md`` and
        ``DIR/report.html``.
    quick : bool, default False
        Smoke-test settings: 32x32, fewer and shorter settings, one trial.
    trials : int, optional
        Monte-Carlo trials per setting (default: 3 for Fig. 4 in full mode, 1 otherwise).
        Fig. 5, 7 and 8 always show trial 0; ``snr`` has its own number of code periods.
    jobs : int, default 1
        Local worker processes (``-1``: all cores).
    scheduler : str or distributed.Client, optional
        Dask scheduler instead of local processes.
    progress : bool, default True
        Progress bars on stderr.
    max_time : float, optional
        Refuse a batch of runs whose estimated time exceeds this many seconds (checked before
        each experiment's runs start).

    Returns
    -------
    int
        0 when every run succeeded, 1 when a run or an experiment failed. The time of each
        experiment is printed on stdout.

    Raises
    ------
    ConfigError
        Unknown experiment, invalid ``trials`` or ``jobs``, an output path that is a file.
    """
    choices = (*EXPERIMENT_REGISTRY.names(), ALL)
    if not isinstance(experiment, str) or experiment not in choices:
        raise ConfigError(
            f"unknown experiment {experiment!r}; choose one of {', '.join(choices)}"
        )
    if trials is not None and (
        isinstance(trials, bool) or not isinstance(trials, (int, np.integer)) or trials < 1
    ):
        raise ConfigError(f"--trials must be a positive integer, got {trials!r}")
    if trials is not None and trials > MAX_TRIALS:
        raise ConfigError(f"--trials {trials} is more than {MAX_TRIALS}: the standard error of a "
                          f"mean RMSE falls as 1/sqrt(trials), 3 % at {MAX_TRIALS} "
                          f"(10^9 trials were killed by the kernel building their points)")
    from spslidar.experiments.sweep.engine import _check_jobs

    jobs = _check_jobs(jobs)
    from spslidar.outdir import claim_folder

    if isinstance(scheduler, str):
        from spslidar.experiments.sweep.engine import _probe_scheduler

        _probe_scheduler(scheduler)  # before the folder is made
    existed = Path(out).exists()
    out = claim_folder(out, "reproduce")  # new, empty or an earlier report: never a user's
    ctx = Context(
        out,
        bool(quick),
        None if trials is None else int(trials),
        int(jobs),
        scheduler,
        bool(progress),
    )
    ctx.max_time = max_time
    names = in_all_names() if experiment == ALL else (experiment,)
    done: list[str] = []
    try:
        status = _run_all(ctx, out, existed, experiment, names, trials, done)
    except KeyboardInterrupt:  # (Terminated too) say what is there, then let the CLI say it
        _interrupted(out, existed, experiment, names, done)
        raise
    return status


def _interrupted(out: Path, existed: bool, experiment: str, names, done: list[str]) -> None:
    """After an interrupt: take the folder back when nothing but its marker is in it (the
    CLI's line said "nothing was written" beside a new folder and its marker); after an
    interrupted ``reproduce all``, say which of its experiments did not run, in the report
    (rebuilt, when one exists) and on stderr (a report of fig2 and fig3 only did not say the
    rest was missing)."""
    from spslidar.outdir import journal, release_folder

    if release_folder(out, existed):
        return
    if experiment != ALL:
        return
    not_run = [n for n in names if n not in done]
    if not not_run:
        return
    earlier = [n for n in not_run if (out / n / SECTION_FILE).is_file()]
    note = (f"**Incomplete:** `spslidar reproduce all` was interrupted during {not_run[0]}; "
            f"{', '.join(not_run)} did not run"
            + (f" (the sections of {', '.join(earlier)} below are from an earlier run)"
               if earlier else "")
            + ". Run the same command again to finish it: the runs that finished are "
              "cached.")
    print(f"spslidar reproduce: all: not run: {', '.join(not_run)}", file=sys.stderr,
          flush=True)
    if (out / "report.md").is_file():
        with journal(out, _REPORT):
            build_report(out, EXPERIMENT_REGISTRY.names(), note=report_note(note))
        from spslidar.outdir import record_outputs

        record_outputs(out, list(_REPORT))


def _run_all(ctx: Context, out: Path, existed: bool, experiment: str, names,
             trials: int | None, done: list[str]) -> int:
    """Run the experiments ``names`` in turn, appending each finished one to ``done``;
    return the exit status."""
    from spslidar.outdir import journal, release_folder

    status = 0
    t_all = time.perf_counter()
    failures: list[str] = []  # "NAME failed: reason", for the report's banner
    for name in names:
        t0 = time.perf_counter()
        before, failed_before = n_cached(ctx), ctx.failed
        ctx.trials_read, ctx.last_trials = False, 1
        _refuse_foreign(out, name)  # before the work: a user's fig3/fig3.png was replaced
        # every standard file is noted in the marker before it is moved into place, so an
        # interrupt at any moment leaves none that the next run would take for a user's
        with journal(out, _outputs(name)):
            try:
                text, claims = EXPERIMENT_REGISTRY.load(name)(ctx)
            except SpslidarError:  # bad input (a time budget too small...): one line, exit 2
                release_folder(out, existed)  # nothing written yet: leave no folder behind
                raise
            except Exception as exc:  # an experiment's bug must not lose the others' results
                # (a killed worker's line says it all, and so does a full disk's or a
                # folder's permissions: they were 40 lines of traceback, an audit of
                # 2026-11-30)
                if not isinstance(exc, (WorkerLost, OSError)):
                    traceback.print_exc(file=sys.stderr)
                reason = (f"{exc.strerror}: {exc.filename}" if isinstance(exc, OSError)
                          and exc.strerror and exc.filename else f"{type(exc).__name__}: {exc}")
                print(f"reproduce {name}: failed: {reason}", file=sys.stderr)
                status = 1
                failures.append(f"{name} failed: {_one_line(reason)}")
                # say so in the report (it said nothing: the section and its summary rows
                # were simply absent, where an interrupted run got a banner)
                build_report(out, EXPERIMENT_REGISTRY.names(),
                             note=report_note(_failed_note(failures, out)))
                continue
            if trials is not None and not ctx.trials_read:
                print(f"spslidar: warning: --trials {trials} is ignored by {name}: it runs no "
                      f"repeated trials", file=sys.stderr)
            write_section(out, name, text, claims)
            build_report(out, EXPERIMENT_REGISTRY.names(),
                         note=report_note(_failed_note(failures, out)))
        _record_written(out, name)
        done.append(name)
        failed = ctx.failed - failed_before
        if failed:
            status = 1
        dt = time.perf_counter() - t0
        print(
            f"reproduce {name}: {dt:.1f} s ({n_cached(ctx) - before} new runs"
            f"{f', {failed} failed' if failed else ''}) -> {out / name}",
            flush=True,
        )
    print(
        f"reproduce {experiment}: {time.perf_counter() - t_all:.1f} s in all"
        f"{f', {len(failures)} failed ({_names(failures)})' if failures else ''}; report: "
        f"{out / 'report.md'}, {out / 'report.html'}",
        flush=True,
    )
    return status


def report_note(note: str = "") -> str:
    """The paragraph(s) after the report's header: a banner (``note``) on what did not run
    or failed, then the rule every verdict follows (said once, in the preamble)."""
    from spslidar.experiments.reproduce.stats import VERDICT_RULE

    return (note.rstrip() + "\n\n" if note else "") + VERDICT_RULE


def _one_line(text: str, limit: int = 200) -> str:
    """``text`` on one line, at most ``limit`` characters."""
    flat = " ".join(str(text).split())
    return flat if len(flat) <= limit else flat[: limit - 3] + "..."


def _names(failures: list[str]) -> str:
    """The experiment names of ``failures`` ("NAME failed: ...")."""
    return ", ".join(f.split(" ", 1)[0] for f in failures)


def _failed_note(failures: list[str], out: Path) -> str:
    """The report's banner for experiments that raised: ``**Incomplete:** fig4 failed:
    <reason>`` (and whether an earlier run's section is shown in its place)."""
    if not failures:
        return ""
    lines = []
    for f in failures:
        name = f.split(" ", 1)[0]
        earlier = (out / name / SECTION_FILE).is_file()
        lines.append(f"**Incomplete:** {f}"
                     + (" (its section below is from an earlier run)." if earlier else
                        " (its section and summary rows are missing)."))
    return "\n\n".join(lines)


#: what an experiment ``NAME`` writes into ``DIR/NAME/`` (and every experiment into ``DIR``)
_STANDARD = ("{name}.png", "{name}.csv", "{name}.md", "{name}_summary.csv", "section.md",
             "claims.json")
_REPORT = ("report.md", "report.html")


def _outputs(name: str) -> list[str]:
    """The files experiment ``name`` writes under its standard names, and the report's."""
    return [f"{name}/{f.format(name=name)}" for f in _STANDARD] + list(_REPORT)


def _refuse_foreign(out: Path, name: str) -> None:
    """Refuse (one line) to run ``name`` where a file it writes exists as ``reproduce`` did
    not write it (not listed, or changed since): a user's ``fig2/fig2.png`` or an edited
    ``report.md`` in a report folder was replaced without a word. Other files of the user's
    (``fig2/notes.txt``) are left as they are. A file an interrupted run wrote counts as
    reproduce's: its SHA-256 was noted in the marker before it was moved into place."""
    from spslidar.outdir import foreign_outputs

    foreign = foreign_outputs(out, _outputs(name))
    if foreign:
        one = len(foreign) == 1
        raise SpslidarError(f"--out {out}: {', '.join(foreign)} {'was' if one else 'were'} not "
                            f"written by spslidar reproduce (or changed since); refusing to "
                            f"replace {'it' if one else 'them'} (move {'it' if one else 'them'} "
                            f"away, or choose another folder)")


def _record_written(out: Path, name: str) -> None:
    """Add what ``name`` wrote (its standard files and the report) to the marker's list (in a
    folder of an earlier version, its marker reproduce's, every experiment's outputs are
    taken as ours)."""
    from spslidar.outdir import record_outputs

    legacy = [n for exp in EXPERIMENT_REGISTRY.names() for n in _outputs(exp)]
    record_outputs(out, _outputs(name), legacy=legacy)
