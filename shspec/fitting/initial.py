"""Starting points and truths read from files, converted to the model that uses them.

A fit's files hold different things: ``summary.json``'s ``cilm`` is ρ itself, whatever the model; ``result.h5``'s
``solution`` is its model's parameters (ρ's coefficients, log ρ's, or per-vertex factors, as its ``model``
attribute says); a ``.npy`` array or a text column holds the parameters of the model it is given to.  A start for
another model is converted (ρ → log ρ and back on a quadrature grid, harmonics → values at a mesh's vertices), and
what cannot be converted is refused: nothing is silently read as something else.  Coefficients in a file, flat or
cilm, are shspec's own, orthonormal (:data:`FILE_NORMALIZATION`), as every file shspec writes holds them.
"""

from __future__ import annotations

import json
import warnings
from pathlib import Path

import h5py
import numpy as np

from ..core.atomic import check_complete
from ..core.checks import real_array
from ..errors import InvalidArgumentError, NotPositiveError
from ..galerkin.log_model import LogHarmonicModel
from ..galerkin.model import HarmonicModel
from ..mesh.model import MeshModel
from ..sphere.evaluate import sample_harmonic
from ..sphere.factor import ConformalFactor
from ..sphere.grid import evaluate_on_grid, expand_grid, glq_grid
from ..sphere.harmonics import as_coefficients, lmax_of_size

__all__ = ["read_parameters", "initial_parameters", "read_initial", "read_truth", "FILE_NORMALIZATION"]

#: The normalization of harmonic coefficients in a file: shspec's ('ortho', csphase 1), that of summary.json's cilm.
#: A file cannot say another; coefficients in pyshtools' '4pi' are converted before saving
#: (``SHCoeffs.convert(normalization="ortho")``).
FILE_NORMALIZATION = "ortho"

#: What a file of parameters holds: ρ's harmonic coefficients, log ρ's, per-vertex factors c, their logarithms, or
#: the parameters of whatever model reads it ("own").
KINDS = ("rho", "log-rho", "factors", "log-factors", "own")


def _kind_of_model(description: str) -> str:
    """The kind of parameters of a model, from its :meth:`describe` string (a result file's ``model`` attribute)."""
    head = description.split()[0] if description else ""
    if head == "harmonic":
        return "rho"
    if head == "log-harmonic":
        return "log-rho"
    if head == "mesh":
        return "log-factors" if description.rstrip().endswith("exp") else "factors"
    raise InvalidArgumentError(f"a result file of an unknown model {description!r}")


def read_parameters(path, what: str = "parameters") -> tuple[np.ndarray, str]:
    """The values in a parameter file and what they are (module notes).

    Parameters
    ----------
    path : path-like
        A fit's ``result.h5`` or ``summary.json``, a ``.npy`` array or a text column.
    what : str
        What the file is for, in messages.

    Returns
    -------
    values : (n,) or cilm array
    kind : str
        One of :data:`KINDS`.

    Raises
    ------
    InvalidArgumentError
        If the file cannot be read, or holds no value.
    """
    path = Path(path)
    if path.suffix in (".h5", ".json"):  # a fit's outputs
        check_complete(path)
    try:
        if path.suffix == ".h5":
            with h5py.File(path, "r") as f:
                value, kind = f["solution"][()], _kind_of_model(str(f.attrs.get("model", "")))
        elif path.suffix == ".json":
            value, kind = np.array(json.loads(path.read_text())["cilm"], dtype=float), "rho"
        elif path.suffix == ".npy":
            value, kind = np.load(path, allow_pickle=False), "own"
        else:
            with warnings.catch_warnings():  # an empty file is named below, not warned about
                warnings.simplefilter("ignore", UserWarning)
                value, kind = np.loadtxt(path, ndmin=1), "own"
    except (OSError, KeyError, ValueError, TypeError, EOFError) as exc:
        raise InvalidArgumentError(f"cannot read {what} from {path}: {exc or type(exc).__name__}") from None
    if np.size(value) == 0:
        raise InvalidArgumentError(f"{path} holds no values; {what} needs at least one")
    return value, kind


def _harmonic(value, kind: str, la: int, name: str) -> np.ndarray:
    """Harmonic coefficients of degree ≤ la of ρ (kind "rho") or log ρ ("log-rho") as given; above la they must
    vanish."""
    a = as_coefficients(value, normalization=FILE_NORMALIZATION)
    n = (la + 1) ** 2
    if a.size > n and np.any(a[n:] != 0):
        raise InvalidArgumentError(f"the starting {'rho' if kind == 'rho' else 'log rho'} in {name} has degree "
                                   f"{lmax_of_size(a.size)} > La = {la}")
    out = np.zeros(n)
    out[:min(a.size, n)] = a[:n]
    return out


def _log_of(a: np.ndarray, la: int, name: str) -> np.ndarray:
    """log ρ's coefficients of degree ≤ la from ρ's (a grid expansion; ρ must be positive)."""
    grid = glq_grid(2 * max(la, lmax_of_size(a.size)) + 8)
    values = evaluate_on_grid(a, grid)
    if not np.all(values > 0):
        raise NotPositiveError(f"the starting rho in {name} is not positive (minimum {values.min():.3g} on a grid): "
                               "it has no logarithm for a log-rho fit")
    return expand_grid(np.log(values), grid, la)


def _exp_of(u: np.ndarray, la: int) -> np.ndarray:
    """ρ = exp(u) cut to degree la (a grid expansion)."""
    grid = glq_grid(2 * max(la, lmax_of_size(u.size)) + 8)
    return expand_grid(np.exp(evaluate_on_grid(u, grid)), grid, la)


def initial_parameters(value, kind: str, model, name: str = "the starting point") -> np.ndarray:
    """A starting point for ``model`` from values of the given kind (module notes).

    Parameters
    ----------
    value : array
        Flat coefficients or a cilm array (kinds "rho", "log-rho"), or one value per vertex.
    kind : str
        One of :data:`KINDS`.
    model : HarmonicModel, LogHarmonicModel or MeshModel
    name : str
        Where the values come from, in messages.

    Returns
    -------
    (model.nparams,) array

    Raises
    ------
    InvalidArgumentError, NotPositiveError
        If the values do not fit the model or cannot be converted to it.

    Examples
    --------
    >>> import numpy as np
    >>> from shspec import LogHarmonicModel
    >>> from shspec.fitting import initial_parameters
    >>> rho = np.zeros(9); rho[0] = np.sqrt(4 * np.pi)          # rho = 1: the unit sphere
    >>> u = initial_parameters(rho, "rho", LogHarmonicModel(8, 2))  # log rho = 0
    >>> bool(np.allclose(u, 0, atol=1e-12))
    True
    """
    if kind not in KINDS:
        raise InvalidArgumentError(f"kind must be one of {KINDS}, got {kind!r}")
    if isinstance(model, (HarmonicModel, LogHarmonicModel)):
        log = isinstance(model, LogHarmonicModel)
        if kind in ("factors", "log-factors"):
            raise InvalidArgumentError(f"{name} holds per-vertex factors of a mesh fit; a harmonic fit starts from "
                                       "harmonic coefficients (a summary.json holds rho's)")
        if kind == "own":
            kind = "log-rho" if log else "rho"
        la = model.lmax_factor
        if kind == ("log-rho" if log else "rho"):
            return _harmonic(value, kind, la, name)
        a = as_coefficients(value, normalization=FILE_NORMALIZATION)
        return _log_of(a, la, name) if log else _exp_of(a, la)
    if isinstance(model, MeshModel):
        log = model.transform == "exp"
        if kind in ("rho", "log-rho"):
            a = as_coefficients(value, normalization=FILE_NORMALIZATION)
            v = sample_harmonic(a, model.mesh.vertices)
            if kind == "rho" and not np.all(v > 0):
                raise NotPositiveError(f"the starting rho in {name} is not positive at every vertex of the fit's mesh")
            kind, value = ("log-factors", v) if kind == "log-rho" else ("factors", v)
        values = real_array(value, name).ravel()
        if values.shape != (model.nparams,):
            raise InvalidArgumentError(f"{name} holds {values.size} values; the mesh model has {model.nparams} "
                                       "vertices")
        if kind == "own":
            return values
        if kind == "factors" and log:
            if not np.all(values > 0):
                raise NotPositiveError(f"{name} holds factors that are not all positive: they have no logarithm")
            return np.log(values)
        return np.exp(values) if kind == "log-factors" and not log else values
    raise InvalidArgumentError(f"no starting point can be read for a {type(model).__name__}")


def read_initial(path, model) -> np.ndarray:
    """A starting point for ``model`` from a file (:func:`read_parameters`, then :func:`initial_parameters`).

    Raises
    ------
    InvalidArgumentError, NotPositiveError
        If the file cannot be read, or does not fit the model.

    Examples
    --------
    >>> import json
    >>> from shspec import LogHarmonicModel
    >>> from shspec.fitting import blob_factor, read_initial
    >>> with open("summary.json", "w") as f:          # a fit's summary holds rho's cilm, whatever its model
    ...     json.dump({"cilm": blob_factor().to_cilm().tolist()}, f)
    >>> u = read_initial("summary.json", LogHarmonicModel(12, 8))   # converted to log rho of degree 8
    >>> u.shape
    (81,)
    """
    value, kind = read_parameters(path, "a starting point")
    return initial_parameters(value, kind, model, name=str(path))


def read_truth(path) -> ConformalFactor:
    """The true ρ of a target from a file of ρ's harmonic coefficients (flat or cilm): a ``summary.json``, the
    ``result.h5`` of a harmonic fit, a ``.npy`` array or a text column.

    Raises
    ------
    InvalidArgumentError, NotPositiveError
        If the file cannot be read, holds no harmonic ρ, or its ρ is not positive.

    Examples
    --------
    >>> import numpy as np
    >>> from shspec.fitting import blob_factor, read_truth
    >>> np.save("truth.npy", blob_factor().coefficients)
    >>> truth = read_truth("truth.npy")
    >>> truth.name, truth.lmax
    ('truth (truth.npy)', 6)
    """
    value, kind = read_parameters(path, "the true rho")
    if kind == "log-rho":
        u = as_coefficients(value, normalization=FILE_NORMALIZATION)
        value = _exp_of(u, lmax_of_size(u.size))
    elif kind not in ("rho", "own"):
        raise InvalidArgumentError(f"{path} holds per-vertex factors, not a harmonic rho")
    rho = ConformalFactor(as_coefficients(value, normalization=FILE_NORMALIZATION), name=f"truth ({Path(path).name})")
    rho.check_positive()
    return rho
