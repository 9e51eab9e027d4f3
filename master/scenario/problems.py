"""Problems found in a scenario, and how they name the place they come from."""

from __future__ import annotations

from dataclasses import dataclass

from lxml import etree

# Fixed prefixes for messages, whatever prefixes the file itself uses.
NS_SSD = "http://ssp-standard.org/SSP1/SystemStructureDescription"
NS_SSC = "http://ssp-standard.org/SSP1/SystemStructureCommon"
NS_SSV = "http://ssp-standard.org/SSP1/SystemStructureParameterValues"
NS_SSM = "http://ssp-standard.org/SSP1/SystemStructureParameterMapping"
NS_MM = "urn:org.multirate-master:settings:1"
PREFIXES = {NS_SSD: "ssd", NS_SSC: "ssc", NS_SSV: "ssv", NS_SSM: "ssm", NS_MM: "mm"}


@dataclass(frozen=True)
class Problem:
    """One thing wrong with a scenario: where (file, line, element) and what."""

    file: str
    line: int | None
    element: str
    message: str

    def __str__(self) -> str:
        where = self.file if self.line is None else f"{self.file}:{self.line}"
        return f"{where}: {self.element}: {self.message}"


class ScenarioError(Exception):
    """A scenario that cannot be run; `problems` lists every reason at once."""

    def __init__(self, problems: list[Problem]) -> None:
        self.problems = list(problems)
        super().__init__("\n".join(str(p) for p in self.problems))


def qualified(tag: str) -> str:
    """'{ns}Local' -> 'ssd:Local' with the fixed prefixes (unknown namespaces stay in braces)."""
    qname = etree.QName(tag)
    prefix = PREFIXES.get(qname.namespace or "")
    return f"{prefix}:{qname.localname}" if prefix else tag


def describe(elem: etree._Element) -> str:
    """A short name for an element that a reader can find in the file: tag plus what identifies it."""
    tag = qualified(elem.tag) if isinstance(elem.tag, str) else "comment"
    local = etree.QName(elem).localname if isinstance(elem.tag, str) else ""
    if tag.startswith("{") and elem.prefix:  # another tool's namespace: as the file writes it
        tag = f"{elem.prefix}:{local}"
    get = elem.get
    if local == "Connection" and get("startConnector") is not None:
        start = f"{get('startElement', '')}.{get('startConnector')}".lstrip(".")
        end = f"{get('endElement', '')}.{get('endConnector')}".lstrip(".")
        return f"{tag} {start} -> {end}"
    if local == "Connection" and get("endConnector") is not None:
        return f"{tag} {get('endElement')}.{get('endConnector')}"
    if local in ("Step", "Table") and get("component") is not None:
        return f"{tag} {get('component')}.{get('variable')}"
    if local == "Variable" and get("component") is not None:
        return f"{tag} {get('component')}.{get('name')}"
    if local == "Annotation" and get("type") is not None:
        return f'{tag} type="{get("type")}"'
    if get("name") is not None:
        return f'{tag} "{get("name")}"'
    return tag


class Problems:
    """Collects problems of one scenario in the order they are found."""

    def __init__(self) -> None:
        self.items: list[Problem] = []

    def add(self, file: str, line: int | None, element: str, message: str) -> None:
        self.items.append(Problem(file, line, element, message))

    def at(self, file: str, elem: etree._Element, message: str) -> None:
        """A problem located at an XML element of `file`."""
        self.add(file, elem.sourceline, describe(elem), message)

    def __len__(self) -> int:
        return len(self.items)
