import os

import pytest

import pbr


def pytest_addoption(parser):
    parser.addoption("--runslow", action="store_true", default=False, help="run slow tests")
    parser.addoption("--scale", type=int, default=1, help="multiply resolution/spp of Mitsuba comparisons")


def pytest_collection_modifyitems(config, items):
    if config.getoption("--runslow"):
        return
    skip = pytest.mark.skip(reason="slow: run with --runslow")
    for item in items:
        if "slow" in item.keywords:
            item.add_marker(skip)


@pytest.fixture(scope="session", autouse=True)
def _backend():
    pbr.set_backend(os.environ.get("PBR_TEST_BACKEND", "llvm"))


@pytest.fixture(scope="session")
def scale(request):
    return request.config.getoption("--scale")
