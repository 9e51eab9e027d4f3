"""No recorded or coupled output lags its time label: after each macro step a component whose
outputs depend on its inputs reads them again with its inputs set to the sources' samples at the
macro step's end (kernel.h: resample), in every backend and coupling."""

import dataclasses
from fractions import Fraction
from pathlib import Path

import numpy as np
import pytest

import master.api as api
from master.backends.component import output_names
from master.evidence.oscillator import SET_A, scene
from master.fmubuild import fmu_path
from master.runtime.tables import resampling
from master.scenario.model import Component, Connection, Scenario

BACKENDS = ("serial", "parallel", "in-process")


@pytest.mark.parametrize("ratios", [(1, 1), (2, 3), (3, 1)])
def test_a_pure_gain_fed_by_another_component_records_k_times_its_input_at_every_row(ratios):
    source = dataclasses.replace(scene(split="force").components[0], step_ratio=ratios[0])  # mass1 alone
    gain = Component("gain", fmu_path("gain"), {"K": 3.0}, ratios[1], 2)
    link, record = Connection("mass1", "x", "gain", "u"), (("mass1", "x"), ("gain", "y"))
    span = (Fraction(0), Fraction(3), Fraction(1, 20))
    sc = Scenario(Path("gain.ssd"), "gain", (source, gain), (link,), *span, record=record)
    for backend in BACKENDS:
        d = api.run(sc, backend=backend).data
        assert np.array_equal(d["gain.y"], 3.0 * d["mass1.x"]), backend  # y(t) = K u(t), not K u(t - H)
        assert len(np.unique(d["gain.y"])) > 50


@pytest.mark.parametrize("coupling, first", [("jacobi", ()), ("gauss-seidel", ("mass1", "mass2")),
                                             ("gauss-seidel", ("mass2", "mass1"))])  # fmt: skip
@pytest.mark.parametrize("ratios", [(1, 1), (1, 4), (4, 1)])
def test_the_coupling_force_is_consistent_with_both_masses_at_every_row(coupling, first, ratios):
    sc = scene(split="force", macro_step=Fraction(1, 20), order=2, step_ratios=ratios, stop_time=Fraction(2),
               coupling=coupling)  # fmt: skip
    sc = dataclasses.replace(sc, order=first or sc.order, record=sc.record + (("mass2", "F_c"),))
    rows = {b: api.run(sc, backend=b).data for b in BACKENDS}
    for d in rows.values():
        assert all(np.array_equal(d[n], rows["serial"][n]) for n in d.dtype.names)  # the same bits
    d = rows["serial"]
    force = SET_A.cc * (d["mass2.x"] - d["mass1.x"]) + SET_A.dc * (d["mass2.v"] - d["mass1.v"])
    assert np.max(np.abs(d["mass2.F_c"] - force)) < 1e-15


def test_only_the_outputs_that_depend_on_inputs_are_read_again():
    force = api.plan(scene(split="force"))
    outs = {pc.name: output_names(force, pc.name, _variables(force, pc.name)) for pc in force.components}
    again, order = resampling(force, outs)
    assert again == {"mass2": ["F_c"]} and order == ["mass2"]  # not x, v: they depend on the state
    plain = api.plan(scene(split="displacement"))
    outs = {pc.name: output_names(plain, pc.name, _variables(plain, pc.name)) for pc in plain.components}
    assert resampling(plain, outs) == ({}, [])  # nothing depends on inputs: no extra FMI call


def _variables(plan, name):
    from master.fmu import read_description, variables_of

    return variables_of(read_description(plan.scenario.component(name).fmu_path))
