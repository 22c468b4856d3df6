"""Parse the ``--rho`` argument shared by the forward commands."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from ..errors import InvalidArgumentError
from ._common import load_numbers
from ..sphere.factor import ConformalFactor

RHO_HELP = (
    "the conformal factor rho: 'boost:K[:X,Y,Z]' (Moebius-boosted unit sphere, spectrum exactly l(l+1); default "
    "'boost:2:1,1,1'), 'sphere[:AREA]', or a file: .npy (flat coefficient vector or cilm array (2,L+1,L+1)), "
    ".json (a list of flat coefficients, or an object with 'cilm' or 'coefficients'), .txt (one coefficient per "
    "line). Coefficients are real orthonormal harmonics as pyshtools (ortho, csphase=1), flat index l*l+l+m."
)


def parse_rho(text: str, lmax_factor: int) -> ConformalFactor:
    """A ConformalFactor from a ``--rho`` string; built-in closed forms are expanded to ``lmax_factor``."""
    kind, _, rest = text.partition(":")
    if kind == "boost":
        parts = rest.split(":") if rest else ["2"]
        try:
            k = float(parts[0])
            axis = [float(x) for x in parts[1].split(",")] if len(parts) > 1 else [0.0, 0.0, 1.0]
        except ValueError:
            raise InvalidArgumentError(f"--rho boost:K[:X,Y,Z] expects numbers, got {text!r}") from None
        return ConformalFactor.mobius_boost(k, lmax_factor, axis)
    if kind == "sphere":
        try:
            area = float(rest) if rest else 4 * np.pi
        except ValueError:
            raise InvalidArgumentError(f"--rho sphere[:AREA] expects a number, got {text!r}") from None
        return ConformalFactor.sphere(area)
    path = Path(text)
    if not path.is_file():
        raise InvalidArgumentError(f"--rho {text!r} is neither a built-in ('boost:...', 'sphere') nor a file")
    suffix = path.suffix.lower()
    try:
        if suffix == ".npy":
            data = np.load(path, allow_pickle=False)
        elif suffix == ".json":
            obj = json.loads(path.read_text())
            if isinstance(obj, dict):
                obj = obj.get("cilm", obj.get("coefficients"))
                if obj is None:
                    raise InvalidArgumentError(f"{path}: a JSON object needs a 'cilm' or 'coefficients' entry")
            data = np.asarray(obj, dtype=float)
        elif suffix in (".txt", ".dat", ".csv"):
            data = load_numbers(path, "coefficients of rho")
        else:
            raise InvalidArgumentError(f"{path}: unknown coefficient file type {suffix!r} (use .npy, .json, .txt)")
    except InvalidArgumentError:
        raise
    except (OSError, ValueError, EOFError) as exc:  # np.load of an empty file: EOFError
        raise InvalidArgumentError(f"cannot read coefficients from {path}: {exc or type(exc).__name__}") from exc
    # a file's coefficients are shspec's own, orthonormal (shspec.fitting.initial.FILE_NORMALIZATION)
    return ConformalFactor(data, name=path.stem, normalization="ortho")
