"""Recorded results and run telemetry.

Rows (time in s, then one column per "component.variable" and, when asked, one per extrapolated
connection, "coupling_error(source.output -> consumer.input)") are buffered in a preallocated
chunk and streamed to disk when it fills: a raw float64 file (read back as a numpy structured
array) and, when asked, a CSV file that `read_csv` reads, and `fmpy.util.read_csv` too unless a
name holds a comma (an element of an FMI 3 matrix, "c.m[1,2]", quoted: fmpy's reader splits the
header at every comma). Memory stays flat however long the run.
"""

from __future__ import annotations

import csv
import shutil
import tempfile
import warnings
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

CHUNK_ROWS = 4096
COUPLING_ERROR = "coupling_error("  # how a coupling error column's name begins (master.schedule)


def signal_columns(data: np.ndarray) -> list[str]:
    """The recorded signals of a result array: every column but "time" and the coupling error
    columns (which measure the coupling, not the system: comparisons and stability checks skip them)."""
    return [n for n in data.dtype.names if n != "time" and not n.startswith(COUPLING_ERROR)]


class ResultsError(OSError):
    """Results cannot be written: names the file and why."""


EXACT_INTEGERS = 2.0**53  # every integer up to this magnitude is a float64


class Recorder:
    """Collects rows of `len(columns)` floats; `columns[0]` is "time"."""

    def __init__(
        self,
        columns: list[str],
        csv_path: Path | None = None,
        chunk_rows: int = CHUNK_ROWS,
        wide: tuple[str, ...] = (),
    ):
        """wide: columns of 64-bit integers, whose values beyond 2^53 in magnitude no float64 holds
        exactly: `rounded` counts them per column (the run summary says so)."""
        self.columns = columns
        self._wide = [columns.index(c) for c in wide]
        self.rounded: dict[str, int] = {}
        self.dtype = np.dtype([(c, np.float64) for c in columns])
        self.chunk = np.zeros((chunk_rows, len(columns)))
        self.fill = 0
        self.rows = 0
        self.csv_path = Path(csv_path) if csv_path is not None else None
        self._csv = None
        if self.csv_path is not None:
            try:
                self.csv_path.parent.mkdir(parents=True, exist_ok=True)
                self._csv = open(self.csv_path, "w")
                self._csv.write(",".join(f'"{c}"' if c != "time" else c for c in columns) + "\n")
            except OSError as e:
                raise ResultsError(
                    f"{self.csv_path}: cannot write the results there ({e.strerror or e})"
                ) from None
        self.tmpdir = Path(tempfile.mkdtemp(prefix="master_results_"))
        self.bin_path = self.tmpdir / "results.bin"
        self._bin = open(self.bin_path, "wb")

    def next_row(self) -> np.ndarray:
        """The row to fill next (a view into the chunk); call `commit()` once it is filled."""
        return self.chunk[self.fill]

    def commit(self) -> None:
        self.fill += 1
        self.rows += 1
        if self.fill == len(self.chunk):
            self.flush()

    def write(self, rows: np.ndarray) -> None:
        """Append a block of filled rows (n x len(columns)), e.g. the kernel's results buffer."""
        if len(rows):
            self.flush()
            self._append(rows)
            self.rows += len(rows)

    def flush(self) -> None:
        """Write the buffered rows to disk."""
        if self.fill:
            self._append(self.chunk[: self.fill])
            self.fill = 0

    def _append(self, block: np.ndarray) -> None:
        for i in self._wide:
            beyond = int(np.count_nonzero(np.abs(block[:, i]) > EXACT_INTEGERS))
            if beyond:
                self.rounded[self.columns[i]] = self.rounded.get(self.columns[i], 0) + beyond
        try:
            self._bin.write(block.tobytes())
            if self._csv is not None:
                np.savetxt(self._csv, block, delimiter=",", fmt="%.17g")
        except OSError as e:  # a full disk, a file system gone read-only
            where = self.csv_path if self._csv is not None else self.bin_path
            raise ResultsError(f"{where}: cannot write the results ({e.strerror or e})") from None

    def close(self) -> None:
        """Flush and close the files (the results stay readable through `data()`)."""
        self.flush()
        if not self._bin.closed:
            self._bin.close()
        if self._csv is not None and not self._csv.closed:
            self._csv.close()

    def data(self) -> np.ndarray:
        """All rows as a structured array with fields "time", "component.variable", ..."""
        if not self._bin.closed:
            self.flush()
            self._bin.flush()
        return np.fromfile(self.bin_path, dtype=self.dtype)

    def discard(self) -> None:
        """Remove the raw file (the CSV, if any, stays)."""
        self.close()
        shutil.rmtree(self.tmpdir, ignore_errors=True)


def read_csv(path: str | Path) -> np.ndarray:
    """A results CSV file (`Recorder`'s, or any of numbers under a header of quoted or plain
    names) as a structured array with a float64 field per column. ValueError if it is not one."""
    with open(path, newline="") as f:
        header = next(csv.reader(f), None)
        if not header:
            raise ValueError("no header line")
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", UserWarning)  # no rows: an empty result
            rows = np.loadtxt(f, delimiter=",", ndmin=2)
    if rows.size == 0:
        rows = np.zeros((0, len(header)))
    if rows.shape[1] != len(header):
        raise ValueError(f"{len(header)} names in the header, {rows.shape[1]} values a row")
    dtype = np.dtype([(name, np.float64) for name in header])
    return np.ascontiguousarray(rows, dtype=np.float64).view(dtype).reshape(-1)


@dataclass
class RunSummary:
    """Telemetry of one run. Times in s."""

    scenario: str
    backend: str
    stop_reason: str  # "finished" or the error message
    simulated_time: float
    wall_time: float  # initialisation and stepping (loading the FMUs not included)
    macro_steps: int
    steps: dict[str, int] = field(default_factory=dict)  # communication steps per component
    fmu_time: dict[str, float] = field(default_factory=dict)  # wall time inside FMI calls
    rows: int = 0
    stepping_time: float = 0.0  # s of wall time in the macro-step loop alone
    overruns: int | None = None  # --real-time only: macro steps that ended late
    worst_lateness: float | None = None  # s
    idle_time: float = 0.0  # s waiting for the wall clock (--real-time), not overhead
    lateness: dict[str, float] | None = (
        None  # --real-time: frame lateness quantiles "p50", "p99", "p99.9" (s)
    )
    lateness_histogram: list[tuple[int, int]] | None = None  # --real-time: (us, frames), nonzero bins
    output: str | None = None
    notes: list[str] = field(default_factory=list)  # what the run could not do as asked
    # per extrapolated connection: predicted vs produced sample at macro-step ends, "max" and
    # "rms", relative to the signal's range (the coupling error estimate)
    coupling_errors: dict[str, dict[str, float]] = field(default_factory=dict)

    @property
    def real_time_factor(self) -> float:
        """Simulated time per wall time (> 1: faster than real time)."""
        return self.simulated_time / self.wall_time if self.wall_time > 0 else float("inf")

    @property
    def overhead_per_macro_step(self) -> float:
        """Wall time outside FMI calls per macro step (s)."""
        if not self.macro_steps:
            return 0.0
        busy = self.wall_time - self.idle_time - sum(self.fmu_time.values())
        return max(busy, 0.0) / self.macro_steps

    def __str__(self) -> str:
        lines = [
            f"scenario {self.scenario}: {self.stop_reason}",
            f"  simulated {self.simulated_time:g} s in {self.wall_time:.3f} s wall "
            f"(real-time factor {self.real_time_factor:.3g}), {self.macro_steps} macro steps, "
            f"backend {self.backend}",
        ]
        for name, n in self.steps.items():
            lines.append(f"  {name}: {n} steps, {self.fmu_time.get(name, 0.0):.3f} s inside the FMU")
        lines.append(f"  master overhead: {self.overhead_per_macro_step * 1e6:.1f} us per macro step")
        if self.overruns is not None:
            late_ms = 1e3 * (self.worst_lateness or 0.0)
            lines.append(
                f"  real time: {self.overruns} frame overruns, worst lateness {late_ms:.3f} ms, "
                f"{self.idle_time:.3f} s waiting for the clock"
            )
        if self.lateness:
            quantiles = ", ".join(f"{q} {v * 1e6:.0f} us" for q, v in self.lateness.items())
            lines.append(f"  frame lateness: {quantiles}")
        worst = sorted(self.coupling_errors.items(), key=lambda kv: -kv[1]["max"])[:6]
        for name, e in worst:
            lines.append(
                f"  coupling error estimate {name}: max {e['max']:.2g}, rms {e['rms']:.2g} of its range"
            )
        lines.extend(f"  note: {n}" for n in self.notes)
        if self.output:
            lines.append(f"  {self.rows} rows written to {self.output}")
        return "\n".join(lines)


class RunResult:
    """What `master.run` returns: `.data` (structured array), `.summary`, `.columns`."""

    def __init__(self, recorder: Recorder, summary: RunSummary):
        self._recorder = recorder
        self.summary = summary
        self.columns = recorder.columns
        self._data: np.ndarray | None = None

    @property
    def data(self) -> np.ndarray:
        if self._data is None:
            self._data = self._recorder.data()
        return self._data

    def __del__(self) -> None:
        try:
            self._recorder.discard()
        except Exception:
            pass


def plot_result(
    data: np.ndarray,
    png: str | Path,
    title: str = "",
    columns: list[str] | None = None,
    units: dict[str, str | None] | None = None,
) -> Path:
    """Plot recorded columns of a structured array over "time" (s) into a PNG file.

    With `units` (column -> unit, None for none) each unit gets its own panel, so that
    pressures in Pa do not flatten positions in m; without, one panel holds every column. Coupling
    error columns ("coupling_error(...)", far smaller than the signals) get panels of their own.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    names = columns or [n for n in data.dtype.names if n != "time"]
    groups: dict[tuple[str, str | None], list[str]] = {}
    for n in names:
        what = "coupling error " if n.startswith(COUPLING_ERROR) else ""
        groups.setdefault((what, units.get(n) if units is not None else ""), []).append(n)
    fig, axes = plt.subplots(
        len(groups) or 1, 1, sharex=True, squeeze=False, figsize=(8, max(4.5, 2.2 * len(groups)))
    )
    for ax, ((what, unit), members) in zip(axes[:, 0], groups.items(), strict=False):
        for n in members:
            ax.plot(data["time"], data[n], label=n)
        if units is not None:
            ax.set_ylabel(what + (f"[{unit}]" if unit else "(no unit)"))
        elif what:
            ax.set_ylabel(what.strip())
        ax.grid(True, alpha=0.3)
        ax.legend(fontsize="small", loc="upper left", bbox_to_anchor=(1.01, 1.0))
    axes[-1, 0].set_xlabel("time [s]")
    axes[0, 0].set_title(title)
    fig.tight_layout()
    png = Path(png)
    png.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(png, dpi=100)
    plt.close(fig)
    return png
