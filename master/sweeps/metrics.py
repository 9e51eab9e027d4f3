"""`--metric NAME=EXPR`: a number computed from one case's recorded columns.

EXPR is arithmetic (+ - * / ** and parentheses, numbers) over the recorded columns, named as in
the results ("mass1.x", or col("any name") for names that are not dotted identifiers; "time" is the
time column), with element-wise functions (abs, sqrt, exp, log, sin, cos) and reductions of a
column to one number:

  max(x)  min(x)  mean(x)  rms(x)  std(x)  final(x)  first(x)  integral(x)  at(x, t)  time_of_max(x)

integral is the trapezoidal rule over time; at(x, t) interpolates x linearly at time t. The text is
parsed into a small tree of these operations (no Python eval); a name, function or construct not
listed is refused before the sweep starts. The value must be a single number.
"""

from __future__ import annotations

import ast
import math
import re
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from master.sweeps.cases import SweepError

_ELEMENTWISE: dict[str, Callable] = {"abs": np.abs, "sqrt": np.sqrt, "exp": np.exp, "log": np.log,
                                     "sin": np.sin, "cos": np.cos}  # fmt: skip
_REDUCTIONS: dict[str, Callable] = {
    "max": np.max,
    "min": np.min,
    "mean": np.mean,
    "std": np.std,
    "rms": lambda x: np.sqrt(np.mean(np.square(x))),
    "final": lambda x: x[-1],
    "first": lambda x: x[0],
}
_BINARY: dict[type, Callable] = {ast.Add: np.add, ast.Sub: np.subtract, ast.Mult: np.multiply,
                                 ast.Div: np.divide, ast.Pow: np.power}  # fmt: skip
_NAME = re.compile(r"[A-Za-z_]\w*$")


@dataclass(frozen=True)
class Metric:
    name: str
    text: str
    tree: ast.expr

    def __call__(self, data: np.ndarray) -> float:
        """The metric of one case (a structured array with "time" and the recorded columns);
        NaN when there are no rows or the arithmetic has no value (0/0, log of a negative)."""
        if len(data) == 0:
            return math.nan
        with np.errstate(all="ignore"):
            value = _eval(self.tree, data)
        return float(value)


def parse_metric(text: str, columns: list[str]) -> Metric:
    """A metric from "NAME=EXPR", checked against the recorded columns."""
    name, eq, expr = text.partition("=")
    name = name.strip()
    if not eq or not _NAME.match(name):
        raise SweepError(f"--metric {text}: expected NAME=EXPR with NAME a plain name (letters, digits, _)")
    try:
        tree = ast.parse(expr.strip(), mode="eval").body
    except SyntaxError as e:
        raise SweepError(f"--metric {text}: not an expression ({e.msg})") from None
    problem = _check(tree, set(columns), scalar=True)
    if problem:
        raise SweepError(f"--metric {text}: {problem}")
    return Metric(name, expr.strip(), tree)


def _column(node: ast.expr) -> str | None:
    """The column a name node stands for: mass1.x (an attribute chain), time, or col("...")."""
    if isinstance(node, ast.Name):
        return node.id
    if isinstance(node, ast.Attribute):
        inner = _column(node.value)
        return None if inner is None else f"{inner}.{node.attr}"
    if isinstance(node, ast.Call) and isinstance(node.func, ast.Name) and node.func.id == "col":
        if (
            len(node.args) == 1
            and isinstance(node.args[0], ast.Constant)
            and isinstance(node.args[0].value, str)
        ):
            return node.args[0].value
    return None


def _check(node: ast.expr, columns: set[str], scalar: bool) -> str | None:
    """Why the expression is not allowed (None: it is); `scalar`: it must give one number."""
    column = _column(node)
    if column is not None:
        if column not in columns:
            return f"no recorded column {column!r} (recorded: {', '.join(sorted(columns))})"
        return (
            "a column is a time series: reduce it to a number, e.g. final(...) or max(...)"
            if scalar
            else None
        )
    if isinstance(node, ast.Constant):
        return (
            None
            if isinstance(node.value, int | float) and not isinstance(node.value, bool)
            else (f"{node.value!r} is not a number")
        )
    if isinstance(node, ast.UnaryOp) and isinstance(node.op, ast.USub | ast.UAdd):
        return _check(node.operand, columns, scalar)
    if isinstance(node, ast.BinOp) and type(node.op) in _BINARY:
        return _check(node.left, columns, scalar) or _check(node.right, columns, scalar)
    if isinstance(node, ast.Call) and isinstance(node.func, ast.Name) and not node.keywords:
        f, args = node.func.id, node.args
        if f in _ELEMENTWISE and len(args) == 1:
            return _check(args[0], columns, scalar)
        if f in _REDUCTIONS or f in ("integral", "time_of_max"):
            return _arity(f, args, 1) or _check(args[0], columns, scalar=False)
        if f == "at":
            return _arity(f, args, 2) or _check(args[0], columns, False) or _check(args[1], columns, True)
        known = sorted([*_ELEMENTWISE, *_REDUCTIONS, "integral", "time_of_max", "at", "col"])
        return f"unknown function {f}(); known: {', '.join(known)}"
    return f"{ast.unparse(node)!r} is not allowed (numbers, columns, + - * / **, and the listed functions)"


def _arity(f: str, args: list[ast.expr], n: int) -> str | None:
    return None if len(args) == n else f"{f}() takes {n} argument{'s' if n > 1 else ''}"


def _eval(node: ast.expr, data: np.ndarray):
    column = _column(node)
    if column is not None:
        return np.asarray(data[column], dtype=float)
    if isinstance(node, ast.Constant):
        return float(node.value)
    if isinstance(node, ast.UnaryOp):
        value = _eval(node.operand, data)
        return -value if isinstance(node.op, ast.USub) else value
    if isinstance(node, ast.BinOp):
        return _BINARY[type(node.op)](_eval(node.left, data), _eval(node.right, data))
    assert isinstance(node, ast.Call) and isinstance(node.func, ast.Name)  # _check allowed nothing else
    f, args = node.func.id, [_eval(a, data) for a in node.args]
    if f in _ELEMENTWISE:
        return _ELEMENTWISE[f](args[0])
    x = np.broadcast_to(args[0], data["time"].shape)
    if f in _REDUCTIONS:
        return _REDUCTIONS[f](x)
    t = np.asarray(data["time"], dtype=float)
    if f == "integral":
        return float(np.sum((x[1:] + x[:-1]) * np.diff(t)) / 2)
    if f == "time_of_max":
        return t[int(np.argmax(x))]
    return np.interp(args[1], t, x)  # at(x, t)


def unit_of(metric: Metric, units: dict[str, str | None]) -> str | None:
    """The metric's unit where its expression shows it (units: each column's, None for none): a
    column's through abs, a sign, a reduction or at(), times or over a number; s for
    time_of_max; the column's times s for an integral; a sum or difference of terms of one unit.
    None where a term has none or the expression does not say (a product of two columns, sqrt)."""
    return _unit(metric.tree, {**units, "time": "s"})


def _unit(node: ast.expr, units: dict[str, str | None]) -> str | None:
    column = _column(node)
    if column is not None:
        return units.get(column)
    if isinstance(node, ast.UnaryOp):
        return _unit(node.operand, units)
    if isinstance(node, ast.BinOp):
        left, right = _unit(node.left, units), _unit(node.right, units)
        if isinstance(node.op, ast.Add | ast.Sub):
            return left if left == right else None
        if isinstance(node.op, ast.Mult) and _number(node.left):
            return right
        if isinstance(node.op, ast.Mult | ast.Div) and _number(node.right):
            return left
        return None
    if isinstance(node, ast.Call) and isinstance(node.func, ast.Name):
        f = node.func.id
        if f == "time_of_max":
            return "s"
        inner = _unit(node.args[0], units) if node.args else None
        if f == "integral":
            return f"{inner}.s" if inner else None
        if f in _REDUCTIONS or f in ("abs", "at"):
            return inner
    return None


def _number(node: ast.expr) -> bool:
    """Whether the node is a number (with or without a sign)."""
    if isinstance(node, ast.UnaryOp):
        return _number(node.operand)
    return isinstance(node, ast.Constant)
