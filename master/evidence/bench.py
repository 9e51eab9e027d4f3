"""Work-precision bench: sweep co-simulation configurations of a scene, time them, measure
their error against the Model Exchange reference, and plot wall time against error.

Families swept (each row of the CSV is one configuration):
- single-rate: every component with the mechanics solver (AB3) at one step h, at several h;
- dual-rate: mechanics at the macro step H, control at H / r, r = 1 ... 20;
- order: extrapolation order 0 ... 3 of the polynomials on the control side's inputs (the
  mechanics holds its inputs, order 0, as in the paper);
- control-solver: Euler, semi-implicit Euler, semi-implicit midpoint on the control side;
- mech-solver: AB2, AB3 on the mechanics side;
- backend: serial and parallel.
Wall time is the median over repeats of the run's stepping wall time (RunSummary.wall_time);
the error is the worst scaled max error over the recorded variables (master.evidence.errors)
against the scene's reference (master.evidence.reference; a best-effort one is named as such).
A run the runtime stops as unstable, or whose error exceeds the variables' range, is kept in
the table and the plot as unstable.  Each row also gives rho, the spectral radius of the
macro-step map of the scene linearised at `Profile.linearize_at` (master.evidence.stability):
rho > 1 predicts a growing mode.
"""

from __future__ import annotations

import argparse
import contextlib
import csv
import dataclasses
import logging
import math
import statistics
import sys
from collections.abc import Iterator
from dataclasses import dataclass
from fractions import Fraction
from pathlib import Path

from master.evidence.errors import Trajectory, as_trajectory, compare
from master.evidence.linear import LinearScheme, spectral_radius
from master.evidence.reference import ReferenceFailed, solve
from master.evidence.stability import linearize
from master.scenario.model import Component, Iteration, ModelExchange, Scenario, Scheme
from master.solvers import AB2, AB3, EULER, ITEMS, NUMBERS, SI_EULER, SI_MIDPOINT, SOLVER_NAMES

GENERIC_FAMILIES = ("scene", "macro-step", "order", "coupling", "backend")  # sweeps of generic_profile


@dataclass(frozen=True)
class Config:
    """One co-simulation configuration: macro step H (s), control step ratio r, solvers, order."""

    family: str
    macro_step: Fraction
    ratio: int = 1
    order: int = 0
    mech_solver: int = AB3
    ctrl_solver: int = EULER
    backend: str = "serial"
    single_rate: bool = False  # every component with the mechanics solver at the macro step
    coupling: Scheme | None = None  # None: the scene's
    # Gauss-Seidel with the control stepping first: the mechanics then interpolate the control's
    # new samples (order mech_order) instead of holding them, over mech_substeps solver steps
    # per macro step (the polynomials handed to the FMU: each substep sees its own time's force)
    control_first: bool = False
    mech_order: int = 0
    mech_substeps: int = 1
    # iterated macro steps (strong coupling): each repeated from saved states until the coupled
    # signals settle (the scene's mm:Iteration, else the defaults of Iteration)
    iterated: bool = False
    # a scene without a profile: its Model Exchange components' method and solver steps per
    # communication step (None: each component's own, its steps counted at the scene's macro step)
    me_solver: int | None = None
    me_substeps: int | None = None

    def __post_init__(self) -> None:
        if self.family == "single-rate":
            object.__setattr__(self, "single_rate", True)

    @property
    def label(self) -> str:
        h = float(self.macro_step)
        how = f"{self.backend}" + (f", {self.coupling}" if self.coupling else "")
        how += ", iterated" if self.iterated else ""
        if self.single_rate:
            return f"single-rate {SOLVER_NAMES[self.mech_solver]} h={h:g}, {how}"
        if self.family in GENERIC_FAMILIES:
            return f"H={h:g}, order {self.order}, {how}"
        first = (f", control first, mechanics order {self.mech_order} x{self.mech_substeps}"
                 if self.control_first else "")  # fmt: skip
        return (
            f"{SOLVER_NAMES[self.mech_solver]} H={h:g} + {SOLVER_NAMES[self.ctrl_solver]} "
            f"h={h / self.ratio:g} (r={self.ratio}), order {self.order}{first}, {how}"
        )


@dataclass(frozen=True)
class Profile:
    """How to sweep one scene: which components are mechanics and control, and the steps (s)."""

    mechanics: tuple[str, ...]
    control: tuple[str, ...]
    record_interval: Fraction  # every macro step of the sweep divides it
    baseline: Config  # the paper's single-rate configuration
    single_steps: tuple[Fraction, ...]
    macro_steps: tuple[Fraction, ...]  # dual-rate macro steps
    base: Config  # the central dual-rate configuration the one-factor sweeps vary
    ratios: tuple[int, ...] = (1, 2, 5, 10, 20)
    stop_time: Fraction | None = None  # None: the scene's
    unstable_step: Fraction | None = None  # a single-rate step past the stability limit (quick sweep)
    linearize_at: float = 0.1  # s: operating point of the linear stability analysis
    variables: tuple[str, ...] | None = None  # the error's variables (None: all recorded)
    generic: bool = False  # a scene without a profile: its own FMUs, steps and ratios swept as they are
    model_exchange: tuple[str, ...] = ()  # its components the master integrates (Model Exchange)

    @property
    def mechanics_me(self) -> bool:
        return any(name in self.model_exchange for name in self.mechanics)

    @property
    def control_me(self) -> bool:
        return any(name in self.model_exchange for name in self.control)


F = Fraction
PROFILES: dict[str, Profile] = {
    "hydraulic-manipulator": Profile(
        mechanics=("mechanics",),
        control=("hydraulics",),
        record_interval=F(1, 100),
        baseline=Config("single-rate", F(2, 10000), coupling=Scheme.JACOBI),  # nearest to monolithic AB3
        single_steps=(F(1, 10000), F(2, 10000), F(5, 10000), F(1, 1000)),
        macro_steps=(F(5, 10000), F(1, 1000), F(2, 1000)),
        base=Config("dual-rate", F(1, 1000), ratio=5, order=1),
        stop_time=F(1),
        unstable_step=F(4, 1000),
        variables=("mechanics.body6_z", "mechanics.body6_vz", "mechanics.body6_az"),  # Fig. 5
    ),
    "dc-motor-arm": Profile(
        mechanics=("mechanics",),
        control=("motors",),
        record_interval=F(3, 50),
        baseline=Config("single-rate", F(2, 1000)),
        single_steps=(F(5, 10000), F(1, 1000), F(2, 1000), F(3, 1000)),
        macro_steps=(F(5, 1000), F(1, 100), F(2, 100), F(3, 100)),
        base=Config("dual-rate", F(2, 100), ratio=4, order=0),
        ratios=(1, 2, 4, 10, 20),
        unstable_step=F(3, 1000),
        linearize_at=0.0,
        stop_time=F(18, 5),  # a whole number of every swept step
        variables=tuple(f"mechanics.{q}{i}" for q in ("q", "qd") for i in (1, 2, 3)),
    ),
    "oscillator": Profile(
        mechanics=("mass1",),
        control=("mass2",),
        record_interval=F(1, 10),
        baseline=Config("single-rate", F(1, 100)),
        single_steps=(F(1, 400), F(1, 200), F(1, 100), F(1, 50)),
        macro_steps=(F(1, 50), F(1, 20), F(1, 10)),
        base=Config("dual-rate", F(1, 20), ratio=5, order=2),
        unstable_step=F(1, 2),
        linearize_at=0.5,
    ),
}


def profile_for(sc: Scenario) -> Profile:
    """The bench profile of a scene, by scenario name or folder name; for any other scene one
    derived from the scenario itself (`generic_profile`)."""
    me = tuple(c.name for c in sc.components if c.model_exchange is not None)
    for key in (sc.name, Path(sc.path).parent.name, Path(sc.path).stem):
        if key in PROFILES:
            return dataclasses.replace(PROFILES[key], model_exchange=me)
    return dataclasses.replace(generic_profile(sc), model_exchange=me)


def generic_profile(sc: Scenario) -> Profile:
    """A sweep any scene allows, with nothing assumed of its FMUs: its macro step H times 2, 1,
    1/2, 1/4 (its components' step ratios kept), every extrapolation order 0..3, both couplings and
    both backends; the baseline is the scene as written. Errors are measured on its record grid
    (a multiple of 2 H, so that every swept step hits it) against the reference solution."""
    H = sc.macro_step
    order = max((c.extrapolation_order for c in sc.components), default=0)
    integrated = [c for c in sc.components if c.model_exchange is not None]
    methods = {NUMBERS[c.model_exchange.solver] for c in integrated}  # one each where they agree
    counts = {c.model_exchange.substeps(H / c.step_ratio) or 1 for c in integrated}
    base = Config("scene", H, order=order, iterated=sc.iteration is not None,
                  me_solver=methods.pop() if len(methods) == 1 else None,
                  me_substeps=counts.pop() if len(counts) == 1 else None)  # fmt: skip
    return Profile(
        mechanics=tuple(c.name for c in sc.components),
        control=(),
        record_interval=lcm(sc.record_interval or H, 2 * H),
        baseline=base,
        single_steps=(),
        macro_steps=(2 * H, H, H / 2, H / 4),
        base=base,
        generic=True,
    )


def configurations(p: Profile, quick: bool = False) -> list[Config]:
    """The sweep: the full one for the docs, or a handful of runs (`quick`) for tests."""
    if p.generic:
        return _unique(_generic_configurations(p, quick))
    b = p.base
    if quick:
        out = [
            p.baseline,
            dataclasses.replace(p.baseline, macro_step=p.single_steps[-1]),
            b,
            dataclasses.replace(b, ratio=p.ratios[-1], order=3),
            dataclasses.replace(b, family="control-solver", ctrl_solver=SI_MIDPOINT, ratio=1),
        ]
        if p.unstable_step is not None:
            out.append(dataclasses.replace(p.baseline, macro_step=p.unstable_step))
        return out
    out = [p.baseline] + [dataclasses.replace(p.baseline, macro_step=h) for h in p.single_steps]
    out += [dataclasses.replace(b, macro_step=h, ratio=r) for h in p.macro_steps for r in p.ratios]
    out += [dataclasses.replace(b, family="order", order=k) for k in range(4) if k != b.order]
    out += [
        dataclasses.replace(b, family="control-solver", ctrl_solver=s, ratio=r)
        for s in (EULER, SI_EULER, SI_MIDPOINT)
        for r in (1, b.ratio)
        if (s, r) != (b.ctrl_solver, b.ratio)
    ]
    out += [dataclasses.replace(b, family="control-solver", ctrl_solver=s, ratio=1, macro_step=h)
            for s in (SI_EULER, SI_MIDPOINT) for h in p.macro_steps]  # fmt: skip
    out += [dataclasses.replace(b, family="mech-solver", mech_solver=AB2)]
    out += [dataclasses.replace(c, family="backend", backend="parallel") for c in (p.baseline, b)]
    for coupling in tuple(Scheme):
        out += [dataclasses.replace(c, family="coupling", coupling=coupling) for c in (p.baseline, b)
                if c.coupling != coupling]  # fmt: skip
    return _unique(out)


def _generic_configurations(p: Profile, quick: bool) -> list[Config]:
    b = p.base
    if quick:
        h_big, h_small = p.macro_steps[0], p.macro_steps[-1]
        return [b, dataclasses.replace(b, family="macro-step", macro_step=h_big),
                dataclasses.replace(b, family="macro-step", macro_step=h_small),
                dataclasses.replace(b, family="order", order=(b.order + 1) % 4)]  # fmt: skip
    out = [b] + [dataclasses.replace(b, family="macro-step", macro_step=h) for h in p.macro_steps]
    out += [dataclasses.replace(b, family="order", order=k) for k in range(4)]
    out += [
        dataclasses.replace(b, family="order", order=k, macro_step=h) for k in range(4) for h in p.macro_steps
    ]
    out += [dataclasses.replace(b, family="coupling", coupling=c) for c in tuple(Scheme)]
    out += [dataclasses.replace(b, family="backend", backend="parallel")]
    return out


def _unique(configs: list[Config]) -> list[Config]:
    seen, unique = set(), []
    for c in configs:
        key = dataclasses.replace(c, family="")
        if key not in seen:
            seen.add(key)
            unique.append(c)
    return unique


def apply(sc: Scenario, p: Profile, c: Config) -> Scenario:
    """The scene with the configuration's steps, ratios, orders and solvers."""
    if p.generic:  # its own FMUs and ratios: the macro step, the orders, the coupling, the ME methods change
        comps = tuple(
            dataclasses.replace(comp, extrapolation_order=c.order, model_exchange=_integrated(sc, comp, c))
            for comp in sc.components
        )
        conns = tuple(dataclasses.replace(cn, extrapolation_order=None) for cn in sc.connections)
        coupling = c.coupling or sc.coupling
        return dataclasses.replace(
            sc,
            coupling=coupling,
            order=(sc.order or tuple(x.name for x in sc.components))
            if coupling == Scheme.GAUSS_SEIDEL
            else (),
            iteration=iteration(sc, c),
            components=comps,
            connections=conns,
            macro_step=c.macro_step,
            record_interval=p.record_interval,
            stop_time=_whole(sc, p.record_interval),
        )
    comps = []
    for comp in sc.components:
        ctrl = comp.name in p.control and not c.single_rate
        solver = c.ctrl_solver if ctrl else c.mech_solver
        mech = comp.name in p.mechanics and c.control_first
        substep = float(c.macro_step) / c.mech_substeps if mech and c.mech_substeps > 1 else 0.0
        params = {**comp.parameters, "solver": solver, "internal_step": substep}
        me = comp.model_exchange
        if me is not None:  # the master integrates it: the method and steps are its own settings
            params, n = comp.parameters, c.mech_substeps if comp.name in p.mechanics else 1
            me = ModelExchange(ITEMS[solver], c.macro_step / n if n > 1 else None)
        comps.append(
            dataclasses.replace(
                comp,
                parameters=params,
                step_ratio=c.ratio if ctrl else 1,
                # the control side extrapolates the mechanics; the mechanics hold, or interpolate
                extrapolation_order=c.order if ctrl else c.mech_order if mech else 0,
                interpolate_inputs=substep > 0 and me is None,
                model_exchange=me,
            )
        )
    conns = tuple(dataclasses.replace(cn, extrapolation_order=None) for cn in sc.connections)
    coupling = Scheme.GAUSS_SEIDEL if c.control_first else c.coupling or sc.coupling
    order = sc.order or tuple(x.name for x in sc.components) if coupling == Scheme.GAUSS_SEIDEL else sc.order
    if c.control_first:
        order = (*p.control, *p.mechanics)
    return dataclasses.replace(
        sc,
        coupling=coupling,
        order=order,
        iteration=iteration(sc, c),
        components=tuple(comps),
        connections=conns,
        macro_step=c.macro_step,
        record_interval=lcm(p.record_interval, c.macro_step),
        stop_time=p.stop_time if p.stop_time is not None else sc.stop_time,
    )


def _integrated(sc: Scenario, comp: Component, c: Config) -> ModelExchange | None:
    """How the master integrates a Model Exchange component of a scene without a profile: the
    configuration's method, and its solver steps per communication step (the component's own count
    at the scene's macro step unless the configuration sets one), whatever the macro step."""
    me = comp.model_exchange
    if me is None:
        return None
    n = c.me_substeps or me.substeps(sc.macro_step / comp.step_ratio) or 1
    step = c.macro_step / comp.step_ratio
    return ModelExchange(ITEMS[c.me_solver] if c.me_solver else me.solver, step / n if n > 1 else None)


def iteration(sc: Scenario, c: Config) -> Iteration | None:
    """The iterated macro steps of a configuration: the scene's settings where it has them."""
    return (sc.iteration or Iteration()) if c.iterated else None


def _whole(sc: Scenario, step: Fraction) -> Fraction:
    """The scene's stop time, brought down to a whole number of `step` after its start (s)."""
    n = (sc.stop_time - sc.start_time) // step
    return sc.start_time + max(n, 1) * step


def lcm(a: Fraction, b: Fraction) -> Fraction:
    """Least common multiple of two positive rationals (s)."""
    num = a.numerator * b.numerator // math.gcd(a.numerator, b.numerator)
    return Fraction(num, math.gcd(a.denominator, b.denominator))


def base_scene(sc: Scenario, p: Profile) -> Scenario:
    """The scene as the reference sees it: the profile's record grid and stop time."""
    stop = p.stop_time if p.stop_time is not None else sc.stop_time
    return dataclasses.replace(
        sc,
        macro_step=p.record_interval,
        record_interval=p.record_interval,
        stop_time=_whole(sc, p.record_interval) if p.generic else stop,
    )


def linearize_scene(sc: Scenario, p: Profile) -> LinearScheme:
    """The scene of a profile (the project's FMUs) linearised at `p.linearize_at`, its base
    configuration applied; `linear_scheme` gives any other configuration from it."""
    return linearize(apply(sc, p, p.base), t=p.linearize_at)


def linear_scheme(lin: LinearScheme, p: Profile, c: Config) -> LinearScheme:
    """The linearised scene with the configuration's solvers, step ratios and order."""
    comps = []
    for comp in lin.components:
        ctrl = comp.name in p.control and not c.single_rate
        mech = comp.name in p.mechanics and c.control_first
        mode = "polynomial" if comp.model_exchange or (mech and c.mech_substeps > 1) else "hold"
        stepped = mech or (comp.model_exchange and comp.name in p.mechanics)  # as `apply` steps it
        comps.append(dataclasses.replace(comp, solver=c.ctrl_solver if ctrl else c.mech_solver,
                                         step_ratio=c.ratio if ctrl else 1,
                                         substeps=c.mech_substeps if stepped else 1,
                                         order=c.order if ctrl else c.mech_order if mech else 0,
                                         input_mode=mode))  # fmt: skip
    coupling = (
        Scheme.GAUSS_SEIDEL
        if c.control_first
        else c.coupling or (Scheme.GAUSS_SEIDEL if lin.first else Scheme.JACOBI)
    )
    first = (lin.first or tuple(x.name for x in lin.components)) if coupling == Scheme.GAUSS_SEIDEL else ()
    if c.control_first:
        first = (*p.control, *p.mechanics)
    return dataclasses.replace(
        lin, components=tuple(comps), order=c.order, first=first, iterate="converged" if c.iterated else 0
    )


@dataclass
class Row:
    """One measured configuration."""

    config: Config
    wall_time: float  # median stepping wall time (s)
    wall_times: list[float]
    error: float  # worst scaled max error
    end_error: float
    worst_variable: str
    stable: bool
    status: str
    rho: float = float("nan")  # spectral radius of the linearised scheme's macro-step map


def measure(sc: Scenario, p: Profile, c: Config, ref: Trajectory, repeats: int) -> Row:
    """Run one configuration `repeats` times; its error from the first run."""
    from master.api import run
    from master.backends.component import SimulationError

    scene = apply(sc, p, c)
    times: list[float] = []
    err = end = float("inf")
    worst = ""
    status = "finished"
    for i in range(repeats):
        try:
            res = run(scene, backend=c.backend)
        except SimulationError as e:
            times.append(e.result.summary.wall_time)
            status = str(e).split(" (hint")[0]
            break
        times.append(res.summary.wall_time)
        if i == 0:
            rep = compare(as_trajectory(res.data), ref, list(p.variables) if p.variables else None)
            err, end, worst = rep.worst_max, rep.worst_end, rep.worst_max_variable
    stable = status == "finished" and err <= 1.0
    if status == "finished" and not stable:
        status = f"diverged: error {err:.3g} of the range ({worst})"
    return Row(c, statistics.median(times), times, err, end, worst, stable, status)


def pareto(rows: list[Row]) -> list[Row]:
    """Stable rows no other stable row beats in both wall time and error, fastest first."""
    front: list[Row] = []
    for r in sorted((r for r in rows if r.stable), key=lambda r: (r.wall_time, r.error)):
        if not front or r.error < front[-1].error:
            front.append(r)
    return front


def speedup(rows: list[Row], baseline: Config) -> tuple[Row, Row] | None:
    """(baseline row, fastest stable row with error <= the baseline's), None if the baseline failed."""
    base = next((r for r in rows if r.config == baseline), None)
    if base is None or not base.stable:
        return None
    ok = [r for r in rows if r.stable and r.error <= base.error]
    return base, min(ok, key=lambda r: r.wall_time)


def write_csv(rows: list[Row], path: Path) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    front = {id(r) for r in pareto(rows)}
    with open(path, "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(
            ["family", "label", "backend", "macro_step_s", "control_step_s", "ratio", "order", "mech_solver",
             "control_solver", "wall_time_s", "error_max", "error_end", "worst_variable", "stable", "pareto",
             "rho_linear", "status"]
        )  # fmt: skip
        for r in rows:
            c = r.config
            ctrl_step = float(c.macro_step) / c.ratio
            generic = c.family in GENERIC_FAMILIES
            ctrl = SOLVER_NAMES[c.ctrl_solver] if not (c.single_rate or generic) else ""
            w.writerow(
                [c.family, c.label, c.backend, f"{float(c.macro_step):g}", f"{ctrl_step:g}", c.ratio, c.order,
                 "" if generic else SOLVER_NAMES[c.mech_solver], ctrl,
                 f"{r.wall_time:.4g}", f"{r.error:.3e}", f"{r.end_error:.3e}", r.worst_variable, r.stable,
                 id(r) in front, f"{r.rho:.6f}", r.status]
            )  # fmt: skip


def plot(rows: list[Row], path: Path, title: str) -> None:
    """Log-log work-precision plot: wall time against error; Pareto front; unstable runs on top."""
    import matplotlib.pyplot as plt

    fig = figure(rows, title)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=120)
    plt.close(fig)


def figure(rows: list[Row], title: str):
    """The work-precision figure of `plot` (a matplotlib Figure)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.ticker import FuncFormatter, LogLocator, NullFormatter

    fig, ax = plt.subplots(figsize=(8, 5.5))
    markers = {"single-rate": "s", "dual-rate": "o", "order": "^", "control-solver": "D", "mech-solver": "v",
               "backend": "P", "coupling": "*", "scene": "o", "macro-step": "s"}  # fmt: skip
    stable = [r for r in rows if r.stable]
    top = max([r.error for r in stable], default=1.0) * 3.0
    for fam, mk in markers.items():
        pts = [r for r in stable if r.config.family == fam]
        if pts:
            ax.loglog([r.wall_time for r in pts], [r.error for r in pts], mk, label=fam, alpha=0.8)
    bad = [r for r in rows if not r.stable]
    if bad:
        ax.loglog([r.wall_time for r in bad], [top] * len(bad), "x", color="red", ms=9, label="unstable")
    front = pareto(rows)
    if front:
        ax.loglog([r.wall_time for r in front], [r.error for r in front], "-", color="black", lw=1,
                  label="Pareto front")  # fmt: skip
    for axis in (ax.xaxis, ax.yaxis):  # labels at 1, 2, 5 per decade: matplotlib's own labels
        axis.set_major_locator(LogLocator(subs=(1.0, 2.0, 5.0)))  # of minor ticks overlap
        axis.set_major_formatter(FuncFormatter(lambda v, _: f"{v:g}"))
        axis.set_minor_formatter(NullFormatter())
    ax.set_xlabel("wall time [s]")
    ax.set_ylabel("worst scaled max error")
    ax.set_title(title)
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize="small")
    fig.tight_layout()
    return fig


@contextlib.contextmanager
def quiet(level: int = logging.WARNING) -> Iterator[None]:
    """Runs with only the messages of `level` and above: a bench or tune makes dozens of runs of
    one scene, whose notes and warnings are the same each time."""
    log = logging.getLogger("master")
    old = log.level
    log.setLevel(max(level, old))
    try:
        yield
    finally:
        log.setLevel(old)


class _Once(logging.Filter):
    def __init__(self) -> None:
        super().__init__()
        self.said: set[str] = set()

    def filter(self, record: logging.LogRecord) -> bool:
        new = record.getMessage() not in self.said
        self.said.add(record.getMessage())
        return new


@contextlib.contextmanager
def said_once(sc: Scenario) -> Iterator[None]:
    """The scene's notes on its FMUs (master.api.say_fmu_notes) said now, and every message of
    master's logger said once in this process until the end: the many runs of a bench or tune
    repeat them (runs in other processes are `quiet`)."""
    from master.api import plan, say_fmu_notes

    log = logging.getLogger("master")
    once = _Once()
    log.addFilter(once)
    try:
        say_fmu_notes(plan(sc))
        yield
    finally:
        log.removeFilter(once)


def bench(
    scenario: str | Path,
    out_dir: Path,
    quick: bool = False,
    repeats: int = 3,
    workers: int = 1,
    scheduler: str | None = None,
) -> tuple[list[Row], str]:
    """Run the sweep of a scene; write <out_dir>/<scene>[-quick].csv and .png; return the rows and
    what the reference is.

    The configurations run through the sweep's executor (master.sweeps.executor): a local Dask
    cluster of `workers` processes, one by default so that no two timed runs share the machine,
    or the cluster at `scheduler`."""
    from master.api import load_scenario
    from master.sweeps.executor import Executor

    sc = load_scenario(scenario)
    p = profile_for(sc)
    base = base_scene(sc, p)
    with said_once(base):
        ref = solve(base)
    lin = None if p.generic else linearize_scene(sc, p)
    configs = configurations(p, quick)
    rows: list[Row | None] = [None] * len(configs)
    with Executor(None if scheduler else workers, scheduler) as ex:
        cases = ex.map(_measure, configs, sc, p, ref.trajectory, repeats)
        for done, (i, row) in enumerate(cases, start=1):
            c = configs[i]
            if not isinstance(row, Row):  # the cluster lost it (its worker died)
                row = Row(c, float("nan"), [], float("inf"), float("inf"), "", False, f"lost: {row}")
            if lin is not None:
                row.rho = spectral_radius(linear_scheme(lin, p, c), float(c.macro_step))
            rows[i] = row
            if sys.stderr.isatty():  # a full sweep takes a while
                print(f"\r[{done}/{len(configs)}] {c.label:<70}", end="", file=sys.stderr, flush=True)
    if sys.stderr.isatty():
        print(file=sys.stderr)
    stem = (Path(sc.path).stem if p.generic else Path(sc.path).parent.name) + ("-quick" if quick else "")
    measured = [r for r in rows if r is not None]
    write_csv(measured, out_dir / f"{stem}.csv")
    plot(
        measured, out_dir / f"{stem}.png", f"{sc.name}: work-precision ({'quick' if quick else 'full'} sweep)"
    )
    return measured, ref.what


def _measure(sc: Scenario, p: Profile, ref: Trajectory, repeats: int, c: Config) -> Row:
    """One configuration, as a task of the executor (in a worker process: the scene's warnings
    were said by the bench)."""
    with quiet(logging.ERROR):
        return measure(sc, p, c, ref, repeats)


def report(rows: list[Row], baseline: Config) -> str:
    """Text summary: every row, the Pareto front and the speed-up over the baseline."""
    lines = [f"{'wall [s]':>9} {'error':>10}  stable  {'rho':>8}  configuration"]
    for r in rows:
        ok = "yes" if r.stable else "NO "
        lines.append(f"{r.wall_time:9.4f} {r.error:10.3e}  {ok:6}  {r.rho:8.5f}  {r.config.label}")
    su = speedup(rows, baseline)
    if su is None:
        lines.append("baseline did not run stably: no speed-up to report")
    elif su[1].config == baseline:
        b = su[0]
        lines.append(f"speed-up: no configuration is faster than the baseline {b.config.label} "
                     f"({b.wall_time:.4f} s) at its error {b.error:.3e} or better")  # fmt: skip
    else:
        b, best = su
        lines.append(
            f"speed-up {b.wall_time / best.wall_time:.2f}x: {best.config.label} ({best.wall_time:.4f} s, "
            f"error {best.error:.3e}) vs baseline {b.config.label} ({b.wall_time:.4f} s, error {b.error:.3e})"
        )
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    """`master bench SCENARIO [--quick] [--out DIR] [--repeats N]`."""
    ap = argparse.ArgumentParser(
        prog="master bench",
        description="Work-precision bench: run a scene in many configurations, time them, measure "
        "their error against a reference solution and plot wall time against error.",
    )
    ap.add_argument("scenario", help="scenario file (.ssd / .ssp)")
    ap.add_argument("--quick", action="store_true", help="a handful of configurations (for tests)")
    ap.add_argument(
        "--out", default=None, help="folder for the CSV table and PNG plot (default: results/bench-SCENE)"
    )
    ap.add_argument("--repeats", type=int, default=3, help="runs per configuration; wall time is the median")
    ap.add_argument(
        "--workers",
        type=int,
        default=1,
        help="configurations timed at once on a local Dask cluster (default 1: timings undisturbed)",
    )
    ap.add_argument("--scheduler", metavar="ADDRESS", help="run the configurations on this Dask cluster")
    a = ap.parse_args(argv)
    from master.api import UsageError, load_scenario
    from master.cli import scene_stem
    from master.scenario import ScenarioError

    out = Path(a.out) if a.out else Path("results") / f"bench-{scene_stem(a.scenario)}"
    try:
        p = profile_for(load_scenario(a.scenario))
        rows, what = bench(
            a.scenario, out, quick=a.quick, repeats=a.repeats, workers=a.workers, scheduler=a.scheduler
        )
    except (UsageError, ScenarioError, ValueError, ReferenceFailed) as e:
        print(f"error: {e}", file=sys.stderr)
        return 1
    print(f"errors against {what}")
    print(report(rows, p.baseline))
    print(f"wrote {out}/")
    return 0


if __name__ == "__main__":
    sys.exit(main())
