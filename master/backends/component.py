"""What every backend needs to know of one component: how it is opened, which outputs it keeps
in its history and how long that history is, which samples are read, and how a run fails.
Times are in seconds.
"""

from __future__ import annotations

import tempfile
from pathlib import Path

from master.description import element_names, lookup
from master.fmu import Fmu, safe_extract
from master.scenario.fmuinfo import TEXTS
from master.scenario.model import Component, Scenario
from master.schedule import KINDS, Plan, value_kind


class SimulationError(Exception):
    """A run stopped: names the component, the variable or cause, and the simulation time (s)."""

    def __init__(self, message: str, component: str, time: float, variable: str | None = None):
        super().__init__(message)
        self.component = component
        self.variable = variable
        self.time = time


# An output beyond this many times its start magnitude (at least 1) has diverged.
GROWTH_LIMIT = 1e6

UNSTABLE_HINT = (
    "hint: the coupled system is unstable at these settings; try a smaller macro step, "
    "a semi-implicit solver in the stiff component, or a lower extrapolation order"
)


def history_capacity(plan: Plan, name: str) -> int:
    """Samples in the ring of `name`'s outputs: k + p + 2, p the highest order of its links.

    In macro step n the component writes samples n k+1 .. (n+1) k while a consumer of order p
    may still read n k-p .. n k (in another process, at the same time: the kernel lets a producer
    write macro step n once every consumer has taken its inputs of macro step n - 1), so k + p + 1
    samples must coexist; the ring keeps one more. p counts links into `name` as well as out of
    it, which only enlarges the ring.
    """
    pc = plan.component(name)
    p = max((lk.order for lk in plan.links if name in (lk.source, lk.consumer)), default=0)
    return pc.step_ratio + p + 2


def output_names(plan: Plan, name: str, variables: dict) -> list[str]:
    """The history columns of `name`, read at each communication point: the coupled Real
    outputs, the recorded Real ones, then the coupled outputs of the other kinds, kind by kind
    (schedule.KINDS: Integer, Boolean, then the FMI 3 ones read through their own calls;
    kernel.h's order). An FMI 3 array is a column per element (y[1], y[2], ...), all of them:
    one call reads it whole; a recorded array of any kind is read into the history too. String
    and Binary outputs have a ring of their own (`string_output_names`)."""
    out: list[str] = []
    recorded = [lookup(variables, v)[0] for c, v in plan.record if c == name]
    for kind in KINDS:
        for lk in plan.links:
            if lk.source == name and lk.kind == kind:
                out.extend(o for o in lk.outputs if o not in out)
        for v in recorded:  # (arrays are FMI 3 only)
            if (value_kind(v, "3.0") == kind) if v.shape else (kind == "Real" and _float64(v)):
                out.extend(e for e in element_names(v.name, v.shape) if e not in out)
    return out


def string_output_names(plan: Plan, name: str) -> list[str]:
    """The coupled String then Binary outputs of `name`, read into its text ring (kernel.h) at each
    communication point whose samples are used, in link order."""
    out: list[str] = []
    for kind in TEXTS:
        for lk in plan.links:
            if lk.source == name and lk.kind == kind:
                out.extend(o for o in lk.outputs if o not in out)
    return out


def _float64(v) -> bool:
    """A Real (FMI 2) or Float64 (FMI 3): read with the history's vector calls (a Float32 is read
    through its own call, as a recorded scalar)."""
    return v.type == "Real" and v.fmi_type != "Float32"


def samples_read(plan: Plan, name: str) -> list[bool]:
    """reads[m]: whether the samples after step m of a macro step of `name` are ever used.

    A consumer's polynomials use the source samples of its windows (`Link.window`, start-up and
    relaxed ones included), the recorder the samples at macro step ends. Outputs are read (and
    checked for divergence) only where used: a source stepping k times per macro step for an
    order-0 consumer is read once, not k times.
    """
    k = plan.component(name).step_ratio
    used = {0}
    for lk in plan.links:
        if lk.source != name:
            continue
        for n in range(lk.order + 3):  # past start-up, windows repeat every macro step
            for m in range(lk.k_consumer):
                for relaxed in (False, True):
                    j_end = lk.window(n, n * lk.k_consumer + m, relaxed)[0]
                    used.update((j_end - i) % k for i in range(lk.order + 1))
    return [(m + 1) % k in used for m in range(k)]


class Unpacked:
    """The FMU files of a run, each extracted once into a folder of its own under `folder`: the
    instances of one FMU in a process share its files and its loaded library, as FMI allows for an
    FMU that may be instantiated more than once per process (Plan.exclusive keeps the others apart).
    `unpacked(path)` extracts on first use and gives the folder; removing `folder` removes them."""

    def __init__(self, folder: str | Path):
        self.folder = Path(folder)
        self.dirs: dict[Path, Path] = {}

    def __call__(self, path: str | Path) -> Path:
        key = Path(path).resolve()
        if key not in self.dirs:
            folder = tempfile.mkdtemp(prefix=f"fmu_{key.stem}_", dir=self.folder)
            self.dirs[key] = safe_extract(key, Path(folder))
        return self.dirs[key]


def open_fmu(sc: Scenario, comp: Component, unpacked: Unpacked | None = None) -> Fmu:
    """Load the FMU of `comp`, set its parameters and start values, enter initialisation mode;
    from the files of `unpacked` where given (else extracted for this instance alone)."""
    fmu = Fmu(
        comp.fmu_path,
        comp.name,
        model_exchange=comp.model_exchange is not None,
        intermediate_update=comp.interpolate_inputs,
        scheduled=comp.scheduled,
        event_mode=comp.event_mode,
        unpacked=unpacked(comp.fmu_path) if unpacked is not None else None,
    )
    try:
        fmu.set_values(dict(comp.parameters))
        fmu.enter_initialization(float(sc.start_time), float(sc.stop_time))
    except BaseException:
        fmu.close()
        raise
    return fmu
