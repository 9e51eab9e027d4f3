"""Build the project's FMUs from C: modelDescription.xml generation, compilation, packaging.

Each folder ``fmus/<name>/`` with a ``model.c`` is one FMU whose model identifier is
``<name>``.  The variable table in C is the single source of truth: a small program
(``fmus/fmi/describe.c`` linked with the model) prints it as JSON and this module turns
that into ``modelDescription.xml``.  The checked-in XML must equal the generated one.

Command line::

    python -m master.fmubuild [--write-xml] [name ...]

builds the named FMUs (all if none) into ``build/fmus/<name>.fmu``; ``--write-xml``
first regenerates ``fmus/<name>/modelDescription.xml`` from the C table.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import re
import shutil
import subprocess
import sys
import tempfile
import time
import zipfile
from pathlib import Path
from typing import Any

from lxml import etree

PACKAGE_DIR = Path(__file__).resolve().parent
REPO_DIR = PACKAGE_DIR.parent  # a source checkout, if fmus/ is beside the package


STATES = "states"  # a model table's dependency on every continuous state (model.h)


def _cache_dir() -> Path:
    """Where an installed package builds FMUs: $XDG_CACHE_HOME (or ~/.cache)/multirate-master/fmus."""
    base = os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache"
    return Path(base) / "multirate-master" / "fmus"


# the FMU sources: shipped inside an installed package (setup.py), else the checkout's fmus/
FMUS_DIR = PACKAGE_DIR / "fmus" if (PACKAGE_DIR / "fmus").is_dir() else REPO_DIR / "fmus"
BUILD_DIR = REPO_DIR / "build" / "fmus" if FMUS_DIR == REPO_DIR / "fmus" else _cache_dir()
FMI_DIR = FMUS_DIR / "fmi"
SOLVERS_DIR = FMUS_DIR / "solvers"

CFLAGS = ["-O2", "-Wall", "-Wextra", "-Werror", "-std=c99", "-D_POSIX_C_SOURCE=200809L", "-fPIC"]
GENERATION_TOOL = "master.fmubuild"
PLATFORM = "linux64"

# Descriptions of the values 1 .. SOLVER_COUNT of the C enumeration SolverKind (fmus/fmi/model.h);
# describe() checks the count against the C side.
SOLVER_ITEMS = [
    ("euler", "explicit Euler"),
    ("ab2", "Adams-Bashforth 2"),
    ("ab3", "Adams-Bashforth 3"),
    ("rk4", "classical Runge-Kutta 4"),
    ("semi_implicit_euler", "semi-implicit (linearly implicit) Euler"),
    ("semi_implicit_midpoint", "semi-implicit midpoint"),
]


class FmuBuildError(RuntimeError):
    """A model cannot be described, compiled or packaged; the message says why."""


# ------------------------------------------------------------------ sources


def project_fmu_names() -> list[str]:
    """Names of the subfolders of fmus/ that contain a model.c, sorted."""
    return sorted(p.parent.name for p in FMUS_DIR.glob("*/model.c"))


def _model_dir(name: str) -> Path:
    d = FMUS_DIR / name
    if not (d / "model.c").is_file():
        raise FmuBuildError(f"{d / 'model.c'}: no such model (known: {', '.join(project_fmu_names())})")
    return d


def _c_sources(name: str) -> list[Path]:
    """The C files compiled into the FMU: the layer (not describe.c), the solvers, the model."""
    layer = [p for p in sorted(FMI_DIR.glob("*.c")) if p.name != "describe.c"]
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
        args += [str(p) for p in _c_sources(name)] + ["-o", str(exe), "-lm"]
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
    if desc["solver_count"] != len(SOLVER_ITEMS):
        raise FmuBuildError(
            f"{FMI_DIR / 'model.h'}: SOLVER_COUNT is {desc['solver_count']} but {Path(__file__).name} "
            f"describes {len(SOLVER_ITEMS)} solvers (SOLVER_ITEMS)"
        )
    _check_table(name, desc)
    return desc


def _check_table(name: str, desc: dict[str, Any]) -> None:
    """Raise FmuBuildError naming fmus/<name>/model.c and the variable if the table is inconsistent."""
    where = f"{FMUS_DIR / name / 'model.c'}"
    counts = {
        "Real": desc["n_reals"],
        "Integer": desc["n_integers"],
        "Solver": desc["n_integers"],
        "Boolean": desc["n_booleans"],
        "String": desc["n_strings"],
    }
    variables = desc["variables"]
    problems: list[str] = []
    if desc["identifier"] != name:
        problems.append(f'MODEL.identifier is "{desc["identifier"]}" but the folder is "{name}"')
    if len(variables) < 2 or variables[0]["name"] != "solver" or variables[1]["name"] != "internal_step":
        problems.append("the table must start with COMMON_VARIABLES(...)")
    real_vr = {v["slot"]: vr for vr, v in enumerate(variables) if v["type"] == "Real"}
    state_vrs = {real_vr.get(s) for s in desc["state_slots"]}
    seen_names: set[str] = set()
    used_slots: dict[tuple[str, int], str] = {}
    for vr, v in enumerate(variables):
        label = f'variable {vr} "{v["name"]}"'
        if v["name"] in seen_names:
            problems.append(f"{label}: duplicate name")
        seen_names.add(v["name"])
        kind = "Integer" if v["type"] == "Solver" else v["type"]
        if not 0 <= v["slot"] < counts[v["type"]]:
            problems.append(f"{label}: slot {v['slot']} outside the {counts[v['type']]} {kind} slots")
        elif (kind, v["slot"]) in used_slots:
            problems.append(f"{label}: shares {kind} slot {v['slot']} with {used_slots[(kind, v['slot'])]}")
        used_slots[(kind, v["slot"])] = f'"{v["name"]}"'
        if v["derivative_of"] != -1:
            target = variables[v["derivative_of"]] if 0 <= v["derivative_of"] < len(variables) else None
            if v["type"] != "Real" or target is None or target["type"] != "Real":
                problems.append(f"{label}: derivative_of {v['derivative_of']} is not a Real variable")
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
        if v["type"] != "String" and v["initial"] != "calculated" and not math.isfinite(v["start"]):
            problems.append(f"{label}: start value {v['start']} is not finite")
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


def _source_names(name: str) -> list[str]:
    return [p.name for p in _c_sources(name)]


def model_description_xml(name: str, desc: dict[str, Any] | None = None) -> str:
    """modelDescription.xml of model `name`, generated from its C table."""
    desc = desc or describe(name)
    variables = desc["variables"]
    root = etree.Element(
        "fmiModelDescription",
        fmiVersion="2.0",
        modelName=name,
        guid=desc["guid"],
        description=desc["description"] or "",
        generationTool=GENERATION_TOOL,
        variableNamingConvention="flat",
        numberOfEventIndicators="0",
    )
    capabilities = {
        "canGetAndSetFMUstate": "true",
        "canSerializeFMUstate": "true",
        "providesDirectionalDerivative": "true",
        "canNotUseMemoryManagementFunctions": "true",
    }
    me = etree.SubElement(
        root, "ModelExchange", modelIdentifier=name, completedIntegratorStepNotNeeded="true", **capabilities
    )
    cs = etree.SubElement(
        root,
        "CoSimulation",
        modelIdentifier=name,
        canHandleVariableCommunicationStepSize="true",
        canInterpolateInputs="true",
        maxOutputDerivativeOrder="0",
        **capabilities,
    )
    for element in (me, cs):
        files = etree.SubElement(element, "SourceFiles")
        for source in _source_names(name):
            etree.SubElement(files, "File", name=source)

    units = sorted({v["unit"] for v in variables if v["unit"]})
    if units:
        unit_defs = etree.SubElement(root, "UnitDefinitions")
        for unit in units:
            u = etree.SubElement(unit_defs, "Unit", name=unit)
            base = base_unit(unit)
            if base is not None:
                scale, dims = base
                attrs = {k: str(e) for k, e in dims.items()}
                if scale != 1.0:
                    attrs["factor"] = repr(scale)
                etree.SubElement(u, "BaseUnit", **attrs)

    if any(v["type"] == "Solver" for v in variables):
        types = etree.SubElement(root, "TypeDefinitions")
        simple = etree.SubElement(types, "SimpleType", name="Solver")
        enum = etree.SubElement(simple, "Enumeration")
        for value, (item, text) in enumerate(SOLVER_ITEMS, start=1):
            etree.SubElement(enum, "Item", name=item, value=str(value), description=text)

    cats = etree.SubElement(root, "LogCategories")
    for cat in desc["log_categories"]:
        etree.SubElement(cats, "Category", name=cat["name"], description=cat["description"])

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


def write_xml(names: list[str] | None = None) -> list[Path]:
    """Regenerate fmus/<name>/modelDescription.xml from the C tables; returns the files written."""
    written = []
    for name in names or project_fmu_names():
        path = _model_dir(name) / "modelDescription.xml"
        path.write_text(model_description_xml(name), encoding="utf-8")
        written.append(path)
    return written


# ------------------------------------------------------------------- build


def build_fmu(name: str) -> Path:
    """Compile and package fmus/<name> into build/fmus/<name>.fmu; returns its path.

    The checked-in modelDescription.xml must equal the one generated from the C
    table (else FmuBuildError says to run --write-xml).  Builds in a temporary
    folder and moves the finished .fmu into place atomically.
    """
    model_dir = _model_dir(name)
    xml_path = model_dir / "modelDescription.xml"
    if sys.stderr.isatty():  # a few seconds of compiling should not look like a hang
        print(f"building FMU {name} from its C sources ...", file=sys.stderr, flush=True)
    started = time.time()
    desc = describe(name)
    expected = model_description_xml(name, desc)
    if not xml_path.is_file() or xml_path.read_text(encoding="utf-8") != expected:
        state = "missing" if not xml_path.is_file() else "out of date with the C table"
        raise FmuBuildError(
            f"{xml_path}: {state}; regenerate it with: python -m master.fmubuild --write-xml {name}"
        )
    BUILD_DIR.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory(prefix=f".{name}-", dir=BUILD_DIR) as tmp:
        stage = Path(tmp) / "fmu"
        binary = stage / "binaries" / PLATFORM / f"{name}.so"
        binary.parent.mkdir(parents=True)
        args = [_compiler(), *CFLAGS, "-shared", "-Wl,--no-undefined", *_include_flags(name)]
        args += [str(p) for p in _c_sources(name)] + ["-o", str(binary), "-lm"]
        _compile(args, f"building FMU {name}")
        sources = stage / "sources"
        sources.mkdir()
        for src in _c_sources(name) + _headers(name):
            shutil.copy2(src, sources / src.name)
        for header in ("fmi2Functions.h", "fmi2FunctionTypes.h", "fmi2TypesPlatform.h"):
            shutil.copy2(_fmi_include_dir() / header, sources / header)
        (stage / "modelDescription.xml").write_text(expected, encoding="utf-8")
        archive = Path(tmp) / f"{name}.fmu"
        with zipfile.ZipFile(archive, "w", zipfile.ZIP_DEFLATED) as zf:
            for path in sorted(stage.rglob("*")):
                if path.is_file():
                    zf.write(path, path.relative_to(stage).as_posix())
        # Date the FMU from the start of the build: a source edited while compiling
        # is then newer than the FMU, and fmu_path builds again.
        os.utime(archive, (started, started))
        target = BUILD_DIR / f"{name}.fmu"
        os.replace(archive, target)
    return target


def _inputs_of(name: str) -> list[Path]:
    """The files an FMU is built from: a change in any of them makes it stale."""
    xml = sorted(_model_dir(name).glob("*.xml"))
    return _c_sources(name) + _headers(name) + xml + [FMI_DIR / "describe.c", Path(__file__)]


def fmu_path(name: str) -> Path:
    """Path of build/fmus/<name>.fmu, (re)built if missing or older than any of its sources."""
    target = BUILD_DIR / f"{name}.fmu"
    if target.is_file():
        built = target.stat().st_mtime
        if all(p.stat().st_mtime <= built for p in _inputs_of(name)):
            return target
    return build_fmu(name)


def _shown(path: Path) -> str:
    """Path relative to the repository when inside it."""
    return str(path.relative_to(REPO_DIR)) if path.is_relative_to(REPO_DIR) else str(path)


def main(argv: list[str] | None = None, prog: str = "python -m master.fmubuild") -> int:
    """Command line: ``[--write-xml] [name ...]``; returns the exit status."""
    parser = argparse.ArgumentParser(prog=prog, description="Build the project's FMUs from their C sources.")
    parser.add_argument("--write-xml", action="store_true", help="regenerate modelDescription.xml first")
    parser.add_argument("names", nargs="*", help="models to build (default: all folders with model.c)")
    args = parser.parse_args(argv)
    names = args.names or project_fmu_names()
    try:
        if args.write_xml:
            for path in write_xml(names):
                print(f"wrote {_shown(path)}")
        for name in names:
            print(f"built {_shown(build_fmu(name))}")
    except FmuBuildError as e:
        print(f"error: {e}", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
