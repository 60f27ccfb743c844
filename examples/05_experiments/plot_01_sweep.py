"""
A small parameter sweep
=======================

:mod:`spslidar.experiments.sweep` runs a grid of parameters times Monte-Carlo trials, gives
every point a seed derived from its parameters (so results do not depend on the order or the
number of workers), caches each finished point and resumes an interrupted sweep. The same grid
in a TOML file runs from the command line as ``spslidar sweep``.

Here: depth RMSE against the noise level ``m_n`` for two code lengths, two trials each, at
16x16 pixels, with the ``camera`` scene squeezed into 20.0-20.3 m so that the range gate (and
the reconstruction) stays short.
"""

import shutil
import tempfile

import matplotlib.pyplot as plt
import numpy as np

from spslidar.experiments.sweep import expand_grid, run_point, run_sweep

base = {"scene": "camera", "size": 16, "depth_min": 20.0, "depth_max": 20.3, "signal": 5.0}
grid = {"code_length": [1023, 2047], "noise": [1.0, 10.0, 50.0]}
points = expand_grid(base, grid, trials=2)
print(len(points), "points, e.g.", points[0])

out = tempfile.mkdtemp()
rows = run_sweep(run_point, points, out, seed=1, jobs=1, progress=False)
print(sorted(rows[0]))

# %%
# Mean and spread over the trials
# -------------------------------
fig, ax = plt.subplots(figsize=(5.5, 3.5), layout="constrained")
for length in grid["code_length"]:
    rmse = np.array([[r["depth_rmse_m"] for r in rows
                      if r["code_length"] == length and r["noise"] == noise]
                     for noise in grid["noise"]])
    ax.errorbar(grid["noise"], rmse.mean(axis=1), yerr=rmse.std(axis=1), marker="o",
                capsize=3, label=f"{length} bits")
ax.set(xscale="log", xlabel="noise m_n [counts per bin per pixel]",
       ylabel="depth RMSE [m]", title="camera 16x16 at 20.0-20.3 m, m_s = 5")
ax.legend()
plt.show()

# %%
# Running the sweep again with the same ``out_dir`` loads every point from the cache
# (``out_dir/runs/<key>.json``) instead of recomputing it.
again = run_sweep(run_point, points, out, seed=1, jobs=1, progress=False)
print("identical:", [r["depth_rmse_m"] for r in again] == [r["depth_rmse_m"] for r in rows])

# %%
# The sweep was written to a temporary folder; remove it.
shutil.rmtree(out, ignore_errors=True)
