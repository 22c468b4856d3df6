"""The shared argument checks (shspec.core.checks), and public functions that rely on them for their options."""

from __future__ import annotations

import pytest

from shspec import HarmonicModel
from shspec.core.checks import check_options
from shspec.errors import InvalidArgumentError, ShspecError
from shspec.inverse import fit
from shspec.fitting import blob_factor, harmonic_target
from shspec.mesh.cmcf import CMCFOptions, cmcf
from shspec.mesh.model import MeshModel
from shspec.mesh.shapes import icosphere
from shspec.spectral.topology import TopologyOptions, estimate_topology


def test_check_options_defaults_none_and_names_a_wrong_type():
    assert check_options(None, CMCFOptions) == CMCFOptions()
    given = CMCFOptions()
    assert check_options(given, CMCFOptions) is given
    with pytest.raises(InvalidArgumentError, match="options must be CMCFOptions, got str"):
        check_options("fast", CMCFOptions)
    with pytest.raises(InvalidArgumentError, match="embed_options must be TopologyOptions, got str"):
        check_options("fast", TopologyOptions, "embed_options")
    assert issubclass(InvalidArgumentError, ShspecError)


def test_public_functions_refuse_options_of_another_kind():
    with pytest.raises(InvalidArgumentError, match="options must be CMCFOptions, got TopologyOptions"):
        cmcf(icosphere(1), TopologyOptions())
    with pytest.raises(InvalidArgumentError, match="options must be TopologyOptions, got CMCFOptions"):
        estimate_topology([0.0, 2.0, 2.0, 2.0, 6.0], options=CMCFOptions())
    with pytest.raises(InvalidArgumentError, match="options must be EigenOptions, got CMCFOptions"):
        MeshModel(icosphere(1), CMCFOptions())
    with pytest.raises(InvalidArgumentError, match="options must be FitOptions, got CMCFOptions"):
        fit(harmonic_target(blob_factor(), 8, 20), HarmonicModel(8, 6), CMCFOptions())
