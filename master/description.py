"""An FMU's model description, read once per file version: its variables (one type for the runtime
and the scenario layer), the FMI types and their ranges, the capability flags of its Co-Simulation
and Model Exchange interfaces, its output dependencies, and the FMI function behind each of the
kernel's calls.

FMI 1.0, 2.0 and 3.0 are all read by fmpy; their type names differ (Real vs Float64, Integer vs
Int32), so types are compared through `type_class`. This module is below both master.fmu and
master.scenario and imports neither.
"""

from __future__ import annotations

import functools
import itertools
import math
import re
import zipfile
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from fmpy.model_description import ModelDescription, Unknown, ValidationError, read_model_description
from fmpy.validation import validate_model_description

from master.archives import damaged
from master.clocks import ClockVariable, read_clocks

# -- FMI types --------------------------------------------------------------------------------------
REAL_TYPES = ("Real", "Float64", "Float32")
INTEGER_TYPES = ("Integer", "Int8", "UInt8", "Int16", "UInt16", "Int32", "UInt32", "Int64", "UInt64")
FMI3_INTEGERS = ("Int8", "UInt8", "Int16", "UInt16", "Int32", "UInt32", "Int64", "UInt64")
NUMERIC = {"Float64", "Float32", "Int8", "UInt8", "Int16", "UInt16", "Int32", "UInt32", "Int64", "UInt64"}
FLOATS = {"Float64", "Float32"}
# FMI 2 names -> their FMI 3 equivalents, so both versions compare alike.
_SAME_TYPE = {"Real": "Float64", "Integer": "Int32"}
INT_RANGES = {
    "Int8": (-(2**7), 2**7 - 1),
    "UInt8": (0, 2**8 - 1),
    "Int16": (-(2**15), 2**15 - 1),
    "UInt16": (0, 2**16 - 1),
    "Int32": (-(2**31), 2**31 - 1),
    "UInt32": (0, 2**32 - 1),
    "Int64": (-(2**63), 2**63 - 1),
    "UInt64": (0, 2**64 - 1),
}
FLOAT32_MAX = 3.4028234663852886e38


def type_class(fmi_type: str) -> str:
    """The FMI 3 name of a variable type ('Real' -> 'Float64')."""
    return _SAME_TYPE.get(fmi_type, fmi_type)


def plain_type(fmi_type: str) -> str:
    """The FMI 2 name of the calls' value class: 'Real' for every float type, 'Integer' for every
    integer type; other types as they are."""
    if fmi_type in REAL_TYPES:
        return "Real"
    if fmi_type in INTEGER_TYPES:
        return "Integer"
    return fmi_type


def hex_bytes(text: str) -> bytes:
    """The bytes that hex digits stand for ("0a1B2c", "0x0a1b2c", "0a 1b": two digits a byte), as
    an FMI 3 Binary's start value writes them; ValueError if `text` is not that. An empty text is
    no bytes."""
    text = text.strip()
    if text[:2] in ("0x", "0X"):
        text = text[2:]
    return bytes.fromhex(text)


# -- FMI functions ----------------------------------------------------------------------------------
# kernel slot (kernel.h mk_component; native.CALLS names the failing ones) -> its function in FMI 1.0
# (Co-Simulation; exported as <modelIdentifier>_<name>), 2.0 and 3.0; None: not used with that
# version. FMI 1 cannot save its state and has no fmi2Terminated status.
FMI_FUNCTIONS = {
    "do_step": ("fmiDoStep", "fmi2DoStep", "fmi3DoStep"),
    "set_real": ("fmiSetReal", "fmi2SetReal", "fmi3SetFloat64"),
    "get_real": ("fmiGetReal", "fmi2GetReal", "fmi3GetFloat64"),
    "set_derivatives": ("fmiSetRealInputDerivatives", "fmi2SetRealInputDerivatives", None),
    "get_integer": ("fmiGetInteger", "fmi2GetInteger", "fmi3GetInt32"),
    "get_boolean": ("fmiGetBoolean", "fmi2GetBoolean", "fmi3GetBoolean"),
    "set_integer": ("fmiSetInteger", "fmi2SetInteger", "fmi3SetInt32"),
    "set_boolean": ("fmiSetBoolean", "fmi2SetBoolean", "fmi3SetBoolean"),
    "get_state": (None, "fmi2GetFMUstate", "fmi3GetFMUState"),
    "set_state": (None, "fmi2SetFMUstate", "fmi3SetFMUState"),
    "free_state": (None, "fmi2FreeFMUstate", "fmi3FreeFMUState"),
    "get_boolean_status": (None, "fmi2GetBooleanStatus", None),  # fmi2Terminated after fmi2Discard
    "get_string": ("fmiGetString", "fmi2GetString", "fmi3GetString"),  # String connections and records only
    "set_string": ("fmiSetString", "fmi2SetString", "fmi3SetString"),
    "get_binary": (None, None, "fmi3GetBinary"),  # Binary connections and records only
    "set_binary": (None, None, "fmi3SetBinary"),
    "get_directional_derivative": (None, "fmi2GetDirectionalDerivative", "fmi3GetDirectionalDerivative"),
    # Model Exchange components, integrated by the kernel (kernel.h: mk_component.me)
    "set_time": (None, "fmi2SetTime", "fmi3SetTime"),
    "set_states": (None, "fmi2SetContinuousStates", "fmi3SetContinuousStates"),
    "get_states": (None, "fmi2GetContinuousStates", "fmi3GetContinuousStates"),
    "get_derivatives": (None, "fmi2GetDerivatives", "fmi3GetContinuousStateDerivatives"),
    "completed_step": (None, "fmi2CompletedIntegratorStep", "fmi3CompletedIntegratorStep"),
    "get_event_indicators": (None, "fmi2GetEventIndicators", "fmi3GetEventIndicators"),
    "enter_event_mode": (None, "fmi2EnterEventMode", "fmi3EnterEventMode"),
    "update_discrete_states": (None, "fmi2NewDiscreteStates", "fmi3UpdateDiscreteStates"),
    "enter_continuous_time_mode": (None, "fmi2EnterContinuousTimeMode", "fmi3EnterContinuousTimeMode"),
    # FMI 3 Co-Simulation with Event Mode (kernel.h: mk_component.cs_events)
    "enter_step_mode": (None, None, "fmi3EnterStepMode"),
    # FMI 3 clocks: output clocks whose ticks are counted (kernel.h: mk_component.out_clock_ticks),
    "get_clock": (None, None, "fmi3GetClock"),
    "set_clock": (None, None, "fmi3SetClock"),  # triggered input clocks of one in event mode
}


# the kernel's slots of a Scheduled Execution component (kernel.h: mk_scheduled) -> FMI 3 function
SCHEDULED_FUNCTIONS = {
    "activate_model_partition": "fmi3ActivateModelPartition",
    "get_interval": "fmi3GetIntervalDecimal",
}


def fmi_function(slot: str, fmi: int) -> str | None:
    """The FMI function of kernel slot `slot` in FMI version `fmi` (1, 2 or 3); None if it has none."""
    return FMI_FUNCTIONS[slot][fmi - 1]


# -- variables --------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Variable:
    """One model variable: a scalar, or an FMI 3 array (one value reference for all its elements)."""

    name: str
    vr: int
    type: str  # the calls' value class: "Real", "Integer", "Boolean", "String", "Enumeration", "Binary", ...
    causality: str  # parameter, calculatedParameter, structuralParameter, input, output, local, independent
    variability: str
    initial: str | None
    start: str | None
    unit: str | None  # its own or its declared type's
    description: str | None
    fmi_type: str = ""  # as the FMU spells it: Real, Float64, Float32, Int8, ..., Enumeration ("": `type`)
    shape: tuple[int, ...] = ()  # FMI 3 array: its dimensions (the start sizes); () for a scalar
    min: str | None = None  # its own or its declared type's
    max: str | None = None
    items: tuple[tuple[str, int], ...] = ()  # Enumeration items (name, value)

    def __post_init__(self) -> None:
        if not self.fmi_type:
            object.__setattr__(self, "fmi_type", self.type)

    @property
    def size(self) -> int:
        """Number of values: the product of the dimensions, 1 for a scalar."""
        return math.prod(self.shape)

    @property
    def kind(self) -> str:
        """Version independent type name: Float64, Int32, Boolean, String, Enumeration, ..."""
        return type_class(self.fmi_type)


def variables_of(md: ModelDescription) -> dict[str, Variable]:
    """Variables of a model description by name; an FMI 3 array with its shape (the sizes its
    dimensions start with, read by fmpy: a Dimension's start or its structural parameter's)."""
    out: dict[str, Variable] = {}
    for v in md.modelVariables:
        declared = v.declaredType
        out[v.name] = Variable(
            name=v.name,
            vr=int(v.valueReference),
            type=plain_type(v.type),
            causality=v.causality or "local",
            variability=v.variability or "continuous",
            initial=v.initial,
            start=v.start,
            unit=v.unit or (declared.unit if declared is not None else None),
            description=v.description,
            fmi_type=v.type,
            shape=tuple(int(n) for n in getattr(v, "shape", ()) or ()),
            min=v.min if v.min is not None else (declared.min if declared is not None else None),
            max=v.max if v.max is not None else (declared.max if declared is not None else None),
            items=tuple((i.name, int(i.value)) for i in declared.items) if declared is not None else (),
        )
    return out


# -- FMI 3 arrays -----------------------------------------------------------------------------------
# An array is one variable (one value reference, its elements in a row in row-major order: the
# last index varies fastest). Its elements are named as FMI's structured names write them,
# indices from 1: y[1], y[2], y[3]; m[1,1], m[1,2], m[2,1], m[2,2]. Results have a column per
# element under that name; mm:Record and parameter bindings may name one element.
_ELEMENT = re.compile(r"^(.+)\[([0-9]+(?:,[0-9]+)*)\]$")


def typed(fmi_type: str, shape: tuple[int, ...] = (), scalar: bool = False) -> str:
    """A variable's type with its dimensions: "Float64[3]", "Float64[2,2]"; a scalar's type alone
    ("Float64", with `scalar` "a scalar Float64")."""
    if shape:
        return f"{fmi_type}[{','.join(str(n) for n in shape)}]"
    return f"a scalar {fmi_type}" if scalar else fmi_type


def element_names(name: str, shape: tuple[int, ...]) -> list[str]:
    """The names of an array's elements in row-major order; [name] for a scalar (shape ())."""
    if not shape:
        return [name]
    ranges = (range(1, n + 1) for n in shape)
    return [f"{name}[{','.join(str(i) for i in index)}]" for index in itertools.product(*ranges)]


def split_element(name: str) -> tuple[str, tuple[int, ...]] | None:
    """ "m[2,1]" -> ("m", (2, 1)); None if `name` does not end in indices written as
    `element_names` writes them (no spaces, no leading zeros)."""
    m = _ELEMENT.match(name)
    if m is None:
        return None
    index = tuple(int(i) for i in m.group(2).split(","))
    return (m.group(1), index) if m.group(2) == ",".join(str(i) for i in index) else None


def lookup(variables: Mapping[str, Any], name: str) -> tuple[Any, int | None] | None:
    """(variable, position) of what `name` names among `variables` (anything with `.shape`): a
    variable itself (position None), or one element y[i,j] of an array y (position: its index
    among y's values, row major). A variable of that exact name wins (FMI 2 FMUs name scalars
    "x[1]"). None if it names neither."""
    v = variables.get(name)
    if v is not None:
        return v, None
    split = split_element(name)
    if split is None:
        return None
    base, index = split
    v = variables.get(base)
    if v is None or len(index) != len(v.shape):
        return None
    if not all(1 <= i <= n for i, n in zip(index, v.shape, strict=True)):
        return None
    position = 0
    for i, n in zip(index, v.shape, strict=True):
        position = position * n + i - 1
    return v, position


# -- capabilities and dependencies ------------------------------------------------------------------
CO_SIMULATION = "CoSimulation"
MODEL_EXCHANGE = "ModelExchange"
SCHEDULED_EXECUTION = "ScheduledExecution"  # FMI 3: the master activates its partitions (master.clocks)


@dataclass(frozen=True)
class Capability:
    """What one interface of an FMU (Co-Simulation or Model Exchange) declares it can do, with the
    FMU's output dependencies: what the planner and the checks need besides the variables."""

    can_interpolate_inputs: bool = False  # Co-Simulation only
    fmi_version: str = "2.0"
    can_get_set_state: bool = False
    once_per_process: bool = False  # canBeInstantiatedOnlyOncePerProcess
    needs_execution_tool: bool = False
    # output -> the inputs it depends on directly (None: every output on every input)
    dependencies: dict[str, frozenset[str]] | None = None
    assumed: frozenset[str] = frozenset()  # outputs that declare no dependencies (`output_dependencies`)
    directional_derivatives: bool = False  # providesDirectionalDerivative(s), as fmpy reads it
    model_exchange: bool = False  # the flags of the Model Exchange interface (else Co-Simulation)
    event_indicators: int = 0  # Model Exchange: numberOfEventIndicators (watched by the kernel: state events)
    model_identifier: str = ""
    completed_integrator_step: bool = False  # Model Exchange: needsCompletedIntegratorStep
    scheduled: bool = False  # the Scheduled Execution interface (master.clocks)
    clocks: tuple[ClockVariable, ...] = ()  # Scheduled Execution: its Clock variables
    event_mode: bool = False  # FMI 3 Co-Simulation: hasEventMode

    def depends(self, output: str, inputs: dict[str, Variable]) -> frozenset[str]:
        """The inputs `output` depends on directly (no table: all of `inputs`)."""
        if self.dependencies is None:
            return frozenset(n for n, v in inputs.items() if v.causality == "input")
        return self.dependencies.get(output, frozenset())


def output_dependencies(md: ModelDescription) -> tuple[dict[str, frozenset[str]], frozenset[str]]:
    """(output -> the inputs it depends on directly, the outputs that declare no dependencies):
    an output without a `dependencies` attribute depends on every input (FMI 2.0 section 2.2.8,
    FMI 3.0 section 2.4.8), an assumption the loop solver tests at the start of a run."""
    inputs = frozenset(v.name for v in md.modelVariables if v.causality == "input")
    depends = {v.name: inputs for v in md.modelVariables if v.causality == "output"}
    assumed = set(depends)
    for u in md.outputs:
        if u.variable is None or u.dependencies is None:
            continue
        depends[u.variable.name] = frozenset(d.name for d in u.dependencies) & inputs
        assumed.discard(u.variable.name)
    return depends, frozenset(assumed)


def feedthrough_outputs(md: ModelDescription) -> set[str]:
    """Outputs that may depend directly on inputs (no dependency list: assume they do)."""
    depends, _ = output_dependencies(md)
    return {o for o, inputs in depends.items() if inputs}


def interfaces(md: ModelDescription, path: Path | None = None) -> dict[str, Capability]:
    """The FMU's interfaces (CO_SIMULATION, MODEL_EXCHANGE, SCHEDULED_EXECUTION: those it has) with
    their flags; a Scheduled Execution interface with the clocks of the FMU at `path`."""
    depends, assumed = output_dependencies(md)
    out = {}
    se = md.scheduledExecution
    if se is not None:  # outputs change at activations only: none depends on inputs between them
        out[SCHEDULED_EXECUTION] = Capability(
            fmi_version=md.fmiVersion,
            can_get_set_state=bool(se.canGetAndSetFMUstate),
            once_per_process=bool(se.canBeInstantiatedOnlyOncePerProcess),
            needs_execution_tool=bool(se.needsExecutionTool),
            dependencies={v.name: frozenset() for v in md.modelVariables if v.causality == "output"},
            model_identifier=se.modelIdentifier or "",
            scheduled=True,
            clocks=read_clocks(path) if path is not None else (),
        )
    for name, kind in ((CO_SIMULATION, md.coSimulation), (MODEL_EXCHANGE, md.modelExchange)):
        if kind is None:
            continue
        out[name] = Capability(
            can_interpolate_inputs=bool(getattr(kind, "canInterpolateInputs", False))
            or (name == CO_SIMULATION and bool(intermediate_inputs(md))),
            fmi_version=md.fmiVersion,
            can_get_set_state=bool(kind.canGetAndSetFMUstate),
            once_per_process=bool(kind.canBeInstantiatedOnlyOncePerProcess),
            needs_execution_tool=bool(kind.needsExecutionTool),
            dependencies=depends,
            assumed=assumed,
            directional_derivatives=bool(kind.providesDirectionalDerivative),
            model_exchange=name == MODEL_EXCHANGE,
            event_indicators=int(md.numberOfEventIndicators or 0) if name == MODEL_EXCHANGE else 0,
            model_identifier=kind.modelIdentifier or "",
            completed_integrator_step=name == MODEL_EXCHANGE and bool(kind.needsCompletedIntegratorStep),
            event_mode=name == CO_SIMULATION and uses_event_mode(md),
        )
    return out


def intermediate_inputs(md: ModelDescription) -> list[str]:
    """The inputs of an FMI 3 Co-Simulation FMU that providesIntermediateUpdate which the master sets
    inside doStep from its intermediate-update callback (the kernel's: their input polynomials at the
    time the FMU asks, what FMI 2 FMUs get as input derivatives): the scalar Float64 inputs declared
    intermediateUpdate="true". Where there is one, the FMU can interpolate its inputs."""
    cs = md.coSimulation
    if not md.fmiVersion.startswith("3.") or cs is None or not cs.providesIntermediateUpdate:
        return []
    return [
        v.name
        for v in md.modelVariables
        if v.causality == "input" and v.type == "Float64" and v.intermediateUpdate and not v.dimensions
    ]


# -- the description of one FMU file ----------------------------------------------------------------
@dataclass(frozen=True)
class Description:
    """What the master knows of one FMU file, read from its modelDescription.xml by `read`."""

    path: Path
    fmi_version: str
    variables: dict[str, Variable]
    feedthrough: dict[str, frozenset[str]]  # output name -> inputs it depends on directly
    interfaces: dict[str, Capability] = field(default_factory=dict)  # CO_SIMULATION, MODEL_EXCHANGE
    # structural parameters that give an array its size -> the arrays they size
    sizes: dict[str, tuple[str, ...]] = field(default_factory=dict)
    # why the master cannot run this FMU (`unsupported`: FMI version, interface); None if it can
    unsupported: str | None = None
    # what fmpy's strict validation finds wrong with a description read all the same (`defects`)
    defects: tuple[str, ...] = ()

    @property
    def co_simulation(self) -> Capability | None:
        return self.interfaces.get(CO_SIMULATION)

    @property
    def model_exchange(self) -> Capability | None:
        return self.interfaces.get(MODEL_EXCHANGE)

    @property
    def scheduled_execution(self) -> Capability | None:
        return self.interfaces.get(SCHEDULED_EXECUTION)

    @property
    def integrable(self) -> bool:
        """Whether the master can integrate it as a Model Exchange component (FMI 2.0 or 3.0)."""
        return self.model_exchange is not None and self.fmi_version != "1.0"

    @property
    def can_interpolate_inputs(self) -> bool:
        return self.co_simulation is not None and self.co_simulation.can_interpolate_inputs


class DescriptionError(Exception):
    """An FMU file whose model description cannot be read: one line saying why."""


def read(path: Path) -> Description:
    """The description of the FMU file at `path`, read once per file version (path, modification
    time, size) and process; DescriptionError saying why if it cannot be read (a damaged archive,
    fmpy's reason). Callers must not change the object they get."""
    st = path.stat()
    return _read(path.resolve(), st.st_mtime_ns, st.st_size)


@functools.lru_cache(maxsize=64)
def _read(path: Path, _mtime_ns: int, _size: int) -> Description:
    why = damaged(path)
    if why:
        raise DescriptionError(f"{path.name}: {why}")
    try:
        md = parse(path)
    except Exception as err:  # fmpy raises plain Exceptions for invalid descriptions
        why = unsized_array(path) or err
        raise DescriptionError(f"cannot read the modelDescription.xml of {path.name}: {why}") from err
    sizes: dict[str, list[str]] = {}
    for v in md.modelVariables:
        for d in v.dimensions or ():
            if d.start is None and d.variable is not None:
                sizes.setdefault(d.variable.name, []).append(v.name)
    depends, _ = output_dependencies(md)
    return Description(
        path=path,
        fmi_version=md.fmiVersion,
        variables=variables_of(md),
        feedthrough=depends,
        interfaces=interfaces(md, path),
        sizes={k: tuple(v) for k, v in sizes.items()},
        unsupported=unsupported(md, path),
        defects=defects(path),
    )


def unsupported(md: ModelDescription, path: Path) -> str | None:
    """Why the master cannot run the FMU at `path` (description `md`); None if it can. The one
    rule that `validate` and `run` share: FMI 1.0, 2.0 or 3.x, a Co-Simulation interface, a binary
    for this platform."""
    from fmpy import platform, platform_tuple, supported_platforms

    if md.fmiVersion not in ("1.0", "2.0") and not md.fmiVersion.startswith("3."):
        return (
            f"FMI {md.fmiVersion} is not supported: the master runs FMI 1.0, 2.0 and 3.x co-simulation FMUs"
        )
    if md.coSimulation is None and (md.modelExchange is None or md.fmiVersion == "1.0") and not scheduled(md):
        return (
            f"model '{md.modelName}' has no co-simulation interface (nor one of Model Exchange 2.0 or 3.0, "
            "nor Scheduled Execution)"
        )
    has = supported_platforms(str(path))
    if platform not in has and platform_tuple not in has:
        return f"no binary for this platform ({platform}); the FMU has: {', '.join(has) or 'none'}"
    return None


def runs_as_model_exchange(md: ModelDescription, asked: bool = False) -> bool:
    """Whether the master integrates an FMU of description `md` itself, as a Model Exchange
    component: asked for (a component's modelExchange setting), or the FMU has no Co-Simulation
    interface."""
    return asked or (md.coSimulation is None and md.modelExchange is not None)


def scheduled(md: ModelDescription) -> bool:
    """Whether the FMU has a Scheduled Execution interface (FMI 3)."""
    return getattr(md, "scheduledExecution", None) is not None


def runs_as_scheduled(md: ModelDescription, asked: bool = False) -> bool:
    """Whether the master runs an FMU of description `md` as a Scheduled Execution component
    (master.clocks): asked for (SSP implementation="ScheduledExecution"), or its only interface."""
    return scheduled(md) and (asked or (md.coSimulation is None and md.modelExchange is None))


def uses_event_mode(md: ModelDescription, model_exchange: bool = False) -> bool:
    """Whether the master runs an FMU of description `md` in FMI 3 Co-Simulation with Event Mode
    (eventModeUsed, early return allowed): it declares hasEventMode and runs as Co-Simulation."""
    cs = md.coSimulation
    return md.fmiVersion.startswith("3") and not model_exchange and cs is not None and bool(cs.hasEventMode)


# -- reading modelDescription.xml -------------------------------------------------------------------
class InvalidDescription(Exception):
    """A modelDescription.xml the master cannot use: fmpy's findings, on one line."""

    def __init__(self, problems: list[str]) -> None:
        super().__init__("; ".join(problems))


def parse(path: Path) -> ModelDescription:
    """An FMU file's modelDescription.xml parsed and checked against the FMI schema by fmpy, once
    per file version (path, modification time, size) and process: the one reader that `read`,
    master.fmu.read_description and the references share. A description that breaks one of
    fmpy's further rules that `tolerated` names (as peer masters do) is read all the same:
    `defects` lists them. Raises an Exception with one line saying why
    for a description that cannot be used; callers must not change the object they get."""
    return _parsed(path)[0]


def defects(path: Path) -> tuple[str, ...]:
    """What fmpy's strict validation finds wrong with a description `parse` reads all the same
    (fmpy's words, each naming the variable and its line); empty for a valid one."""
    return _parsed(path)[1]


def _parsed(path: Path) -> tuple[ModelDescription, tuple[str, ...]]:
    path = Path(path)
    st = path.stat()
    return _parse(path.resolve(), st.st_mtime_ns, st.st_size)


# fmpy's validation findings that leave a description usable by this master, as peer masters
# (libcosim, ecos, OMSimulator) read them; any other finding refuses the FMU.
TOLERATED = (
    # units are compared as written (a connection's two units must be equal), never looked up
    re.compile(r'^The (display )?unit "[^"]*" of .*variable "[^"]*" .*is not defined\.$'),
    # a non-Real signal is held between communication points whatever its variability says
    re.compile(
        r'^The variable "[^"]*" \(line \d+\) is of type \w+ and must have variability != "continuous"\.$'
    ),
    # start values of calculated and independent variables are never set by the master
    re.compile(r'^The variable "[^"]*" \(line \d+\) has (initial="calculated"|causality="independent") but'),
)
_DUPLICATE = re.compile(r'^The variable name "(?P<name>[^"]*)" \(line \d+\) is not unique\.$')


def tolerated(problem: str, md: ModelDescription) -> bool:
    """Whether fmpy's validation finding `problem` leaves the description `md` usable: see
    TOLERATED; a name used twice only among local variables (FMI 1.0 "internal"), which no
    connection, binding or stimulus can name."""
    if any(r.match(problem) for r in TOLERATED):
        return True
    dup = _DUPLICATE.match(problem)
    if dup is None:
        return False
    same = [v for v in md.modelVariables if v.name == dup["name"]]
    return all(v.causality in ("local", "internal") for v in same)


@functools.lru_cache(maxsize=64)
def _parse(path: Path, _mtime_ns: int, _size: int) -> tuple[ModelDescription, tuple[str, ...]]:
    md, found = _checked(path)
    if md.fmiVersion == "1.0":
        _fmi1_terms(path, md)
    elif md.fmiVersion.startswith("3."):
        _intermediate_update(path, md)
    return md, found


def _intermediate_update(path: Path, md: ModelDescription) -> None:
    """The FMI 3 variables' intermediateUpdate attribute, which fmpy does not read."""
    from lxml import etree

    with zipfile.ZipFile(path) as zf:
        root = etree.fromstring(zf.read("modelDescription.xml"))
    marked = {e.get("name") for e in root.iterfind("ModelVariables/*[@intermediateUpdate='true']")}
    for v in md.modelVariables:
        v.intermediateUpdate = v.name in marked


# FMI 1.0 Co-Simulation capabilities that fmpy does not read -> how to read each
FMI1_CAPABILITIES = {
    "canHandleVariableCommunicationStepSize": lambda x: x == "true",
    "canInterpolateInputs": lambda x: x == "true",
    "maxOutputDerivativeOrder": int,
    "canBeInstantiatedOnlyOncePerProcess": lambda x: x == "true",
}


def _fmi1_terms(path: Path, md: ModelDescription) -> None:
    """An FMI 1.0 description in FMI 2's terms where fmpy leaves FMI 1's (it already reads
    causality "internal" as local and variability "parameter" as a parameter): causality "none"
    (no influence on the model) is local too; the outputs are listed with their DirectDependency
    as FMI 2's ModelStructure lists them (fmpy lists none); the Capabilities attributes, which fmpy leaves at
    their defaults, are set on its CoSimulation; an FMU of CoSimulation_Tool wraps a tool, FMI 2's
    needsExecutionTool."""
    from lxml import etree

    for v in md.modelVariables:
        if v.causality == "none":
            v.causality = "local"
    with zipfile.ZipFile(path) as zf:
        root = etree.fromstring(zf.read("modelDescription.xml"))
    # the outputs with their DirectDependency (the inputs each depends on directly; none given:
    # every input), where FMI 2 lists them in ModelStructure
    by_name = {v.name: v for v in md.modelVariables}
    for i, e in enumerate(root.findall("ModelVariables/ScalarVariable"), 1):
        if e.get("causality") != "output":
            continue
        direct = e.find("DirectDependency")
        names = [(n.text or "").strip() for n in direct.findall("Name")] if direct is not None else None
        # a name that is no variable: assume the output depends on every input, as without the list
        depends = [by_name[n] for n in names] if names is not None and set(names) <= by_name.keys() else None
        md.outputs.append(Unknown(index=i, variable=by_name[e.get("name")], dependencies=depends))
    if md.coSimulation is None:
        return

    for kind in root.findall("Implementation/*"):
        if kind.tag == "CoSimulation_Tool":
            md.coSimulation.needsExecutionTool = True
        caps = kind.find("Capabilities")
        for name, read in FMI1_CAPABILITIES.items():
            if caps is not None and caps.get(name) is not None:
                setattr(md.coSimulation, name, read(caps.get(name)))


def _checked(path: Path) -> tuple[ModelDescription, tuple[str, ...]]:
    try:
        return read_model_description(str(path), validate=True), ()
    except ValidationError as strict:
        problems = list(strict.problems)
    try:
        md = read_model_description(str(path), validate=False)
    except Exception:
        raise InvalidDescription(problems) from None
    found = validate_model_description(md)
    if found != problems:  # the schema refused it: its structure cannot be trusted
        raise InvalidDescription(problems)
    refused = [p for p in found if not tolerated(p, md)]
    if refused:
        raise InvalidDescription(refused)
    return md, tuple(found)


def unsized_array(path: Path) -> str | None:
    """Why the size of an FMI 3 array of the FMU at `path` cannot be known before the run (a
    dimension that names no variable, or one without a start value); None if every array has
    its size (or the description cannot be read at all: fmpy says why)."""
    from lxml import etree

    try:
        with zipfile.ZipFile(path) as zf:
            root = etree.fromstring(zf.read("modelDescription.xml"))
    except Exception:
        return None
    variables = root.find("ModelVariables")
    if variables is None:
        return None
    by_vr = {e.get("valueReference"): e for e in variables if isinstance(e.tag, str)}
    for e in variables:
        for d in e.findall("Dimension") if isinstance(e.tag, str) else ():
            if d.get("start") is not None:
                continue
            size = by_vr.get(d.get("valueReference"))
            if size is None:
                return (
                    f"the size of array {e.get('name')} is variable {d.get('valueReference')}, "
                    "which the model description does not declare"
                )
            start = size.get("start")
            if start is None or not start.strip().isdigit():
                return (
                    f"the size of array {e.get('name')} is {size.get('name')}, which has no start value: "
                    "its size cannot be known before the run"
                )
    return None
