"""
The Geiger-mode APD: dead time and pile-up
==========================================

The paper counts photons linearly. A real Geiger-mode avalanche photodiode (GMAPD) records
at most one photon per dead time (50 ns here, 500 bins at 10 GHz) and then is blind: at high
flux the photons arriving early in a burst hide the later ones (*pile-up*).
``detector="gmapd"`` simulates it (:mod:`spslidar.detectors.gmapd`), and corrects the
histograms for pile-up before the matched filter.

This example uses the detector model's core directly, one histogram at a time: the stationary
detection probability per TDC bin of a free-running, non-paralysable detector
(:func:`~spslidar.detectors.pileup.renewal_detection`) and its inverse, the generalised Coates
correction (:func:`~spslidar.detectors.pileup.coates_correction`). The full chain with a GMAPD
(``spslidar run --detector gmapd``) is what ``spslidar reproduce pileup`` runs; see the
:doc:`/reproduction` report.
"""

import matplotlib.pyplot as plt
import numpy as np

from spslidar.codes import make_code
from spslidar.detectors.gmapd import GMAPD
from spslidar.detectors.pileup import coates_correction, renewal_detection

DEAD = 500  # dead time in bins: 50 ns at 10 GHz
L = 1023  # code period in bins
code = make_code("mseq", L).astype(float)
delay = 400


def incident(lidar, photons_per_dead_time, signal_share=0.9):
    """Mean incident photons per bin over one period: the same average power for both
    lidars (the same photons per period), a tenth of them background."""
    per_period = photons_per_dead_time * L / DEAD
    if lidar == "psst":
        shape = np.roll(code, delay) / code.sum()
    else:
        shape = np.zeros(L)
        shape[delay] = 1.0
    return per_period * (signal_share * shape + (1 - signal_share) / L)


# %%
# Detections against incident photons
# -----------------------------------
# A free-running detector's count rate saturates at one per dead time, as ``n / (1 + n)``
# for ``n`` incident photons per dead time, whatever the lidar.
fluxes = np.logspace(-2, 1, 13)
detected = [renewal_detection(incident("psst", n), DEAD).sum() * DEAD / L for n in fluxes]
fig, ax = plt.subplots(figsize=(5.5, 3.5), layout="constrained")
ax.loglog(fluxes, fluxes, "k:", label="linear counter")
ax.loglog(fluxes, fluxes / (1 + fluxes), "C7--", label="n / (1 + n)")
ax.loglog(fluxes, detected, "o", color="C0", label="GMAPD model")
ax.set(xlabel="incident photons per dead time", ylabel="detections per dead time")
_ = ax.legend()

# %%
# Pile-up distorts the conventional pulse, not the code
# -----------------------------------------------------
# At 3 photons per dead time, the conventional lidar's single pulse puts all of a period's
# signal (5.5 photons) in one bin: the detector, once fired by the first of them, is blind to
# the rest and to everything for the next dead time, so the pulse's bin is counted at a
# fraction of its strength and the background after it is lost. The code
# spreads the same photons over 512 pulses, a hundredth of a photon per bin: every bin is
# seen with nearly the same efficiency, a constant factor that the matched filter ignores.
# The Coates correction estimates the incident photons from a measured histogram, here drawn
# as the detector records it, one detection at a time (``GMAPD.detect``: at most one per
# dead time). For the code the correction is a nearly constant factor; for the conventional
# pulse it divides each bin by the share of periods in which the detector was still armed
# there: the pulse period (1023 bins) is longer than the dead time, so the detector re-arms
# before every pulse, and the correction, exact for such a synchronous detector, recovers the
# pulse to within its counting noise, though the bin behind a nearly saturated one is seen in
# few periods and is noisier.
n = 3.0
periods = 100_000
rng = np.random.default_rng(0)
gmapd = GMAPD(dead_time=DEAD * 1e-10, bin_width=1e-10)
window = slice(delay - 60, delay + 120)
bins = np.arange(L)[window]
fig, axes = plt.subplots(2, 2, figsize=(11, 5.5), sharex=True, layout="constrained")
for col, lidar in enumerate(("conventional", "psst")):
    mu = incident(lidar, n)
    p = renewal_detection(mu, DEAD)  # detections per bin per period
    hist = gmapd.detect((mu * periods)[None, :], rng, periods)[0][0]  # a measured histogram
    # incident photons per bin and period, estimated from the measured histogram
    corrected = coates_correction(hist, periods, DEAD) / periods
    axes[0, col].semilogy(bins, mu[window], lw=1, label="incident")
    axes[0, col].semilogy(bins, p[window], lw=1, label="detected")
    axes[0, col].set_title(f"{lidar}: photons per bin per period")
    axes[0, col].legend(fontsize=8)
    axes[1, col].plot(bins, (p / mu)[window], lw=1, label="detected / incident")
    axes[1, col].plot(bins, (corrected / mu)[window], lw=0.6, alpha=0.7,
                      label="corrected / incident")
    axes[1, col].set(ylim=(0, 1.3), xlabel="TDC bin", title=f"{lidar}: detection efficiency")
    axes[1, col].legend(fontsize=8, loc="lower right")
    on = mu > mu.min() * 1.5  # the bins with signal
    print(f"{lidar:12s} signal bins: {p[on].sum() / mu[on].sum():.2f} of the incident photons "
          f"detected (efficiency {np.min(p[on] / mu[on]):.2f}-{np.max(p[on] / mu[on]):.2f} "
          f"across them); after the correction {corrected[on].sum() / mu[on].sum():.3f}")
plt.show()

# %%
# What to do with it: run a GMAPD near one photon per dead time and make up the photons with
# a longer dwell (``periods``). The reproduction's ``pileup`` experiment measures the depth
# error against the flux: the PSST lidar is at 1.3-2.2 cm from 1 to 10 photons per dead time
# with or without the correction; the conventional lidar's error grows to decimetres above one
# photon per dead time uncorrected, and stays at 0.4-1.1 cm corrected.
