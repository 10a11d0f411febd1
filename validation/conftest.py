"""Options of the validation suite.

--allow-missing   skip (instead of fail) tests whose reference code is absent;
                  for local use only — CI runs without it, so a missing code fails
--paper-scale     also run the paper-scale cases (about 200,000 particles; hours)
"""

import pytest

from . import references


def pytest_addoption(parser):
    parser.addoption("--allow-missing", action="store_true",
                     help="skip tests whose reference code (REBOUND, LAMMPS, LIGGGHTS) is missing")
    parser.addoption("--paper-scale", action="store_true",
                     help="run the paper-scale validation cases (slow)")


def pytest_configure(config):
    config.addinivalue_line("markers", "paper_scale: needs --paper-scale")


def pytest_collection_modifyitems(config, items):
    if config.getoption("--paper-scale"):
        return
    skip = pytest.mark.skip(reason="paper-scale case: run with --paper-scale")
    for item in items:
        if "paper_scale" in item.keywords:
            item.add_marker(skip)


def _need(request, loader):
    try:
        return loader()
    except references.MissingReference as exc:
        if request.config.getoption("--allow-missing"):
            pytest.skip(str(exc))
        pytest.fail(f"reference code missing: {exc}", pytrace=False)


@pytest.fixture(scope="session")
def rebound(request):
    return _need(request, references.rebound)


@pytest.fixture(scope="session")
def lammps(request):
    return _need(request, references.lammps_module)


@pytest.fixture(scope="session")
def liggghts(request):
    return _need(request, references.liggghts_binary)


@pytest.fixture(scope="session")
def chromium(request):
    """The headless browser for the report's screenshot."""
    return _need(request, references.chromium_binary)


@pytest.fixture(scope="session")
def lammps_lmp(request):
    """The lmp executable (the DEM harness runs LAMMPS as a subprocess)."""
    return _need(request, references.lammps_binary)


@pytest.fixture(scope="session")
def dem_code(request):
    """Check that the DEM code named by the test's ``code`` parameter is installed."""
    def need(code):
        loader = references.lammps_binary if code == "lammps" else references.liggghts_binary
        return _need(request, loader)
    return need
