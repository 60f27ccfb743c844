"""Names of the reproduction experiments (kept apart so the CLI parser imports no numerics)."""

#: The experiments in report order.
EXPERIMENT_NAMES: tuple[str, ...] = (
    "fig2", "fig3", "fig4", "fig5", "fig6", "fig7", "fig8", "table1", "snr", "ambiguity",
)
#: Runs every experiment.
ALL = "all"
#: Every accepted experiment name (the ten experiments, then ``'all'``).
EXPERIMENTS: tuple[str, ...] = (*EXPERIMENT_NAMES, ALL)
