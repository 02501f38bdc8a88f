"""Shared fixtures.

``both_backends``: a test module that marks itself with ``pytestmark = pytest.mark.usefixtures("both_backends")``
runs every test twice, once with the compiled kernels (``course.kernels``, Numba) and once on the torch path, so
the two implementations of the discrete stages answer to one test suite.
"""
import pytest

from course import kernels

BACKENDS = ["numba", "torch"] if kernels.available() else ["torch"]


@pytest.fixture(params=BACKENDS)
def both_backends(request):
    with kernels.using(request.param):
        yield request.param
