"""Reference of a scene without Model Exchange: a converged co-simulation, with its convergence."""

import logging
from fractions import Fraction
from pathlib import Path

import numpy as np
import pytest
from test_run import LAG, build_pythonfmu  # a Co-Simulation-only FMU source for pythonfmu

from master.evidence.reference import NotConverged, converged_cosimulation, has_model_exchange, reference
from master.scenario.model import Component, Scenario


@pytest.fixture(scope="module")
def lag_fmu(tmp_path_factory) -> Path:
    return build_pythonfmu("Lag", LAG, tmp_path_factory.mktemp("lag"))


def decay(fmu: Path) -> Scenario:
    """y' = -2 y, y(0) = 1, by the FMU's explicit Euler over each communication step."""
    return Scenario(Path("decay.ssd"), "decay", (Component("lag", fmu, {"a": 2.0}),), (), Fraction(0),
                    Fraction(1), Fraction(1, 10), record=(("lag", "y"),))  # fmt: skip


def test_without_model_exchange_the_reference_is_a_converged_cosimulation(lag_fmu, caplog):
    sc = decay(lag_fmu)
    assert not has_model_exchange(sc)
    with caplog.at_level(logging.INFO, logger="master"):
        ref = reference(sc, cache_dir=None, cosim_tol=1e-3)
    exact = np.exp(-2.0 * ref.time)
    assert ref.time[-1] == 1.0 and len(ref.time) == 11  # on the scene's record grid
    # Euler is first order: the last change estimates the error of the finest run
    assert np.max(np.abs(ref.values["lag.y"] - exact)) < 2e-3 * (1 - np.exp(-2.0))
    assert "observed order" in caplog.text


def test_convergence_table_shows_first_order_and_refuses_too_few_halvings(lag_fmu):
    traj, conv = converged_cosimulation(decay(lag_fmu), tol=1e-3)
    assert conv.changes[-1] <= 1e-3 < conv.changes[-2]
    assert abs(conv.observed_order() - 1.0) < 0.2
    assert all(b == a / 2 for a, b in zip(conv.macro_steps[:-1], conv.macro_steps[1:], strict=True))
    with pytest.raises(NotConverged, match="did not converge"):
        converged_cosimulation(decay(lag_fmu), tol=1e-9, max_halvings=2)
