"""One case of a sweep, as a Dask task: the scenario with the case's values, run in isolation.

The run is `master.run`'s with the serial backend, so the FMUs step in a worker process of their
own: a crashing FMU ends that process, never the Dask worker, and the case comes back as failed
with the run's one-line message. The cases of one Dask worker share that process where they can
(master.backends.session: the FMUs loaded once, reset between cases). Nothing a case does raises
out of `run_case`.
"""

from __future__ import annotations

import dataclasses
import time
from dataclasses import dataclass

import numpy as np

from master.recorder import number_columns
from master.scenario.model import Scenario
from master.scenario.names import split
from master.sweeps.cases import Range
from master.sweeps.metrics import Metric

OK, FAILED, INVALID, LOST = "ok", "failed", "invalid", "lost"
FINISHED = (OK, FAILED, INVALID)  # a rerun skips these; a lost case (its worker died) runs again


@dataclass(frozen=True)
class CaseOptions:
    metrics: tuple[Metric, ...] = ()
    series: bool = False  # return the recorded rows too
    backend: str = "serial"
    step_timeout: float | None = None


def apply_case(sc: Scenario, ranges: list[Range], values: dict) -> Scenario:
    """The scenario with one case's values (checked against each variable's type and range)."""
    from master.scenario.values import check_range

    comps = {c.name: c for c in sc.components}
    stimuli = list(sc.stimuli)
    for r in ranges:
        comp, var = split(r.name, comps)  # bound: `cases.bind` checked the component
        value = check_range(r.var, values[r.name]) if r.var is not None else values[r.name]
        if r.stimulus:
            stimuli = [dataclasses.replace(s, values=(value,)) if (s.component, s.variable) == (comp, var)
                       else s for s in stimuli]  # fmt: skip
        else:
            c = comps[comp]
            comps[comp] = dataclasses.replace(c, parameters={**c.parameters, var: value})
    return dataclasses.replace(
        sc, components=tuple(comps[c.name] for c in sc.components), stimuli=tuple(stimuli)
    )


def run_case(sc: Scenario, ranges: list[Range], options: CaseOptions, values: dict) -> dict:
    """Run one case: {"status", "message", "wall_time" (s), "t_end" (s, last row), "columns":
    {column: (final, min, max)}, "metrics": {name: value}, "series": rows or None}."""
    from master.backends.component import SimulationError
    from master.backends.session import warm_run
    from master.scenario.values import BadValue

    t0 = time.perf_counter()
    status, message, data = OK, "", None
    try:
        scene = apply_case(sc, ranges, values)
        data = warm_run(scene, options.backend, options.step_timeout).data
    except BadValue as e:
        status, message = INVALID, str(e)
    except SimulationError as e:
        status, message = FAILED, str(e)
        result = getattr(e, "result", None)
        data = result.data if result is not None else None
    except Exception as e:  # an FMU that will not load, a plan it refuses: this case fails, not the sweep
        status, message = FAILED, f"{type(e).__name__}: {e}"
    out = {"status": status, "message": message, "wall_time": time.perf_counter() - t0}
    out.update(summarise(data, options.metrics))
    out["series"] = data if options.series and data is not None else None
    return out


def summarise(data: np.ndarray | None, metrics: tuple[Metric, ...]) -> dict:
    """Last time, final / min / max per recorded column and the metrics of one case's rows."""
    empty = data is None or len(data) == 0
    names = [] if data is None else number_columns(data)
    nan = float("nan")
    columns = {
        n: (nan, nan, nan) if empty else (float(data[n][-1]), float(np.min(data[n])), float(np.max(data[n])))
        for n in names
    }
    values = {m.name: nan if data is None else m(data) for m in metrics}
    return {"t_end": nan if empty else float(data["time"][-1]), "columns": columns, "metrics": values}
