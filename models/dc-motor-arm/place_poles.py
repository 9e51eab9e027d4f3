"""Feedback gains of the DC-motor arm (paper Sec. 4.2, eq. 13) by pole placement.

The arm (fmus/manipulator with models/mechanism/table3.json: Table 3, joint torques) and
the three motors (fmus/dcmotor) are coupled through their Model Exchange interfaces into
one system z' = F(z, u), z = (q1..q3 rad, qd1..qd3 rad/s, i1..i3 A), u = the motor
voltages w_ext (V).  At the set point q* = (0, 45, 300) degrees, qd* = 0, the holding
currents i* balance gravity: i*_k = tau*_k / Kt_k where tau* makes the joint
accelerations vanish; the motors add the voltage R i* that keeps them flowing, so z* is
an exact equilibrium.  F is linearised there by central differences, A = dF/dz,
B = dF/du, and scipy.signal.place_poles gives K
with eig(A - B K) = POLES.  The gains, set points and holding currents are written to
controller.ssv (SSP 1.0 ParameterValues) beside this file.

Run:  .venv/bin/python models/dc-motor-arm/place_poles.py
"""

from __future__ import annotations

import ctypes
import json
import shutil
import sys
import warnings
from pathlib import Path

import numpy as np
from fmpy import extract, read_model_description
from fmpy.fmi2 import FMU2Model
from scipy.signal import place_poles

from master.scenario.ssv import write_ssv

HERE = Path(__file__).resolve().parent
SSV_PATH = HERE / "controller.ssv"
ARM_PARAMETERS = HERE.parent / "mechanism" / "table3.json"  # the arm of Table 3, joint torques

Q_REF = np.radians([0.0, 45.0, 300.0])  # rad, the paper's set point
MOTOR = {"R": 5.0, "L": 0.02, "Ke": 0.5, "Kt1": 20.0, "Kt2": 15.0, "Kt3": 10.0}  # Table 3
# Closed-loop poles (1/s): three well damped mechanical pairs (zeta 0.8, 8..12 rad/s) and the
# three electrical poles kept near their open-loop place -R/L = -250 1/s.
_WN = np.array([8.0, 10.0, 12.0])
_ZETA = 0.8
POLES = np.concatenate(
    [
        -_ZETA * _WN + 1j * _WN * np.sqrt(1 - _ZETA**2),
        -_ZETA * _WN - 1j * _WN * np.sqrt(1 - _ZETA**2),
        [-230.0, -240.0, -250.0],
    ]
)
_DOUBLE_P = ctypes.POINTER(ctypes.c_double)


class MeFmu:
    """One FMU instantiated through its Model Exchange interface (fmpy underneath)."""

    def __init__(self, path: Path, parameters: dict[str, float | int], name: str) -> None:
        md = read_model_description(str(path))
        self.vr = {v.name: v.valueReference for v in md.modelVariables}
        kinds = {v.name: v.type for v in md.modelVariables}
        self.n = md.numberOfContinuousStates
        self._dir = extract(str(path))
        self.fmu = FMU2Model(
            guid=md.guid,
            unzipDirectory=self._dir,
            modelIdentifier=md.modelExchange.modelIdentifier,
            instanceName=name,
        )
        self.fmu.instantiate()
        self.fmu.setupExperiment(startTime=0.0)
        for key, value in parameters.items():
            if key not in self.vr:
                raise ValueError(f"{path}: no variable {key!r}")
            if kinds[key] in ("Integer", "Enumeration"):
                self.fmu.setInteger([self.vr[key]], [int(value)])
            else:
                self.fmu.setReal([self.vr[key]], [float(value)])
        self.fmu.enterInitializationMode()
        self.fmu.exitInitializationMode()
        while self.fmu.newDiscreteStates()[0]:
            pass
        self.fmu.enterContinuousTimeMode()
        self._x = np.zeros(self.n)
        self._dx = np.zeros(self.n)

    def refs(self, names: list[str]) -> list[int]:
        """Value references of `names`."""
        return [self.vr[n] for n in names]

    def states(self) -> np.ndarray:
        """Current continuous states."""
        self.fmu.getContinuousStates(self._x.ctypes.data_as(_DOUBLE_P), self.n)
        return self._x.copy()

    def set_states(self, x: np.ndarray) -> None:
        self._x[:] = x
        self.fmu.setContinuousStates(self._x.ctypes.data_as(_DOUBLE_P), self.n)

    def derivatives(self) -> np.ndarray:
        """State derivatives at the states and inputs set last."""
        self.fmu.getDerivatives(self._dx.ctypes.data_as(_DOUBLE_P), self.n)
        return self._dx.copy()

    def close(self) -> None:
        self.fmu.terminate()
        self.fmu.freeInstance()
        shutil.rmtree(self._dir, ignore_errors=True)


class CoupledArm:
    """Arm and motors through Model Exchange: z' = F(z, u), z = (q1..3, qd1..3, i1..3), u = w_ext (V).

    The arm's states must be (q1..q3, qd1..qd3) in this order (checked against its outputs).
    """

    def __init__(self, manipulator: Path, motor: Path, motor_parameters: dict[str, float]) -> None:
        self.arm = MeFmu(manipulator, arm_parameters(), "arm")
        self.motor = MeFmu(motor, motor_parameters, "motors")
        if self.arm.n != 6 or self.motor.n != 3:
            raise ValueError(f"expected 6 arm states and 3 motor states, got {self.arm.n} and {self.motor.n}")
        self._arm_out = self.arm.refs(["q1", "q2", "q3", "qd1", "qd2", "qd3"])
        self._effort = self.arm.refs(["effort1", "effort2", "effort3"])
        self._motor_in = self.motor.refs(["q1", "q2", "q3", "qd1", "qd2", "qd3"])
        self._w_ext = self.motor.refs(["w_ext1", "w_ext2", "w_ext3"])
        self._torque = self.motor.refs(["torque1", "torque2", "torque3"])
        probe = np.array([0.1, 0.2, 0.3, 0.4, 0.5, 0.6])
        self.arm.set_states(probe)
        if not np.allclose(self.arm.fmu.getReal(self._arm_out), probe):
            raise ValueError(f"{manipulator}: states are not (q1..q3, qd1..qd3)")

    def initial_state(self) -> np.ndarray:
        """z at the FMUs' start values."""
        return np.concatenate([self.arm.states(), self.motor.states()])

    def rhs(self, z: np.ndarray, u: np.ndarray | None = None) -> np.ndarray:
        """dz/dt at state z and motor voltages u (V, default 0)."""
        self.arm.set_states(z[:6])
        qs = self.arm.fmu.getReal(self._arm_out)
        self.motor.fmu.setReal(self._motor_in, qs)
        self.motor.fmu.setReal(self._w_ext, [0.0, 0.0, 0.0] if u is None else list(u))
        self.motor.set_states(z[6:])
        self.arm.fmu.setReal(self._effort, self.motor.fmu.getReal(self._torque))
        return np.concatenate([self.arm.derivatives(), self.motor.derivatives()])

    def close(self) -> None:
        self.arm.close()
        self.motor.close()


def arm_parameters() -> dict[str, float | int]:
    """The scene's manipulator parameters (models/mechanism/table3.json), with joint torques."""
    params = json.loads(ARM_PARAMETERS.read_text(encoding="utf-8"))
    if params.get("actuation", 0) != 0:
        raise ValueError(f"{ARM_PARAMETERS}: actuation must be 0 (joint torques) for the motors")
    return params


def holding_torques(manipulator: Path, q_ref: np.ndarray = Q_REF) -> np.ndarray:
    """Joint torques (N m) that hold the arm at rest at q_ref: qdd(q_ref, 0, tau) = 0.

    qdd is affine in tau (M qdd = tau - g(q)), so one Newton step from tau = 0 with a
    difference quotient of unit torque steps is exact up to rounding; a second one polishes.
    """
    arm = MeFmu(manipulator, arm_parameters(), "arm")
    try:
        effort = arm.refs(["effort1", "effort2", "effort3"])
        arm.set_states(np.concatenate([q_ref, np.zeros(3)]))

        def qdd(tau: np.ndarray) -> np.ndarray:
            arm.fmu.setReal(effort, list(tau))
            return arm.derivatives()[3:]

        tau = np.zeros(3)
        for _ in range(2):
            base = qdd(tau)
            jac = np.column_stack([qdd(tau + e) - base for e in np.eye(3)])
            tau = tau - np.linalg.solve(jac, base)
        return tau
    finally:
        arm.close()


def linearise(system: CoupledArm, z0: np.ndarray, rel: float = 1e-6) -> tuple[np.ndarray, np.ndarray]:
    """A = dF/dz and B = dF/du at (z0, u = 0) by central differences."""
    n = z0.size
    a = np.zeros((n, n))
    for j in range(n):
        d = rel * max(1.0, abs(z0[j]))
        e = np.zeros(n)
        e[j] = d
        a[:, j] = (system.rhs(z0 + e) - system.rhs(z0 - e)) / (2 * d)
    b = np.zeros((n, 3))
    for j in range(3):
        u = np.zeros(3)
        u[j] = 1e-3
        b[:, j] = (system.rhs(z0, u) - system.rhs(z0, -u)) / 2e-3
    return a, b


def ab3_region_limit(lam: complex, h_hi: float = 1.0) -> float:
    """Largest h > 0 such that h * lam stays in the AB3 stability region along the ray from 0 (s).

    AB3 on y' = lam y: r^3 - (1 + 23z/12) r^2 + (16z/12) r - 5z/12 = 0, z = h lam;
    stable while every root has |r| <= 1.
    """

    def stable(h: float) -> bool:
        z = h * lam
        roots = np.roots([1.0, -(1 + 23 * z / 12), 16 * z / 12, -5 * z / 12])
        return bool(np.max(np.abs(roots)) <= 1 + 1e-12)

    # walk out from 0 until the first unstable h, then bisect
    h, dh = 0.0, h_hi / 2000
    while h < h_hi and stable(h + dh):
        h += dh
    lo, hi = h, h + dh
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if stable(mid) else (lo, mid)
    return lo


def closed_loop_jacobian(system: CoupledArm, z0: np.ndarray) -> np.ndarray:
    """dF/dz at z0 with the gains inside the motor FMU (central differences)."""
    return linearise(system, z0)[0]


def ab3_prediction(jac: np.ndarray) -> float:
    """Largest AB3 step (s) for which every eigenvalue of jac lies in the stability region."""
    return min(ab3_region_limit(lam) for lam in np.linalg.eigvals(jac) if lam.real < 0)


def ab3_grows(system: CoupledArm, z_ref: np.ndarray, dz0: np.ndarray, h: float, t_end: float) -> bool:
    """AB3 (Table 1) on the whole coupled system from z_ref + dz0 for t_end seconds (one Euler and
    one AB2 step start it): True if the deviation ends larger than it began or turns non-finite."""
    z = z_ref + dz0
    f1 = f2 = None
    for _ in range(int(np.ceil(t_end / h))):
        f0 = system.rhs(z)
        if f1 is None:
            z = z + h * f0
        elif f2 is None:
            z = z + h / 2 * (3 * f0 - f1)
        else:
            z = z + h / 12 * (23 * f0 - 16 * f1 + 5 * f2)
        f1, f2 = f0, f1
        if not np.all(np.isfinite(z)) or np.abs(z - z_ref).max() > 1e3:
            return True
    return bool(np.linalg.norm(z - z_ref) > np.linalg.norm(dz0))


def ab3_stable_step(
    system: CoupledArm,
    z_ref: np.ndarray,
    dz0: np.ndarray,
    lo: float,
    hi: float,
    t_end: float,
    iterations: int,
) -> float:
    """Bisection for the largest AB3 step (s) at which the deviation from z_ref does not grow.

    lo must be stable and hi unstable; the answer lies within (hi - lo) / 2^iterations."""
    if ab3_grows(system, z_ref, dz0, lo, t_end) or not ab3_grows(system, z_ref, dz0, hi, t_end):
        raise ValueError(f"bracket [{lo}, {hi}] s does not straddle the AB3 stability limit")
    for _ in range(iterations):
        mid = 0.5 * (lo + hi)
        lo, hi = (lo, mid) if ab3_grows(system, z_ref, dz0, mid, t_end) else (mid, hi)
    return lo


def design(manipulator: Path, motor: Path) -> dict[str, float]:
    """Holding currents and gains K (pole placement) for the set point; returns the parameters."""
    tau = holding_torques(manipulator)
    kt = np.array([MOTOR["Kt1"], MOTOR["Kt2"], MOTOR["Kt3"]])
    i_ref = tau / kt
    params: dict[str, float] = dict(MOTOR)
    params.update({f"q{k + 1}_ref": float(Q_REF[k]) for k in range(3)})
    params.update({f"i_ref{k + 1}": float(i_ref[k]) for k in range(3)})
    system = CoupledArm(manipulator, motor, params)  # gains still 0: u = w_ext is the whole feedback
    try:
        z_ref = np.concatenate([Q_REF, np.zeros(3), i_ref])
        a, b = linearise(system, z_ref)
    finally:
        system.close()
    with warnings.catch_warnings():
        # YT's robustness iteration may stop early; the placement itself is checked below
        warnings.filterwarnings("ignore", "Convergence was not reached", UserWarning)
        k = place_poles(a, b, POLES, method="YT", maxiter=100).gain_matrix
    placed = np.sort_complex(np.linalg.eigvals(a - b @ k))
    if not np.allclose(placed, np.sort_complex(POLES), rtol=1e-6):
        raise RuntimeError(f"pole placement missed: {placed} instead of {POLES}")
    params.update({f"K_{r + 1}_{c + 1}": float(k[r, c]) for r in range(3) for c in range(9)})
    return params


def main() -> int:
    from master.fmubuild import fmu_path

    params = design(fmu_path("manipulator"), fmu_path("dcmotor"))
    write_ssv(SSV_PATH, "dc-motor-arm controller", params, generated_by="dc-motor-arm/place_poles.py")
    k = np.array([[params[f"K_{r}_{c}"] for c in range(1, 10)] for r in range(1, 4)])
    np.set_printoptions(precision=4, suppress=True, linewidth=140)
    print(f"holding currents (A): {[round(params[f'i_ref{k}'], 6) for k in (1, 2, 3)]}")
    print(f"K =\n{k}")
    print(f"wrote {SSV_PATH}")
    print(f"closed-loop poles (1/s): {np.sort_complex(POLES)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
