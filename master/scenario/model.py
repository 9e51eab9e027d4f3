"""The parsed, validated scenario: immutable plain data handed to the planner.

Nothing here reads files or calls FMUs; `master.scenario.reader` builds these objects.
Times are exact rationals (fractions.Fraction) so that schedules never drift.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from enum import StrEnum
from fractions import Fraction
from pathlib import Path
from typing import Literal

Value = float | int | bool | str | bytes  # bytes: an FMI 3 Binary


@dataclass(frozen=True)
class Component:
    """One FMU instance of the scenario."""

    name: str
    fmu_path: Path  # resolved .fmu file (project FMUs already built)
    parameters: dict[str, Value] = field(default_factory=dict)  # variable name -> value
    step_ratio: int = 1  # k: the component's communication step is macro_step / k
    extrapolation_order: int = 0  # default order (0..3) of the polynomials on its inputs
    interpolate_inputs: bool = False  # hand polynomials to the FMU if it canInterpolateInputs
    group: str | None = None  # parallel backend: components sharing a group share a worker
    # run as a Model Exchange FMU that the master integrates (None: Co-Simulation, unless the FMU has
    # no Co-Simulation interface: then ModelExchange())
    model_exchange: ModelExchange | None = None
    # run as Scheduled Execution: the master activates its clocks' model partitions (master.clocks);
    # asked for (implementation="ScheduledExecution") or the FMU's only interface
    scheduled: bool = False


@dataclass(frozen=True)
class ModelExchange:
    """How the master integrates a Model Exchange component in each of its communication steps:
    `solver` (an item of master.solvers.SOLVERS) with steps of `internal_step` (s; None: one step
    per communication step), its inputs at every stage time from the extrapolation polynomials."""

    solver: str = "rk4"
    internal_step: Fraction | None = None

    def substeps(self, step: Fraction) -> int | None:
        """Internal steps in a communication step of `step` s; None where internal_step does not
        divide it."""
        if self.internal_step is None:
            return 1
        k = Fraction(step) / Fraction(self.internal_step)
        return int(k) if k.denominator == 1 and k >= 1 else None


# what a connection may do to the value it carries, by kind; the index is the kernel's code
# (kernel.h: MK_TRANSFORM_*, which master.runtime.native checks against these)
TRANSFORMATIONS = ("none", "linear", "map")


@dataclass(frozen=True)
class Transformation:
    """A connection's transformation of the coupled value, applied after extrapolating the source
    (SSP 1.0 section 5.3.3): "linear" gives factor * value + offset (an ssc:LinearTransformation
    with any unit conversion folded in before it), "map" the target of the `mapping` entry whose
    source equals the value (ssc:Boolean/Integer/EnumerationMappingTransformation; a value no entry
    names passes unchanged)."""

    kind: Literal["linear", "map"]
    factor: float = 1.0
    offset: float = 0.0
    mapping: tuple[tuple[float, float], ...] = ()  # (source value, target value); Booleans 0 / 1
    # the (output unit, input unit) that factor and offset convert between, or that the file asks
    # not to convert (suppressUnitConversion); None: the units agree or one end has none
    units: tuple[str, str] | None = None


@dataclass(frozen=True)
class Connection:
    """Output `start_connector` of `start_component` drives input `end_connector` of `end_component`."""

    start_component: str
    start_connector: str
    end_component: str
    end_connector: str
    extrapolation_order: int | None = None  # None: the consumer component's default
    transformation: Transformation | None = None


class Scheme(StrEnum):
    """Whose samples a component's inputs use within a macro step (the paper's parallel and
    sequential integration): every source's from the macro step's start, extrapolated (Jacobi), or,
    in a stepping order, those of sources earlier in it at the macro step's end, interpolated
    (Gauss-Seidel)."""

    JACOBI = "jacobi"
    GAUSS_SEIDEL = "gauss-seidel"


# how an algebraic loop is solved at a communication point; the index is the kernel's code
# (kernel.h: MK_LOOP_*, which master.runtime.native checks against these)
LOOP_METHODS = ("newton", "fixed-point")


@dataclass(frozen=True)
class LoopSolver:
    """How algebraic loops (outputs that depend directly on inputs around a cycle of components)
    are solved at each communication point: the loop's coupled signals are iterated (inputs set,
    outputs read; no step) until every one changes by at most tolerance * (1 + |value|), at most
    `max_iterations` times. "newton": Newton's method with the Jacobian from directional derivatives
    (finite differences where a member provides none), reused while it converges well; "fixed-point":
    Anderson-accelerated fixed-point iteration (no Jacobian)."""

    method: Literal["newton", "fixed-point"] = "newton"
    tolerance: float = 1e-10
    max_iterations: int = 100
    directional_derivatives: bool = True  # False: finite differences even where FMUs provide them


@dataclass(frozen=True)
class Iteration:
    """Iterated macro steps (strong coupling): each macro step repeated from saved FMU states with
    the input polynomials of the previous sweep's samples until every coupled signal changes by at
    most tolerance * (1 + |value|), at most `max_iterations` sweeps."""

    tolerance: float = 1e-8
    max_iterations: int = 20


@dataclass(frozen=True)
class Stimulus:
    """A signal on an input that no component drives.

    kind "step": value `values[i]` from `times[i]` on (before times[0]: the input's start value).
    kind "table": piecewise linear through (times, values), held constant outside.
    """

    component: str
    variable: str
    kind: Literal["step", "table"]
    times: tuple[float, ...]
    values: tuple[float, ...]


@dataclass(frozen=True)
class Scenario:
    path: Path  # the file it came from (.ssd or .ssp)
    name: str
    components: tuple[Component, ...]
    connections: tuple[Connection, ...]
    start_time: Fraction
    stop_time: Fraction
    macro_step: Fraction  # H
    coupling: Scheme = Scheme.JACOBI
    order: tuple[str, ...] = ()  # Gauss-Seidel: component names in stepping order
    stimuli: tuple[Stimulus, ...] = ()
    record: tuple[tuple[str, str], ...] = ()  # (component, variable); empty: all outputs
    record_interval: Fraction | None = None  # None: every macro step
    # a column per extrapolated connection: its latest coupling error (master.schedule.Plan.columns)
    record_coupling_errors: bool = False
    loops: LoopSolver = LoopSolver()  # how algebraic loops are solved
    iteration: Iteration | None = None  # None: each macro step stepped once (explicit coupling)
    # setting ("macro step", "stop time", "COMP communication step" ...) -> where its value came from
    origins: dict[str, str] = field(default_factory=dict, compare=False)

    def component(self, name: str) -> Component:
        for c in self.components:
            if c.name == name:
                return c
        raise KeyError(name)
