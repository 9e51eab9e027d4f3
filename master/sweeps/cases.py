"""The cases of a sweep: `--vary` ranges, the points drawn from them, and the keys that name them.

A range "COMP.VAR=START:STOP:N" gives N evenly spaced values from START to STOP, both included
(grid); for lhs and sobol, "COMP.VAR=START:STOP" is the side of the box that `samples` points
are drawn in (scipy.stats.qmc, seeded). Each case is one dict "COMP.VAR" -> value.
"""

from __future__ import annotations

import dataclasses
import hashlib
import inspect
import itertools
import json
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from master.description import FLOATS, NUMERIC, Variable
from master.scenario.fmuinfo import read as read_fmu
from master.scenario.model import Scenario
from master.scenario.names import split

METHODS = ("grid", "lhs", "sobol")


class SweepError(ValueError):
    """A sweep that cannot start: a bad --vary, --metric or option (message says which)."""


@dataclass(frozen=True)
class Range:
    """One varied variable: "component.variable", its bounds and, for a grid, its count."""

    name: str
    start: float
    stop: float
    count: int | None  # grid points; None for lhs/sobol
    integer: bool = False  # an integer variable: drawn values are rounded
    stimulus: bool = False  # an input driven by a one-point step stimulus: the value is its height
    var: Variable | None = None  # the FMU's variable (bound by `bind`): each case's value is checked by it

    def grid(self) -> list[float | int]:
        values = np.linspace(self.start, self.stop, self.count or 1).tolist()
        if self.integer:
            if any(v != round(v) for v in values):
                raise SweepError(f"--vary {self.name}: an integer variable; {self._spec()} gives fractions")
            return [int(round(v)) for v in values]
        return values

    def scale(self, unit: np.ndarray) -> list[float | int]:
        """Points of [0, 1) mapped onto [start, stop] (rounded for an integer variable)."""
        values = self.start + unit * (self.stop - self.start)
        return [int(round(v)) for v in values] if self.integer else values.tolist()

    def _spec(self) -> str:
        return f"{self.start:g}:{self.stop:g}:{self.count}"


def parse_vary(text: str, method: str) -> Range:
    """ "COMP.VAR=START:STOP:N" (grid) or "COMP.VAR=START:STOP" (lhs, sobol)."""
    name, eq, spec = text.partition("=")
    name = name.strip()
    comp, _, var = name.partition(".")
    if not eq or not comp or not var:
        raise SweepError(f"--vary {text}: expected COMP.VAR=START:STOP:N")
    parts = spec.split(":")
    want = 3 if method == "grid" else 2
    if len(parts) != want:
        form = (
            "START:STOP:N" if method == "grid" else f"START:STOP (with --method {method}, --samples sets N)"
        )
        raise SweepError(f"--vary {text}: expected {name}={form}")
    try:
        start, stop = float(parts[0]), float(parts[1])
        count = int(parts[2]) if method == "grid" else None
    except ValueError:
        raise SweepError(f"--vary {text}: START and STOP must be numbers, N a whole number") from None
    if not (math.isfinite(start) and math.isfinite(stop)):
        raise SweepError(f"--vary {text}: START and STOP must be finite")
    if count is not None and count < 1:
        raise SweepError(f"--vary {text}: N must be at least 1")
    return Range(name, start, stop, count)


def bind(ranges: list[Range], sc: Scenario) -> list[Range]:
    """The ranges checked against the scenario's FMUs: each names, once, a settable numeric
    variable of a component (a parameter or start value), or an input driven by a one-point step
    stimulus (its height is varied)."""
    comps = {c.name: c for c in sc.components}
    seen: set[str] = set()
    bound = []
    for r in ranges:
        comp, var = split(r.name, comps) or r.name.partition(".")[::2]  # nested: "sub.comp.var"
        if comp not in comps:
            raise SweepError(f"--vary {r.name}: no component {comp!r} (components: {', '.join(comps)})")
        if r.name in seen:
            raise SweepError(f"--vary {r.name}: varied twice")
        seen.add(r.name)
        v = read_fmu(Path(comps[comp].fmu_path)).variables.get(var)
        if v is None:
            raise SweepError(f"--vary {r.name}: component {comp} has no variable {var!r}")
        why = _why_not(v)
        if why:
            raise SweepError(f"--vary {r.name}: {why}")
        stimuli = [s for s in sc.stimuli if s.component == comp and s.variable == var]
        if stimuli and (stimuli[0].kind != "step" or len(stimuli[0].times) != 1):
            raise SweepError(
                f"--vary {r.name}: a {stimuli[0].kind} stimulus of {len(stimuli[0].times)} points drives it; "
                "only a one-point step (a constant from a time on) can be varied, by its height"
            )
        bound.append(dataclasses.replace(r, integer=v.kind not in FLOATS, stimulus=bool(stimuli), var=v))
    return bound


def _why_not(v: Variable) -> str | None:
    from master.scenario.values import settable

    if v.kind not in NUMERIC:
        return f"it is {v.fmi_type}; only numbers can be varied"
    return settable(v)


def points(ranges: list[Range], method: str, samples: int | None, seed: int | None) -> list[dict]:
    """The cases: grid = cartesian product (first range outermost); lhs/sobol = `samples` points."""
    if method not in METHODS:
        raise SweepError(f"--method {method}: choose one of {', '.join(METHODS)}")
    if not ranges:
        raise SweepError("nothing to vary: give at least one --vary COMP.VAR=START:STOP:N")
    names = [r.name for r in ranges]
    if method == "grid":
        if samples is not None:
            raise SweepError("--samples is for --method lhs or sobol; a grid has N points per --vary")
        return [
            dict(zip(names, combo, strict=True)) for combo in itertools.product(*(r.grid() for r in ranges))
        ]
    if not samples or samples < 1:
        raise SweepError(f"--method {method} needs --samples N (N >= 1)")
    unit = _draw(method, len(ranges), samples, seed)
    columns = [r.scale(unit[:, i]) for i, r in enumerate(ranges)]
    return [dict(zip(names, row, strict=True)) for row in zip(*columns, strict=True)]


def _draw(method: str, d: int, n: int, seed: int | None) -> np.ndarray:
    """n points of the unit cube [0, 1)^d; the same seed gives the same points."""
    from scipy.stats import qmc

    engine = qmc.LatinHypercube if method == "lhs" else qmc.Sobol
    rng = np.random.default_rng(seed)
    # scipy >= 1.15 names the generator `rng`, older versions `seed`: the same generator either way
    keyword = "rng" if "rng" in inspect.signature(engine).parameters else "seed"
    sampler = engine(d, **{keyword: rng})
    if method == "sobol":
        m = max(0, math.ceil(math.log2(n)))  # Sobol' points balance in powers of two: draw 2^m, keep n
        return sampler.random_base2(m)[:n]
    return sampler.random(n)


def scenario_hash(sc: Scenario) -> str:
    """Content hash of what a run of `sc` simulates: its settings, parameter values, stimuli and
    the bytes of its FMUs (not where the files are, nor how the XML is laid out)."""
    comps = tuple(dataclasses.replace(c, fmu_path=Path(_file_hash(Path(c.fmu_path)))) for c in sc.components)
    text = repr(dataclasses.replace(sc, path=Path(sc.name), components=comps))
    return hashlib.sha256(text.encode()).hexdigest()[:16]


def _file_hash(path: Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def case_key(scene_hash: str, values: dict) -> str:
    """The name of one case: the scenario's content hash and the case's exact values."""
    exact = {k: float(v).hex() if isinstance(v, float) else v for k, v in sorted(values.items())}
    return hashlib.sha256(json.dumps([scene_hash, exact]).encode()).hexdigest()[:20]
