"""Test configuration: the backend every test runs on is ``PBR_TEST_BACKEND`` ("llvm" by
default, "cuda" for ``make test-cuda``, or "auto"). It is selected before the test
modules are imported (some build Mitsuba objects at import), and a backend that cannot
be used stops the run with an error instead of falling back to another one."""

import os

import pytest

import pbr  # first: it chooses the libLLVM that Dr.Jit loads
from pbr import backend
import mitsuba as mi  # noqa: E402


def pytest_addoption(parser):
    parser.addoption("--runslow", action="store_true", default=False, help="run slow tests")
    parser.addoption("--scale", type=int, default=1, help="multiply resolution/spp of Mitsuba comparisons")


def pytest_configure(config):
    name = os.environ.get("PBR_TEST_BACKEND", "llvm")
    try:
        chosen = pbr.set_backend(name)
    except pbr.BackendError as e:
        raise pytest.UsageError(f"PBR_TEST_BACKEND={name!r}: {e}") from None
    config.pbr_backend = chosen


def pytest_runtest_logreport(report):
    """With ``PBR_FAILURE_LOG`` set, every failure's report is appended to that file as it
    happens (by the process that ran the test): a run cut short by a time limit, as on a
    lent GPU machine (benchmarks/gpu_session.sh), still leaves its tracebacks. With
    ``PBR_DURATION_LOG`` set, every test's time is appended likewise."""
    path = os.environ.get("PBR_FAILURE_LOG")
    if path and report.failed and not hasattr(report, "node"):   # 'node': xdist's copy in the controller
        with open(path, "a") as f:
            f.write(f"===== {report.nodeid} ({report.when})\n{report.longreprtext}\n")
    # With PBR_DURATION_LOG set, each test's call time as it ends (a run cut short still
    # says which tests took its time).
    path = os.environ.get("PBR_DURATION_LOG")
    if path and report.when == "call" and not hasattr(report, "node"):
        with open(path, "a") as f:
            f.write(f"{report.duration:.2f} {report.outcome} {report.nodeid}\n")


def pytest_report_header(config):
    return f"pbr backend: {config.pbr_backend} (Mitsuba variant {backend.variant()}; PBR_TEST_BACKEND)"


def pytest_collection_modifyitems(config, items):
    if config.getoption("--runslow"):
        return
    skip = pytest.mark.skip(reason="slow: run with --runslow")
    for item in items:
        if "slow" in item.keywords:
            item.add_marker(skip)


@pytest.fixture(autouse=True)
def _backend_stays(request):
    """Every test runs on the chosen backend and must leave Mitsuba's variant on it: a test
    that switches variants (e.g. a hard-coded ``mi.set_variant``) fails here."""
    chosen = request.config.pbr_backend

    def check(when):
        now = (pbr.get_backend(), mi.variant())
        if now != (chosen, f"{chosen}_ad_spectral"):
            pbr.set_backend(chosen)
            pytest.fail(f"{when}, pbr's backend and Mitsuba's variant are {now}, not {chosen!r} "
                        f"({chosen}_ad_spectral): something switched them")
    check("before the test (at import or in a fixture)")
    yield
    check("after the test")


@pytest.fixture(scope="session")
def scale(request):
    return request.config.getoption("--scale")
