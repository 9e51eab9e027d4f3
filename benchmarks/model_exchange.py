"""The cost of a communication step of a Model Exchange component (the master integrates it in the
kernel: fmi2SetTime, fmi2SetReal, fmi2SetContinuousStates and fmi2GetDerivatives per stage) against
the same model as a Co-Simulation FMU (one fmi2DoStep, the FMU's own solver): the same method and
steps, bit for bit the same results (tests/test_model_exchange.py), so only the calls differ.

    .venv/bin/python benchmarks/model_exchange.py [--repeat 3]

Scenes (models/): the hydraulic manipulator (mechanics AB3 at 1 ms, hydraulics Euler at 0.2 ms,
3 s) and the DC-motor arm (mechanics AB3 at 20 ms, motors Euler at 5 ms, 4 s), every component
Co-Simulation, then every one Model Exchange; in-process. Printed per component: microseconds per
communication step inside its FMU (and, for Model Exchange, the kernel's solver between the calls),
the best of `repeat` runs, and the run's wall time.
"""

from __future__ import annotations

import argparse
import dataclasses
from fractions import Fraction
from pathlib import Path

import master.api as api
from master.description import variables_of
from master.fmu import read_description
from master.scenario.model import Component, ModelExchange
from master.solvers import ITEMS

ROOT = Path(__file__).resolve().parent.parent
SCENES = ("hydraulic-manipulator", "dc-motor-arm")


def as_model_exchange(comp: Component) -> Component:
    """comp as Model Exchange with the method and internal step of its FMU's own parameters."""
    v = variables_of(read_description(comp.fmu_path))
    solver = int(comp.parameters.get("solver", v["solver"].start))
    h = Fraction(float(comp.parameters.get("internal_step", v["internal_step"].start)))
    return dataclasses.replace(comp, model_exchange=ModelExchange(ITEMS[solver], h if h > 0 else None))


def measure(sc, repeat: int) -> tuple[dict[str, float], float]:
    """(us per communication step by component, wall time in s), the best of `repeat` runs."""
    best: dict[str, float] = {}
    wall = float("inf")
    for _ in range(repeat):
        s = api.run(sc, backend="in-process").summary
        wall = min(wall, s.stepping_time)
        for name, t in s.fmu_time.items():
            best[name] = min(best.get(name, float("inf")), 1e6 * t / s.steps[name])
    return best, wall


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=3)
    args = parser.parse_args()
    for scene in SCENES:
        sc = api.load_scenario(ROOT / "models" / scene / "SystemStructure.ssd")
        me = dataclasses.replace(sc, components=tuple(as_model_exchange(c) for c in sc.components))
        cs_steps, cs_wall = measure(sc, args.repeat)
        me_steps, me_wall = measure(me, args.repeat)
        print(f"{scene}, {float(sc.stop_time):g} s simulated, {sc.macro_step} s macro step:")
        for c in sc.components:
            ratio = me_steps[c.name] / cs_steps[c.name]
            print(
                f"  {c.name:12s} us per step: co-simulation {cs_steps[c.name]:8.2f}, "
                f"model exchange {me_steps[c.name]:8.2f} ({ratio:.2f}x)"
            )
        print(f"  stepping wall time: co-simulation {cs_wall:.3f} s, model exchange {me_wall:.3f} s")


if __name__ == "__main__":
    main()
