"""Stability of a scene's co-simulation: linearised analysis and measured limits.

- `linearize` turns a scene of Model Exchange FMUs into a LinearScheme about an operating
  point (central differences of each component's derivatives and coupled outputs with respect
  to its states and coupled inputs), so master.evidence.linear can give the spectral radius
  of the macro-step map and the largest stable macro step.
- `measured_limit` finds the largest stable macro step of the runtime itself by bisection on
  runs: a run is stable if it finishes and its recorded signals end smaller than the largest
  value they reach in its first fifth, relative to their range (no growing mode).
"""

from __future__ import annotations

from collections.abc import Callable
from fractions import Fraction

import numpy as np
from scipy.integrate import solve_ivp

from master.evidence.linear import LinearComponent, LinearScheme
from master.evidence.reference import _DOUBLE_P, _Scene, break_points
from master.recorder import signal_columns
from master.scenario.model import Scenario, Scheme
from master.schedule import stepping_order
from master.solvers import NUMBERS


def state_at(scene: _Scene, scenario: Scenario, t: float, rtol: float = 1e-8) -> np.ndarray:
    """Concatenated states (FMU units) of the monolithic scene at time t (s)."""
    x = scene.initial_state()
    for a, b in zip(break_points(scenario)[:-1], break_points(scenario)[1:], strict=True):
        if a >= t:
            break
        scene.segment_start = a
        end = min(b, t)
        sol = solve_ivp(scene.rhs, (a, end), x, method="Radau", rtol=rtol, atol=1e-10)
        if not sol.success:
            raise RuntimeError(f"{scenario.path}: integration to the operating point failed: {sol.message}")
        x = sol.y[:, -1]
    return x


def _component_map(scene: _Scene, name: str, t: float, inputs: list[str], outputs: list[str]):
    """(x_i, u_i) -> (f_i, y_i) of one component at time t, other inputs as last set."""
    m = scene.members[name]
    dx = np.zeros(m.n)

    def f(x: np.ndarray, u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        m.fmu.setTime(t)
        if m.n:
            m.x[:] = x
            m.fmu.setContinuousStates(m.x.ctypes.data_as(_DOUBLE_P), m.n)
        if inputs:
            m.fmu.setReal([m.vr[i] for i in inputs], list(map(float, u)))
        if m.n:
            m.fmu.getDerivatives(dx.ctypes.data_as(_DOUBLE_P), m.n)
        y = np.array(m.fmu.getReal([m.vr[o] for o in outputs])) if outputs else np.zeros(0)
        return dx.copy(), y

    return f


def _jacobians(f, x0: np.ndarray, u0: np.ndarray, rel: float = 1e-6):
    """Central-difference Jacobians of (f, y) with respect to x and u."""
    f0, y0 = f(x0, u0)
    cols = {"x": [], "u": []}
    for key, base in (("x", x0), ("u", u0)):
        for j in range(len(base)):
            d = rel * max(abs(base[j]), 1e-3)
            hi, lo = base.copy(), base.copy()
            hi[j] += d
            lo[j] -= d
            args_hi = (hi, u0) if key == "x" else (x0, hi)
            args_lo = (lo, u0) if key == "x" else (x0, lo)
            (fh, yh), (fl, yl) = f(*args_hi), f(*args_lo)
            cols[key].append((np.concatenate([fh, yh]) - np.concatenate([fl, yl])) / (2 * d))
    nx = len(f0)

    def split(c: list, n: int) -> tuple[np.ndarray, np.ndarray]:
        if not c:
            return np.zeros((nx, 0)), np.zeros((len(y0), 0))
        m = np.array(c).T
        return m[:nx], m[nx:]

    a, c = split(cols["x"], len(x0))
    b, d = split(cols["u"], len(u0))
    return a, b, c, d


def linearize(scenario: Scenario, t: float = 0.0, order: int | None = None) -> LinearScheme:
    """The scene linearised about its monolithic solution at time t (s), as a LinearScheme.

    Each component is modelled as the runtime steps it (master.api.plan): its effective step
    ratio, its inputs held or as polynomials (an FMU that interpolates its inputs: one doStep per
    macro step), its solver (parameter "solver") and its solver steps per communication step
    (parameter "internal_step"; 0: one); a Model Exchange component its `solver` and `internalStep`,
    its inputs as polynomials; iterated macro steps as their converged fixed point. order: the
    extrapolation order (default: the largest of the scene's components).
    """
    from master.api import plan as make_plan

    schedule = make_plan(scenario)
    scene = _Scene(scenario)
    try:
        x_all = state_at(scene, scenario, t)
        scene.segment_start = max(p for p in break_points(scenario)[:-1] if p <= t)
        scene.evaluate(t, x_all)  # every input at its operating value
        comps = []
        for comp in scenario.components:
            m = scene.members[comp.name]
            ins = [c.end_connector for c in scenario.connections if c.end_component == comp.name]
            outs = [c.start_connector for c in scenario.connections if c.start_component == comp.name]
            outs = list(dict.fromkeys(outs))
            u0 = np.array(m.fmu.getReal([m.vr[i] for i in ins])) if ins else np.zeros(0)
            x0 = x_all[m.offset : m.offset + m.n]
            a, b, c, d = _jacobians(_component_map(scene, comp.name, t, ins, outs), x0, u0)
            if ins:  # back to the operating point for the next component's reads
                m.fmu.setReal([m.vr[i] for i in ins], list(map(float, u0)))
            solver = int(comp.parameters.get("solver", m.fmu.getInteger([m.vr["solver"]])[0]))
            k_in = comp.extrapolation_order if order is None else order
            pc = schedule.component(comp.name)
            internal = float(comp.parameters.get("internal_step", m.fmu.getReal([m.vr["internal_step"]])[0]))
            substeps = max(1, round(float(pc.step) / internal)) if internal > 0 else 1
            mode = "polynomial" if pc.interpolate_inputs else "hold"
            if pc.model_exchange:  # the master integrates it: its method, its steps, inputs at every stage
                me = pc.model_exchange
                solver, substeps, mode = NUMBERS[me.solver], me.substeps(pc.step) or 1, "polynomial"
            me = pc.model_exchange is not None
            comps.append(LinearComponent(comp.name, a, b, c, d, tuple(ins), tuple(outs), solver=solver,
                                         step_ratio=pc.step_ratio, substeps=substeps, order=k_in,
                                         input_mode=mode, model_exchange=me))  # fmt: skip
        conns = tuple((c.start_component, c.start_connector, c.end_component, c.end_connector)
                      for c in scenario.connections)  # fmt: skip
        k = order if order is not None else max(c.extrapolation_order for c in scenario.components)
        first = tuple(stepping_order(scenario)) if scenario.coupling == Scheme.GAUSS_SEIDEL else ()
        iterate = "converged" if scenario.iteration is not None else 0  # the runtime's iterated steps
        return LinearScheme(tuple(comps), conns, order=k, first=first, iterate=iterate)
    finally:
        scene.close()


def run_is_stable(run: Callable[[], object]) -> bool:
    """Whether a run finishes with no growing mode (see the module docstring)."""
    from master.backends.component import SimulationError

    try:
        data = run().data  # type: ignore[attr-defined]
    except SimulationError:
        return False
    names = signal_columns(data)  # recorded coupling errors are no mode of the system
    n = max(len(data) // 5, 1)
    for name in names:
        y = np.asarray(data[name], dtype=float)
        if not np.all(np.isfinite(y)):
            return False
        span = float(np.ptp(y[:n])) or 1.0
        dev_end = float(np.ptp(y[-n:]))
        if dev_end > 2.0 * span:
            return False
    return True


RunCheck = Callable[[Callable[[], object]], bool]  # judges one run: stable or not


def measured_limit(make_run: Callable[[Fraction], Callable[[], object]], lo: Fraction, hi: Fraction,
                   rel_tol: float = 0.02, max_den: int = 100000,
                   is_stable: RunCheck = run_is_stable) -> Fraction:  # fmt: skip
    """Largest macro step in [lo, hi] (s) at which make_run(H)() is stable, by bisection.

    lo must be stable; returns hi if hi is stable.  is_stable judges one run (default
    run_is_stable; a scene whose growth saturates early needs its own test).
    """
    if not is_stable(make_run(lo)):
        raise ValueError(f"unstable already at the lower bound {float(lo):g} s")
    if is_stable(make_run(hi)):
        return hi
    while hi - lo > rel_tol * lo:
        mid = Fraction((lo + hi) / 2).limit_denominator(max_den)
        if mid in (lo, hi):
            break
        if is_stable(make_run(mid)):
            lo = mid
        else:
            hi = mid
    return lo
