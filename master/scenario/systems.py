"""Nested ssd:System elements flattened into one system of FMU components.

Components are named by their path (`master.scenario.names`: `sub.comp`, `sub.inner.comp`).
A connection between two components of one system is kept as written.  Connections that reach a
system's own connector (startElement or endElement absent or empty: the enclosing system; or the
name of a sub-system) join, through those connectors and at any depth, into nets.  In a net:
- the one component output drives every component input (two outputs in one net are a problem);
- without an output, the value bound to one of its system connectors (kind input or parameter)
  becomes a parameter value of every component input and parameter of the net; the connector of
  the highest system wins, as bindings at a higher level do (SSP 1.0, ssd:ParameterBindings); a net
  whose connectors have no value leaves its inputs at their start values;
- an output connector of the top system names the component output recorded for it.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from lxml import etree

from .context import Context
from .names import join
from .problems import NS_SSD
from .xmlio import tag

SOURCE_KINDS = ("output", "calculatedParameter")
SINK_KINDS = ("input", "parameter")
VALUE_KINDS = ("input", "parameter")  # system connectors whose bound value feeds a net without an output

Link = tuple[tuple[str, str, str, str], etree._Element]  # ((start comp, output, end comp, input), element)


@dataclass
class Scope:
    """One system: its qualified name ("" for the top), element, depth and what it holds."""

    name: str
    elem: etree._Element
    depth: int
    connectors: dict[str, etree._Element] = field(default_factory=dict)  # own connectors by name
    components: dict[str, str] = field(default_factory=dict)  # element name -> qualified name
    systems: dict[str, Scope] = field(default_factory=dict)  # element name -> sub-system
    refused: set[str] = field(default_factory=set)  # elements reported as not supported

    def key(self, connector: str) -> str:
        """The qualified name of one of its connectors ("k", "sub.k")."""
        return f"{self.name}.{connector}" if self.name else connector


@dataclass
class Flat:
    top: Scope
    scopes: list[Scope] = field(default_factory=list)  # every system, top first
    components: list[tuple[str, etree._Element]] = field(default_factory=list)  # (qualified, ssd:Component)
    links: list[Link] = field(default_factory=list)  # component output -> component input
    # (qualified system connectors of the net, top first; component; input or parameter; connection)
    fed: list[tuple[list[str], str, str, etree._Element]] = field(default_factory=list)
    outputs: list[tuple[str, str, str]] = field(default_factory=list)  # (top connector, component, output)

    def connector(self, key: str) -> tuple[Scope, str] | None:
        """The system and name of the system connector with qualified name `key`."""
        for scope in self.scopes:
            for name in scope.connectors:
                if scope.key(name) == key:
                    return scope, name
        return None


@dataclass(frozen=True)
class Node:
    """One end of a connection: a connector of a component or of a system (qualified names)."""

    owner: str
    connector: str
    system: bool


def flatten(ctx: Context, top: etree._Element) -> Flat:
    """Every component of `top` and its sub-systems, and the connections between them resolved."""
    flat = Flat(Scope("", top, 0))
    edges: list[tuple[Node, Node, etree._Element]] = []
    _walk(ctx, flat, flat.top, edges)
    _resolve(ctx, flat, edges)
    return flat


def _walk(ctx: Context, flat: Flat, scope: Scope, edges: list) -> None:
    system = scope.elem
    flat.scopes.append(scope)
    for conn in system.findall(f"{tag(NS_SSD, 'Connectors')}/{tag(NS_SSD, 'Connector')}"):
        name = conn.get("name")
        if name is not None and name in scope.connectors:
            ctx.at(conn, f'a second connector "{name}" on system {scope.name or system.get("name")}')
        elif name is not None:
            scope.connectors[name] = conn
    dictionaries = system.find(tag(NS_SSD, "SignalDictionaries"))
    if dictionaries is not None:
        ctx.at(dictionaries, "signal dictionaries (SSP 1.0) are not supported: connect the signals directly")
    elements = system.find(tag(NS_SSD, "Elements"))
    for elem in elements if elements is not None else ():
        local, name = etree.QName(elem).localname, elem.get("name")
        if name is None:
            continue  # schema error already
        if local == "SignalDictionaryReference":
            ctx.at(elem, "signal dictionaries (SSP 1.0) are not supported: connect the signals directly")
            scope.refused.add(name)
            continue
        if local not in ("Component", "System"):
            ctx.at(elem, f"ssd:{local} is not supported")
            scope.refused.add(name)
            continue
        if name in scope.components or name in scope.systems:
            ctx.at(elem, f'a second component named "{name}"')
            continue
        qualified = join(scope.name, name)
        if local == "System":
            scope.systems[name] = sub = Scope(qualified, elem, scope.depth + 1)
            _walk(ctx, flat, sub, edges)
        else:
            scope.components[name] = qualified
            flat.components.append((qualified, elem))
    for elem in system.findall(f"{tag(NS_SSD, 'Connections')}/{tag(NS_SSD, 'Connection')}"):
        se, sc, ee, ec = (
            elem.get(a) for a in ("startElement", "startConnector", "endElement", "endConnector")
        )
        if sc is None or ec is None or {se, ee} & scope.refused:
            continue  # schema error, or an element reported as not supported, already
        start, end = _node(scope, se, sc), _node(scope, ee, ec)
        if start.system or end.system:
            edges.append((start, end, elem))
        else:
            flat.links.append(((start.owner, sc, end.owner, ec), elem))


def _node(scope: Scope, element: str | None, connector: str) -> Node:
    if not element:
        return Node(scope.name, connector, True)
    if element in scope.systems:
        return Node(scope.systems[element].name, connector, True)
    # a component, or an unknown element that the connection check reports
    return Node(scope.components.get(element, join(scope.name, element)), connector, False)


def _resolve(ctx: Context, flat: Flat, edges: list[tuple[Node, Node, etree._Element]]) -> None:
    """Nets of connections through system connectors -> links, fed parameters, recorded outputs."""
    scopes = {s.name: s for s in flat.scopes}
    kinds = {
        (name, conn.get("name")): conn.get("kind")
        for name, elem in flat.components
        for conn in elem.findall(f"{tag(NS_SSD, 'Connectors')}/{tag(NS_SSD, 'Connector')}")
    }
    comps = {name for name, _ in flat.components}
    parent: dict[Node, Node] = {}

    def root(n: Node) -> Node:
        while parent.setdefault(n, n) != n:
            n = parent[n]
        return n

    touching: dict[Node, etree._Element] = {}  # the first connection at each end: problems name it
    for a, b, elem in edges:
        parent[root(a)] = root(b)
        touching.setdefault(a, elem)
        touching.setdefault(b, elem)
    nets: dict[Node, list[Node]] = {}
    for n in touching:
        nets.setdefault(root(n), []).append(n)
    for net in nets.values():
        sources, sinks, values, outputs = [], [], [], []
        for n in net:
            elem = touching[n]
            if n.system:
                scope = scopes[n.owner]
                conn = scope.connectors.get(n.connector)
                if conn is None:
                    what = f"system {n.owner}" if n.owner else "the system"
                    ctx.at(elem, f'{what} has no connector "{n.connector}"')
                elif conn.get("kind") in VALUE_KINDS:
                    values.append((scope.depth, scope.key(n.connector)))
                elif conn.get("kind") == "output" and scope is flat.top:
                    outputs.append(n.connector)
            elif n.owner not in comps:
                ctx.at(elem, f'unknown component "{n.owner}"')
            elif (n.owner, n.connector) not in kinds:
                ctx.at(elem, f'component {n.owner} has no connector "{n.connector}"')
            elif kinds[n.owner, n.connector] in SOURCE_KINDS:
                sources.append(n)
            elif kinds[n.owner, n.connector] in SINK_KINDS:
                sinks.append(n)
        if len(sources) > 1:
            names = " and ".join(f"{s.owner}.{s.connector}" for s in sources)
            ctx.at(touching[sources[1]], f"joins the outputs {names} through system connectors: one at most")
            continue
        if sources:
            src = sources[0]
            flat.links += [((src.owner, src.connector, s.owner, s.connector), touching[s]) for s in sinks]
            flat.outputs += [(name, src.owner, src.connector) for name in outputs]
            continue
        keys = [key for _, key in sorted(values, key=lambda v: v[0])]
        flat.fed += [(keys, s.owner, s.connector, touching[s]) for s in sinks]


def resolve(scope: Scope, name: str) -> tuple[str, str] | str | None:
    """What `name`, relative to system `scope` as SSP 1.0 names parameters ("k", "sub.k",
    "comp.var", "sub.comp.var"; element names as written, dots and all), names: (component,
    variable), or the qualified name of a system connector; None if nothing."""
    if name in scope.connectors:
        return scope.key(name)
    for element in sorted({*scope.components, *scope.systems}, key=len, reverse=True):
        if not name.startswith(element + "."):
            continue
        rest = name[len(element) + 1 :]
        if element in scope.components:
            return scope.components[element], rest
        found = resolve(scope.systems[element], rest)
        if found is not None:
            return found
    return None


def component_element(system: etree._Element, name: str, prefix: str = "") -> etree._Element | None:
    """The ssd:Component whose qualified name is `name`, in `system` or a system nested in it."""
    elements = system.find(tag(NS_SSD, "Elements"))
    for elem in elements if elements is not None else ():
        qualified = join(prefix, elem.get("name", ""))
        local = etree.QName(elem).localname
        if local == "Component" and qualified == name:
            return elem
        if local == "System" and name.startswith(qualified + "."):
            found = component_element(elem, name, qualified)
            if found is not None:
                return found
    return None
