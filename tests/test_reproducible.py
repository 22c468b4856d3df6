"""The same input gives the same bits on any number of BLAS and numba threads (shspec.core.threads.reproducible)."""

from __future__ import annotations

import numba
import numpy as np
import pytest
from threadpoolctl import threadpool_info, threadpool_limits

from shspec.errors import InvalidArgumentError
from shspec.galerkin import HarmonicModel
from shspec.sphere.random import random_centred_coefficients
from shspec.core.threads import reproducible, set_reproducible

# large enough that OpenBLAS splits its work between two threads: before the rule, 152 of the 200 eigenvalues differed
LB, LA, K = 24, 10, 200


@pytest.fixture(scope="module")
def model_and_rho():
    return HarmonicModel(LB, LA), random_centred_coefficients(5, LA, 0.2)


def _blas_threads() -> list:
    return [pool["num_threads"] for pool in threadpool_info() if pool["user_api"] == "blas"]


def test_a_spectrum_and_its_jacobian_have_the_same_bits_on_one_blas_thread_and_on_two(model_and_rho):
    model, rho = model_and_rho
    with threadpool_limits(limits=1):
        one = model.spectrum(rho, K)
        jac_one = model.jacobian(one)
    with threadpool_limits(limits=2):
        two = model.spectrum(rho, K)
        jac_two = model.jacobian(two)
    np.testing.assert_array_equal(one.eigenvalues, two.eigenvalues)
    np.testing.assert_array_equal(jac_one, jac_two)


@pytest.mark.skipif(numba.config.NUMBA_NUM_THREADS < 2, reason="one numba thread: nothing to compare")
def test_the_eigenvalue_derivatives_have_the_same_bits_on_any_number_of_numba_threads(model_and_rho):
    model, rho = model_and_rho
    spec = model.spectrum(rho, K)
    before = numba.get_num_threads()
    try:
        numba.set_num_threads(1)
        one = model.table.quadratic_forms(spec.eigenvectors)
        numba.set_num_threads(numba.config.NUMBA_NUM_THREADS)
        many = model.table.quadratic_forms(spec.eigenvectors)
    finally:
        numba.set_num_threads(before)
    np.testing.assert_array_equal(one, many)


def test_reproducible_gives_the_blas_threads_back_and_can_be_switched_off():
    with threadpool_limits(limits=2):
        outside = _blas_threads()
        with reproducible():
            with reproducible():  # nested: still one thread after the inner block
                pass
            assert set(_blas_threads()) == {1}
        assert _blas_threads() == outside
        set_reproducible(False)
        try:
            with reproducible():
                assert _blas_threads() == outside
        finally:
            set_reproducible(True)
    with pytest.raises(InvalidArgumentError, match="True or False"):
        set_reproducible("yes")
