"""
Codes compared: m-sequence, Gold and random
============================================

The laser is switched on and off by a pseudo-random bit code; the matched filter correlates the
detected counts with a replica of the code, so the code's periodic autocorrelation is the
lidar's range response. Shen et al. compare m-sequences, Gold codes and Bernoulli ("random")
bits (Fig. 3). :mod:`spslidar.codes` makes all three and their periodic correlations.
"""

import matplotlib.pyplot as plt
import numpy as np

from spslidar.codes import gold_bound, gold_family, make_code, periodic_xcorr, unambiguous_range

T = 1023  # 2^10 - 1 bits
codes = {
    "m-sequence": make_code("mseq", T),
    "Gold": make_code("gold", T, index=2),
    "random (R_a = 0.5)": make_code("random", T, ones_ratio=0.5, rng=0),
}
for name, c in codes.items():
    print(f"{name:20s} {c.size} bits, {c.sum()} ones")
print(f"unambiguous range at 10 Gbit/s: {unambiguous_range(T, 10e9):.2f} m")

# %%
# Periodic autocorrelation
# ------------------------
# With a bipolar (+-1) replica the m-sequence's autocorrelation is two-valued, ``T`` at zero
# lag and ``-1`` elsewhere: a constant background cancels. Gold codes and random bits have
# larger side lobes, which spread a bright return's energy over other depths.
fig, axes = plt.subplots(1, 3, figsize=(11, 3), sharey=True, layout="constrained")
lags = np.arange(T)
for ax, (name, c) in zip(axes, codes.items(), strict=True):
    r = periodic_xcorr(c, c)
    ax.plot(lags, r, lw=0.8)
    side = np.abs(r[1:]).max()
    ax.set_title(f"{name}\nmax side lobe {side:.0f} (peak {r[0]:.0f})")
    ax.set_xlabel("lag [bits]")
axes[0].set_ylabel("periodic autocorrelation")

# %%
# Side lobes in detail, and the Gold family's cross-correlation
# -------------------------------------------------------------
# A Gold family holds ``T + 2`` codes whose pairwise cross-correlations stay within the Gold
# bound ``t(n) = 1 + 2^((n + 2) / 2)``: useful when several lidars share a scene.
family = gold_family(10)
cross = periodic_xcorr(family[2], family[3])
fig, axes = plt.subplots(1, 2, figsize=(10, 3), layout="constrained")
for name, c in codes.items():
    axes[0].plot(lags[1:60], periodic_xcorr(c, c)[1:60], label=name, lw=1)
axes[0].set_xlabel("lag [bits]")
axes[0].set_title("side lobes (lags 1-59)")
axes[0].legend(fontsize=8)
axes[1].plot(lags, cross, lw=0.6)
for s in (-1, 1):
    axes[1].axhline(s * gold_bound(10), color="k", ls="--", lw=0.8)
axes[1].set_title(f"Gold members 2 and 3: cross-correlation, bound {gold_bound(10)}")
axes[1].set_xlabel("lag [bits]")
plt.show()

# %%
# The same choice in a full run is the ``code`` key (``--code`` on the command line), e.g.
# ``spslidar.run(code="gold", code_length=1023)``; see :data:`spslidar.codes.CODES`.
