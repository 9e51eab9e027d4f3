"""The DC motor servo FMU (fmus/dcmotor) alone and closed around the arm (fmus/manipulator).

Real FMUs built from C, driven through fmpy.  Units: A, V, Ohm, H, rad, rad/s, N m, s.
"""

from __future__ import annotations

import importlib.util
import math
import shutil
from pathlib import Path

import numpy as np
import pytest
from fmpy import extract, read_model_description
from fmpy.fmi2 import FMU2Slave

from master.fmubuild import fmu_path
from master.scenario.ssv import read_ssv

EULER, AB3, SI_EULER, SI_MIDPOINT = 1, 3, 5, 6
R, L, KE, KT = 5.0, 0.02, 0.5, (20.0, 15.0, 10.0)  # Table 3
ROOT = Path(__file__).resolve().parents[1]
SCENE = ROOT / "models" / "dc-motor-arm"


def _load_place_poles():
    spec = importlib.util.spec_from_file_location("place_poles", SCENE / "place_poles.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


pp = _load_place_poles()


@pytest.fixture(scope="module")
def motor():
    return fmu_path("dcmotor")


class Slave:
    """An FMU through Co-Simulation with parameters (Real or Integer) and inputs set by name."""

    def __init__(self, path: Path, params: dict[str, float | int], solver: int) -> None:
        md = read_model_description(str(path))
        self.vr = {v.name: v.valueReference for v in md.modelVariables}
        kinds = {v.name: v.type for v in md.modelVariables}
        self.dir = extract(str(path))
        self.f = FMU2Slave(
            guid=md.guid,
            unzipDirectory=self.dir,
            modelIdentifier=md.coSimulation.modelIdentifier,
            instanceName="m",
        )
        self.f.instantiate()
        self.f.setupExperiment(startTime=0.0)
        ints = {"solver": solver} | {
            k: int(v) for k, v in params.items() if kinds[k] in ("Integer", "Enumeration")
        }
        self.f.setInteger([self.vr[k] for k in ints], list(ints.values()))
        self.set({k: v for k, v in params.items() if k not in ints})
        self.f.enterInitializationMode()
        self.f.exitInitializationMode()
        self.t = 0.0

    def set(self, values: dict[str, float]) -> None:
        if values:
            self.f.setReal([self.vr[k] for k in values], [float(v) for v in values.values()])

    def get(self, names: list[str]) -> np.ndarray:
        return np.array(self.f.getReal([self.vr[k] for k in names]))

    def step(self, h: float) -> None:
        self.f.doStep(self.t, h)
        self.t += h

    def close(self) -> None:
        self.f.terminate()
        self.f.freeInstance()
        shutil.rmtree(self.dir, ignore_errors=True)


CURRENTS = ["i1", "i2", "i3"]
W_EXT = {"w_ext1": 10.0, "w_ext2": -6.0, "w_ext3": 3.0}  # V


def held_run(
    motor: Path, solver: int, h: float, steps: int, extra: dict[str, float] | None = None
) -> np.ndarray:
    """Currents after each step of h with the rotors held (q = qd = 0), gains 0, constant w_ext."""
    s = Slave(motor, {**W_EXT, **(extra or {})}, solver)
    try:
        out = [s.get(CURRENTS)]
        for _ in range(steps):
            s.step(h)
            out.append(s.get(CURRENTS))
        return np.array(out)
    finally:
        s.close()


@pytest.mark.parametrize("solver", [EULER, SI_EULER, SI_MIDPOINT])
def test_held_rotor_current_settles_at_v_over_r(motor, solver):
    """L di/dt = w - R i with qd = 0: i -> w/R; torque = Kt i and w are reported."""
    i = held_run(motor, solver, 1e-3, 200)  # 0.2 s = 50 time constants L/R
    np.testing.assert_allclose(i[-1], np.array(list(W_EXT.values())) / R, rtol=1e-10)
    s = Slave(motor, W_EXT, solver)
    try:
        for _ in range(200):
            s.step(1e-3)
        np.testing.assert_allclose(s.get(["torque1", "torque2", "torque3"]), np.array(KT) * s.get(CURRENTS))
        np.testing.assert_allclose(s.get(["w1", "w2", "w3"]), list(W_EXT.values()))
    finally:
        s.close()


@pytest.mark.parametrize(("solver", "order"), [(EULER, 1), (SI_EULER, 1), (SI_MIDPOINT, 2)])
def test_observed_order_against_the_exact_step_response(motor, solver, order):
    """i(t) = w/R (1 - exp(-R t / L)); error at t = 4 ms with h halved twice: ratio 2^order."""
    t_end = 4e-3
    exact = W_EXT["w_ext1"] / R * (1 - math.exp(-R / L * t_end))
    errors = [abs(held_run(motor, solver, t_end / n, n)[-1, 0] - exact) for n in (16, 32, 64)]
    rates = np.log2(np.array(errors[:-1]) / np.array(errors[1:]))
    np.testing.assert_allclose(rates, order, atol=0.1)


def test_euler_limit_and_semi_implicit_beyond_it(motor):
    """The electrical pole -R/L = -250 1/s: Euler needs h < 2 L / R = 8 ms; semi-implicit does not."""
    h_euler = 2 * L / R
    target = np.array(list(W_EXT.values())) / R
    stable = held_run(motor, EULER, 0.95 * h_euler, 400)
    np.testing.assert_allclose(stable[-1], target, rtol=1e-6)
    unstable = held_run(motor, EULER, 1.05 * h_euler, 60)  # |1 - 2.1| = 1.1 per step
    assert np.all(np.abs(unstable[-1] - target) > 100 * np.abs(target))
    si = held_run(motor, SI_EULER, 10 * h_euler, 20)
    np.testing.assert_allclose(si[-1], target, rtol=1e-12)
    mid = held_run(motor, SI_MIDPOINT, 10 * h_euler, 20)
    assert np.all(np.abs(mid - target) <= np.abs(target) * (1 + 1e-12))


def test_back_emf_current_gains_and_voltage_limit(motor):
    """Steady states of L di/dt = w - R i - Ke qd with w = w_ext - K_k_(6+k) i_k, then |w| <= w_max."""
    qd = {"qd1": 2.0, "qd2": -1.0, "qd3": 0.5}
    gains = {"K_1_7": 3.0, "K_2_8": 1.0, "K_3_9": 0.5}
    i = held_run(motor, SI_EULER, 5e-3, 200, {**qd, **gains})[-1]
    w = np.array(list(W_EXT.values()))
    expected = (w - KE * np.array(list(qd.values()))) / (R + np.array(list(gains.values())))
    np.testing.assert_allclose(i, expected, rtol=1e-10)
    limited = held_run(motor, SI_EULER, 5e-3, 200, {"w_max": 4.0})[-1]
    np.testing.assert_allclose(limited, np.clip(w, -4, 4) / R, rtol=1e-10)


def test_analytic_jacobian_equals_finite_differences(motor):
    """d(der i)/d(i) from fmi2GetDirectionalDerivative vs central differences, full gain matrix."""
    rng = np.random.default_rng(1)
    gains = {f"K_{r}_{c}": float(rng.normal(0, 5)) for r in (1, 2, 3) for c in range(1, 10)}
    inputs = {"q1": 0.1, "q2": 0.9, "q3": 5.0, "qd1": 0.3, "qd2": -0.2, "qd3": 0.1}
    m = pp.MeFmu(motor, {**gains, "i_ref2": 0.7}, "m")
    try:
        m.fmu.setReal(m.refs(list(inputs)), list(inputs.values()))
        x = np.array([0.4, -1.2, 2.0])
        m.set_states(x)
        ders = m.refs(["der(i1)", "der(i2)", "der(i3)"])
        states = m.refs(CURRENTS)
        analytic = np.column_stack(
            [m.fmu.getDirectionalDerivative(ders, [states[j]], [1.0]) for j in range(3)]
        )
        numeric = np.zeros((3, 3))
        for j in range(3):
            e = np.zeros(3)
            e[j] = 1e-4
            m.set_states(x + e)
            up = m.derivatives()
            m.set_states(x - e)
            numeric[:, j] = (up - m.derivatives()) / 2e-4
        np.testing.assert_allclose(analytic, numeric, rtol=1e-7)
        k_ii = np.array([[gains[f"K_{r}_{c}"] for c in (7, 8, 9)] for r in (1, 2, 3)])
        np.testing.assert_allclose(analytic, -(k_ii + R * np.eye(3)) / L, rtol=1e-14)
    finally:
        m.close()


# ---------------------------------------------------------------- closed around the arm


@pytest.fixture(scope="module")
def controller():
    """Parameters of the checked-in controller.ssv and the set point z* they hold."""
    params = read_ssv(SCENE / "controller.ssv")
    z_ref = np.concatenate([pp.Q_REF, np.zeros(3), [params[f"i_ref{k}"] for k in (1, 2, 3)]])
    return params, z_ref


@pytest.fixture(scope="module")
def arm_system(motor, controller):
    """Arm and motors with the gains, through Model Exchange: z' = F(z)."""
    system = pp.CoupledArm(fmu_path("manipulator"), motor, controller[0])
    yield system
    system.close()


def test_controller_file_is_what_the_script_computes(motor, controller):
    """controller.ssv is current: place_poles.design() on today's FMUs gives the same set point and
    holding currents, and gains that place the same closed-loop poles.

    Multi-input pole placement is ill-conditioned and its gains are not unique: their digits depend
    on the BLAS build (K_1_2 differs in the sixth digit between machines). The gains are therefore
    compared by what they mean, the poles they place, not digit by digit."""
    params, z_ref = controller
    fresh = pp.design(fmu_path("manipulator"), motor)
    assert set(fresh) == set(params)
    for name in (n for n in fresh if not n.startswith("K_")):
        assert fresh[name] == pytest.approx(params[name], rel=1e-6, abs=1e-9), name
    system = pp.CoupledArm(fmu_path("manipulator"), motor, fresh)
    try:
        eig = np.sort_complex(np.linalg.eigvals(pp.closed_loop_jacobian(system, z_ref)))
    finally:
        system.close()
    np.testing.assert_allclose(eig, np.sort_complex(pp.POLES), rtol=1e-5)


def test_set_point_is_an_equilibrium_with_the_placed_poles(arm_system, controller):
    """F(z*) = 0 (holding currents balance gravity) and eig(dF/dz) are the chosen poles."""
    _, z_ref = controller
    assert np.abs(arm_system.rhs(z_ref)).max() < 1e-9
    assert abs(z_ref[7]) > 1.0  # gravity really needs holding current on the shoulder
    eig = np.sort_complex(np.linalg.eigvals(pp.closed_loop_jacobian(arm_system, z_ref)))
    np.testing.assert_allclose(eig, np.sort_complex(pp.POLES), rtol=1e-5)


def test_closed_loop_co_simulation_settles_at_the_set_points(motor, controller):
    """Both FMUs through Co-Simulation, Jacobi coupling at H = 1 ms (arm: AB3, motors:
    semi-implicit Euler), starting 3 degrees off on every joint: after 3 s the joints are back
    at (0, 45, 300) degrees and the currents at their holding values."""
    params, z_ref = controller
    off = np.radians([3.0, -3.0, 3.0])
    arm_path = fmu_path("manipulator")
    start = {f"q{k + 1}_0": pp.Q_REF[k] + off[k] for k in range(3)}
    arm = Slave(arm_path, pp.arm_parameters() | start, AB3)
    start_i = {f"i{k}": params[f"i_ref{k}"] for k in (1, 2, 3)}
    mot = Slave(motor, {**params, **start_i}, SI_EULER)
    names = ["q1", "q2", "q3", "qd1", "qd2", "qd3"]
    h, deviation = 1e-3, []
    try:
        for _ in range(3000):
            mot.set(dict(zip(names, arm.get(names), strict=True)))
            torques = mot.get(["torque1", "torque2", "torque3"])
            arm.set({f"effort{k + 1}": torques[k] for k in range(3)})
            arm.step(h)
            mot.step(h)
            deviation.append(np.abs(arm.get(names[:3]) - pp.Q_REF).max())
        assert deviation[0] > 0.02  # it did start off the set point
        assert deviation[-1] < 1e-6
        np.testing.assert_allclose(mot.get(CURRENTS), z_ref[6:], atol=1e-5)
    finally:
        arm.close()
        mot.close()


def test_ab3_on_the_whole_system_largest_stable_step(arm_system, controller):
    """AB3 (one step, both FMUs' Model Exchange equations) is stable up to the step that puts
    the fastest closed-loop eigenvalue on the boundary of its stability region.

    Prediction: h* = min over eigenvalues of the AB3 boundary along h lambda; with the
    fastest pole at -250 1/s that is (6/11) / 250 = 2.18e-3 s.  Measurement: bisection on h,
    10 halvings of [0.8, 1.25] h*, 1 s from a deviation of every state; a step counts as
    unstable when the deviation ends larger than it began.  Tolerance 1 %: slightly above
    h* the growth per step is slow, so the measured limit sits a little above h*.
    """
    _, z_ref = controller
    predicted = pp.ab3_prediction(pp.closed_loop_jacobian(arm_system, z_ref))
    assert predicted == pytest.approx(6 / 11 / 250, rel=1e-4)
    dz0 = np.array([0.01, -0.01, 0.01, 0.05, -0.05, 0.05, 0.1, -0.1, 0.1])
    measured = pp.ab3_stable_step(arm_system, z_ref, dz0, 0.8 * predicted, 1.25 * predicted, 1.0, 10)
    print(f"AB3 whole system: predicted {predicted:.5e} s, measured {measured:.5e} s (paper: 2e-3 s)")
    assert measured == pytest.approx(predicted, rel=0.01)
