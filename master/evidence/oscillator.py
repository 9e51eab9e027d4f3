"""The two-mass oscillator benchmark (Gomes et al., "Co-simulation: a survey") in closed form.

m1 x1'' = -c1 x1 - d1 x1' + F,  m2 x2'' = -c2 x2 - d2 x2' - F,  F = cc (x2 - x1) + dc (x2' - x1').
State z = (x1, v1, x2, v2) in (m, m/s, m, m/s); the exact solution is z(t) = expm(A t) z(0).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.linalg import expm


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
