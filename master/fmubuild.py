"""Build the project's FMUs from C: modelDescription.xml generation, compilation, packaging.

Each folder ``fmus/<name>/`` with a ``model.c`` is one FMU whose model identifier is
``<name>``.  The variable table in C is the single source of truth: a small program
(``fmus/fmi/describe.c`` linked with the model) prints it as JSON and this module turns
that into ``modelDescription.xml``.

FMI 2.0 (the default) builds ``build/fmus/<name>.fmu`` with the layer's ``fmi2.c``; its
checked-in ``fmus/<name>/modelDescription.xml`` must equal the generated one.  FMI 3.0
Model Exchange and Co-Simulation (``fmi=3``) builds ``build/fmus/fmi3/<name>.fmu`` with ``fmi3.c``
and an FMI 3.0 description generated at build time (not checked in).  A table that uses FMI 3.0
types or arrays declares ``.fmi3_only = 1`` and builds as FMI 3.0 only; one that declares
``.me_only = 1`` offers Model Exchange alone (no CoSimulation element, no FMI 1.0 build), as
tools that export Model Exchange only do.  FMI 1.0 Co-Simulation
(``fmi=1``) builds ``build/fmus/fmi1/<name>.fmu`` with ``fmi1.c`` (functions prefixed with the
model identifier) and an FMI 1.0 description generated at build time.  ``build/fmus`` stands for
BUILD_DIR: that folder in a checkout, the user's cache for an installed package, or
$MASTER_FMU_DIR where set (``_build_dir_default``).

Command line::

    python -m master.fmubuild [--write-xml] [--fmi {1,2,3}] [name ...]

builds the named FMUs (all of that FMI version if none); ``--write-xml`` first regenerates
``fmus/<name>/modelDescription.xml`` from the C table (FMI 2.0 only).
"""

from __future__ import annotations

import argparse
import json
import logging
import math
import os
import re
import shutil
import struct
import subprocess
import sys
import tempfile
import time
import zipfile
from pathlib import Path
from typing import Any

from lxml import etree

from master import solvers

PACKAGE_DIR = Path(__file__).resolve().parent
REPO_DIR = PACKAGE_DIR.parent  # a source checkout, if fmus/ is beside the package

_log = logging.getLogger(__name__)

STATES = "states"  # a model table's dependency on every continuous state (model.h)


def _build_dir_default() -> Path:
    """Where FMUs are built: $MASTER_FMU_DIR if set; else a checkout's build/fmus, and for an
    installed package $XDG_CACHE_HOME (or ~/.cache)/multirate-master/fmus."""
    if os.environ.get("MASTER_FMU_DIR"):
        return Path(os.environ["MASTER_FMU_DIR"]).expanduser().absolute()
    if FMUS_DIR == REPO_DIR / "fmus":
        return REPO_DIR / "build" / "fmus"
    base = os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache"
    return Path(base) / "multirate-master" / "fmus"


# the FMU sources: shipped inside an installed package (setup.py), else the checkout's fmus/
FMUS_DIR = PACKAGE_DIR / "fmus" if (PACKAGE_DIR / "fmus").is_dir() else REPO_DIR / "fmus"
BUILD_DIR = _build_dir_default()
FMI_DIR = FMUS_DIR / "fmi"
SOLVERS_DIR = FMUS_DIR / "solvers"

CFLAGS = ["-O2", "-Wall", "-Wextra", "-Werror", "-std=c99", "-D_POSIX_C_SOURCE=200809L", "-fPIC"]
GENERATION_TOOL = "master.fmubuild"
PLATFORM = "linux64"  # FMI 2.0 binaries folder
PLATFORM3 = "x86_64-linux"  # FMI 3.0 platform tuple

FMI_VERSIONS = (1, 2, 3)
# The layer's interface file of each FMI version; an FMU is built with its own one only.
INTERFACE_FILES = {1: "fmi1.c", 2: "fmi2.c", 3: "fmi3.c"}
# layer files of FMI 3.0 alone (Scheduled Execution): no FMI 1.0 or 2.0 build needs them
FMI3_LAYER_FILES = ("clocks.c",)
FMI_HEADERS = {
    1: ("fmi1Functions.h",),
    2: ("fmi2Functions.h", "fmi2FunctionTypes.h", "fmi2TypesPlatform.h"),
    3: ("fmi3Functions.h", "fmi3FunctionTypes.h", "fmi3PlatformTypes.h"),
}

# Types of the C tables (describe.c's names) that exist in FMI 3.0 only, and each type's storage.
FMI3_ONLY_TYPES = (
    "Float32", "Int8", "UInt8", "Int16", "UInt16", "UInt32", "Int64", "UInt64", "Binary", "Clock"
)  # fmt: skip
_STORAGE = {
    "Real": "Real",
    "Float32": "Real",
    "Integer": "Integer",
    "Solver": "Integer",
    "Boolean": "Boolean",
    "String": "String",
    **{t: "Int64" for t in ("Int8", "UInt8", "Int16", "UInt16", "UInt32", "Int64")},
    "UInt64": "UInt64",
    "Binary": "Binary",
    "Clock": "Integer",  # its tick or interval qualifier (model.h: T_CLOCK)
}
# FMI 3.0 element of each table type, and the value range of the integer ones.
_FMI3_ELEMENT = {"Real": "Float64", "Integer": "Int32", "Solver": "Enumeration"}
_INTEGER_RANGES = {
    "Int8": (-(2**7), 2**7 - 1),
    "UInt8": (0, 2**8 - 1),
    "Int16": (-(2**15), 2**15 - 1),
    "UInt16": (0, 2**16 - 1),
    "Integer": (-(2**31), 2**31 - 1),
    "UInt32": (0, 2**32 - 1),
    "Int64": (-(2**63), 2**63 - 1),
    "UInt64": (0, 2**64 - 1),
}
# flags of the model table that fmubuild reads from model.c itself (see model.h): `.fmi3_only = 1`
# builds as FMI 3.0 only, `.me_only = 1` offers Model Exchange only (no FMI 1.0 Co-Simulation build)
TABLE_FLAGS = ("fmi3_only", "me_only")


class FmuBuildError(RuntimeError):
    """A model cannot be described, compiled or packaged; the message says why."""


# ------------------------------------------------------------------ sources


def _check_fmi(fmi: int) -> None:
    if fmi not in FMI_VERSIONS:
        raise FmuBuildError(f"FMI version {fmi!r}: expected one of {', '.join(map(str, FMI_VERSIONS))}")


def project_fmu_names(fmi: int = 2) -> list[str]:
    """Names of the subfolders of fmus/ that contain a model.c, sorted: for FMI 2.0 (the default)
    those that build as FMI 2.0, i.e. without the models whose table declares ``.fmi3_only = 1``;
    for FMI 3.0 all of them; FMI 1.0 (Co-Simulation) as FMI 2.0 without the ``.me_only = 1`` ones."""
    _check_fmi(fmi)
    names = sorted(p.parent.name for p in FMUS_DIR.glob("*/model.c"))
    if fmi == 3:
        return names
    return [n for n in names if not _declares(n, "fmi3_only") and not (fmi == 1 and _declares(n, "me_only"))]


def _declares(name: str, flag: str) -> bool:
    """Whether fmus/<name>/model.c says ``.<flag> = 1`` (read from the source: no compiling)."""
    text = (FMUS_DIR / name / "model.c").read_text(encoding="utf-8")
    return re.search(rf"\.{flag}\s*=\s*1\b", text) is not None


def _model_dir(name: str) -> Path:
    d = FMUS_DIR / name
    if not (d / "model.c").is_file():
        raise FmuBuildError(f"{d / 'model.c'}: no such model (known: {', '.join(project_fmu_names(3))})")
    return d


def _c_sources(name: str, fmi: int | None = 2) -> list[Path]:
    """The C files compiled into the FMU of FMI version `fmi`: the layer with that version's
    interface file (None: with none, for describe.c), the solvers, the model."""
    skip = {"describe.c"} | {f for v, f in INTERFACE_FILES.items() if v != fmi}
    skip |= set(FMI3_LAYER_FILES) if fmi in (1, 2) else set()
    layer = [p for p in sorted(FMI_DIR.glob("*.c")) if p.name not in skip]
    return layer + sorted(SOLVERS_DIR.glob("*.c")) + sorted(_model_dir(name).glob("*.c"))


def _headers(name: str) -> list[Path]:
    return (
        sorted(FMI_DIR.glob("*.h")) + sorted(SOLVERS_DIR.glob("*.h")) + sorted(_model_dir(name).glob("*.h"))
    )


def _fmi_include_dir() -> Path:
    import fmpy

    return Path(os.path.dirname(fmpy.__file__)) / "c-code"


def _compiler() -> str:
    for cc in (os.environ.get("CC"), "cc", "gcc"):
        if cc and shutil.which(cc):
            return cc
    raise FmuBuildError("no C compiler found (tried $CC, cc, gcc)")


def _include_flags(name: str) -> list[str]:
    return [f"-I{_fmi_include_dir()}", f"-I{FMI_DIR}", f"-I{SOLVERS_DIR}", f"-I{_model_dir(name)}"]


def _compile(args: list[str], what: str) -> None:
    proc = subprocess.run(args, capture_output=True, text=True)
    if proc.returncode != 0:
        raise FmuBuildError(
            f"{what}: compiler failed (exit {proc.returncode}):\n{' '.join(args)}\n{proc.stderr}"
        )


# ---------------------------------------------------------- description


def describe(name: str) -> dict[str, Any]:
    """The model's C table and the layer's constants as a dict.

    Compiles and runs fmus/fmi/describe.c with the model and the layer.
    """
    with tempfile.TemporaryDirectory(prefix=f"describe-{name}-") as tmp:
        exe = Path(tmp) / "describe"
        # Only the table is read: no need to optimise (-O0 compiles three times faster).
        flags = [f for f in CFLAGS if f != "-O2"] + ["-O0"]
        args = [_compiler(), *flags, *_include_flags(name), str(FMI_DIR / "describe.c")]
        args += [str(p) for p in _c_sources(name, None)] + ["-o", str(exe), "-lm"]
        _compile(args, f"describing model {name}")
        proc = subprocess.run([str(exe)], capture_output=True, text=True)
        if proc.returncode != 0:
            raise FmuBuildError(
                f"describing model {name}: describe exited with {proc.returncode}:\n{proc.stderr}"
            )
    desc = json.loads(proc.stdout)
    for v in desc["variables"]:
        for key in ("start", "min", "max"):
            if isinstance(v[key], str):
                v[key] = float(v[key])
        v["size"] = math.prod(v["dimensions"])
    mismatch = solvers.c_mismatch((FMI_DIR / "model.h").read_text())
    if mismatch is None and desc["solver_count"] != len(solvers.SOLVERS):
        mismatch = (
            f"SOLVER_COUNT is {desc['solver_count']} but master/solvers.py has {len(solvers.SOLVERS)} solvers"
        )
    if mismatch:
        raise FmuBuildError(f"{FMI_DIR / 'model.h'}: {mismatch}")
    _check_table(name, desc)
    return desc


def _check_table(name: str, desc: dict[str, Any]) -> None:
    """Raise FmuBuildError naming fmus/<name>/model.c and the variable if the table is inconsistent."""
    where = f"{FMUS_DIR / name / 'model.c'}"
    counts = {
        "Real": desc["n_reals"],
        "Integer": desc["n_integers"],
        "Boolean": desc["n_booleans"],
        "String": desc["n_strings"],
        "Int64": desc["n_int64s"],
        "UInt64": desc["n_uint64s"],
        "Binary": desc["n_binaries"],
    }
    variables = desc["variables"]
    problems: list[str] = []
    if desc["identifier"] != name:
        problems.append(f'MODEL.identifier is "{desc["identifier"]}" but the folder is "{name}"')
    common = [v["name"] for v in variables[:2]] == ["solver", "internal_step"]
    if not common and not desc["has_activate"]:  # a Scheduled Execution model has no solver
        problems.append("the table must start with COMMON_VARIABLES(...)")
    feature = _fmi3_feature(desc)
    if feature and not desc["fmi3_only"]:
        problems.append(f"{feature}, which FMI 2.0 lacks: declare `.fmi3_only = 1` in MODEL")
    for flag in TABLE_FLAGS:
        if desc[flag] != _declares(name, flag):
            problems.append(
                f"MODEL.{flag} is {int(desc[flag])} but the source does not say `.{flag} = "
                f"{int(desc[flag])}` literally (project_fmu_names reads it from there)"
            )
    real_vr = {v["slot"]: vr for vr, v in enumerate(variables) if v["type"] == "Real"}
    state_vrs = {real_vr.get(s) for s in desc["state_slots"]}
    seen_names: set[str] = set()
    used_slots: dict[tuple[str, int], str] = {}
    for vr, v in enumerate(variables):
        label = f'variable {vr} "{v["name"]}"'
        if v["name"] in seen_names:
            problems.append(f"{label}: duplicate name")
        seen_names.add(v["name"])
        kind = _STORAGE.get(v["type"])
        if kind is None:
            problems.append(f"{label}: unknown type {v['type']!r}")
            continue
        size = v["size"]
        if not (0 <= v["slot"] and v["slot"] + size <= counts[kind]):
            where_slots = f"slot {v['slot']}" if size == 1 else f"slots {v['slot']}..{v['slot'] + size - 1}"
            problems.append(f"{label}: {where_slots} outside the {counts[kind]} {kind} slots")
        else:
            for k in range(size):
                slot = v["slot"] + k
                if (kind, slot) in used_slots:
                    problems.append(f"{label}: shares {kind} slot {slot} with {used_slots[(kind, slot)]}")
                    break
            for k in range(size):
                used_slots[(kind, v["slot"] + k)] = f'"{v["name"]}"'
        if v["derivative_of"] != -1:
            target = variables[v["derivative_of"]] if 0 <= v["derivative_of"] < len(variables) else None
            if v["type"] != "Real" or target is None or target["type"] != "Real":
                problems.append(f"{label}: derivative_of {v['derivative_of']} is not a Real variable")
            elif size != 1 or target["size"] != 1:
                problems.append(f"{label}: a state and its derivative must be scalars")
        for dep in (v["dependencies"] or "").split():
            if dep == STATES:
                continue
            if not dep.isdigit() or int(dep) >= len(variables):
                problems.append(f"{label}: dependency {dep!r} is not a value reference")
            elif variables[int(dep)]["causality"] != "input" and int(dep) not in state_vrs:
                problems.append(
                    f'{label}: dependency {dep} ("{variables[int(dep)]["name"]}") '
                    "is neither an input nor a continuous state"
                )
        problems += _start_problems(label, v, desc)
    for i in range(desc["n_states"]):
        s, d = desc["state_slots"][i], desc["derivative_slots"][i]
        if s not in real_vr:
            problems.append(f"state {i}: real slot {s} belongs to no variable")
        if d not in real_vr:
            problems.append(f"state {i}: derivative real slot {d} belongs to no variable")
        elif s in real_vr and variables[real_vr[d]]["derivative_of"] != real_vr[s]:
            problems.append(
                f'state {i}: derivative variable "{variables[real_vr[d]]["name"]}" must have derivative_of = '
                f'{real_vr[s]} ("{variables[real_vr[s]]["name"]}")'
            )
    if problems:
        raise FmuBuildError(f"{where}: invalid model table:\n  " + "\n  ".join(problems))


def _start_problems(label: str, v: dict[str, Any], desc: dict[str, Any]) -> list[str]:
    """What is wrong with a variable's start value (the C side holds it in a double or a string)."""
    if v["type"] == "String":
        return []
    if v["type"] == "Binary":
        text = v["start_string"] or ""
        if len(text) % 2 or not re.fullmatch(r"[0-9a-fA-F]*", text):
            return [f"{label}: Binary start {text!r} is not an even number of hex digits"]
        if len(text) // 2 > desc["binary_capacity"]:
            return [f"{label}: Binary start has {len(text) // 2} bytes, more than {desc['binary_capacity']}"]
        return []
    if v["initial"] == "calculated":
        return []
    start = float(v["start"])
    if not math.isfinite(start):
        return [f"{label}: start value {start} is not finite"]
    if v["type"] in FMI3_ONLY_TYPES and v["type"] in _INTEGER_RANGES:
        lo, hi = _INTEGER_RANGES[v["type"]]
        if not start.is_integer() or not lo <= start <= hi:
            return [f"{label}: start value {start} is not a {v['type']}"]
    if v["type"] == "Float32" and struct.unpack("f", struct.pack("f", start))[0] != start:
        return [f"{label}: start value {start!r} is not exactly a Float32"]
    return []


def _fmi3_feature(desc: dict[str, Any]) -> str | None:
    """The first FMI 3.0-only type or array of a table, in words (None: there is none)."""
    for v in desc["variables"]:
        if v["type"] in FMI3_ONLY_TYPES:
            return f'variable "{v["name"]}" is {v["type"]}'
        if v["dimensions"]:
            return f'variable "{v["name"]}" is an array'
    return None


def _fmi3_only_reason(desc: dict[str, Any]) -> str | None:
    """Why a table builds as FMI 3.0 only (None: it builds as FMI 2.0 too)."""
    return _fmi3_feature(desc) or ("the table declares .fmi3_only = 1" if desc["fmi3_only"] else None)


def _check_fmi3_table(name: str, desc: dict[str, Any]) -> None:
    """What an FMI 3.0 description needs beyond the common checks."""
    problems = []
    for vr, v in enumerate(desc["variables"]):
        label = f'variable {vr} "{v["name"]}"'
        if v["name"] == "time":
            problems.append(f"{label}: the name is taken by FMI 3.0's independent variable")
        if v["variability"] == "continuous" and v["type"] not in ("Real", "Float32"):
            problems.append(f"{label}: a {v['type']} cannot be continuous in FMI 3.0 (use discrete)")
    problems += _clock_problems(desc)
    if problems:
        where = FMUS_DIR / name / "model.c"
        raise FmuBuildError(f"{where}: invalid model table for FMI 3.0:\n  " + "\n  ".join(problems))


PERIODIC_CLOCKS = ("constant", "fixed", "tunable")


def _clock_problems(desc: dict[str, Any]) -> list[str]:
    """A Scheduled Execution model's clocks (model.h: ModelDef.clocks): a ClockDef per Clock variable,
    an interval for periodic ones, a real slot for countdown ones, a partition function."""
    variables = desc["variables"]
    declared = {c["vr"]: c for c in desc["clocks"]}
    problems = []
    for vr, v in enumerate(variables):
        if (v["type"] == "Clock") != (vr in declared):
            problems.append(f'variable {vr} "{v["name"]}": a Clock variable needs a ClockDef, and only it')
    for c in desc["clocks"]:
        if c["interval_variability"] in PERIODIC_CLOCKS and not c["interval"] > 0:
            problems.append(f"clock {c['vr']}: a {c['interval_variability']} clock needs an interval > 0")
        if c["interval_variability"] == "countdown" and not 0 <= c["interval_slot"] < desc["n_reals"]:
            problems.append(f"clock {c['vr']}: a countdown clock needs a real slot for its interval")
    inputs = {vr for vr, v in enumerate(variables) if v["type"] == "Clock" and v["causality"] == "input"}
    kinds = {c["interval_variability"] for c in desc["clocks"] if c["vr"] in inputs}
    if kinds - {"triggered"} and not desc["has_activate"]:  # a Co-Simulation model's: fmi3SetClock
        problems.append("a model with input clocks other than triggered ones needs MODEL.activate")
    return problems


# ------------------------------------------------------------------- units

# SI base-unit exponents of unit symbols, and decimal prefixes.
_BASE = ("kg", "m", "s", "A", "K", "mol", "cd", "rad")
_SYMBOLS: dict[str, tuple[float, dict[str, int]]] = {
    "kg": (1.0, {"kg": 1}),
    "g": (1e-3, {"kg": 1}),
    "m": (1.0, {"m": 1}),
    "s": (1.0, {"s": 1}),
    "min": (60.0, {"s": 1}),
    "h": (3600.0, {"s": 1}),
    "A": (1.0, {"A": 1}),
    "K": (1.0, {"K": 1}),
    "mol": (1.0, {"mol": 1}),
    "cd": (1.0, {"cd": 1}),
    "rad": (1.0, {"rad": 1}),
    "deg": (math.pi / 180.0, {"rad": 1}),
    "Hz": (1.0, {"s": -1}),
    "N": (1.0, {"kg": 1, "m": 1, "s": -2}),
    "J": (1.0, {"kg": 1, "m": 2, "s": -2}),
    "W": (1.0, {"kg": 1, "m": 2, "s": -3}),
    "Pa": (1.0, {"kg": 1, "m": -1, "s": -2}),
    "bar": (1e5, {"kg": 1, "m": -1, "s": -2}),
    "V": (1.0, {"kg": 1, "m": 2, "s": -3, "A": -1}),
    "Ohm": (1.0, {"kg": 1, "m": 2, "s": -3, "A": -2}),
    "H": (1.0, {"kg": 1, "m": 2, "s": -2, "A": -2}),
    "F": (1.0, {"kg": -1, "m": -2, "s": 4, "A": 2}),
    "C": (1.0, {"s": 1, "A": 1}),
    "Wb": (1.0, {"kg": 1, "m": 2, "s": -2, "A": -1}),
    "T": (1.0, {"kg": 1, "s": -2, "A": -1}),
    "l": (1e-3, {"m": 3}),
}
_PREFIXES = {"G": 1e9, "M": 1e6, "k": 1e3, "c": 1e-2, "m": 1e-3, "u": 1e-6, "n": 1e-9}


def _factor(token: str) -> tuple[float, dict[str, int]] | None:
    if token == "1":
        return 1.0, {}
    match = re.fullmatch(r"([A-Za-z]+)(-?\d+)?", token)
    if not match:
        return None
    symbol, exponent = match.group(1), int(match.group(2) or 1)
    if symbol in _SYMBOLS:
        scale, dims = _SYMBOLS[symbol]
    elif symbol[0] in _PREFIXES and symbol[1:] in _SYMBOLS and symbol[1:] != "kg":
        scale, dims = _SYMBOLS[symbol[1:]]
        scale *= _PREFIXES[symbol[0]]
    else:
        return None
    return scale**exponent, {k: e * exponent for k, e in dims.items()}


def base_unit(unit: str) -> tuple[float, dict[str, int]] | None:
    """Factor and SI base-unit exponents of a unit like "N.m/rad", "m3/s" or "1/s"; None if unknown."""
    parts = unit.split("/")
    if len(parts) > 2:
        return None
    total_scale, total = 1.0, {k: 0 for k in _BASE}
    for sign, part in zip((1, -1), parts, strict=False):
        for token in part.split("."):
            f = _factor(token)
            if f is None:
                return None
            total_scale *= f[0] ** sign
            for k, e in f[1].items():
                total[k] += sign * e
    return total_scale, {k: e for k, e in total.items() if e != 0}


# --------------------------------------------------------------------- XML


def _number(x: float) -> str:
    """Shortest round-trip text of a float ("1", "-0.5", "1e-06")."""
    return repr(int(x)) if float(x).is_integer() and abs(x) < 1e15 else repr(float(x))


def _source_names(name: str, fmi: int = 2) -> list[str]:
    return [p.name for p in _c_sources(name, fmi)]


def model_description_xml(name: str, desc: dict[str, Any] | None = None, fmi: int = 2) -> str:
    """modelDescription.xml of model `name` for FMI version `fmi`, generated from its C table.

    FMI 2.0 refuses (FmuBuildError, one line) a table that builds as FMI 3.0 only."""
    _check_fmi(fmi)
    desc = desc or describe(name)
    if fmi == 3:
        return _model_description_xml3(name, desc)
    reason = _fmi3_only_reason(desc)
    if reason and fmi == 1:
        raise FmuBuildError(f"{FMUS_DIR / name / 'model.c'}: builds as FMI 3.0 only ({reason})")
    if desc["me_only"] and fmi == 1:
        raise FmuBuildError(
            f"{FMUS_DIR / name / 'model.c'}: offers Model Exchange only (.me_only = 1), "
            "which FMI 1.0 Co-Simulation cannot build"
        )
    if fmi == 1:
        return _model_description_xml1(name, desc)
    if reason:
        raise FmuBuildError(
            f"{FMUS_DIR / name / 'model.c'}: builds as FMI 3.0 only ({reason}); "
            f"build it with fmi=3 (python -m master.fmubuild --fmi 3 {name})"
        )
    variables = desc["variables"]
    root = etree.Element(
        "fmiModelDescription",
        fmiVersion="2.0",
        modelName=name,
        guid=desc["guid"],
        description=desc["description"] or "",
        generationTool=GENERATION_TOOL,
        variableNamingConvention="flat",
        numberOfEventIndicators=str(desc["n_event_indicators"]),
    )
    capabilities = {
        "canGetAndSetFMUstate": "true",
        "canSerializeFMUstate": "true",
        "providesDirectionalDerivative": "true",
        "canNotUseMemoryManagementFunctions": "true",
    }
    interfaces = [
        etree.SubElement(
            root,
            "ModelExchange",
            modelIdentifier=name,
            completedIntegratorStepNotNeeded="false" if desc["has_step_event"] else "true",
            **capabilities,
        )
    ]
    if not desc["me_only"]:
        interfaces.append(
            etree.SubElement(
                root,
                "CoSimulation",
                modelIdentifier=name,
                canHandleVariableCommunicationStepSize="true",
                canInterpolateInputs="true",
                maxOutputDerivativeOrder="0",
                **capabilities,
            )
        )
    for element in interfaces:
        files = etree.SubElement(element, "SourceFiles")
        for source in _source_names(name):
            etree.SubElement(files, "File", name=source)

    _unit_definitions(root, {v["unit"] for v in variables if v["unit"]})

    if any(v["type"] == "Solver" for v in variables):
        types = etree.SubElement(root, "TypeDefinitions")
        simple = etree.SubElement(types, "SimpleType", name="Solver")
        enum = etree.SubElement(simple, "Enumeration")
        for solver in solvers.SOLVERS:
            etree.SubElement(
                enum, "Item", name=solver.item, value=str(solver.number), description=solver.description
            )

    _log_categories(root, desc)
    _default_experiment(root, desc)

    vendor = etree.SubElement(etree.SubElement(root, "VendorAnnotations"), "Tool", name=GENERATION_TOOL)
    etree.SubElement(vendor, "Capabilities", maxInputDerivativeOrder=str(desc["max_input_derivative_order"]))

    mv = etree.SubElement(root, "ModelVariables")
    for vr, v in enumerate(variables):
        sv = etree.SubElement(mv, "ScalarVariable", name=v["name"], valueReference=str(vr))
        if v["description"]:
            sv.set("description", v["description"])
        sv.set("causality", v["causality"])
        sv.set("variability", v["variability"])
        if v["initial"]:
            sv.set("initial", v["initial"])
        has_start = v["effective_initial"] in ("exact", "approx") or v["causality"] == "input"
        if v["type"] == "Real":
            e = etree.SubElement(sv, "Real")
            if v["unit"]:
                e.set("unit", v["unit"])
            if math.isfinite(v["min"]):
                e.set("min", _number(v["min"]))
            if math.isfinite(v["max"]):
                e.set("max", _number(v["max"]))
            if has_start:
                e.set("start", _number(v["start"]))
            if v["derivative_of"] != -1:
                e.set("derivative", str(v["derivative_of"] + 1))
        elif v["type"] in ("Integer", "Solver"):
            e = etree.SubElement(sv, "Integer" if v["type"] == "Integer" else "Enumeration")
            if v["type"] == "Solver":
                e.set("declaredType", "Solver")
            elif math.isfinite(v["min"]):
                e.set("min", str(int(v["min"])))
            if v["type"] == "Integer" and math.isfinite(v["max"]):
                e.set("max", str(int(v["max"])))
            if has_start:
                e.set("start", str(int(v["start"])))
        elif v["type"] == "Boolean":
            e = etree.SubElement(sv, "Boolean")
            if has_start:
                e.set("start", "true" if v["start"] else "false")
        else:
            e = etree.SubElement(sv, "String")
            if has_start:
                e.set("start", v["start_string"] or "")

    def unknown(parent: etree._Element, vr: int, with_dependencies: bool) -> None:
        u = etree.SubElement(parent, "Unknown", index=str(vr + 1))
        deps = variables[vr]["dependencies"]
        if with_dependencies and deps is not None:
            states = [str(v) for v in state_vrs]
            listed = [d for dep in deps.split() for d in (states if dep == STATES else [dep])]
            u.set("dependencies", " ".join(str(int(d) + 1) for d in listed))

    real_vr = {v["slot"]: vr for vr, v in enumerate(variables) if v["type"] == "Real"}
    state_vrs = [real_vr[s] for s in desc["state_slots"]]
    structure = etree.SubElement(root, "ModelStructure")
    outputs = [vr for vr, v in enumerate(variables) if v["causality"] == "output"]
    if outputs:
        out = etree.SubElement(structure, "Outputs")
        for vr in outputs:
            unknown(out, vr, True)
    derivative_vrs = [real_vr[s] for s in desc["derivative_slots"]]
    if derivative_vrs:
        der = etree.SubElement(structure, "Derivatives")
        for vr in derivative_vrs:
            unknown(der, vr, True)
    # Initial unknowns: their dependencies on parameters are not in the C table, so
    # the attribute is left out (= may depend on every known), which is always valid.
    initial_unknowns = set()
    for vr, v in enumerate(variables):
        calculated = v["effective_initial"] in ("approx", "calculated")
        if (v["causality"] == "output" and calculated) or v["causality"] == "calculatedParameter":
            initial_unknowns.add(vr)
        if (vr in state_vrs or vr in derivative_vrs) and calculated:
            initial_unknowns.add(vr)
    if initial_unknowns:
        iu = etree.SubElement(structure, "InitialUnknowns")
        for vr in sorted(initial_unknowns):
            unknown(iu, vr, False)

    text = etree.tostring(root, pretty_print=True, xml_declaration=True, encoding="UTF-8")
    return text.decode("utf-8")


# FMI 1.0 names of the table's causalities and variabilities (parameters and locals are "internal").
_FMI1_CAUSALITY = {"parameter": "internal", "calculatedParameter": "internal", "local": "internal"}
_FMI1_VARIABILITY = {"fixed": "parameter", "tunable": "parameter"}


def _model_description_xml1(name: str, desc: dict[str, Any]) -> str:
    """FMI 1.0 Co-Simulation (stand-alone) description: the FMI 2.0 table in FMI 1.0 terms.
    The solver parameter is an Integer in 1..SOLVER_COUNT (its items are in its description)."""
    variables = desc["variables"]
    root = etree.Element(
        "fmiModelDescription",
        fmiVersion="1.0",
        modelName=name,
        modelIdentifier=name,
        guid=desc["guid"],
        description=desc["description"] or "",
        generationTool=GENERATION_TOOL,
        variableNamingConvention="flat",
        numberOfContinuousStates=str(len(desc["state_slots"])),
        numberOfEventIndicators="0",
    )
    inputs = {str(vr): v["name"] for vr, v in enumerate(variables) if v["causality"] == "input"}
    mv = etree.SubElement(root, "ModelVariables")
    for vr, v in enumerate(variables):
        if v["causality"] == "independent":
            continue
        sv = etree.SubElement(mv, "ScalarVariable", name=v["name"], valueReference=str(vr))
        if v["description"]:
            sv.set("description", v["description"])
        sv.set("variability", _FMI1_VARIABILITY.get(v["variability"], v["variability"]))
        sv.set("causality", _FMI1_CAUSALITY.get(v["causality"], v["causality"]))
        has_start = v["effective_initial"] in ("exact", "approx") or v["causality"] == "input"
        element = {"Solver": "Integer"}.get(v["type"], v["type"])
        e = etree.SubElement(sv, element)
        if element == "Real" and v["unit"]:
            e.set("unit", v["unit"])
        if element in ("Real", "Integer"):
            show = _number if element == "Real" else (lambda x: str(int(x)))
            for attr in ("min", "max"):
                if math.isfinite(v[attr]):
                    e.set(attr, show(v[attr]))
            if has_start:
                e.set("start", show(v["start"]))
        elif element == "Boolean" and has_start:
            e.set("start", "true" if v["start"] else "false")
        elif element == "String" and has_start:
            e.set("start", v["start_string"] or "")
        if has_start and v["causality"] != "input":
            e.set("fixed", "true" if v["effective_initial"] == "exact" else "false")
        deps = v["dependencies"]
        if v["causality"] == "output" and deps is not None:  # no element: depends on every input
            dd = etree.SubElement(sv, "DirectDependency")
            for dep in deps.split():
                if dep in inputs:
                    etree.SubElement(dd, "Name").text = inputs[dep]
    implementation = etree.SubElement(root, "Implementation")
    etree.SubElement(
        etree.SubElement(implementation, "CoSimulation_StandAlone"),
        "Capabilities",
        canHandleVariableCommunicationStepSize="true",
        canHandleEvents="true",
        canRejectSteps="false",
        canInterpolateInputs="true",
        maxOutputDerivativeOrder="0",
        canRunAsynchronuously="false",
        canBeInstantiatedOnlyOncePerProcess="false",
        canNotUseMemoryManagementFunctions="true",
    )
    text = etree.tostring(root, pretty_print=True, xml_declaration=True, encoding="UTF-8")
    return text.decode("utf-8")


def _default_experiment(root: etree._Element, desc: dict) -> None:
    """DefaultExperiment with the model's stepSize, where it gives one (the same in FMI 2.0 and 3.0)."""
    if desc["default_step_size"]:
        etree.SubElement(root, "DefaultExperiment", stepSize=repr(float(desc["default_step_size"])))


def _has_events(desc: dict) -> bool:
    """Whether a model has events: indicators, an event update or step events (fmi/event.c)."""
    return bool(desc["n_event_indicators"] or desc["has_update"] or desc["has_step_event"])


def _unit_definitions(root: etree._Element, units: set[str]) -> None:
    """UnitDefinitions (with SI base units where known) of the units used (the same in FMI 2.0 and 3.0)."""
    if units:
        unit_defs = etree.SubElement(root, "UnitDefinitions")
        for unit in sorted(units):
            u = etree.SubElement(unit_defs, "Unit", name=unit)
            base = base_unit(unit)
            if base is not None:
                scale, dims = base
                attrs = {k: str(e) for k, e in dims.items()}
                if scale != 1.0:
                    attrs["factor"] = repr(scale)
                etree.SubElement(u, "BaseUnit", **attrs)


def _log_categories(root: etree._Element, desc: dict[str, Any]) -> None:
    cats = etree.SubElement(root, "LogCategories")
    for cat in desc["log_categories"]:
        etree.SubElement(cats, "Category", name=cat["name"], description=cat["description"])


def _dependency_vrs(desc: dict[str, Any], deps: str) -> list[int]:
    """Value references in a table's dependency string ("states" = every continuous state)."""
    variables = desc["variables"]
    real_vr = {v["slot"]: vr for vr, v in enumerate(variables) if v["type"] == "Real"}
    states = [real_vr[s] for s in desc["state_slots"]]
    return [d for dep in deps.split() for d in (states if dep == STATES else [int(dep)])]


def _start_text3(v: dict[str, Any]) -> str:
    """The FMI 3.0 start attribute of a number or Boolean: one value per element."""
    if v["type"] == "Boolean":
        one = "true" if v["start"] else "false"
    elif v["type"] in _INTEGER_RANGES or v["type"] == "Solver":
        one = str(int(v["start"]))
    else:
        one = _number(v["start"])
    return " ".join([one] * v["size"])


def _intermediate_input(v: dict[str, Any]) -> bool:
    """An input the importer may set inside doStep through the intermediate-update callback (FMI 3.0
    intermediateUpdate="true"): a continuous Float64 input, fmus/fmi/instance.c intermediate_input."""
    return v["causality"] == "input" and v["type"] == "Real" and v["variability"] == "continuous"


def _model_description_xml3(name: str, desc: dict[str, Any]) -> str:
    """FMI 3.0 Model Exchange and Co-Simulation modelDescription.xml.  Value references are the
    table positions (unique across all types); `time`, the independent variable, takes the next one."""
    _check_fmi3_table(name, desc)
    variables = desc["variables"]
    time_vr = len(variables)
    root = etree.Element(
        "fmiModelDescription",
        fmiVersion="3.0",
        modelName=name,
        instantiationToken=desc["guid"],
        description=desc["description"] or "",
        generationTool=GENERATION_TOOL,
        variableNamingConvention="flat",
    )
    scalars_only = not any(v["dimensions"] for v in variables)
    intermediate = [vr for vr, v in enumerate(variables) if _intermediate_input(v)]
    clocks = {c["vr"]: c for c in desc["clocks"]}
    scheduled = bool(desc["has_activate"])  # partitions: Scheduled Execution alone; else output clocks
    if scheduled:  # the master activates its partitions
        etree.SubElement(
            root,
            "ScheduledExecution",
            modelIdentifier=name,
            canGetAndSetFMUState="true",
            canSerializeFMUState="true",
        )
    if not clocks:  # (the layer's Model Exchange has no clocks)
        etree.SubElement(  # as FMI 2.0's
            root,
            "ModelExchange",
            modelIdentifier=name,
            needsCompletedIntegratorStep="true" if desc["has_step_event"] else "false",
            canGetAndSetFMUState="true",
            canSerializeFMUState="true",
            providesDirectionalDerivatives="true" if scalars_only else "false",
        )
    if not desc["me_only"] and not scheduled:
        etree.SubElement(
            root,
            "CoSimulation",
            modelIdentifier=name,
            canGetAndSetFMUState="true",
            canSerializeFMUState="true",
            # fmi3GetDirectionalDerivative takes scalar Float64 variables only
            providesDirectionalDerivatives="true" if scalars_only else "false",
            canHandleVariableCommunicationStepSize="true",
            providesIntermediateUpdate="true" if intermediate else "false",
            canReturnEarlyAfterIntermediateUpdate="false",
            # Event Mode for a model with events (fmi3.c: doStep stops at them where eventModeUsed)
            hasEventMode="true" if _has_events(desc) else "false",
        )
    _unit_definitions(root, {v["unit"] for v in variables if v["unit"]} | {"s"})
    if any(v["type"] == "Solver" for v in variables):
        types = etree.SubElement(root, "TypeDefinitions")
        enum = etree.SubElement(types, "EnumerationType", name="Solver")
        for solver in solvers.SOLVERS:
            etree.SubElement(
                enum, "Item", name=solver.item, value=str(solver.number), description=solver.description
            )
    _log_categories(root, desc)
    _default_experiment(root, desc)

    mv = etree.SubElement(root, "ModelVariables")
    etree.SubElement(
        mv,
        "Float64",
        name="time",
        valueReference=str(time_vr),
        description="simulation time",
        causality="independent",
        variability="continuous",
        unit="s",
    )
    for vr, v in enumerate(variables):
        kind = v["type"]
        e = etree.SubElement(mv, _FMI3_ELEMENT.get(kind, kind), name=v["name"], valueReference=str(vr))
        if v["description"]:
            e.set("description", v["description"])
        e.set("causality", v["causality"])
        if kind == "Clock":  # discrete, no start: its interval instead
            _clock_attributes(e, clocks[vr], v["causality"])
            continue
        e.set("variability", v["variability"])
        if v["clocks"]:
            e.set("clocks", v["clocks"])
        if v["initial"]:
            e.set("initial", v["initial"])
        has_start = v["effective_initial"] in ("exact", "approx") or v["causality"] == "input"
        if kind == "Solver":
            e.set("declaredType", "Solver")
        elif kind in ("Real", "Float32"):
            if v["unit"]:
                e.set("unit", v["unit"])
            if math.isfinite(v["min"]):
                e.set("min", _number(v["min"]))
            if math.isfinite(v["max"]):
                e.set("max", _number(v["max"]))
        elif kind in _INTEGER_RANGES:
            if math.isfinite(v["min"]):
                e.set("min", str(int(v["min"])))
            if math.isfinite(v["max"]):
                e.set("max", str(int(v["max"])))
        elif kind == "Binary":
            e.set("maxSize", str(desc["binary_capacity"]))
        if has_start and kind not in ("String", "Binary"):
            e.set("start", _start_text3(v))
        if v["derivative_of"] != -1:
            e.set("derivative", str(v["derivative_of"]))
        if vr in intermediate:
            e.set("intermediateUpdate", "true")
        for extent in v["dimensions"]:
            etree.SubElement(e, "Dimension", start=str(extent))
        if has_start and kind in ("String", "Binary"):
            text = (v["start_string"] or "").lower() if kind == "Binary" else v["start_string"] or ""
            for _ in range(v["size"]):
                etree.SubElement(e, "Start", value=text)

    real_vr = {v["slot"]: vr for vr, v in enumerate(variables) if v["type"] == "Real"}
    state_vrs = [real_vr[s] for s in desc["state_slots"]]
    derivative_vrs = [real_vr[s] for s in desc["derivative_slots"]]
    structure = etree.SubElement(root, "ModelStructure")

    def unknown(element: str, vr: int, with_dependencies: bool) -> None:
        u = etree.SubElement(structure, element, valueReference=str(vr))
        deps = variables[vr]["dependencies"]
        if with_dependencies and deps is not None:
            u.set("dependencies", " ".join(str(d) for d in _dependency_vrs(desc, deps)))

    for vr, v in enumerate(variables):
        if v["causality"] == "output":
            unknown("Output", vr, True)
    for vr in derivative_vrs:
        unknown("ContinuousStateDerivative", vr, True)
    # As in FMI 2.0: initial unknowns without dependencies (= may depend on every known).
    for vr, v in enumerate(variables):
        calculated = v["effective_initial"] in ("approx", "calculated")
        clocked = v["type"] == "Clock" or v["clocks"]  # known at its clocks' ticks, not at initialization
        if (
            (v["causality"] == "output" and calculated and not clocked)
            or v["causality"] == "calculatedParameter"
            or ((vr in state_vrs or vr in derivative_vrs) and calculated)
        ):
            unknown("InitialUnknown", vr, False)
    given, needed = len(desc["event_indicator_vrs"]), desc["n_event_indicators"]
    if given != needed:
        raise FmuBuildError(
            f"{FMUS_DIR / name / 'model.c'}: FMI 3.0 needs a variable per event indicator "
            f"(MODEL.event_indicator_vrs gives {given} of {needed})"
        )
    for vr in desc["event_indicator_vrs"]:
        unknown("EventIndicator", vr, False)

    text = etree.tostring(root, pretty_print=True, xml_declaration=True, encoding="UTF-8")
    return text.decode("utf-8")


def _clock_attributes(e: etree._Element, clock: dict[str, Any], causality: str) -> None:
    """A Clock variable's FMI 3.0 attributes (model.h: ClockDef)."""
    e.set("intervalVariability", clock["interval_variability"])
    if clock["interval_variability"] in PERIODIC_CLOCKS:
        e.set("intervalDecimal", _number(clock["interval"]))
    if causality == "input":
        e.set("priority", str(clock["priority"]))


def build_description_xml(name: str) -> str:
    """sources/buildDescription.xml of the FMI 3.0 FMU: how to compile its sources."""
    root = etree.Element("fmiBuildDescription", fmiVersion="3.0")
    config = etree.SubElement(root, "BuildConfiguration", modelIdentifier=name)
    files = etree.SubElement(config, "SourceFileSet", language="C99")
    for source in _source_names(name, 3):
        etree.SubElement(files, "SourceFile", name=source)
    etree.SubElement(files, "PreprocessorDefinition", name="_POSIX_C_SOURCE", value="200809L")
    etree.SubElement(config, "Library", name="m", external="true", description="the C math library")
    text = etree.tostring(root, pretty_print=True, xml_declaration=True, encoding="UTF-8")
    return text.decode("utf-8")


def write_xml(names: list[str] | None = None) -> list[Path]:
    """Regenerate fmus/<name>/modelDescription.xml from the C tables; returns the files written."""
    written = []
    for name in names or project_fmu_names():
        path = _model_dir(name) / "modelDescription.xml"
        path.write_text(model_description_xml(name), encoding="utf-8")
        written.append(path)
    return written


# ------------------------------------------------------------------- build


def _build_dir(fmi: int) -> Path:
    return BUILD_DIR if fmi == 2 else BUILD_DIR / f"fmi{fmi}"


def build_fmu(name: str, fmi: int = 2) -> Path:
    """Compile and package fmus/<name> as an FMI `fmi` FMU; returns its path.

    FMI 2.0: build/fmus/<name>.fmu; the checked-in modelDescription.xml must equal the one
    generated from the C table (else FmuBuildError says to run --write-xml), and a table that
    builds as FMI 3.0 only is refused.  FMI 3.0 and 1.0 (Co-Simulation): build/fmus/fmi3/<name>.fmu,
    build/fmus/fmi1/<name>.fmu, with the description generated now.  Builds in a temporary folder
    and moves the finished .fmu into place atomically.
    """
    _check_fmi(fmi)
    model_dir = _model_dir(name)
    xml_path = model_dir / "modelDescription.xml"
    build_dir = _build_dir(fmi)
    # a few seconds of compiling should not look like a hang, and the user learns where FMUs go
    # (the command line shows master's info messages unless -q)
    _log.info(f"building FMU {name} (FMI {fmi}.0) from its C sources into {build_dir} ...")
    started = time.time()
    desc = describe(name)
    expected = model_description_xml(name, desc, fmi)
    if fmi == 2 and (not xml_path.is_file() or xml_path.read_text(encoding="utf-8") != expected):
        state = "missing" if not xml_path.is_file() else "out of date with the C table"
        raise FmuBuildError(
            f"{xml_path}: {state}; regenerate it with: python -m master.fmubuild --write-xml {name}"
        )
    build_dir.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory(prefix=f".{name}-", dir=build_dir) as tmp:
        stage = Path(tmp) / "fmu"
        binary = stage / "binaries" / (PLATFORM3 if fmi == 3 else PLATFORM) / f"{name}.so"
        binary.parent.mkdir(parents=True)
        args = [_compiler(), *CFLAGS, "-shared", "-Wl,--no-undefined", *_include_flags(name)]
        if fmi == 1:  # FMI 1.0 functions carry the model identifier as prefix (fmi1.c)
            args.append(f"-DMODEL_IDENTIFIER={name}")
        args += [str(p) for p in _c_sources(name, fmi)] + ["-o", str(binary), "-lm"]
        _compile(args, f"building FMU {name}" + ("" if fmi == 2 else f" (FMI {fmi}.0)"))
        sources = stage / "sources"
        sources.mkdir()
        for src in _c_sources(name, fmi) + _headers(name):
            shutil.copy2(src, sources / src.name)
        for header in FMI_HEADERS[fmi]:
            shutil.copy2(_fmi_include_dir() / header, sources / header)
        if fmi == 3:
            (sources / "buildDescription.xml").write_text(build_description_xml(name), encoding="utf-8")
        (stage / "modelDescription.xml").write_text(expected, encoding="utf-8")
        archive = Path(tmp) / f"{name}.fmu"
        with zipfile.ZipFile(archive, "w", zipfile.ZIP_DEFLATED) as zf:
            for path in sorted(stage.rglob("*")):
                if path.is_file():
                    zf.write(path, path.relative_to(stage).as_posix())
        # Date the FMU from the start of the build: a source edited while compiling
        # is then newer than the FMU, and fmu_path builds again.
        os.utime(archive, (started, started))
        target = build_dir / f"{name}.fmu"
        os.replace(archive, target)
    return target


def _inputs_of(name: str, fmi: int = 2) -> list[Path]:
    """The files an FMU is built from: a change in any of them makes it stale."""
    xml = sorted(_model_dir(name).glob("*.xml"))
    return _c_sources(name, fmi) + _headers(name) + xml + [FMI_DIR / "describe.c", Path(__file__)]


def fmu_path(name: str, fmi: int = 2) -> Path:
    """Path of the FMI `fmi` FMU of fmus/<name> (build/fmus/<name>.fmu, FMI 3.0:
    build/fmus/fmi3/<name>.fmu), (re)built if missing or older than any of its sources."""
    _check_fmi(fmi)
    target = _build_dir(fmi) / f"{name}.fmu"
    if target.is_file():
        built = target.stat().st_mtime
        if all(p.stat().st_mtime <= built for p in _inputs_of(name, fmi)):
            return target
    return build_fmu(name, fmi)


def _shown(path: Path) -> str:
    """Path relative to the repository when inside it."""
    return str(path.relative_to(REPO_DIR)) if path.is_relative_to(REPO_DIR) else str(path)


def main(argv: list[str] | None = None, prog: str = "python -m master.fmubuild") -> int:
    """Command line: ``[--write-xml] [name ...]``; returns the exit status."""
    parser = argparse.ArgumentParser(prog=prog, description="Build the project's FMUs from their C sources.")
    parser.add_argument(
        "--write-xml", action="store_true", help="regenerate modelDescription.xml first (FMI 2)"
    )
    parser.add_argument(
        "--fmi",
        type=int,
        choices=FMI_VERSIONS,
        default=2,
        help="FMI version: 2 (default, build/fmus/NAME.fmu), 3 or 1 (Co-Simulation, "
        "build/fmus/fmi3/NAME.fmu, build/fmus/fmi1/NAME.fmu)",
    )
    parser.add_argument(
        "names", nargs="*", help="models to build (default: every folder with model.c that builds for --fmi)"
    )
    args = parser.parse_args(argv)
    if args.write_xml and args.fmi != 2:
        parser.error(
            "--write-xml writes the checked-in FMI 2.0 descriptions "
            "(FMI 1.0 and 3.0 ones are built each time)"
        )
    names = args.names or project_fmu_names(args.fmi)
    try:
        if args.write_xml:
            for path in write_xml(names):
                print(f"wrote {_shown(path)}")
        for name in names:
            print(f"built {_shown(build_fmu(name, args.fmi))}")
    except FmuBuildError as e:
        print(f"error: {e}", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
