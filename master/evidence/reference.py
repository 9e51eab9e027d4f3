"""Reference solutions: all FMUs of a scene integrated together through Model Exchange.

The FMUs' ME interfaces give f(t, x, u) and y(t, x, u); the scene's connections close the loop
and its stimuli drive the free inputs.  One stiff, tight-tolerance integrator (scipy Radau,
rtol 1e-10) advances the concatenated states of all components monolithically, piecewise
between stimulus break points so that step inputs do not smear.  Direct-feedthrough outputs
are read after the producer's inputs are set, in topological order of the components.

Where a component has no FMI 2.0 Model Exchange interface, the reference is a converged
co-simulation instead: the scene's own scheme run with the macro step halved until two successive
results agree to a tolerance (`converged_cosimulation`). Where that does not converge (a counter
recorded, a scheme that stalls), `solve` gives the finest run as a best-effort reference, named as
such with its last change; `reference` refuses it (NotConverged).

Results are cached in build/reference-cache/, keyed by a hash of the scenario file, the
loaded scene (parameters, times, records), the integration settings and the FMU files.
"""

from __future__ import annotations

import ctypes
import hashlib
import json
import logging
import shutil
import tempfile
from dataclasses import dataclass, replace
from fractions import Fraction
from pathlib import Path

import numpy as np
from fmpy.fmi2 import FMU2Model
from scipy.integrate import solve_ivp

from master.coupling import stimulus_value
from master.description import feedthrough_outputs, parse
from master.evidence.errors import Trajectory, as_trajectory, compare
from master.fmu import safe_extract
from master.scenario.model import Scenario, Stimulus

log = logging.getLogger("master")
CACHE_DIR = Path(__file__).resolve().parents[2] / "build" / "reference-cache"
_DOUBLE_P = ctypes.POINTER(ctypes.c_double)


FLOAT_TYPES = ("Real", "Float64", "Float32")  # outputs a reference compares when a scene records none
STALLED = 3  # halvings without the change shrinking by a tenth: the co-simulation will not converge


class NoModelExchange(Exception):
    """A component's FMU offers no Model Exchange interface."""


class ReferenceFailed(RuntimeError):
    """No reference at all: the integration failed, or the scene's co-simulation does not run."""


class NotConverged(RuntimeError):
    """The co-simulation did not converge; carries the finest run and the convergence table."""

    def __init__(self, message: str, trajectory: Trajectory, convergence: Convergence):
        super().__init__(message)
        self.trajectory, self.convergence = trajectory, convergence


@dataclass
class _Member:
    """One component instantiated for Model Exchange."""

    name: str
    fmu: FMU2Model
    unzip_dir: str
    n: int  # number of continuous states
    offset: int  # first index of its states in the concatenated state vector
    vr: dict[str, int]  # variable name -> value reference
    kind: dict[str, str]  # variable name -> FMI type (Real, Integer, Boolean, String, Enumeration)
    feedthrough: set[str]  # outputs that depend on an input
    x: np.ndarray  # state buffer handed to the FMU
    dx: np.ndarray  # derivative buffer


def _open(comp_name: str, fmu_path: Path, parameters: dict, start_time: float) -> _Member:
    md = parse(fmu_path)
    if md.modelExchange is None:
        raise NoModelExchange(f"{fmu_path}: component {comp_name!r} has no Model Exchange interface")
    vr = {v.name: v.valueReference for v in md.modelVariables}
    kind = {v.name: v.type for v in md.modelVariables}
    unzip = str(safe_extract(fmu_path, Path(tempfile.mkdtemp(prefix="reference-"))))
    fmu = FMU2Model(
        guid=md.guid,
        unzipDirectory=unzip,
        modelIdentifier=md.modelExchange.modelIdentifier,
        instanceName=comp_name,
    )
    fmu.instantiate()
    fmu.setupExperiment(startTime=start_time)
    for name, value in parameters.items():
        if name not in vr:
            shutil.rmtree(unzip, ignore_errors=True)
            raise ValueError(f"{fmu_path}: component {comp_name!r} has no variable {name!r}")
        _set(fmu, kind[name], vr[name], value)
    fmu.enterInitializationMode()
    fmu.exitInitializationMode()
    while fmu.newDiscreteStates()[0]:
        pass
    fmu.enterContinuousTimeMode()
    n = md.numberOfContinuousStates
    return _Member(comp_name, fmu, unzip, n, 0, vr, kind, feedthrough_outputs(md), np.zeros(n), np.zeros(n))


def _set(fmu: FMU2Model, kind: str, vr: int, value) -> None:
    if kind == "Real":
        fmu.setReal([vr], [float(value)])
    elif kind in ("Integer", "Enumeration"):
        fmu.setInteger([vr], [int(value)])
    elif kind == "Boolean":
        fmu.setBoolean([vr], [bool(value)])
    else:
        fmu.setString([vr], [str(value)])


def _topological(scenario: Scenario, members: dict[str, _Member]) -> list[str]:
    """Component order in which every direct-feedthrough producer precedes its consumers."""
    # Consumer B waits for producer A when A's output depends on A's own inputs (direct
    # feedthrough): A must be evaluated with its inputs set before B reads it.
    after: dict[str, set[str]] = {name: set() for name in members}
    for c in scenario.connections:
        if c.start_connector in members[c.start_component].feedthrough:
            after[c.end_component].add(c.start_component)
    order: list[str] = []
    done: set[str] = set()
    while len(order) < len(members):
        ready = [n for n in members if n not in done and after[n] <= done]
        if not ready:
            loop = sorted(n for n in members if n not in done)
            raise ValueError(f"{scenario.path}: algebraic loop through components {', '.join(loop)}")
        for n in ready:
            order.append(n)
            done.add(n)
    return order


def _stimulus_value(s: Stimulus, t: float, segment_start: float) -> float | None:
    """Value of a stimulus: steps are held from the segment start (None before the first step:
    the input keeps its start value), tables interpolate in t."""
    if s.kind == "step":
        return None if segment_start < s.times[0] else stimulus_value(s, segment_start, 0.0)
    return stimulus_value(s, t, 0.0)


class _Scene:
    """The monolithic ODE of a scene: concatenated states, connections, stimuli."""

    def __init__(self, scenario: Scenario) -> None:
        self.scenario = scenario
        t0 = float(scenario.start_time)
        self.members: dict[str, _Member] = {}
        try:
            offset = 0
            for comp in scenario.components:
                m = _open(comp.name, comp.fmu_path, dict(comp.parameters), t0)
                m.offset = offset
                offset += m.n
                self.members[comp.name] = m
        except BaseException:
            self.close()
            raise
        self.n = offset
        self.order = _topological(scenario, self.members)
        self.incoming = {
            name: [c for c in scenario.connections if c.end_component == name] for name in self.members
        }
        self.stimuli = {name: [s for s in scenario.stimuli if s.component == name] for name in self.members}
        self.segment_start = t0

    def close(self) -> None:
        for m in self.members.values():
            try:
                m.fmu.terminate()
                m.fmu.freeInstance()
            except Exception:  # noqa: BLE001  (an instance already in error: nothing more to free)
                pass
            shutil.rmtree(m.unzip_dir, ignore_errors=True)

    def initial_state(self) -> np.ndarray:
        x = np.zeros(self.n)
        for m in self.members.values():
            if m.n:
                m.fmu.getContinuousStates(m.x.ctypes.data_as(_DOUBLE_P), m.n)
                x[m.offset : m.offset + m.n] = m.x
        return x

    def evaluate(self, t: float, x: np.ndarray) -> None:
        """Set time, states and inputs of every component for (t, x)."""
        for m in self.members.values():
            m.fmu.setTime(t)
            if m.n:
                m.x[:] = x[m.offset : m.offset + m.n]
                m.fmu.setContinuousStates(m.x.ctypes.data_as(_DOUBLE_P), m.n)
        for name in self.order:
            m = self.members[name]
            for s in self.stimuli[name]:
                v = _stimulus_value(s, t, self.segment_start)
                if v is not None:
                    m.fmu.setReal([m.vr[s.variable]], [float(v)])
            for c in self.incoming[name]:
                src = self.members[c.start_component]
                (v,) = src.fmu.getReal([src.vr[c.start_connector]])
                m.fmu.setReal([m.vr[c.end_connector]], [v])

    def rhs(self, t: float, x: np.ndarray) -> np.ndarray:
        self.evaluate(t, x)
        dx = np.empty(self.n)
        for m in self.members.values():
            if m.n:
                m.fmu.getDerivatives(m.dx.ctypes.data_as(_DOUBLE_P), m.n)
                dx[m.offset : m.offset + m.n] = m.dx
        return dx

    def read(self, t: float, x: np.ndarray, names: list[tuple[str, str]]) -> list[float]:
        self.evaluate(t, x)
        return [self.members[c].fmu.getReal([self.members[c].vr[v]])[0] for c, v in names]


def recorded_variables(scenario: Scenario) -> list[tuple[str, str]]:
    """The (component, variable) pairs the scene records; all floating-point outputs if it names
    none (a counter or a flag is not a signal a reference converges on)."""
    if scenario.record:
        return list(scenario.record)
    names = []
    for comp in scenario.components:
        md = parse(comp.fmu_path)
        names += [(comp.name, v.name) for v in md.modelVariables
                  if v.causality == "output" and v.type in FLOAT_TYPES]  # fmt: skip
    return names


def record_grid(scenario: Scenario, step: Fraction | None = None) -> np.ndarray:
    """Times (s) from start to stop every `step` (default: record_interval, else macro_step)."""
    h = step or scenario.record_interval or scenario.macro_step
    n = int((scenario.stop_time - scenario.start_time) / h)
    return np.array([float(scenario.start_time + i * h) for i in range(n + 1)])


def break_points(scenario: Scenario) -> list[float]:
    """Start, stimulus break points strictly inside the run, stop (s)."""
    t0, t1 = float(scenario.start_time), float(scenario.stop_time)
    inner = {float(t) for s in scenario.stimuli for t in s.times if t0 < t < t1}
    return [t0, *sorted(inner), t1]


def integrate(
    scenario: Scenario,
    grid: np.ndarray | None = None,
    rtol: float = 1e-10,
    atol: float = 1e-12,
    method: str = "Radau",
) -> Trajectory:
    """Integrate the scene monolithically through Model Exchange; values on `grid` (s).

    Raises NoModelExchange if a component's FMU offers no ME interface,
    RuntimeError if the integrator fails.
    """
    times = record_grid(scenario) if grid is None else np.asarray(grid, dtype=float)
    names = recorded_variables(scenario)
    scene = _Scene(scenario)
    try:
        x = scene.initial_state()
        out = np.full((len(times), len(names)), np.nan)
        bps = break_points(scenario)
        for a, b in zip(bps[:-1], bps[1:], strict=True):
            scene.segment_start = a
            sol = solve_ivp(scene.rhs, (a, b), x, method=method, rtol=rtol, atol=atol, dense_output=True)
            if not sol.success:
                raise ReferenceFailed(
                    f"{scenario.path}: reference integration failed on [{a}, {b}] s: {sol.message}"
                )
            last = b == bps[-1]
            sel = np.nonzero((times >= a) & ((times <= b) if last else (times < b)))[0]
            for i in sel:
                out[i] = scene.read(times[i], sol.sol(times[i]), names)
            x = sol.y[:, -1]
    finally:
        scene.close()
    return Trajectory(np.array(times), {f"{c}.{v}": out[:, j] for j, (c, v) in enumerate(names)})


def _file_hash(path: Path) -> str:
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()


def cache_key(scenario: Scenario, settings: dict) -> str:
    """Hash of the scenario file (if any), the scene's content (parameters, times, records), the
    integration settings and every FMU file."""
    h = hashlib.sha256()
    if Path(scenario.path).is_file():
        h.update(Path(scenario.path).read_bytes())
    h.update(repr(scenario).encode())
    h.update(json.dumps(settings, sort_keys=True, default=str).encode())
    for comp in scenario.components:
        h.update(comp.name.encode())
        h.update(_file_hash(comp.fmu_path).encode())
    return h.hexdigest()[:32]


def has_model_exchange(scenario: Scenario) -> bool:
    """Whether every component's FMU offers an FMI 2.0 Model Exchange interface (the one the
    monolithic integration speaks)."""
    return all(
        (md := parse(c.fmu_path)).modelExchange is not None and md.fmiVersion == "2.0"
        for c in scenario.components
    )


@dataclass(frozen=True)
class Convergence:
    """How a converged co-simulation got there: macro steps (s) and the worst scaled change
    between each run and the one before (fraction of the variable's range), and in which variable
    the last one was."""

    macro_steps: tuple[Fraction, ...]
    changes: tuple[float, ...]
    variable: str = ""

    def observed_order(self) -> float:
        """log2 of the ratio of the last two changes (nan with fewer than two)."""
        if len(self.changes) < 2 or self.changes[-1] <= 0:
            return float("nan")
        return float(np.log2(self.changes[-2] / self.changes[-1]))

    def table(self) -> str:
        pairs = zip(self.macro_steps[1:], self.changes, strict=True)
        rows = [f"  H = {float(h):.6g} s: change {c:.3e}" for h, c in pairs]
        return "\n".join(rows + [f"  observed order {self.observed_order():.2f}"])

    @property
    def last_change(self) -> float:
        return self.changes[-1] if self.changes else float("inf")


def _stalled(changes: list[float]) -> bool:
    """STALLED halvings in a row, all finite, none shrinking the change by a tenth."""
    last = changes[-STALLED - 1 :]
    return (
        len(last) == STALLED + 1
        and all(np.isfinite(last))
        and all(b > 0.9 * a for a, b in zip(last[:-1], last[1:], strict=True))
    )


def converged_cosimulation(
    scenario: Scenario, grid_step: Fraction | None = None, tol: float = 1e-6, max_halvings: int = 12
) -> tuple[Trajectory, Convergence]:
    """The scene's co-simulation with its macro step halved until two successive results differ by
    at most `tol` (worst scaled max difference over `recorded_variables`) on the record grid; the
    finest run and the table.

    Raises NotConverged (with the finest run) if `max_halvings` halvings do not get there or the
    change stalls, ReferenceFailed if the scene's co-simulation fails at its own macro step.
    """
    from master import api  # the runtime; imported here since it is heavy and optional for ME scenes
    from master.backends.component import SimulationError

    step = Fraction(grid_step or scenario.record_interval or scenario.macro_step)
    record = tuple(recorded_variables(scenario))
    previous, steps, changes, worst = None, [], [], ""
    for j in range(max_halvings + 1):
        h = scenario.macro_step / 2**j
        try:
            data = api.run(replace(scenario, macro_step=h, record_interval=step, record=record)).data
        except SimulationError as e:
            if previous is None:
                why = str(e).split(" (hint")[0]
                raise ReferenceFailed(
                    f"{scenario.path}: no reference: its co-simulation fails ({why})"
                ) from None
            break  # the finest run that finished is the best effort
        traj = as_trajectory(data)
        steps.append(h)
        if previous is not None:
            rep = compare(traj, previous)
            changes.append(rep.worst_max)
            worst = rep.worst_max_variable
            if changes[-1] <= tol:
                return traj, Convergence(tuple(steps), tuple(changes), worst)
            if _stalled(changes):
                break
        previous = traj
    conv = Convergence(tuple(steps), tuple(changes), worst)
    what = f"co-simulation did not converge to {tol:g} in {len(changes)} halvings"
    raise NotConverged(f"{scenario.path}: {what}:\n{conv.table()}", previous, conv)


@dataclass(frozen=True)
class Reference:
    """A reference solution and what it is."""

    trajectory: Trajectory
    what: str  # for reports: which reference, and how good
    converged: bool = True  # False: a best effort, the finest co-simulation that did not converge
    uncertainty: float = 0.0  # worst scaled change between its last two runs (0: Model Exchange)


def reference(scenario: Scenario, **options) -> Trajectory:
    """The cached reference solution of a loaded scene (`solve`, with its options); raises
    NotConverged where there is only a best effort."""
    ref = solve(scenario, **options)
    if not ref.converged:
        raise NotConverged(f"{scenario.path}: no reference: {ref.what}", ref.trajectory, Convergence((), ()))
    return ref.trajectory


def solve(
    scenario: Scenario,
    grid_step: Fraction | None = None,
    rtol: float = 1e-10,
    atol: float = 1e-12,
    cache_dir: Path | None = CACHE_DIR,
    cosim_tol: float = 1e-6,
) -> Reference:
    """The cached reference solution of a loaded scene: `integrate` through Model Exchange; without
    it `converged_cosimulation` to cosim_tol, or its finest run as a best effort.

    grid_step: spacing (s) of the reference grid; default the scene's record interval.
    cache_dir: None disables the cache.
    """
    grid = record_grid(scenario, grid_step)
    me = has_model_exchange(scenario)
    me_what = f"the Model Exchange reference (Radau, rtol {rtol:g})"
    settings = {"rtol": rtol, "atol": atol, "grid": [grid[0], grid[-1], len(grid)], "method": "Radau"}
    if not me:
        settings = {"tol": cosim_tol, "grid": settings["grid"], "method": "converged co-simulation", "v": 2}
    path = None
    if cache_dir is not None:
        path = Path(cache_dir) / f"{cache_key(scenario, settings)}.npz"
        if path.exists():
            data = np.load(path)
            meta = json.loads(str(data["__meta__"])) if "__meta__" in data.files else {"what": me_what}
            values = {k: data[k] for k in data.files if not k.startswith("__")}
            return Reference(Trajectory(data["__time__"], values), **meta)
    if me:
        ref = Reference(integrate(scenario, grid, rtol=rtol, atol=atol), me_what)
    else:
        try:
            traj, conv = converged_cosimulation(scenario, grid_step, tol=cosim_tol)
            what = (f"a converged co-simulation (no Model Exchange; macro step halved to "
                    f"{float(conv.macro_steps[-1]):.3g} s, last change {conv.last_change:.2g})")  # fmt: skip
            ref = Reference(traj, what, True, conv.last_change)
        except NotConverged as e:
            conv = e.convergence
            what = (f"a best-effort reference: no Model Exchange, and the co-simulation did not converge "
                    f"to {cosim_tol:g} (finest macro step {float(conv.macro_steps[-1]):.3g} s, last change "
                    f"{conv.last_change:.2g} of the range{f' in {conv.variable}' if conv.variable else ''}): "
                    f"errors below that are not resolved")  # fmt: skip
            ref = Reference(e.trajectory, what, False, conv.last_change)
        log.info("%s: %s:\n%s", scenario.path, ref.what, conv.table())
    if path is not None:
        path.parent.mkdir(parents=True, exist_ok=True)
        meta = {"what": ref.what, "converged": ref.converged, "uncertainty": ref.uncertainty}
        with tempfile.NamedTemporaryFile(dir=path.parent, suffix=".npz", delete=False) as f:
            np.savez(f, __time__=ref.trajectory.time, __meta__=json.dumps(meta), **ref.trajectory.values)
        Path(f.name).replace(path)
    return ref
