"""The manipulator FMU (fmus/manipulator): closed-loop six-body arm by coordinate partitioning.

Checked through fmpy against mathematics and an independent formulation
(tests/reference_mechanism.py, absolute coordinates with Lagrange multipliers): loop
closure and M_bar along trajectories, accelerations for random states and inputs, energy
conservation, convergence orders of the solvers, clean failure at a singular pose.
"""

from __future__ import annotations

import ctypes
import math
import sys
from pathlib import Path

import numpy as np
import pytest
from fmpy import extract, read_model_description, simulate_fmu
from fmpy.fmi1 import FMICallException
from fmpy.fmi2 import (
    FMU2Model,
    fmi2CallbackAllocateMemoryTYPE,
    fmi2CallbackFreeMemoryTYPE,
    fmi2CallbackFunctions,
    fmi2CallbackLoggerTYPE,
)

from master import fmubuild

from fmpy import calloc, free  # isort: skip

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT / "models" / "mechanism"))
sys.path.insert(0, str(Path(__file__).resolve().parent))
import parameters  # noqa: E402  (models/mechanism/parameters.py)
from reference_mechanism import Mechanism  # noqa: E402

AB2, AB3, RK4 = 2, 3, 4
TABLES = {"table2": parameters.table2, "table3": parameters.table3}
MBAR = [f"mbar_{i}{j}" for i in (1, 2, 3) for j in (1, 2, 3)]


@pytest.fixture(scope="module")
def fmu(tmp_path_factory: pytest.TempPathFactory) -> dict:
    """The built FMU, its description, extraction folder and value references."""
    path = fmubuild.fmu_path("manipulator")
    md = read_model_description(str(path))
    unzip = extract(str(path), unzipdir=str(tmp_path_factory.mktemp("manipulator")))
    return {"path": path, "md": md, "dir": unzip, "vr": {v.name: v.valueReference for v in md.modelVariables}}


class ME:
    """A Model Exchange instance that records its log messages."""

    def __init__(self, fmu: dict, params: dict[str, float] | None = None) -> None:
        self.vr = fmu["vr"]
        self.messages: list[str] = []
        self.callbacks = fmi2CallbackFunctions()
        self.callbacks.logger = fmi2CallbackLoggerTYPE(self._log)
        self.callbacks.allocateMemory = fmi2CallbackAllocateMemoryTYPE(calloc)
        self.callbacks.freeMemory = fmi2CallbackFreeMemoryTYPE(free)
        self.m = FMU2Model(
            guid=fmu["md"].guid, unzipDirectory=fmu["dir"], modelIdentifier="manipulator", instanceName="arm"
        )
        self.m.instantiate(callbacks=self.callbacks, loggingOn=True)
        self.m.setupExperiment(startTime=0.0)
        self.m.enterInitializationMode()
        if params:
            self.set_parameters(params)

    def _log(self, env, instance_name, status, category, message) -> None:  # noqa: ANN001
        self.messages.append(message.decode())

    def set_parameters(self, params: dict[str, float]) -> None:
        for name, value in params.items():
            if name == "actuation" or name.endswith(("_body_a", "_body_b")):
                self.m.setInteger([self.vr[name]], [int(value)])
            else:
                self.m.setReal([self.vr[name]], [float(value)])

    def start(self) -> ME:
        self.m.exitInitializationMode()
        self.m.enterContinuousTimeMode()
        return self

    def set(self, **values: float) -> None:
        for name, value in values.items():
            self.m.setReal([self.vr[name]], [float(value)])

    def get(self, *names: str) -> np.ndarray:
        return np.array(self.m.getReal([self.vr[n] for n in names]))

    def derivatives(self, v: np.ndarray, vd: np.ndarray) -> np.ndarray:
        """Set the states (v, v') and return der(v), der(v')."""
        x = (ctypes.c_double * 6)(*np.concatenate([v, vd]))
        self.m.setContinuousStates(x, 6)
        dx = (ctypes.c_double * 6)()
        self.m.getDerivatives(dx, 6)
        return np.array(dx[:])

    def free(self) -> None:
        self.m.freeInstance()


def simulate(
    fmu: dict, params: dict[str, float], solver: int, h: float, stop: float, output: list[str]
) -> np.ndarray:
    """Co-simulation run with communication step = internal step h (s)."""
    start = {**params, "solver": solver, "internal_step": h}
    return simulate_fmu(
        str(fmu["path"]),
        stop_time=stop,
        output_interval=h,
        start_values=start,
        output=output,
        fmi_type="CoSimulation",
    )


# ---------------------------------------------------------------- along trajectories


@pytest.mark.parametrize("table", ["table2", "table3"])
def test_loop_closure_and_mbar_along_a_trajectory(fmu: dict, table: str) -> None:
    """The arm falls under gravity (no efforts) for 1.5 s with the paper's AB3 at 1 ms:
    the loop residual stays below 1e-9 and M_bar stays symmetric positive definite."""
    params = TABLES[table]()
    params.update({"qd1_0": 0.5, "qd2_0": -0.3})
    out = ["constraint_residual", "mbar_min_eigenvalue", "q3", "q5", *MBAR]
    r = simulate(fmu, params, AB3, 1e-3, 1.5, out)
    assert np.ptp(r["q3"]) > 0.3  # the elbow really moves
    assert np.all(r["constraint_residual"] < 1e-9)
    mb = np.stack([r[n] for n in MBAR], axis=1).reshape(-1, 3, 3)
    scale = np.abs(mb).max(axis=(1, 2))
    assert np.all(np.abs(mb - mb.transpose(0, 2, 1)).max(axis=(1, 2)) <= 1e-12 * scale)
    assert np.all(r["mbar_min_eigenvalue"] > 0)
    assert np.allclose(
        r["mbar_min_eigenvalue"], np.linalg.eigvalsh(mb)[:, 0], rtol=1e-9, atol=1e-12 * scale.max()
    )


# ---------------------------------------------------------------- against the independent formulation


@pytest.mark.parametrize("table", ["table2", "table3"])
@pytest.mark.parametrize("actuation", [0, 1])
def test_accelerations_match_the_absolute_coordinate_formulation(
    fmu: dict, table: str, actuation: int
) -> None:
    """Random states, efforts, disturbances and damping: v'' of the FMU (ME getDerivatives)
    equals the Newton-Euler + Lagrange-multiplier solution to 1e-8 relative; so do the
    dependent coordinates and rates, body 6's motion, the strokes, the energy and M_bar."""
    rng = np.random.default_rng(20 + actuation + 10 * (table == "table2"))
    params = TABLES[table]()
    params.update({"actuation": actuation})
    params.update({f"damping{k}": float(rng.uniform(0, 5)) for k in (1, 2, 3)})
    mech = Mechanism(params)
    me = ME(fmu, params).start()
    scale = 1.0 if table == "table3" else 1e3  # Table 2 bodies are ~100 times heavier
    try:
        v_prev = np.array([params["q1_0"], params["q2_0"], params["q3_0"]])
        for _ in range(8):
            v = v_prev + rng.uniform(-0.4, 0.4, 3)
            vd = rng.uniform(-1.5, 1.5, 3)
            effort = rng.uniform(-20, 20, 3) * scale * (50 if actuation else 1)
            dist = rng.uniform(-5, 5, 3) * scale
            me.set(**{f"effort{k + 1}": effort[k] for k in range(3)})
            me.set(**{f"disturbance{k + 1}": dist[k] for k in range(3)})
            dx = me.derivatives(v, vd)
            qdd, a6 = mech.accelerations(
                v, vd, effort, dist, actuation, [params[f"damping{k}"] for k in (1, 2, 3)]
            )
            assert np.array_equal(dx[:3], vd)
            assert np.abs(dx[3:] - qdd).max() <= 1e-8 * np.abs(qdd).max()
            q = mech.full_q(v)
            qd = mech.full_qd(q, vd)
            names = [f"q{k}" for k in range(1, 7)] + [f"qd{k}" for k in range(1, 7)]
            assert np.allclose(me.get(*names), np.concatenate([q, qd]), rtol=0, atol=1e-9)
            got_a6 = me.get("body6_ax", "body6_ay", "body6_az")
            assert np.abs(got_a6 - a6).max() <= 1e-8 * max(np.abs(a6).max(), 1.0)
            energy = mech.energy(v, vd)
            assert abs(me.get("energy")[0] - energy) <= 1e-10 * abs(energy)
            mbar = me.get(*MBAR).reshape(3, 3)
            ref_mbar = mech.reduced_mass_matrix(v)
            assert np.abs(mbar - ref_mbar).max() <= 1e-8 * np.abs(ref_mbar).max()
            strokes = me.get("stroke1", "stroke2", "stroke3", "stroke_rate1", "stroke_rate2", "stroke_rate3")
            if actuation == 0:
                expect = np.concatenate([v, vd])
            else:
                lengths = [mech.cylinder_length(q, k) - mech.length0[k] for k in range(3)]
                expect = np.array(lengths + [mech.cylinder_rate(q, qd, k) for k in range(3)])
            assert np.allclose(strokes, expect, rtol=0, atol=1e-9)
            v_prev = v
    finally:
        me.free()


# ---------------------------------------------------------------- energy, orders


@pytest.mark.parametrize("table", ["table2", "table3"])
def test_energy_is_conserved_without_actuation_or_damping(fmu: dict, table: str) -> None:
    """No efforts, no damping: RK4 at 1 ms keeps kinetic + potential energy to 1e-6 over 3 s."""
    params = TABLES[table]()
    params.update({"qd1_0": 1.0, "qd2_0": -0.5, "qd3_0": 0.8, "actuation": 0})
    r = simulate(fmu, params, RK4, 1e-3, 3.0, ["energy", "q2", "q3"])
    e = r["energy"]
    drift = np.abs(e - e[0]).max() / abs(e[0])
    assert drift < 1e-6, drift
    assert np.ptp(r["q3"]) > 0.5


@pytest.mark.parametrize(("solver", "order"), [(AB2, 2), (AB3, 3), (RK4, 4)])
def test_solvers_converge_at_their_order(fmu: dict, solver: int, order: int) -> None:
    """Falling Table 3 arm over 0.5 s: the max error of q2, q3 on a 20 ms grid, against RK4
    at 0.125 ms, falls by 2^order when the step halves (observed order within 0.35)."""
    params = parameters.table3()
    params.update({"qd1_0": 1.0})

    def run(s: int, h: float) -> np.ndarray:
        start = {**params, "solver": s, "internal_step": h}
        r = simulate_fmu(
            str(fmu["path"]), stop_time=0.5, output_interval=0.02, start_values=start, output=["q2", "q3"]
        )
        return np.stack([r["q2"], r["q3"]])

    ref = run(RK4, 1.25e-4)
    steps = (4e-3, 2e-3) if solver != RK4 else (1e-2, 5e-3)
    errors = [np.abs(run(solver, h) - ref).max() for h in steps]
    observed = math.log2(errors[0] / errors[1])
    assert abs(observed - order) < 0.35, (errors, observed)


# ---------------------------------------------------------------- Table 2 hydraulics design


def test_table2_hydromechanical_frequencies_are_resolved_by_ab3_at_1ms(fmu: dict) -> None:
    """Linearised cylinders as springs k = beta A^2 (1/V1 + 1/V2) (Table 2) on M_bar: all three
    coupled frequencies satisfy omega h <= 0.25 at h = 1e-3 s (AB3 stays stable to 0.72)."""
    params = parameters.table2()
    me = ME(fmu, params).start()
    try:
        v = np.array([params["q1_0"], params["q2_0"], params["q3_0"]])
        G = np.zeros((3, 3))  # d stroke_i / d v_j
        for j in range(3):
            me.derivatives(v, np.eye(3)[j])
            G[:, j] = me.get("stroke_rate1", "stroke_rate2", "stroke_rate3")
        mbar = me.get(*MBAR).reshape(3, 3)
    finally:
        me.free()
    beta, area, volume = 1.03e9, np.array([1.94e-2, 1.55e-2, 1.55e-2]), np.array([1.23e-2, 3.28e-3, 3.28e-3])
    k = beta * area**2 * 2 / volume
    omega = np.sqrt(np.linalg.eigvals(np.linalg.solve(mbar, G.T @ np.diag(k) @ G)).real)
    assert omega.max() * 1e-3 <= 0.25, omega
    assert omega.min() > 50  # stiff enough to matter: the paper's reason for the small step


# ---------------------------------------------------------------- failures


@pytest.mark.parametrize("offset", [0.0, 1e-10])
def test_singular_pose_fails_cleanly(fmu: dict, offset: float) -> None:
    """Pin A placed where the strut hinge B passes at q3 = 250 deg: there the strut length
    q5 -> 0 and Phi_u is singular.  getDerivatives returns fmi2Error with a logged reason,
    never NaN; walking there with shrinking gaps, 1e-3 rad away evaluations still succeed."""
    params = parameters.table3()
    q3s = 250 * math.pi / 180
    c, s = math.cos(q3s), math.sin(q3s)
    j4 = (params["j4_y"], params["j4_z"])
    params["a3_y"] = params["j3_y"] + c * j4[0] - s * j4[1]
    params["a3_z"] = params["j3_z"] + s * j4[0] + c * j4[1]
    me = ME(fmu, params).start()
    try:
        v = np.array([0.0, params["q2_0"], 0.0])
        for gap in np.geomspace(params["q3_0"] - q3s, 1e-3, 40):  # walk there: Newton warm starts
            v[2] = q3s + gap
            dx = me.derivatives(v, np.zeros(3))
            assert np.all(np.isfinite(dx))
        assert me.get("q5")[0] < 0.01
        v[2] = q3s + offset
        with pytest.raises(FMICallException):
            me.derivatives(v, np.zeros(3))
        assert any("loop closure failed" in m and "singular" in m for m in me.messages), me.messages
    finally:
        me.free()


@pytest.mark.parametrize(
    ("change", "words"),
    [
        ({"m3": 0.0}, ["m3", "positive"]),
        ({"Izz6": 200.0}, ["body 6", "Izz6"]),
        ({"cyl2_by": 0.4, "cyl2_bz": 0.6, "actuation": 1}, ["cylinder 2", "coincide"]),
    ],
)
def test_bad_parameters_are_named(fmu: dict, change: dict, words: list[str]) -> None:
    """Initialization rejects impossible body data and cylinders with a message naming them."""
    params = parameters.table2()
    params.update(change)
    me = ME(fmu)
    try:
        me.set_parameters(params)
        with pytest.raises(FMICallException):
            me.m.exitInitializationMode()
        text = "\n".join(me.messages)
        assert all(w in text for w in words), text
    finally:
        me.free()


def test_fmu_defaults_are_table3(fmu: dict) -> None:
    """The start values in the C table are exactly models/mechanism's table3() set."""
    starts = {v.name: v.start for v in fmu["md"].modelVariables}
    for name, value in parameters.table3().items():
        assert float(starts[name]) == pytest.approx(value, rel=1e-15, abs=1e-15), name
