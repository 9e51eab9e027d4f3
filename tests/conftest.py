"""Set-up of a run of several test files: the compiled parts they all share are built first, in
parallel (one compiler per core) rather than one after another by the first test that needs each."""

from __future__ import annotations

import os
from concurrent.futures import ThreadPoolExecutor

import pytest

from master import fmubuild
from master.runtime import native


def _build(name: str) -> None:
    # a model that does not build is left to the tests that use it, which say why
    try:
        fmubuild.fmu_path(name)
    except fmubuild.FmuBuildError:
        pass


def _kernel() -> None:
    try:
        native.library()
    except native.KernelBuildError:
        pass


@pytest.fixture(scope="session", autouse=True)
def _shared_builds(request: pytest.FixtureRequest) -> None:
    """The kernel and every project FMU (FMI 2.0), built where missing or stale (fmu_path): the
    suite uses them all. A single test file builds what it needs as it goes."""
    if len({item.path for item in request.session.items}) < 2:
        return
    with ThreadPoolExecutor(os.cpu_count() or 1) as pool:
        done = [pool.submit(_kernel)] + [pool.submit(_build, n) for n in fmubuild.project_fmu_names()]
        for future in done:
            future.result()
