"""`master tune`: the cheapest configuration of a scene that meets an error tolerance.

The error of a configuration is the bench's measure (master.evidence.errors): the worst, over the
scene's error variables, of the largest deviation from the reference solution (Model Exchange, or
a converged co-simulation) on the record grid, relative to the variable's range. It is measured,
not estimated: each candidate is a pilot run over the bench horizon of the scene
(`Profile.stop_time`, or `pilot_time`), compared with the reference.

The search, in the bench's configuration space (master.evidence.bench):
1. families: single-rate (every component with the mechanics solver), and for every control step
   ratio and extrapolation order a dual-rate family; then a coordinate search: in each of up to
   ROUNDS rounds, the three cheapest dual-rate families that meet the tolerance (or, failing
   those, the nearest to it) not yet expanded have every neighbour one setting away tried
   (`variants`: coupling, control first with the mechanics interpolating, the mechanics' order
   and solver steps, control solver, order, ratio, mechanics solver). A scene without a bench
   profile varies its extrapolation order and coupling.
2. per family, the largest macro step of a ladder of round steps (1, 1.25, 2, 2.5, 4, 5 x 10^k dividing
   the record interval) that meets the tolerance: galloping from the best step found so far, then
   bisection (error grows with the step). A step the linear stability analysis finds unstable is
   not run; the search goes no lower than steps whose modelled cost is PRUNE times the best's.
   The cost model (`_Pilot.cost`) is learned from the pilot runs: the least time per step of
   each component with each solver inside its FMU calls, and of the master per macro step.
3. the four cheapest families by the model, and the cheapest single-rate and multirate ones, are
   timed (serial backend, median of `repeats` runs); the fastest wins. With a real-time budget F
   it must also step at most F s of wall time per simulated second.
"""

from __future__ import annotations

import dataclasses
import math
import statistics
from dataclasses import dataclass, field
from fractions import Fraction

from master.evidence import bench
from master.evidence.bench import AB2, AB3, EULER, SI_EULER, SI_MIDPOINT, SOLVER_NAMES, Config, Profile
from master.evidence.errors import Trajectory, as_trajectory, compare
from master.scenario.model import Scenario

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
MAX_SUBSTEPS = 16  # mechanics solver steps per macro step, at most
FINALISTS = 4  # families timed again at the end
FLOOR = 50  # no macro step below the scene's own (and its baseline's) divided by this
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


@dataclass
class Choice:
    """The best configuration of one family: its largest macro step within the tolerance."""

    family: str
    trial: Trial
    timed: list[float] = field(default_factory=list)  # final wall times (serial backend)

    cost: float = math.inf  # modelled wall time (s) over the pilot horizon (`_Pilot.cost`)

    @property
    def wall_time(self) -> float:
        return statistics.median(self.timed) if self.timed else self.cost


@dataclass
class TuneResult:
    scenario: Scenario
    profile: Profile
    tolerance: float
    horizon: float  # s: the pilot runs' simulated time
    reference: str  # what the errors are measured against
    choices: list[Choice]  # every family that met the tolerance, fastest first once timed
    failed: list[tuple[str, Trial, str]]  # families that met it at no step tried: the last trial, why
    best: Choice | None
    budget: float | None  # wall s per simulated s allowed
    pilots: int = 0  # pilot runs made
    stable_limit: float | None = None  # the winner's largest linearly stable macro step (s)

    @property
    def within_budget(self) -> bool:
        return self.best is not None and (
            self.budget is None or self.best.wall_time <= self.budget * self.horizon
        )


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
        return [(f"order {k}, {c}", dataclasses.replace(b, order=k, coupling=c))
                for c in ("jacobi", "gauss-seidel") for k in range(4)]  # fmt: skip
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
        flip = "gauss-seidel" if (c.coupling or "jacobi") == "jacobi" else "jacobi"
        out.append(dataclasses.replace(c, coupling=flip))
        out += [dataclasses.replace(c, control_first=True, mech_order=2, mech_substeps=m) for m in (1, 2, 4)]
    else:
        out.append(dataclasses.replace(c, control_first=False, mech_order=0, mech_substeps=1))
        out += [dataclasses.replace(c, mech_substeps=m) for m in (c.mech_substeps // 2, 2 * c.mech_substeps)
                if 1 <= m <= MAX_SUBSTEPS]  # fmt: skip
        out += [
            dataclasses.replace(c, mech_order=k) for k in (c.mech_order - 1, c.mech_order + 1) if 0 <= k <= 3
        ]
    out += [dataclasses.replace(c, ctrl_solver=s) for s in CONTROL_SOLVERS if s != c.ctrl_solver]
    out += [dataclasses.replace(c, order=k) for k in (c.order - 1, c.order + 1) if 0 <= k <= 3]
    below = [r for r in p.ratios if r < c.ratio - 1][-1:]  # the profile's next ratios, and one either side
    above = [r for r in p.ratios if r > c.ratio + 1][:1]
    out += [dataclasses.replace(c, ratio=r) for r in (*below, c.ratio - 1, c.ratio + 1, *above) if r >= 1]
    out.append(dataclasses.replace(c, mech_solver=AB2 if c.mech_solver == AB3 else AB3))
    return [(_name(v), v) for v in out]


def _name(c: Config) -> str:
    if c.single_rate:
        return f"single-rate {SOLVER_NAMES[c.mech_solver]}"
    how = (f", control first, mechanics order {c.mech_order} x{c.mech_substeps}" if c.control_first
           else f", {c.coupling}" if c.coupling else "")  # fmt: skip
    return f"{SOLVER_NAMES[c.mech_solver]} + {SOLVER_NAMES[c.ctrl_solver]} r={c.ratio}, order {c.order}{how}"


class _Pilot:
    """Runs configurations over the pilot horizon and measures their errors (each once), and
    models their cost."""

    def __init__(self, sc: Scenario, p: Profile, ref: Trajectory, tolerance: float, lin, horizon: Fraction):
        self.sc, self.p, self.ref, self.tolerance, self.lin = sc, p, ref, tolerance, lin
        self.horizon = horizon
        self.trials: dict[Config, Trial] = {}
        self.per_step: dict[tuple[str, object], float] = {}  # (component, solver) -> s per step
        self.per_macro_step = math.inf  # the master's own s per macro step

    def __call__(self, c: Config) -> Trial:
        if c not in self.trials:
            self.trials[c] = self._run(c)
        return self.trials[c]

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
        scene = bench.apply(self.sc, self.p, c)
        try:
            with bench.quiet():
                res = run(scene, backend="in-process")
        except SimulationError as e:
            return Trial(c, False, math.inf, str(e).split(" (hint")[0], rho)
        self._learn(res.summary, scene)
        rep = compare(as_trajectory(res.data), self.ref, list(self.p.variables) if self.p.variables else None)
        ok = rep.worst_max <= self.tolerance
        status = "finished" if ok else f"error {rep.worst_max:.3g} ({rep.worst_max_variable})"
        return Trial(c, ok, rep.worst_max, status, rho)

    # The cost model: the least wall time per communication step of each component with each
    # solver inside its FMU calls, and of the master per macro step, over the pilot runs so far.
    # Pilot runs of a few ms are too noisy to rank configurations by their own wall times.
    def _learn(self, s, scene: Scenario) -> None:
        for comp in scene.components:
            n = s.steps.get(comp.name, 0)
            if n and comp.name in s.fmu_time:
                key = _step_kind(scene, comp)
                self.per_step[key] = min(self.per_step.get(key, math.inf), s.fmu_time[comp.name] / n)
        if s.macro_steps:
            self.per_macro_step = min(self.per_macro_step, s.overhead_per_macro_step)

    def cost(self, c: Config) -> float:
        """Modelled wall time (s) of the configuration over the pilot horizon (0 for a kind of
        step not yet seen: never pruned on a guess)."""
        scene = bench.apply(self.sc, self.p, c)
        n = self.horizon / c.macro_step
        per_macro = sum(comp.step_ratio * self.per_step.get(_step_kind(scene, comp), 0.0)
                        for comp in scene.components)  # fmt: skip
        return float(n) * (per_macro + (self.per_macro_step if math.isfinite(self.per_macro_step) else 0.0))


def _step_kind(scene: Scenario, comp) -> tuple:
    """What a communication step of a component costs by: its solver, its solver steps per
    communication step, polynomial inputs or not."""
    internal = float(comp.parameters.get("internal_step", 0.0) or 0.0)
    substeps = round(float(scene.macro_step) / comp.step_ratio / internal) if internal > 0 else 1
    return comp.name, comp.parameters.get("solver"), substeps, comp.interpolate_inputs


def largest_step(
    pilot: _Pilot, c: Config, steps: list[Fraction], start: int, bound: float
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


def _tune(
    scenario: Scenario,
    tolerance: float,
    real_time_budget: float | None,
    pilot_time: Fraction | None,
    repeats: int,
    rounds: int,
) -> TuneResult:
    from master.api import run
    from master.evidence.reference import ReferenceFailed, solve

    p = bench.profile_for(scenario)
    if pilot_time is not None:
        p = dataclasses.replace(p, stop_time=scenario.start_time + pilot_time)
    if p.generic:  # compared on a grid of about 100 rows, so that steps up to its spacing can be tried
        span = (p.stop_time or scenario.stop_time) - scenario.start_time
        grid = [h for h in ladder(span) if h <= span / 100 and (h / p.record_interval).denominator == 1]
        p = dataclasses.replace(p, record_interval=grid[-1]) if grid else p
    base = bench.base_scene(scenario, p)
    try:
        with bench.quiet():
            solved = solve(base)
    except ReferenceFailed as e:
        raise TuneError(str(e)) from None
    if not solved.converged and solved.uncertainty * RESOLVED > tolerance:
        raise TuneError(f"{scenario.path}: a tolerance of {tolerance:g} cannot be checked against "
                        f"{solved.what}")  # fmt: skip
    ref = solved.trajectory
    lin = None if p.generic else bench.linearize_scene(scenario, p)  # a scene of the project's FMUs
    horizon = base.stop_time - base.start_time
    pilot = _Pilot(scenario, p, ref, tolerance, lin, horizon)
    lowest = min(p.base.macro_step, p.baseline.macro_step) / FLOOR
    steps = [h for h in ladder(p.record_interval) if lowest <= h <= horizon]
    choices: list[Choice] = []
    failed: list[tuple[str, Trial, str]] = []

    def rank() -> list[Choice]:
        for ch in choices:
            ch.cost = pilot.cost(ch.trial.config)
        return sorted(choices, key=lambda ch: ch.wall_time)

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
    for _ in range(0 if p.generic else rounds):  # coordinate search from the best families
        # the cheapest dual-rate families within the tolerance, else those nearest to it
        dual = [(ch.family, ch.trial) for ch in rank() if not ch.trial.config.single_rate]
        dual += sorted(((n, t) for n, t, _ in failed if not t.config.single_rate), key=lambda f: f[1].error)
        todo = [(n, t) for n, t in dual if n not in expanded][:VARIANTS_OF]
        if not todo:
            break
        for name, t in todo:
            expanded.add(name)
            search(variants(t.config, p))
    ranked = rank()
    # the fastest single-rate and multirate families are timed too, so the report compares them
    single = [ch for ch in ranked if ch.trial.config.single_rate]
    multi = [ch for ch in ranked if ch.trial.config.ratio > 1]
    for ch in _unique(ranked[:FINALISTS] + single[:1] + multi[:1]):
        scene = bench.apply(scenario, p, ch.trial.config)
        with bench.quiet():
            ch.timed = [run(scene, backend="serial").summary.wall_time for _ in range(repeats)]
    timed = sorted((ch for ch in choices if ch.timed), key=lambda ch: ch.wall_time)
    rest = sorted((ch for ch in choices if not ch.timed), key=lambda ch: ch.wall_time)
    best = timed[0] if timed else None
    result = TuneResult(scenario, p, tolerance, float(horizon), solved.what, timed + rest,
                        failed, best, real_time_budget, pilots=len(pilot.trials))  # fmt: skip
    if best is not None and lin is not None:
        result.stable_limit = _stable_limit(lin, p, best.trial.config)
    return result


def _unique(choices: list[Choice]) -> list[Choice]:
    return list({id(ch): ch for ch in choices}.values())


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


def report(result: TuneResult) -> str:
    """Why each choice was made and what it costs, as text."""
    p, best = result.profile, result.best
    what = ", ".join(p.variables) if p.variables else "every recorded variable"
    lines = [
        f"master tune: {result.scenario.name} to a tolerance of {result.tolerance:g}",
        f"error: the largest deviation over the range of {what}, against {result.reference}, "
        f"over the first {result.horizon:g} s",
        f"{result.pilots} pilot runs (in-process); the fastest families timed again with the serial "
        f"backend (median of their runs)",
        "",
    ]
    if best is None:
        lines.append("no configuration tried meets the tolerance")
    else:
        c = best.trial.config
        rt = result.horizon / best.wall_time
        lines.append(f"chosen: {best.family}, macro step {float(c.macro_step):g} s: error "
                     f"{best.trial.error:.3g}, {best.wall_time * 1e3:.3g} ms for {result.horizon:g} s "
                     f"({rt:.3g}x real time)")  # fmt: skip
        if result.stable_limit is not None:
            lines.append(f"  linear stability (at t = {p.linearize_at:g} s): stable up to a macro step of "
                         f"{result.stable_limit:.4g} s, {result.stable_limit / float(c.macro_step):.3g}x the "
                         f"chosen one")  # fmt: skip
        if result.budget is not None:
            verdict = "within" if result.within_budget else "OVER"
            lines.append(f"  real-time budget {result.budget:g} s per simulated s: {verdict} "
                         f"({best.wall_time / result.horizon:.3g} s per s)")  # fmt: skip
        single = next((ch for ch in result.choices if ch.trial.config.single_rate and ch.timed), None)
        multi = next((ch for ch in result.choices if ch.trial.config.ratio > 1 and ch.timed), None)
        if single is not None and multi is not None:
            ratio = single.wall_time / multi.wall_time
            lines.append(f"  fastest multirate (step ratio > 1: {multi.family}) against fastest single-rate "
                         f"({single.family}), both within the tolerance: {ratio:.2f}x the speed")  # fmt: skip
    head = f"{'timed [ms]':>10} {'model [ms]':>10} {'step [s]':>9} {'error':>9} {'rho':>8}  family"
    lines += ["", "families within the tolerance (largest step that meets it), fastest first:", head]
    for ch in result.choices:
        timed = f"{ch.wall_time * 1e3:10.3g}" if ch.timed else f"{'':>10}"
        lines.append(f"{timed} {ch.cost * 1e3:10.3g} {float(ch.trial.config.macro_step):9.3g} "
                     f"{ch.trial.error:9.3g} {ch.trial.rho:8.5f}  {ch.family}")  # fmt: skip
    if result.failed:
        lines += ["", "families that met it at no step tried:"]
        lines += [f"  {name}: {why or trial.status}" for name, trial, why in result.failed]
    return "\n".join(lines)
