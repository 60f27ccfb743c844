"""
The GPU backend
===============

``backend="torch", device="cuda"`` (or ``backend="cupy"``) runs the numeric core on a GPU:
patterns and Poisson counts drawn on the device, the matched filter, centred QCR, FISTA with
TV and the argmax depth there (:mod:`spslidar.backends`). NumPy stays the default.

This example compares the two where PyTorch and a CUDA device are present. Where they are not
(as on the machine that may have built this page), it runs the NumPy half only and says so:
the example never fails for want of a GPU.
"""

import importlib.util

import matplotlib.pyplot as plt
import numpy as np

import spslidar


def cuda_available() -> bool:
    if importlib.util.find_spec("torch") is None:
        return False
    import torch

    return bool(torch.cuda.is_available())


params = dict(scene="camera", size=128, patterns="hadamard", compression=0.1,
              code_length=1023, depth="argmax", seed=0)
runs = {"numpy (CPU)": spslidar.run(**params)}
if cuda_available():
    spslidar.run(**params, backend="torch", device="cuda")  # warm-up: CUDA context, graphs
    runs["torch (CUDA)"] = spslidar.run(**params, backend="torch", device="cuda")
else:
    print("No CUDA device (or no PyTorch) on this machine: the GPU run is skipped. "
          'Install with pip install -e ".[gpu]" on a machine with an NVIDIA GPU.')
for name, r in runs.items():
    print(f"{name:13s} total {r.timing['total']:.2f} s (simulate {r.timing['simulate']:.2f}, "
          f"solve {r.timing['solve']:.2f}), RMSE {r.depth_rmse:.4f} m")

# %%
# The depth maps
# --------------
# Torch draws its random numbers on the device from the same seed, so the two runs are
# different realisations: reproducible per backend, not bitwise equal across backends.
truth = runs["numpy (CPU)"].truth
lo, hi = np.nanmin(truth), np.nanmax(truth)
fig, axes = plt.subplots(1, 1 + len(runs), figsize=(4 * (1 + len(runs)), 3.6),
                         layout="constrained")
axes[0].imshow(truth, vmin=lo, vmax=hi)
axes[0].set_title("truth, 128x128")
for ax, (name, r) in zip(axes[1:], runs.items(), strict=True):
    im = ax.imshow(r.depth, vmin=lo, vmax=hi)
    ax.set_title(f"{name}\n{r.timing['total']:.2f} s, RMSE {r.depth_rmse:.3f} m")
for ax in axes:
    ax.set_axis_off()
_ = fig.colorbar(im, ax=axes, label="depth [m]", shrink=0.8)
plt.show()
