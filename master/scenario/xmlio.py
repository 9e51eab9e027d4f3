"""Reading XML safely and validating it against the SSP schemas of the file's version (1.0 or 2.0)
and ours."""

from __future__ import annotations

import functools
import io
import logging
import re
from pathlib import Path

import fmpy
from lxml import etree

from .problems import NS_MM, NS_SSC, NS_SSD, NS_SSM, NS_SSV, PREFIXES, Problems, qualified

log = logging.getLogger("master")

SCHEMAS = Path(__file__).resolve().parents[1] / "schemas"
OUR_SCHEMA = SCHEMAS / "multirate-settings.xsd"
# SSP major version -> its schemas.  SSP 2.0 keeps the SSP 1 namespaces and says "2.0" in the version
# attribute of each file; its schemas (the Modelica Association's, v2.0) accept 1.0 and 2.0 there.
SSP_SCHEMAS = {"1": Path(fmpy.__file__).parent / "ssp" / "schema", "2": SCHEMAS / "ssp2"}
VERSIONS = re.compile(r"\s*(1)[.][0-9]+(-.*)?\s*|\s*(2)[.]0\s*")  # as the schemas' version patterns


def ssp_major(root: etree._Element) -> str | None:
    """Which SSP schemas check a file ("1" or "2"), by its root's version attribute (none: "1",
    whose schema then says it is required); None for a version this master does not read."""
    text = root.get("version")
    if text is None:
        return "1"
    match = VERSIONS.fullmatch(text)
    return None if match is None else match.group(1) or match.group(3)


def _parser() -> etree.XMLParser:
    return etree.XMLParser(
        resolve_entities=False, no_network=True, huge_tree=False, remove_comments=True, remove_pis=True
    )


def parse(path: Path, shown: str, problems: Problems) -> etree._ElementTree | None:
    """Parse `path` without entities or network access; syntax errors become problems. A file
    that uses SSP's own prefixes (ssd, ssc, ssv, ssm, ssb) without declaring them is read with
    their SSP 1.0 namespaces, a warning per prefix (`undeclared_prefixes`)."""
    parser = _parser()
    try:
        tree = etree.parse(str(path), parser)
    except etree.XMLSyntaxError as err:
        before = len(problems)
        tree = undeclared_prefixes(path, shown, parser.error_log, problems)
        if tree is None and len(problems) == before:
            entry = err.error_log.last_error if err.error_log else None
            line = entry.line if entry is not None else err.lineno
            message = entry.message if entry is not None else str(err)
            problems.add(shown, line, "XML", f"not well-formed XML: {message}")
        if tree is None:
            return None
    except OSError as err:
        problems.add(shown, None, "file", f"cannot read: {err}")
        return None
    if tree.docinfo.doctype:  # entities would reach the schema check unexpanded
        problems.add(
            shown, 1, "XML", "a DOCTYPE (DTD, entity declarations) is not accepted in scenario files"
        )
        return None
    return tree


# The prefixes the SSP standard gives its namespaces: a file that uses one without declaring it
# means that namespace (as libcosim and ecos read it).
SSP_PREFIXES = {
    "ssd": NS_SSD,
    "ssc": NS_SSC,
    "ssv": NS_SSV,
    "ssm": NS_SSM,
    "ssb": "http://ssp-standard.org/SSP1/SystemStructureSignalDictionary",
}
_ROOT_TAG = re.compile(rb"<[^?!\s/>][^\s/>]*")  # the root element's start tag: <name
_UNDECLARED = re.compile(r"^Namespace prefix (\S+) on (\S+) is not defined")


def undeclared_prefixes(
    path: Path, shown: str, errors: etree._ListErrorLog, problems: Problems
) -> etree._ElementTree | None:
    """The tree of a file whose only fault (`errors`: its parser's log) is namespace prefixes it
    never declares, if they are all SSP's own (read with SSP's namespaces, a warning per prefix at
    its first use); otherwise None, with a problem per undeclared prefix that is not SSP's (file,
    line, prefix, what to declare), or none at all if the file has other faults too (the caller
    reports the syntax error)."""
    first: dict[str, tuple[int, str]] = {}  # prefix -> (line, element) of its first use
    for entry in errors:  # this parse's own errors (an exception's log may hold earlier ones too)
        m = _UNDECLARED.match(entry.message)
        if entry.type_name != "NS_ERR_UNDEFINED_NAMESPACE" or m is None:
            return None
        first.setdefault(m.group(1), (entry.line, f"{m.group(1)}:{m.group(2)}"))
    unknown = sorted(set(first) - set(SSP_PREFIXES))
    for prefix in unknown:
        line, element = first[prefix]
        problems.add(
            shown, line, element,
            f'namespace prefix "{prefix}" is not declared: declare it on the root element '
            f'(xmlns:{prefix}="its namespace URI")',
        )  # fmt: skip
    if unknown:
        return None
    # Parsed again, strictly, as if the root element declared them (lines stay where they were)
    text = path.read_bytes()
    root = _ROOT_TAG.search(text)
    if root is None:
        return None
    declared = "".join(f' xmlns:{p}="{SSP_PREFIXES[p]}"' for p in first).encode()
    parser = _parser()
    try:
        tree = etree.parse(io.BytesIO(text[: root.end()] + declared + text[root.end() :]), parser)
    except etree.XMLSyntaxError as err:  # faults of its own, which the undeclared prefixes hid
        entry = parser.error_log.last_error
        line, message = (entry.line, entry.message) if entry is not None else (err.lineno, str(err))
        problems.add(shown, line, "XML", f"not well-formed XML: {message}")
        return None
    for prefix, (line, element) in first.items():
        log.warning(
            '%s:%s: %s: namespace prefix "%s" is not declared; read as SSP\'s: declare '
            'xmlns:%s="%s" on the root element',
            shown, line, element, prefix, prefix, SSP_PREFIXES[prefix],
        )  # fmt: skip
    return tree


def _combined_schema(imports: dict[str, Path]) -> etree.XMLSchema:
    """One schema importing several, so that lax wildcards (annotations, inline
    parameter sets) are validated against every namespace we know."""
    lines = [f'<xs:import namespace="{ns}" schemaLocation="{p.as_uri()}"/>' for ns, p in imports.items()]
    wrapper = '<xs:schema xmlns:xs="http://www.w3.org/2001/XMLSchema">' + "".join(lines) + "</xs:schema>"
    return etree.XMLSchema(etree.fromstring(wrapper))


@functools.cache
def ssd_schema(major: str = "1") -> etree.XMLSchema:
    """SSP SystemStructureDescription + ParameterValues and ParameterMapping (inline sets and
    mappings) + our settings."""
    return _combined_schema(
        {
            NS_SSD: SSP_SCHEMAS[major] / "SystemStructureDescription.xsd",
            NS_SSV: SSP_SCHEMAS[major] / "SystemStructureParameterValues.xsd",
            NS_SSM: SSP_SCHEMAS[major] / "SystemStructureParameterMapping.xsd",
            NS_MM: OUR_SCHEMA,
        }
    )


def ssv_schema(tree: etree._ElementTree | None = None) -> etree.XMLSchema:
    """SSP SystemStructureParameterValues (.ssv files) of the version `tree` says (else 1.0; an
    unknown version then fails the 1.0 schema's version pattern)."""
    return _file_schema(NS_SSV, (ssp_major(tree.getroot()) if tree is not None else None) or "1")


def ssm_schema(tree: etree._ElementTree) -> etree.XMLSchema:
    """SSP SystemStructureParameterMapping (.ssm files) of the version `tree` says, as `ssv_schema`."""
    return _file_schema(NS_SSM, ssp_major(tree.getroot()) or "1")


FILE_SCHEMAS = {NS_SSV: "SystemStructureParameterValues.xsd", NS_SSM: "SystemStructureParameterMapping.xsd"}


@functools.cache
def _file_schema(ns: str, major: str) -> etree.XMLSchema:
    return _combined_schema({ns: SSP_SCHEMAS[major] / FILE_SCHEMAS[ns]})


_BRACED = re.compile(r"\{([^}]*)\}(\w+)")


def _readable(message: str) -> str:
    """libxml2 messages name elements '{namespace}Local'; use our short prefixes instead."""
    return _BRACED.sub(lambda m: f"{PREFIXES.get(m.group(1), m.group(1))}:{m.group(2)}", message)


def check_schema(tree: etree._ElementTree, schema: etree.XMLSchema, shown: str, problems: Problems) -> bool:
    """Validate `tree`; each schema error becomes a problem at its line.  True if valid."""
    if schema.validate(tree):
        return True
    for entry in schema.error_log:
        message = _readable(entry.message)
        element = "XML"
        match = re.match(r"Element '([^']+)'(?:, attribute '([^']+)')?: (.*)", message, re.S)
        if match:
            element = match.group(1)
            message = match.group(3)
            if match.group(2):
                message = f"attribute {match.group(2)}: {message}"
            named = _name_at(tree, entry.path)
            if named:
                element = f"{element} {named}"
        problems.add(shown, entry.line, element, f"schema violation: {message.strip()}")
    return False


def _name_at(tree: etree._ElementTree, path: str | None) -> str | None:
    """What names the element at a libxml2 error path: its name attribute, else that of its
    parent (`in ssv:Parameter "m"`)."""
    if not path:
        return None
    try:
        found = tree.xpath(path, namespaces=_nsmap(tree.getroot()))
    except etree.XPathError:
        return None
    if not found or not isinstance(found[0], etree._Element):
        return None
    elem = found[0]
    if elem.get("name") is not None:
        return f'"{elem.get("name")}"'
    up = elem.getparent()
    if up is not None and up.get("name") is not None:
        return f'in {qualified(up.tag)} "{up.get("name")}"'
    return None


def _nsmap(root: etree._Element) -> dict[str, str]:
    mapping: dict[str, str] = {}
    for elem in root.iter():
        if isinstance(elem.tag, str):
            for prefix, ns in elem.nsmap.items():
                if prefix:
                    mapping.setdefault(prefix, ns)
    return mapping


def tag(ns: str, local: str) -> str:
    """Clark notation '{ns}local' for lxml lookups."""
    return f"{{{ns}}}{local}"


__all__ = ["parse", "check_schema", "ssd_schema", "ssv_schema", "ssm_schema", "ssp_major", "tag", "qualified"]
