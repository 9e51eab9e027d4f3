"""State shared by the passes that read one scenario."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

from lxml import etree

from master.description import Description, Variable, lookup

from . import names
from .fmuinfo import no_element
from .problems import Problems


@dataclass
class Comp:
    """A component as read so far: its element, its FMU (None if unreadable), its connectors."""

    name: str
    elem: etree._Element
    info: Description | None
    connectors: dict[str, etree._Element] = field(default_factory=dict)


@dataclass
class Context:
    problems: Problems
    shown: str  # how problems name the .ssd (inside an archive: "x.ssp!/SystemStructure.ssd")
    base: Path  # folder of the .ssd: relative sources resolve against it
    inside: Path | None  # unpacked archive: relative sources must stay inside it
    comps: dict[str, Comp] = field(default_factory=dict)
    # input (component, variable) -> the connection element driving it
    driven: dict[tuple[str, str], etree._Element] = field(default_factory=dict)
    # the inputs that connections lead to, also those with problems of their own (component, input)
    ends: set[tuple[str, str]] = field(default_factory=set)
    built: dict = field(default_factory=dict)  # project FMU name -> path or SourceError, this read

    def at(self, elem: etree._Element, message: str) -> None:
        """A problem at an element of the .ssd."""
        self.problems.at(self.shown, elem, message)

    def variable(self, comp: str, name: str, elem: etree._Element, what: str = "variable") -> Variable | None:
        """The FMU variable `comp`.`name`, or None after reporting an unknown component or variable.

        Silent (None) if the component exists but its FMU could not be read: that is reported once."""
        c = self.comps.get(comp)
        if c is None:
            self.at(elem, f'unknown component "{comp}"')
            return None
        if c.info is None:
            return None
        var = c.info.variables.get(name)
        if var is None:
            self.at(elem, f'unknown {what}: the FMU of {comp} ({c.info.path.name}) has no variable "{name}"')
        return var

    def element(self, comp: str, name: str, elem: etree._Element) -> tuple[Variable, int | None] | None:
        """As `variable`, where `name` may also be one element y[i,j] of an FMI 3 array y:
        (variable, its position among the array's values; None for the variable itself)."""
        c = self.comps.get(comp)
        if c is None or c.info is None or name in c.info.variables:
            var = self.variable(comp, name, elem)
            return None if var is None else (var, None)
        found = lookup(c.info.variables, name)
        if found is None:
            why = no_element(c.info.variables, name)
            if why:
                self.at(elem, f"unknown variable: {comp}.{why}")
            else:
                self.variable(comp, name, elem)
        return found

    def split_name(self, dotted: str) -> tuple[str, str] | None:
        """'component.variable' -> (component, variable), components by qualified name (`names`)."""
        return names.split(dotted, self.comps)
