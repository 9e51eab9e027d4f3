"""Model Exchange reference solutions against exact solutions, and their cache."""

from fractions import Fraction

import numpy as np
import pytest

import master.evidence.reference as reference_module
from master.evidence.reference import integrate, reference
from master.fmubuild import fmu_path
from master.scenario.model import Component, Scenario


def _dahlquist(tmp_path, lam: float) -> Scenario:
    ssd = tmp_path / "d.ssd"
    ssd.write_text("<stand-in scenario file: its bytes are part of the cache key/>")
    comp = Component("d", fmu_path("dahlquist"), {"lambda": lam, "y0": 3.0})
    return Scenario(ssd, "d", (comp,), (), Fraction(0), Fraction(2), Fraction(1, 10))


def test_dahlquist_reference_matches_exponential(tmp_path):
    tr = integrate(_dahlquist(tmp_path, -2.0))
    exact = 3.0 * np.exp(-2.0 * tr.time)
    assert len(tr.time) == 21
    assert np.max(np.abs(tr.values["d.y"] - exact)) < 1e-9


def test_stiff_dahlquist_reference_is_cheap_and_exact(tmp_path):
    tr = integrate(_dahlquist(tmp_path, -1e4))  # Radau: no step limit from stiffness
    assert np.max(np.abs(tr.values["d.y"][1:])) < 1e-12


def test_cache_hit_and_key(tmp_path, monkeypatch):
    sc = _dahlquist(tmp_path, -1.0)
    cache = tmp_path / "cache"
    a = reference(sc, cache_dir=cache)
    assert len(list(cache.glob("*.npz"))) == 1

    def no_integration(*args, **kwargs):
        raise AssertionError("integrated again instead of reading the cache")

    monkeypatch.setattr(reference_module, "integrate", no_integration)
    b = reference(sc, cache_dir=cache)  # from the file
    assert np.array_equal(a.values["d.y"], b.values["d.y"])
    monkeypatch.undo()  # another parameter must integrate again: a new entry
    other = _dahlquist(tmp_path, -2.0)
    reference(other, cache_dir=cache)
    assert len(list(cache.glob("*.npz"))) == 2


def test_unknown_parameter_is_named(tmp_path):
    sc = _dahlquist(tmp_path, -1.0)
    comp = Component("d", fmu_path("dahlquist"), {"lambada": 1.0})
    with pytest.raises(ValueError, match="component 'd' has no variable 'lambada'"):
        integrate(Scenario(sc.path, "d", (comp,), (), Fraction(0), Fraction(1), Fraction(1, 10)))


@pytest.mark.parametrize("split", ["displacement", "force"])
def test_oscillator_reference_matches_the_matrix_exponential(split, tmp_path):
    """The two-mass oscillator (two msd FMUs) through Model Exchange against expm(A t) z0, and
    x1(10) against the benchmark's published value."""
    from master.evidence.oscillator import SET_A, SET_A_X1_10, SET_A_Z0, scene

    tr = integrate(scene(split=split, macro_step=Fraction(1, 10), path=tmp_path / "osc.ssd"))
    exact = SET_A.exact(tr.time, SET_A_Z0)
    for col, name in ((0, "mass1.x"), (1, "mass1.v")):
        assert np.max(np.abs(tr.values[name] - exact[:, col])) < 1e-9, name
    assert tr.values["mass1.x"][-1] == pytest.approx(SET_A_X1_10, abs=1e-10)
