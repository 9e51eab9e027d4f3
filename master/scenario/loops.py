"""Algebraic loops: cycles in which every hop is without delay.

Nodes are ports "component.variable".  Edges: each connection (output -> input, no delay
in the master) and, inside an FMU, each input -> output it feeds through directly
(ModelStructure/Outputs dependencies; no dependencies attribute means all inputs).
A strongly connected component with more than one port holds a loop. The runtime solves loops of
continuous signals at communication points (master.schedule.Loop); a loop through a discrete or
text connection is a problem.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping

from lxml import etree

from .context import Context
from .fmuinfo import CONTINUOUS, coupling_kind

Port = tuple[str, str]


def port_graph(
    connections: Iterable[tuple[str, str, str, str]], feedthrough: Mapping[str, Mapping[str, Iterable[str]]]
) -> dict[Port, list[Port]]:
    """Adjacency lists of the port graph: each connection (start component, output, end component,
    input) and, per component, each input -> output its `feedthrough` (output -> inputs) names."""
    edges: dict[Port, list[Port]] = {}
    for se, sc, ee, ec in connections:
        edges.setdefault((se, sc), []).append((ee, ec))
    for name, through in feedthrough.items():
        for output, inputs in sorted(through.items()):
            for inp in sorted(inputs):
                edges.setdefault((name, inp), []).append((name, output))
    return edges


def graph(
    ctx: Context, connections: list[tuple[tuple[str, str, str, str], etree._Element]]
) -> dict[Port, list[Port]]:
    """The port graph of a scenario file's connections and its FMUs' model structure."""
    feedthrough = {c.name: c.info.feedthrough for c in ctx.comps.values() if c.info is not None}
    return port_graph((key for key, _ in connections), feedthrough)


def strongly_connected(edges: dict[Port, list[Port]]) -> list[list[Port]]:
    """Tarjan's algorithm, iterative (scenes may be large; no recursion limit)."""
    index: dict[Port, int] = {}
    low: dict[Port, int] = {}
    stack: list[Port] = []
    on_stack: set[Port] = set()
    result: list[list[Port]] = []
    nodes = list(edges) + [n for targets in edges.values() for n in targets]
    for root in nodes:
        if root in index:
            continue
        work = [(root, 0)]
        while work:
            node, i = work.pop()
            if i == 0:
                index[node] = low[node] = len(index)
                stack.append(node)
                on_stack.add(node)
            targets = edges.get(node, [])
            if i < len(targets):
                work.append((node, i + 1))
                nxt = targets[i]
                if nxt not in index:
                    work.append((nxt, 0))
                elif nxt in on_stack:
                    low[node] = min(low[node], index[nxt])
                continue
            if low[node] == index[node]:
                scc = []
                while True:
                    member = stack.pop()
                    on_stack.discard(member)
                    scc.append(member)
                    if member == node:
                        break
                result.append(scc)
            if work:
                parent = work[-1][0]
                low[parent] = min(low[parent], low[node])
    return result


def cycle_in(scc: list[Port], edges: dict[Port, list[Port]]) -> list[Port]:
    """One cycle through the first port of a strongly connected component (closed: last == first)."""
    members = set(scc)
    start = min(scc)
    # breadth-first search back to start, staying inside the component
    previous: dict[Port, Port] = {}
    frontier = [start]
    while frontier:
        nxt_frontier = []
        for node in frontier:
            for nxt in edges.get(node, []):
                if nxt not in members:
                    continue
                if nxt == start:
                    path = [node]
                    while path[-1] != start:
                        path.append(previous[path[-1]])
                    return path[::-1] + [start]
                if nxt not in previous:
                    previous[nxt] = node
                    nxt_frontier.append(nxt)
        frontier = nxt_frontier
    return [start]


def check(ctx: Context, connections: list[tuple[tuple[str, str, str, str], etree._Element]]) -> None:
    """One problem per algebraic loop the runtime cannot solve (one through a connection that does
    not carry a Real or Float32 signal), at that connection."""
    edges = graph(ctx, connections)
    elems = {(key[0], key[1], key[2], key[3]): elem for key, elem in connections}
    for scc in strongly_connected(edges):
        if len(scc) < 2:
            continue
        members = set(scc)
        for (se, sc, ee, ec), elem in sorted(elems.items(), key=lambda e: e[1].sourceline or 0):
            if (se, sc) not in members or (ee, ec) not in members:
                continue
            info = ctx.comps[se].info if se in ctx.comps else None
            var = info.variables.get(sc) if info is not None else None
            kind = coupling_kind(var.fmi_type, info.fmi_version) if var is not None else None
            if kind is None or kind in CONTINUOUS:
                continue
            path = " -> ".join(f"{c}.{v}" for c, v in cycle_in(scc, edges))
            ctx.at(
                elem,
                f"algebraic loop through direct feedthrough: {path}; this connection carries {kind} values "
                "and the master solves loops of Real and Float32 signals only: break it with a "
                "component whose output does not depend directly on its inputs",
            )
            break
