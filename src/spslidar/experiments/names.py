"""Names of the reproduction experiments (kept apart so the CLI parser imports no numerics).

They are read from the experiment registry,
:data:`spslidar.experiments.reproduce.EXPERIMENT_REGISTRY`, whose module imports no numerics.
"""

from spslidar.experiments.reproduce import ALL, EXPERIMENT_NAMES, EXPERIMENTS

__all__ = ["ALL", "EXPERIMENTS", "EXPERIMENT_NAMES"]
