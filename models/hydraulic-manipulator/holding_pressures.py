"""Chamber pressures that hold the hydraulic manipulator at rest in its initial pose.

The paper's Table 2 initial pressures (8.14 / 5.66 MPa on actuator 1, 6.9 / 6.9 MPa on 2
and 3) belong to the paper's own geometry; with ours (models/mechanism/table2.json) they
would push 48 kN on cylinder 1, which turns the base and holds nothing.  Here the cylinder
forces F that make the arm's accelerations vanish at its start pose are found from the
manipulator FMU's Model Exchange interface (accelerations are affine in F: one Newton
step is exact, a second polishes), and each cylinder gets the centred pressures

    p_left = (p_s + p_t + F / A) / 2,   p_right = (p_s + p_t - F / A) / 2     (Pa)

like the paper's (its p_left + p_right = p_s).  They are written as start values of the
hydraulics FMU to hydraulics.ssv (SSP 1.0 ParameterValues) beside this file.

Run:  .venv/bin/python models/hydraulic-manipulator/holding_pressures.py
"""

from __future__ import annotations

import ctypes
import json
import shutil
import sys
from pathlib import Path

import numpy as np
from fmpy import extract, read_model_description
from fmpy.fmi2 import FMU2Model

from master.scenario.ssv import write_ssv

HERE = Path(__file__).resolve().parent
ARM_PARAMETERS = HERE.parent / "mechanism" / "table2.json"
SSV_PATH = HERE / "hydraulics.ssv"
P_SUPPLY, P_TANK = 1.38e7, 0.0  # Pa, Table 2 and the FMU's default
AREA = (1.94e-2, 1.55e-2, 1.55e-2)  # m^2, Table 2
_P = ctypes.POINTER(ctypes.c_double)


def holding_forces(manipulator: Path, params: dict[str, float | int]) -> np.ndarray:
    """Cylinder forces (N, + extends) that keep the arm at rest in its start pose."""
    md = read_model_description(str(manipulator))
    vr = {v.name: v.valueReference for v in md.modelVariables}
    kinds = {v.name: v.type for v in md.modelVariables}
    unzip = extract(str(manipulator))
    fmu = FMU2Model(
        guid=md.guid,
        unzipDirectory=unzip,
        modelIdentifier=md.modelExchange.modelIdentifier,
        instanceName="arm",
    )
    try:
        fmu.instantiate()
        fmu.setupExperiment(startTime=0.0)
        for name, value in params.items():
            if kinds[name] in ("Integer", "Enumeration"):
                fmu.setInteger([vr[name]], [int(value)])
            else:
                fmu.setReal([vr[name]], [float(value)])
        fmu.enterInitializationMode()
        fmu.exitInitializationMode()
        while fmu.newDiscreteStates()[0]:
            pass
        fmu.enterContinuousTimeMode()
        n = md.numberOfContinuousStates
        x, dx = np.zeros(n), np.zeros(n)
        fmu.getContinuousStates(x.ctypes.data_as(_P), n)
        if np.any(x[n // 2 :] != 0):
            raise ValueError(f"{ARM_PARAMETERS}: the start pose is not at rest")
        effort = [vr[f"effort{k}"] for k in (1, 2, 3)]

        def accelerations(force: np.ndarray) -> np.ndarray:
            fmu.setReal(effort, list(force))
            fmu.getDerivatives(dx.ctypes.data_as(_P), n)
            return dx[n // 2 :].copy()

        force = np.zeros(3)
        for _ in range(2):
            base = accelerations(force)
            jac = np.column_stack([accelerations(force + 1e3 * e) - base for e in np.eye(3)]) / 1e3
            force = force - np.linalg.solve(jac, base)
        residual = np.abs(accelerations(force)).max()
        if residual > 1e-9:
            raise RuntimeError(f"holding forces leave accelerations of {residual:.3g} (rad/s^2 or m/s^2)")
        return force
    finally:
        fmu.terminate()
        fmu.freeInstance()
        shutil.rmtree(unzip, ignore_errors=True)


def pressures(force: np.ndarray) -> dict[str, float]:
    """Centred chamber pressures (Pa) that make A (p_left - p_right) = force."""
    out: dict[str, float] = {}
    for k in range(3):
        load = force[k] / AREA[k]
        if abs(load) >= P_SUPPLY - P_TANK:
            raise ValueError(f"cylinder {k + 1}: holding force {force[k]:.4g} N needs more than the supply")
        out[f"p_left{k + 1}"] = (P_SUPPLY + P_TANK + load) / 2
        out[f"p_right{k + 1}"] = (P_SUPPLY + P_TANK - load) / 2
    return out


def main() -> int:
    from master.fmubuild import fmu_path

    params = json.loads(ARM_PARAMETERS.read_text(encoding="utf-8"))
    force = holding_forces(fmu_path("manipulator"), params)
    write_ssv(
        SSV_PATH,
        "hydraulics holding pressures",
        pressures(force),
        generated_by="hydraulic-manipulator/holding_pressures.py",
    )
    print(f"holding forces (N): {np.round(force, 3).tolist()}")
    print(f"wrote {SSV_PATH}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
