"""
Quadratic correlation reconstruction (QCR) or not
==================================================

Every DMD pattern gives one matched-filter output per range bin: a matrix ``C`` of ``M``
patterns by ``K`` gated delays. Most of each output is the mean over the patterns (half the
mirrors are on on average) and the background. QCR (eq. 11-17 of the paper) centres the
patterns and the measurements over the pattern index and solves with the covariance
``Delta = Phi_c^T C_c / M`` (:func:`spslidar.qcr.qcr_delta`) instead of the raw data.

One measurement is simulated once (:func:`spslidar.measure`) and reconstructed both ways
(:func:`spslidar.reconstruct`), so the two differ only in processing.

The 1023-bit code keeps the example quick; its unambiguous range, 15.33 m, falls short of the
scene at 20 m, so the run warns that the range gate lies beyond it. The depths are right
because the gate is known to hold the scene (a 4095-bit code, 61.4 m, reaches it without a
warning, as the first example's does).
"""

import matplotlib.pyplot as plt
import numpy as np

import spslidar
from spslidar.qcr import qcr_delta

meas = spslidar.measure(scene="camera", size=32, code_length=1023, seed=0)
with_qcr = spslidar.reconstruct(meas)
without = spslidar.reconstruct(meas, qcr=False)
for name, r in (("QCR", with_qcr), ("no QCR", without)):
    print(f"{name:7s} RMSE {r.depth_rmse:.4f} m, solve {r.timing['solve']:.2f} s")

# %%
# What QCR removes
# ----------------
# The raw matched-filter outputs (left) are dominated by their mean over the patterns: bright
# columns at the delays of the scene's surfaces. Centred over the patterns (middle) only the
# pattern-dependent part is left. The covariance ``Delta`` (right, at the delay with the
# largest covariance) is a back-projection of it onto the pixels: with 256 patterns for 1024
# pixels the centred patterns are far from orthogonal (``H = Phi_c^T Phi_c / M`` of eq. 17 is
# not the identity), so ``Delta`` alone is no image; QCR solves ``H X = Delta`` for all delays
# with a TV prior.
corr = with_qcr.corr
delta = qcr_delta(meas.patterns, corr)
k = int(np.argmax(np.abs(delta).sum(axis=0)))
n = meas.config.size

fig, axes = plt.subplots(1, 3, figsize=(11, 3.2), layout="constrained")
im = axes[0].imshow(corr, aspect="auto", cmap="magma")
axes[0].set(title="matched filter C (patterns x delays)", xlabel="delay index",
            ylabel="pattern")
fig.colorbar(im, ax=axes[0])
im = axes[1].imshow(corr - corr.mean(axis=0), aspect="auto", cmap="RdBu_r")
axes[1].set(title="centred over the patterns", xlabel="delay index")
fig.colorbar(im, ax=axes[1])
im = axes[2].imshow(delta[:, k].reshape(n, n), cmap="gray")
axes[2].set_title(f"Delta at delay index {k}")
axes[2].set_axis_off()

# %%
# Depth maps
# ----------
# Both solve the same measurement with FISTA and TV. Without QCR the mean direction of the
# patterns is eliminated exactly instead (:class:`spslidar.qcr.MeanEliminated`, with the TV
# regulariser); on this small, short-code problem QCR does better (the two RMSE printed
# above: about 0.066 against 0.116 m at seed 0); the reproduction report compares them over
# code lengths at 64x64 (Fig. 4).
fig, axes = plt.subplots(1, 3, figsize=(10, 3.2), layout="constrained")
lo, hi = np.nanmin(with_qcr.truth), np.nanmax(with_qcr.truth)
panels = [(with_qcr.truth, "truth"),
          (with_qcr.depth, f"QCR, RMSE {with_qcr.depth_rmse:.3f} m"),
          (without.depth, f"no QCR, RMSE {without.depth_rmse:.3f} m")]
for ax, (img, title) in zip(axes, panels, strict=True):
    im = ax.imshow(img, vmin=lo, vmax=hi)
    ax.set_title(title)
    ax.set_axis_off()
fig.colorbar(im, ax=axes, label="depth [m]", shrink=0.85)
plt.show()
