"""Turning parameter values (.ssv entries and --set strings) into values of an FMU variable's type."""

from __future__ import annotations

import math

from master.description import FLOATS, INT_RANGES, Variable, element_names, hex_bytes, typed

from .model import Value

SETTABLE_CAUSALITIES = {"parameter", "structuralParameter", "input"}


class BadValue(Exception):
    """A value that does not fit the variable (message says why)."""


def settable(var: Variable, element: bool = False) -> str | None:
    """Why `var` cannot take a parameter binding, or None if it can.

    SSP 1.0 / FMI: parameters and inputs that are not constant and whose start is not calculated,
    and outputs with initial="exact" or "approx" (start values of states, such as a pressure
    that is both a state and an output; FMI lets them be set before initialisation). An FMI 3
    array takes values element by element (`element`: the binding names one, y[i,j]); SSP 1.0
    values are scalars, so the array as a whole takes none. Strings and Binaries are scalars only."""
    if var.shape and not element:
        first = element_names(var.name, var.shape)[0]
        return (
            f"it is an array ({typed(var.fmi_type, var.shape)}); array parameters are not supported as a "
            f"whole: bind its elements, such as {first}, one by one"
        )
    if element and var.kind in ("String", "Binary"):
        return f"arrays of {var.fmi_type} take no values"
    start_output = var.causality == "output" and var.initial in ("exact", "approx")
    if var.causality not in SETTABLE_CAUSALITIES and not start_output:
        return (
            f"it has causality {var.causality}; only parameters, inputs and outputs with"
            ' initial="exact" or "approx" take values'
        )
    if var.variability == "constant":
        return "it is a constant"
    if var.initial == "calculated":
        return "its start value is calculated"
    return None


def from_string(var: Variable, text: str) -> Value:
    """Convert a command-line string to `var`'s type (Enumeration: item name or number)."""
    kind = var.kind
    text = text.strip()
    if kind in FLOATS:
        try:
            value = float(text)
        except ValueError:
            raise BadValue(f'"{text}" is not a number ({var.name} is {var.fmi_type})') from None
        return check_range(var, value)
    if kind in INT_RANGES:
        try:
            return check_range(var, int(text))
        except ValueError:
            raise BadValue(f'"{text}" is not an integer ({var.name} is {var.fmi_type})') from None
    if kind == "Boolean":
        lowered = text.lower()
        if lowered in ("true", "1"):
            return True
        if lowered in ("false", "0"):
            return False
        raise BadValue(f'"{text}" is not a Boolean (true, false, 1, 0)')
    if kind == "Enumeration":
        return enumeration(var, text)
    if kind == "String":
        return text
    if kind == "Binary":
        return binary(var, text)
    raise BadValue(f"{var.name} has type {var.fmi_type}, which parameters cannot set")


def from_ssv(var: Variable, ssv_type: str, text: str, unit: str | None) -> Value:
    """Convert one ssv:Parameter value (already schema-valid for `ssv_type`) to `var`'s type."""
    kind = var.kind
    if ssv_type == "Real" and kind in FLOATS:
        if unit and var.unit and unit != var.unit:
            raise BadValue(f'unit mismatch: value in "{unit}", {var.name} is in "{var.unit}"')
        return check_range(var, float(text))
    if ssv_type == "Integer" and (kind in FLOATS or kind in INT_RANGES):
        number = int(text)
        return check_range(var, float(number) if kind in FLOATS else number)
    if ssv_type == "Integer" and kind == "Enumeration":
        return enumeration(var, text)
    if ssv_type == "Boolean" and kind == "Boolean":
        return text.strip() in ("true", "1")
    if ssv_type == "String" and kind == "String":
        return text
    if ssv_type == "Enumeration" and kind == "Enumeration":
        return enumeration(var, text)
    if ssv_type == "Binary" and kind == "Binary":  # mime-type not compared (SSP leaves that to users)
        return binary(var, text)
    raise BadValue(f"type mismatch: ssv:{ssv_type} value for {var.name}, which is {var.fmi_type}")


def enumeration(var: Variable, text: str) -> int:
    """An Enumeration value from an item name or its number."""
    names = dict(var.items)
    if text in names:
        return names[text]
    try:
        number = int(text)
    except ValueError:
        number = None
    if number is not None and (not names or number in names.values()):
        return number
    choices = ", ".join(f"{n}={v}" for n, v in var.items)
    raise BadValue(f'"{text}" is not an item of {var.name} ({choices})')


def binary(var: Variable, text: str) -> bytes:
    """A Binary value from hex digits (ssv:Binary's xs:hexBinary, or --set c.b=0a1b2c)."""
    try:
        return hex_bytes(text)
    except ValueError:
        raise BadValue(
            f'"{text}" is not hex digits ({var.name} is Binary: two digits a byte, such as 0a1b2c)'
        ) from None


def check_range(var: Variable, value: float | int) -> float | int:
    """`value` if it is finite and inside [min, max] of `var` (and of its integer type)."""
    if isinstance(value, float) and not math.isfinite(value):
        raise BadValue(f"{value} is not a finite number")
    low, high = INT_RANGES.get(var.kind, (-math.inf, math.inf))
    if var.min is not None:
        low = max(low, float(var.min))
    if var.max is not None:
        high = min(high, float(var.max))
    if not low <= value <= high:
        raise BadValue(f"{value} is outside the range [{_fmt(low)}, {_fmt(high)}] of {var.name}")
    return value


def _fmt(x: float) -> str:
    return f"{x:g}" if isinstance(x, float) else str(x)
