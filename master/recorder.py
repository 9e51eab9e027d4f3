"""Recorded results and run telemetry.

Rows (time in s, then one column per "component.variable" and, when asked, one per extrapolated
connection, "coupling_error(source.output -> consumer.input)") are buffered in a preallocated
chunk and streamed to disk when it fills: a raw file of 8 bytes a value (read back as a numpy
structured array) and, when asked, a CSV file that `read_csv` reads, and `fmpy.util.read_csv`
too unless a name holds a comma (an element of an FMI 3 matrix, "c.m[1,2]", quoted: fmpy's reader
splits the header at every comma) or a column holds text. Memory stays flat however long the run.

Columns are float64 but those `types` names (master.scenario.fmuinfo.recorded_as): FMI 3 Int64
and UInt64 values are held as int64 / uint64 (exact beyond 2^53), Strings as str and FMI 3
Binaries as bytes. A String or Binary is written to a side file once per change of its column's
value; the raw row holds its place there. In the CSV file a String is a quoted text, a Binary
its bytes as quoted hex digits.
"""

from __future__ import annotations

import csv
import json
import shutil
import tempfile
import warnings
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

CHUNK_ROWS = 4096
COUPLING_ERROR = "coupling_error("  # how a coupling error column's name begins (master.schedule)
TEXT_TYPES = ("String", "Binary")
_RAW = {"int64": np.int64, "uint64": np.uint64}  # raw column types other than float64


def signal_columns(data: np.ndarray) -> list[str]:
    """The recorded numeric signals of a result array: every column but "time", the coupling error
    columns (which measure the coupling, not the system: comparisons and stability checks skip
    them) and the Strings and Binaries."""
    return [n for n in number_columns(data) if not n.startswith(COUPLING_ERROR)]


def number_columns(data: np.ndarray) -> list[str]:
    """The columns of a result array but "time" that hold numbers (not Strings or Binaries)."""
    return [n for n in data.dtype.names if n != "time" and data.dtype[n].kind in "fiu"]


class ResultsError(OSError):
    """Results cannot be written: names the file and why."""


class Recorder:
    """Collects rows of `len(columns)` values of 8 bytes; `columns[0]` is "time"."""

    def __init__(
        self,
        columns: list[str],
        csv_path: Path | None = None,
        chunk_rows: int = CHUNK_ROWS,
        types: dict[str, str] | None = None,
        in_memory: bool = False,
    ):
        """types: column -> "int64", "uint64", "String" or "Binary" for those not float64 (a row
        holds an int64's or uint64's bits in its 8 bytes; a String's or Binary's come with the
        rows, `write`). in_memory: the rows kept in memory, not in a temporary folder (`tmpdir`
        None; not where a column holds Strings or Binaries): short runs one after another, a
        sweep's, make and remove no folder each."""
        self.columns = columns
        self.types = {c: t for c, t in (types or {}).items() if c in columns and t != "float64"}
        self._text = [i for i, c in enumerate(columns) if self.types.get(c) in TEXT_TYPES]
        self._last: list[tuple[bytes, int] | None] = [None] * len(self._text)  # per text column
        self.dtype = np.dtype([(c, _RAW.get(self.types.get(c, ""), np.float64)) for c in columns])
        self.chunk = np.zeros((chunk_rows, len(columns)))
        self.fill = 0
        self.rows = 0
        self.csv_path = Path(csv_path) if csv_path is not None else None
        self._csv = None
        if self.csv_path is not None:
            try:
                self.csv_path.parent.mkdir(parents=True, exist_ok=True)
                self._csv = open(self.csv_path, "w", encoding="utf-8")
                # names quoted as CSV does (a quote in a name doubled): element names may hold any
                header = ('"' + c.replace('"', '""') + '"' if c != "time" else c for c in columns)
                self._csv.write(",".join(header) + "\n")
            except OSError as e:
                raise ResultsError(
                    f"{self.csv_path}: cannot write the results there ({e.strerror or e})"
                ) from None
        self._blocks: list[np.ndarray] | None = [] if in_memory and not self._text else None
        self.tmpdir: Path | None = None
        self._bin = self._texts = None
        if self._blocks is not None:
            return
        self.tmpdir = Path(tempfile.mkdtemp(prefix="master_results_"))
        self.bin_path = self.tmpdir / "results.bin"
        self._bin = open(self.bin_path, "wb")
        self.texts_path = self.tmpdir / "texts.bin"  # each: its length (8 bytes), its bytes
        self._texts = open(self.texts_path, "w+b") if self._text else None

    def next_row(self) -> np.ndarray:
        """The row to fill next (a view into the chunk); call `commit()` once it is filled."""
        return self.chunk[self.fill]

    def commit(self) -> None:
        self.fill += 1
        self.rows += 1
        if self.fill == len(self.chunk):
            self.flush()

    def write(self, rows: np.ndarray, texts: np.ndarray | None = None) -> None:
        """Append a block of filled rows (n x len(columns)), e.g. the kernel's results ring, and
        with them their Strings and Binaries: texts[row][j] the j-th text column's slot (kernel.h
        MK_STRING_SLOT: a uint64 length, then the bytes)."""
        if not len(rows):
            return
        self.flush()
        if self._text and texts is not None:
            rows = np.array(rows)  # the ring's rows stay as they are
            for j, col in enumerate(self._text):
                rows[:, col] = self._places(j, texts[:, j])
        self._append(rows)
        self.rows += len(rows)

    def _places(self, j: int, slots: np.ndarray) -> np.ndarray:
        """Where text column j's values of a block of rows lie in the side file: a row whose slot
        equals the one before it (held values mostly do) takes its place without a look."""
        new = np.ones(len(slots), bool)
        new[1:] = np.any(slots[1:] != slots[:-1], axis=1)
        looked = np.flatnonzero(new)
        places = np.array([self._place(j, slots[r]) for r in looked], dtype=np.float64)
        return places[np.cumsum(new) - 1]  # each row: the place of the last row looked at

    def _place(self, j: int, slot: np.ndarray) -> int:
        """Where text column j's value of one row lies in the side file (appended if it changed)."""
        n = int(slot[:8].view(np.uint64)[0])
        value = slot[8 : 8 + n].tobytes()
        last = self._last[j]
        if last is not None and last[0] == value:
            return last[1]
        assert self._texts is not None
        self._texts.seek(0, 2)
        place = self._texts.tell()
        self._texts.write(np.uint64(n).tobytes() + value)
        self._last[j] = (value, place)
        return place

    def _texts_at(self, places: np.ndarray) -> dict[int, bytes]:
        """The stored bytes at each of these places of the side file (read, not kept: memory stays
        flat whatever the number of distinct values)."""
        assert self._texts is not None
        self._texts.flush()
        found = {}
        for place in set(map(int, places)):
            self._texts.seek(place)
            n = int(np.frombuffer(self._texts.read(8), np.uint64)[0])
            found[place] = self._texts.read(n)
        return found

    def _value(self, column: str, raw: bytes) -> str | bytes:
        """A String (str) or Binary (bytes) from its stored bytes."""
        return raw.decode("utf-8", "replace") if self.types[column] == "String" else raw

    def flush(self) -> None:
        """Write the buffered rows to disk."""
        if self.fill:
            self._append(self.chunk[: self.fill])
            self.fill = 0

    def _append(self, block: np.ndarray) -> None:
        if self._blocks is not None:
            self._blocks.append(np.array(block))  # a copy: the block may be the kernel's ring
            return
        try:
            self._bin.write(np.ascontiguousarray(block).tobytes())
            if self._csv is not None:
                if self.types:
                    self._csv.writelines(self._csv_lines(block))
                else:
                    np.savetxt(self._csv, block, delimiter=",", fmt="%.17g")
        except OSError as e:  # a full disk, a file system gone read-only
            where = self.csv_path if self._csv is not None else self.bin_path
            raise ResultsError(f"{where}: cannot write the results ({e.strerror or e})") from None

    def _csv_lines(self, block: np.ndarray) -> list[str]:
        """CSV lines of rows with typed columns: numbers as `np.savetxt` writes floats (%.17g),
        64-bit integers in full, Strings quoted, Binaries as quoted hex digits."""
        cells = []
        for i, name in enumerate(self.columns):
            x, t = block[:, i], self.types.get(name)
            if t in _RAW:
                cells.append([str(v) for v in x.view(_RAW[t])])
            elif t in TEXT_TYPES:
                shown = {p: _quoted(v.hex() if t == "Binary" else self._value(name, v))
                         for p, v in self._texts_at(x).items()}  # fmt: skip
                cells.append([shown[int(p)] for p in x])
            else:
                cells.append([f"{v:.17g}" for v in x])
        return [",".join(row) + "\n" for row in zip(*cells, strict=True)]

    def close(self) -> None:
        """Flush and close the files (the results stay readable through `data()`)."""
        self.flush()
        if self._bin is not None and not self._bin.closed:
            self._bin.close()
        if self._csv is not None and not self._csv.closed:
            self._csv.close()

    def data(self) -> np.ndarray:
        """All rows as a structured array with fields "time", "component.variable", ... (float64;
        int64 / uint64, and object for Strings (str) and Binaries (bytes), where `types` says)."""
        if self._blocks is not None:
            self.flush()
            rows = np.concatenate(self._blocks) if self._blocks else np.zeros((0, len(self.columns)))
            return np.ascontiguousarray(rows).view(self.dtype).reshape(-1)  # the bytes a file holds
        if not self._bin.closed:
            self.flush()
            self._bin.flush()
        raw = np.fromfile(self.bin_path, dtype=self.dtype)
        if not self._text:
            return raw
        texts = {self.columns[i] for i in self._text}
        dtype = np.dtype([(c, object if c in texts else raw.dtype[c]) for c in self.columns])
        out = np.empty(len(raw), dtype)
        for c in self.columns:
            if c in texts:
                values = {p: self._value(c, v) for p, v in self._texts_at(raw[c]).items()}
                out[c] = [values[int(p)] for p in raw[c]]
            else:
                out[c] = raw[c]
        return out

    def discard(self) -> None:
        """Remove the raw files (the CSV, if any, stays)."""
        self.close()
        if self._texts is not None and not self._texts.closed:
            self._texts.close()
        if self.tmpdir is not None:
            shutil.rmtree(self.tmpdir, ignore_errors=True)


def _quoted(text: str) -> str:
    return '"' + text.replace('"', '""') + '"'


def metadata_path(csv: str | Path) -> Path:
    """The results' metadata beside a results CSV file: same name, .json."""
    return Path(csv).with_suffix(".json")


def read_csv(path: str | Path) -> np.ndarray:
    """A results CSV file (`Recorder`'s, or any of numbers under a header of quoted or plain
    names) as a structured array with the field types `Recorder.data` has: each column's type as
    the run's metadata beside the file says ("types", see master.api), else as the text shows (a
    column of quoted texts: object, of str; of integers only: int64, uint64 beyond it; any other
    and "time": float64). 64-bit integers are exact; a Binary is read as its hex digits. ValueError
    if it is not one."""
    types = _declared_types(path)
    with open(path, newline="", encoding="utf-8") as f:
        header = next(csv.reader([f.readline()]), None)
        if not header:
            raise ValueError("no header line")
        start = f.tell()
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", UserWarning)  # no rows: an empty result
                rows = np.loadtxt(f, delimiter=",", ndmin=2)
        except ValueError:  # quoted texts among the numbers
            f.seek(start)
            return _read_texts(f, header, types)
        if not rows.size:  # no rows: each column's type as the metadata says, else float64
            return _structured(header, {n: np.zeros(0, _held_as((types or {}).get(n))) for n in header})
        if rows.shape[1] != len(header):
            raise ValueError(f"{len(header)} names in the header, {rows.shape[1]} values a row")
        # the columns whose numbers may be integers are read again as text, to be exact
        exact = [i for i, n in enumerate(header) if _maybe_integers(n, rows[:, i], types)]
        if exact:
            f.seek(start)
            texts = np.loadtxt(f, delimiter=",", usecols=exact, dtype=str, ndmin=2)
    columns = {n: rows[:, i] for i, n in enumerate(header)}
    columns |= {header[i]: _numbers(header[i], texts[:, j], types) for j, i in enumerate(exact)}
    return _structured(header, columns)


def _held_as(t: str | None) -> type:
    """The field type of a column of type t ("float64", "int64", "uint64", "String", "Binary")."""
    return object if t in TEXT_TYPES else _RAW.get(t or "", np.float64)


def _declared_types(csv_path: str | Path) -> dict[str, str] | None:
    """Each column's type ("float64", "int64", "uint64", "String", "Binary") as the run's metadata
    beside the CSV file says; None without one."""
    try:
        types = json.loads(metadata_path(csv_path).read_text(encoding="utf-8"))["types"]
    except (OSError, ValueError, KeyError, TypeError):
        return None
    return types if isinstance(types, dict) else None


def _maybe_integers(name: str, values: np.ndarray, types: dict[str, str] | None) -> bool:
    """Whether a column of numbers read as float64 has to be read again as integers."""
    if types is not None and name in types:
        return types[name] in _RAW
    return name != "time" and bool(np.all(np.isfinite(values) & (values == np.round(values))))


def _numbers(name: str, texts: np.ndarray, types: dict[str, str] | None) -> np.ndarray:
    """A column of numbers from its cells' text: int64 or uint64 where its type says so or, without
    one, where every cell is an integer (exact); else float64."""
    declared = (types or {}).get(name)
    if declared is None and name != "time":
        for kind in (np.int64, np.uint64):  # a column of integers only
            try:
                return texts.astype(kind)
            except (ValueError, OverflowError):
                pass
    if declared in _RAW:
        try:
            return texts.astype(_RAW[declared])
        except (ValueError, OverflowError):
            raise ValueError(f"column {name!r}: not the {declared} values its metadata says") from None
    return texts.astype(np.float64)


def _read_texts(f, header: list[str], types: dict[str, str] | None) -> np.ndarray:
    """The rows of a file with quoted texts among the numbers: a column of quoted texts (or one its
    type says is a String or Binary) is an object field of str, any other one of numbers."""
    start = f.tell()
    cells = [r for r in csv.reader(f) if r]
    f.seek(start)
    quoted = [r for r in csv.reader(f, quoting=csv.QUOTE_NONNUMERIC) if r]  # unquoted cells: float
    if any(len(r) != len(header) for r in cells):
        raise ValueError(f"{len(header)} names in the header, rows of other lengths")
    columns = {}
    for i, name in enumerate(header):
        text = (types or {}).get(name) in TEXT_TYPES or any(isinstance(r[i], str) for r in quoted)
        if text:
            columns[name] = np.array([r[i] for r in cells], dtype=object)
        else:
            columns[name] = _numbers(name, np.array([r[i] for r in cells], dtype=str), types)
    return _structured(header, columns)


def _structured(header: list[str], columns: dict[str, np.ndarray]) -> np.ndarray:
    """One structured array of these columns, in the header's order."""
    n = len(next(iter(columns.values()))) if columns else 0
    out = np.empty(n, np.dtype([(name, columns[name].dtype) for name in header]))
    for name in header:
        out[name] = columns[name]
    return out


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
    # "rms", relative to the range of the source's samples from the first full-order prediction
    # on (the coupling error estimate, master.runtime.tables.coupling_errors)
    coupling_errors: dict[str, dict[str, float]] = field(default_factory=dict)
    # per algebraic loop (its cycle): its counters, master.runtime.tables.loop_stats
    loops: dict[str, dict[str, float]] = field(default_factory=dict)
    # Scheduled Execution components: "component.clock" -> activations (input clocks), ticks (output)
    clock_ticks: dict[str, int] = field(default_factory=dict)
    # events handled per component that had any (Model Exchange, FMI 3 Co-Simulation in event mode)
    events: dict[str, int] = field(default_factory=dict)
    # iterated macro steps (master.runtime.tables.iteration_counts): "sweeps" in all, "max" in one
    # macro step, "macro_steps" iterated; None: explicit coupling
    iterations: dict[str, int] | None = None

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
            events = f", {self.events[name]} events" if name in self.events else ""
            lines.append(f"  {name}: {n} steps{events}, {self.fmu_time.get(name, 0.0):.3f} s inside the FMU")
        lines.append(f"  master overhead: {self.overhead_per_macro_step * 1e6:.1f} us per macro step")
        if self.iterations is not None:
            it, mean = self.iterations, self.iterations["sweeps"] / max(self.iterations["macro_steps"], 1)
            lines.append(
                f"  iterated coupling: {it['sweeps']} sweep{'s' if it['sweeps'] != 1 else ''} in "
                f"{it['macro_steps']} macro step{'s' if it['macro_steps'] != 1 else ''} "
                f"(mean {mean:.2f}, at most {it['max']} in one)"
            )
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
        for cycle, s in self.loops.items():
            how = (
                "no cycle found at the start: each member read once per point"
                if s["sequential"]
                else f"{s['iterations']} iterations (at most {s['most']} at one point), {s['jacobians']} "
                f"Jacobians, largest accepted change {s['worst']:.2g}"
            )
            lines.append(f"  algebraic loop {cycle}: {s['solves']} solves, {how}")
        if self.clock_ticks:
            ticks = ", ".join(f"{name} {n}" for name, n in self.clock_ticks.items())
            lines.append(f"  clock activations and ticks: {ticks}")
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
    """Plot recorded columns of a structured array over "time" (s) into a PNG file (`result_figure`;
    the title is also the PNG's "Title")."""
    import matplotlib.pyplot as plt

    fig = result_figure(data, title, columns, units)
    png = Path(png)
    png.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(png, dpi=100, metadata={"Title": title})
    plt.close(fig)
    return png


def result_figure(
    data: np.ndarray,
    title: str = "",
    columns: list[str] | None = None,
    units: dict[str, str | None] | None = None,
):
    """The figure of recorded columns over "time" (a matplotlib Figure).

    With `units` (column -> unit, None for none) each unit gets its own panel, labelled "[unit]"
    (a panel of columns without a unit: no label), so that pressures in Pa do not flatten
    positions in m; without, one panel holds every column. Coupling error columns
    ("coupling_error(...)", far smaller than the signals) get panels of their own.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    names = columns or number_columns(data)
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
        ax.set_ylabel((what + (f"[{unit}]" if unit else "")).strip())
        ax.grid(True, alpha=0.3)
        ax.legend(fontsize="small", loc="upper left", bbox_to_anchor=(1.01, 1.0))
    axes[-1, 0].set_xlabel("time [s]")
    axes[0, 0].set_title(title)
    fig.tight_layout()
    return fig
