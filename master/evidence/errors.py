"""Error measures of a co-simulation result against a reference solution.

A result is a `Trajectory`: a time grid (s) and, per recorded variable ("component.variable"),
its values on that grid.  Errors are compared on the common time grid: the times the result
and the reference share (no interpolation, which would add its own error).

Measures (documented in docs/evidence/README.md):
- scaled max error of a variable: max_t |y(t) - y_ref(t)| / range(y_ref), where range is
  max - min of the reference over the run (1 if the reference is constant),
- worst: the largest scaled max error over all variables,
- end error: |y(T) - y_ref(T)| / range(y_ref) at the last common time, and its worst.
A non-finite value anywhere makes the error infinite.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from master.recorder import signal_columns


@dataclass(frozen=True)
class Trajectory:
    """Recorded variables on a time grid.

    time: strictly increasing times (s); values: name -> array of the same length as time.
    """

    time: np.ndarray
    values: dict[str, np.ndarray] = field(default_factory=dict)

    def __post_init__(self) -> None:
        for name, v in self.values.items():
            if np.shape(v) != np.shape(self.time):
                raise ValueError(f"variable {name!r}: {np.size(v)} values for {np.size(self.time)} times")


def as_trajectory(data: np.ndarray) -> Trajectory:
    """A run's structured result array (time + "component.variable" columns) as a Trajectory
    (recorded coupling errors left out)."""
    names = signal_columns(data)
    return Trajectory(
        np.asarray(data["time"], dtype=float), {n: np.asarray(data[n], dtype=float) for n in names}
    )


@dataclass(frozen=True)
class ErrorReport:
    """Scaled errors (dimensionless: fraction of the reference's range) per variable and worst."""

    max_error: dict[str, float]  # scaled max abs error over the common grid
    end_error: dict[str, float]  # scaled abs error at the last common time
    worst_max: float
    worst_max_variable: str
    worst_end: float
    n_times: int  # number of common grid points compared


def variable_range(y: np.ndarray) -> float:
    """Range max - min of a reference variable, 1.0 if it is constant (avoids dividing by 0)."""
    span = float(np.max(y) - np.min(y))
    return span if span > 0.0 else 1.0


def common_times(t: np.ndarray, tr: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Indices (into t, into tr) of the times two increasing grids share (to 1e-9 relative)."""
    k = np.clip(np.searchsorted(tr, t), 1, max(len(tr) - 1, 1))
    left = np.abs(tr[k - 1] - t) <= np.abs(tr[np.minimum(k, len(tr) - 1)] - t)
    nearest = np.where(left, k - 1, np.minimum(k, len(tr) - 1))
    tol = 1e-9 * max(1.0, float(np.max(np.abs(tr))))
    hit = np.abs(tr[nearest] - t) <= tol
    return np.flatnonzero(hit), nearest[hit]


def compare(result: Trajectory, reference: Trajectory, variables: list[str] | None = None) -> ErrorReport:
    """Scaled errors of `result` against `reference` on the result's times inside the reference span.

    variables: names to compare (default: all names the two have in common).
    Raises ValueError if a requested variable is missing or no common time exists.
    """
    names = variables if variables is not None else sorted(set(result.values) & set(reference.values))
    if not names:
        raise ValueError("no common variables between result and reference")
    for n in names:
        for label, traj in (("result", result), ("reference", reference)):
            if n not in traj.values:
                raise ValueError(f"variable {n!r} missing in the {label}")
    t = np.asarray(result.time, dtype=float)
    tr = np.asarray(reference.time, dtype=float)
    mine, theirs = common_times(t, tr)
    if len(mine) == 0:
        raise ValueError("result and reference share no time on their grids")
    max_err: dict[str, float] = {}
    end_err: dict[str, float] = {}
    for n in names:
        y = np.asarray(result.values[n], dtype=float)[mine]
        yr_full = np.asarray(reference.values[n], dtype=float)
        yr = yr_full[theirs]
        scale = variable_range(yr_full)
        if not np.all(np.isfinite(y)):
            max_err[n] = end_err[n] = float("inf")
            continue
        d = np.abs(y - yr) / scale
        max_err[n] = float(np.max(d))
        end_err[n] = float(d[-1])
    worst_var = max(names, key=lambda n: max_err[n])
    return ErrorReport(
        max_error=max_err,
        end_error=end_err,
        worst_max=max_err[worst_var],
        worst_max_variable=worst_var,
        worst_end=max(end_err.values()),
        n_times=len(mine),
    )
