"""Write the parameter files of the DC-motor arm scene (paper Sec. 4.2, Table 3).

mechanics.ssv  the manipulator FMU: body data of Table 3 and the geometry chosen for it
               (models/mechanism/parameters.py, table3()), joint torques (actuation 0), and
               the start pose moved to the controller's set point q* = (0, 45, 300) degrees.
motors.ssv     start currents of the motors FMU: the holding currents i* of controller.ssv,
               so that the scene starts at rest in the equilibrium z* the controller holds.

controller.ssv (gains, set points, holding currents, Table 3 motor data) is written by
place_poles.py; run that first if the FMUs changed.

Run:  .venv/bin/python models/dc-motor-arm/make_parameters.py
"""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path
from types import ModuleType

from master.scenario.ssv import read_ssv, real_units, write_ssv

HERE = Path(__file__).resolve().parent
ROOT = HERE.parents[1]


def _module(path: Path) -> ModuleType:
    spec = importlib.util.spec_from_file_location(path.stem, path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def main(out: Path = HERE) -> int:
    """Write mechanics.ssv and motors.ssv into `out` (default: beside this script)."""
    controller = read_ssv(HERE / "controller.ssv")
    mech = _module(ROOT / "models" / "mechanism" / "parameters.py").table3()
    for k in (1, 2, 3):
        mech[f"q{k}_0"] = controller[f"q{k}_ref"]  # rad
        mech[f"qd{k}_0"] = 0.0  # rad/s
    currents = {f"i{k}": controller[f"i_ref{k}"] for k in (1, 2, 3)}  # A
    for file, name, params, fmu in (
        ("mechanics.ssv", "Table 3 mechanics at the set point", mech, "manipulator"),
        ("motors.ssv", "holding currents", currents, "dcmotor"),
    ):
        units = real_units(ROOT / "fmus" / fmu / "modelDescription.xml")
        write_ssv(out / file, name, dict(sorted(params.items())), units, f"{HERE.name}/make_parameters.py")
        print(f"wrote {out / file}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
