"""Reproducible experiments of the study, one command each (``shspec experiment NAME``)."""

from . import (identifiability_study, pl_basin, pl_bunny, pl_numeig, pl_perturbation, sh_convergence,  # noqa: F401  (registration)
               sh_inverse, sh_perturbation)
from .base import EXPERIMENTS, Experiment, Finding, run_experiment

__all__ = ["EXPERIMENTS", "Experiment", "Finding", "run_experiment"]
