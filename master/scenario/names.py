"""How components of nested systems are named, and how "component.variable" is split.

A component inside system `sub` is `sub.comp`, deeper `sub.inner.comp`; the top system's own
components keep their names.  An element name that holds a dot or starts with a single quote is
written in single quotes, `'a.b'`, with a quote or backslash inside escaped by a backslash (the
quoting of FMI's structured names), so that `'a.b'.c` (component c of system "a.b") and `a.b.c`
(component c of system b of system a) stay apart.  Names with spaces are written as they are.
Variable names are the FMU's own and never quoted.
"""

from __future__ import annotations

from collections.abc import Iterable


def part(name: str) -> str:
    """One element name as it appears in a qualified name."""
    if "." not in name and not name.startswith("'"):
        return name
    return "'" + name.replace("\\", "\\\\").replace("'", "\\'") + "'"


def join(prefix: str, name: str) -> str:
    """The qualified name of element `name` inside the system whose qualified name is `prefix`
    ("" for the top system)."""
    return f"{prefix}.{part(name)}" if prefix else part(name)


def split(dotted: str, components: Iterable[str]) -> tuple[str, str] | None:
    """'component.variable' -> (component, variable), with the component one of `components`
    (qualified names); None if `dotted` starts with none of them and a dot.  Qualified names are
    never a prefix of one another up to a dot (only systems hold elements), so the match is unique;
    the longest one is taken all the same."""
    best = None
    for name in components:
        if dotted.startswith(name + ".") and (best is None or len(name) > len(best)):
            best = name
    return (best, dotted[len(best) + 1 :]) if best is not None else None
