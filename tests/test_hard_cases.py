"""Hard cases of the coupled scheme on real FMUs, checked against the linear stability analysis.

The two-mass oscillator (two msd FMUs) is linear, so the analysis of master.evidence.linear
is exact for it (tests/test_evidence_linear.py shows the runtime and the model agree to
round-off): predicted stability limits must be the runtime's.
"""

import dataclasses
from fractions import Fraction
from pathlib import Path

import numpy as np
import pytest

from master.api import run
from master.backends.component import SimulationError
from master.evidence.errors import as_trajectory, compare
from master.evidence.linear import largest_stable_step, spectral_radius
from master.evidence.oscillator import SET_A, TwoMass, scene, split_scheme
from master.evidence.reference import reference
from master.scenario.model import Stimulus
from master.solvers import AB3, EULER, RK4, SI_EULER, SI_MIDPOINT

# Mass 2 made stiff: eigenvalues -1 and -1000 1/s, so explicit Euler needs h < 2e-3 s there.
STIFF = TwoMass(c2=1000.0, d2=1001.0)
EULER_LIMIT = 2.0 / 1000.0


@pytest.fixture(scope="module")
def stiff_reference():
    return reference(scene(STIFF, split="force", macro_step=Fraction(1, 10)), cache_dir=None)


def test_explicit_euler_past_its_limit_on_the_stiff_side_is_reported_unstable():
    h = Fraction(1, 400)  # 1.25 x the Euler limit of mass 2
    assert spectral_radius(split_scheme(STIFF, solvers=(RK4, EULER), split="force"), float(h)) > 1.0
    with pytest.raises(SimulationError, match=r"unstable: mass2\.\w+ at t=") as err:
        run(scene(STIFF, split="force", macro_step=h, solvers=(RK4, EULER)))
    assert err.value.component == "mass2" and err.value.time < 1.0
    data = err.value.result.data  # the rows before the stop are kept, and they are numbers
    assert len(data) > 10 and all(np.isfinite(data[n]).all() for n in data.dtype.names)


@pytest.mark.parametrize("solver", [SI_EULER, SI_MIDPOINT])
def test_semi_implicit_solvers_stable_ten_times_past_the_explicit_limit(solver, stiff_reference):
    h = Fraction(1, 50)  # 10 x the Euler limit
    assert spectral_radius(split_scheme(STIFF, solvers=(RK4, solver), split="force"), float(h)) < 1.0
    with pytest.raises(SimulationError):
        run(scene(STIFF, split="force", macro_step=h, solvers=(RK4, EULER)))
    res = as_trajectory(run(scene(STIFF, split="force", macro_step=h, solvers=(RK4, solver))).data)
    x2 = np.abs(res.values["mass2.x"])
    n = len(x2) // 5
    assert x2[-n:].max() < x2[:n].max()  # decays: no growing mode
    err = compare(res, stiff_reference).worst_max
    # semi-implicit Euler damps the stiff mode (L-stable); the midpoint rule keeps it ringing
    # (|R| -> 1 for stiff modes): stable, but far less accurate at this step
    assert err < (0.05 if solver == SI_EULER else 1.0)


ORDER_TREND = dict(
    split="force", solvers=(AB3, EULER), step_ratios=(1, 10)
)  # mechanics AB3 at H, Euler at H/10


@pytest.fixture(scope="module")
def predicted_limits():
    return [
        largest_stable_step(split_scheme(SET_A, order=k, **ORDER_TREND), 1e-2, 2.0, rel_tol=1e-3)
        for k in range(4)
    ]


def test_stability_limit_barely_depends_on_the_extrapolation_order(predicted_limits):
    # the coupling force is read again at every macro step's end (resampling), so it no longer
    # lags a step: the order moves the limit by a few per cent (it halved it per order before)
    assert all(b <= a for a, b in zip(predicted_limits, predicted_limits[1:], strict=False))
    assert predicted_limits[-1] > 0.95 * predicted_limits[0]


@pytest.mark.parametrize("order", [0, 1, 2, 3])
def test_runtime_stability_limits_match_linear_analysis(order, predicted_limits):
    h_star = predicted_limits[order]
    below = Fraction(0.8 * h_star).limit_denominator(2000)
    above = Fraction(1.25 * h_star).limit_denominator(2000)
    res = run(scene(order=order, macro_step=below, stop_time=300 * below, **ORDER_TREND)).data
    x = np.abs(res["mass1.x"])
    assert x[-30:].max() < x[:30].max()
    with pytest.raises(SimulationError, match="unstable"):
        run(scene(order=order, macro_step=above, stop_time=400 * above, **ORDER_TREND))


def test_measured_growth_per_macro_step_is_the_spectral_radius(predicted_limits):
    h = Fraction(1.05 * predicted_limits[2]).limit_denominator(1000)  # rho 1.046: 300 steps to diverge
    rho = spectral_radius(split_scheme(SET_A, order=2, **ORDER_TREND), float(h))
    with pytest.raises(SimulationError) as err:
        run(scene(order=2, macro_step=h, stop_time=400 * h, **ORDER_TREND))
    x = np.abs(err.value.result.data["mass1.x"])
    w = 20  # envelope over windows of 20 macro steps (a few oscillation periods)
    env = np.array([x[i : i + w].max() for i in range(0, len(x) - w, w)])
    half = len(env) // 2
    slope = np.polyfit(w * np.arange(half, len(env)), np.log(env[half:]), 1)[0]
    assert np.exp(slope) == pytest.approx(rho, abs=3e-3)


@pytest.mark.parametrize("ratio", [20, 30])
@pytest.mark.parametrize("order", [2, 3])
def test_large_step_ratios_with_high_order_extrapolation(ratio, order):
    ref = reference(scene(split="force", macro_step=Fraction(1, 10)), cache_dir=None)
    cfg = dict(split="force", macro_step=Fraction(1, 20), solvers=(AB3, EULER), step_ratios=(1, ratio))
    assert spectral_radius(split_scheme(SET_A, order=order, **{k: cfg[k] for k in ("split", "solvers")},
                                        step_ratios=(1, ratio)), 1 / 20) < 1.0  # fmt: skip
    err = compare(as_trajectory(run(scene(order=order, **cfg)).data), ref).worst_max
    err0 = compare(as_trajectory(run(scene(order=0, **cfg)).data), ref).worst_max
    assert err < err0 / 2  # extrapolation pays off at large ratios instead of destabilising


def test_step_input_at_t0_does_not_destabilise_high_order_extrapolation():
    step = Stimulus("mass1", "F", "step", (0.0,), (1.0,))  # force step on mass 1 at the start

    def with_step(sc):
        return dataclasses.replace(sc, stimuli=(step,))

    ref = reference(with_step(scene(macro_step=Fraction(1, 10))), cache_dir=None)
    errs = []
    for order in range(4):
        sc = scene(macro_step=Fraction(1, 20), order=order, solvers=(AB3, EULER), step_ratios=(1, 20))
        errs.append(compare(as_trajectory(run(with_step(sc)).data), ref).worst_max)
    assert max(errs[2:]) < errs[0] / 1.5 and max(errs) < 0.05


def test_valve_steps_at_t0_with_high_order_extrapolation_on_the_hydraulic_scene():
    """The scene's spool steps at t = 0 with the hydraulics extrapolating the strokes with order
    2 and 3 (the scene's Jacobi coupling, Euler at H / 5): bounded, as the linearised
    analysis predicts, and body 6 follows the reference."""
    from pathlib import Path

    from master.api import load_scenario
    from master.evidence.linear import is_stable
    from master.evidence.stability import linearize

    path = Path(__file__).resolve().parents[1] / "models" / "hydraulic-manipulator" / "SystemStructure.ssd"
    sc = dataclasses.replace(load_scenario(path), stop_time=Fraction(3, 10), record_interval=Fraction(1, 100))
    assert any(s.times[0] == 0.0 for s in sc.stimuli)
    ref = reference(sc)
    lin = linearize(sc, t=0.1)
    for order in (2, 3):
        comps = tuple(dataclasses.replace(c, extrapolation_order=order if c.name == "hydraulics" else 0)
                      for c in sc.components)  # fmt: skip
        conns = tuple(dataclasses.replace(c, extrapolation_order=None) for c in sc.connections)
        orders = tuple(
            dataclasses.replace(c, order=order if c.name == "hydraulics" else 0) for c in lin.components
        )
        scheme = dataclasses.replace(lin, components=orders)
        assert is_stable(scheme, float(sc.macro_step))
        res = run(dataclasses.replace(sc, components=comps, connections=conns)).data
        rep = compare(as_trajectory(res), ref, ["mechanics.body6_z"])
        assert rep.worst_max < 0.02


HYDRAULIC = Path(__file__).resolve().parents[1] / "models" / "hydraulic-manipulator" / "SystemStructure.ssd"
NO_FRICTION = {f"mechanics.damping{k}": 0.0 for k in (1, 2, 3)}  # the cylinders' seal friction off
BODY6 = ["mechanics.body6_z", "mechanics.body6_vz", "mechanics.body6_az"]


def test_hydraulic_scene_without_seal_friction_grows_under_jacobi():
    """The paper's concurrent scheme (Jacobi, hydraulics Euler at H / 5 on quadratically
    extrapolated strokes, mechanics AB3 holding the forces, H = 1 ms) on the scene with its
    seal friction set to 0 (--set mechanics.dampingK=0): the linearised scheme grows
    (rho = 1.0011 per macro step, above the physical exp(a H)), and so does the run: the
    ringing the valve steps excite grows by the same factor per macro step (measured 1.00109
    over 1-3 s) from |a_z| = 9 m/s^2 to about 200 m/s^2 at 3 s.  The runtime's divergence stop
    (an output beyond 1e6 times its start magnitude) would need about 10 s of this growth;
    the chamber pressures reach tank and supply first (at 3.8 s), and the relief and
    anti-cavitation clamps then hold a limit cycle, so the growth is measured from the signals.
    With the friction the same scheme is stable."""
    from master.api import apply_overrides, load_scenario
    from master.evidence.linear import is_stable
    from master.evidence.stability import linearize, run_is_stable

    damped = load_scenario(HYDRAULIC)
    undamped = apply_overrides(damped, set_values=NO_FRICTION)
    assert damped.coupling == "jacobi" and damped.macro_step == Fraction(1, 1000)
    h = float(damped.macro_step)
    lin = linearize(undamped, t=0.1)
    rho = spectral_radius(lin, h)
    assert not is_stable(lin, h) and rho > 1.0005
    assert is_stable(linearize(damped, t=0.1), h)

    res = run(undamped)
    assert not run_is_stable(lambda: res)
    t, az = res.data["time"], np.abs(res.data["mechanics.body6_az"])
    w = 50  # envelope over windows of 50 macro steps (about two periods of the 37 Hz mode)
    env = np.array([az[i : i + w].max() for i in range(0, len(az) - w, w)])
    late = t[: len(env) * w : w] >= 1.0
    slope = np.polyfit(w * np.arange(len(env))[late], np.log(env[late]), 1)[0]
    assert np.exp(slope) == pytest.approx(rho, abs=1e-4)
    assert env[-1] > 10 * env[0]


def test_damped_hydraulic_scene_under_jacobi_matches_single_rate_ab3():
    """The paper's Fig. 5 claim: over 3 s the dual-rate concurrent run (the scene) and the
    whole system by AB3 at 2e-4 s differ by little in body 6's vertical position, velocity and
    acceleration.  Measured (max difference / range of the single-rate run): 8.7e-5, 3.1e-2,
    0.11; the acceleration's worst is the first millisecond after the valve steps, where the
    mechanics still hold the start forces; after 0.05 s it is below 0.05."""
    from master.api import load_scenario
    from master.evidence.stability import run_is_stable

    sc = load_scenario(HYDRAULIC)
    dual = run(sc)
    assert run_is_stable(lambda: dual)
    comps = tuple(dataclasses.replace(c, step_ratio=1, parameters={**c.parameters, "solver": AB3})
                  for c in sc.components)  # fmt: skip
    single = run(dataclasses.replace(sc, components=comps, macro_step=Fraction(2, 10000),
                                     record_interval=Fraction(1, 1000)))  # fmt: skip
    a, b = as_trajectory(dual.data), as_trajectory(single.data)
    err = compare(a, b, BODY6).max_error
    assert err["mechanics.body6_z"] < 2e-4
    assert err["mechanics.body6_vz"] < 0.06
    assert err["mechanics.body6_az"] < 0.2
    np.testing.assert_allclose(a.time, b.time, atol=1e-12)  # both recorded every 1 ms
    az, az_single = a.values["mechanics.body6_az"], b.values["mechanics.body6_az"]
    late = a.time >= 0.05
    assert np.abs(az - az_single)[late].max() < 0.05 * np.ptp(az_single)
