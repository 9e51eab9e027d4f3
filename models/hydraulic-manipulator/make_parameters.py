"""Write the parameter files of the hydraulic manipulator scene (paper Sec. 4.1, Table 2).

mechanics.ssv   the manipulator FMU: body data of Table 2 and the geometry chosen for it
                (models/mechanism/parameters.py, table2()), cylinder forces (actuation 1),
                and the cylinders' seal friction as joint damping (ours: Table 2 has none).
actuators.ssv   the hydraulics FMU: Table 2's hydraulic data converted to SI
                (kN/m^2 -> Pa, MN/m^2 -> Pa, flow coefficient -> m^3/(s m Pa^0.5)).

Not here: the start pressures.  Table 2's initial pressures belong to the paper's own
geometry; the scene starts from the pressures that hold our arm at rest, written to
hydraulics.ssv by holding_pressures.py beside this file.

Run:  .venv/bin/python models/hydraulic-manipulator/make_parameters.py
"""

from __future__ import annotations

import importlib.util
import math
import sys
from pathlib import Path

import numpy as np

from master.scenario import ssv

HERE = Path(__file__).resolve().parent
ROOT = HERE.parents[1]

# Table 2, hydraulic part, in the paper's units; one entry per actuator 1, 2, 3.
SUPPLY_KPA = 1.38e4  # kN/m^2
BULK_MPA = 1.03e3  # MN/m^2
AREA = (1.94e-2, 1.55e-2, 1.55e-2)  # m^2
VOLUME_LEFT = (1.23e-2, 3.28e-3, 3.28e-3)  # m^3
VOLUME_RIGHT = (1.23e-2, 3.28e-3, 3.28e-3)  # m^3
FLOW_COEFFICIENT = (1.49e-3, 7.45e-4, 7.45e-4)  # l/s per (mm sqrt(kN/m^2)), see fmus/hydraulics/model.c
KV_SCALE = math.sqrt(1e-3)  # -> m^3/(s m Pa^0.5)

# Viscous seal friction of each cylinder, N s/m (our assumption, README.md): 1.5 kN at a piston
# speed of 10 mm/s, 0.56-0.70 % of the stall forces A p_s.  It damps the three hydro-mechanical
# modes to zeta = 0.08-0.14.
SEAL_FRICTION = 1.5e5


def mechanics() -> dict[str, float | int]:
    """Manipulator FMU parameters of Table 2 from models/mechanism/parameters.py."""
    spec = importlib.util.spec_from_file_location(
        "parameters", ROOT / "models" / "mechanism" / "parameters.py"
    )
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    p = module.table2()
    for k, arm in enumerate(lever_arms(p)):
        p[f"damping{k + 1}"] = SEAL_FRICTION * arm**2
    return p


def lever_arms(p: dict[str, float | int]) -> list[float]:
    """dl_k/dq_k (m/rad) of cylinder k about joint k in the start pose.

    Cylinder k joins body k to body k + 1, so its length depends on q_k alone and its seal
    friction -b dl/dt acts on joint k as the viscous damping b (dl_k/dq_k)^2 (N m s/rad).
    Joint 1 turns about z through the origin, joints 2 and 3 about x through J2 and the
    elbow C = J2 + (0, j3_y, j3_z); cylinder points are global in the table pose, which must
    be the start pose.
    """
    if any(p[f"q{k}_0"] != p[f"q{k}_table"] for k in (1, 2, 3)):
        raise ValueError("lever arms: the start pose must be the table pose")
    j2 = np.array([0.0, p["j2_y"], p["j2_z"]])
    x_axis, z_axis = np.eye(3)[0], np.eye(3)[2]
    joints = [(z_axis, np.zeros(3)), (x_axis, j2), (x_axis, j2 + [0.0, p["j3_y"], p["j3_z"]])]
    arms = []
    for k, (axis, centre) in enumerate(joints, start=1):
        if (p[f"cyl{k}_body_a"], p[f"cyl{k}_body_b"]) != (k, k + 1):
            raise ValueError(f"lever arms: cylinder {k} must join bodies {k} and {k + 1}")
        a = np.array([p[f"cyl{k}_a{c}"] for c in "xyz"])
        b = np.array([p[f"cyl{k}_b{c}"] for c in "xyz"])
        # b moves at axis x (b - centre) per unit joint rate; the length changes along b - a
        arms.append(float(abs(np.cross(axis, b - centre) @ (b - a)) / np.linalg.norm(b - a)))
    return arms


def hydraulics() -> dict[str, float]:
    """Hydraulics FMU parameters of Table 2 in SI units (Pa, m^2, m^3, m^3/(s m Pa^0.5))."""
    p: dict[str, float] = {"p_supply": SUPPLY_KPA * 1e3, "p_tank": 0.0, "bulk_modulus": BULK_MPA * 1e6}
    for k in range(3):
        n = k + 1
        p[f"area{n}"] = AREA[k]
        p[f"volume_left{n}"] = VOLUME_LEFT[k]
        p[f"volume_right{n}"] = VOLUME_RIGHT[k]
        p[f"Kv{n}"] = FLOW_COEFFICIENT[k] * KV_SCALE
    return p


def write_ssv(path: Path, name: str, params: dict[str, float | int], fmu: str) -> None:
    """Write a generated parameter set (sorted by name, with the units of project FMU `fmu`)."""
    units = ssv.real_units(ROOT / "fmus" / fmu / "modelDescription.xml")
    ssv.write_ssv(path, name, dict(sorted(params.items())), units, f"{HERE.name}/make_parameters.py")
    print(f"wrote {path}")


def main(out: Path = HERE) -> int:
    """Write mechanics.ssv and actuators.ssv into `out` (default: beside this script)."""
    write_ssv(out / "mechanics.ssv", "Table 2 mechanics", mechanics(), "manipulator")
    write_ssv(out / "actuators.ssv", "Table 2 hydraulics", hydraulics(), "hydraulics")
    return 0


if __name__ == "__main__":
    sys.exit(main())
