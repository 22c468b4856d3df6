"""The piecewise-linear mesh path: meshes, shapes, cotan spectra, cMCF, Möbius centering and the harmonic bridge."""
