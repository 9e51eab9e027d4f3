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
"""

from __future__ import annotations

from pathlib import Path

from lxml import etree

from . import xmlio
from .context import Context
from .fmuinfo import FmuInfo, SourceError, file_at, lookup, no_element
from .model import Value
from .problems import NS_SSD, NS_SSV, Problems
from .systems import Flat, Scope, resolve
from .values import BadValue, from_ssv, from_string, settable
from .xmlio import tag

PARAMETER_SET = "application/x-ssp-parameter-set"

# (component or None, name, value element, file shown in problems) as found, in precedence order
Entry = tuple[str | None, str, etree._Element, str]


def read(ctx: Context, flat: Flat, overrides: dict[str, str]) -> dict[str, dict[str, Value]]:
    """component -> {variable: value} after every binding and override, checked."""
    params: dict[str, dict[str, Value]] = {name: {} for name in ctx.comps}
    for c in ctx.comps.values():
        for entry in _entries(ctx, c.name, c.elem):
            _apply(ctx, params, entry)
    connectors: dict[str, Entry | str] = {}  # system connector -> its value (a binding or --set text)
    # the top system last: its bindings win (SSP 1.0, ParameterBindings; precedence 2 above)
    for scope in sorted(flat.scopes, key=lambda s: -s.depth):  # stable: siblings in document order
        for entry in _entries(ctx, None, scope.elem):
            _system_entry(ctx, flat, scope, params, connectors, entry)
    connectors |= {key: text for key, text in overrides.items() if flat.connector(key) is not None}
    for keys, comp, name, _ in flat.fed:
        value = next((connectors[k] for k in keys if k in connectors), None)
        if isinstance(value, str):
            _override(ctx, params, f"{comp}.{name}", value, (comp, name))
        elif value is not None:
            _apply(ctx, params, (comp, name, value[2], value[3]))
    for key, text in overrides.items():
        if key not in connectors:
            _override(ctx, params, key, text)
    return params


def _system_entry(
    ctx: Context,
    flat: Flat,
    scope: Scope,
    params: dict[str, dict[str, Value]],
    connectors: dict[str, Entry | str],
    entry: Entry,
) -> None:
    """One parameter bound on a system: to a variable of a component in it, or to a system connector."""
    _, name, value_elem, shown = entry
    found = resolve(scope, name)
    if isinstance(found, str):
        connectors[found] = entry
    elif found is not None:
        _apply(ctx, params, (*found, value_elem, shown))
    else:
        system = f"system {scope.name}" if scope.name else f'system "{scope.elem.get("name")}"'
        ctx.problems.at(
            shown,
            value_elem.getparent(),
            f'"{name}" names neither a connector of {system} nor a component of it and a dot',
        )


def _entries(ctx: Context, comp: str | None, holder: etree._Element) -> list[Entry]:
    """The parameters bound on one element: file sources first, then inline sets."""
    from_files: list[Entry] = []
    inline: list[Entry] = []
    for binding in holder.findall(f"{tag(NS_SSD, 'ParameterBindings')}/{tag(NS_SSD, 'ParameterBinding')}"):
        if binding.get("type", PARAMETER_SET) != PARAMETER_SET:
            ctx.at(binding, f'type "{binding.get("type")}" is not supported (only {PARAMETER_SET})')
            continue
        if binding.find(tag(NS_SSD, "ParameterMapping")) is not None:
            ctx.at(binding, "ssd:ParameterMapping is not supported: name the parameters as the FMU does")
        if binding.get("sourceBase", "SSD") != "SSD":
            ctx.at(binding, 'sourceBase="component" is not supported: put the .ssv beside the .ssd')
            continue
        prefix = binding.get("prefix", "")
        source = binding.get("source")
        values = binding.find(tag(NS_SSD, "ParameterValues"))
        if source is not None and values is not None:
            ctx.at(binding, "give either source= or inline ssd:ParameterValues, not both")
            continue
        if source is not None:
            found = _ssv_file(ctx, binding, source)
            if found is not None:
                pset, shown = found
                from_files += [(comp, prefix + n, v, shown) for n, v in _parameters(pset)]
        elif values is not None:
            pset = values.find(tag(NS_SSV, "ParameterSet"))
            if pset is None:
                ctx.at(values, "must hold one ssv:ParameterSet")
                continue
            inline += [(comp, prefix + n, v, ctx.shown) for n, v in _parameters(pset)]
        else:
            ctx.at(binding, "has neither source= nor inline ssd:ParameterValues")
    return from_files + inline


def _ssv_file(ctx: Context, binding: etree._Element, source: str) -> tuple[etree._Element, str] | None:
    """The checked ssv:ParameterSet of a .ssv file, and how problems name that file."""
    if "://" in source or source.startswith("file:"):
        ctx.at(binding, f'unsupported URI "{source}": use a path relative to the .ssd')
        return None
    try:
        path, found = file_at(ctx.base, source)
    except SourceError as err:
        ctx.at(binding, str(err))
        return None
    if ctx.inside is not None and not path.is_relative_to(ctx.inside.resolve()):
        ctx.at(binding, f'source "{source}" points outside the archive')
        return None
    shown = (
        str(Path(ctx.shown).parent / source)
        if ctx.inside is None
        else f"{ctx.shown.rsplit('!/', 1)[0]}!/{source}"
    )
    if not found:
        ctx.at(binding, f'parameter file "{source}" not found')
        return None
    problems = Problems()
    tree = xmlio.parse(path, shown, problems)
    if tree is not None and xmlio.check_schema(tree, xmlio.ssv_schema(tree), shown, problems):
        root = tree.getroot()
        if root.tag == tag(NS_SSV, "ParameterSet"):
            return root, shown
        problems.at(shown, root, "not an ssv:ParameterSet")
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
    comp, name, value_elem, shown = entry
    param = value_elem.getparent()
    c = ctx.comps.get(comp)
    if c is None:
        ctx.problems.at(shown, param, f'unknown component "{comp}"')
        return
    if c.info is None:
        return
    found = lookup(c.info.variables, name)
    if found is None:
        why = no_element(c.info.variables, name)
        unknown = f"{comp}.{why}" if why else f'the FMU of {comp} ({c.info.path.name}) has no "{name}"'
        ctx.problems.at(shown, param, f"unknown variable: {unknown}")
        return
    var = found[0]
    why = settable(var, found[1] is not None) or _sizes(c.info, name)
    if why:
        ctx.problems.at(shown, param, f"cannot bind {comp}.{name}: {why}")
        return
    ssv_type = etree.QName(value_elem).localname
    try:
        params[comp][name] = from_ssv(var, ssv_type, value_elem.get("value", ""), value_elem.get("unit"))
    except (BadValue, ValueError) as err:
        ctx.problems.at(shown, param, f"{comp}.{name}: {err}")


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


def _sizes(info: FmuInfo, name: str) -> str | None:
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
