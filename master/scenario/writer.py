"""Writing a scenario's master settings into a copy of its file (`master tune`).

The copy keeps everything of the original (comments, parameter sets, connectors, stimuli) and
changes only what differs between two loaded scenarios: the macro step, the coupling and its
order, each component's step ratio, extrapolation order and input interpolation, the record
interval and whether coupling errors are recorded, iterated macro steps (mm:Iteration), and
parameter values (appended as a last
inline parameter set of the top system, names relative to it such as "comp.var" or
"sub.comp.var": SSP gives the top system's bindings precedence over all others).
Per-connection extrapolation orders are removed when the new scenario has none. An .ssp is
written as a new archive with its other members copied; an .ssd written to another folder has
its relative references rewritten to still point at the same files.
"""

from __future__ import annotations

import os
import shutil
import tempfile
import zipfile
from decimal import Decimal
from fractions import Fraction
from pathlib import Path

from lxml import etree

from master.description import Variable, lookup

from . import fmuinfo
from .archive import SSD_NAME
from .model import ModelExchange, Scenario, Scheme, Value
from .problems import NS_MM, NS_SSC, NS_SSD, NS_SSV
from .systems import component_element
from .values import BadValue, from_string
from .xmlio import tag

SETTINGS_TYPE = "org.multirate-master.settings"


def write_settings(original: Scenario, changed: Scenario, dest: Path, title: str) -> Path:
    """Write `changed`'s settings into a copy of `original`'s file at `dest` (.ssd or .ssp, the
    original's kind); `title` becomes a comment at the top of the settings. Refuses to overwrite
    the original."""
    source = Path(original.path)
    dest = Path(dest)
    if dest.suffix != source.suffix:
        raise ValueError(f"{dest}: a tuned copy of a {source.suffix} file must end in {source.suffix}")
    if dest.resolve() == source.resolve():
        raise ValueError(f"{dest}: would overwrite the original scenario")
    parser = etree.XMLParser(resolve_entities=False, no_network=True)  # comments kept
    if source.suffix == ".ssp":
        with zipfile.ZipFile(source) as zf:
            root = etree.fromstring(zf.read(SSD_NAME), parser)
    else:
        root = etree.parse(str(source), parser).getroot()
    _edit(root, original, changed, title)
    if source.suffix != ".ssp":
        _rebase(root, source.parent, dest.parent)
    dest.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=".tuned-", dir=dest.parent)
    os.close(fd)
    try:
        if source.suffix == ".ssp":
            _copy_archive(source, Path(tmp), _serialize(root))
        else:
            Path(tmp).write_bytes(_serialize(root))
        umask = os.umask(0)  # mkstemp makes it 0600: give it the mode a plain new file gets
        os.umask(umask)
        os.chmod(tmp, 0o666 & ~umask)
        os.replace(tmp, dest)
    finally:
        if os.path.exists(tmp):
            os.unlink(tmp)
    return dest


def _serialize(root: etree._Element) -> bytes:
    """The document with its comments before the root element each on a line of their own."""
    prolog = list(root.itersiblings(preceding=True))[::-1]
    parts = [b'<?xml version="1.0" encoding="UTF-8"?>', *map(etree.tostring, prolog), etree.tostring(root)]
    return b"\n".join(parts) + b"\n"


def decimal(t: Fraction) -> str:
    """An exact decimal for a time with a finite one, else the fraction (both read back exactly)."""
    d = Decimal(t.numerator) / Decimal(t.denominator)
    return format(d.normalize(), "f") if Fraction(d) == t else f"{t.numerator}/{t.denominator}"


def _model_exchange(elem: etree._Element, me: ModelExchange | None) -> None:
    """A component's Model Exchange settings (none: its attributes go)."""
    for attr in ("solver", "internalStep"):
        elem.attrib.pop(attr, None)
    if me is None:
        elem.attrib.pop("modelExchange", None)
        return
    elem.set("modelExchange", "true")
    elem.set("solver", me.solver)
    if me.internal_step is not None:
        elem.set("internalStep", decimal(me.internal_step))


def _edit(root: etree._Element, old: Scenario, new: Scenario, title: str) -> None:
    system = root.find(tag(NS_SSD, "System"))
    settings = _settings(system)
    note = etree.Comment(f" {title} ")
    settings.addprevious(note)
    note.tail = settings.getparent().text
    settings.set("macroStep", decimal(new.macro_step))
    settings.set("coupling", new.coupling)
    if new.coupling == Scheme.GAUSS_SEIDEL and new.order:
        settings.set("order", " ".join(new.order))
    elif "order" in settings.attrib:
        del settings.attrib["order"]
    settings.attrib.pop("extrapolationOrder", None)  # every component gets its own below
    for comp in new.components:
        elem = _child(settings, "Component", name=comp.name)
        elem.attrib.pop("communicationStep", None)
        elem.set("stepRatio", str(comp.step_ratio))
        elem.set("extrapolationOrder", str(comp.extrapolation_order))
        if comp.interpolate_inputs or "interpolateInputs" in elem.attrib:
            elem.set("interpolateInputs", "true" if comp.interpolate_inputs else "false")
        _model_exchange(elem, comp.model_exchange)
    per_link = {(c.end_component, c.end_connector): c.extrapolation_order for c in new.connections}
    for elem in settings.findall(tag(NS_MM, "Connection")):
        order = per_link.get((elem.get("endElement"), elem.get("endConnector")))
        if order is None:
            settings.remove(elem)
        else:
            elem.set("extrapolationOrder", str(order))
    if new.record_interval != old.record_interval and new.record_interval is not None:
        _child(settings, "Record").set("interval", decimal(new.record_interval))
    if new.record_coupling_errors != old.record_coupling_errors:
        _child(settings, "Record").set("couplingErrors", "true" if new.record_coupling_errors else "false")
    if new.iteration != old.iteration:
        for elem in settings.findall(tag(NS_MM, "Iteration")):
            settings.remove(elem)
        if new.iteration is not None:
            it = _child(settings, "Iteration")
            it.set("tolerance", repr(new.iteration.tolerance))
            it.set("maxIterations", str(new.iteration.max_iterations))
    changes: dict[str, tuple[Variable, Value]] = {}
    for comp in new.components:
        before = old.component(comp.name).parameters
        variables = fmuinfo.read(comp.fmu_path).variables
        changed = {k: v for k, v in comp.parameters.items()
                   if before.get(k) != v and (k in before or not _is_start(variables, k, v))}  # fmt: skip
        if changed:
            path = _path(system, component_element(system, comp.name))  # also in a nested system
            changes |= {f"{path}.{k}": (lookup(variables, k)[0], v) for k, v in changed.items()}
    if changes:
        _append_parameters(system, changes, title)


def _path(system: etree._Element, element: etree._Element) -> str:
    """The name of a component relative to `system` as SSP forms it: element names, dots between."""
    names = []
    while element is not system:
        names.append(element.get("name", ""))
        element = element.getparent().getparent()  # ssd:Elements, then its ssd:System
    return ".".join(reversed(names))


def _settings(system: etree._Element) -> etree._Element:
    """The system's mm:Settings (created with its annotation if the file has none)."""
    annotations = system.find(tag(NS_SSD, "Annotations"))
    if annotations is None:
        annotations = etree.SubElement(system, tag(NS_SSD, "Annotations"))
    for ann in annotations.findall(tag(NS_SSC, "Annotation")):
        if ann.get("type") == SETTINGS_TYPE:
            found = ann.find(tag(NS_MM, "Settings"))
            if found is not None:
                return found
    ann = etree.SubElement(annotations, tag(NS_SSC, "Annotation"), type=SETTINGS_TYPE)
    return etree.SubElement(ann, tag(NS_MM, "Settings"))


def _child(parent: etree._Element, kind: str, **attrs: str) -> etree._Element:
    """The first mm:`kind` child with these attributes, or a new one in the schema's place
    (components first, then connections, the record, the stimuli, loops, iteration)."""
    for elem in parent.findall(tag(NS_MM, kind)):
        if all(elem.get(k) == v for k, v in attrs.items()):
            return elem
    elem = etree.Element(tag(NS_MM, kind), **attrs)
    order = ["Component", "Connection", "Record", "Stimuli", "Loops", "Iteration"]
    later = [e for e in parent if etree.QName(e).localname in order[order.index(kind) + 1 :]]
    if later:
        later[0].addprevious(elem)
        elem.tail = parent.text
    else:
        parent.append(elem)
        _indent(elem, parent)
    return elem


def _is_start(variables: dict[str, Variable], name: str, value: Value) -> bool:
    """Whether `value` is the FMU's own start value of variable (or array element) `name`
    (setting it changes nothing)."""
    var, position = lookup(variables, name)
    start = var.start
    if start is not None and position is not None:  # an array's start: its elements, row major
        starts = start.split()
        start = starts[position] if position < len(starts) else None
    if start is None:
        return False
    try:
        return from_string(var, start) == value
    except BadValue:
        return False


def _append_parameters(
    element: etree._Element, values: dict[str, tuple[Variable, Value]], title: str
) -> None:
    bindings = element.find(tag(NS_SSD, "ParameterBindings"))
    if bindings is None:
        bindings = etree.Element(tag(NS_SSD, "ParameterBindings"))
        after = [e for e in element if etree.QName(e).localname in ("Connectors", "ElementGeometry")]
        (after[-1].addnext(bindings) if after else element.insert(0, bindings))
    binding = etree.SubElement(bindings, tag(NS_SSD, "ParameterBinding"))
    pv = etree.SubElement(binding, tag(NS_SSD, "ParameterValues"))
    pset = etree.SubElement(pv, tag(NS_SSV, "ParameterSet"), version="1.0", name=title)
    params = etree.SubElement(pset, tag(NS_SSV, "Parameters"))
    for name, (var, value) in values.items():
        p = etree.SubElement(params, tag(NS_SSV, "Parameter"), name=name)
        etree.SubElement(p, tag(NS_SSV, _ssv_type(var, value)), value=_ssv_text(var, value))
    _indent(binding, bindings)


def _ssv_type(var: Variable, value: Value) -> str:
    if var.kind == "Enumeration":
        return "Enumeration"
    if isinstance(value, bytes):
        return "Binary"
    if isinstance(value, bool):
        return "Boolean"
    return "Integer" if isinstance(value, int) else "String" if isinstance(value, str) else "Real"


def _ssv_text(var: Variable, value: Value) -> str:
    if var.kind == "Enumeration":  # the item's name, as people write it
        return next((n for n, v in var.items if v == value), str(value))
    if isinstance(value, bytes):  # xs:hexBinary
        return value.hex()
    return (
        str(value).lower()
        if isinstance(value, bool)
        else repr(value)
        if isinstance(value, float)
        else str(value)
    )


def _indent(elem: etree._Element, parent: etree._Element) -> None:
    """Indent a new last child like its siblings (two spaces a level)."""
    depth = sum(1 for _ in parent.iterancestors())
    etree.indent(elem, space="  ", level=depth + 1)
    siblings = [e for e in parent if e is not elem]
    inner = "\n" + "  " * (depth + 1)
    if siblings:
        elem.tail = siblings[-1].tail
        siblings[-1].tail = inner
    else:
        parent.text, elem.tail = inner, "\n" + "  " * depth


def _rebase(root: etree._Element, src_dir: Path, dest_dir: Path) -> None:
    """Relative `source` references to files (FMUs, .ssv and .ssm files) made relative to the new folder;
    project FMU names ("project:msd", or a bare name no file has) stay as they are."""
    if src_dir.resolve() == dest_dir.resolve():
        return
    for elem in root.iter(
        tag(NS_SSD, "Component"), tag(NS_SSD, "ParameterBinding"), tag(NS_SSD, "ParameterMapping")
    ):
        ref = elem.get("source")
        if ref and ":" not in ref.split("/")[0] and not os.path.isabs(ref) and (src_dir / ref).is_file():
            elem.set("source", os.path.relpath(src_dir.resolve() / ref, dest_dir.resolve()))


def _copy_archive(source: Path, dest: Path, ssd: bytes) -> None:
    with zipfile.ZipFile(source) as zin, zipfile.ZipFile(dest, "w", zipfile.ZIP_DEFLATED) as zout:
        for info in zin.infolist():
            if info.filename == SSD_NAME:
                zout.writestr(SSD_NAME, ssd)
            else:
                with zin.open(info) as src, zout.open(info, "w") as out:
                    shutil.copyfileobj(src, out)
