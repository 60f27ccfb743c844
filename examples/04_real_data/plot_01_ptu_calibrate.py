"""
Real data: a PTU file, its calibration and its reconstruction
=============================================================

A real acquisition is a PicoQuant T3 PTU file of photon time tags (sync at every code period
start, a marker at every DMD pattern change), the patterns that were shown and the code.
``spslidar reconstruct`` turns it into a depth map; ``spslidar calibrate`` first measures the
instrument's system delay and response (IRF) from a flat target at a known distance.

Here the instrument is simulated, so that every step can be checked against a known truth:
``spslidar run --system-delay --irf`` delays every return by 13.74 ns (2.06 m) and spreads it
by a Gaussian response with a tail, and ``--save-ptu`` writes the acquisition photon by photon
with the patterns and the code beside it. The commands are run through
:func:`spslidar.cli.main`, exactly as on the command line.
"""

import json
import shutil
import tempfile
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np

from spslidar.cli import main

work = Path(tempfile.mkdtemp(prefix="spslidar-ptu-"))
instrument = ["--size", "16", "--code-length", "1023", "--signal", "1", "--noise", "0.02",
              "--compression", "0.5", "--system-delay", "13.74e-9",
              "--irf", "gaussian:150e-12,tail:400e-12", "--range-gate", "24", "30",
              "--no-figure"]

# %%
# 1. Acquire a flat target at 25 m and calibrate
# ----------------------------------------------
np.save(work / "wall.npy", np.full((16, 16), 25.0))
main(["run", "--scene", str(work / "wall.npy"), *instrument,
      "--save-ptu", str(work / "wall.ptu"), "--out", str(work / "wall")])
main(["calibrate", "--ptu", str(work / "wall.ptu"),
      "--patterns", str(work / "wall_patterns.npy"), "--code", str(work / "wall_code.npy"),
      "--bit-rate", "10e9", "--distance", "25", "--out", str(work / "cal.json")])
cal = json.loads((work / "cal.json").read_text())
print(f"measured delay {cal['delay_s'] * 1e9:.3f} ns (simulated 13.740 ns)")

# %%
# 2. Acquire a scene: steps at 24.5-25.5 m
# ----------------------------------------
main(["run", "--scene", "steps", "--depth-min", "24.5", "--depth-max", "25.5", *instrument,
      "--save-ptu", str(work / "scan.ptu"), "--out", str(work / "scan")])
print(sorted(p.name for p in work.glob("scan*")))

# %%
# 3. Reconstruct it, without and with the calibration
# ---------------------------------------------------
# Without the calibration every depth is the system delay (2.06 m) too far, so the range gate
# must be moved to find the returns at all; with it, the gate is in true metres.
common = ["--ptu", str(work / "scan.ptu"), "--patterns", str(work / "scan_patterns.npy"),
          "--code", str(work / "scan_code.npy"), "--bit-rate", "10e9",
          "--truth", str(work / "scan" / "truth.npy"), "--no-figure"]
main(["reconstruct", *common, "--range-gate", "26", "28", "--out", str(work / "raw")])
main(["reconstruct", *common, "--range-gate", "24", "26",
      "--calibration", str(work / "cal.json"), "--out", str(work / "calibrated")])

# %%
# The depth maps
# --------------
truth = np.load(work / "scan" / "truth.npy")
raw = np.load(work / "raw" / "depth.npy")
calibrated = np.load(work / "calibrated" / "depth.npy")
fig, axes = plt.subplots(1, 3, figsize=(11, 3.4), layout="constrained")
panels = (("truth", truth), ("no calibration", raw), ("calibrated", calibrated))
for ax, (title, img) in zip(axes, panels, strict=True):
    im = ax.imshow(img, vmin=24.4, vmax=27.6)
    ax.set_title(f"{title}\nmedian {np.nanmedian(img):.2f} m")
    ax.set_axis_off()
_ = fig.colorbar(im, ax=axes, label="depth [m]", shrink=0.8)
plt.show()

metrics = json.loads((work / "calibrated" / "metrics.json").read_text())
print(f"calibrated: bias {100 * metrics['depth_bias_m']:.1f} cm, "
      f"median |error| {1000 * np.nanmedian(np.abs(calibrated - truth)):.1f} mm, "
      f"{int(sum(metrics['ptu']['counts_per_pattern']))} photons")

# %%
# The files of this example were written to a temporary folder; remove it.
shutil.rmtree(work, ignore_errors=True)
