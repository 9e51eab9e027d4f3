"""Events of Model Exchange components: time events met exactly, state events located inside the
step (Illinois on the solver's step, to EVENT_TOLERANCE), step events, the event iteration and the
multistep history restarted after each event (fmus/solvers/events.c, shared by the kernel and the
project's Co-Simulation FMUs, so both meet an event the same way).

Models with closed-form answers: bouncing_ball (state events), stair (time events), kicked (time
events that change the state), ratchet (step events).
"""

from __future__ import annotations

import dataclasses
import math
from fractions import Fraction
from pathlib import Path

import fmpy
import numpy as np
import pytest
from helpers import run_everywhere

import master.api as api
from master.backends.component import SimulationError
from master.fmubuild import fmu_path
from master.scenario.model import Component, Connection, ModelExchange, Scenario
from master.solvers import NUMBERS

EVENT_TOLERANCE = 1e-10  # s, fmus/solvers/solvers.h
G, E, H0 = 9.81, 0.7, 1.0  # bouncing_ball's defaults


def fmu(name: str, fmi: int) -> Path:
    return fmu_path(name, fmi)  # built once, then taken from build/fmus (FMI 3.0: build/fmus/fmi3)


def scene(name: str, comp: Component, stop: Fraction, step: Fraction) -> Scenario:
    return Scenario(Path(f"{name}.ssd"), name, (comp,), (), Fraction(0), stop, step)


def me(name: str, fmi: int, solver: str, stop: float, step: float, internal: Fraction | None = None, **p):
    """Component `name` of the project's FMU run as Model Exchange by the master."""
    comp = Component(name, fmu(name, fmi), parameters=p, model_exchange=ModelExchange(solver, internal))
    return scene(name, comp, Fraction(str(stop)), Fraction(str(step)))


def cs(name: str, fmi: int, solver: str, stop: float, step: float, internal: Fraction | None = None, **p):
    """The same FMU as Co-Simulation, its own solver and internal step the same."""
    p = {**p, "solver": NUMBERS[solver], "internal_step": float(internal or 0)}
    return scene(
        name, Component(name, fmu(name, fmi), parameters=p), Fraction(str(stop)), Fraction(str(step))
    )


def bounces(until: float, most: int = 20) -> list[float]:
    """The closed-form bounce times before `until` (h0, g, e), at most `most`: t1 = sqrt(2 h0 / g),
    then flights of 2 e^k v1 / g."""
    v1 = math.sqrt(2 * G * H0)
    times = [v1 / G]
    while times[-1] + 2 * E ** len(times) * v1 / G < until and len(times) < most:
        times.append(times[-1] + 2 * E ** len(times) * v1 / G)
    return times


@pytest.mark.parametrize("fmi", [2, 3])
def test_bouncing_ball_bounces_at_the_closed_form_times_in_every_backend(fmi):
    """RK4 integrates the flights (quadratics) exactly, so the samples give the bounce times the
    master located: from a sample (h, v) after bounce k, the ball left the ground s before, with
    h = v s + g s^2 / 2. Each bounce is met up to a location tolerance late, and carries the
    earlier ones' lateness (bounce k within 2 k tolerances; measured 0.5, 1.7, 3.4, 5.4 x 1e-10 s).
    The flight after bounce k rises to e^(2k) h0."""
    d = run_everywhere(me("bouncing_ball", fmi, "rk4", 2.0, 0.01))
    t, h, v = d["time"], d["bouncing_ball.h"], d["bouncing_ball.v"]
    closed = bounces(2.0)
    assert len(closed) == 4
    assert np.all(h > -1e-9)  # never below the ground (the right end of the located interval)
    for k, tk in enumerate(closed, start=1):
        end = closed[k] if k < len(closed) else 2.0
        flight = (t > tk + 1e-6) & (t < end - 1e-6)
        assert flight.sum() >= 5
        s = (-v[flight] + np.sqrt(v[flight] ** 2 + 2 * G * h[flight])) / G
        located = t[flight] - s
        late = located - tk  # located at the right end of an interval of the tolerance: late, never early
        assert np.all(late > -1e-12) and np.all(late <= 2 * k * EVENT_TOLERANCE), (k, late.min(), late.max())
        apex = h[flight] + v[flight] ** 2 / (2 * G)
        np.testing.assert_allclose(apex, E ** (2 * k) * H0, rtol=0, atol=1e-9)


@pytest.mark.parametrize("solver,fmi", [("rk4", 2), ("ab3", 2), ("euler", 2), ("rk4", 3)])
def test_bouncing_ball_as_model_exchange_equals_the_co_simulation_fmu(solver, fmi):
    """The Co-Simulation FMU locates its bounces inside doStep with the same code: the same bits."""
    internal = Fraction(1, 400)
    a = run_everywhere(me("bouncing_ball", fmi, solver, 2.0, 0.01, internal))
    b = run_everywhere(cs("bouncing_ball", fmi, solver, 2.0, 0.01, internal))
    assert np.min(a["bouncing_ball.v"]) < -4 and np.max(a["bouncing_ball.v"]) > 2  # it bounced
    for name in a.dtype.names:
        assert np.array_equal(a[name], b[name]), name


@pytest.mark.parametrize("fmi", [2, 3])
@pytest.mark.parametrize("step", [Fraction(1, 10), Fraction(3, 10)], ids=["events-at-points", "inside-steps"])
def test_stair_counts_exactly_at_its_time_events(fmi, step):
    """counter(t) = 1 + floor(t): at a communication point that is an event time the event is
    handled (the point's value is after it); events inside a step cut it there."""
    d = run_everywhere(me("stair", fmi, "euler", 3.0, step))
    times = [Fraction(j) * step for j in range(len(d))]
    assert times[-1] == 3
    expected = [1 + math.floor(t) for t in times]
    assert d["stair.counter"].tolist() == expected
    assert run_everywhere(cs("stair", fmi, "euler", 3.0, step))["stair.counter"].tolist() == expected


@pytest.mark.parametrize("fmi", [2, 3])
def test_an_fmu_that_ends_the_simulation_in_its_event_iteration_ends_the_run(fmi):
    """stair with last = 3: terminateSimulation at t = 2, the run ends there as for an FMU that ends
    the simulation in a step."""
    d = run_everywhere(me("stair", fmi, "euler", 5.0, 0.1, last=3))
    assert d["time"][-1] == pytest.approx(2.0)
    assert d["stair.counter"][-1] == 3


def kicked_exact(t: float) -> float:
    k = math.floor(t + 1e-12)
    return math.exp(-(t - k)) * sum(math.exp(-i) for i in range(k + 1))


def test_history_restarts_after_an_event_ab3_keeps_its_order():
    """kicked: y' = -y, y := y + 1 at t = 1, 2. AB3 with its history restarted after each kick (RK4
    steps to start again) keeps order 3 on the piece after an event: halving the step divides the
    error at t = 1.5 and at t = 2.5 by about 8 (a history kept across the kick would mix f from both
    sides of the jump: first order)."""
    errors = []
    for internal in (Fraction(1, 40), Fraction(1, 80)):
        d = run_everywhere(me("kicked", 2, "ab3", 3.0, 0.1, internal))
        at = {round(float(t), 9): y for t, y in zip(d["time"], d["kicked.y"], strict=True)}
        errors.append([abs(at[t] - kicked_exact(t)) for t in (1.5, 2.5)])
    for before, after in zip(*errors, strict=True):
        assert 1e-12 < after < before
        assert 6.5 < before / after < 9.5, before / after


def fmpy_me(path: Path, stop: float, step: float, names: list[str]) -> np.ndarray:
    r = fmpy.simulate_fmu(
        str(path), fmi_type="ModelExchange", solver="Euler", step_size=step, stop_time=stop, output=names
    )
    # with events recorded, a point that is an event time appears before and after it: keep the later
    _, last = np.unique(np.round(r["time"][::-1] / step).astype(int), return_index=True)
    return r[len(r) - 1 - last]


@pytest.mark.parametrize("fmi", [2, 3])
def test_agrees_with_fmpy_model_exchange_euler_where_events_are_handled_alike(fmi):
    """fmpy's ME simulation with Euler at the same fixed step meets time events exactly (cuts the
    step there) and handles step events as the master does: the same values, to rounding (fmpy's
    step is t_(n+1) - t_n of its own grid). Its Euler does not locate state events (it handles them
    at the step's end): the ball agrees up to its first bounce."""
    d = api.run(me("stair", fmi, "euler", 3.0, 0.1), backend="serial").data
    ref = fmpy_me(fmu("stair", fmi), 3.0, 0.1, ["counter"])
    assert d["stair.counter"].tolist() == ref["counter"].tolist()

    d = api.run(me("kicked", fmi, "euler", 3.0, 0.1), backend="serial").data
    ref = fmpy_me(fmu("kicked", fmi), 3.0, 0.1, ["y"])
    np.testing.assert_allclose(d["kicked.y"], ref["y"], rtol=1e-13)
    assert d["kicked.y"][10] > 1.0  # kicked at t = 1

    # step events on a grid of powers of two: the same bits
    d = api.run(me("ratchet", fmi, "euler", 3.0, 0.125), backend="serial").data
    ref = fmpy_me(fmu("ratchet", fmi), 3.0, 0.125, ["x", "count"])
    assert np.array_equal(d["ratchet.x"], ref["x"]) and np.array_equal(d["ratchet.count"], ref["count"])
    assert d["ratchet.count"].tolist() == [math.floor(j / 8) for j in range(len(d))]

    d = api.run(me("bouncing_ball", fmi, "euler", 2.0, 0.01), backend="serial").data
    ref = fmpy_me(fmu("bouncing_ball", fmi), 2.0, 0.01, ["h", "v"])
    before = d["time"] < bounces(2.0)[0] - 0.01
    assert before.sum() == 45
    np.testing.assert_allclose(d["bouncing_ball.h"][before], ref["h"][before], rtol=1e-13)
    np.testing.assert_allclose(d["bouncing_ball.v"][before], ref["v"][before], rtol=1e-13, atol=1e-15)


def test_step_events_in_every_backend():
    """ratchet: the step event after the step that reaches x = 1 sets x back to 0 and counts."""
    d = run_everywhere(me("ratchet", 2, "euler", 3.0, 0.25, Fraction(1, 8)))
    assert d["ratchet.count"].tolist() == [math.floor(j / 4) for j in range(13)]
    np.testing.assert_array_equal(d["ratchet.x"], [j / 4 - math.floor(j / 4) for j in range(13)])


def test_start_up_sweeps_restore_the_pending_time_event():
    """kicked (period 0.05 s: kicks inside macro steps 0 and 1) feeding a gain through a link of
    order 2: the start-up macro steps are repeated from saved FMU states, the pending time event and
    the history with them, so kicked gives the bits it gives alone; the gain sees them."""
    me_ = ModelExchange("ab3", Fraction(1, 40))
    kicked = Component("kicked", fmu_path("kicked"), parameters={"period": 0.05}, model_exchange=me_)
    gain = Component("gain", fmu_path("gain"), extrapolation_order=2)
    coupled = Scenario(
        Path("k.ssd"),
        "k",
        (kicked, gain),
        (Connection("kicked", "y", "gain", "u"),),
        Fraction(0),
        Fraction(1),
        Fraction(1, 10),
    )
    assert api.plan(coupled).startup_sweeps > 0
    alone = run_everywhere(scene("kicked", kicked, Fraction(1), Fraction(1, 10)))
    d = run_everywhere(coupled)
    assert np.array_equal(d["kicked.y"], alone["kicked.y"])
    assert d["kicked.y"][1] > 1.0  # kicked twice by t = 0.1


@pytest.mark.parametrize("fmi", [2, 3])
@pytest.mark.parametrize("ratio_b, coupling", [(1, "jacobi"), (3, "jacobi"), (1, "gauss-seidel")])
def test_discrete_inputs_of_a_model_exchange_component_are_input_events(fmi, ratio_b, coupling):
    """FMI lets Integer and Boolean inputs change in event mode only: a Model Exchange component with
    such inputs rests in event mode between its steps, each step beginning with the event iteration.
    The discrete ring (tests/test_discrete.py) with b run as Model Exchange (Euler) gives the bits
    of b as Co-Simulation, in every backend."""
    from test_discrete import ring

    sc = ring(ratio_b, coupling)
    comps = tuple(dataclasses.replace(c, fmu_path=fmu("discrete", fmi)) for c in sc.components)
    cs_ = dataclasses.replace(sc, components=comps)
    b = dataclasses.replace(comps[1], model_exchange=ModelExchange("euler"))
    me_ = dataclasses.replace(sc, components=(comps[0], b))
    a, d = run_everywhere(cs_), run_everywhere(me_)
    assert len(np.unique(d["b.n_in"])) > 1 and len(np.unique(d["b.on_in"])) > 1  # the inputs change
    for name in a.dtype.names:
        assert np.array_equal(a[name], d[name]), name


@pytest.mark.parametrize("fmi", [2, 3])
def test_a_ball_too_slow_to_take_off_rests(fmi):
    """A bounce slower than v_min (0.1 m/s) puts the ball to rest before the bounces accumulate at
    t1 (1 + e) / (1 - e): from the closed-form time of that bounce on h = DBL_MIN, v = 0, and no
    more events (the run to 5 s ends)."""
    v1 = math.sqrt(2 * G * H0)
    last = next(k for k in range(1, 100) if E**k * v1 < 0.1)  # the bounce that ends it
    rest = bounces(3.0)[last - 1]
    d = run_everywhere(me("bouncing_ball", fmi, "rk4", 5.0, 0.01))
    t, h, v = d["time"], d["bouncing_ball.h"], d["bouncing_ball.v"]
    assert np.all(v[t > rest + 1e-6] == 0) and np.all(h[t > rest + 1e-6] == np.finfo(float).tiny)
    assert np.all(v[(t > rest - 0.02) & (t < rest - 1e-6)] != 0)  # still flying just before


@pytest.mark.parametrize("model_exchange", [True, False])
def test_an_event_iteration_that_never_ends_stops_the_run_with_one_line(model_exchange):
    """ratchet with drop = 0: at t = 1 every round changes its count and leaves x at 1."""
    make = me if model_exchange else cs
    with pytest.raises(SimulationError) as e:
        api.run(make("ratchet", 2, "euler", 3.0, 0.25, drop=0.0), backend="in-process")
    if model_exchange:
        assert str(e.value) == (
            "ratchet: its event iteration does not end (1000 rounds of fmi2NewDiscreteStates) "
            "in the step from t=0.75 to t=1.0"
        )
    else:  # the FMU's own doStep: the layer's limit, named by the FMU
        assert "the event iteration at t = 1 s does not end (100 rounds)" in str(e.value)
        assert "fmi2DoStep" in str(e.value) and "t=0.75" in str(e.value)
