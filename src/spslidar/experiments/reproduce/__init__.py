"""Reproduce the computer simulations of Shen et al (Section III: Figures 2-8, Table I).

``spslidar reproduce EXPERIMENT --out DIR`` calls :func:`reproduce_main`. Each experiment

* runs its parameter points through the sweep engine (:func:`~spslidar.experiments.sweep.
  run_sweep`), so ``--jobs`` and ``--scheduler`` apply and an interrupted run resumes;
* writes into ``DIR/<experiment>/`` its figure(s) (PNG, colour bars in metres, titles that say
  the parameters) and the data behind them as a tidy CSV (one row per run, every parameter a
  column);
* writes its report section (what was run, our numbers next to the paper's, and whether each
  claim holds here, computed from the numbers) and regenerates ``DIR/report.md`` and
  ``DIR/report.html`` from all section files (:mod:`spslidar.experiments.report`).

All experiments share one run cache, ``DIR/cache/runs/<key>.json``, and the depth maps of those
runs, ``DIR/cache/maps/<key>.npy`` (written by the run function itself, so a cached run can be
plotted again). A run is identified by its full parameters, which every experiment writes in
the same canonical form (:func:`base_params`): the same configuration in two experiments is
one run. Fig. 5 reuses Fig. 4's runs, Fig. 7 Fig. 6's, Table I Fig. 6's FISTA runs and Fig. 8's,
Fig. 2's 25 % point Fig. 4's QCR run at 16383 bits. Seeds come from the sweep seed (0) and the
parameters (:func:`~spslidar.experiments.sweep.derive_seed`); nothing is tuned to the paper.

``quick=True`` is a smoke test for CI: 32x32 pixels, fewer and shorter settings, one trial.

Layout
------
This module only holds the experiment registry (no numerics are imported with it, so the
command line reads its choices from here); the rest is imported on first use:

* :mod:`~spslidar.experiments.reproduce.context`: :class:`Context`, :func:`base_params`, the
  picklable point functions, running points into the cache and tidy CSVs, the paper's numbers;
* :mod:`~spslidar.experiments.reproduce.stats`, :mod:`~spslidar.experiments.reproduce.plotting`,
  :mod:`~spslidar.experiments.reproduce.prose`: statistics and verdicts, figure panels, the
  layout of a report section;
* one module per group of experiments: ``compression`` (Fig. 2, 3), ``code_length`` (Fig. 4),
  ``edges`` (Fig. 5, 7), ``motorcycle`` (Fig. 6), ``solvers`` (Fig. 8, Table I), ``eq10``
  (SNR), ``ambiguity``;
* :mod:`~spslidar.experiments.reproduce.runner`: :func:`reproduce_main`.

Adding an experiment
--------------------
Write one module with a function ``exp_NAME(ctx: Context) -> tuple[str, list[Claim]]`` that
runs its points (e.g. :func:`~spslidar.experiments.reproduce.context.run_and_write`), writes its
figures and data into ``ctx.folder(NAME)`` and returns its report section (Markdown, paths
relative to ``ctx.out``; :func:`~spslidar.experiments.reproduce.prose.section` lays it out) and
its headline :class:`~spslidar.experiments.report.Claim` s; then add one line below::

    _add("NAME", "spslidar.experiments.NAME:exp_NAME", "Display name", "one line of help")

``spslidar reproduce NAME`` then runs it and the report places its section in registry order.
Pass ``in_all=False`` to keep a slow or optional experiment out of ``reproduce all``.
"""

from __future__ import annotations

from spslidar.registry import Registry, lazy_exports

__all__ = [
    "ALL",
    "EXPERIMENTS",
    "EXPERIMENT_NAMES",
    "EXPERIMENT_REGISTRY",
    "PAPER",
    "Context",
    "base_params",
    "in_all_names",
    "reproduce_main",
    "reproduce_point",
    "snr_point",
]

#: The reproduction experiments, in report order. An entry's target is its
#: ``exp_NAME(ctx) -> (section, claims)`` function; ``defaults["in_all"]`` (default true) says
#: whether ``reproduce all`` runs it.
EXPERIMENT_REGISTRY = Registry("experiment", "experiment")
_add = EXPERIMENT_REGISTRY.add
_PKG = "spslidar.experiments.reproduce"
_add("fig2", f"{_PKG}.compression:exp_fig2", "Fig. 2", "depth maps against the compression M/Q")
_add("fig3", f"{_PKG}.compression:exp_fig3", "Fig. 3", "code kinds at m_n = 1")
_add("fig4", f"{_PKG}.code_length:exp_fig4", "Fig. 4",
     "RMSE against code length, with and without QCR, and the conventional lidar")
_add("fig5", f"{_PKG}.edges:exp_fig5", "Fig. 5", "edge maps of Fig. 4's depth maps")
_add("fig6", f"{_PKG}.motorcycle:exp_fig6", "Fig. 6", "the real-object stand-in at m_n = 5-10")
_add("fig7", f"{_PKG}.edges:exp_fig7", "Fig. 7", "edge maps of Fig. 6's depth maps")
_add("fig8", f"{_PKG}.solvers:exp_fig8", "Fig. 8", "the four reconstruction methods")
_add("table1", f"{_PKG}.solvers:exp_table1", "Table I",
     "RMSE, time and iterations of the four methods at m_n = 5 and 10")
_add("snr", f"{_PKG}.eq10:exp_snr", "Eq. (10)", "output SNR against its simulation")
_add("ambiguity", f"{_PKG}.ambiguity:exp_ambiguity", "Range ambiguity",
     "a target beyond the conventional lidar's unambiguous range")
_add("pileup", f"{_PKG}.pileup:exp_pileup", "Pile-up",
     "depth RMSE against flux: linear counter, GMAPD uncorrected and corrected")
_add("pattern_kinds", "spslidar.experiments.pattern_kinds:exp_pattern_kinds", "Pattern kinds",
     "Gaussian, Bernoulli and Hadamard orderings at 128x128 and 256x256: RMSE and time "
     "against compression (long: not in 'all')", in_all=False)

#: Runs every experiment registered with ``in_all`` (the default).
ALL = "all"
if ALL in EXPERIMENT_REGISTRY:  # pragma: no cover - a registration mistake
    raise ValueError(f"{ALL!r} is reserved for running every experiment")


def in_all_names() -> tuple[str, ...]:
    """The experiments ``reproduce all`` runs, in report order (read from the registry now)."""
    return tuple(e.name for e in EXPERIMENT_REGISTRY if e.defaults.get("in_all", True))


#: The experiments ``reproduce all`` runs, in report order (as registered in this module).
EXPERIMENT_NAMES: tuple[str, ...] = in_all_names()
#: Every accepted experiment name (the registered experiments, then ``'all'``).
EXPERIMENTS: tuple[str, ...] = (*EXPERIMENT_REGISTRY.names(), ALL)

# the numerical API, imported on first access (PEP 562)
__getattr__ = lazy_exports(__name__, {
    "BIN_DEPTH_M": "context",
    "BIN_WIDTH_S": "context",
    "CODE_NAMES": "context",
    "PAPER": "context",
    "SOLVER_NAMES": "context",
    "Context": "context",
    "base_params": "context",
    "reproduce_point": "context",
    "snr_point": "context",
    "Stat": "stats",
    "FIG4_SOLVED_ITERATIONS": "code_length",
    "exp_fig2": "compression",
    "exp_fig3": "compression",
    "exp_fig4": "code_length",
    "exp_fig5": "edges",
    "exp_fig6": "motorcycle",
    "exp_fig7": "edges",
    "exp_fig8": "solvers",
    "exp_table1": "solvers",
    "exp_snr": "eq10",
    "exp_ambiguity": "ambiguity",
    "exp_pileup": "pileup",
    "reproduce_main": "runner",
})


def __dir__() -> list[str]:
    # the lazy names too, so dir() and a REPL's completion list them (an audit of 2026-11-30)
    return sorted(set(globals()) | set(__all__))
