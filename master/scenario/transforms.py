"""Connection transformations (SSP 1.0 section 5.3.3): an ssd:Connection's ssc:LinearTransformation,
ssc:BooleanMappingTransformation, ssc:IntegerMappingTransformation or
ssc:EnumerationMappingTransformation, and the conversion between different but compatible units
that the file's unit definitions (ssd:Units) allow, read into one `model.Transformation`; and the
rules a connection's transformation keeps, for files and for scenarios built in Python alike.

Unit conversion comes first and the linear transformation after it, as SSP says (the source value
"is already converted to the target unit"); suppressUnitConversion="true" leaves only the linear
transformation. A unit's value v stands for factor * v + offset in its SI base units (ssc:BaseUnit).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from lxml import etree

from master.description import FLOATS, Variable

from .context import Context
from .fmuinfo import stimulus_value_problem
from .model import Transformation
from .problems import NS_SSC, NS_SSD
from .xmlio import tag

BASE_UNITS = ("kg", "m", "s", "A", "K", "mol", "cd", "rad")  # ssc:BaseUnit's exponents
INTEGERS = {"Int8", "UInt8", "Int16", "UInt16", "Int32", "UInt32", "Int64", "UInt64"}
# ssc element -> (the value types (description.type_class) of the connections it may transform, their name)
ELEMENTS = {
    "LinearTransformation": (FLOATS, "Real"),
    "BooleanMappingTransformation": ({"Boolean"}, "Boolean"),
    "IntegerMappingTransformation": (INTEGERS | {"Enumeration"}, "Integer and Enumeration"),
    "EnumerationMappingTransformation": ({"Enumeration"}, "Enumeration"),
}
# the same for each kind of model.Transformation (a map: any held numeric kind)
KINDS = {
    "linear": (FLOATS, "Real"),
    "map": (INTEGERS | {"Enumeration", "Boolean"}, "Integer, Enumeration and Boolean"),
}


@dataclass(frozen=True)
class Unit:
    """An ssc:Unit: the exponents of its SI base units, and its factor and offset towards them."""

    exponents: tuple[int, ...]
    factor: float
    offset: float


def units(ctx: Context, root: etree._Element) -> dict[str, Unit]:
    """The unit definitions of a scenario file (ssd:Units), by name."""
    found: dict[str, Unit] = {}
    for elem in root.findall(f"{tag(NS_SSD, 'Units')}/{tag(NS_SSC, 'Unit')}"):
        base = elem.find(tag(NS_SSC, "BaseUnit"))
        name = elem.get("name")
        if base is None or name is None:
            continue  # the schema check has said so
        try:
            exponents = tuple(int(base.get(b, "0")) for b in BASE_UNITS)
            factor, offset = float(base.get("factor", "1")), float(base.get("offset", "0"))
        except ValueError:
            continue  # the schema check has said so
        if not (math.isfinite(factor) and math.isfinite(offset)) or factor == 0:
            ctx.at(base, f'unit "{name}": factor and offset must be finite numbers, the factor not 0')
            continue
        found[name] = Unit(exponents, factor, offset)
    return found


def read(
    ctx: Context,
    elem: etree._Element,
    ends: tuple[str, str],
    out: Variable,
    inp: Variable,
    unit_of: tuple[str | None, str | None],
    defined: dict[str, Unit],
    in_version: str,
) -> tuple[bool, Transformation | None]:
    """The transformation of connection `elem` between `out` and `inp` (named `ends`; `inp` of an
    FMU of FMI version `in_version`), with the units `unit_of` of its two ends: (False, None) after
    reporting a problem, else (True, the transformation or None where the value passes unchanged)."""
    chosen = [c for c in elem if etree.QName(c).namespace == NS_SSC and etree.QName(c).localname in ELEMENTS]
    given = chosen[0] if chosen else None
    suppress = elem.get("suppressUnitConversion", "false").strip() in ("true", "1")
    if given is not None:
        local = etree.QName(given).localname
        allowed, named = ELEMENTS[local]
        wrong = [
            f"{n} is {v.fmi_type}" for n, v in zip(ends, (out, inp), strict=True) if v.kind not in allowed
        ]
        if wrong:
            ctx.at(given, f"transforms {named} values only: {', '.join(wrong)}")
            return False, None
        if local != "LinearTransformation":
            mapping = _mapping(ctx, given, local, ends, out, inp)
            if mapping is None:
                return False, None
            t = Transformation("map", mapping=mapping)
            wrong = problem(t, ends, out, inp, in_version)
            if wrong:
                ctx.at(given, wrong)
            return not wrong, t if not wrong else None
    factor, offset = 1.0, 0.0
    if given is not None:
        try:
            factor, offset = float(given.get("factor", "1")), float(given.get("offset", "0"))
        except ValueError:
            return False, None  # the schema check has said so
        if not (math.isfinite(factor) and math.isfinite(offset)):
            ctx.at(given, "factor and offset must be finite numbers")
            return False, None
    a, b = unit_of
    if a is None or b is None or a == b:
        return True, Transformation("linear", factor, offset) if given is not None else None
    if suppress:
        return True, Transformation("linear", factor, offset, units=(a, b))
    missing = [u for u in (a, b) if u not in defined]
    if missing:
        names = " and ".join(f'"{u}"' for u in missing)
        ctx.at(elem, f'unit mismatch: {ends[0]} is in "{a}", {ends[1]} in "{b}"; define {names} in the '
               'ssd:Units of the file (ssc:Unit with its ssc:BaseUnit) to convert between them')  # fmt: skip
        return False, None
    ua, ub = defined[a], defined[b]
    if ua.exponents != ub.exponents:
        ctx.at(elem, f'unit mismatch: {ends[0]} is in "{a}", {ends[1]} in "{b}": they measure different '
               f"quantities ({_dimension(ua)} and {_dimension(ub)}), no conversion exists")  # fmt: skip
        return False, None
    # v in a is ua.factor v + ua.offset in SI, which is (that - ub.offset) / ub.factor in b
    scale = ua.factor / ub.factor
    shift = (ua.offset - ub.offset) / ub.factor
    return True, Transformation("linear", factor * scale, factor * shift + offset, units=(a, b))


def _dimension(u: Unit) -> str:
    parts = [f"{b}^{e}" if e != 1 else b for b, e in zip(BASE_UNITS, u.exponents, strict=True) if e]
    return " ".join(parts) or "dimensionless"


def _mapping(
    ctx: Context, given: etree._Element, local: str, ends: tuple[str, str], out: Variable, inp: Variable
) -> tuple[tuple[float, float], ...] | None:
    """The (source, target) values of a mapping transformation's ssc:MapEntry elements."""
    pairs: list[tuple[float, float]] = []
    for entry in given.findall(tag(NS_SSC, "MapEntry")):
        values = []
        for attr, var, end in (("source", out, ends[0]), ("target", inp, ends[1])):
            text = (entry.get(attr) or "").strip()
            value = _entry_value(local, text, var)
            if value is None:
                what = f"an item of {end}" if local.startswith("Enumeration") else "a value"
                ctx.at(entry, f'{attr} "{text}" is not {what}')
                return None
            values.append(value)
        pairs.append((values[0], values[1]))
    sources = [s for s, _ in pairs]
    if len(set(sources)) != len(sources):
        ctx.at(given, "a source value is mapped twice")
        return None
    return tuple(pairs)


def _entry_value(local: str, text: str, var: Variable) -> float | None:
    if local == "BooleanMappingTransformation":
        return {"true": 1.0, "1": 1.0, "false": 0.0, "0": 0.0}.get(text)
    if local == "EnumerationMappingTransformation":
        return next((float(v) for n, v in var.items if n == text), None)
    try:
        return float(int(text))
    except ValueError:
        return None


def problem(
    t: Transformation, ends: tuple[str, str], out: Variable, inp: Variable, in_version: str
) -> str | None:
    """What is wrong with transformation `t` on the connection `ends` from `out` to `inp` (of an
    FMU of FMI version `in_version`); None: it can run. A scenario built in Python keeps these rules
    as a file does."""
    if t.kind not in KINDS:
        return f'transformation kind "{t.kind}": expected "linear" or "map"'
    allowed, named = KINDS[t.kind]
    wrong = [f"{n} is {v.fmi_type}" for n, v in zip(ends, (out, inp), strict=True) if v.kind not in allowed]
    if wrong:
        return f"a {t.kind} transformation transforms {named} values only: {', '.join(wrong)}"
    numbers = (t.factor, t.offset, *(x for pair in t.mapping for x in pair))
    if not all(isinstance(x, int | float) and math.isfinite(x) for x in numbers):
        return "a transformation's factor, offset and mapped values must be finite numbers"
    for _, target in t.mapping:  # the kernel sets them as the input's type
        wrong = stimulus_value_problem(inp.fmi_type, in_version, target)
        if wrong:
            return f"mapped value {target:g} is {wrong} ({ends[1]} is {inp.fmi_type})"
    return None


def unit_problem(ends: tuple[str, str], out: Variable, inp: Variable, t: Transformation | None) -> str | None:
    """A unit mismatch between the ends of a connection that its transformation does not convert
    (None: the units agree, one end has none, or `t` converts between them)."""
    if not (out.unit and inp.unit) or out.unit == inp.unit:
        return None
    if t is not None and t.units == (out.unit, inp.unit):
        return None
    return (
        f'unit mismatch: {ends[0]} is in "{out.unit}", {ends[1]} in "{inp.unit}" (a file converts '
        "between units its ssd:Units defines with the same base units)"
    )


def applied(t: Transformation, value: float) -> float:
    """`value` transformed by `t`, as the kernel transforms a coupled value (a map passes a value
    that no entry names unchanged); parameter mappings use it for the value they bind."""
    if t.kind == "map":
        return next((target for source, target in t.mapping if source == value), value)
    return t.factor * value + t.offset
