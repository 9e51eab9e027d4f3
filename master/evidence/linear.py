"""Linear stability analysis of a multirate Jacobi co-simulation.

Each component is linear, x' = A x + B u, y = C x + D u, integrated by one of the shared
core's fixed-step solvers (fmus/solvers, same formulas and same history handling: the
multistep history carries on across communication steps).  The coupling follows the runtime
(master/backends/component.py, master/schedule.py): a component with step ratio r makes r
communication steps of H / r per macro step and samples its outputs after each; a consumer's
input is the polynomial of order k through the source's last samples up to t_n, evaluated at
the start of each communication step and held over it ("hold"), or at every solver stage time
("polynomial"); feedthrough outputs are read with the inputs evaluated at the step's end,
and read again at the macro step's end with the sources' own samples there (the runtime's
resampling: no output lags its time label).

The scheme is linear in its extended state z = (states, solver histories, coupling history),
so one macro step is z_(n+1) = G(H) z_n; the co-simulation is stable iff rho(G) < 1.
G is built column by column by stepping unit vectors through the scheme.

Iterated macro steps (strong coupling, `LinearScheme.iterate`): after the explicit pass the macro
step is repeated from the saved states with relaxed windows (the sources' samples up to t_(n+1)
of the previous sweep, interpolated; under Gauss-Seidel those of sources that go first from the
current sweep), as the runtime's start-up sweeps do. A fixed number of sweeps keeps the map
linear. "converged" is the limit the runtime approaches as its tolerance goes to 0: the fixed
point of the sweep, y* = M y* + N z, solved exactly, which exists and is what the runtime reaches
only where the sweep contracts (rho(M) < 1, `sweep_radius`); beyond, the runtime's sweeps diverge
and the step counts as unstable.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from master.solvers import AB2, AB3, EULER, RK4, SI_EULER, SI_MIDPOINT


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
    order: int | None = None  # extrapolation order of its inputs (None: the scheme's)
    input_mode: str | None = None  # "hold" or "polynomial" (None: the scheme's `inputs`)
    model_exchange: bool = False  # integrated by the master: its inputs polynomials at every stage


@dataclass(frozen=True)
class LinearScheme:
    """Components, connections (producer, output, consumer, input), extrapolation order, input mode."""

    components: tuple[LinearComponent, ...]
    connections: tuple[tuple[str, str, str, str], ...]
    order: int = 0
    inputs: str = "hold"  # "hold" or "polynomial"
    first: tuple[str, ...] = ()  # Gauss-Seidel stepping order (empty: Jacobi)
    # iterated macro steps: 0 explicit; n > 0 that many sweeps after the explicit pass; "converged"
    # the fixed point of the sweeps (see the module docstring)
    iterate: int | str = 0

    def order_of(self, consumer: LinearComponent) -> int:
        """Extrapolation order of the consumer's inputs."""
        return self.order if consumer.order is None else consumer.order

    def max_order(self) -> int:
        """Highest order of any link (the history every sample buffer must hold)."""
        return max([self.order_of(c) for c in self.components] + [self.order])

    def stepping(self) -> tuple[LinearComponent, ...]:
        """Components in stepping order."""
        if not self.first:
            return self.components
        by_name = {c.name: c for c in self.components}
        return tuple(by_name[n] for n in self.first)

    def source_first(self, source: str, consumer: str) -> bool:
        """Gauss-Seidel: the source completes the macro step before the consumer starts it."""
        return bool(self.first) and self.first.index(source) < self.first.index(consumer)


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
            m = len(comp.outputs) * (scheme.max_order() + 1)
            self.samples[comp.name] = slice(i, i + m)
            i += m
        self.size = i


def _driver(scheme: LinearScheme, consumer: str, name: str) -> tuple[str, str] | None:
    """The (producer, output) driving input `name` of `consumer`, None if undriven."""
    return next(((p, o) for p, o, c, i in scheme.connections if c == consumer and i == name), None)


def _window(order: int, ks: int, kc: int, n: int, j: int, relaxed: bool) -> tuple[int, int]:
    """(last source sample, order used) for the consumer's step j in macro step n; relaxed:
    the source's samples up to t_(n+1) exist (a start-up sweep, or Gauss-Seidel source first)."""
    available = (n + 1) * ks if relaxed else n * ks
    j_end = min(available, -((-(j + 1) * ks) // kc))
    return j_end, min(order, j_end)


class _State:
    """One component's solver state: x, f_(n-1), f_(n-2), Delta_(n-1), steps taken."""

    def __init__(self, x, f1, f2, delta, count: int) -> None:
        self.x, self.f1, self.f2, self.delta, self.count = x, f1, f2, delta, count

    def copy(self) -> _State:
        return _State(self.x.copy(), self.f1.copy(), self.f2.copy(), self.delta.copy(), self.count)


def _advance(scheme: LinearScheme, states: dict, read: dict, write: dict, n: int, big_h: float,
             relaxed: bool = False) -> None:  # fmt: skip
    """Macro step n of every component: states in place; samples read from `read`, own new
    samples written into `write` (dicts: component -> {sample index: outputs}). An iterated
    sweep (relaxed, scheme.iterate) reads a source that goes first from `write`: its samples of
    this sweep (Gauss-Seidel waveform iteration); a start-up sweep reads every source from `read`."""
    comps = {c.name: c for c in scheme.components}
    for c in scheme.stepping():
        st = states[c.name]
        kc = c.step_ratio
        drivers = [_driver(scheme, c.name, i) for i in c.inputs]

        k_in = scheme.order_of(c)

        def inputs(j: int, at: float, drivers=drivers, kc=kc, name=c.name, k=k_in, cols=st.x.shape[1:]):
            vals = np.zeros((len(drivers), *cols))  # one column per state vector stepped side by side
            for q, d in enumerate(drivers):
                if d is None:
                    continue  # undriven: the linearisation is about its operating value
                src = comps[d[0]]
                ks, col = src.step_ratio, src.outputs.index(d[1])
                first = scheme.source_first(src.name, name)
                j_end, p = _window(k, ks, kc, n, j, relaxed or first)
                w = extrapolation_weights(p, (at * ks - j_end * kc) / kc)
                samples = write if relaxed and first and scheme.iterate else read
                vals[q] = sum(w[i] * samples[src.name][j_end - i][col] for i in range(p + 1))
            return vals

        h = big_h / kc / c.substeps
        for j in range(n * kc, n * kc + kc):
            u0 = inputs(j, j)
            for m in range(c.substeps):
                if (c.input_mode or scheme.inputs) == "hold":
                    u_of_t = _constant(u0)
                else:
                    u_of_t = _polynomial(inputs, j, (m / c.substeps), 1.0 / c.substeps)
                _solver_step(c, h, st.x, st.f1, st.f2, st.delta, u_of_t, st.count)
                st.count += 1
            u1 = inputs(j, j + 1) if len(drivers) else u0
            write[c.name][j + 1] = c.c @ st.x + (c.d @ u1 if len(u1) else 0.0)


def _resample(scheme: LinearScheme, states: dict, hist: dict, n: int) -> None:
    """After macro step n, as the runtime does (kernel.h: resample): a component with outputs that
    depend on inputs reads them again with its inputs set to the sources' samples at the macro
    step's end. Repeated once per component, so that a chain of such outputs settles in any order
    (the runtime follows it)."""
    comps = {c.name: c for c in scheme.components}
    # every component with such outputs and a driven input: where the runtime does not resample,
    # the step-end inputs were the sources' samples already and this changes nothing
    again = [c for c in scheme.components
             if np.any(c.d) and any(_driver(scheme, c.name, i) is not None for i in c.inputs)]  # fmt: skip
    for _ in range(len(again)):
        for c in again:
            u = np.zeros((len(c.inputs), *states[c.name].x.shape[1:]))
            for q, i in enumerate(c.inputs):
                d = _driver(scheme, c.name, i)
                if d is not None:
                    src = comps[d[0]]
                    u[q] = hist[src.name][(n + 1) * src.step_ratio][src.outputs.index(d[1])]
            hist[c.name][(n + 1) * c.step_ratio] = c.c @ states[c.name].x + c.d @ u


def _constant(u0: np.ndarray):
    return lambda theta: u0


def _polynomial(inputs, j: int, frac0: float, dfrac: float):
    return lambda theta: inputs(j, j + frac0 + theta * dfrac)


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


def _unpack(scheme: LinearScheme, lay: _Layout, z: np.ndarray, n: int) -> tuple[dict, dict]:
    """(solver states, sample history) of every component from the extended state z at macro step n."""
    k, cols = scheme.max_order(), z.shape[1:]
    states, hist = {}, {}
    for c in scheme.components:
        sx, s1, s2, sd = lay.slices[c.name]
        states[c.name] = _State(z[sx].copy(), z[s1].copy(), z[s2].copy(), z[sd].copy(), 2)
        ys = z[lay.samples[c.name]].reshape(k + 1, len(c.outputs), *cols)
        hist[c.name] = {n * c.step_ratio - i: ys[i] for i in range(k + 1)}
    return states, hist


def _pack(
    scheme: LinearScheme, lay: _Layout, states: dict, hist: dict, n: int, like: np.ndarray
) -> np.ndarray:
    """The extended state after macro step n (the inverse of `_unpack` at n + 1)."""
    out = np.empty_like(like)
    for c in scheme.components:
        sx, s1, s2, sd = lay.slices[c.name]
        st = states[c.name]
        out[sx], out[s1], out[s2], out[sd] = st.x, st.f1, st.f2, st.delta
        last = (n + 1) * c.step_ratio
        out[lay.samples[c.name]] = np.concatenate(
            [hist[c.name][last - i] for i in range(scheme.max_order() + 1)]
        )
    return out


def _own_samples(scheme: LinearScheme, hist: dict, n: int) -> np.ndarray:
    """The samples every component produced in macro step n (n k + 1 .. (n + 1) k), stacked: what
    a sweep changes and the next one reads."""
    return np.concatenate(
        [
            hist[c.name][j]
            for c in scheme.components
            for j in range(n * c.step_ratio + 1, (n + 1) * c.step_ratio + 1)
        ]
    )


def _sweep(scheme: LinearScheme, lay: _Layout, z: np.ndarray, y: np.ndarray, n: int, big_h: float):
    """One iterated sweep of macro step n from the extended state z, the previous sweep's own
    samples being y (`_own_samples`): (the extended state after it, resampled; its own samples)."""
    states, hist = _unpack(scheme, lay, z, n)
    previous = {name: dict(h) for name, h in hist.items()}
    i = 0
    for c in scheme.components:
        for j in range(n * c.step_ratio + 1, (n + 1) * c.step_ratio + 1):
            previous[c.name][j] = y[i : i + len(c.outputs)]
            i += len(c.outputs)
    _advance(scheme, states, previous, hist, n, big_h, relaxed=True)
    own = _own_samples(scheme, hist, n)
    _resample(scheme, states, hist, n)
    return _pack(scheme, lay, states, hist, n, z), own


def _sweep_maps(scheme: LinearScheme, big_h: float) -> tuple[np.ndarray, np.ndarray]:
    """(M, N) of the sweep's own samples y' = M y + N z (`_sweep`), from unit vectors."""
    lay = _Layout(scheme)
    n = scheme.max_order() + 1
    ny = sum(len(c.outputs) * c.step_ratio for c in scheme.components)
    m = _sweep(scheme, lay, np.zeros((lay.size, ny)), np.eye(ny), n, big_h)[1]
    nz = _sweep(scheme, lay, np.eye(lay.size), np.zeros((ny, lay.size)), n, big_h)[1]
    return m, nz


def sweep_radius(scheme: LinearScheme, big_h: float) -> float:
    """rho(M): how much one iterated sweep shrinks the difference between sweeps (< 1: the sweeps
    converge, by about this factor each)."""
    return float(np.max(np.abs(np.linalg.eigvals(_sweep_maps(scheme, big_h)[0]))))


def sweeps_needed(scheme: LinearScheme, big_h: float, tolerance: float) -> float:
    """Sweeps per macro step the runtime needs to settle to `tolerance` (relative), by the sweep's
    contraction: the sweeps that shrink a difference of order 1 below the tolerance, then the one
    that confirms it; inf where the sweeps do not converge."""
    rho = sweep_radius(scheme, big_h)
    if rho >= 1.0:
        return float("inf")
    if rho < tolerance:
        return 2.0
    return float(np.ceil(np.log(tolerance) / np.log(rho))) + 1.0


def macro_step(scheme: LinearScheme, z: np.ndarray, big_h: float) -> np.ndarray:
    """One steady macro step of size big_h (s) applied to the extended state z (a vector, or a
    matrix whose columns are stepped side by side), iterated as scheme.iterate says."""
    lay = _Layout(scheme)
    z = np.asarray(z, dtype=float)
    n = scheme.max_order() + 1  # any macro step past the start-up
    if scheme.iterate == "converged":  # the fixed point of the sweep (module docstring)
        m, nz = _sweep_maps(scheme, big_h)
        y = np.linalg.solve(np.eye(len(m)) - m, nz @ z)
        return _sweep(scheme, lay, z, y, n, big_h)[0]
    states, hist = _unpack(scheme, lay, z, n)
    _advance(scheme, states, hist, hist, n, big_h)
    if not scheme.iterate:
        _resample(scheme, states, hist, n)
        return _pack(scheme, lay, states, hist, n, z)
    y = _own_samples(scheme, hist, n)
    for _ in range(int(scheme.iterate)):
        z_next, y = _sweep(scheme, lay, z, y, n, big_h)
    return z_next


def step_matrix(scheme: LinearScheme, big_h: float) -> np.ndarray:
    """G(H): the macro-step map on the extended state (every unit vector stepped at once)."""
    return macro_step(scheme, np.eye(_Layout(scheme).size), big_h)


def spectral_radius(scheme: LinearScheme, big_h: float) -> float:
    """rho(G(H)); the co-simulation is asymptotically stable iff it is below 1."""
    return float(np.max(np.abs(np.linalg.eigvals(step_matrix(scheme, big_h)))))


def monolithic_matrix(scheme: LinearScheme) -> np.ndarray:
    """System matrix of the coupled linear system itself (no co-simulation): x' = A x with the
    connections closed, u = (I - P D)^-1 P C x (P: which output drives which input)."""
    comps = scheme.components
    nx = [c.a.shape[0] for c in comps]
    nu = [len(c.inputs) for c in comps]
    ny = [len(c.outputs) for c in comps]
    a = _block_diag([c.a for c in comps], nx, nx)
    b = _block_diag([c.b for c in comps], nx, nu)
    cm = _block_diag([c.c for c in comps], ny, nx)
    d = _block_diag([c.d for c in comps], ny, nu)
    u_index = {(c.name, i): sum(nu[:k]) + c.inputs.index(i) for k, c in enumerate(comps) for i in c.inputs}
    y_index = {(c.name, o): sum(ny[:k]) + c.outputs.index(o) for k, c in enumerate(comps) for o in c.outputs}
    p = np.zeros((sum(nu), sum(ny)))
    for src, out, dst, inp in scheme.connections:
        p[u_index[(dst, inp)], y_index[(src, out)]] = 1.0
    closed = np.linalg.solve(np.eye(sum(nu)) - p @ d, p @ cm)
    return a + b @ closed


def _block_diag(blocks: list[np.ndarray], rows: list[int], cols: list[int]) -> np.ndarray:
    out = np.zeros((sum(rows), sum(cols)))
    r = c = 0
    for blk, nr, nc in zip(blocks, rows, cols, strict=True):
        if nr and nc:
            out[r : r + nr, c : c + nc] = blk
        r, c = r + nr, c + nc
    return out


RHO_TOL = 1e-10  # relative: the rounding of the eigenvalue computation, not a stability margin


def is_stable(scheme: LinearScheme, big_h: float, growth: float | None = None) -> bool:
    """Whether the scheme adds no growth: rho(G(H)) <= exp(max(a, 0) H) (up to rounding, RHO_TOL),
    a the largest real part of the coupled system's own eigenvalues (1/s; computed if None), so
    that neutral or slowly drifting physical modes of a linearised scene are not counted."""
    return _margin(scheme, big_h, _growth(scheme) if growth is None else growth) <= 0.0


def _growth(scheme: LinearScheme) -> float:
    return float(np.max(np.linalg.eigvals(monolithic_matrix(scheme)).real))


def _margin(scheme: LinearScheme, big_h: float, growth: float) -> float:
    """How far the scheme is from stable at H: rho(G) / exp(max(a, 0) H) - 1 - RHO_TOL (> 0: it
    grows); iterated until converged, also rho(M) - 1 (> 0: the sweeps diverge)."""
    margin = spectral_radius(scheme, big_h) / np.exp(max(growth, 0.0) * big_h) - 1.0 - RHO_TOL
    if scheme.iterate == "converged":
        margin = max(margin, sweep_radius(scheme, big_h) - 1.0)
    return margin


def largest_stable_step(
    scheme: LinearScheme, h_min: float, h_max: float, rel_tol: float = 1e-3, spacing: float = 0.01
) -> float:
    """The first crossing: the largest H (s) in [h_min, h_max] such that the scheme is stable
    (`is_stable`) at every step from h_min to H, to rel_tol.

    The stability margin is sampled at geometric steps `spacing` apart (relative: 1 %) and the
    first sign change bisected. Between windows of instability the margin of a damped scheme
    falls slowly and monotonically, so a window shows as a sample above zero, or as a local
    maximum of the samples, around which the true maximum is searched (golden section): only a
    window narrower than the spacing whose rise no sample sees is missed. Returns h_max if the
    scheme is stable on the whole range, raises ValueError if h_min is unstable.
    """
    growth = _growth(scheme)

    def margin(h: float) -> float:
        return _margin(scheme, h, growth)

    grid = np.geomspace(h_min, h_max, max(3, int(np.ceil(np.log(h_max / h_min) / np.log1p(spacing))) + 1))
    m = [margin(h) for h in grid]
    if m[0] > 0:
        raise ValueError(f"unstable already at the smallest step {h_min} s")
    for i in range(1, len(grid)):
        if m[i] > 0:
            return _first_crossing(margin, grid[i - 1], grid[i], rel_tol)
        if i + 1 < len(grid) and m[i] > m[i - 1] and m[i] >= m[i + 1]:  # a peak near grid[i]
            h_peak, m_peak = _maximum(margin, grid[i - 1], grid[i + 1], rel_tol)
            if m_peak > 0:
                return _first_crossing(margin, grid[i - 1], h_peak, rel_tol)
    return h_max


def _first_crossing(margin, lo: float, hi: float, rel_tol: float) -> float:
    """Bisection: the last stable step below the crossing in (lo, hi] (margin(lo) <= 0 < margin(hi))."""
    while hi - lo > rel_tol * lo:
        mid = 0.5 * (lo + hi)
        if margin(mid) <= 0:
            lo = mid
        else:
            hi = mid
    return lo


def _maximum(margin, a: float, b: float, rel_tol: float) -> tuple[float, float]:
    """(h, margin(h)) at the maximum of the margin on [a, b] (golden section; stops early once
    the margin is positive: a crossing is all that is needed)."""
    ratio = (np.sqrt(5.0) - 1.0) / 2.0
    c, d = b - ratio * (b - a), a + ratio * (b - a)
    mc, md = margin(c), margin(d)
    while b - a > rel_tol * a and max(mc, md) <= 0:
        if mc >= md:
            b, d, md = d, c, mc
            c = b - ratio * (b - a)
            mc = margin(c)
        else:
            a, c, mc = c, d, md
            d = a + ratio * (b - a)
            md = margin(d)
    return (c, mc) if mc >= md else (d, md)


def initial_outputs(scheme: LinearScheme, x0: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """Consistent outputs at t_0 (inputs from the sources' outputs, feedthrough settled)."""
    y = {c.name: np.zeros(len(c.outputs)) for c in scheme.components}
    comps = {c.name: c for c in scheme.components}
    for _ in range(len(scheme.components) + 1):  # settles any acyclic feedthrough chain
        for c in scheme.components:
            drivers = [_driver(scheme, c.name, i) for i in c.inputs]
            u = np.array([0.0 if d is None else y[d[0]][comps[d[0]].outputs.index(d[1])] for d in drivers])
            y[c.name] = c.c @ x0[c.name] + (c.d @ u if len(u) else 0.0)
    return y


def startup(scheme: LinearScheme) -> tuple[int, int]:
    """(start-up macro steps, sweeps per step) as the runtime plans them when every FMU can
    save its state: the steps in which a link lacks samples for its order, each repeated
    (highest order) times."""
    comps = {c.name: c for c in scheme.components}
    steps, sweeps = 0, 0
    for p, _, c, _ in scheme.connections:
        ks, kc, k = comps[p].step_ratio, comps[c].step_ratio, scheme.order_of(comps[c])
        ahead = scheme.source_first(p, c)
        n = 0
        while min(_window(k, ks, kc, n, n * kc + m, ahead)[1] for m in range(kc)) < k:
            n += 1
        steps = max(steps, n)
        sweeps = max(sweeps, k)
    return (steps, sweeps) if steps else (0, 0)


def simulate(scheme: LinearScheme, x0: dict[str, np.ndarray], big_h: float, n_steps: int,
             tolerance: float = 1e-12, max_sweeps: int = 1000) -> np.ndarray:  # fmt: skip
    """States of every component at the macro points 0 .. n_steps, start-up included; shape
    (n_steps + 1, total states) in component order. Iterated as the runtime does it: every macro
    step (with `iterate`; else the start-up steps, a fixed number of times) repeated from the
    saved states; "converged": until no sample of the step changes by more than tolerance (1 +
    |sample|) between sweeps, at most max_sweeps times (then ValueError)."""
    states = {}
    for c in scheme.components:
        zeros = (np.zeros(c.a.shape[0]) for _ in range(3))
        states[c.name] = _State(np.array(x0[c.name], dtype=float), *zeros, 0)
    y0 = initial_outputs(scheme, x0)
    hist = {c.name: {0: y0[c.name]} for c in scheme.components}
    steps, sweeps = startup(scheme)
    rows = [np.concatenate([states[c.name].x for c in scheme.components])]
    for n in range(n_steps):
        saved = {name: st.copy() for name, st in states.items()}
        _advance(scheme, states, hist, hist, n, big_h)
        limit = max_sweeps if scheme.iterate == "converged" else int(scheme.iterate)
        if not scheme.iterate:
            limit = sweeps if n < steps else 0
        for s in range(limit):
            previous = {name: dict(h) for name, h in hist.items()}
            states = {name: st.copy() for name, st in saved.items()}
            _advance(scheme, states, previous, hist, n, big_h, relaxed=True)
            if scheme.iterate == "converged" and _settled(scheme, previous, hist, n, tolerance):
                break
            if s == max_sweeps - 1:
                raise ValueError(f"macro step {n}: the sweeps did not converge in {max_sweeps}")
        _resample(scheme, states, hist, n)
        rows.append(np.concatenate([states[c.name].x for c in scheme.components]))
    return np.array(rows)


def _settled(scheme: LinearScheme, previous: dict, hist: dict, n: int, tolerance: float) -> bool:
    """Whether no sample of macro step n changed by more than tolerance (1 + |sample|) (the runtime's
    convergence test)."""
    return all(
        np.all(np.abs(hist[c.name][j] - previous[c.name][j]) <= tolerance * (1.0 + np.abs(hist[c.name][j])))
        for c in scheme.components
        for j in range(n * c.step_ratio + 1, (n + 1) * c.step_ratio + 1)
    )
