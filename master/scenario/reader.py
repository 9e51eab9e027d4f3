"""Reading a scenario (.ssd or .ssp) into a validated `Scenario`, or into the list of its problems.

Passes, each reporting every problem it finds and going on where it can:
XML syntax -> schemas (SSP 1.0 or 2.0 + our settings) -> nested systems flattened (`systems`) ->
components and their FMUs -> connectors -> connections -> settings (our annotation, else
defaults.py) -> parameter bindings and overrides -> algebraic loops.

Inputs that nothing drives are not reported: FMI gives every input a start value (fmpy refuses
an FMU without one), which such an input keeps unless a binding or stimulus sets it.
"""

from __future__ import annotations

import logging
from fractions import Fraction
from pathlib import Path

from lxml import etree

from master.description import FLOATS, Description, Variable

from . import archive, bindings, defaults, fmuinfo, loops, settings, systems, transforms, xmlio
from .check import clock_link_problem, clock_mode
from .check import times as time_problems
from .context import Comp, Context
from .fmuinfo import SourceError
from .model import Component, Connection, Scenario, Transformation
from .numbers import parse_time
from .problems import NS_SSC, NS_SSD, Problem, Problems, ScenarioError, describe
from .xmlio import tag

log = logging.getLogger("master")

FMU_TYPE = "application/x-fmu-sharedlibrary"
SCENARIO_SUFFIXES = (".ssd", ".ssp")
# ssd:Connector kind -> FMU causalities it may stand for
KIND_CAUSALITY = {
    "input": {"input"},
    "output": {"output"},
    "parameter": {"parameter", "structuralParameter"},
    "calculatedParameter": {"calculatedParameter"},
}
# ssc type element of a connector -> FMU types it may stand for (FMI 3 names, see description.type_class)
CONNECTOR_TYPES = {
    "Real": FLOATS,
    "Integer": {"Int8", "UInt8", "Int16", "UInt16", "Int32", "UInt32", "Int64", "UInt64"},
    "Boolean": {"Boolean"},
    "String": {"String"},
    "Enumeration": {"Enumeration"},
    "Binary": {"Binary"},
}


def load(
    path: str | Path,
    overrides: dict[str, str] | None = None,
    *,
    stop_time: Fraction | None = None,
    macro_step: Fraction | None = None,
) -> Scenario:
    """Read and check a scenario; raise ScenarioError listing every problem if it is not runnable.

    overrides: "component.variable" -> value string (the CLI's --set), applied last; stop_time,
    macro_step (s): the CLI's --stop-time and --macro-step, which win over the file's."""
    scenario, problems = read(path, overrides, stop_time=stop_time, macro_step=macro_step)
    if problems or scenario is None:
        raise ScenarioError(problems)
    return scenario


def validate(
    path: str | Path,
    overrides: dict[str, str] | None = None,
    *,
    stop_time: Fraction | None = None,
    macro_step: Fraction | None = None,
) -> list[Problem]:
    """Every problem of a scenario at once (empty: it loads).  Never raises for bad input."""
    return read(path, overrides, stop_time=stop_time, macro_step=macro_step)[1]


def read(
    path: str | Path,
    overrides: dict[str, str] | None = None,
    *,
    stop_time: Fraction | None = None,
    macro_step: Fraction | None = None,
) -> tuple[Scenario | None, list[Problem]]:
    """The scenario (None if it cannot be built) and the problems found."""
    path = Path(path)
    problems = Problems()
    scenario = _read(path, overrides or {}, problems, stop_time, macro_step)
    return (scenario if not problems.items else None), problems.items


def scenario_file(path: Path, problems: Problems) -> Path | None:
    """The scenario file `path` names: itself if an .ssd or .ssp file, else the one a folder holds
    (its SystemStructure.ssd, or its only .ssd or .ssp file); None with a problem saying why not."""
    shown = str(path)
    try:
        if path.is_dir():
            if (path / archive.SSD_NAME).is_file():
                return path / archive.SSD_NAME
            found = sorted(p for p in path.iterdir() if p.suffix.lower() in SCENARIO_SUFFIXES and p.is_file())
            if len(found) == 1:
                return found[0]
            names = ", ".join(p.name for p in found)
            why = f"holds several scenarios ({names}): name one" if found else "holds no scenario"
            problems.add(
                shown, None, "folder", f"{why}: expected {archive.SSD_NAME} or one .ssd or .ssp file"
            )
            return None
        if not path.is_file():
            problems.add(shown, None, "scenario", "no such file")
            return None
    except OSError as err:  # a name too long for the file system, a folder that cannot be listed
        problems.add(shown, None, "scenario", f"cannot read: {err.strerror or err}")
        return None
    if path.suffix.lower() == ".fmu":
        problems.add(shown, None, "file", f"an FMU, not a scenario: `master info {path}` describes it; "
                     "a scenario (.ssd or .ssp) that names it runs it")  # fmt: skip
        return None
    if path.suffix.lower() not in SCENARIO_SUFFIXES:
        problems.add(shown, None, "file", "not a scenario: expected an .ssd or .ssp file")
        return None
    return path


def _read(
    path: Path,
    overrides: dict[str, str],
    problems: Problems,
    stop_time: Fraction | None = None,
    macro_step: Fraction | None = None,
) -> Scenario | None:
    found = scenario_file(path, problems)
    if found is None:
        return None
    path = found
    shown = str(path)
    inside = None
    ssd = path
    if path.suffix.lower() == ".ssp":
        inside = archive.extract(path, shown, problems)
        if inside is None:
            return None
        ssd = inside / archive.SSD_NAME
        shown = f"{path}!/{archive.SSD_NAME}"
    tree = xmlio.parse(ssd, shown, problems)
    if tree is None:
        return None
    root = tree.getroot()
    if root.tag != tag(NS_SSD, "SystemStructureDescription"):
        problems.at(shown, root, "not an SSP ssd:SystemStructureDescription")
        return None
    major = xmlio.ssp_major(root)
    if major is None:
        problems.at(shown, root, f'version "{root.get("version")}": this master reads SSP 1.0 and 2.0 files')
        return None
    xmlio.check_schema(tree, xmlio.ssd_schema(major), shown, problems)
    system = root.find(tag(NS_SSD, "System"))
    if system is None:
        return None  # the schema check has said so
    ctx = Context(problems, shown, ssd.parent, inside)

    flat = systems.flatten(ctx, system)
    ctx.ends = {(ee, ec) for (_, _, ee, ec), _ in flat.links}
    _components(ctx, flat)
    connections, links, transformed = _connections(ctx, flat)
    times, origins = _experiment(ctx, root, stop_time)
    in_file = times if stop_time is None else None  # a command-line stop time is checked below
    annotation = settings.find(ctx, root, system)
    if annotation is not None:
        setup = settings.read(ctx, annotation, root, system, in_file, macro_step)
    else:  # a file written by another tool: macro step from the command line, a hint, the FMUs
        setup = defaults.choose(ctx, root, system, in_file, macro_step)
    params = bindings.read(ctx, flat, overrides)
    if setup is not None:  # an interpolating FMU's communication step becomes its internal step,
        for name, h in setup.internal_step.items():  # unless a binding chose one
            params.setdefault(name, {}).setdefault(settings.INTERNAL_STEP, float(h))
    loops.check(ctx, links)
    if setup is not None:  # Clock connections: what their ends' components can do (check.clock_link_problem)
        infos = {n: c.info for n, c in ctx.comps.items()}
        modes = {
            n: clock_mode(c.info, n in setup.scheduled, setup.event_mode.get(n, True))
            for n, c in ctx.comps.items()
        }
        for ends, elem in links:
            problem = clock_link_problem((ends[:2], ends[2:]), infos, modes, setup.iteration is not None)
            if problem:
                ctx.at(elem, problem)
    if problems.items or setup is None or times is None:
        return None

    start, stop = times
    components = tuple(
        Component(
            name=c.name,
            fmu_path=c.info.path,
            parameters=params.get(c.name, {}),
            step_ratio=setup.step_ratio[c.name],
            extrapolation_order=setup.extrapolation_order[c.name],
            interpolate_inputs=setup.interpolate_inputs[c.name],
            group=setup.group.get(c.name),
            model_exchange=setup.model_exchange.get(c.name),
            scheduled=c.name in setup.scheduled,
            event_mode=setup.event_mode.get(c.name, True),
        )
        for c in ctx.comps.values()
        if c.info is not None
    )
    final = tuple(
        Connection(
            *key,
            extrapolation_order=setup.connection_order.get(key[2:]),
            transformation=transformed.get(key[2:]),
        )
        for key in (k for k, _ in connections)
    )
    scenario = Scenario(
        path=path.resolve(),
        name=root.get("name", ""),
        components=components,
        connections=final,
        start_time=start,
        stop_time=stop,
        macro_step=setup.macro_step,
        coupling=setup.coupling,
        order=setup.order,
        stimuli=setup.stimuli,
        record=_recorded(setup.record, flat),
        record_interval=setup.record_interval,
        record_coupling_errors=setup.record_coupling_errors,
        loops=setup.loops,
        iteration=setup.iteration,
        origins={**origins, **setup.origins},
    )
    if stop_time is not None:  # named as the option, as `check` names a stop time set after reading
        problems.items.extend(time_problems(scenario))
    return scenario


def _recorded(record: tuple[tuple[str, str], ...], flat: systems.Flat) -> tuple[tuple[str, str], ...]:
    """The record list with the outputs behind the top system's output connectors (an empty list
    records every output, those included)."""
    if not record:
        return record
    return record + tuple(dict.fromkeys((c, v) for _, c, v in flat.outputs if (c, v) not in record))


def _components(ctx: Context, flat: systems.Flat) -> None:
    """Components (of every system, by qualified name), their FMUs and their declared connectors."""
    for name, elem in flat.components:
        ctx.comps[name] = comp = Comp(name, elem, _fmu(ctx, elem))
        for conn in elem.findall(f"{tag(NS_SSD, 'Connectors')}/{tag(NS_SSD, 'Connector')}"):
            _connector(ctx, comp, conn)


def _fmu(ctx: Context, elem: etree._Element) -> Description | None:
    if elem.get("type", FMU_TYPE) != FMU_TYPE:
        ctx.at(elem, f'type "{elem.get("type")}" is not supported: components must be FMUs ({FMU_TYPE})')
        return None
    source = elem.get("source")
    if source is None:
        return None
    try:
        info = fmuinfo.read(fmuinfo.resolve_source(source, ctx.base, ctx.inside, ctx.built))
    except SourceError as err:
        ctx.at(elem, str(err))
        return None
    if info.unsupported:
        ctx.at(elem, f"{info.path.name}: {info.unsupported}")
        return None
    for defect in info.defects:  # read all the same, as peer masters do (master.description.TOLERATED)
        where = f"{ctx.shown}:{elem.sourceline}: {describe(elem)}"
        log.warning("%s: modelDescription.xml of %s: %s (read all the same)", where, info.path.name, defect)
    return info


def _connector(ctx: Context, comp: Comp, conn: etree._Element) -> None:
    name, kind = conn.get("name"), conn.get("kind")
    if name is None:
        return
    if name in comp.connectors:
        ctx.at(conn, f'a second connector "{name}" on component {comp.name}')
        return
    comp.connectors[name] = conn
    var = ctx.variable(comp.name, name, conn)
    if var is None:
        return
    allowed = KIND_CAUSALITY.get(kind or "")
    if allowed is None:
        ctx.at(conn, f'kind "{kind}" has no FMI counterpart')
    elif var.causality not in allowed:
        ctx.at(conn, f'kind "{kind}" but {comp.name}.{name} has causality {var.causality} in the FMU')
    for typed in conn:
        if etree.QName(typed).namespace != NS_SSC:
            continue
        declared = etree.QName(typed).localname
        if var.kind not in CONNECTOR_TYPES.get(declared, set()):
            ctx.at(conn, f"type mismatch: connector is ssc:{declared}, {comp.name}.{name} is {var.fmi_type}")
        unit = typed.get("unit")
        if unit and var.unit and unit != var.unit:
            ctx.at(conn, f'unit mismatch: connector in "{unit}", {comp.name}.{name} in "{var.unit}"')


Link = systems.Link


def _connections(
    ctx: Context, flat: systems.Flat
) -> tuple[list[Link], list[Link], dict[tuple[str, str], Transformation]]:
    """(connections without problems, every output -> input link even with a type or unit problem:
    the algebraic loop check needs the latter, the transformations of the former by input).
    Connections through system connectors come resolved into component-to-component ones
    (`systems`)."""
    good: list[Link] = []
    links: list[Link] = []
    transformed: dict[tuple[str, str], Transformation] = {}  # input -> its connection's transformation
    defined = transforms.units(ctx, flat.top.elem.getroottree().getroot())  # ssd:Units, for conversion
    for (se, sc, ee, ec), elem in flat.links:
        out = _end(ctx, elem, se, sc)
        inp = _end(ctx, elem, ee, ec)
        if out is None or inp is None:
            continue
        written = (se, sc)
        (se, sc, out), (ee, ec, inp) = _oriented(ctx, elem, (se, sc, out), (ee, ec, inp))
        wrong_way = fmuinfo.direction_problems(f"{se}.{sc}", out.causality, f"{ee}.{ec}", inp.causality)
        for problem in wrong_way:
            ctx.at(elem, problem)
        if wrong_way:
            continue
        links.append(((se, sc, ee, ec), elem))
        ok = True
        problem = fmuinfo.connection_problem(
            f"{se}.{sc}", out.fmi_type, ctx.comps[se].info.fmi_version, f"{ee}.{ec}", inp.fmi_type,
            ctx.comps[ee].info.fmi_version, out.shape, inp.shape,
        )  # fmt: skip
        transformation = None
        if problem:
            ctx.at(elem, problem)
            ok = False
        else:  # a transformation or unit conversion (transforms), or a unit mismatch
            ends = (f"{se}.{sc}", f"{ee}.{ec}")
            unit_of = (_unit(ctx, se, sc, out), _unit(ctx, ee, ec, inp))
            version = ctx.comps[ee].info.fmi_version
            ok, transformation = transforms.read(ctx, elem, ends, out, inp, unit_of, defined, version)
            if ok and (se, sc) != written and _written_transformation(elem):
                ctx.at(elem, "a transformation maps the start connector's value to the end's: write this "
                       f"connection {se}.{sc} -> {ee}.{ec} (output to input) to use one")  # fmt: skip
                ok = False
        first = ctx.driven.get((ee, ec))
        if first is not None:
            ctx.at(elem, f"{ee}.{ec} is already driven by the connection on line {first.sourceline}")
            continue
        ctx.driven[(ee, ec)] = elem
        if ok:
            good.append(((se, sc, ee, ec), elem))
            if transformation is not None:
                transformed[(ee, ec)] = transformation
    return good, links, transformed


def _unit(ctx: Context, comp: str, connector: str, var: Variable) -> str | None:
    """The unit of a connection's end: its FMU variable's, else the one its ssd:Connector declares."""
    if var.unit:
        return var.unit
    typed = [t for t in ctx.comps[comp].connectors[connector] if etree.QName(t).namespace == NS_SSC]
    return next((t.get("unit") for t in typed if t.get("unit")), None)


End = tuple[str, str, Variable]  # (component, connector, its FMU variable)


def _written_transformation(elem: etree._Element) -> bool:
    """Whether a connection carries a transformation element (ssc:LinearTransformation, a mapping)."""
    return any(etree.QName(child).localname.endswith("Transformation") for child in elem.iter("{*}*"))


def _oriented(ctx: Context, elem: etree._Element, start: End, end: End) -> tuple[End, End]:
    """(output end, input end) of a connection. SSP 1.0 says startElement/endElement do not fix
    the direction: one written input -> output is turned around, with a note; any other pair is
    kept as written (two inputs or two outputs are then refused)."""
    if start[2].causality == "input" and end[2].causality == "output":
        log.info(
            "%s:%s: %s: written input -> output: read as %s.%s -> %s.%s",
            ctx.shown, elem.sourceline, describe(elem), end[0], end[1], start[0], start[1],
        )  # fmt: skip
        return end, start
    return start, end


def _end(ctx: Context, elem: etree._Element, comp: str, connector: str) -> Variable | None:
    """The FMU variable at one end of a connection (which must be a declared connector)."""
    c = ctx.comps.get(comp)
    if c is None:
        ctx.at(elem, f'unknown component "{comp}"')
        return None
    if connector not in c.connectors:
        known = c.info is not None and connector in c.info.variables
        hint = f"; declare it in the ssd:Connectors of {comp}" if known else ""
        ctx.at(elem, f'component {comp} has no connector "{connector}"{hint}')
        return None
    if c.info is None:
        return None
    return c.info.variables.get(connector)  # None: reported at the ssd:Connector already


def _experiment(
    ctx: Context, root: etree._Element, stop_time: Fraction | None = None
) -> tuple[tuple[Fraction, Fraction] | None, dict[str, str]]:
    """((startTime, stopTime), where each came from): ssd:DefaultExperiment's, startTime 0 where it
    gives none, stopTime from the command line (`stop_time`) where given, else required."""
    exp = root.find(tag(NS_SSD, "DefaultExperiment"))
    where = exp if exp is not None else root
    origins = {"start time": "ssd:DefaultExperiment startTime", "stop time": "ssd:DefaultExperiment stopTime"}
    times = []
    for attr, default in (("startTime", "0"), ("stopTime", None)):
        text = exp.get(attr, default) if exp is not None else default
        if attr == "startTime" and (exp is None or exp.get(attr) is None):
            origins["start time"] = "default (0)"
        if attr == "stopTime" and stop_time is not None:
            times.append(stop_time)
            origins["stop time"] = "command line (--stop-time)"
            continue
        if text is None:
            ctx.at(where, "no stopTime: give --stop-time T (seconds) or set it on ssd:DefaultExperiment")
            return None, origins
        try:
            times.append(parse_time(text))
        except ValueError as e:
            ctx.at(where, f"{attr}: {e}")
            return None, origins
    start, stop = times
    if stop <= start:
        ctx.at(where, f"stopTime {float(stop):g} s is not after startTime {float(start):g} s")
        return None, origins
    return (start, stop), origins
