"""The public Python API: `run`, `validate`, `info`, `plan`.

result = master.run("models/oscillator/oscillator.ssd", stop_time=10, output="out.csv")
result.data["mass1.x"], result.summary.real_time_factor
"""

from __future__ import annotations

import dataclasses
import json
import logging
import os
from fractions import Fraction
from pathlib import Path

from master import description, extras
from master.backends import BACKENDS
from master.backends.component import SimulationError
from master.backends.driver import execute, interruption, stop_signals
from master.description import (
    CO_SIMULATION,
    MODEL_EXCHANGE,
    SCHEDULED_EXECUTION,
    defects,
    interfaces,
    runs_as_model_exchange,
    variables_of,
)
from master.fmu import FmuError, read_description
from master.recorder import Recorder, ResultsError, RunResult, RunSummary, metadata_path
from master.scenario import ScenarioError, check
from master.scenario.model import Component, Scenario, Value
from master.schedule import Plan, build_plan

log = logging.getLogger("master")

_NOTED_FMUS: set[str] = set()  # FMUs whose Plan.fmu_notes this process has said


class UsageError(Exception):
    """Bad input from the user (option, value or file), with a message saying what and where."""


def load_scenario(
    path: str | Path,
    overrides: dict[str, str] | None = None,
    stop_time: float | str | Fraction | None = None,
    macro_step: float | str | Fraction | None = None,
) -> Scenario:
    """Read a scenario file (.ssd / .ssp); overrides: "component.variable" -> value text;
    stop_time, macro_step (s): as --stop-time and --macro-step, over the file's."""
    from master.scenario import load

    path = Path(path)
    if not path.exists():
        raise UsageError(f"{path}: no such scenario file")
    return load(path, overrides or None, **_times(stop_time, macro_step))


def _times(stop_time, macro_step) -> dict[str, Fraction | None]:
    """--stop-time and --macro-step as exact times for the reader (a macro step must be positive)."""
    stop = _parse_time("--stop-time", stop_time) if stop_time is not None else None
    macro = _parse_time("--macro-step", macro_step) if macro_step is not None else None
    if macro is not None and macro <= 0:
        raise UsageError(f"--macro-step {macro_step}: must be positive")
    return {"stop_time": stop, "macro_step": macro}


def parse_value(text: str) -> Value:
    """A --set value: int, float, true/false, else the string itself."""
    low = text.strip().lower()
    if low in ("true", "false"):
        return low == "true"
    for conv in (int, float):
        try:
            return conv(text)
        except ValueError:
            pass
    return text


def _parse_time(what: str, value: float | str | Fraction) -> Fraction:
    try:
        return Fraction(str(value)) if not isinstance(value, Fraction) else value
    except (ValueError, ZeroDivisionError) as e:
        raise UsageError(f"{what}: {value!r} is not a number") from e


def apply_overrides(
    sc: Scenario,
    stop_time: float | str | Fraction | None = None,
    record: list[str] | None = None,
    set_values: dict[str, Value] | list[str] | None = None,
    output_interval: float | str | Fraction | None = None,
    record_coupling_errors: bool = False,
) -> Scenario:
    """A copy of `sc` with command-line style overrides ("component.variable" names);
    record_coupling_errors: record the coupling error columns (whatever the scenario says)."""
    from master.scenario.names import split  # components of nested systems: "sub.comp.var"

    names = [c.name for c in sc.components]
    if record_coupling_errors:
        sc = dataclasses.replace(sc, record_coupling_errors=True)
    if stop_time is not None:
        sc = dataclasses.replace(sc, stop_time=_parse_time("--stop-time", stop_time))
    if output_interval is not None:
        sc = dataclasses.replace(sc, record_interval=_parse_time("--output-interval", output_interval))
    if record:
        pairs = []
        for r in record:
            comp, var = split(r, names) or ("", "")
            if not var:
                raise UsageError(f"--record {r}: expected component.variable with a component of {names}")
            pairs.append((comp, var))
        sc = dataclasses.replace(sc, record=tuple(pairs))
    if set_values:
        items = set_values.items() if isinstance(set_values, dict) else map(_split_set, set_values)
        comps = {c.name: c for c in sc.components}
        for key, value in items:
            comp, var = split(key, comps) or ("", "")
            if not var:
                raise UsageError(
                    f"--set {key}={value}: expected component.variable=value with a component of {names}"
                )
            c = comps[comp]
            if not isinstance(set_values, dict):  # text: converted by the variable's type
                value = _typed_value(c, var, key, value)
            comps[comp] = dataclasses.replace(c, parameters={**c.parameters, var: value})
        sc = dataclasses.replace(sc, components=tuple(comps[n] for n in names))
    return sc


def _typed_value(c: Component, name: str, key: str, text: str) -> Value:
    """A --set text for variable `name` of component `c`, converted as the scenario reader does
    (hex digits for a Binary, an item name for an Enumeration); `parse_value`'s guess where the
    FMU cannot be read or has no such variable (the run then says why)."""
    from master.description import lookup
    from master.scenario.fmuinfo import SourceError
    from master.scenario.fmuinfo import read as read_info
    from master.scenario.values import BadValue, from_string

    try:
        found = lookup(read_info(Path(c.fmu_path)).variables, name)
    except (OSError, SourceError):
        found = None
    if found is None:
        return parse_value(text)
    try:
        return from_string(found[0], text)
    except BadValue as e:
        raise UsageError(f"--set {key}={text}: {e}") from None


def _split_set(text: str) -> tuple[str, str]:
    key, eq, value = text.partition("=")
    if not eq:
        raise UsageError(f"--set {text}: expected component.variable=value")
    return key.strip(), value.strip()


def plan(sc: Scenario) -> Plan:
    """Schedule a scenario from its FMUs' model descriptions (no FMU is loaded). A scenario that
    breaks a rule (`master.scenario.check`: one built in Python, or a file's after overrides)
    raises ScenarioError listing every problem, as `load` does for a file."""
    variables = {}
    caps = {}
    for c in sc.components:
        try:
            md = read_description(Path(c.fmu_path))
            info = description.read(Path(c.fmu_path))  # read once per file version and process
        except (FmuError, description.DescriptionError) as e:
            raise FmuError(f"{sc.path}: component {c.name}: {e}") from e
        variables[c.name] = info.variables
        kind = MODEL_EXCHANGE if runs_as_model_exchange(md, c.model_exchange is not None) else CO_SIMULATION
        kind = SCHEDULED_EXECUTION if c.scheduled else kind
        # the interface it is instantiated for (none: `check` says)
        caps[c.name] = info.interfaces.get(kind)
    problems = check(sc)  # the planner keeps no rule of its own
    if problems:
        raise ScenarioError(problems)
    return build_plan(sc, variables, caps)


def _make_backend(name: str, p: Plan, step_timeout: float | None = None, cpus: list[int] | None = None):
    from master.backends.workers import DEFAULT_STEP_TIMEOUT, WorkerBackend, separate, worker_groups

    timeout = step_timeout or DEFAULT_STEP_TIMEOUT
    if name == "in-process":
        from master.backends.in_process import InProcessBackend

        if p.exclusive:
            raise UsageError(
                f"{', '.join(p.exclusive[0])}: their FMU can be instantiated only once per process; "
                "--serial or --parallel give each its own worker"
            )
        return InProcessBackend(p)
    if name == "serial":
        return WorkerBackend(p, separate([[pc.name for pc in p.components]], p), timeout, cpus, "serial")
    if name == "parallel":
        return WorkerBackend(p, worker_groups(p), timeout, cpus)
    if name == "auto":
        from master.backends.auto import choose_backend

        chosen, why = choose_backend(p, timeout)
        log.info("backend %s chosen automatically: %s", chosen, why)
        be = _make_backend(chosen, p, step_timeout, cpus)
        be.name = f"{chosen} (auto: {why})"
        return be
    raise UsageError(f"unknown backend {name!r}; choose one of {', '.join(BACKENDS)}")


def say_fmu_notes(p: Plan) -> None:
    """The plan's notes on its FMUs (needsExecutionTool) at INFO, each FMU's once in this process:
    a bench or a tune runs one FMU many times."""
    for fmu, note in p.fmu_notes:
        if fmu not in _NOTED_FMUS:
            _NOTED_FMUS.add(fmu)
            log.info(note)


def run(
    scenario: str | Path | Scenario,
    *,
    stop_time: float | str | Fraction | None = None,
    macro_step: float | str | Fraction | None = None,
    output: str | Path | None = None,
    record: list[str] | None = None,
    set_values: dict[str, Value] | list[str] | None = None,
    output_interval: float | str | Fraction | None = None,
    backend: str = "serial",
    real_time: float | None = None,
    progress: bool = False,
    plot: str | Path | None = None,
    step_timeout: float | None = None,
    cpus: list[int] | None = None,
    record_coupling_errors: bool = False,
) -> RunResult:
    """Run a scenario (file or `Scenario`) and return its results.

    stop_time, macro_step, output_interval in s (a file's macro step is replaced while it is read:
    the components' steps follow it as docs/scenario-format.md says); `record` and `set_values`
    use "component.variable" names;
    `real_time` paces the run (1.0: wall clock speed). backend: "serial" (one worker process runs
    every FMU), "parallel" (a worker process per component or group), "auto" (parallel when a
    timed serial trial says it pays) or "in-process" (the FMUs in this process: no protection
    against a crashing FMU, for debugging); `step_timeout`: s one component's macro step may take
    before it counts as a hang (default 10); `cpus`: processors to pin the workers to, worker w on
    cpus[w % len(cpus)] (paced runs also ask for SCHED_FIFO and locked memory).
    `record_coupling_errors` (or `<mm:Record couplingErrors="true">`): one more column per
    extrapolated connection, "coupling_error(source.output -> consumer.input)": the absolute
    difference (in the signal's unit) between the sample the consumer's polynomial predicted and
    the sample the source produced, of the latest prediction checked; the row at time t shows the
    prediction of the source's sample at t - H (0 before the first full-order one).
    On failure, SIGINT, SIGTERM or SIGHUP a SimulationError is raised after the rows computed so
    far are written; it carries `.result` (a RunResult) and, when a signal stopped the run,
    `.signal` (its number).
    A `plot` without matplotlib installed raises extras.MissingExtra before the run.
    """
    extras.require("run", {"plot": plot})
    if isinstance(scenario, Scenario):
        if macro_step is not None:  # the step ratios are kept
            scenario = dataclasses.replace(scenario, macro_step=_times(None, macro_step)["macro_step"])
        sc = apply_overrides(scenario, stop_time, record, set_values, output_interval, record_coupling_errors)
    else:  # the reader converts and checks --set values against the FMUs
        texts = dict(_split_set(s) for s in set_values) if isinstance(set_values, list) else None
        if isinstance(set_values, dict):  # bytes (a Binary) as the hex digits the reader takes
            texts = {k: v.hex() if isinstance(v, bytes) else str(v) for k, v in set_values.items()}
        sc = apply_overrides(
            load_scenario(scenario, texts, stop_time, macro_step),
            stop_time, record, None, output_interval, record_coupling_errors,
        )  # fmt: skip
    p = plan(sc)
    for note in p.notes:
        log.info(note)
    say_fmu_notes(p)
    with stop_signals():
        if cpus is not None:
            if backend == "in-process":
                raise UsageError("--cpus pins worker processes; --in-process runs without any")
            bad = sorted(set(cpus) - os.sched_getaffinity(0))
            if bad or not cpus:
                raise UsageError(
                    f"--cpus {cpus}: not processors this process may use ({sorted(os.sched_getaffinity(0))})"
                )
        columns = p.columns
        try:  # before anything runs: a results file that cannot be written stops it at once
            recorder = Recorder(columns, Path(output) if output is not None else None, types=p.column_types)
        except ResultsError as e:
            raise UsageError(str(e)) from None
        try:
            be = _make_backend(backend, p, step_timeout, cpus)
        except BaseException:
            recorder.discard()
            raise
        try:
            try:
                be.open()
            except KeyboardInterrupt as e:  # a signal while the FMUs load: the same clean stop
                t0 = float(sc.start_time)
                raise interruption(e, t0, RunSummary(sc.name, be.name, "", 0.0, 0.0, 0)) from None
            summary = execute(p, be, recorder, real_time=real_time, progress=progress)
        except SimulationError as e:
            summary = e.summary  # type: ignore[attr-defined]
            summary.output = str(output) if output is not None else None
            _write_metadata(output, summary, sc, p)
            e.result = RunResult(recorder, summary)  # type: ignore[attr-defined]
            raise
        except BaseException:
            recorder.discard()
            raise
        finally:
            be.close()
    summary.output = str(output) if output is not None else None
    _write_metadata(output, summary, sc, p)
    result = RunResult(recorder, summary)
    if plot is not None:
        from master.recorder import plot_result

        try:
            plot_result(result.data, plot, title=sc.name, units=_units(sc, p))
        except (OSError, ValueError) as e:  # PIL raises either for a path it cannot write
            raise UsageError(f"--plot {plot}: cannot write the plot there ({e})") from None
    return result


def _write_metadata(output: str | Path | None, summary, sc: Scenario, p: Plan) -> None:
    """Beside the CSV: the run summary (with the real-time lateness histogram), each column's unit
    and type (as `Recorder.data` holds it: "float64", "int64", "uint64", "String" or "Binary";
    `read_csv` reads it), as JSON. A metadata file that cannot be written costs the run nothing
    but a warning."""
    if output is None:
        return
    meta = {
        "scenario": str(sc.path),
        "units": _units(sc, p),
        "types": {c: p.column_types.get(c, "float64") for c in p.columns},
        "summary": dataclasses.asdict(summary)
        | {
            "real_time_factor": summary.real_time_factor,
            "overhead_per_macro_step": summary.overhead_per_macro_step,
        },
    }
    try:
        metadata_path(output).write_text(json.dumps(meta, indent=1, default=str) + "\n")
    except OSError as e:
        log.warning("%s: metadata not written (%s)", metadata_path(output), e.strerror or e)


def _units(sc: Scenario, p: Plan) -> dict[str, str | None]:
    """Unit of each recorded column "component.variable" from the FMUs' model descriptions (an
    array element: the array's unit); a coupling error column has the unit of the signal (its
    source output)."""
    find = _variables(sc)
    units = {f"{c}.{v}": getattr(find(c, v), "unit", None) for c, v in p.record}
    for name, (source, output, *_) in zip(p.columns[1 + len(p.record) :], p.record_errors, strict=True):
        units[name] = getattr(find(source, output), "unit", None)
    return units


def _variables(sc: Scenario):
    """find(component, name): the model variable a recorded name means (an array element: its
    array), None if none."""
    from master.description import lookup

    described = {c.name: variables_of(read_description(Path(c.fmu_path))) for c in sc.components}

    def find(component: str, name: str):
        hit = lookup(described[component], name)
        return hit[0] if hit else None

    return find


def validate(
    path: str | Path,
    stop_time: float | str | Fraction | None = None,
    macro_step: float | str | Fraction | None = None,
) -> list:
    """Problems found in a scenario file (empty: none); see `master.scenario.validate`."""
    from master.scenario import validate as _validate

    return list(_validate(Path(path), **_times(stop_time, macro_step)))


def loop_notes(
    path: str | Path,
    stop_time: float | str | Fraction | None = None,
    macro_step: float | str | Fraction | None = None,
) -> list[str]:
    """What a valid scenario's plan says of its algebraic loops and of the FMUs that declare no
    dependencies there (`master validate` prints them)."""
    p = plan(load_scenario(path, None, stop_time, macro_step))
    return [n for n in p.notes if n.startswith("algebraic loop")] + [
        n for _, n in p.fmu_notes if "declares no dependencies" in n
    ]


def info(
    path: str | Path,
    stop_time: float | str | Fraction | None = None,
    macro_step: float | str | Fraction | None = None,
) -> str:
    """Text description of an FMU (variables, capabilities) or a scenario (components, where each
    setting came from, schedule)."""
    path = Path(path)
    if path.suffix.lower() == ".fmu":
        return fmu_info(path)
    sc = load_scenario(path, None, stop_time, macro_step)
    p = plan(sc)
    lines = [f"scenario {sc.name} ({sc.path})"]
    for c in sc.components:
        lines.append(f"  component {c.name}: {c.fmu_path}")
    values = {"start time": sc.start_time, "stop time": sc.stop_time, "macro step": sc.macro_step}
    values |= {f"{c.name} communication step": sc.macro_step / c.step_ratio for c in sc.components}
    for setting, origin in sc.origins.items():
        shown = f" = {_seconds(values[setting])}" if setting in values else ""
        lines.append(f"  {setting}{shown}: from {origin}")
    lines.append(p.describe())
    return "\n".join(lines)


def _seconds(t: Fraction) -> str:
    from master.scenario.settings import seconds

    return seconds(t)


def fmu_info(path: Path) -> str:
    """Variables and Co-Simulation capabilities of one FMU."""
    md = read_description(path)
    cs, me = md.coSimulation, md.modelExchange
    lines = [f"{path}: {md.modelName}, FMI {md.fmiVersion}, generated by {md.generationTool or '?'}"]
    if cs is not None:
        lines.append(
            f"  canHandleVariableCommunicationStepSize={cs.canHandleVariableCommunicationStepSize} "
            f"canInterpolateInputs={cs.canInterpolateInputs} "
            f"maxOutputDerivativeOrder={cs.maxOutputDerivativeOrder} "
            f"canGetAndSetFMUstate={cs.canGetAndSetFMUstate}"
        )
    if me is not None:  # the master integrates it where asked (modelExchange="true") or without cs
        lines.append(
            f"  Model Exchange{'' if cs is not None else ' only'}: {md.numberOfContinuousStates} continuous "
            f"states, {md.numberOfEventIndicators} event indicators, "
            f"canGetAndSetFMUstate={me.canGetAndSetFMUstate}"
        )
    se = interfaces(md, Path(path)).get(SCHEDULED_EXECUTION)
    if se is not None:  # the master activates its partitions (master.clocks)
        clocks = ", ".join(f"{c.name} ({c.causality}, {c.interval_variability})" for c in se.clocks)
        lines.append(f"  Scheduled Execution: clocks {clocks or 'none'}")
    lines += [f"  read all the same, as peer masters do: {d}" for d in defects(path)]
    lines.append(f"  {'name':<24} {'causality':<20} {'variability':<12} {'type':<12} {'start':<12} unit")
    for v in variables_of(md).values():
        shape = f"[{','.join(str(n) for n in v.shape)}]" if v.shape else ""  # an FMI 3 array
        kind = (v.fmi_type or v.type) + shape  # FMI 3's own type names: Float32, Int64, ...
        lines.append(
            f"  {v.name:<24} {v.causality:<20} {v.variability:<12} {kind:<12} "
            f"{v.start or '':<12} {v.unit or ''}"
        )
    return "\n".join(lines)


__all__ = [
    "run",
    "validate",
    "info",
    "plan",
    "apply_overrides",
    "UsageError",
    "SimulationError",
    "ScenarioError",
]
