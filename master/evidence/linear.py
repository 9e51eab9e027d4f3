"""Linear stability analysis of a multirate Jacobi co-simulation.

Each component is linear, x' = A x + B u, y = C x + D u, integrated by one of the shared
core's fixed-step solvers (fmus/solvers, same formulas and same history handling: the
multistep history carries on across communication steps).  Coupling signals are sampled at
macro-step points t_n and extrapolated by a polynomial of order k through y(t_n), ...,
y(t_{n-k}).  A component with step ratio r makes r communication steps of H / r per macro
step; its inputs are the polynomial evaluated at the start of each communication step and
held over it ("hold"), or evaluated at every solver stage time ("polynomial").

The scheme is linear in its extended state z = (states, solver histories, coupling history),
so one macro step is z_(n+1) = G(H) z_n; the co-simulation is stable iff rho(G) < 1.
G is built column by column by stepping unit vectors through the scheme.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

EULER, AB2, AB3, RK4, SI_EULER, SI_MIDPOINT = 1, 2, 3, 4, 5, 6


@dataclass(frozen=True)
class LinearComponent:
    """One linear component: x' = a x + b u, y = c x + d u, solved by `solver` (SolverKind value).

    substeps: solver steps per communication step (communication step / internal_step).
    """

    name: str
    a: np.ndarray
    b: np.ndarray
    c: np.ndarray
    d: np.ndarray
    inputs: tuple[str, ...]
    outputs: tuple[str, ...]
    solver: int = RK4
    step_ratio: int = 1
    substeps: int = 1


@dataclass(frozen=True)
class LinearScheme:
    """Components, connections (producer, output, consumer, input), extrapolation order, input mode."""

    components: tuple[LinearComponent, ...]
    connections: tuple[tuple[str, str, str, str], ...]
    order: int = 0
    inputs: str = "hold"  # "hold" or "polynomial"


def extrapolation_weights(order: int, s: float) -> np.ndarray:
    """Lagrange weights of samples at t_n, t_(n-1), ..., t_(n-order) for the value at t_n + s H."""
    nodes = -np.arange(order + 1, dtype=float)
    w = np.ones(order + 1)
    for j in range(order + 1):
        for m in range(order + 1):
            if m != j:
                w[j] *= (s - nodes[m]) / (nodes[j] - nodes[m])
    return w


class _Layout:
    """Index ranges of the extended state z.

    Per component: x, f_(n-1), f_(n-2), Delta_(n-1) (solver histories), then its last
    order + 1 output samples (newest first), as the runtime's history ring buffer holds them.
    """

    def __init__(self, scheme: LinearScheme) -> None:
        self.slices: dict[str, tuple[slice, ...]] = {}
        self.samples: dict[str, slice] = {}
        i = 0
        for comp in scheme.components:
            n = comp.a.shape[0]
            self.slices[comp.name] = tuple(slice(i + j * n, i + (j + 1) * n) for j in range(4))
            i += 4 * n
            m = len(comp.outputs) * (scheme.order + 1)
            self.samples[comp.name] = slice(i, i + m)
            i += m
        self.size = i


def _driver(scheme: LinearScheme, consumer: str, name: str) -> tuple[str, str] | None:
    """The (producer, output) driving input `name` of `consumer`, None if undriven."""
    return next(((p, o) for p, o, c, i in scheme.connections if c == consumer and i == name), None)


def _inputs(columns: list, t: float, big_h: float) -> np.ndarray:
    """Inputs at t (s after t_n): polynomials through each source's samples up to t_n."""
    vals = []
    for col in columns:
        if col is None:
            vals.append(0.0)  # undriven: the linearisation is about its operating value
            continue
        ys, ratio = col
        vals.append(float(extrapolation_weights(len(ys) - 1, t * ratio / big_h) @ ys))
    return np.array(vals)


def _solver_step(comp: LinearComponent, h: float, x, f1, f2, delta, u_of_t, count: int = 2) -> None:
    """One step of the component's solver in place (x, histories), u_of_t(theta) input at t + theta h.

    count: steps already taken (the solver's history length); as fmus/solvers does it, AB2/AB3
    start with RK4 steps and the semi-implicit midpoint rule with one semi-implicit Euler step.
    """

    def f(xv, theta):
        u = u_of_t(theta)
        return comp.a @ xv + (comp.b @ u if len(u) else 0.0)

    fn = f(x, 0.0)
    kind = comp.solver
    if (kind == AB2 and count < 1) or (kind == AB3 and count < 2):
        kind = RK4
    elif kind == SI_MIDPOINT and count < 1:
        kind = SI_EULER
    if kind == EULER:
        x += h * fn
    elif kind == AB2:
        x += h * (3.0 * fn - f1) / 2.0
    elif kind == AB3:
        x += h * (23.0 * fn - 16.0 * f1 + 5.0 * f2) / 12.0
    elif kind == RK4:
        k2 = f(x + 0.5 * h * fn, 0.5)
        k3 = f(x + 0.5 * h * k2, 0.5)
        k4 = f(x + h * k3, 1.0)
        x += h / 6.0 * (fn + 2.0 * k2 + 2.0 * k3 + k4)
    elif kind in (SI_EULER, SI_MIDPOINT):
        m = np.eye(len(x)) - h * comp.a
        if kind == SI_EULER:
            d_new = np.linalg.solve(m, h * fn)
        else:
            d_new = delta + 2.0 * np.linalg.solve(m, h * fn - delta)
        delta[:] = d_new
        x += d_new
    else:
        raise ValueError(f"component {comp.name!r}: unknown solver {kind}")
    if comp.solver not in (SI_EULER, SI_MIDPOINT):
        delta[:] = 0.0  # unused memory must not persist (it would add an eigenvalue 1 to G)
    f2[:] = f1
    f1[:] = fn


def macro_step(scheme: LinearScheme, z: np.ndarray, big_h: float, n: int | None = None) -> np.ndarray:
    """One Jacobi macro step of size big_h (s) applied to the extended state z.

    As master/backends/component.py does it: the consumer's input for its communication step
    starting at t is the polynomial through the source's samples up to t_n evaluated at t;
    after each communication step the component samples its outputs, y = C x + D u with the
    input u it held over that step (the FMU restores the set value after the step).
    n: index of the macro step, to reproduce the start-up (lower orders, solver start-up);
    None: the steady scheme (full histories), as the stability analysis needs it.
    """
    lay = _Layout(scheme)
    z = np.asarray(z, dtype=float)
    k = scheme.order
    comps = {c.name: c for c in scheme.components}
    # samples[name][i]: outputs of `name` at its communication point t_n - i h_name
    samples = {c.name: z[lay.samples[c.name]].reshape(k + 1, len(c.outputs)) for c in scheme.components}
    out = z.copy()
    for c in scheme.components:
        sx, s1, s2, sd = lay.slices[c.name]
        x, f1, f2, delta = out[sx], out[s1], out[s2], out[sd]  # views into out
        columns = []
        for name in c.inputs:
            d = _driver(scheme, c.name, name)
            src = comps[d[0]] if d else None
            used = k if n is None else min(k, n * src.step_ratio)  # start-up: samples that exist
            columns.append(
                (samples[src.name][: used + 1, src.outputs.index(d[1])], src.step_ratio) if d else None
            )
        h_comm = big_h / c.step_ratio
        h = h_comm / c.substeps
        new = []
        for j in range(c.step_ratio):
            t_comm = j * h_comm  # step start, s after t_n
            u0 = _inputs(columns, t_comm, big_h)
            for m in range(c.substeps):
                t0 = t_comm + m * h
                if scheme.inputs == "hold":
                    u_of_t = _constant(u0)
                else:
                    u_of_t = _polynomial(columns, t0, h, big_h)
                count = 2 if n is None else n * c.step_ratio * c.substeps + j * c.substeps + m
                _solver_step(c, h, x, f1, f2, delta, u_of_t, count)
            new.append(c.c @ x + (c.d @ u0 if len(u0) else 0.0))
        hist = np.vstack([np.array(new[::-1]).reshape(-1, len(c.outputs)), samples[c.name]])[: k + 1]
        out[lay.samples[c.name]] = hist.ravel()
    return out


def _constant(u0: np.ndarray):
    return lambda theta: u0


def _polynomial(columns: list, t0: float, h: float, big_h: float):
    return lambda theta: _inputs(columns, t0 + theta * h, big_h)


def step_matrix(scheme: LinearScheme, big_h: float) -> np.ndarray:
    """G(H): the macro-step map on the extended state."""
    n = _Layout(scheme).size
    return np.column_stack([macro_step(scheme, e, big_h) for e in np.eye(n)])


def spectral_radius(scheme: LinearScheme, big_h: float) -> float:
    """rho(G(H)); the co-simulation is asymptotically stable iff it is below 1."""
    return float(np.max(np.abs(np.linalg.eigvals(step_matrix(scheme, big_h)))))


def largest_stable_step(scheme: LinearScheme, h_min: float, h_max: float, rel_tol: float = 1e-3) -> float:
    """Largest H (s) in [h_min, h_max] below which rho(G) < 1, scanning up then bisecting.

    Returns h_max if the scheme is stable on the whole scan, raises ValueError if h_min is unstable.
    """
    if spectral_radius(scheme, h_min) >= 1.0:
        raise ValueError(f"unstable already at the smallest step {h_min} s")
    grid = np.geomspace(h_min, h_max, 60)
    lo = h_min
    for h in grid[1:]:
        if spectral_radius(scheme, h) >= 1.0:
            hi = h
            break
        lo = h
    else:
        return h_max
    while hi - lo > rel_tol * lo:
        mid = 0.5 * (lo + hi)
        if spectral_radius(scheme, mid) < 1.0:
            lo = mid
        else:
            hi = mid
    return lo


def initial_state(scheme: LinearScheme, x0: dict[str, np.ndarray]) -> np.ndarray:
    """Extended state at the start: states x0 (per component), consistent output samples at t_0."""
    lay = _Layout(scheme)
    z = np.zeros(lay.size)
    y = {c.name: np.zeros(len(c.outputs)) for c in scheme.components}
    for _ in range(len(scheme.components) + 1):  # settles any acyclic feedthrough chain
        for c in scheme.components:
            u = np.array([0.0 if d is None else y[d[0]][_index(scheme, d)] for d in
                          (_driver(scheme, c.name, i) for i in c.inputs)])  # fmt: skip
            y[c.name] = c.c @ x0[c.name] + (c.d @ u if len(u) else 0.0)
    for c in scheme.components:
        z[lay.slices[c.name][0]] = x0[c.name]
        z[lay.samples[c.name]][: len(c.outputs)] = y[c.name]
    return z


def _index(scheme: LinearScheme, driver: tuple[str, str]) -> int:
    comp = next(c for c in scheme.components if c.name == driver[0])
    return comp.outputs.index(driver[1])


def simulate(scheme: LinearScheme, x0: dict[str, np.ndarray], big_h: float, n_steps: int) -> np.ndarray:
    """States of every component at the macro points 0 .. n_steps, start-up included; shape
    (n_steps + 1, total states) in component order."""
    lay = _Layout(scheme)
    z = initial_state(scheme, x0)
    idx = np.concatenate([np.arange(lay.size)[lay.slices[c.name][0]] for c in scheme.components])
    out = [z[idx]]
    for n in range(n_steps):
        z = macro_step(scheme, z, big_h, n)
        out.append(z[idx])
    return np.array(out)
