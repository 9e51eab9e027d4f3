"""The hydraulic servo FMU (fmus/hydraulics): Jacobian, orifice equilibrium, oil balance, stiff stability.

Every test runs the real FMU built from C through fmpy (Model Exchange or Co-Simulation).
Units: pressures Pa, volumes m^3, flows m^3/s, spool and stroke m, time s.
"""

from __future__ import annotations

import ctypes
import math
import shutil

import numpy as np
import pytest
from fmpy import extract, read_model_description
from fmpy.fmi1 import FMICallException
from fmpy.fmi2 import FMU2Model, FMU2Slave
from scipy.integrate import solve_ivp

from master.fmubuild import fmu_path
from master.scenario.ssv import read_ssv

EULER, SI_EULER, SI_MIDPOINT = 1, 5, 6
PS, BETA = 1.38e7, 1.03e9  # Table 2 supply pressure and bulk modulus (Pa)
AREA = (1.94e-2, 1.55e-2, 1.55e-2)  # m^2
V0 = (1.23e-2, 3.28e-3, 3.28e-3)  # m^3, both chambers
KV = tuple(k * math.sqrt(1e-3) for k in (1.49e-3, 7.45e-4, 7.45e-4))  # SI flow coefficients
_P = ctypes.POINTER(ctypes.c_double)


@pytest.fixture(scope="module")
def fmu():
    """Path and variable table of the built FMU."""
    path = fmu_path("hydraulics")
    md = read_model_description(str(path))
    return path, md, {v.name: v.valueReference for v in md.modelVariables}


class Instance:
    """One FMU instance (Model Exchange or Co-Simulation) with parameters set by name."""

    def __init__(self, fmu, kind: str, params: dict[str, float], solver: int | None = None) -> None:
        path, md, self.vr = fmu
        self.dir = extract(str(path))
        cls, iface = (FMU2Model, md.modelExchange) if kind == "me" else (FMU2Slave, md.coSimulation)
        self.f = cls(
            guid=md.guid, unzipDirectory=self.dir, modelIdentifier=iface.modelIdentifier, instanceName="h"
        )
        self.f.instantiate()
        self.f.setupExperiment(startTime=0.0)
        if solver is not None:
            self.f.setInteger([self.vr["solver"]], [solver])
        self.set(params)
        self.f.enterInitializationMode()
        self.f.exitInitializationMode()
        self.me = kind == "me"
        if self.me:
            while self.f.newDiscreteStates()[0]:
                pass
            self.f.enterContinuousTimeMode()
        self.n = md.numberOfContinuousStates
        self.states = [self.vr[f"p_{side}{k}"] for k in (1, 2, 3) for side in ("left", "right")]

    def set(self, values: dict[str, float]) -> None:
        if values:
            self.f.setReal([self.vr[k] for k in values], [float(v) for v in values.values()])

    def get(self, names: list[str]) -> np.ndarray:
        return np.array(self.f.getReal([self.vr[k] for k in names]))

    def rhs(self, x: np.ndarray) -> np.ndarray:
        """Model Exchange: derivatives at states x (inputs as set)."""
        xs = np.ascontiguousarray(x, dtype=float)
        self.f.setContinuousStates(xs.ctypes.data_as(_P), self.n)
        dx = np.zeros(self.n)
        self.f.getDerivatives(dx.ctypes.data_as(_P), self.n)
        return dx

    def close(self) -> None:
        self.f.terminate()
        self.f.freeInstance()
        shutil.rmtree(self.dir, ignore_errors=True)


def pressures(inst: Instance) -> np.ndarray:
    return np.array(inst.f.getReal(inst.states))


def start_pressures(values: list[float]) -> dict[str, float]:
    names = [f"p_{side}{k}" for k in (1, 2, 3) for side in ("left", "right")]
    return dict(zip(names, values, strict=True))


MOVING = {
    "spool1": 1.0e-3, "spool2": -0.7e-3, "spool3": 0.4e-3,
    "stroke1": 0.05, "stroke2": -0.02, "stroke3": 0.01,
    "stroke_rate1": 0.01, "stroke_rate2": -0.02, "stroke_rate3": 0.005,
}  # fmt: skip


@pytest.mark.parametrize(
    "x",
    [
        [8.0e6, 5.0e6, 3.0e6, 9.0e6, 7.0e6, 6.5e6],  # interior: square-root law
        [PS - 3e4, 2e4, 4e4, PS - 5e4, PS - 1e3, 7e3],  # drops below dp_lin: regularised law
    ],
)
def test_analytic_jacobian_equals_finite_differences(fmu, x):
    """fmi2GetDirectionalDerivative (the model's analytic Jacobian) vs central differences of f."""
    inst = Instance(fmu, "me", {"leakage": 2e-12, **MOVING})
    try:
        x = np.array(x)
        inst.rhs(x)
        ders = [inst.vr[f"der(p_{side}{k})"] for k in (1, 2, 3) for side in ("left", "right")]
        analytic = np.column_stack(
            [inst.f.getDirectionalDerivative(ders, [inst.states[j]], [1.0]) for j in range(6)]
        )
        numeric = np.zeros((6, 6))
        for j in range(6):
            d = 1.0  # Pa: far below every pressure scale, far above rounding of f
            e = np.zeros(6)
            e[j] = d
            numeric[:, j] = (inst.rhs(x + e) - inst.rhs(x - e)) / (2 * d)
        scale = np.abs(analytic).max()
        assert scale > 1.0
        np.testing.assert_allclose(analytic, numeric, rtol=1e-6, atol=1e-7 * scale)
        # block diagonal: actuators do not talk to each other
        mask = np.kron(np.eye(3), np.ones((2, 2))) == 0
        assert np.all(analytic[mask] == 0)
    finally:
        inst.close()


def run_cs(fmu, params: dict[str, float], solver: int, h: float, t_end: float, every: int = 1) -> np.ndarray:
    """Co-simulation with communication step h * every and internal step h; pressures after each."""
    inst = Instance(fmu, "cs", {"internal_step": h, **params}, solver=solver)
    try:
        out = [pressures(inst)]
        n = round(t_end / (h * every))
        for k in range(n):
            inst.f.doStep(k * h * every, h * every)
            out.append(pressures(inst))
        return np.array(out)
    finally:
        inst.close()


def test_pressures_settle_at_the_orifice_equilibrium(fmu):
    """Pistons held, valves open, leakage C across the piston: flows balance where the law says.

    Valve in, leakage across, valve out: Kv x sqrt(ps - p1) = C (p1 - p2) = Kv x sqrt(p2 - pt).
    Hence ps - p1 = p2 - pt, and u = sqrt(ps - p1) solves 2 C u^2 + Kv x u - C (ps - pt) = 0.
    A negative spool mirrors it: p1 and p2 swap roles.  dp_lin = 100 Pa keeps the
    regularisation's shift of the flows (relative (dp_lin/dp)^2/4) below 1e-9.
    """
    c, pt = 1.6e-11, 2.0e5
    spool = (1.2e-3, -0.9e-3, 0.6e-3)
    params = {"leakage": c, "p_tank": pt, "dp_lin": 100.0}
    params |= {f"spool{k + 1}": s for k, s in enumerate(spool)}
    p = run_cs(fmu, params, SI_EULER, h=0.01, t_end=30.0, every=500)
    for k in range(3):
        kx = KV[k] * abs(spool[k])
        u = (-kx + math.sqrt(kx**2 + 8 * c**2 * (PS - pt))) / (4 * c)
        high, low = PS - u * u, pt + u * u
        expected = (high, low) if spool[k] > 0 else (low, high)
        np.testing.assert_allclose(p[-1, 2 * k : 2 * k + 2], expected, rtol=1e-8)
        # settled: the last two samples (5 s apart) agree
        np.testing.assert_allclose(p[-1, 2 * k : 2 * k + 2], p[-2, 2 * k : 2 * k + 2], rtol=1e-9)


def test_open_valve_without_leakage_drives_chambers_to_supply_and_tank(fmu):
    """No leakage, pistons held: the orifices fill one chamber to supply and drain the other to tank,
    and the pressures never leave [tank, supply] by more than the regularised law allows."""
    spool = {"spool1": 1.2e-3, "spool2": -0.9e-3, "spool3": 1.2e-3}
    p = run_cs(fmu, spool, EULER, h=2e-4, t_end=2.0, every=50)
    final = p[-1]
    np.testing.assert_allclose(final[[0, 3, 4]], PS, rtol=1e-4)
    np.testing.assert_allclose(final[[1, 2, 5]], 0.0, atol=1e-4 * PS)
    assert p.max() <= PS * (1 + 1e-6) and p.min() >= -1e-6 * PS


def test_oil_mass_balance_with_moving_pistons(fmu):
    """Integrated flows equal the change of oil in each chamber while the pistons move.

    With rho = rho0 exp(p / beta) the oil mass in a chamber is rho0 V exp(p / beta) and
    d/dt [V exp(p/beta)] = exp(p/beta) Q (while no pressure sits at a clamp).  The FMU's Model
    Exchange equations, integrated tightly with the strokes s(t) = v t fed in exactly, must
    satisfy this to the tolerance.
    """
    rates = (4e-3, -1.5e-3, 2e-3)  # m/s, slow enough that no chamber reaches supply or tank
    params = {"spool1": 0.8e-3, "spool2": -0.5e-3, "spool3": 0.3e-3, "leakage": 5e-12}
    inst = Instance(fmu, "me", params)
    flows = [inst.vr[f"flow_{side}{k}"] for k in (1, 2, 3) for side in ("left", "right")]
    try:

        def volumes(t: float) -> np.ndarray:
            return np.array([V0[k] + sgn * AREA[k] * rates[k] * t for k in range(3) for sgn in (1, -1)])

        def f(t: float, y: np.ndarray) -> np.ndarray:
            inst.set({f"stroke{k + 1}": rates[k] * t for k in range(3)})
            inst.set({f"stroke_rate{k + 1}": rates[k] for k in range(3)})
            dp = inst.rhs(y[:6])
            q = np.array(inst.f.getReal(flows))
            return np.concatenate([dp, np.exp(y[:6] / BETA) * q])

        y0 = np.concatenate([pressures(inst), np.zeros(6)])
        t_end = 1.0
        sol = solve_ivp(f, (0, t_end), y0, method="Radau", rtol=1e-11, atol=1e-3)
        assert sol.success
        p0, p1, inflow = y0[:6], sol.y[:6, -1], sol.y[6:, -1]
        stored = volumes(t_end) * np.exp(p1 / BETA) - volumes(0) * np.exp(p0 / BETA)
        assert np.all(np.abs(p1 - p0) > 1e4)  # the test moves real oil
        assert 0 < sol.y[:6].min() and sol.y[:6].max() < PS  # the clamp (relief) never acts
        np.testing.assert_allclose(stored, inflow, rtol=1e-7, atol=1e-9 * np.abs(inflow).max())
    finally:
        inst.close()


# Leakage alone (valves closed, pistons held) is linear: each actuator's pressure difference
# decays at lambda = -beta C (1/V_left + 1/V_right) and V_left p_left + V_right p_right is kept.
C_STIFF = 1e-9  # m^3/(s Pa)
LAM = [-BETA * C_STIFF * 2 / v for v in V0]  # 1/s: -167.5, -628 (twice)
START = [8.14e6, 5.66e6, 8.0e6, 6.0e6, 7.5e6, 6.5e6]


def leak_run(fmu, solver: int, h: float, steps: int) -> np.ndarray:
    return run_cs(fmu, {"leakage": C_STIFF, **start_pressures(START)}, solver, h, h * steps)


def test_leakage_eigenvalues_from_the_analytic_jacobian(fmu):
    inst = Instance(fmu, "me", {"leakage": C_STIFF})
    try:
        ders = [inst.vr[f"der(p_{side}{k})"] for k in (1, 2, 3) for side in ("left", "right")]
        jac = np.column_stack(
            [inst.f.getDirectionalDerivative(ders, [inst.states[j]], [1.0]) for j in range(6)]
        )
        eig = np.sort(np.linalg.eigvals(jac).real)
        np.testing.assert_allclose(eig, np.sort(LAM + [0.0] * 3), rtol=1e-12, atol=1e-9)
    finally:
        inst.close()


def test_euler_limit_and_semi_implicit_far_beyond_it(fmu):
    """Euler is stable below h = 2/|lambda| and grows above it; the semi-implicit methods stay
    bounded at 100 times that step, semi-implicit Euler landing on the exact equilibrium."""
    h_euler = 2 / abs(LAM[1])  # 3.18e-3 s, actuators 2 and 3
    dev0 = np.array([START[2 * k] - START[2 * k + 1] for k in range(3)])

    def dev(p):
        return p[:, 0::2] - p[:, 1::2]

    below = dev(leak_run(fmu, EULER, 0.95 * h_euler, 200))
    assert np.all(np.abs(below[-1]) < 1e-3 * np.abs(dev0))
    above = dev(leak_run(fmu, EULER, 1.05 * h_euler, 20))  # |1 + h lambda| = 1.1 per step
    assert np.all(np.abs(above[-1, 1:]) > 5 * np.abs(dev0[1:]))

    big = 100 * h_euler
    mean = [(START[2 * k] + START[2 * k + 1]) / 2 for k in range(3)]  # equal volumes
    si = leak_run(fmu, SI_EULER, big, 10)
    assert np.all(np.abs(np.diff(np.abs(dev(si)), axis=0)) <= np.abs(dev0))  # monotone decay
    np.testing.assert_allclose(si[-1], np.repeat(mean, 2), rtol=1e-12)
    mid = leak_run(fmu, SI_MIDPOINT, big, 50)
    assert np.all(np.abs(dev(mid)) <= np.abs(dev0) * (1 + 1e-12))
    np.testing.assert_allclose(mid[:, 0::2] + mid[:, 1::2], np.tile(2 * np.array(mean), (51, 1)), rtol=1e-12)


@pytest.mark.parametrize(("solver", "order"), [(EULER, 1), (SI_EULER, 1), (SI_MIDPOINT, 2)])
def test_observed_order_on_the_exact_leakage_decay(fmu, solver, order):
    """Error at t = 2 ms (lambda t = -1.26) against dev0 exp(lambda t), halving h: ratio 2^order."""
    t_end = 2e-3
    exact = (START[2] - START[3]) * math.exp(LAM[1] * t_end)
    errors = []
    for steps in (20, 40, 80):
        p = leak_run(fmu, solver, t_end / steps, steps)
        errors.append(abs(p[-1, 2] - p[-1, 3] - exact))
    rates = np.log2(np.array(errors[:-1]) / np.array(errors[1:]))
    np.testing.assert_allclose(rates, order, atol=0.1)


def test_stroke_beyond_the_cylinder_is_an_error(fmu, capsys):
    """A stroke that empties a chamber is refused with an error naming the stroke."""
    inst = Instance(fmu, "me", {})
    try:
        inst.set({"stroke2": -0.25})  # V0/A = 0.21 m
        with pytest.raises(FMICallException):
            inst.rhs(pressures(inst))
        assert "stroke2 = -0.25 m leaves a chamber volume <= 0" in capsys.readouterr().out
    finally:
        inst.close()


def test_unloaded_piston_speed_per_mm_of_spool(fmu):
    """The flow-coefficient reading documented in model.c: with 1 mm of spool and no load
    (p_left = p_right = p_s / 2) the valve passes A v with v = 6.38e-3 m/s (actuator 1) and
    3.99e-3 m/s (actuators 2, 3)."""
    half = start_pressures([PS / 2] * 6)
    inst = Instance(fmu, "me", {"spool1": 1e-3, "spool2": 1e-3, "spool3": 1e-3, **half})
    try:
        dp = inst.rhs(pressures(inst))
        speed = dp[0::2] * np.array(V0) / BETA / np.array(AREA)  # Q_left / A
        np.testing.assert_allclose(speed, [6.38e-3, 3.99e-3, 3.99e-3], rtol=2e-3)
        np.testing.assert_allclose(dp[1::2], -dp[0::2])  # the other chamber drains alike
    finally:
        inst.close()


def test_holding_pressures_hold_the_table2_arm_at_rest(fmu):
    """models/hydraulic-manipulator/hydraulics.ssv is what its script computes today (forces
    whose arm accelerations are below 1e-9, checked there), and with these start pressures
    and closed valves the hydraulics FMU puts out exactly those forces and stays put."""
    import importlib.util
    import json
    from pathlib import Path

    scene = Path(__file__).resolve().parents[1] / "models" / "hydraulic-manipulator"
    spec = importlib.util.spec_from_file_location("holding_pressures", scene / "holding_pressures.py")
    hp = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(hp)
    stored = read_ssv(scene / "hydraulics.ssv")
    arm_params = json.loads(hp.ARM_PARAMETERS.read_text(encoding="utf-8"))
    forces = hp.holding_forces(fmu_path("manipulator"), arm_params)
    assert stored == pytest.approx(hp.pressures(forces), rel=1e-9)

    inst = Instance(fmu, "me", stored)
    try:
        np.testing.assert_allclose(inst.get(["force1", "force2", "force3"]), forces, rtol=1e-9, atol=1e-6)
        assert np.all(inst.rhs(pressures(inst)) == 0)  # closed valves, pistons still
        assert abs(forces[1]) > 1e3  # the shoulder cylinder really carries the arm
    finally:
        inst.close()
