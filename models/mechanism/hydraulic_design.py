"""Table 2 cylinder layout check: hydro-mechanical frequencies and holding forces.

Through the FMU (Model Exchange) in the initial pose of table2(): M_bar (locals mbar_ij),
the stroke Jacobian G = d stroke / d v (stroke rates for unit joint rates) and the
gravity acceleration at rest.  With Table 2's hydraulics each cylinder is a spring
k = beta A^2 (1/V1 + 1/V2) (N/m); the coupled frequencies are sqrt(eig(M_bar^-1 G' K G))
(rad/s).  The holding forces F solve G' F = -M_bar v''(rest, no effort) (N).
Run: python hydraulic_design.py
"""

from __future__ import annotations

import ctypes

import numpy as np
import parameters
from fmpy import extract, read_model_description
from fmpy.fmi2 import FMU2Model

from master import fmubuild

BETA = 1.03e9  # Pa
AREA = np.array([1.94e-2, 1.55e-2, 1.55e-2])  # m^2
VOLUME = np.array([1.23e-2, 3.28e-3, 3.28e-3])  # m^3, each chamber at stroke 0


def design(params: dict[str, float]) -> dict[str, np.ndarray]:
    """G (m/rad), M_bar (SI), frequencies (rad/s), holding forces (N), initial lengths (m)."""
    path = str(fmubuild.fmu_path("manipulator"))
    md = read_model_description(path)
    vr = {v.name: v.valueReference for v in md.modelVariables}
    m = FMU2Model(
        guid=md.guid, unzipDirectory=extract(path), modelIdentifier="manipulator", instanceName="design"
    )
    m.instantiate()
    m.setupExperiment(startTime=0.0)
    m.enterInitializationMode()
    for name, value in params.items():
        integer = name == "actuation" or name.endswith(("_body_a", "_body_b"))
        (m.setInteger if integer else m.setReal)([vr[name]], [value])
    m.exitInitializationMode()
    m.enterContinuousTimeMode()

    def evaluate(vd: np.ndarray) -> np.ndarray:
        v = [params["q1_0"], params["q2_0"], params["q3_0"]]
        m.setContinuousStates((ctypes.c_double * 6)(*v, *vd), 6)
        dx = (ctypes.c_double * 6)()
        m.getDerivatives(dx, 6)
        return np.array(dx[3:])

    get = lambda *names: np.array(m.getReal([vr[n] for n in names]))  # noqa: E731
    G = np.zeros((3, 3))
    for j in range(3):
        evaluate(np.eye(3)[j])
        G[:, j] = get("stroke_rate1", "stroke_rate2", "stroke_rate3")
    vdd = evaluate(np.zeros(3))
    mbar = get(*[f"mbar_{i}{j}" for i in (1, 2, 3) for j in (1, 2, 3)]).reshape(3, 3)
    lengths = get("cyl1_length0", "cyl2_length0", "cyl3_length0")
    m.terminate()
    m.freeInstance()
    k = BETA * AREA**2 * 2 / VOLUME
    omega = np.sort(np.sqrt(np.linalg.eigvals(np.linalg.solve(mbar, G.T @ np.diag(k) @ G)).real))
    hold = -np.linalg.solve(G.T, mbar @ vdd)
    return {"G": G, "mbar": mbar, "k": k, "omega": omega, "hold": hold, "lengths": lengths}


def main() -> None:
    d = design(parameters.table2())
    np.set_printoptions(precision=4, suppress=True)
    print("lever arms dl/dq (diag of G, m/rad):", np.diag(d["G"]))
    print("M_bar:\n", d["mbar"])
    print("hydraulic stiffness k (N/m):", d["k"])
    print("coupled frequencies (rad/s):", d["omega"], " omega*h at h = 1e-3 s:", d["omega"] * 1e-3)
    print("holding forces at rest (N):", d["hold"], " = pressure differences (Pa):", d["hold"] / AREA)
    print("cylinder lengths at stroke 0 (m):", d["lengths"], " half strokes V/A (m):", VOLUME / AREA)


if __name__ == "__main__":
    main()
