"""Parameter values: SSP parameter bindings (.ssv files and inline sets) and command-line overrides.

Precedence, lowest first (a later value replaces an earlier one for the same variable):
1. bindings on an ssd:Component: those with source= (.ssv files) in document order,
   then inline ssd:ParameterValues in document order;
2. bindings on each ssd:System, the deepest systems first and the top system last: "bindings
   at a higher hierarchy level take precedence over lower levels, i.e. bindings at a system
   level take precedence over bindings at a sub-system or component level" (SSP 1.0, the
   ParameterBindings element, as its SystemStructureDescription.xsd documents it; OMSimulator
   agrees).  Names are relative to the system, formed as that text
   says ("comp.var", "sub.comp.var", or a connector of the system or of a sub-system: "k", "sub.k");
3. values of system connectors (kind input or parameter) reach the component inputs and
   parameters their connections lead to (`systems`), replacing what those had: a connection
   makes the connected variable equal to its source, as OMSimulator does;
4. overrides ("component.variable" or a system connector's qualified name -> text, the CLI's
   --set); a system connector's override takes the place of its bound value in 3.

A binding's ssd:ParameterMapping (inline, or an .ssm file) renames its values first and transforms
them (`_named`, `_mapped`); a mapped value then stands where the binding's value would.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import NamedTuple

from lxml import etree

from master.description import FLOATS, Description, Variable, lookup

from . import transforms, xmlio
from .context import Context
from .fmuinfo import SourceError, file_at, no_element
from .model import Value
from .problems import NS_SSC, NS_SSD, NS_SSM, NS_SSV, Problems
from .systems import Flat, Scope, resolve
from .values import BadValue, from_ssv, from_string, settable
from .xmlio import log, tag

PARAMETER_SET = "application/x-ssp-parameter-set"
PARAMETER_MAPPING = "application/x-ssp-parameter-mapping"
SSV_TYPES = ("Real", "Integer", "Boolean", "Enumeration")  # the ssv types a transformation reads


class Entry(NamedTuple):
    """One value as found, in precedence order: the component it is bound on (None: a system), the
    name it binds, its ssv value element (ssv:Real ...), the file shown in problems, and the
    ssm:MappingEntry that gave it that name (with its file), if a parameter mapping did."""

    comp: str | None
    name: str
    value: etree._Element
    shown: str
    via: tuple[etree._Element, str] | None = None

    def target(self) -> tuple[str, etree._Element]:
        """Where a problem with the name it binds is shown: the mapping entry that chose the name,
        else the ssv:Parameter."""
        return (self.via[1], self.via[0]) if self.via else (self.shown, self.value.getparent())


def read(ctx: Context, flat: Flat, overrides: dict[str, str]) -> dict[str, dict[str, Value]]:
    """component -> {variable: value} after every binding and override, checked."""
    params: dict[str, dict[str, Value]] = {name: {} for name in ctx.comps}
    for c in ctx.comps.values():
        for entry in _entries(ctx, c.name, c.elem):
            _apply(ctx, params, entry)
    connectors: dict[str, Entry | str] = {}  # system connector -> its value (a binding or --set text)
    connectors |= system_values(ctx, flat, params)
    connectors |= {key: text for key, text in overrides.items() if flat.connector(key) is not None}
    for keys, comp, name, _ in flat.fed:
        value = next((connectors[k] for k in keys if k in connectors), None)
        if isinstance(value, str):
            _override(ctx, params, f"{comp}.{name}", value, (comp, name))
        elif value is not None:
            _apply(ctx, params, value._replace(comp=comp, name=name))
    for key, text in overrides.items():
        if key not in connectors:
            _override(ctx, params, key, text)
    return params


def system_values(ctx: Context, flat: Flat, params: dict[str, dict[str, Value]]) -> dict[str, Entry]:
    """The bindings on systems: those that name a component variable applied to `params`, and the
    values of system connectors returned (qualified connector name -> the binding that wins)."""
    connectors: dict[str, Entry] = {}
    # the top system last: its bindings win (SSP 1.0, ParameterBindings; precedence 2 above)
    for scope in sorted(flat.scopes, key=lambda s: -s.depth):  # stable: siblings in document order
        for entry in _entries(ctx, None, scope.elem):
            _system_entry(ctx, scope, params, connectors, entry)
    return connectors


def _system_entry(
    ctx: Context,
    scope: Scope,
    params: dict[str, dict[str, Value]],
    connectors: dict[str, Entry],
    entry: Entry,
) -> None:
    """One parameter bound on a system: to a variable of a component in it, or to a system connector."""
    found = resolve(scope, entry.name)
    if isinstance(found, str):
        connectors[found] = entry
    elif found is not None:
        _apply(ctx, params, entry._replace(comp=found[0], name=found[1]))
    else:
        system = f"system {scope.name}" if scope.name else f'system "{scope.elem.get("name")}"'
        ctx.problems.at(
            *entry.target(),
            f'"{entry.name}" names neither a connector of {system} nor a component of it and a dot',
        )


def _entries(ctx: Context, comp: str | None, holder: etree._Element) -> list[Entry]:
    """The parameters bound on one element: file sources first, then inline sets."""
    from_files: list[Entry] = []
    inline: list[Entry] = []
    for binding in holder.findall(f"{tag(NS_SSD, 'ParameterBindings')}/{tag(NS_SSD, 'ParameterBinding')}"):
        if binding.get("type", PARAMETER_SET) != PARAMETER_SET:
            ctx.at(binding, f'type "{binding.get("type")}" is not supported (only {PARAMETER_SET})')
            continue
        if binding.get("sourceBase", "SSD") != "SSD":
            ctx.at(binding, 'sourceBase="component" is not supported: put the .ssv beside the .ssd')
            continue
        ok, mapping = _mapping(ctx, binding)
        if not ok:
            continue
        prefix = binding.get("prefix", "")
        source = binding.get("source")
        values = binding.find(tag(NS_SSD, "ParameterValues"))
        if source is not None and values is not None:
            ctx.at(binding, "give either source= or inline ssd:ParameterValues, not both")
            continue
        if source is not None:
            found = _source_file(ctx, binding, source, "parameter file", ("ssv", NS_SSV, "ParameterSet"))
            if found is not None:
                pset, shown = found
                from_files += _named(comp, prefix, pset, shown, mapping)
        elif values is not None:
            pset = values.find(tag(NS_SSV, "ParameterSet"))
            if pset is None:
                ctx.at(values, "must hold one ssv:ParameterSet")
                continue
            inline += _named(comp, prefix, pset, ctx.shown, mapping)
        else:
            ctx.at(binding, "has neither source= nor inline ssd:ParameterValues")
    return from_files + inline


Mapping = dict[str, list[tuple[etree._Element, str]]]  # source name -> (ssm:MappingEntry, its file)


def _mapping(ctx: Context, binding: etree._Element) -> tuple[bool, Mapping | None]:
    """The ssd:ParameterMapping of a binding, inline or from an .ssm file, by source name (one
    source may have several targets): (True, the mapping), (True, None) without one, (False, None)
    after reporting a problem."""
    elem = binding.find(tag(NS_SSD, "ParameterMapping"))
    if elem is None:
        return True, None
    if elem.get("type", PARAMETER_MAPPING) != PARAMETER_MAPPING:
        ctx.at(elem, f'type "{elem.get("type")}" is not supported (only {PARAMETER_MAPPING})')
        return False, None
    if elem.get("sourceBase", "SSD") != "SSD":
        ctx.at(elem, 'sourceBase="component" is not supported: put the .ssm beside the .ssd')
        return False, None
    source = elem.get("source")
    inline = elem.find(tag(NS_SSM, "ParameterMapping"))
    if source is not None and inline is not None:
        ctx.at(elem, "give either source= or an inline ssm:ParameterMapping, not both")
        return False, None
    if source is not None:
        found = _source_file(ctx, elem, source, "parameter mapping", ("ssm", NS_SSM, "ParameterMapping"))
        if found is None:
            return False, None
        root, shown = found
    elif inline is not None:
        root, shown = inline, ctx.shown
    else:
        ctx.at(elem, "has neither source= nor an inline ssm:ParameterMapping")
        return False, None
    mapping: Mapping = {}
    sources: dict[str, str] = {}  # target -> the source mapped to it
    for entry in root.findall(tag(NS_SSM, "MappingEntry")):
        source, target = entry.get("source"), entry.get("target")
        if source is None or target is None:
            continue  # the schema check has said so
        if sources.setdefault(target, source) != source:  # SSP 1.0.1 and 2.0, SSM chapter
            ctx.problems.at(shown, entry, f'maps "{source}" to "{target}", to which "{sources[target]}" '
                            "is mapped already: implementations must not map multiple parameters to "
                            "the same name")  # fmt: skip
            return False, None
        mapping.setdefault(source, []).append((entry, shown))
    return True, mapping


def _named(
    comp: str | None, prefix: str, pset: etree._Element, shown: str, mapping: Mapping | None
) -> list[Entry]:
    """The entries of a parameter set under the names they bind. Without a mapping, each keeps its
    name (with the prefix): "If no mapping is supplied, the parameter names of the parameter source
    are used as is for name matching" (SSP 1.0.1 and 2.0, ssd:ParameterMapping). With one, a name the
    mapping maps binds the target of each of its entries (one source, several targets: "CAN map
    the same parameter to multiple names"; prefix= is not added to a target, "the name of the
    parameter in the system or component"), and the others are dropped, a warning naming them:
    "All parameters of the parameter source which are not referenced in a mapping entry will not
    be applied. All parameters that are referenced in a mapping entry will only be applied using
    the name they are mapped to" (SSP 1.0.1 and 2.0, the SSM chapter, ParameterMapping). OMSimulator
    applies unmapped ones under their own names; the standard's rule is kept here. Mapping entries
    whose source the set lacks bind nothing (OMSimulator's .ssm templates list every target with
    source="")."""
    if mapping is None:
        return [Entry(comp, prefix + name, value, shown) for name, value in _parameters(pset)]
    found: list[Entry] = []
    dropped: list[str] = []
    for name, value in _parameters(pset):
        if name in mapping:
            found += [Entry(comp, e.get("target"), value, shown, (e, file)) for e, file in mapping[name]]
        else:
            dropped.append(name)
    if dropped:
        names = ", ".join(f'"{n}"' for n in dropped[:5]) + (
            f" and {len(dropped) - 5} more" if len(dropped) > 5 else ""
        )
        log.warning(
            "%s:%s: %s not applied: the binding's parameter mapping does not name %s (SSP: parameters a "
            "mapping does not reference are not applied)",
            shown, pset.sourceline, names, "it" if len(dropped) == 1 else "them",
        )  # fmt: skip
    return found


def _source_file(
    ctx: Context, holder: etree._Element, source: str, what: str, root_tag: tuple[str, str, str]
) -> tuple[etree._Element, str] | None:
    """The checked root element (`root_tag`: prefix, namespace, local name) of a file that `holder`
    names in source= (.ssv or .ssm, checked with the schema of the file's own SSP version), and
    how problems name that file."""
    if "://" in source or source.startswith("file:"):
        ctx.at(holder, f'unsupported URI "{source}": use a path relative to the .ssd')
        return None
    try:
        path, found = file_at(ctx.base, source)
    except SourceError as err:
        ctx.at(holder, str(err))
        return None
    if ctx.inside is not None and not path.is_relative_to(ctx.inside.resolve()):
        ctx.at(holder, f'source "{source}" points outside the archive')
        return None
    shown = (
        str(Path(ctx.shown).parent / source)
        if ctx.inside is None
        else f"{ctx.shown.rsplit('!/', 1)[0]}!/{source}"
    )
    if not found:
        ctx.at(holder, f'{what} "{source}" not found')
        return None
    prefix, ns, local = root_tag
    problems = Problems()
    tree = xmlio.parse(path, shown, problems)
    schema = (xmlio.ssv_schema if ns == NS_SSV else xmlio.ssm_schema)(tree) if tree is not None else None
    if tree is not None and xmlio.check_schema(tree, schema, shown, problems):
        root = tree.getroot()
        if root.tag == tag(ns, local):
            return root, shown
        problems.at(shown, root, f"not an {prefix}:{local}")
    ctx.problems.items.extend(problems.items)
    return None


def _parameters(pset: etree._Element) -> list[tuple[str, etree._Element]]:
    """(name, value element such as ssv:Real) of each ssv:Parameter of a set."""
    found = []
    for p in pset.findall(f"{tag(NS_SSV, 'Parameters')}/{tag(NS_SSV, 'Parameter')}"):
        value = next((c for c in p if etree.QName(c).namespace == NS_SSV), None)
        if p.get("name") is not None and value is not None:
            found.append((p.get("name"), value))
    return found


def _apply(ctx: Context, params: dict[str, dict[str, Value]], entry: Entry) -> None:
    comp, name, value_elem, shown = entry.comp, entry.name, entry.value, entry.shown
    param = value_elem.getparent()
    c = ctx.comps.get(comp)
    if c is None:
        ctx.problems.at(*entry.target(), f'unknown component "{comp}"')
        return
    if c.info is None:
        return
    found = lookup(c.info.variables, name)
    if found is None:
        why = no_element(c.info.variables, name)
        unknown = f"{comp}.{why}" if why else f'the FMU of {comp} ({c.info.path.name}) has no "{name}"'
        ctx.problems.at(*entry.target(), f"unknown variable: {unknown}")
        return
    var = found[0]
    why = settable(var, found[1] is not None) or _sizes(c.info, name)
    if why:
        ctx.problems.at(*entry.target(), f"cannot bind {comp}.{name}: {why}")
        return
    ssv_type = etree.QName(value_elem).localname
    try:
        if entry.via is not None:
            value = _mapped(ctx, entry, var, c.info.fmi_version)
            if value is not None:
                params[comp][name] = value
            return
        params[comp][name] = from_ssv(var, ssv_type, value_elem.get("value", ""), value_elem.get("unit"))
    except (BadValue, ValueError) as err:
        ctx.problems.at(shown, param, f"{comp}.{name}: {err}")


def _mapped(ctx: Context, entry: Entry, var: Variable, fmi_version: str) -> Value | None:
    """The value of `entry` (given its name by ssm:MappingEntry `entry.via`) for variable `var`:
    the entry's transformation (ssc:LinearTransformation or a mapping transformation, read as a
    connection's: `transforms.read`) applied, after converting the value's unit to the variable's
    where they differ and the entry does not set suppressUnitConversion; None after a problem.
    BadValue for a value that does not fit `var`."""
    mapping, file = entry.via
    ssv_type = etree.QName(entry.value).localname
    text, unit = entry.value.get("value", ""), entry.value.get("unit")
    transformed = any(etree.QName(c).namespace == NS_SSC for c in mapping)
    if not transformed and not (unit and var.unit and unit != var.unit):
        return from_ssv(var, ssv_type, text, unit)
    source = _source_var(entry, mapping)
    if source is None:
        ctx.problems.at(file, mapping, f"a transformation of ssv:{ssv_type} values is not supported")
        return None
    root = ctx.comps[entry.comp].elem.getroottree().getroot()
    quiet = dataclasses.replace(ctx, problems=Problems())  # the connections' reader reports bad units
    defined = transforms.units(quiet, root)
    # problems at the mapping entry, in its file; once, though a system connector's value may
    # reach several variables
    here = dataclasses.replace(ctx, shown=file, problems=Problems())
    ends = (f'parameter "{mapping.get("source")}"', f"{entry.comp}.{entry.name}")
    ok, t = transforms.read(here, mapping, ends, source, var, (unit, var.unit), defined, fmi_version)
    ctx.problems.items += [p for p in here.problems.items if p not in ctx.problems.items]
    if not ok:
        return None
    if ssv_type == "Enumeration" and text not in dict(source.items):  # no ssc:MapEntry names it:
        return from_ssv(var, ssv_type, text, unit)  # unchanged, as a map passes such a value
    number = _number(source, ssv_type, text)
    result = number if t is None else transforms.applied(t, number)
    if var.kind in FLOATS:
        return from_string(var, repr(result))
    if result != int(result):  # a unit conversion towards an integer variable
        raise BadValue(f"{result!r} is not an integer ({var.name} is {var.fmi_type})")
    return from_string(var, str(int(result)))


def _source_var(entry: Entry, mapping: etree._Element) -> Variable | None:
    """A variable standing for the value's side of a mapping entry (its ssv type and unit; an
    enumeration's items are the source names of the entry's ssc:MapEntry elements)."""
    ssv_type = etree.QName(entry.value).localname
    if ssv_type not in SSV_TYPES:
        return None
    items: tuple[tuple[str, int], ...] = ()
    if ssv_type == "Enumeration":
        names = [m.get("source", "") for m in mapping.iter(tag(NS_SSC, "MapEntry"))]
        items = tuple((n, i) for i, n in enumerate(dict.fromkeys(names)))
    name = entry.value.getparent().get("name", "")
    unit = entry.value.get("unit")
    # not the FMU's: no value reference
    return Variable(name, -1, ssv_type, "parameter", "fixed", None, None, unit, None, items=items)


def _number(source: Variable, ssv_type: str, text: str) -> float:
    """The number a schema-valid ssv value stands for, as a transformation reads it."""
    if ssv_type == "Boolean":
        return 1.0 if text.strip() in ("true", "1") else 0.0
    if ssv_type == "Enumeration":
        return float(dict(source.items)[text])
    return float(text)


def _override(
    ctx: Context,
    params: dict[str, dict[str, Value]],
    key: str,
    text: str,
    split: tuple[str, str] | None = None,
) -> None:
    """--set key=text; `split`: the (component, variable) that a system connector's --set reaches."""
    where = ("--set", None, key)
    split = split or ctx.split_name(key)
    if split is None:
        ctx.problems.add(
            *where,
            "expected component.variable with a component of the scenario (in a sub-system:"
            " sub.comp.variable; a name with a dot in quotes: 'a.b'.variable), or a system connector",
        )
        return
    comp, name = split
    c = ctx.comps[comp]
    if c.info is None:
        return
    found = lookup(c.info.variables, name)
    if found is None:
        why = no_element(c.info.variables, name)
        unknown = f"{comp}.{why}" if why else f'the FMU of {comp} ({c.info.path.name}) has no "{name}"'
        ctx.problems.add(*where, f"unknown variable: {unknown}")
        return
    var = found[0]
    why = settable(var, found[1] is not None) or _sizes(c.info, name)
    if why:
        ctx.problems.add(*where, f"cannot set {comp}.{name}: {why}")
        return
    try:
        params[comp][name] = from_string(var, text)
    except BadValue as err:
        ctx.problems.add(*where, str(err))


def _sizes(info: Description, name: str) -> str | None:
    """Why `name` cannot be set if it is a structural parameter that sizes FMI 3 arrays: the
    master takes every array's size from the model description (its start), which a value set
    here would change (configuration mode is not supported)."""
    arrays = info.sizes.get(name)
    if not arrays:
        return None
    return (
        f"it is the size of {', '.join(arrays)}; array sizes are the model description's "
        "(structural parameters that size arrays are not set)"
    )
