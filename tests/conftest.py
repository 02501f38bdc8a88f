"""Shared fixtures.

``both_backends``: a test module that marks itself with ``pytestmark = pytest.mark.usefixtures("both_backends")``
runs every test twice, once with the compiled kernels (``course.kernels``, Numba) and once on the torch path, so
the two implementations of the discrete stages answer to one test suite.

The ``browser`` marker (tests/test_browser.py: JupyterLab in Chromium) is registered here; those tests are
skipped unless asked for with ``-m browser`` or ``COURSE_BROWSER=1``.
"""
import pytest

from course import kernels

BACKENDS = ["numba", "torch"] if kernels.available() else ["torch"]


@pytest.fixture(params=BACKENDS)
def both_backends(request):
    with kernels.using(request.param):
        yield request.param


def pytest_configure(config):
    config.addinivalue_line("markers", "browser: JupyterLab in Chromium through Playwright (tests/test_browser.py); "
                                       "opt in with -m browser or COURSE_BROWSER=1")


def pytest_collection_modifyitems(config, items):
    """Browser tests run only when asked for: ``-m browser`` (or an -m expression naming it) or COURSE_BROWSER=1."""
    import os
    if "browser" in (config.getoption("-m") or "").replace("not browser", "") or os.environ.get("COURSE_BROWSER"):
        return
    skip = pytest.mark.skip(reason="a browser test: opt in with -m browser or COURSE_BROWSER=1")
    for item in items:
        if "browser" in item.keywords:
            item.add_marker(skip)


@pytest.fixture
def shown(monkeypatch):
    """What ``viz.explorer`` displays (tests/test_explorer.py, tests/test_explorers.py): a list of
    (object, kwargs) passed to IPython's display; the figures are closed afterwards."""
    import matplotlib.pyplot as plt
    calls = []
    monkeypatch.setattr("IPython.display.display", lambda obj, **kw: calls.append((obj, kw)))
    yield calls
    plt.close("all")
