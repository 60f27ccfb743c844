"""
Your own scene from a NumPy array
==================================

A scene is a depth map in metres. Save one as ``.npy`` (depth only) or ``.npz`` (``depth`` plus
optional ``reflectivity`` in [0, 1] and a boolean ``valid`` mask of pixels with known truth)
and pass its path as the ``scene`` (``--scene`` on the command line);
:func:`spslidar.scenes.load_scene` reads it.
"""

import shutil
import tempfile
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np

import spslidar
from spslidar.scenes import load_scene

# %%
# A scene: a slanted wall at 10 m with a box 30 cm in front of it
# ---------------------------------------------------------------
n = 32
y, x = np.mgrid[0:n, 0:n] / (n - 1)
depth = 10.0 + 0.2 * x                      # wall, 10.0 to 10.2 m
box = (abs(x - 0.4) < 0.2) & (abs(y - 0.55) < 0.25)
depth[box] = 9.7                            # box face
reflectivity = np.where(box, 0.9, 0.5)
valid = np.ones((n, n), bool)
valid[:3, -6:] = False                      # say: no ground truth in one corner

tmp = Path(tempfile.mkdtemp())
np.save(tmp / "wall.npy", depth)
np.savez(tmp / "wall_box.npz", depth=depth, reflectivity=reflectivity, valid=valid)

scene = load_scene(tmp / "wall_box.npz", size=n)
print(scene.name, scene.depth.shape, f"{scene.valid.mean():.0%} valid")

# %%
# Run it
# ------
# A ``.npy`` file gives depth only (reflectivity 1, every pixel valid); the ``.npz`` adds the
# reflectivity and the mask, and the RMSE is taken over the valid pixels only. The
# ``.npz`` scene reflects half the light of the ``.npy`` one (0.5 on the wall instead of 1),
# so it returns fewer signal photons and its depth is noisier.
runs = {
    "wall.npy": spslidar.run(scene=str(tmp / "wall.npy"), size=n, code_length=1023),
    "wall_box.npz": spslidar.run(scene=str(tmp / "wall_box.npz"), size=n, code_length=1023),
}
for name, r in runs.items():
    print(f"{name:13s} RMSE {r.depth_rmse:.4f} m over {100 * r.metrics['coverage']:.0f}% "
          "of pixels")

fig, axes = plt.subplots(1, 4, figsize=(12, 3), layout="constrained")
lo, hi = depth.min(), depth.max()
axes[0].imshow(depth, vmin=lo, vmax=hi)
axes[0].set_title("your depth array")
axes[1].imshow(scene.reflectivity, cmap="gray", vmin=0, vmax=1)
axes[1].set_title("reflectivity (.npz)")
for ax, (name, r) in zip(axes[2:], runs.items(), strict=True):
    im = ax.imshow(r.depth, vmin=lo, vmax=hi)
    ax.set_title(f"{name}\nRMSE {r.depth_rmse:.3f} m")
for ax in axes:
    ax.set_axis_off()
fig.colorbar(im, ax=axes, label="depth [m]", shrink=0.8)
plt.show()

# %%
# ``depth_min`` / ``depth_max`` rescale a metric scene into another window, e.g. to move the
# same geometry to 30-31 m: ``spslidar.run(scene=path, depth_min=30, depth_max=31)``.

# %%
# The files of this example were written to a temporary folder; remove it.
shutil.rmtree(tmp, ignore_errors=True)
