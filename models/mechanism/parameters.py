"""Parameter sets of the manipulator FMU (fmus/manipulator) for the paper's two experiments.

`table2()` (hydraulic manipulator, Sec. 4.1) and `table3()` (DC-motor robot arm, Sec. 4.2)
return {FMU parameter name: value} in SI units (m, kg, kg m^2, rad).  Body data are the
paper's Tables 2 and 3 verbatim; the geometry (joint points, loop pin, cylinder
attachment points) is ours, chosen to fit those tables (see README.md beside this file).
Run this file to write table2.json and table3.json, which scene files are generated from.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

HERE = Path(__file__).resolve().parent
DEG = math.pi / 180


def _bodies(rows: dict[int, tuple[float, ...]]) -> dict[str, float]:
    """Table rows {body: (x, y, z, mass, Ixx, Iyy, Izz)} -> FMU parameters."""
    p: dict[str, float] = {}
    for b, (x, y, z, m, ixx, iyy, izz) in rows.items():
        p.update({f"m{b}": m, f"Ixx{b}": ixx, f"Iyy{b}": iyy, f"Izz{b}": izz})
        p.update({f"cg{b}_x": x, f"cg{b}_y": y, f"cg{b}_z": z})
    return p


def _planar(origin: tuple[float, float], angle: float, local: tuple[float, float]) -> tuple[float, float]:
    """Global (y, z) of local (y, z) in a frame at `origin` turned by `angle` (rad) about x."""
    c, s = math.cos(angle), math.sin(angle)
    return origin[0] + c * local[0] - s * local[1], origin[1] + s * local[0] + c * local[1]


def loop_points(p: dict[str, float]) -> dict[str, tuple[float, float]]:
    """Global (y, z) of the joints J2 (shoulder), C (elbow), B (strut hinge) and pin A in the
    table pose (q1_table = 0 assumed, so that the arm lies in the y-z plane)."""
    q2, q3 = p["q2_table"], p["q3_table"]
    J2 = (p["j2_y"], p["j2_z"])
    C = _planar(J2, q2, (p["j3_y"], p["j3_z"]))
    B = _planar(C, q2 + q3, (p["j4_y"], p["j4_z"]))
    A = _planar(J2, q2, (p["a3_y"], p["a3_z"]))
    return {"J2": J2, "C": C, "B": B, "A": A}


def _cylinder(
    n: int, body_a: int, a: tuple[float, ...], body_b: int, b: tuple[float, ...]
) -> dict[str, float]:
    """Cylinder n between point a on body_a and point b on body_b (global x, y, z, table pose)."""
    p: dict[str, float] = {f"cyl{n}_body_a": body_a, f"cyl{n}_body_b": body_b}
    for e, x in (("a", a), ("b", b)):
        p.update({f"cyl{n}_{e}x": x[0], f"cyl{n}_{e}y": x[1], f"cyl{n}_{e}z": x[2]})
    return p


def table3() -> dict[str, float]:
    """Robot arm of Sec. 4.2: body data of Table 3, joint torques (actuation 0)."""
    p = _bodies(
        {
            2: (0, 0, 1, 2, 0.7, 0.7, 0.04),
            3: (0, 0.866, 2.503, 2, 0.7, 0.04, 0.7),
            4: (0, 2.598, 2.512, 2, 0.7, 0.04, 0.7),
            5: (0, 2.385, 1.888, 1.5, 0.4, 0.04, 0.4),
            6: (0, 1.084, 1.881, 1.5, 0.4, 0.04, 0.4),
        }
    )
    p.update({"j2_y": 0.0, "j2_z": 2.0, "j3_y": 2.0, "j3_z": 0.0, "j4_y": 2.0, "j4_z": -0.1})
    p.update({"a3_y": 0.2, "a3_z": -0.25})
    p.update({"q1_table": 0.0, "q2_table": 30 * DEG, "q3_table": 300 * DEG})
    p.update({"q1_0": 0.0, "q2_0": 30 * DEG, "q3_0": 300 * DEG, "qd1_0": 0.0, "qd2_0": 0.0, "qd3_0": 0.0})
    p.update({"actuation": 0, "g": 9.81, "damping1": 0.0, "damping2": 0.0, "damping3": 0.0})
    pts = loop_points(p)
    # Cylinders are unused with joint torques; they still describe valid lines:
    # a slewing lever (0.3 m arm), a boom lift and the strut B-A itself.
    p.update(_cylinder(1, 1, (0.3, -1.0, 0.5), 2, (0.3, 0.0, 0.5)))
    boom = _planar(pts["J2"], p["q2_table"], (0.7, 0.0))
    p.update(_cylinder(2, 2, (0.0, 0.3, 1.0), 3, (0.0, *boom)))
    p.update(_cylinder(3, 4, (0.0, *pts["B"]), 3, (0.0, *pts["A"])))
    return p


def table2() -> dict[str, float]:
    """Hydraulic manipulator of Sec. 4.1: body data of Table 2, cylinder forces (actuation 1)."""
    p = _bodies(
        {
            2: (0, 0, 0, 219, 1356, 1356, 1356),
            3: (0, 3.2, 2.4, 73, 678, 67.8, 678),
            4: (0, 3.2, 2.4, 15, 67.8, 67.8, 5.4),
            5: (0, 5.0, 3.4, 30, 203.4, 13.6, 203.4),
            6: (0, 6.8, 2.2, 15, 67.8, 40.7, 27.1),
        }
    )
    # Horizontal boom at z = 2.4 from the turret axis; vertical rocker (body 4) pivoting at
    # the boom's cg C = (3.2, 2.4); strut from the rocker top B = (3.2, 4.6) to the boom pin
    # A = (6.5, 2.4), on the line through the tabulated cgs of bodies 5 and 6.
    p.update({"j2_y": 0.0, "j2_z": 2.4, "j3_y": 3.2, "j3_z": 0.0, "j4_y": 2.2, "j4_z": 0.0})
    p.update({"a3_y": 6.5, "a3_z": 0.0})
    p.update({"q1_table": 0.0, "q2_table": 0.0, "q3_table": 90 * DEG})
    p.update({"q1_0": 0.0, "q2_0": 0.0, "q3_0": 90 * DEG, "qd1_0": 0.0, "qd2_0": 0.0, "qd3_0": 0.0})
    p.update({"actuation": 1, "g": 9.81, "damping1": 0.0, "damping2": 0.0, "damping3": 0.0})
    # 1: slewing cylinder from the ground point of Table 2's body 1 to a 1.06 m lever (1.0 m arm)
    p.update(_cylinder(1, 1, (0.0, -3.0, 0.0), 2, (math.sqrt(9 / 8), 0.0, 0.0)))
    # 2: boom lift from the turret to a bracket under the boom
    p.update(_cylinder(2, 2, CYL2_A, 3, CYL2_B))
    # 3: across the elbow, from a bracket under the boom to the rocker's lower arm
    p.update(_cylinder(3, 3, CYL3_A, 4, CYL3_B))
    return p


CYL2_A, CYL2_B = (0.0, 0.4, 0.6), (0.0, 1.0, 2.4)
CYL3_A, CYL3_B = (0.0, 1.2, 2.2), (0.0, 3.2, 2.2)


def main() -> None:
    for name, params in (("table2", table2()), ("table3", table3())):
        path = HERE / f"{name}.json"
        path.write_text(json.dumps(params, indent=1, sort_keys=True) + "\n")
        print(f"wrote {path}")


if __name__ == "__main__":
    main()
