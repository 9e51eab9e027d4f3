"""Algebraic loops: cycles in which every hop is without delay.

Nodes are ports "component.variable".  Edges: each connection (output -> input, no delay
in the master) and, inside an FMU, each input -> output it feeds through directly
(ModelStructure/Outputs dependencies; no dependencies attribute means all inputs).
A strongly connected component with more than one port holds a loop.
"""

from __future__ import annotations

from lxml import etree

from .context import Context

Port = tuple[str, str]


def graph(
    ctx: Context, connections: list[tuple[tuple[str, str, str, str], etree._Element]]
) -> dict[Port, list[Port]]:
    """Adjacency lists of the port graph."""
    edges: dict[Port, list[Port]] = {}
    for (se, sc, ee, ec), _ in connections:
        edges.setdefault((se, sc), []).append((ee, ec))
    for c in ctx.comps.values():
        if c.info is None:
            continue
        for output, inputs in sorted(c.info.feedthrough.items()):
            for inp in sorted(inputs):
                edges.setdefault((c.name, inp), []).append((c.name, output))
    return edges


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
    """One problem per algebraic loop, at the first connection on it."""
    edges = graph(ctx, connections)
    elems = {(key[0], key[1], key[2], key[3]): elem for key, elem in connections}
    for scc in strongly_connected(edges):
        if len(scc) < 2:
            continue
        cycle = cycle_in(scc, edges)
        hops = list(zip(cycle, cycle[1:], strict=False))
        links = [elems[(a[0], a[1], b[0], b[1])] for a, b in hops if (a[0], a[1], b[0], b[1]) in elems]
        where = min(links, key=lambda e: e.sourceline or 0)
        path = " -> ".join(f"{c}.{v}" for c, v in cycle)
        ctx.at(
            where,
            f"algebraic loop through direct feedthrough: {path}; break it with a component"
            " whose output does not depend directly on its inputs",
        )
