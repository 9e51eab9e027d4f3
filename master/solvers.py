"""The fixed-step solvers of the project's FMUs (fmus/solvers), by number and name.

The one table of them: the values of the FMUs' `solver` parameter (their Enumeration "Solver"),
which the C enumeration SolverKind in fmus/fmi/model.h must spell the same way (master.fmubuild
checks it before every build; the kernel, which links the same solvers for Model Exchange
components, reports SOLVER_COUNT to master.runtime.native), the methods a scenario names for a
Model Exchange component, and the names the evidence and tuning modules use.
"""

from __future__ import annotations

import re
from dataclasses import dataclass


@dataclass(frozen=True)
class Solver:
    number: int  # the `solver` parameter's value; in C the SolverKind value
    item: str  # the Enumeration item of the FMUs' Solver type; in C SOLVER_<ITEM>
    short: str  # in labels and result tables
    description: str

    @property
    def c_name(self) -> str:
        """Its enumerator in SolverKind (fmus/fmi/model.h)."""
        return f"SOLVER_{self.item.upper()}"


SOLVERS = (
    Solver(1, "euler", "euler", "explicit Euler"),
    Solver(2, "ab2", "ab2", "Adams-Bashforth 2"),
    Solver(3, "ab3", "ab3", "Adams-Bashforth 3"),
    Solver(4, "rk4", "rk4", "classical Runge-Kutta 4"),
    Solver(5, "semi_implicit_euler", "si-euler", "semi-implicit (linearly implicit) Euler"),
    Solver(6, "semi_implicit_midpoint", "si-midpoint", "semi-implicit midpoint"),
)
EULER, AB2, AB3, RK4, SI_EULER, SI_MIDPOINT = (s.number for s in SOLVERS)
SOLVER_NAMES = {s.number: s.short for s in SOLVERS}  # number -> its short name
NUMBERS = {s.item: s.number for s in SOLVERS}  # item (a Model Exchange component's solver) -> number
ITEMS = {s.number: s.item for s in SOLVERS}  # number -> item

_SOLVER_KIND = re.compile(r"typedef\s+enum\s*\{([^}]*)\}\s*SolverKind\s*;")
_ENUMERATOR = re.compile(r"\b(\w+)\s*=\s*(\d+)")


def c_mismatch(header: str) -> str | None:
    """How the C enumeration SolverKind in the text of model.h differs from `SOLVERS` (each
    enumerator SOLVER_<ITEM> = number); None where they agree."""
    block = _SOLVER_KIND.search(header)
    if block is None:
        return "no enumeration SolverKind"
    c = {name: int(number) for name, number in _ENUMERATOR.findall(block.group(1))}
    ours = {s.c_name: s.number for s in SOLVERS}
    if c == ours:
        return None
    shown = ", ".join(f"{k} = {v}" for k, v in sorted(c.items(), key=lambda kv: kv[1]))
    return f"SolverKind is {{{shown}}} but master/solvers.py has {len(SOLVERS)} solvers: " + ", ".join(
        f"{s.c_name} = {s.number}" for s in SOLVERS
    )
