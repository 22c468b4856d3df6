"""A fit made ready to run: the target, the model, the options and a starting point, in one object.

:func:`shspec.fitting.prepare_fit` plans one (:class:`~shspec.fitting.FitPlan`, which adds the reasons for its
choices); :func:`~shspec.inverse.fit` runs it as ``fit(plan)``.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..spectral_model import SpectralModel
from .options import FitOptions
from .target import Target

__all__ = ["PreparedFit"]


@dataclass(frozen=True)
class PreparedFit:
    """What :func:`~shspec.inverse.fit` needs, ready to run.

    Attributes
    ----------
    target : Target
    model : SpectralModel
    options : FitOptions
    init : (model.nparams,) array or None
        The first start's parameters (None: random, as every other start).
    """

    target: Target
    model: SpectralModel
    options: FitOptions
    init: np.ndarray | None = field(default=None, repr=False)

    def run(self, fit_target, *, resume: bool = False, executor=None):
        """Run the fit: ``fit_target(target, model, options, resume=, init=, executor=)`` is the solver's fit of
        one target (``fit(plan)`` passes it; a plan may run it otherwise, e.g. stage by stage); returns its
        :class:`~shspec.inverse.FitResult`."""
        return fit_target(self.target, self.model, self.options, resume=resume, init=self.init, executor=executor)
