"""One component's work in the multirate algorithm, written once for every backend.

`ComponentRunner.macro_step(n)` advances one FMU through macro step n: it evaluates its coupling
polynomials for all its communication points of the macro step at once from the source
histories, then at each point sets its inputs (one raw FMI call), steps, and reads its outputs
straight into its own history (one raw call, only where a consumer or the recorder uses the
sample). Serial and parallel backends both call exactly this code, so they produce
bit-identical results. Times are in seconds.
"""

from __future__ import annotations

import ctypes
import math
import sys
import time

import numpy as np

from master.coupling import History, LinkBlock, stimulus_span, stimulus_value, weights
from master.fmu import NO_STATE_RESTORED, OK_STATUS, Fmu, FmuError
from master.scenario.model import Component, Scenario
from master.schedule import Link, Plan, PlanComponent


class SimulationError(Exception):
    """A run stopped: names the component, the variable or cause, and the simulation time (s)."""

    def __init__(self, message: str, component: str, time: float, variable: str | None = None):
        super().__init__(message)
        self.component = component
        self.variable = variable
        self.time = time


# An output beyond this many times its start magnitude (at least 1) has diverged.
GROWTH_LIMIT = 1e6

UNSTABLE_HINT = (
    "hint: the coupled system is unstable at these settings; try a smaller macro step, "
    "a semi-implicit solver in the stiff component, or a lower extrapolation order"
)


def history_capacity(plan: Plan, name: str) -> int:
    """Samples in the ring of `name`'s outputs: k + p + 2, p the highest order of its links.

    In macro step n the component writes samples n k+1 .. (n+1) k while a consumer of order p
    may still read n k-p .. n k (Jacobi: in another process at the same time), so k + p + 1
    samples must coexist; the ring keeps one more. p counts links into `name` as well as out
    of it, which only enlarges the ring.
    """
    pc = plan.component(name)
    p = max((lk.order for lk in plan.links if name in (lk.source, lk.consumer)), default=0)
    return pc.ratio + p + 2


def output_names(plan: Plan, name: str, variables: dict) -> list[str]:
    """Real variables of `name` read at each communication point: coupled outputs, then recorded."""
    out: list[str] = []
    for lk in plan.links:
        if lk.source == name:
            out.extend(o for o in lk.outputs if o not in out)
    for comp, var in plan.record:
        if comp == name and var not in out and variables[var].type == "Real":
            out.append(var)
    return out


class _InLink:
    """A link as the consumer evaluates it: all its steps of a macro step in one `LinkBlock`.

    Blocks b of the consumer's input array: the values at the step start (b = 0), at the step
    end (b = 1, for direct feedthrough) and the derivatives d = 1..D at the step start (units/s^d,
    for FMUs that interpolate inputs). Step m of macro step n uses source samples
    j_end - i, i = 0..order, with (j_end, p) = `Link.window`; terms beyond p (start-up) get weight 0
    on sample j_end, derivatives beyond p are 0. Weights and offsets depend on n only at start-up,
    so they are cached.
    """

    def __init__(
        self, link: Link, columns: np.ndarray, slots: slice, blocks: list[tuple[int, int]], step_s: float
    ):
        self.link = link
        self.source, self.k_source = link.source, link.k_source
        self.columns = columns
        self.slots = slots
        self.blocks = blocks  # (step offset of the evaluation point, derivative order) per block
        self.scale = [step_s**d for _, d in blocks]  # source step (s) ** derivative order
        # from this macro step on every step uses the full order (per relaxed flag)
        self.steady = {r: next(n for n in range(link.order + 2) if self._full(n, r)) for r in (False, True)}
        self._blocks: dict[object, LinkBlock] = {}
        self._steady: LinkBlock | None = None  # the block of every steady, not relaxed macro step

    def _full(self, n: int, relaxed: bool) -> bool:
        kc = self.link.k_consumer
        return all(self.link.window(n, n * kc + m, relaxed)[1] == self.link.order for m in range(kc))

    def block(self, n: int, relaxed: bool) -> LinkBlock:
        """The LinkBlock of macro step n (shared by all steady macro steps)."""
        if not relaxed and n >= self.steady[False] and self._steady is not None:
            return self._steady
        key = relaxed if n >= self.steady[relaxed] else (n, relaxed)
        b = self._blocks.get(key)
        if b is None:
            b = self._blocks[key] = self._make(n, relaxed)
            if key is False:
                self._steady = b
        return b

    def _make(self, n: int, relaxed: bool) -> LinkBlock:
        lk = self.link
        ks, kc, terms = lk.k_source, lk.k_consumer, lk.order + 1
        offsets = np.zeros((terms, kc), dtype=np.intp)
        w = np.zeros((len(self.blocks), terms, kc))
        zero = np.zeros((len(self.blocks), kc), dtype=bool)
        for m in range(kc):
            j = n * kc + m
            j_end, p = lk.window(n, j, relaxed)
            offsets[:, m] = j_end - n * ks - np.minimum(np.arange(terms), p)
            for b, (shift, d) in enumerate(self.blocks):
                if d <= p:
                    w[b, : p + 1, m] = weights(p, (j + shift) * ks - j_end * kc, kc, d)
                zero[b, m] = d > p
        return LinkBlock(self.columns, offsets, w, zero)


class ComponentRunner:
    """Runs one FMU through the plan; owns its output history.

    Per macro step: every link's polynomials for all its steps at once (input array `u`,
    blocks as in `_InLink`), then per step raw FMI calls on prepared pointers (inputs from a row
    of `u`, outputs straight into the history ring), then one divergence check of the history.
    history: the ring the outputs go to (`history_capacity` rows, one column per output name),
    e.g. in shared memory; None: a private one.
    """

    def __init__(
        self,
        plan: Plan,
        pc: PlanComponent,
        fmu: Fmu,
        out_names: dict[str, list[str]],
        history: History | None = None,
    ):
        self.pc = pc
        self.fmu = fmu
        self.name = pc.name
        self.clock = pc.clock
        self.h = float(pc.step)
        self.out = fmu.real_port(out_names[pc.name])
        links = plan.links_into(pc.name)
        stimuli = [s for s in plan.stimuli if s.component == pc.name]
        in_names = [i for lk in links for i in lk.inputs] + [s.variable for s in stimuli]
        self.inp = fmu.real_port(in_names)
        # outputs that depend directly on driven inputs need those inputs at the end of each step
        self.feedthrough = self.inp.n > 0 and any(o in fmu.feedthrough for o in self.out.names)
        k = pc.ratio
        n_in = self.inp.n
        self.n_values = nv = 2 if self.feedthrough else 1  # value blocks of u: step start (and end)
        blocks = [(0, 0), (1, 0)][:nv] + [(0, d) for d in range(1, pc.derivative_order + 1)]
        # u[m, b, i]: input i for step m of the macro step, block b (values, then derivatives);
        # each u[m] is one contiguous run for the FMI calls
        self.u = np.zeros((k, len(blocks), n_in))
        self.links: list[_InLink] = []
        self._link_out: list[np.ndarray] = []  # each link's (block, step, input) view of u
        self._scaled: list[tuple[np.ndarray, np.ndarray]] = []  # (derivative view of u, h_s ** d)
        pos = 0
        for lk in links:
            src_names = out_names[lk.source]
            cols = np.array([src_names.index(o) for o in lk.outputs], dtype=np.intp)
            sl = slice(pos, pos + len(lk.inputs))
            il = _InLink(lk, cols, sl, blocks, float(plan.component(lk.source).step))
            self.links.append(il)
            self._link_out.append(self.u[:, :, sl].swapaxes(0, 1))
            if len(blocks) > nv:
                self._scaled.append((self.u[:, nv:, sl], np.array(il.scale[nv:])[:, np.newaxis]))
            pos = sl.stop
        self.stimuli = [(pos + i, s, _start_value(fmu, s.variable)) for i, s in enumerate(stimuli)]
        self._stim_steps = (1, 0)  # communication points i0 <= i < i1 at which u holds the stimuli
        self._stim_last = k - 2 + nv  # last communication point a macro step evaluates, from its first
        # every derivative of every input (zero for stimuli) in one call per step, straight from u[m]
        self._deriv = None
        if len(blocks) > nv:
            nd = (len(blocks) - nv) * n_in
            vrs = (ctypes.c_uint * nd)(*(list(self.inp.vrs)[:n_in] * (len(blocks) - nv)))
            orders = (ctypes.c_int * nd)(*[d for _, d in blocks[nv:] for _ in range(n_in)])
            ptrs = [ctypes.c_void_p(self.u[m, nv].ctypes.data) for m in range(k)]
            self._deriv = (vrs, ctypes.c_size_t(nd), orders, ptrs)
        self._u_rows = [[ctypes.c_void_p(self.u[m, b].ctypes.data) for m in range(k)] for b in range(nv)]
        cap = history_capacity(plan, pc.name)
        if history is None:
            history = History(self.out.n, cap)
        elif history.buf.shape != (cap, self.out.n):
            raise ValueError(
                f"{self.name}: output history of shape {history.buf.shape}, {(cap, self.out.n)} needed"
            )
        self.history = history
        self.reads = samples_read(plan, pc.name)  # reads[m]: outputs are read after step m
        self._rows_of: np.ndarray | None = None  # the history buffer `_rows` point into
        self.fmu_time = 0.0  # wall time inside FMI calls (s)
        self.bound: np.ndarray | None = None  # divergence bound per output, from the start values
        self.steps = 0
        # (column in the result row, column in the history) / (column, variable name)
        self.record_real: list[tuple[int, int]] = []
        self.record_other: list[tuple[int, str]] = []
        for i, (c, v) in enumerate(plan.record):
            if c == pc.name and v in self.out.names:
                self.record_real.append((1 + i, self.out.names.index(v)))
            elif c == pc.name:
                self.record_other.append((1 + i, v))
        dst = [i for i, _ in self.record_real]
        self._rec_src = np.array([c for _, c in self.record_real], dtype=np.intp)
        contiguous = dst == list(range(dst[0], dst[0] + len(dst))) if dst else False
        self._rec_dst: slice | np.ndarray = (
            slice(dst[0], dst[0] + len(dst)) if contiguous else np.array(dst, dtype=np.intp)
        )

    def _bind_history(self) -> None:
        """Prepare the stepping loop for the current history buffer (it may be replaced, e.g. by
        shared memory): pointers to its rows, everything the loop reads, the divergence screen."""
        buf = self.history.buf
        if not buf.flags.c_contiguous or buf.dtype != np.float64:
            raise ValueError(f"{self.name}: the output history must be a C-contiguous float64 array")
        if self.bound is None:
            self.bound = GROWTH_LIMIT * np.maximum(1.0, np.abs(buf[0]))
        rows = [ctypes.c_void_p(buf.ctypes.data + r * buf.strides[0]) for r in range(buf.shape[0])]
        # sum over the ring of (y / bound)^2 <= 1 proves every sample within bounds (NaN fails it)
        self._flat = buf.reshape(-1)
        self._squares = np.empty_like(self._flat)
        self._inv_bound2 = np.tile(1.0 / self.bound**2, buf.shape[0])
        fmu = self.fmu
        d = self._deriv or (None,) * 4
        self._calls = (fmu, fmu.handle, fmu.raw_set_real, fmu.raw_get_real, fmu.raw_do_step)
        self._calls += (fmu.raw_set_input_derivatives if self._deriv else None,)
        self._args = (self.inp.vrs, self.inp.count, self.out.vrs, self.out.count, *d[:3])
        self._flags = (self.inp.n > 0, self.out.n > 0, self.feedthrough, self._deriv is not None, self.reads)
        self._pointers = (self._u_rows[0], self._u_rows[-1], d[3], rows)
        self._steps = (
            self.clock.num0,
            self.clock.dnum,
            self.clock.den,
            ctypes.c_double(self.h),
            self.pc.ratio,
        )
        self._rows_of = buf

    # -- inputs ---------------------------------------------------------------------------------
    def _fill_inputs(self, n: int, histories: dict[str, History], relaxed: bool) -> None:
        """The input array `u` for macro step n: every link's polynomials, then the stimuli."""
        for il, out in zip(self.links, self._link_out, strict=True):
            il.block(n, relaxed).evaluate(histories[il.source], n * il.k_source, out)
        for view, divisor in self._scaled:
            np.divide(view, divisor, view)
        if self.stimuli:
            j0 = n * self.pc.ratio
            i0, i1 = self._stim_steps
            if not (i0 <= j0 and j0 + self._stim_last < i1):
                self._fill_stimuli(j0)

    def _fill_stimuli(self, j0: int) -> None:
        """Stimulus columns of the value blocks of u for the macro step from point j0."""
        u, nv, clock = self.u, self.n_values, self.clock
        t0 = clock.time(j0)
        lo, hi = -np.inf, np.inf
        for slot, s, start in self.stimuli:
            v, a, b = stimulus_span(s, t0, start)
            lo, hi = max(lo, a), min(hi, b)
            u[:, :nv, slot] = v
        # these values hold from point j0 up to the first point at or after hi (lo <= t0 always)
        if hi == np.inf:
            i1 = sys.maxsize
        else:
            i1 = max(j0, math.ceil((hi * clock.den - clock.num0) / clock.dnum))  # estimate, then exact
            while i1 > j0 and clock.time(i1 - 1) >= hi:
                i1 -= 1
            while clock.time(i1) < hi:
                i1 += 1
        if j0 + self._stim_last < i1:  # for the whole macro step: u keeps them until then
            self._stim_steps = (j0, i1)
            return
        self._stim_steps = (1, 0)  # they change within the macro step: point by point
        for m in range(self.pc.ratio):
            for b in range(nv):
                t = clock.time(j0 + m + b)
                for slot, s, start in self.stimuli:
                    u[m, b, slot] = stimulus_value(s, t, start)

    # -- stepping -------------------------------------------------------------------------------
    def initial_sweep(self, histories: dict[str, History]) -> None:
        """In initialisation mode: set inputs from the sources' current outputs, read own outputs."""
        t0 = perf()
        try:
            self._fill_initial(histories)
            self.inp.set()
            self.out.get()
        except FmuError as e:
            raise SimulationError(f"{e} at t={self.clock.time(0)}", self.name, self.clock.time(0)) from e
        finally:
            self.fmu_time += perf() - t0
        self.history.push(0, self.out.values)

    def exit_initialization(self) -> None:
        """Leave initialisation mode; a failure is named with the component and the start time."""
        self.fmu_call(0, self.fmu.exit_initialization)

    def fmu_call(self, n: int, fn, *args):
        """fn(*args) for an FMU call outside stepping (state save/restore, exit of initialisation);
        a failure becomes a SimulationError naming the component and the start of macro step n."""
        try:
            return fn(*args)
        except FmuError as e:
            t = self.clock.time(n * self.pc.ratio)
            raise SimulationError(f"{e} at t={t}", self.name, t) from e

    def _fill_initial(self, histories: dict[str, History]) -> None:
        vals = self.inp.values
        for il in self.links:
            h = histories[il.link.source]
            vals[il.slots] = h.buf[0, il.columns]
        t = self.clock.time(0)
        for slot, s, start in self.stimuli:
            vals[slot] = stimulus_value(s, t, start)

    def macro_step(self, n: int, histories: dict[str, History], relaxed: bool = False) -> None:
        """Advance through macro step n: `ratio` communication steps of h each.

        relaxed: a start-up sweep (see Plan.startup_sweeps); `histories` then hold the sources'
        samples of macro step n from the previous sweep.
        """
        hist = self.history
        if hist.buf is not self._rows_of:
            self._bind_history()
        self._fill_inputs(n, histories, relaxed)
        fmu, c, set_real, get_real, do_step, set_deriv = self._calls
        ivrs, icount, ovrs, ocount, dvrs, dcount, dorders = self._args
        has_in, has_out, feedthrough, deriv, reads = self._flags
        u0, u1, dptrs, rows = self._pointers
        num0, dnum, den, h, k = self._steps
        cap = len(rows)
        j = j0 = n * k
        inside = 0.0  # s in FMI calls
        t, t0 = 0.0, perf()
        try:
            for m in range(k):
                t = (num0 + j * dnum) / den
                t0 = perf()
                if has_in and (st := set_real(c, ivrs, icount, u0[m])) > OK_STATUS:
                    raise fmu.call_error("set_real", st)
                if deriv and (st := set_deriv(c, dvrs, dcount, dorders, dptrs[m])) > OK_STATUS:
                    raise fmu.call_error("set_input_derivatives", st)
                if (st := do_step(c, c_double(t), h, NO_STATE_RESTORED)) > OK_STATUS:
                    raise fmu.call_error("do_step", st)
                if feedthrough and (st := set_real(c, ivrs, icount, u1[m])) > OK_STATUS:
                    raise fmu.call_error("set_real", st)
                if (
                    has_out
                    and reads[m]
                    and (st := get_real(c, ovrs, ocount, rows[(j + 1) % cap])) > OK_STATUS
                ):
                    raise fmu.call_error("get_real", st)
                inside += perf() - t0
                j += 1
        except FmuError as e:
            self.fmu_time += inside + perf() - t0
            self.steps += j - j0
            self._check(j0, j)  # a diverged sample before the failing call explains it better
            raise SimulationError(
                f"{e} in the step from t={t} to t={self.clock.time(j + 1)}", self.name, t
            ) from e
        self.fmu_time += inside
        self.steps += k
        if not np.multiply(self._flat, self._flat, self._squares) @ self._inv_bound2 <= 1.0:
            self._check(j0, j)

    def _check(self, j0: int, j1: int) -> None:
        """Raise if one of the samples j0+1 .. j1 read is not finite or beyond its bound (the earliest).

        Samples before j0+1 passed this check before; history rows not yet written hold zeros.
        """
        buf = self.history.buf
        for j in range(j0 + 1, j1 + 1):
            if not self.reads[j - j0 - 1]:
                continue
            vals = buf[j % self.history.capacity]
            t1 = self.clock.time(j)
            if not np.isfinite(vals).all():
                bad = self.out.names[int(np.flatnonzero(~np.isfinite(vals))[0])]
                raise SimulationError(
                    f"unstable: {self.name}.{bad} at t={t1} ({UNSTABLE_HINT})", self.name, t1, bad
                )
            if (np.abs(vals) > self.bound).any():
                i = int(np.flatnonzero(np.abs(vals) > self.bound)[0])
                bad = self.out.names[i]
                raise SimulationError(
                    f"unstable: {self.name}.{bad} at t={t1}: {vals[i]:.3g} is beyond {GROWTH_LIMIT:g} times "
                    f"its start magnitude ({UNSTABLE_HINT})",
                    self.name,
                    t1,
                    bad,
                )

    def record(self, n: int, row: np.ndarray) -> None:
        """Fill this component's recorded values at the end of macro step n into its columns of `row`."""
        vals = self.history.buf[((n + 1) * self.pc.ratio) % self.history.capacity]
        dst = self._rec_dst
        if isinstance(dst, slice):
            vals.take(self._rec_src, None, row[dst], "clip")
        elif len(dst):
            row[dst] = vals[self._rec_src]
        for i, var in self.record_other:
            t0 = perf()
            try:
                row[i] = self.fmu.get_value(var)
            except FmuError as e:
                raise SimulationError(str(e), self.name, math.nan, var) from e
            finally:
                self.fmu_time += perf() - t0


def samples_read(plan: Plan, name: str) -> list[bool]:
    """reads[m]: whether the samples after step m of a macro step of `name` are ever used.

    A consumer's polynomials use the source samples of its windows (`Link.window`, start-up and
    relaxed ones included), the recorder the samples at macro step ends. Outputs are read (and
    checked for divergence) only where used: a source stepping k times per macro step for an
    order-0 consumer is read once, not k times.
    """
    k = plan.component(name).ratio
    used = {0}
    for lk in plan.links:
        if lk.source != name:
            continue
        for n in range(lk.order + 3):  # past start-up, windows repeat every macro step
            for m in range(lk.k_consumer):
                for relaxed in (False, True):
                    j_end = lk.window(n, n * lk.k_consumer + m, relaxed)[0]
                    used.update((j_end - i) % k for i in range(lk.order + 1))
    return [(m + 1) % k in used for m in range(k)]


def open_fmu(sc: Scenario, comp: Component) -> Fmu:
    """Load the FMU of `comp`, set its parameters and start values, enter initialisation mode."""
    fmu = Fmu(comp.fmu_path, comp.name)
    try:
        fmu.set_values(dict(comp.parameters))
        fmu.enter_initialization(float(sc.start_time), float(sc.stop_time))
    except BaseException:
        fmu.close()
        raise
    return fmu


def _start_value(fmu: Fmu, var: str) -> float:
    s = fmu.variables[var].start
    return float(s) if s is not None else 0.0


perf = time.perf_counter
c_double = ctypes.c_double
