"""
Convergence of the Galerkin spectrum
====================================

A Möbius-boosted sphere is isometric to the unit sphere, so its eigenvalues are exactly l(l+1). Its conformal
factor is far from constant, which makes it a hard test of the band limits: the eigenvalues converge from above,
exponentially in the basis degree Lb.
"""

import matplotlib.pyplot as plt

from shspec import ConformalFactor, convergence

rho = ConformalFactor.mobius_boost(2.0, lmax=24, axis=(1, 1, 1))
study = convergence(rho, [8, 12, 16, 20, 24], k=25)
for row in study.table():
    print(f"Lb = {row['lmax']}: largest relative change against Lb = 24: {row['max_relative_change']:.1e}")

fig = plt.figure(figsize=(11, 4.4), layout="constrained")  # room for the map's title and colour bar
rho.plot(ax=fig.add_subplot(1, 2, 1, projection="hammer"), title="rho of the boost k = 2")
study.plot(ax=fig.add_subplot(1, 2, 2))
