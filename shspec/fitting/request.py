"""What a user asks of a fit, before it is planned: :class:`FitRequest`.

``shspec fit`` parses its arguments into one, and a Python user writes the same fields as keywords of
:func:`~shspec.fitting.prepare_fit`; every field left at None is planned (:mod:`shspec.fitting.plan`).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..core.checks import check_float, check_int, check_options
from ..errors import InvalidArgumentError
from ..inverse.options import FitOptions
from ..inverse.target import Target
from ..mesh.mesh_files import load_mesh
from ..mesh.model import REGULARIZER_KINDS
from ..mesh.triangle_mesh import TriangleMesh
from ..sphere.factor import ConformalFactor
from .adaptive import AdaptiveOptions
from .targets import TARGET_SOURCES, check_target_text

__all__ = ["FitRequest", "MODEL_KINDS"]

#: The discretizations a fit can use: ρ's harmonic coefficients, log ρ's, or per-vertex factors of a mesh.
MODEL_KINDS = ("harmonic", "log", "mesh")


@dataclass(frozen=True)
class FitRequest:
    """A fit as asked for; None means "plan it" (:func:`~shspec.fitting.prepare_fit`).

    Attributes
    ----------
    target : str, TriangleMesh, ConformalFactor, Target or (k,) array
        What to hear: the command line's ``blob | star:l,m,p | mesh:PATH | spectrum:FILE`` (a shipped mesh by
        name, ``mesh:spot_600``), a mesh, a harmonic ρ (its Galerkin spectrum), a target, or eigenvalues (λ₀ = 0
        first).
    model : {"harmonic", "log", "mesh"} or None
        None: "log" for a mesh, else "harmonic".
    lmax_factor, lmax : int or None
        Degree La of ρ and the basis degree Lb; ``lmax_factor="auto"``: the largest La that a given spectrum's K
        eigenvalues support at 2.5 per coefficient of ρ (the plan's own share).
    numeig : int, "auto", "all" or None
        Eigenvalues matched, λ₀ included; "auto" (a mesh): those its mesh resolves to ``numeig_tol``; "all": every
        eigenvalue of a mesh's.
    noise : float or None
        Relative error of each eigenvalue, σ_i = noise·λ_i.  Not with a target that has errors of its own.
    errors : (k,) array or None
        The absolute errors of eigenvalues given as an array.
    truth : ConformalFactor, array, path or None
        The true ρ (its coefficients, or a file of them): the fit is compared with it.
    reg : float or None
        Penalty weight R; None: ``options.reg``, or 0.05 for a mesh fit (the study's).
    source : {"pl", "cmcf", "harmonic"}
        A mesh's spectrum (:data:`~shspec.fitting.targets.TARGET_SOURCES`).
    subdivisions : int
        Icosphere subdivisions of a star.
    numeig_tol : float
        Relative eigenvalue error that ``numeig="auto"`` accepts.
    reg_kind : str
        Penalty of a mesh fit (:data:`~shspec.mesh.model.REGULARIZER_KINDS`).
    log_factors : bool
        A mesh fit's parameters are log c (True) or c.
    adaptive : AdaptiveOptions or None
        Fit a mesh's factors from an icosphere refined as the fit goes (:func:`~shspec.fitting.adaptive_fit`).
    schedule : str or tuple
        "auto" (``options.schedule``, else the fit's default), "degree-ramp", "parity-ramp", "ramp", "none", a
        stage text ("2,4,8,15", "6:16,6:64h", "8:64e,8") or a tuple of :class:`~shspec.inverse.Stage`.
    hop_degree : int or None
        The degree whose stage hops in the degree ramp (0: none).
    init : array, path or None
        The first start: a file (a fit's result.h5 or summary.json, .npy, a text column; converted to the model,
        :mod:`shspec.fitting.initial`) or the model's parameters.
    allow_any_genus : bool
        Fit a spectrum whose heat trace says its genus is not 0.
    allow_short_spectrum : bool
        Fit the degree asked with a spectrum of fewer eigenvalues than its plan asks for (2.5 per coefficient of
        ρ); by default such a spectrum is refused with the degree it supports
        (:class:`~shspec.errors.ShortSpectrumError`).
    options : FitOptions
        The search; its ``reg`` and ``schedule`` are those above when given.
    workers : int, "auto" or None
        Processes for the starts: "auto" (``shspec fit``'s default) one per start and usable core; None or 1: in
        this process.  A pool starts its processes with ``spawn``, which imports the calling script again: run it
        from a script whose fit sits under ``if __name__ == "__main__":``, or from the command line.
    scheduler : str or None
        A Dask scheduler's address.
    progress : bool
        Show what the planning and the fit do on stderr.

    Examples
    --------
    >>> from shspec.fitting import FitRequest, prepare_fit
    >>> request = FitRequest("blob", lmax_factor=6, lmax=12, numeig=40, progress=False)
    >>> request.is_mesh, prepare_fit(request).model.describe()
    (False, 'harmonic Lb=12 La=6')
    """

    target: object
    model: str | None = None
    lmax_factor: int | str | None = None
    lmax: int | None = None
    numeig: int | str | None = None
    noise: float | None = None
    errors: np.ndarray | None = field(default=None, repr=False)
    truth: object = field(default=None, repr=False)
    reg: float | None = None
    source: str = "pl"
    subdivisions: int = 3
    numeig_tol: float = 0.01
    reg_kind: str = "cotan-squared"
    log_factors: bool = True
    adaptive: AdaptiveOptions | None = None
    schedule: object = "auto"
    hop_degree: int | None = None
    init: object = field(default=None, repr=False)
    allow_any_genus: bool = False
    allow_short_spectrum: bool = False
    options: FitOptions = field(default_factory=FitOptions)
    workers: int | str | None = None
    scheduler: str | None = None
    progress: bool = True

    def __post_init__(self):
        self._check_target()
        if self.model is not None and self.model not in MODEL_KINDS:
            raise InvalidArgumentError(f"model must be one of {MODEL_KINDS}, got {self.model!r}")
        for name in ("lmax_factor", "lmax"):
            if getattr(self, name) is not None and not (name == "lmax_factor" and self.lmax_factor == "auto"):
                check_int(getattr(self, name), name, minimum=1 if name == "lmax_factor" else 0)
        if isinstance(self.numeig, str) and self.numeig not in ("auto", "all"):
            raise InvalidArgumentError(f"numeig is a whole number, 'auto' or 'all', got {self.numeig!r}")
        if self.numeig is not None and not isinstance(self.numeig, str):
            check_int(self.numeig, "numeig", minimum=2)
        if isinstance(self.numeig, str) and not self.is_mesh:
            raise InvalidArgumentError(f"numeig={self.numeig!r} needs a mesh target (star:..., mesh:... or a "
                                       "TriangleMesh)")
        if self.noise is not None:
            check_float(self.noise, "noise (the relative error of each eigenvalue)", positive=True)
        if self.reg is not None and not check_float(self.reg, "reg") >= 0:
            raise InvalidArgumentError(f"reg must be >= 0, got {self.reg}")
        if self.source not in TARGET_SOURCES:
            raise InvalidArgumentError(f"source must be one of {TARGET_SOURCES}, got {self.source!r}")
        if self.reg_kind not in REGULARIZER_KINDS:
            raise InvalidArgumentError(f"reg_kind must be one of {REGULARIZER_KINDS}, got {self.reg_kind!r}")
        check_int(self.subdivisions, "subdivisions", minimum=0)
        check_float(self.numeig_tol, "numeig_tol", positive=True)
        check_options(self.options, FitOptions)
        if self.workers is not None and self.workers != "auto":
            check_int(self.workers, "workers", minimum=1)
        self._check_adaptive()

    def _check_target(self):
        what = self.target
        if isinstance(what, str):
            check_target_text(what)  # a typo is named now, not after a minute of planning
        elif isinstance(what, Path):
            raise InvalidArgumentError(f"a target path must say what it holds: 'spectrum:{what}' or 'mesh:{what}'")
        elif not isinstance(what, (TriangleMesh, ConformalFactor, Target, np.ndarray, list, tuple)):
            raise InvalidArgumentError("a target is a string (blob, star:l,m,p, mesh:PATH, spectrum:FILE), a "
                                       f"TriangleMesh, a ConformalFactor, a Target or eigenvalues; got "
                                       f"{type(what).__name__}")
        if self.errors is not None and not isinstance(what, (np.ndarray, list, tuple)):
            raise InvalidArgumentError("errors go with eigenvalues given as an array; a Target carries its own")

    def _check_adaptive(self):
        if self.adaptive is None:
            return
        check_options(self.adaptive, AdaptiveOptions)
        if self.model != "mesh" or self.init is not None or self.workers not in (None, "auto") or self.scheduler:
            raise InvalidArgumentError("an adaptive fit is a mesh fit (model='mesh', --model mesh) without a starting "
                                       "point, workers or a scheduler")
        if not self.log_factors:
            raise InvalidArgumentError("an adaptive fit fits log factors (refinement follows log c); drop "
                                       "--no-log-factors")

    @property
    def is_mesh(self) -> bool:
        """Whether the target is a mesh (a star, a mesh file or a TriangleMesh)."""
        if isinstance(self.target, TriangleMesh):
            return True
        return isinstance(self.target, str) and self.target.partition(":")[0] in ("star", "mesh")

    def mesh_size(self) -> int:
        """Vertices of the target's mesh."""
        if isinstance(self.target, TriangleMesh):
            return self.target.nvertices
        scheme, _, arg = self.target.partition(":")
        if scheme == "mesh":
            return load_mesh(arg).nvertices
        return 10 * 4 ** self.subdivisions + 2
