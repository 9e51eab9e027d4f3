"""The shared C FMI 2.0 layer (fmus/fmi), exercised through fmpy on real FMUs built from C.

dahlquist (y' = lambda y) and msd (mass-spring-damper) have closed-form solutions, so the
tests compare with mathematics: exp(lambda t), the stability function of Euler, polynomial
responses to polynomial inputs, and the two-mass oscillator reference of numerics-facts.md.
"""

from __future__ import annotations

import ctypes
import math
from pathlib import Path

import numpy as np
import pytest
import scipy.linalg
from fmpy import extract, read_model_description, simulate_fmu
from fmpy.fmi1 import FMICallException
from fmpy.fmi2 import (
    FMU2Model,
    FMU2Slave,
    fmi2CallbackAllocateMemoryTYPE,
    fmi2CallbackFreeMemoryTYPE,
    fmi2CallbackFunctions,
    fmi2CallbackLoggerTYPE,
    fmi2LastSuccessfulTime,
)
from fmpy.validation import validate_fmu

from master import fmubuild

from fmpy import calloc, free  # isort: skip


# ----------------------------------------------------------------- helpers


class Fmu:
    """A project FMU extracted once, with a factory for instances that record log messages."""

    def __init__(self, name: str, tmp: Path) -> None:
        self.path = fmubuild.fmu_path(name)
        self.md = read_model_description(str(self.path))
        self.dir = extract(str(self.path), unzipdir=str(tmp / name))
        self.vr = {v.name: v.valueReference for v in self.md.modelVariables}

    def instance(self, kind: str = "cs", guid: str | None = None, name: str = "inst") -> Instance:
        return Instance(self, kind, guid, name)


class Instance:
    """An fmpy instance plus the messages its logger received, as (status, category, text)."""

    def __init__(self, fmu: Fmu, kind: str, guid: str | None, name: str) -> None:
        cls = FMU2Slave if kind == "cs" else FMU2Model
        self.fmu = fmu
        self.messages: list[tuple[int, str, str]] = []
        self.callbacks = fmi2CallbackFunctions()
        self.callbacks.logger = fmi2CallbackLoggerTYPE(self._log)
        self.callbacks.allocateMemory = fmi2CallbackAllocateMemoryTYPE(calloc)
        self.callbacks.freeMemory = fmi2CallbackFreeMemoryTYPE(free)
        self.slave = cls(
            guid=guid or fmu.md.guid,
            unzipDirectory=fmu.dir,
            modelIdentifier=fmu.md.coSimulation.modelIdentifier,
            instanceName=name,
        )
        self.slave.instantiate(callbacks=self.callbacks)

    def _log(self, env, instance_name, status, category, message) -> None:  # noqa: ANN001
        self.messages.append((status, category.decode(), message.decode().replace("%%", "%")))

    def errors(self) -> str:
        return "\n".join(m for s, c, m in self.messages if c == "logError")

    def set(self, **values: float) -> None:
        for name, value in values.items():
            self.slave.setReal([self.fmu.vr[name]], [value])

    def get(self, *names: str) -> list[float]:
        return self.slave.getReal([self.fmu.vr[n] for n in names])

    def init(self, start: float = 0.0, **parameters: float) -> Instance:
        self.slave.setupExperiment(startTime=start)
        for name, value in parameters.items():
            if name == "solver":
                self.slave.setInteger([self.fmu.vr["solver"]], [int(value)])
            else:
                self.set(**{name: value})
        self.slave.enterInitializationMode()
        self.slave.exitInitializationMode()
        return self

    def free(self) -> None:
        self.slave.freeInstance()


@pytest.fixture(scope="module")
def fmus(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Fmu]:
    tmp = tmp_path_factory.mktemp("fmus")
    return {name: Fmu(name, tmp) for name in ("dahlquist", "msd")}


EULER, AB3, RK4, SEMI_EULER, SEMI_MIDPOINT = 1, 3, 4, 5, 6


# ------------------------------------------------ every project FMU, via fmpy


@pytest.mark.parametrize("name", fmubuild.project_fmu_names())
def test_project_fmu_validates_and_simulates(name: str) -> None:
    path = fmubuild.fmu_path(name)
    assert validate_fmu(str(path)) == []
    md = read_model_description(str(path))
    internal_step = next(float(v.start) for v in md.modelVariables if v.name == "internal_step")
    interval = 10 * internal_step if internal_step > 0 else 1e-3
    stop = 20 * interval
    me_only = fmubuild._declares(name, "me_only")  # such a model offers Model Exchange alone
    assert md.modelExchange is not None and (md.coSimulation is None) == me_only
    for fmi_type in ("ModelExchange",) if me_only else ("CoSimulation", "ModelExchange"):
        result = simulate_fmu(str(path), fmi_type=fmi_type, stop_time=stop, output_interval=interval)
        assert result["time"][-1] == pytest.approx(stop)
        for field in result.dtype.names:
            assert np.all(np.isfinite(result[field].astype(float))), (name, fmi_type, field)


def test_dahlquist_cs_and_me_match_exponential(fmus: dict[str, Fmu]) -> None:
    path = str(fmus["dahlquist"].path)
    params = {"lambda": -2.0, "y0": 1.5}
    cs = simulate_fmu(path, fmi_type="CoSimulation", stop_time=2.0, output_interval=0.01, start_values=params)
    exact = 1.5 * np.exp(-2.0 * cs["time"])
    # RK4, h = 0.01: global error about h^4 |lambda|^5 t e^(lambda t) / 120 ~ 1e-9
    assert np.max(np.abs(cs["y"] - exact)) < 1e-8
    me = simulate_fmu(
        path,
        fmi_type="ModelExchange",
        stop_time=2.0,
        output_interval=0.01,
        start_values=params,
        relative_tolerance=1e-9,
    )
    assert np.max(np.abs(me["y"] - 1.5 * np.exp(-2.0 * me["time"]))) < 1e-6


STABILITY_FUNCTIONS = {
    EULER: lambda z: 1 + z,
    RK4: lambda z: 1 + z + z**2 / 2 + z**3 / 6 + z**4 / 24,
    SEMI_EULER: lambda z: 1 / (1 - z),  # exact Jacobian from the model: L-stable
}


@pytest.mark.parametrize("solver", sorted(STABILITY_FUNCTIONS))
@pytest.mark.parametrize("lam", [-3.0, -100.0])
def test_internal_steps_follow_the_stability_function(fmus: dict[str, Fmu], solver: int, lam: float) -> None:
    """n internal steps of h per doStep multiply y by R(lambda h)^n."""
    inst = fmus["dahlquist"].instance().init(solver=solver, internal_step=0.025, **{"lambda": lam})
    R = STABILITY_FUNCTIONS[solver](lam * 0.025)
    t, H = 0.0, 0.1
    for k in range(1, 11):
        inst.slave.doStep(t, H)
        t += H
        assert inst.get("y")[0] == pytest.approx(R ** (4 * k), rel=1e-12)
    # the FMU's time is exactly t + H of the master's arguments, no accumulation of its own
    assert inst.slave.getRealStatus(fmi2LastSuccessfulTime) == t
    inst.free()


def test_internal_step_that_does_not_divide_the_step_is_an_error(fmus: dict[str, Fmu]) -> None:
    inst = fmus["dahlquist"].instance().init(internal_step=0.03)
    with pytest.raises(FMICallException):
        inst.slave.doStep(0.0, 0.1)
    assert "not an integer multiple of internal_step" in inst.errors()
    # nothing happened: a dividing step still works from t = 0 and ends exactly at t + H
    inst.slave.doStep(0.0, 0.09)
    assert inst.slave.getRealStatus(fmi2LastSuccessfulTime) == 0.09
    assert inst.get("y")[0] == pytest.approx(math.exp(-0.09), rel=1e-9)
    inst.free()


def test_derivative_and_output_values_are_up_to_date(fmus: dict[str, Fmu]) -> None:
    fmu = fmus["msd"]
    inst = fmu.instance().init(x0=0.5, v0=-0.25, cc=2.0, dc=0.5, m=2.0)
    inst.set(F=1.0, x_in=0.1, v_in=0.3)
    x, v = 0.5, -0.25
    f_c = 2.0 * (x - 0.1) + 0.5 * (v - 0.3)
    assert inst.get("F_c")[0] == pytest.approx(f_c, rel=1e-15)
    assert inst.get("der(v)")[0] == pytest.approx((-x - v + 1.0 - f_c) / 2.0, rel=1e-15)
    inst.set(x_in=-1.0)  # inputs changed: outputs follow without a step
    assert inst.get("F_c")[0] == pytest.approx(2.0 * (x + 1.0) + 0.5 * (v - 0.3), rel=1e-15)
    inst.free()


def test_msd_pair_reproduces_the_two_mass_oscillator(fmus: dict[str, Fmu]) -> None:
    """Set A of numerics-facts.md, Jacobi coupling with zero-order hold: error O(H), constant ~ known."""
    ref = np.array([-1.0849853810160e-3, -2.6931070586924e-3])
    # sanity of the reference itself from the 4x4 matrix exponential
    a = np.array([[0, 1, 0, 0], [-2, -2, 1, 1], [0, 0, 0, 1], [1, 1, -2, -2]], dtype=float)
    exact = scipy.linalg.expm(10 * a) @ np.array([1.0, 0, 0, 0])
    assert np.allclose(exact[:2], ref, rtol=1e-10, atol=0)
    errors = []
    for H in (0.02, 0.01):
        m1 = fmus["msd"].instance(name="mass1").init(x0=1.0)
        m2 = fmus["msd"].instance(name="mass2").init(cc=1.0, dc=1.0)
        n = round(10 / H)
        for k in range(n):
            x1, v1 = m1.get("x", "v")
            (f,) = m2.get("F_c")
            m1.set(F=f)
            m2.set(x_in=x1, v_in=v1)
            m1.slave.doStep(k * H, H)
            m2.slave.doStep(k * H, H)
        errors.append(np.max(np.abs(np.array(m1.get("x", "v")) - ref)))
        m1.free()
        m2.free()
    assert errors[1] < 2e-3
    assert errors[0] / errors[1] == pytest.approx(2.0, rel=0.15)  # first order in H


# ------------------------------------------------------- input derivatives


def _double_integrator_run(fmus: dict[str, Fmu], poly: list[float], with_derivatives: bool) -> tuple:
    """msd with m = 1, c = d = 0 (x'' = F) driven by F(t) = sum poly[k] t^k / k!, RK4, H = 0.1."""
    inst = fmus["msd"].instance().init(c=0.0, d=0.0, solver=RK4)
    vr = inst.fmu.vr["F"]
    H, n = 0.1, 10
    for k in range(n):
        t = k * H
        # value and derivatives of the input at the communication point
        d = [sum(poly[j + i] * t**j / math.factorial(j) for j in range(len(poly) - i)) for i in range(4)]
        inst.set(F=d[0])
        if with_derivatives:
            for order in (1, 2, 3):
                inst.slave.setRealInputDerivatives([vr], [order], [d[order] if order < len(d) else 0.0])
        inst.slave.doStep(t, H)
        assert inst.get("F")[0] == d[0]  # the slot is back at the value the master set
    x, v = inst.get("x", "v")
    inst.free()
    T = n * H
    v_exact = sum(p * T ** (k + 1) / math.factorial(k + 1) for k, p in enumerate(poly))
    x_exact = sum(p * T ** (k + 2) / math.factorial(k + 2) for k, p in enumerate(poly))
    return x - x_exact, v - v_exact


def test_input_derivatives_make_polynomial_inputs_exact(fmus: dict[str, Fmu]) -> None:
    # ramp F = t: x = t^3/6 is within RK4's reach, exact to rounding with the derivative
    ex, ev = _double_integrator_run(fmus, [0.0, 1.0], with_derivatives=True)
    assert abs(ex) < 1e-14 and abs(ev) < 1e-14
    hx, hv = _double_integrator_run(fmus, [0.0, 1.0], with_derivatives=False)
    assert abs(hv) == pytest.approx(0.05, rel=1e-9)  # zero-order hold lags by H/2 * slope * T
    # cubic F = 1 + 2t + 3t^2/2 + 4t^3/6: v' = F is Simpson-exact; x (degree 5) within O(H^4)
    ex, ev = _double_integrator_run(fmus, [1.0, 2.0, 3.0, 4.0], with_derivatives=True)
    hx, hv = _double_integrator_run(fmus, [1.0, 2.0, 3.0, 4.0], with_derivatives=False)
    assert abs(ev) < 1e-13
    assert abs(ex) < 1e-5 and abs(hx) > 100 * abs(ex)


def test_input_derivative_checks(fmus: dict[str, Fmu]) -> None:
    inst = fmus["msd"].instance().init()
    vr = inst.fmu.vr
    for bad_vr, order, value, reason in [
        (vr["x"], 1, 1.0, "not an input"),
        (vr["F"], 4, 1.0, "order 4 not in 1..3"),
        (vr["F"], 1, math.nan, "not finite"),
    ]:
        with pytest.raises(FMICallException):
            inst.slave.setRealInputDerivatives([bad_vr], [order], [value])
        assert reason in inst.errors()
    inst.free()


# ------------------------------------------------------------- FMU state


def _run(inst: Instance, t0: float, steps: int, H: float = 0.05) -> np.ndarray:
    out = []
    for k in range(steps):
        t = t0 + k * H
        inst.set(F=math.sin(3 * t), x_in=0.2 * t, v_in=0.2)
        inst.slave.setRealInputDerivatives([inst.fmu.vr["F"]], [1], [3 * math.cos(3 * t)])
        inst.slave.doStep(t, H)
        out.append(inst.get("x", "v", "F_c", "der(v)"))
    return np.array(out)


@pytest.mark.parametrize("solver", [AB3, SEMI_MIDPOINT])
def test_get_set_fmu_state_is_bitwise(fmus: dict[str, Fmu], solver: int) -> None:
    """AB3 keeps a history in the solver memory: restoring must restore it too."""
    inst = fmus["msd"].instance().init(x0=1.0, cc=2.0, dc=0.3, solver=solver)
    _run(inst, 0.0, 20)
    state = inst.slave.getFMUstate()
    first = _run(inst, 1.0, 30)
    inst.slave.setFMUstate(state)
    second = _run(inst, 1.0, 30)
    assert np.array_equal(first, second)

    # serialized, then restored into a fresh instance of the same FMU
    blob = inst.slave.serializeFMUstate(state)
    other = fmus["msd"].instance(name="other").init()
    restored = other.slave.deSerializeFMUstate(blob)
    other.slave.setFMUstate(restored)
    third = _run(other, 1.0, 30)
    assert np.array_equal(first, third)
    other.slave.freeFMUstate(restored)
    inst.slave.freeFMUstate(state)
    other.free()
    inst.free()


def test_deserialize_rejects_foreign_and_truncated_buffers(fmus: dict[str, Fmu]) -> None:
    dq = fmus["dahlquist"].instance().init()
    state = dq.slave.getFMUstate()
    foreign = dq.slave.serializeFMUstate(state)
    msd = fmus["msd"].instance().init()
    with pytest.raises(FMICallException):
        msd.slave.deSerializeFMUstate(foreign)
    assert "foreign model" in msd.errors()
    own_state = msd.slave.getFMUstate()
    own = msd.slave.serializeFMUstate(own_state)
    with pytest.raises(FMICallException):
        msd.slave.deSerializeFMUstate(own[:-8])
    assert "truncated" in msd.errors()
    with pytest.raises(FMICallException):
        msd.slave.deSerializeFMUstate(b"not a state at all, really")
    assert "not a serialized state" in msd.errors()
    # the instance is unharmed
    msd.slave.doStep(0.0, 0.1)
    dq.slave.freeFMUstate(state)
    msd.slave.freeFMUstate(own_state)
    dq.free()
    msd.free()


# ------------------------------------------------------------- bad calls


def test_bad_calls_return_error_log_and_leave_the_instance_usable(fmus: dict[str, Fmu]) -> None:
    fmu = fmus["msd"]
    inst = fmu.instance()
    with pytest.raises(FMICallException):
        inst.slave.doStep(0.0, 0.1)  # before initialization
    assert "fmi2DoStep: not allowed in state Instantiated" in inst.errors()
    with pytest.raises(FMICallException):
        inst.slave.getReal([999])
    with pytest.raises(FMICallException):
        inst.slave.setReal([999], [1.0])
    assert "value reference 999 out of range" in inst.errors()
    with pytest.raises(FMICallException):
        inst.set(m=math.nan)
    assert "variable m: value nan is not finite" in inst.errors()
    with pytest.raises(FMICallException):
        inst.set(m=-1.0)
    assert "variable m: value -1 outside [0, inf]" in inst.errors()
    with pytest.raises(FMICallException):
        inst.slave.setInteger([fmu.vr["m"]], [1])
    assert "variable m (value reference 2) is of type Real" in inst.errors()
    with pytest.raises(FMICallException):
        inst.slave.setInteger([fmu.vr["solver"]], [7])
    assert "variable solver: value 7 outside [1, 6]" in inst.errors()
    with pytest.raises(FMICallException):
        inst.set(x=1.0)
    assert "variable x cannot be set in state Instantiated" in inst.errors()
    with pytest.raises(FMICallException):
        inst.slave.setDebugLogging(True, ["logNonsense"])
    assert 'unknown log category "logNonsense"' in inst.errors()
    n_errors = len(inst.messages)
    assert all(status == 3 for status, _, _ in inst.messages)

    # the instance goes on normally, unchanged by the rejected calls
    inst.init(x0=1.0)
    with pytest.raises(FMICallException):
        inst.set(m=2.0)  # fixed parameter after initialization
    assert "only inputs and tunable parameters" in inst.errors()
    with pytest.raises(FMICallException):
        inst.slave.getRealOutputDerivatives([fmu.vr["x"]], [1])
    assert len(inst.messages) == n_errors + 2
    inst.slave.doStep(0.0, 0.01)
    x, v = inst.get("x", "v")
    assert x == pytest.approx(1.0 - 0.5 * 0.01**2, abs=1e-6) and v == pytest.approx(-0.01, rel=0.02)
    inst.free()


def test_debug_logging_filters_categories_but_never_errors(fmus: dict[str, Fmu]) -> None:
    quiet = fmus["dahlquist"].instance(name="quiet").init()
    assert quiet.messages == []  # instantiated with loggingOn = false
    chatty = fmus["dahlquist"].instance(name="chatty")
    chatty.slave.setDebugLogging(True, ["logInfo"])
    chatty.init(internal_step=0.01)
    assert chatty.messages == [
        (0, "logInfo", "initialized at t = 0 s: 1 continuous states, solver 4, internal_step 0.01 s")
    ]
    chatty.slave.setDebugLogging(False, [])
    with pytest.raises(FMICallException):
        chatty.slave.getReal([99])
    assert chatty.messages[-1][:2] == (3, "logError")
    quiet.free()
    chatty.free()


def test_guid_mismatch_and_model_initialization_errors(fmus: dict[str, Fmu]) -> None:
    fmu = fmus["msd"]
    with pytest.raises(Exception, match="Failed to instantiate"):
        fmu.instance(guid="{00000000-0000-0000-0000-000000000000}")
    inst = fmu.instance()
    inst.set(m=0.0)
    inst.slave.setupExperiment(startTime=0.0)
    inst.slave.enterInitializationMode()
    with pytest.raises(FMICallException):
        inst.slave.exitInitializationMode()
    # the last message names the model's own reason too (masters often show only that one)
    assert (
        inst.messages[-1][2]
        == "fmi2ExitInitializationMode: model initialization failed: msd: mass m = 0 must be > 0"
    )
    # an instance in the Error state recovers with fmi2Reset
    inst.slave.reset()
    inst.init(m=1.0, x0=1.0)
    inst.slave.doStep(0.0, 0.1)
    inst.free()


def test_non_finite_result_stops_the_step_with_a_named_variable(fmus: dict[str, Fmu]) -> None:
    inst = fmus["dahlquist"].instance().init(solver=EULER, y0=1e300, **{"lambda": 1e10})
    state = inst.slave.getFMUstate()
    with pytest.raises(FMICallException):
        inst.slave.doStep(0.0, 1.0)
    assert "fmi2DoStep: output y = inf at t = 1" in inst.errors()
    with pytest.raises(FMICallException):
        inst.slave.doStep(1.0, 1.0)
    assert "not allowed in state Error" in inst.errors()
    inst.slave.setFMUstate(state)  # back to the good state before the step
    assert inst.get("y") == [1e300]
    inst.slave.freeFMUstate(state)
    inst.free()


# ------------------------------------------------ directional derivatives


def test_directional_derivatives_analytic_and_finite_difference(fmus: dict[str, Fmu]) -> None:
    fmu = fmus["msd"]
    inst = fmu.instance().init(m=2.0, c=3.0, d=0.5, cc=1.5, dc=0.25, x0=0.3, v0=-0.2)
    vr = fmu.vr
    dd = inst.slave.getDirectionalDerivative
    # states -> derivatives: analytic Jacobian [[0, 1], [-(c+cc)/m, -(d+dc)/m]]
    assert dd([vr["der(x)"], vr["der(v)"]], [vr["x"]], [1.0]) == [0.0, -(3.0 + 1.5) / 2.0]
    assert dd([vr["der(x)"], vr["der(v)"]], [vr["x"], vr["v"]], [0.0, 2.0]) == [2.0, -(0.5 + 0.25)]
    # inputs and outputs: central differences of the model functions (linear: exact to rounding)
    assert dd([vr["der(v)"]], [vr["F"]], [1.0])[0] == pytest.approx(0.5, rel=1e-8)
    assert dd([vr["F_c"]], [vr["x_in"], vr["v_in"]], [1.0, 1.0])[0] == pytest.approx(-1.75, rel=1e-8)
    assert dd([vr["F_c"]], [vr["x"]], [1.0])[0] == pytest.approx(1.5, rel=1e-8)
    # nothing changed by differentiating
    assert inst.get("x", "v", "F_c") == [0.3, -0.2, 1.5 * 0.3 + 0.25 * -0.2]
    inst.free()


# ----------------------------------------------------------- model exchange


def test_model_exchange_functions(fmus: dict[str, Fmu]) -> None:
    fmu = fmus["msd"]
    inst = fmu.instance(kind="me")
    inst.init(m=2.0, cc=1.0, x0=0.5)
    inst.slave.enterContinuousTimeMode()
    inst.set(F=1.0, x_in=0.25)
    ptr = ctypes.POINTER(ctypes.c_double)
    x, dx, nominals = np.zeros(2), np.zeros(2), np.zeros(2)
    inst.slave.getContinuousStates(x.ctypes.data_as(ptr), 2)
    assert list(x) == [0.5, 0.0]
    new = np.array([0.1, 0.4])
    inst.slave.setTime(0.5)
    inst.slave.setContinuousStates(new.ctypes.data_as(ptr), 2)
    inst.slave.getDerivatives(dx.ctypes.data_as(ptr), 2)
    f_c = 1.0 * (0.1 - 0.25)
    assert list(dx) == [0.4, (-0.1 - 0.4 + 1.0 - f_c) / 2.0]
    assert inst.get("der(v)", "F_c") == [dx[1], f_c]
    with pytest.raises(FMICallException):
        inst.slave.setContinuousStates(new.ctypes.data_as(ptr), 3)
    assert "nx = 3 but the model has 2 continuous states" in inst.errors()
    inst.slave.getNominalsOfContinuousStates(nominals.ctypes.data_as(ptr), 2)
    assert list(nominals) == [1.0, 1.0]
    assert inst.slave.completedIntegratorStep() == (False, False)
    with pytest.raises(FMICallException):
        inst.slave.newDiscreteStates()  # only in Event Mode
    assert "fmi2NewDiscreteStates: not allowed in state ContinuousTimeMode" in inst.errors()
    inst.slave.enterEventMode()
    inst.slave.newDiscreteStates()
    inst.slave.terminate()
    inst.free()


def test_instances_do_not_share_data(fmus: dict[str, Fmu]) -> None:
    """Two instances of the same FMU do not share data (no globals in the layer)."""
    a = fmus["dahlquist"].instance(name="a").init(**{"lambda": -1.0})
    b = fmus["dahlquist"].instance(name="b").init(**{"lambda": -2.0})
    a.slave.doStep(0.0, 0.1)
    b.slave.doStep(0.0, 0.1)
    rk4 = lambda z: 1 + z + z**2 / 2 + z**3 / 6 + z**4 / 24  # noqa: E731 (stability function)
    assert a.get("y")[0] == pytest.approx(rk4(-0.1), rel=1e-14)
    assert b.get("y")[0] == pytest.approx(rk4(-0.2), rel=1e-14)
    a.free()
    b.free()


def test_a_kept_evaluation_of_f_serves_its_own_arguments_only(tmp_path: Path) -> None:
    """The manipulator's outputs evaluate f too, and the layer keeps that evaluation for a step that
    starts with the same time, states and Real inputs (the master re-reads outputs at a point, then
    steps from it). A step after a read at other inputs, or after a parameter changed, is the step
    without the read (to the loop closure's tolerance: the read moves its warm start)."""
    fmu = Fmu("manipulator", tmp_path)
    names = ["q1", "q2", "q3", "qd1", "qd2", "qd3"]

    def step(read: dict[str, float] | None, inputs: dict[str, float], parameter: float | None = None):
        inst = fmu.instance().init(solver=AB3)
        if read is not None:
            inst.set(**read)
            inst.get("body6_az")  # evaluates outputs, f with them
        if parameter is not None:
            inst.set(disturbance1=parameter)  # an input the other runs leave at 0: f changes
        inst.set(**inputs)
        inst.slave.doStep(0.0, 1e-3)
        try:
            return np.array(inst.get(*names))
        finally:
            inst.free()

    without = step(None, {"effort1": 500.0})
    same = step({"effort1": 500.0}, {"effort1": 500.0})  # the kept f is this step's
    other = step({"effort1": -500.0}, {"effort1": 500.0})  # kept at other inputs: not used
    scale = np.maximum(np.abs(without), 1e-3)
    assert np.all(np.abs(same - without) <= 1e-9 * scale)
    assert np.all(np.abs(other - without) <= 1e-9 * scale)
    assert not np.array_equal(step({"effort1": 500.0}, {"effort1": 500.0}, 50.0), without)
