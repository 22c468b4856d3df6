"""
Hearing a random surface
========================

Thirty-six eigenvalues of a random smooth ρ of degree 4 recover it up to the symmetries a spectrum cannot see:
the fitted ρ is compared with the truth after Möbius centering and the best rotation or reflection.
"""

import matplotlib.pyplot as plt

from shspec import ConformalFactor, HarmonicModel
from shspec.inverse import FitOptions, align, fit
from shspec.fitting import harmonic_target
from shspec.sphere.random import random_centred_coefficients

truth = ConformalFactor(random_centred_coefficients(3, 4, 0.2), name="random rho of degree 4")
target = harmonic_target(truth, lmax=12, numeig=36)
result = fit(target, HarmonicModel(12, 4), FitOptions(starts=2, seed=1))
aligned = align(result.factor(), target.truth)
print(f"best residual {result.best.relative_residual:.1e}; rho off by {aligned.relative_error:.1e} after alignment")
print(result.identifiability().statement())

reference = ConformalFactor(aligned.reference, name="truth, Möbius-centred")
fitted = ConformalFactor(aligned.aligned, name="fit, centred and rotated onto it")
values = reference.evaluate()[0]
fig = plt.figure(figsize=(11, 4))
for i, rho in enumerate((reference, fitted)):
    rho.plot(ax=fig.add_subplot(1, 2, i + 1, projection="hammer"), vmin=values.min(), vmax=values.max())
fig.tight_layout()
