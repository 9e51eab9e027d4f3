"""`master tune`: the cheapest configuration of a scene that meets an error tolerance.

The error of a configuration is the bench's measure (master.evidence.errors): the worst, over the
scene's error variables, of the largest deviation from the reference solution (Model Exchange, or
a converged co-simulation) relative to the variable's range. It is measured, not estimated: each
candidate is a pilot run over the scene's whole stop time (`--pilot-time` shortens it), compared
with the reference on the finest grid the candidates produce (`check_grid`: every macro step of
each candidate at least as coarse as the scene's smallest component step).

The search, in the bench's configuration space (master.evidence.bench):
1. families: single-rate (every component with the mechanics solver), and for every control step
   ratio and extrapolation order a dual-rate family; then a coordinate search: in each of up to
   ROUNDS rounds, the three cheapest dual-rate families that meet the tolerance (or, failing
   those, the nearest to it) not yet expanded have every neighbour one setting away tried
   (`variants`: coupling, control first with the mechanics interpolating, the mechanics' order
   and solver steps, control solver, order, ratio, mechanics solver, iterated macro steps). A
   scene without a bench profile varies its extrapolation order and coupling, explicit and
   iterated (Gauss-Seidel sweeps: they settle sooner than Jacobi's, at the same fixed point).
   Model Exchange components, which the master integrates, take the solver of their side from
   all six methods and their solver steps per macro step as settings of their own (not the FMU's
   `solver` parameter); in a scene without a profile the coordinate search varies those two.
2. per family, the largest macro step of a ladder of round steps (1, 1.25, 2, 2.5, 4, 5 x 10^k dividing
   the record interval and the stop time) that meets the tolerance: galloping from the best step
   found so far, then bisection (error grows with the step). A step the linear stability analysis
   finds unstable is not run; the search goes no lower than steps whose modelled cost is PRUNE
   times the best's.
3. the ranking: a cost model (`CostModel`): the work a configuration does per simulated second,
   counted from its schedule (macro steps, and each component's FMU calls by kind: solver, solver
   steps per call, polynomial inputs; iterated: times 1 + its pilot run's mean sweeps per macro
   step, before the run the linear model's `sweeps_needed`), times the time each kind costs,
   calibrated once after the search from the pilot runs (the median time per call of each kind:
   a load spike in a minority of the runs moves nothing). Timings never reorder it, so load
   cannot flip the choice.
4. the two cheapest by the model are timed in turn (serial backend) until one is faster outside
   the noise (`decide`); where they stay within it, they are equal and the cheaper by the model
   wins. With a real-time budget F the winner must also step at most F s of wall time per
   simulated second.
"""

from __future__ import annotations

import dataclasses
import math
import statistics
from dataclasses import dataclass, field
from fractions import Fraction
from pathlib import Path

from master.evidence import bench
from master.evidence.bench import Config, Profile
from master.evidence.errors import as_trajectory, compare
from master.evidence.reference import Reference
from master.scenario.model import Scenario, Scheme
from master.scenario.names import split
from master.solvers import AB2, AB3, EULER, NUMBERS, SI_EULER, SI_MIDPOINT, SOLVER_NAMES, SOLVERS

MANTISSAS = (
    1,
    Fraction(5, 4),
    2,
    Fraction(5, 2),
    4,
    5,
)  # the ladder of macro steps: these times powers of ten
LADDER_DECADES = (-6, 1)  # 1e-6 s ... 50 s
VARIANTS_OF = 3  # per round, the cheapest families that meet the tolerance get their variants tried
ROUNDS = 12  # rounds of that coordinate search
CONTROL_SOLVERS = (EULER, AB2, AB3, SI_EULER, SI_MIDPOINT)
ALL_SOLVERS = tuple(s.number for s in SOLVERS)  # a Model Exchange component's: any of the six
MAX_SUBSTEPS = 16  # mechanics solver steps per macro step, at most
MIN_ROUNDS, MAX_ROUNDS = 3, 15  # interleaved timings of the two cheapest: at least, at most
SIGNIFICANT = 0.05  # a ratio of medians nearer 1 than this is no difference
FLOOR = 50  # no macro step below the scene's own (and its baseline's) divided by this
MAX_POINTS = 200_000  # compared times per variable at most
PRUNE = 2.0  # a family's search goes no lower than steps modelled to cost this times the best so far
RESOLVED = 10  # a best-effort reference checks a tolerance this many times its last change, or more


class TuneError(ValueError):
    """The scene cannot be tuned to the tolerance (no reference good enough to check it)."""


@dataclass
class Trial:
    """One pilot run of a configuration."""

    config: Config
    ok: bool  # stable and within the tolerance
    error: float  # worst scaled max error (inf: did not finish)
    status: str  # "finished", or why it is not a candidate
    rho: float = math.nan  # spectral radius of the linearised macro-step map (nan: no analysis)
    sweeps: float = 0.0  # iterated: the run's mean sweeps per macro step (0: explicit, or not run)


@dataclass
class Choice:
    """The best configuration of one family: its largest macro step within the tolerance."""

    family: str
    trial: Trial
    cost: float = math.inf  # modelled wall s per simulated s (`CostModel`)
    timed: list[float] = field(default_factory=list)  # wall times (s) over the horizon, serial backend

    @property
    def wall_time(self) -> float | None:
        """Median timed wall time over the horizon (s); None if not timed."""
        return statistics.median(self.timed) if self.timed else None


@dataclass
class TuneResult:
    scenario: Scenario
    profile: Profile
    tolerance: float
    horizon: float  # s: the pilot runs' simulated time
    grid: float  # s: the spacing of the times the errors are compared at
    reference: str  # what the errors are measured against
    choices: list[Choice]  # every family that met the tolerance, cheapest by the model first
    failed: list[tuple[str, Trial, str]]  # families that met it at no step tried: the last trial, why
    best: Choice | None
    budget: float | None  # wall s per simulated s allowed
    pilots: int = 0  # pilot runs made
    stable_limit: float | None = None  # the winner's largest linearly stable macro step (s)
    runner_up: Choice | None = None  # the one it was timed against
    verdict: str = ""  # how the timing of the two decided
    costs: dict[tuple, float] = field(default_factory=dict)  # the model's calibration: s per call kind

    @property
    def within_budget(self) -> bool:
        if self.best is None:
            return False
        wall = self.best.wall_time if self.best.wall_time is not None else self.best.cost * self.horizon
        return self.budget is None or wall <= self.budget * self.horizon


def ladder(record_interval: Fraction) -> list[Fraction]:
    """Round macro steps (ascending) that divide the record interval, so every configuration
    records on the same grid."""
    steps = {
        Fraction(m) * Fraction(10) ** k
        for k in range(LADDER_DECADES[0], LADDER_DECADES[1] + 1)
        for m in MANTISSAS
    }
    return sorted(h for h in steps if (record_interval / h).denominator == 1)


def families(p: Profile) -> list[tuple[str, Config]]:
    """The first round of families (named), each a configuration whose macro step the search sets."""
    b = p.base
    if p.generic:
        plain = [
            dataclasses.replace(b, order=k, coupling=c, iterated=False) for c in Scheme for k in range(4)
        ]
        swept = dataclasses.replace(b, coupling=Scheme.GAUSS_SEIDEL, iterated=True)
        iterated = [dataclasses.replace(swept, order=k) for k in range(4)]
        return [(_generic_name(c), c) for c in plain + iterated]
    out = [(f"single-rate {SOLVER_NAMES[p.baseline.mech_solver]}", p.baseline)]
    for r in p.ratios:
        for k in range(4):
            c = dataclasses.replace(b, family="dual-rate", ratio=r, order=k)
            out.append((_name(c), c))
    return out


def variants(c: Config, p: Profile) -> list[tuple[str, Config]]:
    """A dual-rate family's neighbours, each one setting away: the coupling (Jacobi, Gauss-Seidel
    either way, control first with the mechanics interpolating), the mechanics' order and solver
    steps when they interpolate, the control solver, the extrapolation order, the step ratio,
    the mechanics solver."""
    out = []
    if not c.control_first:
        flip = Scheme.GAUSS_SEIDEL if (c.coupling or Scheme.JACOBI) == Scheme.JACOBI else Scheme.JACOBI
        out.append(dataclasses.replace(c, coupling=flip))
        out += [dataclasses.replace(c, control_first=True, mech_order=2, mech_substeps=m) for m in (1, 2, 4)]
    else:
        out.append(dataclasses.replace(c, control_first=False, mech_order=0, mech_substeps=1))
        out += [dataclasses.replace(c, mech_substeps=m) for m in (c.mech_substeps // 2, 2 * c.mech_substeps)
                if 1 <= m <= MAX_SUBSTEPS]  # fmt: skip
        out += [
            dataclasses.replace(c, mech_order=k) for k in (c.mech_order - 1, c.mech_order + 1) if 0 <= k <= 3
        ]
    if p.mechanics_me and not c.control_first:  # integrated by the master: its steps, in any coupling
        out += [dataclasses.replace(c, mech_substeps=m) for m in (c.mech_substeps // 2, 2 * c.mech_substeps)
                if 1 <= m <= MAX_SUBSTEPS]  # fmt: skip
    ctrl_solvers = ALL_SOLVERS if p.control_me else CONTROL_SOLVERS
    out += [dataclasses.replace(c, ctrl_solver=s) for s in ctrl_solvers if s != c.ctrl_solver]
    out += [dataclasses.replace(c, order=k) for k in (c.order - 1, c.order + 1) if 0 <= k <= 3]
    below = [r for r in p.ratios if r < c.ratio - 1][-1:]  # the profile's next ratios, and one either side
    above = [r for r in p.ratios if r > c.ratio + 1][:1]
    out += [dataclasses.replace(c, ratio=r) for r in (*below, c.ratio - 1, c.ratio + 1, *above) if r >= 1]
    if p.mechanics_me:
        out += [dataclasses.replace(c, mech_solver=s) for s in ALL_SOLVERS if s != c.mech_solver]
    else:
        out.append(dataclasses.replace(c, mech_solver=AB2 if c.mech_solver == AB3 else AB3))
    out.append(dataclasses.replace(c, iterated=not c.iterated))
    return [(_name(v), v) for v in out]


def generic_variants(c: Config) -> list[tuple[str, Config]]:
    """A family's neighbours in a scene without a profile whose Model Exchange components the
    master integrates: each of the six methods for them, and half and twice their solver steps."""
    n = c.me_substeps or 1
    out = [dataclasses.replace(c, me_solver=s) for s in ALL_SOLVERS if s != c.me_solver]
    out += [dataclasses.replace(c, me_substeps=m) for m in (n // 2, 2 * n) if 1 <= m <= MAX_SUBSTEPS]
    return [(_generic_name(v), v) for v in out]


def _generic_name(c: Config) -> str:
    how = f"order {c.order}, {c.coupling}" + (", iterated" if c.iterated else "")
    if c.me_solver is not None:
        how += f", model exchange {SOLVER_NAMES[c.me_solver]}"
    return how + (f" x{c.me_substeps}" if c.me_substeps else "")


def _name(c: Config) -> str:
    if c.single_rate:
        return f"single-rate {SOLVER_NAMES[c.mech_solver]}"
    how = (f", control first, mechanics order {c.mech_order} x{c.mech_substeps}" if c.control_first
           else f", {c.coupling}" if c.coupling else "")  # fmt: skip
    how += f", mechanics x{c.mech_substeps}" if c.mech_substeps > 1 and not c.control_first else ""
    how += ", iterated" if c.iterated else ""
    return f"{SOLVER_NAMES[c.mech_solver]} + {SOLVER_NAMES[c.ctrl_solver]} r={c.ratio}, order {c.order}{how}"


MACRO = ("master",)  # the call kind of the master's own work per macro step


def call_kind(scene: Scenario, comp) -> tuple:
    """What one communication step of a component costs by: the component, its solver, its solver
    steps per communication step, polynomial inputs or not."""
    me = comp.model_exchange
    if me is not None:  # integrated by the master: its inputs polynomials at every stage
        return comp.name, NUMBERS[me.solver], me.substeps(scene.macro_step / comp.step_ratio) or 1, True
    internal = float(comp.parameters.get("internal_step", 0.0) or 0.0)
    substeps = round(float(scene.macro_step) / comp.step_ratio / internal) if internal > 0 else 1
    return comp.name, comp.parameters.get("solver"), substeps, comp.interpolate_inputs


def work(scene: Scenario, sweeps: float = 0.0) -> dict[tuple, float]:
    """The counted work of a scene per simulated second: its macro steps (MACRO) and each
    component's communication steps by `call_kind`, each macro step stepped 1 + `sweeps` times
    (iterated: the mean sweeps per macro step)."""
    per_second = 1 / scene.macro_step
    out = {MACRO: float(per_second)}
    for comp in scene.components:
        kind = call_kind(scene, comp)
        out[kind] = out.get(kind, 0.0) + float(comp.step_ratio * per_second) * (1.0 + sweeps)
    return out


class CostModel:
    """Wall time per simulated second of a scene: its counted work (`work`) times the time each
    kind of call takes. The times are learned from runs (`learn`: the time inside each component's
    FMU calls per communication step, and the master's time per macro step) and fixed by
    `calibrate`: per kind the median over the runs, so that load on a minority of them moves
    nothing and a ranking by `cost` is the same whatever the timings' noise."""

    def __init__(self) -> None:
        self.samples: dict[tuple, list[float]] = {}

    def learn(self, summary, scene: Scenario) -> None:
        for comp in scene.components:
            n = summary.steps.get(comp.name, 0)
            if n and comp.name in summary.fmu_time:
                self.samples.setdefault(call_kind(scene, comp), []).append(summary.fmu_time[comp.name] / n)
        if summary.macro_steps:
            self.samples.setdefault(MACRO, []).append(summary.overhead_per_macro_step)

    def calibrate(self) -> dict[tuple, float]:
        """s per call of each kind seen: the (lower) median over the runs."""
        return {kind: statistics.median_low(times) for kind, times in self.samples.items()}

    @staticmethod
    def cost(scene: Scenario, times: dict[tuple, float], sweeps: float = 0.0) -> float:
        """Modelled wall s per simulated s (a kind not calibrated counts 0: never pruned on a guess);
        sweeps: iterated, the mean sweeps per macro step."""
        return sum(n * times.get(kind, 0.0) for kind, n in work(scene, sweeps).items())


class Pilot:
    """Runs configurations over the horizon and measures their errors (each once) on the check
    grid; what the runs take calibrates the cost model."""

    def __init__(self, sc: Scenario, p: Profile, ref: Reference, tolerance: float, lin, stop: Fraction,
                 grid: Fraction):  # fmt: skip
        self.sc, self.p, self.reference, self.tolerance, self.lin = sc, p, ref, tolerance, lin
        self.ref = ref.trajectory
        self.stop, self.grid = stop, grid
        self.trials: dict[Config, Trial] = {}
        self.model = CostModel()

    def __call__(self, c: Config) -> Trial:
        if c not in self.trials:
            self.trials[c] = self._run(c)
        return self.trials[c]

    def scene(self, c: Config) -> Scenario:
        """The configuration over the horizon, recording at each macro step on the check grid."""
        return dataclasses.replace(bench.apply(self.sc, self.p, c), stop_time=self.stop,
                                   record_interval=bench.lcm(c.macro_step, self.grid))  # fmt: skip

    def _run(self, c: Config) -> Trial:
        from master.api import run
        from master.backends.component import SimulationError
        from master.evidence.linear import is_stable, spectral_radius

        rho = math.nan
        if self.lin is not None:
            scheme = bench.linear_scheme(self.lin, self.p, c)
            rho = spectral_radius(scheme, float(c.macro_step))
            if not is_stable(scheme, float(c.macro_step)):
                return Trial(c, False, math.inf, f"unstable by the linear analysis (rho {rho:.4f})", rho)
        scene = self.scene(c)
        try:
            with bench.quiet():
                res = run(scene, backend="in-process")
        except SimulationError as e:
            return Trial(c, False, math.inf, str(e).split(" (hint")[0], rho)
        self.model.learn(res.summary, scene)
        rep = compare(as_trajectory(res.data), self.ref, list(self.p.variables) if self.p.variables else None)
        ok = rep.worst_max <= self.tolerance
        status = "finished" if ok else f"error {rep.worst_max:.3g} ({rep.worst_max_variable})"
        it = res.summary.iterations
        sweeps = it["sweeps"] / it["macro_steps"] if it and it["macro_steps"] else 0.0
        return Trial(c, ok, rep.worst_max, status, rho, sweeps)

    def sweeps(self, c: Config) -> float:
        """Mean sweeps per macro step of a configuration: its run's, else the linear model's
        estimate, else the most any iterated run needed so far (at least one)."""
        if not c.iterated:
            return 0.0
        if c in self.trials and self.trials[c].sweeps:
            return self.trials[c].sweeps
        if self.lin is not None:
            from master.evidence.linear import sweeps_needed

            tolerance = bench.iteration(self.sc, c).tolerance
            return sweeps_needed(bench.linear_scheme(self.lin, self.p, c), float(c.macro_step), tolerance)
        return max([t.sweeps for t in self.trials.values()] + [1.0])

    def cost(self, c: Config) -> float:
        """Modelled s per simulated s with the runs so far (the search's pruning only)."""
        return CostModel.cost(self.scene(c), self.model.calibrate(), self.sweeps(c))


def _pair(name: str, sc: Scenario) -> tuple[str, str]:
    """A "component.variable" column name as (component, variable); components of nested systems
    are qualified names with dots of their own (`master.scenario.names`)."""
    return split(name, [c.name for c in sc.components]) or tuple(name.split(".", 1))


def check_grid(sc: Scenario, steps: list[Fraction], span: Fraction) -> Fraction:
    """The spacing (s) of the times errors are compared at: the finest grid on which the scene's
    smallest component step and every candidate macro step at least as coarse all produce outputs
    (their greatest common divisor), at most MAX_POINTS times over `span`."""
    smallest = min(sc.macro_step / c.step_ratio for c in sc.components)
    g = smallest
    for h in steps:
        if h >= smallest:
            g = _gcd(g, h)
    if span / g > MAX_POINTS:
        g = min((h for h in steps if h >= span / MAX_POINTS), default=steps[-1])
    return g


def _gcd(a: Fraction, b: Fraction) -> Fraction:
    return Fraction(math.gcd(a.numerator * b.denominator, b.numerator * a.denominator),
                    a.denominator * b.denominator)  # fmt: skip


def largest_step(
    pilot: Pilot, c: Config, steps: list[Fraction], start: int, bound: float
) -> tuple[Trial, str]:
    """The trial at the largest of `steps` (ascending) within the tolerance, or the failed trial
    at the smallest step tried and why it is the last. Galloping from steps[start] (up while the
    tolerance is met, else down), then bisection: error grows with the step. Going down stops
    where the modelled cost passes `bound` (s): such a step could not win."""

    def at(i: int) -> Trial:
        return pilot(dataclasses.replace(c, macro_step=steps[i]))

    if at(start).ok:
        lo, jump = start, 1
        while lo + jump < len(steps) and at(lo + jump).ok:
            lo, jump = lo + jump, 2 * jump
        hi = min(lo + jump, len(steps))
    else:
        hi, jump = start, 1
        while True:
            i = max(hi - jump, 0)
            if pilot.cost(dataclasses.replace(c, macro_step=steps[i])) > bound:
                i = next(
                    (
                        k
                        for k in range(i + 1, hi)
                        if pilot.cost(dataclasses.replace(c, macro_step=steps[k])) <= bound
                    ),
                    hi,
                )
                if i == hi:
                    return at(
                        hi
                    ), f"{at(hi).status} at {float(steps[hi]):g} s; smaller steps cost more than the best"
            if at(i).ok:
                lo = i
                break
            if i == 0:
                return at(0), f"{at(0).status} at the smallest step {float(steps[0]):g} s"
            hi, jump = i, 2 * jump
    while hi - lo > 1:  # steps[lo] meets the tolerance, steps[hi] does not (or is past the end)
        mid = (lo + hi) // 2
        lo, hi = (mid, hi) if at(mid).ok else (lo, mid)
    return at(lo), ""


def tune(
    scenario: Scenario,
    tolerance: float,
    real_time_budget: float | None = None,
    pilot_time: Fraction | None = None,
    repeats: int = 3,
    rounds: int = ROUNDS,
) -> TuneResult:
    """Search the scene's configurations for the fastest that meets `tolerance` (see the module);
    `rounds` of coordinate search at most. Raises TuneError where the scene has no reference
    that resolves the tolerance."""
    p = bench.profile_for(scenario)
    with bench.said_once(bench.base_scene(scenario, p)):  # dozens of runs: each warning said once
        return _tune(scenario, tolerance, real_time_budget, pilot_time, repeats, rounds)


def pilot_for(
    scenario: Scenario, tolerance: float, pilot_time: Fraction | None = None
) -> tuple[Pilot, list[Fraction]]:
    """The pilot of a tune (its horizon, check grid, reference and linearisation) and the ladder
    of macro steps it tries. Raises TuneError where the reference cannot check `tolerance`."""
    from master.evidence.reference import ReferenceFailed, solve

    p = bench.profile_for(scenario)
    span = scenario.stop_time - scenario.start_time if pilot_time is None else pilot_time
    if p.generic:  # compared on a grid of about 100 rows, so that steps up to its spacing can be tried
        grid = [h for h in ladder(span) if h <= span / 100 and (h / p.record_interval).denominator == 1]
        p = dataclasses.replace(p, record_interval=grid[-1]) if grid else p
    lowest = min(p.base.macro_step, p.baseline.macro_step) / FLOOR
    steps = [h for h in ladder(_gcd(p.record_interval, span)) if lowest <= h <= span]  # each divides span
    if not steps:
        raise TuneError(f"{scenario.path}: no round macro step divides both the record interval "
                        f"{float(p.record_interval):g} s and the horizon {float(span):g} s")  # fmt: skip
    stop = scenario.start_time + span
    grid = check_grid(scenario, steps, span)
    names = p.variables or tuple(f"{c}.{v}" for c, v in scenario.record)
    base = dataclasses.replace(scenario, macro_step=grid, record_interval=grid, stop_time=stop,
                               record=tuple(_pair(n, scenario) for n in names))  # fmt: skip
    try:
        with bench.quiet():
            solved = solve(base)
    except ReferenceFailed as e:
        raise TuneError(str(e)) from None
    if not solved.converged and solved.uncertainty * RESOLVED > tolerance:
        raise TuneError(f"{scenario.path}: a tolerance of {tolerance:g} cannot be checked against "
                        f"{solved.what}")  # fmt: skip
    lin = None if p.generic else bench.linearize_scene(scenario, p)  # a scene of the project's FMUs
    return Pilot(scenario, p, solved, tolerance, lin, stop, grid), steps


def _tune(
    scenario: Scenario,
    tolerance: float,
    real_time_budget: float | None,
    pilot_time: Fraction | None,
    repeats: int,
    rounds: int,
) -> TuneResult:
    pilot, steps = pilot_for(scenario, tolerance, pilot_time)
    p = pilot.p
    choices: list[Choice] = []
    failed: list[tuple[str, Trial, str]] = []

    def rank() -> list[Choice]:
        for ch in choices:
            ch.cost = pilot.cost(ch.trial.config)
        return sorted(choices, key=lambda ch: (ch.cost, ch.family))

    def search(named: list[tuple[str, Config]]) -> None:
        for name, c in named:
            if any(ch.family == name for ch in choices) or any(f[0] == name for f in failed):
                continue
            best = rank()[0] if choices else None
            near = best.trial.config.macro_step if best else p.base.macro_step
            start = min(range(len(steps)), key=lambda i: abs(math.log(steps[i] / near)))
            bound = PRUNE * best.cost if best else math.inf
            trial, why = largest_step(pilot, c, steps, start, bound)
            if trial.ok:
                choices.append(Choice(name, trial))
            else:
                failed.append((name, trial, why))

    search(families(p))
    expanded: set[str] = set()
    # a scene without a profile has a coordinate search only where the master integrates components
    for _ in range(rounds if p.model_exchange or not p.generic else 0):  # from the best families
        # the cheapest dual-rate families within the tolerance, else those nearest to it
        dual = [(ch.family, ch.trial) for ch in rank() if not ch.trial.config.single_rate]
        dual += sorted(((n, t) for n, t, _ in failed if not t.config.single_rate), key=lambda f: f[1].error)
        todo = [(n, t) for n, t in dual if n not in expanded][:VARIANTS_OF]
        if not todo:
            break
        for name, t in todo:
            expanded.add(name)
            search(generic_variants(t.config) if p.generic else variants(t.config, p))
    costs = pilot.model.calibrate()  # once: every candidate is ranked by these times
    for ch in choices:
        ch.cost = CostModel.cost(pilot.scene(ch.trial.config), costs, ch.trial.sweeps)
    ranked = sorted(choices, key=lambda ch: (ch.cost, ch.family))
    horizon = pilot.stop - scenario.start_time
    result = TuneResult(scenario, p, tolerance, float(horizon), float(pilot.grid), pilot.reference.what,
                        ranked, failed, None, real_time_budget, len(pilot.trials), costs=costs)  # fmt: skip
    if ranked:
        first, second = (ranked + [None])[:2]
        result.best, result.runner_up, result.verdict = decide(first, second, pilot.scene, repeats)
    if result.best is not None and pilot.lin is not None:
        result.stable_limit = _stable_limit(pilot.lin, p, result.best.trial.config)
    return result


def decide(first: Choice, second: Choice | None, scene_of, min_rounds: int = MIN_ROUNDS):
    """(winner, the other, why) of the two cheapest by the model, timed in turn with the serial
    backend (the order swapped each round, so that drifting load falls on both alike) until the
    median ratio of their times is outside the noise (twice its standard error, and SIGNIFICANT)
    or clearly inside SIGNIFICANT, MAX_ROUNDS at most; equal within the noise, the cheaper by the
    model wins. Without a second, the first is timed `min_rounds` times (MIN_ROUNDS at least)."""
    from master.api import run

    def clock(ch: Choice) -> None:
        with bench.quiet():
            ch.timed.append(run(scene_of(ch.trial.config), backend="serial").summary.wall_time)

    min_rounds = max(min_rounds, MIN_ROUNDS)
    if second is None:
        for _ in range(min_rounds):
            clock(first)
        return first, None, ""
    margin = math.log1p(SIGNIFICANT)
    for k in range(1, max(MAX_ROUNDS, min_rounds) + 1):
        for ch in (first, second) if k % 2 else (second, first):
            clock(ch)
        if k < min_rounds:
            continue
        logs = [math.log(a / b) for a, b in zip(first.timed, second.timed, strict=True)]
        m = statistics.median(logs)
        noise = 2 * 1.4826 * statistics.median(abs(x - m) for x in logs) / math.sqrt(k)
        if abs(m) > max(noise, margin):
            winner, other = (first, second) if m < 0 else (second, first)
            why = f"{math.exp(abs(m)):.2f}x faster in {k} interleaved timings, outside the noise"
            return winner, other, why
        if abs(m) + noise < margin:
            break
    return first, second, (f"as fast within the noise in {len(first.timed)} interleaved timings: the "
                           f"cheaper by the cost model")  # fmt: skip


def _stable_limit(lin, p: Profile, c: Config) -> float | None:
    """The largest macro step (s) at which the configuration stays stable, up to 100 times its own."""
    from master.evidence.linear import largest_stable_step

    try:
        return largest_stable_step(
            bench.linear_scheme(lin, p, c), float(c.macro_step), 100 * float(c.macro_step)
        )
    except ValueError:
        return None


def tuned_scenario(result: TuneResult) -> Scenario:
    """The scenario with the winning configuration, over its own stop time, recording on its own
    row grid where the new macro step divides it (else on the nearest common multiple)."""
    sc = result.scenario
    chosen = bench.apply(sc, result.profile, result.best.trial.config)
    rows = sc.record_interval or sc.macro_step
    interval = rows if (rows / chosen.macro_step).denominator == 1 else bench.lcm(rows, chosen.macro_step)
    return dataclasses.replace(chosen, stop_time=sc.stop_time, record_interval=interval)


def _speed(result: TuneResult, ch: Choice) -> str:
    """What a choice costs: measured where it was timed, else modelled."""
    if ch.wall_time is not None:
        per_s = ch.wall_time / result.horizon
        return f"{per_s * 1e3:.3g} ms per simulated s, {1 / per_s:.3g}x real time (timed)"
    return f"{ch.cost * 1e3:.3g} ms per simulated s, {1 / ch.cost:.3g}x real time (modelled)"


def _chosen(result: TuneResult) -> list[str]:
    best = result.best
    c = best.trial.config
    lines = [f"chosen: {best.family}, macro step {float(c.macro_step):g} s: error {best.trial.error:.3g}, "
             f"{_speed(result, best)}"]  # fmt: skip
    other = result.runner_up
    if other is not None:
        h = float(other.trial.config.macro_step)
        lines.append(f"  against the runner-up ({other.family}, macro step {h:g} s, error "
                     f"{other.trial.error:.3g}): {result.verdict}")  # fmt: skip
    if result.budget is not None:
        verdict = "within" if result.within_budget else "OVER"
        lines.append(f"  real-time budget {result.budget:g} s per simulated s: {verdict}")
    return lines


def _measure(result: TuneResult) -> str:
    what = ", ".join(result.profile.variables) if result.profile.variables else "every recorded variable"
    return (f"error: the largest deviation over the range of {what}, against {result.reference}, over "
            f"{result.horizon:g} s every {result.grid:g} s")  # fmt: skip


def summary(result: TuneResult, report_path: Path | None = None) -> str:
    """The console's few lines: the choice, its error and speed, how it was decided, the report."""
    lines = [f"master tune: {result.scenario.name} to a tolerance of {result.tolerance:g} ({result.pilots} "
             f"pilot runs, {len(result.choices)} families within it)"]  # fmt: skip
    lines += _chosen(result) if result.best is not None else ["no configuration tried meets the tolerance"]
    if report_path is not None:
        lines.append(f"report: {report_path}")
    return "\n".join(lines)


def report(result: TuneResult) -> str:
    """Why each choice was made and what it costs, as text."""
    p, best = result.profile, result.best
    lines = [
        f"master tune: {result.scenario.name} to a tolerance of {result.tolerance:g}",
        _measure(result),
        f"{result.pilots} pilot runs (in-process); candidates ranked by the cost model (counted work per "
        f"simulated s times the median time of each kind of call over the pilot runs); the two cheapest "
        f"timed in turn with the serial backend",
        "",
    ]
    if best is None:
        lines.append("no configuration tried meets the tolerance")
    else:
        lines += _chosen(result)
        c = best.trial.config
        if result.stable_limit is not None:
            lines.append(f"  linear stability (at t = {p.linearize_at:g} s): stable up to a macro step of "
                         f"{result.stable_limit:.4g} s, {result.stable_limit / float(c.macro_step):.3g}x the "
                         f"chosen one")  # fmt: skip
        single = next((ch for ch in result.choices if ch.trial.config.single_rate), None)
        multi = next((ch for ch in result.choices if ch.trial.config.ratio > 1), None)
        if single is not None and multi is not None:
            lines.append(f"  cheapest multirate (step ratio > 1: {multi.family}) against cheapest "
                         f"single-rate "
                         f"({single.family}), both within the tolerance, by the cost model: "
                         f"{single.cost / multi.cost:.2f}x the speed")  # fmt: skip
    head = f"{'model [ms/s]':>12} {'timed [ms/s]':>12} {'step [s]':>9} {'error':>9} {'rho':>8}  family"
    lines += ["", "families within the tolerance (largest step that meets it), cheapest first:", head]
    for ch in result.choices:
        timed = f"{ch.wall_time / result.horizon * 1e3:12.3g}" if ch.wall_time is not None else f"{'':>12}"
        lines.append(f"{ch.cost * 1e3:12.3g} {timed} {float(ch.trial.config.macro_step):9.3g} "
                     f"{ch.trial.error:9.3g} {ch.trial.rho:8.5f}  {ch.family}")  # fmt: skip
    if result.costs:
        lines += ["", "the cost model's calibration: time per call (median over the pilot runs)"]
        for kind, t in sorted(result.costs.items(), key=lambda kt: str(kt[0])):
            name = "master, per macro step" if kind == MACRO else (
                f"{kind[0]}: solver {SOLVER_NAMES.get(kind[1], kind[1])}, {kind[2]} solver step(s)"
                + (", polynomial inputs" if kind[3] else ""))  # fmt: skip
            lines.append(f"  {t * 1e6:10.3g} us  {name}")
    if result.failed:
        lines += ["", "families that met it at no step tried:"]
        lines += [f"  {name}: {why or trial.status}" for name, trial, why in result.failed]
    return "\n".join(lines)
