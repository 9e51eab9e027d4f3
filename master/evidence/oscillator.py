"""The two-mass oscillator benchmark (Gomes et al., "Co-simulation: a survey") in closed form.

m1 x1'' = -c1 x1 - d1 x1' + F,  m2 x2'' = -c2 x2 - d2 x2' - F,  F = cc (x2 - x1) + dc (x2' - x1').
State z = (x1, v1, x2, v2) in (m, m/s, m, m/s); the exact solution is z(t) = expm(A t) z(0).
"""

from __future__ import annotations

from dataclasses import dataclass
from fractions import Fraction
from pathlib import Path

import numpy as np
from scipy.linalg import expm

from master.scenario.model import Scheme
from master.solvers import RK4


@dataclass(frozen=True)
class TwoMass:
    """Parameters: masses (kg), spring stiffnesses (N/m), dampers (N s/m); cc, dc couple the masses."""

    m1: float = 1.0
    c1: float = 1.0
    d1: float = 1.0
    m2: float = 1.0
    c2: float = 1.0
    d2: float = 1.0
    cc: float = 1.0
    dc: float = 1.0

    def matrix(self) -> np.ndarray:
        """The 4x4 system matrix A (1/s, 1/s^2) of z' = A z."""
        m1, c1, d1, m2, c2, d2, cc, dc = (
            self.m1, self.c1, self.d1, self.m2, self.c2, self.d2, self.cc, self.dc,
        )  # fmt: skip
        return np.array(
            [
                [0.0, 1.0, 0.0, 0.0],
                [-(c1 + cc) / m1, -(d1 + dc) / m1, cc / m1, dc / m1],
                [0.0, 0.0, 0.0, 1.0],
                [cc / m2, dc / m2, -(c2 + cc) / m2, -(d2 + dc) / m2],
            ]
        )

    def exact(self, t: np.ndarray | float, z0: np.ndarray) -> np.ndarray:
        """Exact states z(t) for times t (s) from z(0) = z0; shape (len(t), 4)."""
        a = self.matrix()
        times = np.atleast_1d(np.asarray(t, dtype=float))
        return np.array([expm(a * ti) @ np.asarray(z0, dtype=float) for ti in times])


# Parameter set A of the benchmark and its published reference values at t = 10 s.
SET_A = TwoMass()
SET_A_Z0 = np.array([1.0, 0.0, 0.0, 0.0])
SET_A_X1_10 = -1.0849853810160e-3
SET_A_V1_10 = -2.6931070586924e-3


def split_scheme(
    p: TwoMass = SET_A,
    order: int = 0,
    solvers: tuple[int, int] = (RK4, RK4),
    step_ratios: tuple[int, int] = (1, 1),
    substeps: tuple[int, int] = (1, 1),
    inputs: str | tuple[str, str] = "hold",
    split: str = "displacement",
):
    """The benchmark's co-simulation split as a linear scheme (see master.evidence.linear).

    split "displacement": two alike components, each one mass with its own spring and the
    coupling spring-damper; each takes the other's position and velocity (no feedthrough).
    mass1: states (x1, v1), inputs x_in, v_in (= x2, v2), outputs x, v; mass2 likewise.
    split "force": mass1 takes the coupling force F; mass2 carries the coupling and outputs
    F = cc (x2 - x1) + dc (v2 - v1), which feeds through from its inputs x1, v1.
    """
    from master.evidence.linear import LinearComponent, LinearScheme

    modes = (inputs, inputs) if isinstance(inputs, str) else tuple(inputs)

    def mass(name, m, c, d, cc, dc, inputs, outputs, i):
        a = np.array([[0.0, 1.0], [-(c + cc) / m, -(d + dc) / m]])
        b = np.array([[0.0, 0.0], [cc / m, dc / m]])
        return dict(name=name, a=a, b=b, inputs=inputs, outputs=outputs, solver=solvers[i],
                    step_ratio=step_ratios[i], substeps=substeps[i], input_mode=modes[i])  # fmt: skip

    if split == "displacement":
        io = (("x_in", "v_in"), ("x", "v"))
        m1 = LinearComponent(
            c=np.eye(2), d=np.zeros((2, 2)), **mass("mass1", p.m1, p.c1, p.d1, p.cc, p.dc, *io, 0)
        )
        m2 = LinearComponent(
            c=np.eye(2), d=np.zeros((2, 2)), **mass("mass2", p.m2, p.c2, p.d2, p.cc, p.dc, *io, 1)
        )
        conns = (
            ("mass1", "x", "mass2", "x_in"),
            ("mass1", "v", "mass2", "v_in"),
            ("mass2", "x", "mass1", "x_in"),
            ("mass2", "v", "mass1", "v_in"),
        )
        return LinearScheme((m1, m2), conns, order=order, inputs=modes[0])
    if split != "force":
        raise ValueError(f"unknown split {split!r}: 'displacement' or 'force'")
    m1 = LinearComponent(
        c=np.eye(2),
        d=np.zeros((2, 1)),
        **{
            **mass("mass1", p.m1, p.c1, p.d1, 0.0, 0.0, ("F",), ("x", "v"), 0),
            "b": np.array([[0.0], [1.0 / p.m1]]),
        },
    )
    m2 = LinearComponent(
        c=np.array([[p.cc, p.dc]]),
        d=np.array([[-p.cc, -p.dc]]),
        **mass("mass2", p.m2, p.c2, p.d2, p.cc, p.dc, ("x_in", "v_in"), ("F",), 1),
    )
    conns = (("mass1", "x", "mass2", "x_in"), ("mass1", "v", "mass2", "v_in"), ("mass2", "F", "mass1", "F"))
    return LinearScheme((m1, m2), conns, order=order, inputs=modes[0])


def scene(
    p: TwoMass = SET_A,
    split: str = "displacement",
    macro_step: Fraction = Fraction(1, 100),
    stop_time: Fraction = Fraction(10),
    order: int = 0,
    solvers: tuple[int, int] = (RK4, RK4),
    step_ratios: tuple[int, int] = (1, 1),
    z0: np.ndarray = SET_A_Z0,
    path: Path | None = None,
    coupling: Scheme = Scheme.JACOBI,
    interpolate: tuple[bool, bool] = (False, False),
    substeps: int = 0,
):
    """The benchmark as a Scenario of two msd FMUs (the split as in `split_scheme`).

    Records x and v of both masses.  coupling: Jacobi or Gauss-Seidel (mass1 first);
    interpolate: hand the input polynomials to mass1 / mass2; substeps: solver steps inside each
    communication step (0: one); path: the scenario's file name (default: the msd model source).
    """
    from master.fmubuild import fmu_path
    from master.scenario.model import Component, Connection, Scenario

    fmu = fmu_path("msd")
    coupled = split == "displacement"
    comps = []
    for i, (name, m, c, d) in enumerate((("mass1", p.m1, p.c1, p.d1), ("mass2", p.m2, p.c2, p.d2))):
        has_coupling = coupled or i == 1
        params = {"m": m, "c": c, "d": d, "x0": float(z0[2 * i]), "v0": float(z0[2 * i + 1]),
                  "cc": p.cc if has_coupling else 0.0, "dc": p.dc if has_coupling else 0.0,
                  "solver": solvers[i], "internal_step": 0.0}  # fmt: skip
        if substeps:
            params["internal_step"] = float(Fraction(macro_step) / (step_ratios[i] * substeps))
        comps.append(Component(name, fmu, params, step_ratios[i], order, interpolate[i]))
    conns = [Connection("mass1", "x", "mass2", "x_in"), Connection("mass1", "v", "mass2", "v_in")]
    if coupled:
        conns += [Connection("mass2", "x", "mass1", "x_in"), Connection("mass2", "v", "mass1", "v_in")]
    elif split == "force":
        conns += [Connection("mass2", "F_c", "mass1", "F")]
    else:
        raise ValueError(f"unknown split {split!r}: 'displacement' or 'force'")
    record = tuple((c, v) for c in ("mass1", "mass2") for v in ("x", "v"))
    src = path or Path(__file__).resolve().parents[2] / "fmus" / "msd" / "model.c"
    return Scenario(src, f"oscillator-{split}", tuple(comps), tuple(conns), Fraction(0), Fraction(stop_time),
                    Fraction(macro_step), coupling, ("mass1", "mass2"), record=record)  # fmt: skip


def estimate_against_truth(macro_step: Fraction, order: int) -> tuple[float, float, float]:
    """The coupling error estimate of mass1.x -> mass2.x_in against the truth, parameter set A,
    force split, polynomial inputs handed to both FMUs, 10 s; each relative to the range of the
    exact x1: (the run summary's estimate: the largest difference between the value the
    polynomial gave mass2 at a macro step's end and the sample mass1 then produced; the true
    coupling error of the connection: the largest difference between that value and the exact
    x1 at that time; the error the coupling leaves in mass1.x, which mass2's dynamics filter)."""
    from master.api import run
    from master.coupling import weights

    r = run(scene(split="force", macro_step=macro_step, stop_time=Fraction(10), order=order,
                  interpolate=(True, True)), backend="in-process")  # fmt: skip
    y = r.data["mass1.x"]  # a row every macro step: the source's samples
    exact = SET_A.exact(r.data["time"], SET_A_Z0)[:, 0]
    span = float(np.ptp(exact))
    w = weights(order, 1, 1)
    ends = range(order + 1, len(y) - 1)  # the macro steps the estimate covers (full order)
    given = np.array([sum(w[q] * y[n - 1 - q] for q in range(order + 1)) for n in ends])
    link = float(np.max(np.abs(given - exact[order + 1 : len(y) - 1]))) / span
    state = float(np.max(np.abs(y - exact))) / span
    return r.summary.coupling_errors["mass1.x -> mass2.x_in"]["max"], link, state
