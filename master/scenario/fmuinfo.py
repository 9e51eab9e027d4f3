"""What the checks need to know about an FMU: the FMU a component's source names, and what its
variables may be connected to, stimulated with and recorded as. The FMU's description itself
(variables, types, capabilities) is master.description's, read once per file.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from master import description
from master.description import (
    FLOAT32_MAX,
    INT_RANGES,
    Description,
    Variable,
    element_names,
    lookup,
    split_element,
    type_class,
    typed,
)

PROJECT_SCHEME = "project:"


# What a connection of each FMI type carries: the runtime's value kinds (kernel.h). FMI 2 Real and
# FMI 3 Float64 are both "Real", FMI 2 Integer and FMI 3 Int32 both "Integer" (so they connect
# across versions, as SSP compares them); every other FMI 3 numeric type is a kind of its own, set
# and read through the calls of its own type (an FMI 3 Enumeration through those of Int64). A
# String (FMI 2 or 3) and an FMI 3 Binary travel as bytes in a text ring beside the numeric history
# (kernel.h: MK_STRING_SLOT, at most MK_TEXT_MAX = 1023 bytes a value).
COUPLED = {
    "Real": "Real",
    "Float64": "Real",
    "Integer": "Integer",
    "Int32": "Integer",
    "Boolean": "Boolean",
    **{t: t for t in ("Float32", "Int8", "UInt8", "Int16", "UInt16", "UInt32", "Int64", "UInt64")},
    "String": "String",
    "Binary": "Binary",
    "Clock": "Clock",  # an output clock's count of ticks to a triggered input clock (master.clocks)
}
CONTINUOUS = ("Real", "Float32")  # extrapolated by the consumer's order; the other kinds are held
TEXTS = ("String", "Binary")  # the kinds carried as bytes, not as numbers: never stimulated
CONNECTABLE = "numeric, Boolean, Enumeration, String and Binary signals"
STIMULATED = "numeric, Boolean and Enumeration"


def coupling_kind(fmi_type: str, fmi_version: str) -> str | None:
    """What a connection of a variable of this type carries (`COUPLED`): "Real", "Integer",
    "Boolean", "String", or in FMI 3 "Float32", "Int8" ... "UInt64" (an Enumeration: "Int64"; in
    FMI 1 and 2 an Enumeration is an "Integer") and "Binary", "Clock" (its count of ticks: master.clocks).
    Kinds in `CONTINUOUS` are extrapolated by the consumer's order, the others held between
    communication points (order 0). A String or Binary connection carries at most 1023 bytes
    (kernel.h: MK_TEXT_MAX): a longer output stops the run."""
    if fmi_type == "Enumeration":
        return "Int64" if fmi_version.startswith("3") else "Integer"
    return COUPLED.get(fmi_type)


def direction_problems(start: str, out_causality: str, end: str, in_causality: str) -> list[str]:
    """Why a connection from `start` to `end` does not go output -> input (a problem per wrong
    end); empty if it does."""
    problems = []
    if out_causality != "output":
        problems.append(
            f"start {start} is {_a(out_causality)}, not an output: connections go output -> input"
        )
    if in_causality != "input":
        problems.append(f"end {end} is {_a(in_causality)}, not an input: connections go output -> input")
    return problems


def _a(causality: str) -> str:
    return f"an {causality}" if causality[0] in "aeiou" else f"a {causality}"


def connection_problem(
    start: str,
    out_type: str,
    out_version: str,
    end: str,
    in_type: str,
    in_version: str,
    out_shape: tuple[int, ...] = (),
    in_shape: tuple[int, ...] = (),
) -> str | None:
    """Why output `start` (of FMI type out_type, in an FMU of FMI version out_version) cannot
    drive input `end`; None if it can. Both ends must have the same type class (FMI 2 Real =
    FMI 3 Float64, FMI 2 Integer = FMI 3 Int32, a String = a String, as SSP compares them) and be
    connectable. An FMI 2 Enumeration is an Integer, an FMI 3 one an Int64: they do not connect to
    each other. FMI 3 arrays (out_shape, in_shape: their dimensions, () for a scalar) drive arrays
    of the same shape, element by element."""
    if type_class(out_type) != type_class(in_type):
        return f"type mismatch: {start} is {typed(out_type, out_shape)}, {end} is {typed(in_type, in_shape)}"
    carried = coupling_kind(out_type, out_version)
    if carried is None:
        return f"{start} is {out_type}: connections carry {CONNECTABLE}"
    other = coupling_kind(in_type, in_version)
    if other != carried:
        return (
            f"type mismatch: {start} is an FMI {out_version} {out_type} (carried as {carried}), {end} an "
            f"FMI {in_version} {in_type} (carried as {other}); connect enumerations of one FMI version"
        )
    if tuple(out_shape) != tuple(in_shape):
        return (
            f"shape mismatch: {start} is {typed(out_type, out_shape, True)}, "
            f"{end} is {typed(in_type, in_shape, True)}; an array drives an array of the same shape"
        )
    return None


def no_element(variables: Mapping[str, Any], name: str) -> str | None:
    """Why `name`, written as an element y[...] of an array y of `variables`, names none of its
    elements ("y is Float64[3]: it has no element y[4]"); None if it does not look like one."""
    split = split_element(name)
    v = variables.get(split[0]) if split else None
    if v is None or lookup(variables, name) is not None:
        return None
    if not v.shape:
        return f"{split[0]} is {typed(v.fmi_type, ())}, not an array"
    return f"{split[0]} is {typed(v.fmi_type, v.shape)}: it has no element {name}"


def iteration_problem(info: Description) -> str | None:
    """Why iterated macro steps cannot run this FMU (they repeat each macro step from its saved
    state); None if they can."""
    if info.co_simulation is not None and info.co_simulation.can_get_set_state:
        return None
    return (f"iterated macro steps (mm:Iteration) repeat each macro step from saved FMU states, but "
            f"{info.path.name} cannot save its state (canGetAndSetFMUstate false)")  # fmt: skip


def stimulus_problem(fmi_type: str, fmi_version: str, kind: str, shape: tuple[int, ...] = ()) -> str | None:
    """Why a stimulus of `kind` ("step" or "table") cannot drive an input of this type (and shape:
    () for a scalar); None if it can. Numeric, Boolean and Enumeration scalar inputs take steps;
    tables (piecewise linear) only continuous ones."""
    carried = coupling_kind(fmi_type, fmi_version)
    if carried is None or carried in TEXTS:
        return f"stimuli drive {STIMULATED} inputs"
    if shape:
        return "stimuli drive scalar inputs, not arrays"
    if kind != "step" and carried not in CONTINUOUS:
        return f"{_an(fmi_type)} input takes a step stimulus, not a table"
    return None


def stimulus_value_problem(fmi_type: str, fmi_version: str, value: float) -> str | None:
    """Why a stimulus value cannot be set on an input of this type ("not an integer", "outside
    [low, high]": the runtime converts it to that type); None if it can."""
    if fmi_type in ("Real", "Float64"):
        return None
    if fmi_type == "Float32":
        return None if abs(value) <= FLOAT32_MAX else f"outside [-{FLOAT32_MAX:g}, {FLOAT32_MAX:g}]"
    if fmi_type == "Boolean":
        return None if value in (0, 1) else "not 0 (false) or 1 (true)"
    if value != int(value):
        return "not an integer"
    typed = (
        "Int32" if fmi_type in ("Integer", "Enumeration") and not fmi_version.startswith("3") else fmi_type
    )
    low, high = INT_RANGES.get("Int64" if typed == "Enumeration" else typed, (-math.inf, math.inf))
    return None if low <= value <= high else f"outside [{low}, {high}]"


def point_problem(name: str, var: Variable, fmi_version: str, t: float, v: float) -> str | None:
    """Why a stimulus cannot hold value v from time t (s) on input `name` (variable `var`): not of
    its type (`stimulus_value_problem`), or outside the range it declares, which the FMU would
    refuse in the run; None if it can."""
    wrong = stimulus_value_problem(var.fmi_type, fmi_version, v)
    if wrong:
        return f"value {v:g} is {wrong} ({name} is {var.fmi_type})"
    outside = range_problem(v, declared_range(var.fmi_type, var.min, var.max, var.items))
    if outside:
        whose = "its items" if var.min is None and var.max is None else "its min and max"
        return f"value {v:g} at time {t:g} s is {outside}, the range of {name} ({whose})"
    return None


def declared_range(fmi_type: str, low: str | None, high: str | None, items=()) -> tuple[float, float] | None:
    """[min, max] a variable declares (its own or its declared type's min and max; an Enumeration
    without them: its lowest and highest item), None if it declares neither bound. The FMU
    refuses values outside it."""
    if low is None and high is None and fmi_type == "Enumeration" and items:
        values = [v for _, v in items]
        return min(values), max(values)
    if low is None and high is None:
        return None
    return _number(low, -math.inf), _number(high, math.inf)


def _number(text: str | None, default: float) -> float:
    if text is None:
        return default
    try:
        return int(text)
    except ValueError:
        return float(text)


def range_problem(value: float, bounds: tuple[float, float] | None) -> str | None:
    """Why `value` is outside the `declared_range` bounds ("outside [1, 6]"); None if it is inside."""
    if bounds is None or bounds[0] <= value <= bounds[1]:
        return None
    return f"outside [{_shown(bounds[0])}, {_shown(bounds[1])}]"


def _shown(x: float) -> str:
    return str(x) if isinstance(x, int) else f"{x:g}"


def _an(word: str) -> str:
    return f"an {word}" if word[0] in "AEIOU" else f"a {word}"


RECORDED = (
    "Real, Integer, Boolean, Enumeration and String values (FMI 3: every numeric type and Binary; "
    "arrays of numbers and Booleans)"
)


def recordable(fmi_type: str, fmi_version: str, shape: tuple[int, ...] = ()) -> bool:
    """Whether the runtime can record a variable of this type (and shape: () for a scalar): what
    connections carry (in FMI 3 every numeric type and Enumeration, each read through its own
    call, and Binary; Strings and Binaries of at most 1023 bytes, scalars only)."""
    kind = coupling_kind(fmi_type, fmi_version)
    return kind not in (None, "Clock") and not (shape and kind in TEXTS)


def record_problem(
    comp: str, name: str, var: Variable, position: int | None, fmi_version: str, columns: set[tuple[str, str]]
) -> str | None:
    """Why `comp`.`name` (variable `var`, or its element at `position`) cannot be recorded beside
    the `columns` (component, variable or array element) recorded so far, which it joins if it
    can; None then."""
    names = element_names(var.name, var.shape) if position is None else [name]
    if not recordable(var.fmi_type, fmi_version, var.shape):
        return f"{comp}.{name} is {var.fmi_type}: the runtime records {RECORDED}"
    if columns & {(comp, n) for n in names}:
        return "recorded twice"
    columns.update((comp, n) for n in names)
    return None


def recorded_as(fmi_type: str) -> str:
    """How the results hold a recorded variable of this type: "float64" (exact for every type but
    64-bit integers beyond 2^53), "int64" or "uint64" (FMI 3 Int64, UInt64: exact), "String"
    (text) or "Binary" (bytes; hex digits in a CSV file)."""
    held = {"Int64": "int64", "UInt64": "uint64", "String": "String", "Binary": "Binary"}
    return held.get(fmi_type, "float64")


def project_fmu_names() -> list[str]:
    """The project's FMUs: folders fmus/NAME with a model.c (see master.fmubuild), those that build
    as FMI 3.0 only (such as alltypes) included."""
    from master import fmubuild

    return fmubuild.project_fmu_names(3)


class SourceError(Exception):
    """A component source that does not lead to an FMU."""


def resolve_source(source: str, base: Path, inside: Path | None = None, built: dict | None = None) -> Path:
    """The .fmu file a component's source attribute names.

    1. "project:NAME": the project's FMU NAME (fmus/NAME), built if missing or stale (as FMI 2.0,
       or as FMI 3.0 where the model builds only as that).
    2. otherwise a path relative to the folder of the .ssd (`base`); used if that file exists.
    3. otherwise the NAME of a project FMU (a folder fmus/NAME with a model.c): as in 1.
    `inside`: for unpacked archives, the folder a relative path may not leave.
    `built`: project FMUs already resolved while reading this scenario (name -> path or error),
    so that a scene with many instances of one model checks its build once.
    """
    if source.startswith(PROJECT_SCHEME):
        return _project(source[len(PROJECT_SCHEME) :], built)
    if "://" in source or source.startswith("file:"):
        raise SourceError(f'unsupported URI "{source}": use a relative path or project:NAME')
    candidate, found = file_at(base, source)
    if inside is not None and not candidate.is_relative_to(inside.resolve()):
        raise SourceError(f'source "{source}" points outside the archive')
    if found:
        return candidate
    if source in project_fmu_names():
        return _project(source, built)
    raise SourceError(f'FMU file "{source}" not found (looked for {candidate})')


def file_at(base: Path, source: str) -> tuple[Path, bool]:
    """The path a file name from a scenario means (relative to `base`) and whether it is a file;
    SourceError, not OSError, for a name the file system refuses (too long, a NUL byte)."""
    try:
        candidate = (base / source).resolve()
        return candidate, candidate.is_file()
    except (OSError, ValueError) as err:
        shown = source if len(source) <= 60 else f"{source[:60]}..."
        why = err.strerror if isinstance(err, OSError) and err.strerror else err
        raise SourceError(
            f'source "{shown}" ({len(source)} characters): not a usable file name ({why})'
        ) from None


def _project(name: str, built: dict | None) -> Path:
    built = {} if built is None else built
    if name not in built:
        built[name] = _build(name)
    if isinstance(built[name], SourceError):
        raise built[name]
    return built[name]


def _build(name: str) -> Path | SourceError:
    from master import fmubuild

    names = fmubuild.project_fmu_names(3)
    if name not in names:
        return SourceError(f'no project FMU "{name}" (the project has: {", ".join(names)})')
    try:
        return Path(fmubuild.fmu_path(name, fmi=2 if name in fmubuild.project_fmu_names() else 3))
    except Exception as err:  # a failed C build: report it as a problem of this component
        return SourceError(f'cannot build project FMU "{name}": {err}')


def read(path: Path) -> Description:
    """An FMU's model description (master.description.read: cached while the file is unchanged).

    Raises SourceError with the reason if the FMU cannot be read."""
    try:
        return description.read(path)
    except description.DescriptionError as err:
        raise SourceError(str(err)) from err
